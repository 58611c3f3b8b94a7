"""Snakemake entry point: train one depth model (its mode's system: Monodepth2, Manydepth or Feature Depth) on a
dataset's training scenes; systems with validation passes pick their best epoch on the val split."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

# torch / BLAS threads from the configuration, not the executor, and deterministic kernels, before numpy
# and torch load: same seed -> same bits under any --cores or cluster (redsup.determinism)
from redsup.determinism import configure as deterministic_torch  # noqa: E402
deterministic_torch(snakemake.config["jobs"]["compute_threads"])  # noqa: F821

import json  # noqa: E402

import torch  # noqa: E402

from redsup.depth import checkpoint, data, experiments, systems, training  # noqa: E402
from redsup.depth.configs import model_seed, parse_model, train_settings  # noqa: E402
from redsup.depth.plan import model_parent  # noqa: E402
from redsup.depth.experiments import loss_settings  # noqa: E402
from redsup.fileio import write_text_atomic  # noqa: E402
from redsup.runlog import child_run, plain  # noqa: E402
from redsup.mlflow_model import log_model  # noqa: E402

sm = snakemake  # noqa: F821
cfg = sm.config["depth"]
dataset, mode, seed_index = parse_model(sm.wildcards.model)
mode_cfg = cfg["modes"][mode]
sources = list(mode_cfg["sources"])
device = cfg["device"] if cfg["device"] != "auto" else ("cuda" if torch.cuda.is_available() else "cpu")
seed = model_seed(sm.config["seed"], sm.wildcards.model)
model_cfg, tcfg = train_settings(cfg, dataset, mode)
params = {"dataset": dataset, "mode": mode, "seed_index": seed_index, "sources": sources,
          "cameras": mode_cfg["cameras"], "seed": seed, "device": device, "model": model_cfg, "loss": cfg["loss"],
          "train": tcfg}

parent = model_parent(sm.config, f"{dataset}/{mode}")
with child_run(sm.log.run, parent, f"train {sm.wildcards.model}", rule=sm.rule, wildcards=dict(sm.wildcards),
               config=sm.config, params=params) as run:
    seqs = []
    for cam in mode_cfg["cameras"]:
        stereo = sm.input.get("stereo") if cam == "cam_front" and "stereo" in sources else None
        for k, (scene_dir, npz) in enumerate(zip(sm.input.scenes, sm.input[cam])):
            seqs.append(data.load_sequence(npz, scene_dir=scene_dir, stereo_npz=stereo[k] if stereo else None,
                                           reversed_order=(cam == "cam_back"), camera=cam,
                                           stereo_baseline=cfg["train"]["stereo_baseline"]))
    h, w = systems.input_size(seqs[0].size, float(model_cfg.get("input_scale", 1.0)))
    seqs = [data.resize_sequence(s, (h, w)) for s in seqs]
    meta = {**model_cfg, "height": h, "width": w, "mode": mode, "sources": sources,
            "cameras": list(mode_cfg["cameras"]), "dataset": dataset, "train": dict(tcfg), "loss": dict(cfg["loss"]),
            "seed": seed, "scenes": [str(s) for s in sm.input.scenes]}
    torch.manual_seed(seed)
    models = systems.build(meta).to(device)
    every = int(cfg["train"]["log_every"])

    def log_step(step, terms):
        if step % every == 0 or step == 1:
            run.log_metrics({k: v for k, v in terms.items()}, step=step)
        if step % 50 == 0 or step == 1:
            print(f"step {step}: " + ", ".join(f"{k} {v:.4g}" for k, v in terms.items()), flush=True)

    validate, val_every = None, 0
    if int(tcfg["epochs"]) > 0 and sm.input.get("val_images"):
        val = [experiments.EvalSequence(data.resize_sequence(data.load_sequence(npz, scene_dir=sd), (h, w)),
                                        data.read_gt_depth(gt))
               for sd, npz, gt in zip(sm.input.val_scenes, sm.input.val_images, sm.input.val_gt)]
        val_every = max(1, int(tcfg["steps"]) // int(tcfg["epochs"]))

        def validate(step):  # one validation pass per "epoch": the seven metrics with the step (MLflow curves)
            frames = cfg["eval"]["frames"].get("val", cfg["eval"]["frames"]["all"])
            metrics = experiments.validation_metrics(models, meta, val, cfg["eval"], frames)
            run.log_metrics({f"val_{k}": v for k, v in metrics.items()}, step=step)
            print(f"validation at step {step}: " + ", ".join(f"{k} {v:.4g}" for k, v in metrics.items()), flush=True)
            return metrics
    elif int(tcfg["epochs"]) > 0:
        print("no val scenes: no validation passes, the last step's weights are kept")

    automask_after = int(tcfg.get("automask_after", 0))
    criterion = systems.criterion(meta, loss_settings(cfg), int(tcfg["steps"]), seed, automask_after)
    summary = training.train(models, seqs, sources, steps=int(tcfg["steps"]), batch_size=int(tcfg["batch_size"]),
                             lr=float(tcfg["lr"]), decay_at=tcfg["decay_at"], gamma=float(tcfg["gamma"]),
                             flip=tcfg["flip"], min_speed=tcfg["min_speed"], seed=seed,
                             loss_kwargs=loss_settings(cfg), callback=log_step, device=device,
                             criterion=criterion, validate=validate, validate_every=val_every,
                             automask_after=automask_after if criterion is None else 0)
    meta.update(summary)
    if "stereo" in sources:  # metres per network unit: evaluate S / MS with this fixed scale (Monodepth2's 5.4)
        metric = seqs[0].extra["stereo_baseline_m"]
        meta.update(stereo_baseline=cfg["train"]["stereo_baseline"],
                    stereo_scale_factor=metric / cfg["train"]["stereo_baseline"])
    checkpoint.save(sm.output.model, models, meta, sm.config)
    write_text_atomic(sm.output.meta, json.dumps(plain({"meta": meta, "config": sm.config}), indent=1))
    log_model(run, models, sm.output.model, name=f"depth-{sm.wildcards.model}")   # the system's networks, for MLflow
    run.log_metrics({k: float(v) for k, v in summary.items() if isinstance(v, (int, float))})
    print({k: v for k, v in summary.items() if k != "validation"})
