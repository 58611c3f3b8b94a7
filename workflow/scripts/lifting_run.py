"""Snakemake entry point: train one lifting configuration with one seed (McCraith ch. 6) and evaluate it on the
test scenes."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

# torch / BLAS threads from the configuration, not the executor, and deterministic kernels, before numpy
# and torch load: same seed -> same bits under any --cores or cluster (redsup.determinism)
from redsup.determinism import configure as deterministic_torch  # noqa: E402
deterministic_torch(snakemake.config["jobs"]["compute_threads"])  # noqa: F821

import json  # noqa: E402

import torch  # noqa: E402

from redsup.fileio import write_text_atomic  # noqa: E402
from redsup.lifting import plan  # noqa: E402
from redsup.lifting.pipeline import run_configuration, save_model, scene_inputs  # noqa: E402
from redsup.det3d.template import load_template, spec_from_config  # noqa: E402
from redsup.runlog import child_run  # noqa: E402
from redsup.mlflow_model import log_model  # noqa: E402

sm = snakemake  # noqa: F821
cfg = sm.config["lifting"]
conf, seed_index = sm.wildcards.conf, int(sm.wildcards.seed)
run_name = plan.run_id(conf, seed_index)
seed = plan.training_seed(sm.config, seed_index)
spec = cfg["runs"][conf]
tables = plan.tables_of(sm.config, run_name) or list(cfg["tables"])[:1]   # every table whose rows read it
train = scene_inputs(sm.input.train_scenes, sm.input.train_detections, sm.input.train_tracks)
test = scene_inputs(sm.input.test_scenes, sm.input.test_detections)
labels = sm.input.labels if "labels" in sm.input.keys() else None
with child_run(sm.log.run, tables[0], run_name, rule=sm.rule, wildcards=dict(sm.wildcards), config=sm.config,
               params={"run": spec, "tables": tables, "seed": seed, "train": cfg["train"], "loss": cfg["loss"],
                       "network": cfg["network"], "max_points": cfg["max_points"]}) as run:
    model, metrics, info, boot = run_configuration(spec, cfg, train, test, seed=seed, labels_path=labels,
                                                   log=run.log_metric, camera=sm.config["detection"]["camera"],
                                                   min_depth=sm.config["detection"]["points"]["min_depth"],
                                                   template=load_template(sm.input.template, spec_from_config(cfg)))
    run.log_metrics(metrics)
    run.log_metrics(info)
    save_model(model, spec, sm.config, sm.output.model, {"configuration": conf, "seed": seed})
    log_model(run, model, sm.output.model, name=f"lifting-{run_name}")
    write_text_atomic(sm.output.info, json.dumps(info, indent=1, sort_keys=True) + "\n")
    # the result the tables read: the KITTI metrics and the evaluation diagnostics
    result = metrics | {k: v for k, v in info.items() if k.startswith("diag/")}
    if boot:   # bootstrap replicates of the AP over the test frames (the tables' test-sampling noise)
        result["bootstrap"] = boot
    write_text_atomic(sm.output.metrics, json.dumps(result, indent=1, sort_keys=True) + "\n")
    print(json.dumps({k: v for k, v in metrics.items() if "_0.5/" in k and k.endswith("R40")}, indent=1))
