"""McCraith ch. 5 as tables: the depth scale from the camera height evaluated on the prepared data.

Modules (pure functions; the per-frame geometry lives in ``redsup.depth.calibration``):

- ``names``    names the others share: method names (``road_method``) and the Fig. 1 row labels
- ``inputs``   one scene's raw network depth, LiDAR ground truth and road masks, brought to common resolutions
- ``methods``  the scaling methods of ch. 5 Table 1 (per-frame GT median, single GT scale, fixed road plane,
               fitted road plane with length / width limits) and their evaluation with skipped-frame reasons
- ``tables``   the tables (ch. 5 Tables 1-4), the Fig. 1 summary and plot
- ``plan``     the jobs as data for workflow/rules/calibration.smk (methods per table, input files)
"""
