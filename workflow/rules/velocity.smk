# Velocity from tracked boxes and synthetic box tracks (McCraith ch. 3).
# Appends its ids to TABLE_IDS / FIGURE_IDS (see common.smk).
