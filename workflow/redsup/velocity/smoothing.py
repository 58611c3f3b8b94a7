"""The filter g of McCraith ch. 3 §III-B: temporal Gaussian smoothing of each box coordinate.

Where it is applied is configured per training data and phase (config velocity.smoothing): the thesis
applies sigma = 5 only to MLP-synthetic, only at test time, to remove from the tracker boxes the noise the
generated tracks do not have; MLP-tracker sees the raw boxes on both sides.
Boundary handling: the edge value is repeated (scipy mode "nearest").
"""
from __future__ import annotations

import numpy as np
from scipy.ndimage import gaussian_filter1d


def gaussian_smooth(boxes: np.ndarray, sigma: float) -> np.ndarray:
    """Boxes (..., T, 4) smoothed along time with a Gaussian of std `sigma` frames (0: a copy)."""
    boxes = np.asarray(boxes, dtype=np.float64)
    if sigma <= 0 or boxes.shape[-2] < 2:
        return boxes.copy()
    return gaussian_filter1d(boxes, sigma=float(sigma), axis=-2, mode="nearest", truncate=4.0)
