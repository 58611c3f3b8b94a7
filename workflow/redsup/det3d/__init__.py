"""3D detection pieces shared by McCraith ch. 6 (lifting 2D masks to 3D boxes) and ch. 7 (LiDAR-only detector).

Pure, tested library code, no I/O and no hidden state:

- `boxes`: corners of 3D boxes, rotated-box BEV / 3D IoU (pairwise and for aligned pairs), 2D box overlap,
  projection of 3D boxes to image boxes.
- `kitti_eval`: average precision exactly as the KITTI object benchmark (R11 and R40; 2d / bev / 3d).
- `kitti_types`: `FrameGT` / `FrameDet`, the per-frame arrays `kitti_eval` scores and `kitti_files` reads.
- `template`: the fixed "average car" surface and its precomputed distance field.
- `losses`: per-point alignment losses (L2, Soft Inlier Count, outlier-aware), multi-frame consistency,
  best-yaw-bin search.
- `voting`: ch. 7 multi-cell voting.
- `pointsets`: padding L_m sets into batches, dropping non-finite points and empty sets with counts.

Boxes are (N, 7) arrays (x, y, z, l, w, h, yaw): geometric centre in the vehicle frame (x forward, y left,
z up), size along heading / across / vertical, yaw about +z with 0 facing +x (README, "The canonical raw-scene format").
"""
