"""The filter g of McCraith ch. 3 §III-B: temporal Gaussian smoothing of each box coordinate.

Applied to every MLP input, at training and at test time, so that the model is V = Psi(vec(g(b))) on both
sides (the thesis applies sigma = 5 to the tracker boxes at test time; we apply the same g to the training
tracks as well, tracker or synthetic, so train and test inputs see the same filter, ends included).
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
