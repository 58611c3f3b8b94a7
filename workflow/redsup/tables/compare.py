"""Comparing two builds' table CSVs cell by cell: which cells differ, and whether only measured-time columns do
(wall-clock seconds, FPS: never reproducible from one run to the next)."""
from __future__ import annotations

import csv
import re
from pathlib import Path

TIMING_COLUMN = re.compile(r"runtime|second|\(ms\)|\(s\)|time|fps|per s\b", re.IGNORECASE)


def differing_cells(a: Path, b: Path) -> list[tuple[int, str]] | None:
    """(row, column header) of every cell that differs between two CSVs; None when their shapes differ."""
    with open(a, newline="") as fa, open(b, newline="") as fb:
        ra, rb = list(csv.reader(fa)), list(csv.reader(fb))
    if len(ra) != len(rb) or not ra or any(len(x) != len(y) for x, y in zip(ra, rb)) or ra[0] != rb[0]:
        return None
    return [(i, ra[0][j]) for i in range(1, len(ra)) for j in range(len(ra[i])) if ra[i][j] != rb[i][j]]


def timing_only(cells: list[tuple[int, str]] | None) -> bool:
    """True when every differing cell is in a measured-time column (and there is at least one)."""
    return bool(cells) and all(TIMING_COLUMN.search(col) for _, col in cells)
