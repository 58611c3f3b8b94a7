"""Snakemake entry point: one evaluation configuration of the depth tables (adaptation run or prediction only)."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

# torch / BLAS threads from the configuration, not the executor, and deterministic kernels, before numpy
# and torch load: same seed -> same bits under any --cores or cluster (redsup.determinism)
from redsup.determinism import configure as deterministic_torch  # noqa: E402
deterministic_torch(snakemake.config["jobs"]["compute_threads"])  # noqa: F821

import json  # noqa: E402

import torch  # noqa: E402

from redsup.depth import checkpoint, data, experiments, plan  # noqa: E402
from redsup.fileio import write_text_atomic  # noqa: E402
from redsup.runlog import child_run  # noqa: E402

sm = snakemake  # noqa: F821
cfg = sm.config["depth"]
spec = plan.spec_of(sm.params.run)
tables = list(sm.params.run["tables"])

with child_run(sm.log.run, tables[0], spec.name, rule=sm.rule, wildcards=dict(sm.wildcards), config=sm.config,
               params={**spec.as_dict(), "tables": tables}) as run:
    models, meta = checkpoint.load(sm.input.model)
    stereo = sm.input.get("stereo")
    seqs = []
    for k, (scene_dir, npz, gt) in enumerate(zip(sm.input.scenes, sm.input.images, sm.input.gt)):
        seq = data.load_sequence(npz, scene_dir=scene_dir, stereo_npz=stereo[k] if stereo else None,
                                 stereo_baseline=meta.get("stereo_baseline"))
        seq = data.resize_sequence(seq, (int(meta["height"]), int(meta["width"])))  # the model's input size
        seqs.append(experiments.EvalSequence(seq, data.read_gt_depth(gt)))
    result = experiments.run_spec(spec, models, meta, seqs, cfg,
                                  progress=lambda i, n: print(f"{i}/{n}", flush=True) if i % 10 == 0 else None)
    result["timing"] = experiments.timing_context(torch.get_num_threads(), (int(meta["height"]), int(meta["width"])))
    curve_name = "adapt_loss" if spec.kind != "direct" else "direct_loss"
    for step, value in enumerate(result["loss_curve"], start=1):
        run.log_metric(curve_name, value, step=step)
    for step, agg in result["summary"].items():
        run.log_metrics({k: v for k, v in agg.items() if isinstance(v, (int, float))}, step=step)
        for reason in agg["skip_reasons"]:
            print(f"skipped (step {step}): {reason}")
    write_text_atomic(sm.output[0], json.dumps(result, indent=1, default=float))
    print(json.dumps({k: {m: v for m, v in a.items() if m != "skip_reasons"} for k, a in result["summary"].items()},
                     indent=1))
