# Self-supervised depth, test-time instance adaptation, Galteland's tables (McCraith ch. 4).
# Appends its ids to TABLE_IDS / FIGURE_IDS (see common.smk).
