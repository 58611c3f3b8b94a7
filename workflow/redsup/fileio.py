"""Atomic output writing: a failed job never leaves a partial file behind."""
from __future__ import annotations

import os
import threading
from pathlib import Path

import numpy as np


def save_npz_atomic(path: str | Path, **arrays: np.ndarray) -> None:
    """np.savez_compressed to a temporary sibling, then rename over `path`."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".part")
    with open(tmp, "wb") as fh:
        np.savez_compressed(fh, **arrays)
    os.replace(tmp, path)


def write_text_atomic(path: str | Path, text: str) -> None:
    """Write ``text`` to a temporary sibling, then rename over ``path``: a reader sees the old or the new file,
    never a partial one. The temporary name carries the process and thread, so concurrent writers of one
    path do not share it."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f"{path.name}.{os.getpid()}.{threading.get_ident()}.part")
    tmp.write_text(text)
    os.replace(tmp, path)
