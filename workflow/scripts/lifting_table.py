"""Snakemake entry point: one of McCraith ch. 6 Tables I-IV from the per-configuration metrics."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

import json  # noqa: E402
import re  # noqa: E402
from pathlib import Path  # noqa: E402

from redsup.lifting.tables import TABLE_NOTES, build_table, gt_count_note, row_summary  # noqa: E402
from redsup.runlog import child_run  # noqa: E402
from redsup.tables import write_table  # noqa: E402

sm = snakemake  # noqa: F821
cfg = sm.config["lifting"]
table_id = sm.wildcards.table
metrics = {Path(p).stem: json.loads(Path(p).read_text()) for p in sm.input.metrics}
infos = {Path(p).stem: json.loads(Path(p).read_text()) for p in sm.input.info}
with child_run(sm.log.run, table_id, "table", rule=sm.rule, wildcards=dict(sm.wildcards), config=sm.config,
               params={"rows": [[row, r] for row, r in cfg["tables"][table_id].items()]}) as run:
    table = build_table(cfg["tables"][table_id], metrics, iou=cfg["eval"]["table_iou"], info_by_run=infos)
    note = (f"Ours: {cfg['dataset']} test scenes, profile {sm.config['profile']}, seed {sm.config['seed']}; "
            f"AP at IoU {cfg['eval']['table_iou']:g} with 40 recall points (R40), the 11-point AP in the (R11) "
            "columns; 2D box heights of the difficulty cuts in KITTI-camera pixels; box size fixed to the "
            "template's 3.9 x 1.6 x 1.5 m; score = mask score; the last two columns: share of the test detections "
            "matched to a car with the lifted centre within 1 m and the yaw within 20 degrees (mod 180); "
            + TABLE_NOTES.get(table_id, "") + "; "
            + gt_count_note(metrics) + ". Rows: " + row_summary(cfg["tables"][table_id], cfg["runs"]))
    write_table(table_id, table, sm.output.md, sm.output.csv, sm.output.tex, note=note)
    runs = cfg["tables"][table_id]
    run.log_metrics({re.sub(r"[^\w./ -]", "", f"{runs[row]}/{col}"): v
                     for row, cells in table.iterrows() for col, v in cells.items() if v == v})
    for path in (sm.output.md, sm.output.csv, sm.output.tex):
        run.log_parent_artifact(path)
    print(table.to_string())
