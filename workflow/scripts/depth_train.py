"""Snakemake entry point: train one depth + pose model (Monodepth2 recipe) on a dataset's training scenes."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

import zlib  # noqa: E402

import torch  # noqa: E402

from redsup.depth import checkpoint, data, networks, training  # noqa: E402
from redsup.depth.configs import parse_model  # noqa: E402
from redsup.depth.plan import model_parent  # noqa: E402
from redsup.depth.experiments import loss_settings  # noqa: E402
from redsup.runlog import child_run  # noqa: E402

sm = snakemake  # noqa: F821
from redsup.determinism import configure as deterministic_torch  # noqa: E402
deterministic_torch(sm.threads)  # the rule's threads and deterministic kernels: same seed -> same bits
cfg = sm.config["depth"]
dataset, mode, seed_index = parse_model(sm.wildcards.model)
mode_cfg = cfg["modes"][mode]
sources = list(mode_cfg["sources"])
device = cfg["device"] if cfg["device"] != "auto" else ("cuda" if torch.cuda.is_available() else "cpu")
seed = int(sm.config["seed"]) + zlib.crc32(f"{dataset}/{mode}".encode()) % 100000  # seed index 0
seed += 0 if seed_index == 0 else zlib.crc32(sm.wildcards.model.encode()) % 100000
init_disparity = mode_cfg.get("init_disparity", cfg["model"].get("init_disparity"))
steps = next((m.get("steps") for m in cfg["models"] if m["dataset"] == dataset and m["mode"] == mode), None)  # override
params = {"dataset": dataset, "mode": mode, "seed_index": seed_index, "sources": sources,
          "cameras": mode_cfg["cameras"], "seed": seed,
          "device": device, "model": {**cfg["model"], "init_disparity": init_disparity}, "loss": cfg["loss"],
          "train": {**cfg["train"], **({"steps": steps} if steps else {})}}

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
    torch.manual_seed(seed)
    models = networks.build_models(cfg["model"]["base_channels"], cfg["model"]["num_scales"], init_disparity).to(device)
    every = int(cfg["train"]["log_every"])

    def log_step(step, terms):
        if step % every == 0 or step == 1:
            run.log_metrics({k: v for k, v in terms.items()}, step=step)
        if step % 50 == 0 or step == 1:
            print(f"step {step}: " + ", ".join(f"{k} {v:.4g}" for k, v in terms.items()), flush=True)

    tcfg = params["train"]  # depth.train with this model's steps override
    summary = training.train(models, seqs, sources, steps=tcfg["steps"], batch_size=tcfg["batch_size"], lr=tcfg["lr"],
                             decay_at=tcfg["decay_at"], gamma=tcfg["gamma"], flip=tcfg["flip"],
                             min_speed=tcfg["min_speed"], seed=seed, loss_kwargs=loss_settings(cfg),
                             callback=log_step, device=device)
    h, w = seqs[0].size
    meta = {"base_channels": cfg["model"]["base_channels"], "num_scales": cfg["model"]["num_scales"],
            "height": h, "width": w, "min_depth": cfg["model"]["min_depth"], "max_depth": cfg["model"]["max_depth"],
            "mode": mode, "sources": sources, "cameras": list(mode_cfg["cameras"]), "dataset": dataset,
            "train": dict(tcfg), "loss": dict(cfg["loss"]), "seed": seed,
            "scenes": [str(s) for s in sm.input.scenes], **summary}
    if "stereo" in sources:  # metres per network unit: evaluate S / MS with this fixed scale (Monodepth2's 5.4)
        metric = seqs[0].extra["stereo_baseline_m"]
        meta.update(stereo_baseline=cfg["train"]["stereo_baseline"],
                    stereo_scale_factor=metric / cfg["train"]["stereo_baseline"])
    checkpoint.save(sm.output[0], models, meta, sm.config)
    run.log_metrics({k: float(v) for k, v in summary.items()})
    print(summary)
