"""A depth training step with `redsup.depth.losses` as of a git revision (before) against the working tree (after),
in one process, timed alternately (run by hand, not a test; the machines are shared and noisy, so the ratio of
medians measured side by side is the figure to quote).

    python benchmarks/ab_depth_step.py --rev HEAD~1                 # 208x64, width 16, batch 4: default profile
    python benchmarks/ab_depth_step.py --rev 0f0337e --repeats 15 --threads 2

Prints whether both give the same loss and bitwise the same gradients (a speed change must not change numbers),
then per side the median step, GFLOP/s (the step's FLOPs from ``torch.utils.flop_counter``) and its share of the
fp32 sgemm peak measured at the end of the same run, its process CPU time, and the speed-up in wall and CPU time
(another process on the cores inflates wall time more than CPU time).
"""
from __future__ import annotations

import argparse
import importlib.util
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

import torch

from bench_depth import _batch, sgemm_gflops, step_flops
from redsup.depth import losses, networks, pipeline
from redsup.optim import Adam

ROOT = Path(__file__).resolve().parents[1]


def losses_at(rev: str):
    """`redsup.depth.losses` as of git revision ``rev``, as a module of its own."""
    text = subprocess.run(["git", "show", f"{rev}:workflow/redsup/depth/losses.py"], cwd=ROOT, check=True,
                          capture_output=True, text=True).stdout
    path = Path(tempfile.mkdtemp()) / "losses_before.py"
    path.write_text(text)
    spec = importlib.util.spec_from_file_location("losses_before", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--rev", required=True, help="git revision of the 'before' losses module")
    parser.add_argument("--size", default="208x64")
    parser.add_argument("--width", type=int, default=16)
    parser.add_argument("--batch", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=9)
    parser.add_argument("--threads", type=int, default=1, help="1: a default-profile train_depth job")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    w, h = (int(v) for v in args.size.lower().split("x"))
    sides = {"before": losses_at(args.rev).self_supervised_loss, "after": losses.self_supervised_loss}
    torch.manual_seed(0)
    models = networks.build_models(base_channels=args.width).train()
    optimizer = Adam(models.parameters(), lr=0.0)   # lr 0: every step sees the same weights
    batch = _batch(args.batch, h, w)

    def loss_and_grad(fn):
        losses.self_supervised_loss = fn
        models.zero_grad()
        out = pipeline.batch_loss(models, batch, generator=torch.Generator().manual_seed(0))
        out["loss"].backward()
        return out["loss"].item(), torch.cat([p.grad.flatten() for p in models.parameters() if p.grad is not None])

    (l0, g0), (l1, g1) = (loss_and_grad(fn) for fn in sides.values())
    print(f"loss before {l0:.8f} after {l1:.8f}; gradients bitwise equal: {torch.equal(g0, g1)}")

    def step(fn) -> tuple[float, float]:
        losses.self_supervised_loss = fn
        start, cpu = time.perf_counter(), time.process_time()
        pipeline.train_step(models, optimizer, batch, generator=torch.Generator().manual_seed(0))
        return time.perf_counter() - start, time.process_time() - cpu

    flops = step_flops(lambda: step(sides["after"]))
    times = {k: [] for k in sides}
    cpu = {k: [] for k in sides}
    for _ in range(args.repeats):
        for k, fn in sides.items():
            wall, used = step(fn)
            times[k].append(wall)
            cpu[k].append(used)
    peak = sgemm_gflops()
    print(f"torch {torch.__version__}, {args.threads} thread(s), {args.size}, width {args.width}, batch {args.batch}, "
          f"{flops / 1e9:.2f} GFLOP per step, sgemm peak {peak:.1f} GFLOP/s, median of {args.repeats}")
    for k, v in times.items():
        m = statistics.median(v)
        print(f"{k:>6} ({args.rev if k == 'before' else 'working tree'}): {m * 1e3:.0f} ms per step, "
              f"{flops / m / 1e9:.2f} GFLOP/s, {flops / m / 1e9 / peak:.3f} of peak; "
              f"{statistics.median(cpu[k]) * 1e3:.0f} ms of process CPU")
    print(f"speed-up {statistics.median(times['before']) / statistics.median(times['after']):.2f}x wall, "
          f"{statistics.median(cpu['before']) / statistics.median(cpu['after']):.2f}x CPU (the steadier figure on a "
          f"loaded machine)")


if __name__ == "__main__":
    main()
