"""Lifting 2D instance masks to 3D boxes (McCraith ch. 6): a Frustum-PointNet-style network trained from
the LiDAR points inside each mask with the one-sided Chamfer loss to a fixed template car.

Small modules, one job each:

- `frames`: the per-object input frame (pseudo-centre + viewing azimuth) and back to the vehicle frame.
- `model`: shared point MLP + masked max-pool -> translation, a yaw head (bins / (cos, sin) / hypotheses),
  and the per-point variance head of eq. (3).
- `criterion`: loss terms (alignment at the best yaw bin, at the regressed yaw, over hypotheses;
  multi-frame consistency; supervised boxes), composed by `build_criterion` from a configuration.
- `data`: object sets of a split (L_m or 2D-box points, tracks, ego poses, optional box targets), padded
  once, with the bad-input counts; the track-window batch sampler and the frame pairs of eq. (7).
- `gt_objects`: point sets of ground-truth cars (fully supervised reference rows only).
- `train`: the optimisation loop (Adam, step decay), loss curves, non-finite steps skipped and counted.
- `postprocess`: network outputs -> vehicle-frame boxes with the fixed template size, scores = mask scores.
- `evaluate`: predictions of a split -> KITTI AP (`redsup.det3d.kitti_eval`), flat metric dict.
- `pipeline`: one configuration end to end (what the Snakemake script calls).
- `tables`: the chapter's four tables from the per-configuration metrics.
"""
