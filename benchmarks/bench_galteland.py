"""Training speed of Galteland's two systems and of Monodepth2 at the default profile's size (run by hand, not a test).

    python benchmarks/bench_galteland.py                         # the default profile's systems settings
    python benchmarks/bench_galteland.py --profile paper --repeats 3 --device cuda

Per system (Monodepth2 = the M model, Manydepth = MD, Feature Depth = FD), at the network input the profile trains
it on (prepared world_kitti size x ``depth.systems.<system>.input_scale``), its width, bins and batch size: the
median over repeats of one training step (forward, the system's criterion, backward, Adam), as steps per second and
images per second, and the steps a default training takes in minutes at that speed; then the test-time frames per
second of one frame (batch 1; Manydepth with its previous frame and pose network). Random inputs and weights (the
speed does not depend on them).
"""
from __future__ import annotations

import argparse
from pathlib import Path

import torch
import yaml

from redsup import config as config_mod
from redsup.depth import configs, experiments, systems
from timing import median_time


def _batch(b: int, h: int, w: int, device) -> dict:
    K = torch.tensor([[0.58 * w, 0.0, (w - 1) / 2], [0.0, 1.92 * h, (h - 1) / 2], [0.0, 0.0, 1.0]])
    return {"target": torch.rand(b, 3, h, w, device=device), "K": K.expand(b, 3, 3).clone().to(device),
            "sources": {"prev": torch.rand(b, 3, h, w, device=device), "next": torch.rand(b, 3, h, w, device=device)}}


def bench(cfg: dict, mode: str, repeats: int, device: str) -> dict:
    d = cfg["depth"]
    model, train = configs.train_settings(d, "world_kitti", mode)
    res = cfg["datasets"]["world_kitti"]["resize"]
    h, w = systems.input_size((res["height"], res["width"]), float(model.get("input_scale", 1.0)))
    torch.manual_seed(0)
    models = systems.build({**model, "height": h, "width": w, "mode": mode}).to(device).train()
    steps = int(train["steps"])
    kw = experiments.loss_settings(d)
    crit = systems.criterion(model, kw, steps, 0)
    if crit is None:
        from redsup.depth import pipeline

        crit = lambda m, b, step: pipeline.batch_loss(m, b, **kw)  # noqa: E731
    opt = torch.optim.Adam(models.parameters(), lr=1e-4)
    batch = _batch(int(train["batch_size"]), h, w, device)

    def step():
        opt.zero_grad(set_to_none=True)
        crit(models, batch, 1)["loss"].backward()
        opt.step()
        if device == "cuda":
            torch.cuda.synchronize()

    sec = median_time(step, repeats, warmup=1)
    models.eval()
    one = {"target": batch["target"][:1], "K": batch["K"][:1], "prev": batch["sources"]["prev"][:1]}
    meta = {**model, "min_depth": model["min_depth"], "max_depth": model["max_depth"]}
    fps = 1.0 / median_time(lambda: experiments.predict_frame(models, one, meta), repeats, warmup=1)
    return {"mode": mode, "system": model["system"], "input": f"{w}x{h}", "width": model["base_channels"],
            "batch": int(train["batch_size"]), "steps_per_s": 1.0 / sec, "images_per_s": int(train["batch_size"]) / sec,
            "train_steps": steps, "train_minutes": steps * sec / 60.0, "test_fps": fps}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--profile", default="default")
    ap.add_argument("--modes", nargs="+", default=["M", "MD", "FD"])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--threads", type=int, default=1)
    ap.add_argument("--device", default="cpu")
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    raw = yaml.safe_load((Path(__file__).resolve().parents[1] / "config.yaml").read_text())
    raw["profile"] = args.profile
    cfg = config_mod.resolve(raw)
    ctx = experiments.timing_context(args.threads, (0, 0), args.device)
    print(f"profile {args.profile}, {ctx['device']}, {args.threads} thread(s)")
    print(f"{'mode':<6}{'system':<12}{'input':>9}{'width':>6}{'batch':>6}{'steps/s':>9}{'img/s':>8}"
          f"{'steps':>7}{'train min':>10}{'test FPS':>9}")
    for mode in args.modes:
        r = bench(cfg, mode, args.repeats, args.device)
        print(f"{r['mode']:<6}{r['system']:<12}{r['input']:>9}{r['width']:>6}{r['batch']:>6}{r['steps_per_s']:>9.2f}"
              f"{r['images_per_s']:>8.1f}{r['train_steps']:>7}{r['train_minutes']:>10.1f}{r['test_fps']:>9.1f}")


if __name__ == "__main__":
    main()
