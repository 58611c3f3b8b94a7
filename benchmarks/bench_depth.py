"""Speed of the self-supervised depth library on CPU (run by hand, not a test).

    python benchmarks/bench_depth.py                                  # 256x80 and 640x192, widths 16 and 64
    python benchmarks/bench_depth.py --sizes 256x96 --widths 16 32 --batch 4 --repeats 5

Per (input size, base width): the median over repeats of
- a training step: forward of the depth and pose networks, the full monocular loss (prev/next sources,
  4 scales, auto-masking, smoothness), backward and an Adam step, batch ``--batch``; and images/s from it;
- an adaptation step at batch 1 (vanilla SGD on the depth + pose encoders, BatchNorm frozen), as in
  McCraith ch. 4 (the sequential / instance-wise speed ratio follows: 5 vs 50 steps per frame);
- inference (depth network only) at batch 1.
Random inputs and random weights (the speed does not depend on them). ``torch.set_num_threads(--threads)``.
"""
from __future__ import annotations

import argparse
import functools
import statistics
import time

import torch

from redsup.depth import adaptation, networks, pipeline


def _batch(b: int, h: int, w: int) -> dict:
    K = torch.tensor([[0.58 * w, 0.0, (w - 1) / 2], [0.0, 1.92 * h, (h - 1) / 2], [0.0, 0.0, 1.0]])
    return {"target": torch.rand(b, 3, h, w), "K": K.expand(b, 3, 3).clone(),
            "sources": {"prev": torch.rand(b, 3, h, w), "next": torch.rand(b, 3, h, w)}}


def _median_time(fn, repeats: int, warmup: int = 1) -> float:
    for _ in range(warmup):
        fn()
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return statistics.median(times)


def bench(h: int, w: int, width: int, batch: int, repeats: int) -> dict:
    torch.manual_seed(0)
    models = networks.build_models(base_channels=width)
    n_params = sum(p.numel() for p in models.parameters())
    optimizer, _ = pipeline.make_optimizer(models)
    train_batch = _batch(batch, h, w)
    models.train()
    train_s = _median_time(lambda: pipeline.train_step(models, optimizer, train_batch), repeats)

    test_batch = _batch(1, h, w)
    params = adaptation.select_parameters(models, ["depth_encoder", "pose_encoder"])
    loss_fn = functools.partial(pipeline.batch_loss, noise_std=0.0)
    adapt_s = _median_time(lambda: adaptation.adapt(models, loss_fn, test_batch, params, 1e-3, 1), repeats)

    models.eval()

    def infer():
        with torch.no_grad():
            pipeline.predict_depth(models, test_batch["target"])
    infer_s = _median_time(infer, repeats)
    return {"size": f"{w}x{h}", "width": width, "params_M": n_params / 1e6, "batch": batch,
            "train_step_s": train_s, "train_img_per_s": batch / train_s, "adapt_step_s": adapt_s,
            "infer_s": infer_s, "seq5_s": infer_s + 5 * adapt_s, "inst50_s": infer_s + 50 * adapt_s}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sizes", nargs="+", default=["256x80", "640x192"], help="WxH")
    parser.add_argument("--widths", nargs="+", type=int, default=[16, 64], help="ResNet base channels")
    parser.add_argument("--batch", type=int, default=4)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    print(f"torch {torch.__version__}, {args.threads} threads, batch {args.batch}, median of {args.repeats}")
    header = ("size", "width", "params_M", "train_step_s", "train_img_per_s", "adapt_step_s", "infer_s",
              "seq5_s", "inst50_s")
    print(" | ".join(header))
    for size in args.sizes:
        w, h = (int(v) for v in size.lower().split("x"))
        for width in args.widths:
            r = bench(h, w, width, args.batch, args.repeats)
            print(" | ".join(f"{r[k]:.3f}" if isinstance(r[k], float) else str(r[k]) for k in header), flush=True)


if __name__ == "__main__":
    main()
