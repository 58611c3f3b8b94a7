"""Stable seeds for the stochastic preparation stages (independent of Python's hash randomisation)."""
from __future__ import annotations

import hashlib


def derive_seed(base: int, *parts: object) -> int:
    """A 32-bit seed from a base seed and names (scene, level, stage...): same inputs, same seed."""
    blob = "/".join([str(int(base))] + [str(p) for p in parts]).encode()
    return int.from_bytes(hashlib.sha256(blob).digest()[:4], "little")
