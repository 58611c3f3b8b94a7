"""Snakemake entry point: train one MLP configuration of McCraith ch. 3 (tracker or synthetic tracks) and
evaluate it on the test splits."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

# torch / BLAS threads from the configuration, not the executor, and deterministic kernels, before numpy
# and torch load: same seed -> same bits under any --cores or cluster (redsup.determinism)
from redsup.determinism import configure as deterministic_torch  # noqa: E402
deterministic_torch(snakemake.config["jobs"]["compute_threads"])  # noqa: F821

import json  # noqa: E402
from pathlib import Path  # noqa: E402

import torch  # noqa: E402

from redsup.prep.seeds import derive_seed  # noqa: E402
from redsup.runlog import child_run  # noqa: E402
from redsup.mlflow_model import log_model  # noqa: E402
from redsup.velocity import plan  # noqa: E402
from redsup.velocity.data import load_split  # noqa: E402
from redsup.velocity.experiment import run_mlp  # noqa: E402
from redsup.velocity.mlp import resolve_device, save_model  # noqa: E402
from redsup.velocity.tables import write_configuration_outputs  # noqa: E402

sm = snakemake  # noqa: F821
vcfg = sm.config["velocity"]
spec = sm.params.run
configuration = plan.configurations(sm.config)[spec["configuration"]]
seed = derive_seed(sm.config["seed"], "velocity", configuration["name"])  # seed index 0: as before seeds existed
seed = seed if spec["seed_index"] == 0 else derive_seed(seed, "seed", str(spec["seed_index"]))
device = resolve_device(vcfg["device"])
params = {"configuration": configuration, "seed_index": spec["seed_index"], "tables": spec["tables"],
          "mlp": vcfg["mlp"], "smoothing": vcfg["smoothing"],
          "synthetic": vcfg["synthetic"], "min_box_px": vcfg["min_box_px"], "seed": seed, "device": device}
with child_run(sm.log.run, plan.parent(sm.config, configuration["name"]), sm.wildcards.run, rule=sm.rule,
               wildcards=dict(sm.wildcards), config=sm.config, params=params) as run:
    train = load_split(sm.input.train_tracks, sm.input.train_clips, vcfg["min_box_px"])
    splits = {Path(c).name: load_split(t, c, vcfg["min_box_px"]) for t, c in zip(sm.input.tracks, sm.input.clips)}
    stats = json.loads(Path(sm.input.generator[0]).read_text()) if sm.input.generator else None
    print("training clips:", train.quality(), "bad input per clip:", train.bad_input_per_clip())

    def on_epoch(epoch, row):
        run.log_metrics(row, step=epoch)

    metrics, predictions, model, curve = run_mlp(configuration, vcfg["mlp"], vcfg["smoothing"],
                                                 vcfg["synthetic"]["samples"], train, splits, stats, seed,
                                                 on_epoch=on_epoch, device=device)
    save_model(model, sm.output.model, sm.config, {"configuration": configuration, "seed": seed,
                                                   "smoothing": vcfg["smoothing"][configuration["train_on"]],
                                                   "calibration": train.calib.as_dict()})
    log_model(run, model, sm.output.model, name=f"velocity_mlp-{sm.wildcards.run}")
    write_configuration_outputs(configuration, metrics, predictions, splits, sm.output.metrics, sm.output.predictions)
    run.log_metrics(metrics)
    print(metrics)
