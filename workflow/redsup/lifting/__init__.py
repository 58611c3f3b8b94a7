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
- `pipeline`: one configuration end to end (what the Snakemake script calls), the auto-labels of Table IV.
- `tables`: the chapter's four tables from the per-configuration metrics.
- `plan`: the stage's jobs and their input files as data (used by `workflow/rules/lifting.smk`).

Test time lifts every 2D detection of the test scenes (single frames, no search): box = the posed template's
box with the FIXED template size 3.9 x 1.6 x 1.5 m (the method predicts no size), score = the mask score.
"""
