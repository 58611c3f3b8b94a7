# LiDAR-only detector trained from 2D detections, SIC loss, multi-cell voting (McCraith ch. 7).
# Appends its ids to TABLE_IDS / FIGURE_IDS (see common.smk).
