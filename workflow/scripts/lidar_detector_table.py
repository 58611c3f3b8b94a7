"""Snakemake entry point: one of McCraith ch. 7 Tables 1-3 from the trained configurations' metrics."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

import json  # noqa: E402
from pathlib import Path  # noqa: E402

from redsup.lidar_detector.tables import CH6_ROW, build_table, caption_note, metric_name  # noqa: E402
from redsup.runlog import child_run  # noqa: E402
from redsup.tables import write_table  # noqa: E402

sm = snakemake  # noqa: F821
cfg = sm.config["lidar_detector"]
table_id = sm.wildcards.table
recall = cfg["eval"]["recall"]
with child_run(sm.log.run, table_id, "table", rule=sm.rule, wildcards=dict(sm.wildcards), config=sm.config,
               params={"rows": json.dumps(dict(cfg["tables"][table_id]), ensure_ascii=False), "recall": recall}) as run:
    by_run = {Path(p).stem: json.loads(Path(p).read_text()) for p in sm.input.metrics}
    rows = {row: by_run[name] for row, name in cfg["tables"][table_id].items()}
    if hasattr(sm.input, "lifting"):
        lifting = json.loads(Path(sm.input.lifting).read_text())
        print(f"ch. 6 row from {sm.input.lifting}: {sorted(k for k in lifting if 'bev_0.7' in k)}")
        rows = {CH6_ROW: lifting, **rows}
    table = build_table(table_id, rows, recall=recall, second_iou=float(cfg["eval"]["iou"][-1]))
    note = caption_note(sm.config["profile"], next(iter(by_run.values())), recall, len(by_run))
    score = write_table(table_id, table, sm.output.md, sm.output.csv, sm.output.tex, note=note)
    names = {CH6_ROW: "lifting_full_cityscapes", **cfg["tables"][table_id]}
    run.log_metrics({metric_name(f"{names[r]}/{c}"): float(v) for r, line in table.iterrows()
                     for c, v in line.items() if v == v})
    for path in (sm.output.md, sm.output.csv, sm.output.tex, sm.output.score):
        run.log_parent_artifact(path)
    print(table.to_string())
    print(Path(sm.output.md).read_text())
