"""Frames/s of instance-wise test-time adaptation, one frame at a time against K frames as one batched
optimisation (``adaptation.adapt_batched``), at a profile's model and input size (run by hand, not a test).

    python benchmarks/bench_adaptation_batched.py                       # default profile, batches 1 4 8 16
    python benchmarks/bench_adaptation_batched.py --batches 1 8 --frames 16 --steps 10 --repeats 5 --threads 2

Read from config.yaml's ``depth`` section under ``--profile``: the network width (``model.base_channels``,
``num_scales``), the input size of the adaptation tables' dataset (``adaptation.dataset`` -> ``datasets.<d>.resize``),
its mode's sources, the adapted groups (``adaptation.groups``) and the loss settings; ``--steps`` SGD steps per
frame (Table 1: 10) at ``adaptation.lr``, then one prediction, for ``--frames`` frames of a synthetic sideways pan
(random images and weights: the speed does not depend on them). Rows: ``one-at-a-time`` (``adaptation.adapt``
per frame from the reset weights, as ``experiments.run_instance`` with ``batch_size`` 1) and ``batched K``
(``adapt_batched`` on K frames at once; K = 1 shows the cost of the vmap machinery alone). Every repeat runs every
row once, interleaved, so that a shared machine's load hits all rows alike; the table shows the medians over
repeats (frames/s = frames / the median wall time; min / max: the fastest / slowest repeat, s/frame) and the
ratio to one-at-a-time, by wall time and by this process's CPU time (steadier where other jobs share the cores).
"""
from __future__ import annotations

import argparse
import functools
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "workflow"))

from redsup import config as rconfig  # noqa: E402
from redsup.depth import adaptation, data, experiments, networks, pipeline  # noqa: E402


def setting(cfg: dict) -> dict:
    """Model width, input size, sources, groups, lr and loss settings of the profile's adaptation tables."""
    depth = cfg["depth"]
    ad = depth["adaptation"]
    resize = cfg["datasets"][ad["dataset"]]["resize"]
    return {"base_channels": int(depth["model"]["base_channels"]), "num_scales": int(depth["model"]["num_scales"]),
            "height": int(resize["height"]), "width": int(resize["width"]),
            "sources": list(depth["modes"][ad["mode"]]["sources"]), "groups": list(ad["groups"]),
            "lr": float(ad["lr"]), "loss": experiments.loss_settings(depth),
            "dataset": ad["dataset"], "mode": ad["mode"]}


def samples_of(n: int, h: int, w: int, sources: list[str]) -> list[dict]:
    """The test samples of frames 1..n of a synthetic sideways pan (temporal sources only)."""
    rng = np.random.default_rng(0)
    base = rng.integers(0, 255, size=(h, w + n + 2, 3), dtype=np.uint8)
    images = np.stack([base[:, i:i + w] for i in range(n + 2)])
    K = np.array([[0.58 * w, 0.0, (w - 1) / 2], [0.0, 1.92 * h, (h - 1) / 2], [0.0, 0.0, 1.0]])
    seq = data.Sequence("bench", images, K)
    return [data.eval_sample(seq, t, sources) for t in range(1, n + 1)]


def one_at_a_time(models, state, samples, params, s: dict, steps: int) -> None:
    for k, sample in enumerate(samples):
        adaptation.load_snapshot(models, state)
        adaptation.adapt(models, experiments.frame_loss(s["loss"], k), sample, params, s["lr"], steps)
        with torch.no_grad():
            pipeline.predict_depth(models, sample["target"], s["loss"]["min_depth"], s["loss"]["max_depth"])
    adaptation.load_snapshot(models, state)


def batched(models, samples, params, s: dict, steps: int, k: int) -> None:
    loss_fn = functools.partial(pipeline.batch_loss, **s["loss"])
    predict = functools.partial(_predict, lo=s["loss"]["min_depth"], hi=s["loss"]["max_depth"])
    for start in range(0, len(samples), k):
        chunk = samples[start:start + k]
        gens = [experiments.frame_generator(s["loss"], start + j) for j in range(len(chunk))]
        _, copies = adaptation.adapt_batched(models, loss_fn, chunk, params, s["lr"], steps,
                                             generators=None if gens[0] is None else gens)
        copies.map(predict)


def _predict(models, sample, lo, hi):
    return pipeline.predict_depth(models, sample["target"], lo, hi)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", default=str(ROOT / "config.yaml"))
    ap.add_argument("--profile", default="default")
    ap.add_argument("--batches", type=int, nargs="+", default=[1, 4, 8, 16])
    ap.add_argument("--frames", type=int, default=16, help="frames adapted per timed run")
    ap.add_argument("--steps", type=int, default=5, help="SGD steps per frame (Table 1: 10)")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--threads", type=int, default=1, help="torch threads (the depth evaluation rules use 1)")
    args = ap.parse_args()
    if args.repeats < 3:
        ap.error("--repeats must be >= 3 (medians)")
    torch.set_num_threads(args.threads)
    s = setting(rconfig.load(args.config, {"profile": args.profile}))
    torch.manual_seed(0)
    models = networks.build_models(s["base_channels"], s["num_scales"]).eval()
    state = adaptation.snapshot(models)
    params = adaptation.select_parameters(models, s["groups"])
    samples = samples_of(args.frames, s["height"], s["width"], s["sources"])
    print(f"profile {args.profile}: {s['dataset']} / {s['mode']} ({'+'.join(s['sources'])}), input "
          f"{s['height']} x {s['width']}, base_channels {s['base_channels']}, groups {'+'.join(s['groups'])}, "
          f"lr {s['lr']:g}; {args.frames} frames x {args.steps} steps + 1 prediction, {args.threads} thread(s), "
          f"torch {torch.__version__}")
    rows = {"one-at-a-time": lambda: one_at_a_time(models, state, samples, params, s, args.steps)}
    for k in args.batches:
        rows[f"batched {k}"] = functools.partial(batched, models, samples, params, s, args.steps, k)
    for fn in rows.values():   # warm-up (first-call allocations, vmap's first trace)
        fn() if fn is rows["one-at-a-time"] else batched(models, samples[:2], params, s, 1, 2)
    times: dict[str, list[float]] = {name: [] for name in rows}
    cpu: dict[str, list[float]] = {name: [] for name in rows}
    for _ in range(args.repeats):
        for name, fn in rows.items():
            start, start_cpu = time.perf_counter(), time.process_time()
            fn()
            times[name].append(time.perf_counter() - start)
            cpu[name].append(time.process_time() - start_cpu)
    base = statistics.median(times["one-at-a-time"])
    base_cpu = statistics.median(cpu["one-at-a-time"])
    # wall time is what a job waits; CPU time (this process, all its threads) is steadier on a shared machine
    print(f"{'path':<16}{'frames/s':>10}{'s/frame':>10}{'min':>8}{'max':>8}{'speed-up':>10}"
          f"{'CPU s/frame':>13}{'CPU ratio':>11}")
    for name, ts in times.items():
        med, med_cpu = statistics.median(ts), statistics.median(cpu[name])
        print(f"{name:<16}{args.frames / med:>10.2f}{med / args.frames:>10.3f}{min(ts) / args.frames:>8.3f}"
              f"{max(ts) / args.frames:>8.3f}{base / med:>9.2f}x{med_cpu / args.frames:>13.3f}"
              f"{base_cpu / med_cpu:>10.2f}x")


if __name__ == "__main__":
    main()
