"""Relative-velocity spread per distance bin of a TuSimple-shaped clip split (rendered or real).

The statistic the traffic model of the clips is measured by (issue 11 §2): per TuSimple bin (distance
||[z, x]||, as the challenge script), the number of annotated vehicles and the standard deviation of the
relative velocity along (v_z) and across (v_x) the road. It is also the per-bin E_v of the oracle constant
predictor (the bin's own mean velocity): E_v^bin = std(v_z)^2 + std(v_x)^2 (population std).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from redsup.datastats import BIN_EDGES, BIN_NAMES, clip_annotations, distance_bin


def spread_table(z, x, vz, vx, edges=BIN_EDGES) -> pd.DataFrame:
    """Rows near / medium / far: n, std v_z, std v_x (m/s, population std; NaN for an empty bin)."""
    z, x, vz, vx = (np.asarray(a, dtype=np.float64) for a in (z, x, vz, vx))
    bins = distance_bin(z, x, tuple(edges))
    rows = {}
    for k, name in enumerate(BIN_NAMES):
        m = bins == k
        rows[name] = {"n": int(m.sum()), "std v_z": float(vz[m].std()) if m.any() else np.nan,
                      "std v_x": float(vx[m].std()) if m.any() else np.nan}
    df = pd.DataFrame.from_dict(rows, orient="index")
    df.index.name = "bin"
    return df


def velocity_spread(split_dir: str | Path, edges=BIN_EDGES) -> pd.DataFrame:
    """`spread_table` of every annotated vehicle of a split folder (clips/*/annotation.json)."""
    ann = clip_annotations(split_dir)
    return spread_table(ann["z"], ann["x"], ann["vz"], ann["vx"], edges)
