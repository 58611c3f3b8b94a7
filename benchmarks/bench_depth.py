"""Speed of the self-supervised depth library on CPU (run by hand, not a test).

    python benchmarks/bench_depth.py                                  # 208x64 (default profile), width 16
    python benchmarks/bench_depth.py --sizes 208x64 640x192 --widths 16 64 --batch 4 --repeats 5

Per (input size, base width): the median over repeats of
- a training step: forward of the depth and pose networks, the full monocular loss (prev/next sources,
  4 scales, auto-masking, smoothness), backward and an Adam step, batch ``--batch``; and images/s from it;
- an adaptation step at batch 1 (vanilla SGD on the depth + pose encoders, BatchNorm frozen), as in
  McCraith ch. 4 (the sequential / instance-wise speed ratio follows: 5 vs 50 steps per frame);
- inference (depth network only) at batch 1;
- the achieved GFLOP/s of the training step (its FLOPs counted once with ``torch.utils.flop_counter``:
  convolutions and matmuls, forward and backward) beside the measured fp32 sgemm peak of the same threads
  (a 1024x1024 matmul), and their ratio: how well a training step uses the cores;
- the two test-time scenarios of ch. 4 Table 6 end to end on a short synthetic video (``--frames`` frames):
  seconds per frame of instance-wise adaptation (``--instance-steps`` steps, weights reset per frame) and of
  sequential adaptation (``--sequential-steps`` steps, weights carried over), and their ratio.
Random inputs and random weights (the speed does not depend on them). ``torch.set_num_threads(--threads)``.
"""
from __future__ import annotations

import argparse
import functools
import statistics

import numpy as np
import torch

from redsup.depth import adaptation, data, experiments, networks, pipeline
from redsup.optim import Adam
from timing import median_time


def _batch(b: int, h: int, w: int) -> dict:
    K = torch.tensor([[0.58 * w, 0.0, (w - 1) / 2], [0.0, 1.92 * h, (h - 1) / 2], [0.0, 0.0, 1.0]])
    return {"target": torch.rand(b, 3, h, w), "K": K.expand(b, 3, 3).clone(),
            "sources": {"prev": torch.rand(b, 3, h, w), "next": torch.rand(b, 3, h, w)}}


def sgemm_gflops(n: int = 1024, repeats: int = 5) -> float:
    """Measured fp32 matmul throughput (GFLOP/s) at the current thread count: the peak to compare with."""
    a, b = torch.rand(n, n), torch.rand(n, n)
    return 2 * n ** 3 / median_time(lambda: a @ b, repeats, warmup=1) / 1e9


def step_flops(fn) -> int:
    """FLOPs of one call of ``fn`` (convolutions and matmuls, forward and backward)."""
    from torch.utils.flop_counter import FlopCounterMode

    with FlopCounterMode(display=False) as counter:
        fn()
    return counter.get_total_flops()


def bench(h: int, w: int, width: int, batch: int, repeats: int) -> dict:
    torch.manual_seed(0)
    models = networks.build_models(base_channels=width)
    n_params = sum(p.numel() for p in models.parameters())
    optimizer = Adam(models.parameters(), lr=1e-4)   # as redsup.depth.training
    train_batch = _batch(batch, h, w)
    models.train()
    flops = step_flops(lambda: pipeline.train_step(models, optimizer, train_batch))
    train_s = median_time(lambda: pipeline.train_step(models, optimizer, train_batch), repeats)

    test_batch = _batch(1, h, w)
    params = adaptation.select_parameters(models, ["depth_encoder", "pose_encoder"])
    loss_fn = functools.partial(pipeline.batch_loss, noise_std=0.0)
    adapt_s = median_time(lambda: adaptation.adapt(models, loss_fn, test_batch, params, 1e-3, 1), repeats)

    models.eval()

    def infer():
        with torch.no_grad():
            pipeline.predict_depth(models, test_batch["target"])
    infer_s = median_time(infer, repeats)
    return {"size": f"{w}x{h}", "width": width, "params_M": n_params / 1e6, "batch": batch,
            "train_step_s": train_s, "train_img_per_s": batch / train_s, "train_gflop": flops / 1e9,
            "train_gflops": flops / train_s / 1e9, "adapt_step_s": adapt_s,
            "infer_s": infer_s, "seq5_s": infer_s + 5 * adapt_s, "inst50_s": infer_s + 50 * adapt_s}


