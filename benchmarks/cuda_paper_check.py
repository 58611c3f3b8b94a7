"""The device check of a size profile's trainings (a GPU smoke test, not a speed benchmark): a command-line
wrapper over `redsup.device_check`, whose docstring says what it runs and reports. Needs neither Snakemake nor
MLflow.

    python3 benchmarks/cuda_paper_check.py --profile paper --device cuda --steps 20 --out out/
    python benchmarks/cuda_paper_check.py --profile tiny --device cpu --steps 2 --out /tmp/check
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "workflow"))

from redsup.device_check import main  # noqa: E402

if __name__ == "__main__":
    main()
