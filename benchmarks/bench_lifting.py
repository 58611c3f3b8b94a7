"""Speed of the ch. 6 lifting network (run by hand, not a test; CPU, `--threads` torch threads).

    python benchmarks/bench_lifting.py                     # default profile's network, 2 threads
    python benchmarks/bench_lifting.py --profile paper --repeats 3

- inference: objects per second lifted (network forward + box decoding), batched over all the detections of
  a frame-like set (`--batch`) and one object at a time (latency); the thesis reports 200 Hz on a GPU after
  the 2D detector.
- training step: one optimisation step (forward, yaw-bin search over K bins, loss, backward, Adam) with a
  batch of 64 objects, for K = 16, 64 and 128 bins, with and without the multi-frame pairs.
Point sets have `max_points` points (the configured subsampling), drawn around a car-sized blob.
"""
from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import torch

from redsup import config as cfgmod
from redsup.lifting.criterion import build_criterion
from redsup.lifting.data import Batch
from redsup.lifting.frames import to_vehicle
from redsup.lifting.model import build_model
from redsup.lifting.pipeline import make_template
from timing import median_time

ROOT = Path(__file__).resolve().parents[1]


def fake_batch(n: int, p: int, rng: np.random.Generator, pairs: bool = False) -> Batch:
    pts = torch.as_tensor(rng.normal(0.0, [1.2, 0.6, 0.4], size=(n, p, 3)), dtype=torch.float32)
    mask = torch.ones(n, p, dtype=torch.bool)
    centre = torch.as_tensor(rng.uniform([5, -10, 0.5], [40, 10, 1.0], size=(n, 3)), dtype=torch.float32)
    azimuth = torch.atan2(centre[:, 1], centre[:, 0])
    pair = None
    if pairs:   # consecutive objects of windows of 5 form the pairs of eq. (7)
        i = torch.arange(0, n - 1)
        i = i[(i % 5) != 4]
        T = torch.eye(4).repeat(len(i), 1, 1)
        T[:, 0, 3] = -1.0
        pair = (i, i + 1, T)
    return Batch(pts, mask, centre, azimuth, pair)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--profile", default="default")
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--batch", type=int, default=512)
    args = ap.parse_args()
    torch.set_num_threads(args.threads)
    cfg = cfgmod.load(ROOT / "config.yaml", {"profile": args.profile})["lifting"]
    p = int(cfg["max_points"])
    rng = np.random.default_rng(0)
    template = make_template(cfg)
    print(f"profile {args.profile}, {args.threads} threads, {p} points per object, network {cfg['network']}")

    model = build_model(cfg["network"], {"kind": "bins", "n_bins": 64}).eval()
    big = fake_batch(args.batch, p, rng)
    one = fake_batch(1, p, rng)

    @torch.no_grad()
    def infer(b: Batch) -> None:
        out = model(b.points, b.mask, b.context)
        to_vehicle(out["translation"], model.yaw.decode(out), b.centre, b.azimuth)

    infer(big)
    t_big = median_time(lambda: infer(big), args.repeats)
    t_one = median_time(lambda: infer(one), max(20, args.repeats * 10))
    print(f"inference, batch {args.batch}: {args.batch / t_big:,.0f} objects/s ({t_big * 1e3:.1f} ms per batch)")
    print(f"inference, one object at a time: {1 / t_one:,.0f} objects/s ({t_one * 1e3:.2f} ms latency)")

    for k in (16, 64, 128):
        for terms in (["alignment"], ["alignment", "multiview"]):
            spec = {"terms": terms, "point_loss": "outlier_aware", "yaw": {"kind": "bins", "n_bins": k}}
            net = build_model(cfg["network"], spec["yaw"]).train()
            crit = build_criterion(spec, cfg["loss"], template, net.yaw)
            opt = torch.optim.Adam(net.parameters(), lr=1e-3)
            b = fake_batch(64, p, rng, pairs="multiview" in terms)

            def step() -> None:
                loss, _ = crit(net(b.points, b.mask, b.context), b)
                opt.zero_grad()
                loss.backward()
                opt.step()

            step()
            t = median_time(step, args.repeats)
            print(f"training step, batch 64, {k:3d} bins, {'+'.join(terms):20s}: {t * 1e3:7.1f} ms")


if __name__ == "__main__":
    main()
