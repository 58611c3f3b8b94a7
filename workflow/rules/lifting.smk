# Lifting 2D masks to 3D boxes with outlier-aware loss and yaw bins (McCraith ch. 6).
# Appends its ids to TABLE_IDS / FIGURE_IDS (see common.smk).
