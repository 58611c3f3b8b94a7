"""McCraith ch. 7: a LiDAR-only CenterPoint-style detector trained from 2D detections.

Small modules, pure functions where possible (no I/O except `data`):

- `grid`: the pillar grid and the BEV output grid (ranges, pillar size, output stride).
- `data`: per-split training / evaluation sets cached from the prepared scenes (FOV-cropped sweeps, L_m
  sets with the bad-input counts, ground truth for evaluation and the supervised reference rows).
- `augment`: global rotation, flip, scaling and translation applied consistently to points, L_m and boxes.
- `model`: pillar feature net scattered into the BEV grid, a small 2D CNN, the heads (centre heatmap,
  3D offset within the cell, K yaw bins, optional size).
- `targets`: target assignment (median cell of L_m, multi-cell voting, Gaussian heatmap targets; gt boxes
  for the supervised reference).
- `criterion`: focal heatmap loss, SIC / L2 template alignment at the best yaw bin + yaw cross-entropy
  (ch. 7 eq. 8-9), the supervised L1 / CE terms; all unreduced.
- `postprocess`: heatmap peaks, box decoding, rotated BEV NMS, camera-view filtering and 2D boxes.
- `train`: the training loop (curves through a callback) and `evaluate`: inference + KITTI AP.
- `tables`: the three tables of ch. 7 from the per-configuration metrics.
- `plan`: the stage's jobs and tables as data; `names`: the run-id prefix `plan` and `tables` share.
"""
