"""Training steps with glibc's default allocator settings against the ones the Snakefile gives every job
(`redsup.jobenv.ALLOCATOR_ENV`), each workload in fresh processes, alternated (run by hand, not a test; quote the
ratio of medians measured side by side).

    python benchmarks/bench_allocator.py                       # M depth step (208 x 64, width 16, batch 4) + detector
    python benchmarks/bench_allocator.py --rounds 5 --steps 30 --workloads depth

Per workload and setting: median seconds a step, minor page faults, user and system CPU per step (from the
child's own `getrusage`), over `--rounds` processes of `--steps` timed steps after 3 warm-up steps.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
from pathlib import Path

from redsup.jobenv import ALLOCATOR_ENV

HERE = Path(__file__).resolve().parent

CHILD = r"""
import json, resource, sys, time
import torch
torch.set_num_threads(1)
torch.manual_seed(0)
workload, steps = sys.argv[1], int(sys.argv[2])
if workload == "depth":
    from bench_depth import _batch
    from redsup.depth import networks, pipeline
    from redsup.optim import Adam
    models = networks.build_models(base_channels=16).train()
    opt = Adam(models.parameters(), lr=1e-4)
    batch = _batch(4, 64, 208)
    def step():
        pipeline.train_step(models, opt, batch, generator=torch.Generator().manual_seed(0))
    for _ in range(3):
        step()
    stamps = []
    r0 = resource.getrusage(resource.RUSAGE_SELF)
    for _ in range(steps):
        stamps.append(time.perf_counter()); step()
    stamps.append(time.perf_counter())
else:
    from bench_lidar_detector import synthetic_split
    from redsup.det3d.template import TemplateSpec, build_template
    from redsup.lidar_detector.augment import AugmentSpec
    from redsup.lidar_detector.grid import GridSpec
    from redsup.lidar_detector.train import RunSpec, TrainSpec, train
    grid = GridSpec()
    data = synthetic_split(grid, 20, 12000, 8)
    template = build_template(TemplateSpec(voxel=0.1))
    stamps, marks = [], {}
    def log(metrics, step):
        stamps.append(time.perf_counter())
        if len(stamps) == 3:
            marks["r0"] = resource.getrusage(resource.RUSAGE_SELF)
    train(data, RunSpec(window=2), grid, TrainSpec(steps=steps + 3, batch=2, log_every=1), AugmentSpec(), template,
          n_bins=64, seed=0, log=log)
    stamps = stamps[2:]
    r0 = marks["r0"]
r1 = resource.getrusage(resource.RUSAGE_SELF)
n = len(stamps) - 1
diffs = sorted(b - a for a, b in zip(stamps, stamps[1:]))
print(json.dumps({"step_s": diffs[len(diffs) // 2], "faults": (r1.ru_minflt - r0.ru_minflt) / n,
                  "user_s": (r1.ru_utime - r0.ru_utime) / n, "sys_s": (r1.ru_stime - r0.ru_stime) / n}))
"""


def run_child(workload: str, steps: int, tuned: bool) -> dict:
    env = {k: v for k, v in os.environ.items() if not k.startswith("MALLOC_")}
    if tuned:
        env.update(ALLOCATOR_ENV)
    env["PYTHONPATH"] = os.pathsep.join([str(HERE), str(HERE.parent / "workflow"), env.get("PYTHONPATH", "")])
    out = subprocess.run([sys.executable, "-c", CHILD, workload, str(steps)], env=env, capture_output=True,
                         text=True, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--workloads", nargs="+", default=["depth", "detector"], choices=["depth", "detector"])
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--steps", type=int, default=20)
    args = ap.parse_args()
    print(f"allocator settings of the jobs: {ALLOCATOR_ENV}")
    for workload in args.workloads:
        results = {False: [], True: []}
        for _ in range(args.rounds):
            for tuned in (False, True):
                results[tuned].append(run_child(workload, args.steps, tuned))
        med = {t: {k: statistics.median(r[k] for r in rs) for k in rs[0]} for t, rs in results.items()}
        for tuned in (False, True):
            m = med[tuned]
            label = "jobs' settings" if tuned else "glibc defaults"
            each = ", ".join(f"{r['step_s'] * 1000:.0f}" for r in results[tuned])
            print(f"{workload:8s} {label}: {m['step_s'] * 1000:7.1f} ms a step, {m['faults']:7.0f} page faults, "
                  f"user {m['user_s'] * 1000:6.1f} ms, system {m['sys_s'] * 1000:5.1f} ms (medians: {each} ms)")
        print(f"{workload:8s} ratio of medians: {med[True]['step_s'] / med[False]['step_s']:.3f} a step, "
              f"{(med[True]['user_s'] + med[True]['sys_s']) / (med[False]['user_s'] + med[False]['sys_s']):.3f} CPU")


if __name__ == "__main__":
    main()
