"""Snakemake entry point: one of McCraith ch. 5 Tables 1-4 from the per-method results."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

import json  # noqa: E402
from pathlib import Path  # noqa: E402

from redsup.calib import report  # noqa: E402
from redsup.calib.methods import road_method  # noqa: E402
from redsup.runlog import child_run  # noqa: E402
from redsup.tables import write_table  # noqa: E402

sm = snakemake  # noqa: F821
cfg = sm.config["calibration"]
table_id = sm.wildcards.table
length, width = float(cfg["length"]), float(cfg["width"])
results = {Path(p).stem: json.loads(Path(p).read_text()) for p in sm.input}
ours = road_method(length, width)
if table_id == "mccraith_ch5_table1":
    df = report.table1(results, length, width)
    labels = {(ours if k == "ours" else k): v for k, v in report.TABLE1_ROWS.items()}
    what = f"road box |X| < {width:g} m, Z < {length:g} m for (c) and (d)"
elif table_id == "mccraith_ch5_table2":
    df = report.table2(results, length, width)
    labels = {"gt_median": report.TABLE2_ROWS["gt_median"], ours: "Ours"}
    what = ("'Godard et al. [2019]' = our monocular model with per-frame GT median scaling (LiDAR at test time); "
            f"'Ours' = the same model scaled by the road plane (|X| < {width:g} m, Z < {length:g} m), no LiDAR")
elif table_id == "mccraith_ch5_table3":
    df = report.sweep_table(results, cfg["lengths"], vary="length", length=length, width=width)
    labels = {road_method(v, width): f"{float(v):g} m" for v in cfg["lengths"]}
    what = f"road points with Z < length and |X| < {width:g} m"
else:
    df = report.sweep_table(results, cfg["widths"], vary="width", length=length, width=width)
    labels = {road_method(length, v): f"{float(v):g} m" for v in cfg["widths"]}
    what = f"road points with |X| < width and Z < {length:g} m"
n_test = max(r["summary"]["n_frames"] + r["summary"]["n_skipped"] for r in results.values())
note = (f"Ours: {cfg['dataset']} ({n_test} test frames), depth model {cfg['mode']}, profile "
        f"{sm.config['profile']}; {what}; metrics not median-scaled except the GT scaling rows; scale err = "
        f"median |scale / per-frame GT scale - 1|. {report.skipped_note(results, labels)}")
with child_run(sm.log.run, table_id, "table", rule=sm.rule, wildcards=dict(sm.wildcards), config=sm.config,
               params={"methods": list(results)}) as run:
    score = write_table(table_id, df, sm.output.md, sm.output.csv, sm.output.tex, note=note)
    for path in (sm.output.md, sm.output.csv, sm.output.tex, sm.output.score):
        run.log_parent_artifact(path)
    run.log_metrics({"claims_held": score["claims_held"], "claims_evaluated": score["claims_evaluated"]})
    print(df.to_string())
    print(Path(sm.output.md).read_text())
