"""Where the val studies and diagnoses of studies/ store what they measured: results/studies/<name>.json."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

STUDIES_ROOT = "results/studies"


def _plain(value):
    """numpy scalars and arrays as JSON numbers and lists (everything else as text)."""
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)


def write_study(name: str, payload: dict, out_dir: str | Path = STUDIES_ROOT) -> Path:
    """Write ``payload`` to ``<out_dir>/<name>.json`` (``name`` may hold a '/': a subfolder) and return the path."""
    path = Path(out_dir) / f"{name}.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(payload, indent=1, default=_plain) + "\n")
    print(f"-> {path}", flush=True)
    return path
