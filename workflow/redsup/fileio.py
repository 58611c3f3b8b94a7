"""Atomic output writing: a failed job never leaves a partial file behind, and a reader sees the old or the new
file, never a partial one. And YAML through libyaml where PyYAML has it (every job writes its resolved
configuration, every table job reads tables.yaml: the pure-Python emitter and parser took 0.2-0.3 s each time)."""
from __future__ import annotations

import os
import threading
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    import numpy as np


def part_path(path: str | Path) -> Path:
    """The temporary sibling ``<name>.<pid>.<thread>.part`` an atomic write of ``path`` goes through (created
    parent directory included): process and thread in the name, so concurrent writers of one path never share
    it (a live MLflow sync thread and a final sync rewriting the registry, for instance)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    return path.with_name(f"{path.name}.{os.getpid()}.{threading.get_ident()}.part")


def save_npz_atomic(path: str | Path, **arrays: np.ndarray) -> None:
    """np.savez_compressed to a temporary sibling, then rename over `path`."""
    import numpy as np

    tmp = part_path(path)
    with open(tmp, "wb") as fh:
        np.savez_compressed(fh, **arrays)
    os.replace(tmp, path)


def write_text_atomic(path: str | Path, text: str) -> None:
    """Write ``text`` to a temporary sibling, then rename over ``path``."""
    tmp = part_path(path)
    tmp.write_text(text)
    os.replace(tmp, path)


def yaml_load(text: str):
    """``yaml.safe_load`` (the same safe constructor and resolver), with libyaml's parser when available."""
    import yaml

    return yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))


def yaml_dump(obj) -> str:
    """``yaml.safe_dump(obj, sort_keys=True)``, with libyaml's emitter when available."""
    import yaml

    return yaml.dump(obj, Dumper=getattr(yaml, "CSafeDumper", yaml.SafeDumper), sort_keys=True)
