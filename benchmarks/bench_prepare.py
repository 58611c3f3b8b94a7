"""Wall time of the world + data-preparation stage for a size profile (run by hand, not a test).

    python benchmarks/bench_prepare.py --profile tiny --repeats 3
    python benchmarks/bench_prepare.py --profile default

Each repeat builds `world` and `prepare` from scratch in a fresh temporary working directory with the
repository's Snakefile and reports the median wall time.
"""
from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def build_once(profile: str, cores: int, targets: list[str]) -> float:
    with tempfile.TemporaryDirectory(prefix=f"bench_{profile}_") as workdir:
        start = time.perf_counter()
        subprocess.run([sys.executable, "-m", "snakemake", "--snakefile", str(ROOT / "Snakefile"),
                        "--directory", workdir, "--cores", str(cores), *targets,
                        "--config", f"profile={profile}"],  # --config takes every word after it: targets first
                       check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        return time.perf_counter() - start


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--profile", default="tiny", choices=["tiny", "default", "paper"])
    parser.add_argument("--repeats", type=int, default=1)
    parser.add_argument("--cores", type=int, default=2)
    parser.add_argument("--targets", nargs="+", default=["world", "prepare"])
    args = parser.parse_args()
    times = [build_once(args.profile, args.cores, args.targets) for _ in range(args.repeats)]
    print(f"profile={args.profile} targets={' '.join(args.targets)} cores={args.cores} "
          f"repeats={args.repeats} median_wall_s={statistics.median(times):.1f} "
          f"all={[round(t, 1) for t in times]}")


if __name__ == "__main__":
    main()
