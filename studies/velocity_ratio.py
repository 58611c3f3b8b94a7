"""MLP-tracker E_v against the constant predictor's in a finished build: the ratio and its paired,
bin-stratified bootstrap over the vehicles (`redsup.velocity.compare`).

    python studies/velocity_ratio.py results/velocity [--split test val] [--a mlp_tracker] [--b constant]
        [--clips FIRST STOP]      # only the vehicles of clips FIRST <= clip < STOP
        [--b-dir OTHER/velocity]  # the reference from another build (a variant against the baseline, paired)
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "workflow"))

from redsup.studies import write_study  # noqa: E402
from redsup.velocity.compare import in_clips, per_vehicle_errors, ratio_bootstrap  # noqa: E402


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("velocity_dir", help="a build's results/velocity")
    ap.add_argument("--split", nargs="+", default=["test", "val"])
    ap.add_argument("--a", default="mlp_tracker", help="the configuration of the method (numerator)")
    ap.add_argument("--b", default="constant", help="the configuration of the reference (denominator)")
    ap.add_argument("--b-dir", help="the reference's results/velocity when it comes from another build "
                                    "(default: velocity_dir); the vehicles are paired by clip and track id")
    ap.add_argument("--n", type=int, default=2000, help="bootstrap replicates")
    ap.add_argument("--clips", nargs=2, type=int, metavar=("FIRST", "STOP"),
                    help="only the vehicles of clips FIRST <= clip < STOP (e.g. the clips an enlarged split gained)")
    ap.add_argument("--name", default="velocity_ratio", help="stored as results/studies/<name>.json")
    args = ap.parse_args(argv)
    ratios = {}
    for split in args.split:
        try:
            a = per_vehicle_errors(args.velocity_dir, args.a, split)
            b = per_vehicle_errors(args.b_dir or args.velocity_dir, args.b, split)
        except FileNotFoundError as exc:
            print(f"{split}: {exc}")
            continue
        if args.clips:
            a, b = (in_clips(e, *args.clips) for e in (a, b))
        ids = sorted(set(a) & set(b))
        if not ids:
            print(f"{split}: no vehicle in clips {args.clips}")
            continue
        r = ratio_bootstrap([a[i][1] for i in ids], [b[i][1] for i in ids], [a[i][0] for i in ids], n=args.n)
        print(f"{split}: {r['n']} vehicles, E_v {args.a} {r['ev_a']:.3f} / {args.b} {r['ev_b']:.3f} = "
              f"{r['ratio']:.3f} (95 % [{r['ratio_lo']:.3f}, {r['ratio_hi']:.3f}]); "
              f"{args.b} - {args.a} {r['diff']:.3f} [{r['diff_lo']:.3f}, {r['diff_hi']:.3f}]")
        ratios[split] = r
    write_study(args.name, {"args": vars(args), "ratios": ratios})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