def bench_scenarios(h: int, w: int, width: int, frames: int, instance_steps: int, sequential_steps: int) -> dict:
    """Seconds per frame of the instance-wise and sequential runners on a synthetic pan (ch. 4 Table 6)."""
    torch.manual_seed(0)
    models = networks.build_models(base_channels=width).eval()
    rng = np.random.default_rng(0)
    base = rng.integers(0, 255, size=(h, w + 4 * frames, 3), dtype=np.uint8)
    images = np.stack([base[:, 4 * i:4 * i + w] for i in range(frames)])
    K = np.array([[0.58 * w, 0.0, (w - 1) / 2], [0.0, 1.92 * h, (h - 1) / 2], [0.0, 0.0, 1.0]])
    seq = experiments.EvalSequence(data.Sequence("bench", images, K), np.full((frames, h, w), 10.0, np.float32))
    meta = {"min_depth": 0.1, "max_depth": 100.0}
    kw = dict(sources=("prev", "next"), groups=("depth_encoder", "pose_encoder"), lr=0.1,
              eval_cfg={"min_depth": 1e-3, "max_depth": 80.0, "crop": "garg"},
              loss_kwargs={"noise_std": 1e-5, "min_depth": 0.1, "max_depth": 100.0}, metric_scale=False)
    inner = [(0, t) for t in range(1, frames - 1)]
    inst, _ = experiments.run_instance(models, meta, [seq], inner, checkpoints=[instance_steps], **kw)
    seq_recs, _ = experiments.run_sequential(models, meta, [seq], steps=sequential_steps, **kw)
    inst_s = statistics.mean(r["seconds"] for r in inst if r["seconds"] is not None)
    seq_s = statistics.mean(r["seconds"] for r in seq_recs if r["seconds"] is not None)
    return {"size": f"{w}x{h}", "width": width, "instance_s_per_frame": inst_s, "sequential_s_per_frame": seq_s,
            "speed_ratio": inst_s / seq_s}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", nargs="+", default=["208x64"], help="WxH (208x64: the default profile)")
    parser.add_argument("--widths", nargs="+", type=int, default=[16], help="ResNet base channels")
    parser.add_argument("--batch", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--frames", type=int, default=6, help="frames of the synthetic video (0: skip)")
    parser.add_argument("--instance-steps", type=int, default=50)
    parser.add_argument("--sequential-steps", type=int, default=5)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    peak = sgemm_gflops()
    print(f"torch {torch.__version__}, {args.threads} threads, batch {args.batch}, median of {args.repeats}; "
          f"fp32 sgemm peak {peak:.1f} GFLOP/s")
    header = ("size", "width", "params_M", "train_step_s", "train_img_per_s", "train_gflop", "train_gflops",
              "of_peak", "adapt_step_s", "infer_s", "seq5_s", "inst50_s")
    print(" | ".join(header))
    for size in args.sizes:
        w, h = (int(v) for v in size.lower().split("x"))
        for width in args.widths:
            r = bench(h, w, width, args.batch, args.repeats)
            r["of_peak"] = r["train_gflops"] / peak
            print(" | ".join(f"{r[k]:.3f}" if isinstance(r[k], float) else str(r[k]) for k in header), flush=True)
    if args.frames >= 3:
        header = ("size", "width", "instance_s_per_frame", "sequential_s_per_frame", "speed_ratio")
        print(f"\nscenarios on {args.frames} frames: instance-wise {args.instance_steps} steps vs sequential "
              f"{args.sequential_steps} steps per frame")
        print(" | ".join(header))
        for size in args.sizes:
            w, h = (int(v) for v in size.lower().split("x"))
            for width in args.widths:
                r = bench_scenarios(h, w, width, args.frames, args.instance_steps, args.sequential_steps)
                print(" | ".join(f"{r[k]:.3f}" if isinstance(r[k], float) else str(r[k]) for k in header),
                      flush=True)


if __name__ == "__main__":
    main()
