"""COCO run-length encoded masks, decoded without pycocotools.

A COCO RLE is ``{"size": [h, w], "counts": ...}``. Runs alternate 0s and 1s, start with 0s, and walk the
mask in column-major (Fortran) order. ``counts`` is either a list of ints (uncompressed RLE) or the
compressed string of pycocotools' ``rleToString``: each run length (from the fourth on, minus the run two
before it) is written in 5-bit groups, least significant first, as characters ``48 + group``; bit 0x20
marks "more groups follow" and bit 0x10 of the last group is the sign.
"""
from __future__ import annotations

import numpy as np


class RLEError(ValueError):
    """A malformed RLE."""


def string_to_counts(s: str) -> list[int]:
    """Run lengths from a compressed COCO RLE string (pycocotools `rleFrString`)."""
    counts: list[int] = []
    p = 0
    n = len(s)
    while p < n:
        x = 0
        k = 0
        more = True
        while more:
            if p >= n:
                raise RLEError(f"compressed RLE ends inside a number: {s[:40]!r}")
            c = ord(s[p]) - 48
            if c < 0 or c > 63:
                raise RLEError(f"compressed RLE has a character outside '0'..'o' at {p}: {s[p]!r}")
            x |= (c & 0x1F) << (5 * k)
            more = bool(c & 0x20)
            p += 1
            k += 1
            if not more and (c & 0x10):
                x |= -1 << (5 * k)
        if len(counts) > 2:
            x += counts[-2]
        counts.append(x)
    return counts


def counts_to_string(counts) -> str:
    """Compressed COCO RLE string of run lengths (pycocotools `rleToString`)."""
    out = []
    counts = [int(c) for c in counts]
    for i, value in enumerate(counts):
        x = value - counts[i - 2] if i > 2 else value
        more = True
        while more:
            c = x & 0x1F
            x >>= 5
            more = (x != -1) if (c & 0x10) else (x != 0)
            if more:
                c |= 0x20
            out.append(chr(c + 48))
    return "".join(out)


def decode(rle: dict) -> np.ndarray:
    """(h, w) bool mask of a COCO RLE (compressed string or uncompressed list of counts)."""
    try:
        h, w = (int(v) for v in rle["size"])
        counts = rle["counts"]
    except (KeyError, TypeError, ValueError) as exc:
        raise RLEError(f"an RLE needs 'size': [h, w] and 'counts', got {str(rle)[:80]}") from exc
    if isinstance(counts, bytes):
        counts = counts.decode("ascii")
    if isinstance(counts, str):
        counts = string_to_counts(counts)
    try:
        counts = np.asarray(counts, dtype=np.int64)
    except (TypeError, ValueError):
        counts = None
    if counts is None or counts.ndim != 1:
        raise RLEError(f"RLE counts must be a string or a list of run lengths, got {str(rle['counts'])[:40]}")
    if (counts < 0).any():
        raise RLEError("an RLE has a negative run length")
    if counts.sum() != h * w:
        raise RLEError(f"RLE run lengths sum to {int(counts.sum())}, but size {h}x{w} has {h * w} pixels")
    values = np.zeros(len(counts), dtype=bool)
    values[1::2] = True
    flat = np.repeat(values, counts)
    return flat.reshape((w, h)).T.copy()


def encode(mask: np.ndarray) -> dict:
    """Compressed COCO RLE of a 2D bool mask (for tests and for writing detection files)."""
    mask = np.asarray(mask, dtype=bool)
    h, w = mask.shape
    flat = mask.T.ravel()
    change = np.flatnonzero(flat[1:] != flat[:-1]) + 1
    bounds = np.concatenate([[0], change, [flat.size]])
    runs = np.diff(bounds).tolist()
    if flat.size and flat[0]:
        runs = [0] + runs
    return {"size": [h, w], "counts": counts_to_string(runs)}
