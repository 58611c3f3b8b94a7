"""Clip shards: the consecutive clips of a velocity-clip split that one job renders (rule ``world_clips_shard``).

A shard is named by its first and last clip, 1-based as the clip folders (``001-025``), so a shard size that
changes names other shards and never reuses a finished shard as another. Pure and dependency-free: the rules read
it when the workflow is parsed.
"""
from __future__ import annotations

import re

NAME = re.compile(r"(\d+)-(\d+)")


def ranges(n_clips: int, shard_size: int) -> list[range]:
    """The 0-based clip ranges of a split of ``n_clips`` in shards of ``shard_size``; the last one may be shorter."""
    if shard_size < 1:
        raise ValueError(f"velocity_clips.shard_size must be at least 1, got {shard_size}")
    return [range(a, min(a + shard_size, n_clips)) for a in range(0, n_clips, shard_size)]


def name(clips: range) -> str:
    """``001-025`` for clips 0..24 (0-based)."""
    return f"{clips.start + 1:03d}-{clips.stop:03d}"


def names(n_clips: int, shard_size: int) -> list[str]:
    """The shard names of a split, in clip order."""
    return [name(r) for r in ranges(n_clips, shard_size)]


def clips_of(shard: str) -> range:
    """The 0-based clips of the shard named ``shard`` (the inverse of `name`)."""
    match = NAME.fullmatch(shard)
    if not match or not 1 <= int(match[1]) <= int(match[2]):
        raise ValueError(f"clip shard {shard!r} is not <first>-<last> (1-based, first <= last)")
    return range(int(match[1]) - 1, int(match[2]))
