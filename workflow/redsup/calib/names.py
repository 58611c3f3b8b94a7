"""Names the calibration modules share (torch-free, no imports): method names and the Fig. 1 row labels.

Below ``methods``, ``report`` and ``plan``, so that none of them imports another for a name.
"""
from __future__ import annotations


def road_method(length: float, width: float) -> str:
    """``road_L<length>_W<width>`` (numbers as %g), e.g. ``road_L30_W3``."""
    return f"road_L{float(length):g}_W{float(width):g}"


# row labels of a series table (redsup.calib.tables.fig1_table)
FIG1_GT_ROW = "per-frame GT scaling factor"
FIG1_SINGLE_ROW = "GT Single Scaling (training set)"
FIG1_OURS_ROW = "Ours (road plane, per frame)"
FIG1_ROAD_ROW = "GT scaling on the road-box pixels (diagnostic)"
