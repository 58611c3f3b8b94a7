"""Snakemake entry point: fit the synthetic box-track generator (McCraith ch. 3 §IV-B) on the training clips."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

import json  # noqa: E402

from redsup.fileio import write_text_atomic  # noqa: E402
from redsup.runlog import child_run  # noqa: E402
from redsup.velocity import plan  # noqa: E402
from redsup.velocity.data import load_split  # noqa: E402
from redsup.velocity.synthetic import fit_statistics  # noqa: E402

sm = snakemake  # noqa: F821
vcfg = sm.config["velocity"]
synthetic = [c["name"] for c in vcfg["configurations"] if c.get("train_on") == "synthetic"]
parent = plan.parent(sm.config, synthetic[0]) if synthetic else next(iter(vcfg["tables"]))
with child_run(sm.log.run, parent, "synthetic generator fit", rule=sm.rule, wildcards={},
               config=sm.config, params={"synthetic": vcfg["synthetic"], "min_box_px": vcfg["min_box_px"]}) as run:
    train = load_split(sm.input.tracks, sm.input.clips, vcfg["min_box_px"])
    print("training clips:", train.quality(), "bad input per clip:", train.bad_input_per_clip())
    stats = fit_statistics(train, train.calib, n_frames=train.boxes.shape[1], fps=sm.config["velocity_clips"]["fps"],
                           size_degree=vcfg["synthetic"]["size_degree"], max_depth=vcfg["synthetic"]["max_depth"],
                           min_depth=vcfg["synthetic"]["min_depth"])
    write_text_atomic(sm.output[0], json.dumps(stats, indent=1))
    run.log_metrics({k: v for k, v in stats.items() if isinstance(v, (int, float))})
    run.log_metrics({f"train_{k}": v for k, v in train.quality().items()})
    run.log_artifact(sm.output[0])
    print({k: v for k, v in stats.items() if k != "start_points"})
