"""Timings of the ch. 3 velocity pieces (run by hand, not a test; CPU, `--threads` torch threads).

    python benchmarks/bench_velocity.py                   # all, 5 repeats, medians
    python benchmarks/bench_velocity.py --only forward --repeats 3

- forward: the whole estimator Psi per track (Gaussian smoothing, features, MLP forward), one track at a
  time (the Table II runtime column) and a batch of 375 tracks (the thesis' test set size), per track;
  the geometric baseline per track for comparison.
- generate: synthetic tracks per second of the §IV-B generator.
- epoch: one training epoch of the thesis' MLP on 11536 synthetic tracks (batch 32), seconds.
"""
from __future__ import annotations

import argparse

import numpy as np
import torch

from redsup.velocity import geometry, mlp
from redsup.velocity.data import TrackSet
from redsup.velocity.synthetic import fit_statistics, generate_tracks
from timing import median_time

CAL = geometry.Calibration(fx=714.0, fy=714.0, cx=640.0, cy=360.0, height=1.8)  # TuSimple-like, 1280 x 720
FPS = 20.0


def statistics_for_bench(n: int = 400) -> dict:
    rng = np.random.default_rng(0)
    t = np.arange(40) / FPS
    X0, Z0 = rng.choice([-3.75, 0.0, 3.75], n), rng.uniform(8, 80, n)
    V = rng.normal(0, [0.2, 1.5], (n, 2))
    X, Z = X0[:, None] + V[:, :1] * t, Z0[:, None] + V[:, 1:] * t
    boxes = geometry.box_from_ground(X, Z, CAL.fx * 1.8 / Z, CAL.fy * 1.5 / Z, CAL)
    train = TrackSet(boxes=boxes, velocity=V, position=np.stack([X[:, -1], Z[:, -1]], -1),
                     bins=np.digitize(Z[:, -1], (20, 45)), clip=np.arange(n), track_id=np.zeros(n, int),
                     tracker_failed=np.zeros(n, bool), degenerate=np.zeros(n, bool), calib=CAL)
    return fit_statistics(train, CAL, n_frames=40, fps=FPS)


def bench_forward(stats: dict, repeats: int) -> None:
    boxes = generate_tracks(stats, 375, np.random.default_rng(1))["boxes"]
    model = mlp.VelocityMLP(160).eval()
    one = mlp.forward_time_ms(model, boxes, CAL, 5.0, repeats=200 * repeats)
    print(f"forward, one track at a time: median {one['forward_ms_median']:.3f} ms, p90 {one['forward_ms_p90']:.3f} ms")

    def batch():
        with torch.no_grad():
            model(torch.from_numpy(mlp.box_features(boxes, CAL, 5.0)))

    print(f"forward, batch of 375: {median_time(batch, 20 * repeats) / 375 * 1000:.4f} ms per track")
    geo = median_time(lambda: geometry.geometric_velocity(boxes[:1], CAL, FPS, 10), 200 * repeats)
    print(f"geometric baseline, one track: {geo * 1000:.3f} ms")


def bench_generate(stats: dict, repeats: int) -> None:
    s = median_time(lambda: generate_tracks(stats, 11536, np.random.default_rng(2)), repeats)
    print(f"generator: 11536 tracks in {s:.3f} s ({11536 / s:.0f} tracks/s)")


def bench_epoch(stats: dict, repeats: int) -> None:
    gen = generate_tracks(stats, 11536, np.random.default_rng(3))
    feats = mlp.box_features(gen["boxes"], CAL, 5.0)
    s = median_time(lambda: mlp.train_mlp(feats, gen["velocity"], hidden=70, layers=4, dropout=0.2, lr=6e-4,
                                     lr_decay=0.99, epochs=1, batch_size=32, seed=0), repeats)
    print(f"one epoch, 11536 tracks, batch 32: {s:.2f} s (150 epochs: {150 * s / 60:.1f} min)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--only", choices=("forward", "generate", "epoch"))
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--threads", type=int, default=1)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    stats = statistics_for_bench()
    print(f"torch {torch.__version__}, {args.threads} thread(s)")
    for name, fn in (("forward", bench_forward), ("generate", bench_generate), ("epoch", bench_epoch)):
        if args.only in (None, name):
            fn(stats, args.repeats)


if __name__ == "__main__":
    main()
