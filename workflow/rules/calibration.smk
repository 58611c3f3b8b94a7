# Depth scale from the camera height: per-frame road-plane fit (McCraith ch. 5).
# Appends its ids to TABLE_IDS / FIGURE_IDS (see common.smk).
