"""Snakemake entry point: our automatically generated labels, the lifted boxes of the training detections
(McCraith ch. 6 Table IV (iii)), from one trained run."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

# torch / BLAS threads from the configuration, not the executor, and deterministic kernels, before numpy
# and torch load: same seed -> same bits under any --cores or cluster (redsup.determinism)
from redsup.determinism import configure as deterministic_torch  # noqa: E402
deterministic_torch(snakemake.config["jobs"]["compute_threads"])  # noqa: F821

import torch  # noqa: E402

from redsup.fileio import save_npz_atomic  # noqa: E402
from redsup.lifting import plan  # noqa: E402
from redsup.lifting.pipeline import load_model, make_labels, resolve_device, scene_inputs  # noqa: E402
from redsup.det3d.template import load_template, spec_from_config  # noqa: E402
from redsup.runlog import child_run  # noqa: E402

sm = snakemake  # noqa: F821
cfg = sm.config["lifting"]
conf, seed_index = sm.wildcards.conf, int(sm.wildcards.seed)
run_name = plan.run_id(conf, seed_index)
spec = cfg["runs"][conf]
tables = plan.tables_of_labels(sm.config, run_name) or list(cfg["tables"])[:1]  # tables of the runs it supervises
scenes = scene_inputs(sm.input.train_scenes, sm.input.train_detections, sm.input.train_tracks)
with child_run(sm.log.run, tables[0], f"labels_{run_name}", rule=sm.rule, wildcards=dict(sm.wildcards),
               config=sm.config, params={"run": spec, "tables": tables}) as run:
    model = load_model(sm.input.model, resolve_device(cfg["device"]))
    labels = make_labels(model, spec, cfg, scenes, seed=plan.training_seed(sm.config, seed_index),
                         template=load_template(sm.input.template, spec_from_config(cfg)))
    save_npz_atomic(sm.output[0], **labels)
    run.log_metrics({"labels": float(len(labels["box"]))})
    print(f"{len(labels['box'])} labels from {len(scenes)} scenes")
