"""Shared fixtures: one tiny build of the whole workflow per test session (`built`, or `tiny`: a finished
build named by $REDSUP_TINY_BUILD), and the real data samples (`realdata`: $REDSUP_REALDATA, else
../shared/realdata beside the repository; the tests that read them skip where they are absent)."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SNAKEMAKE = [sys.executable, "-m", "snakemake", "--snakefile", str(ROOT / "Snakefile"), "--cores", "2"]

# The real data samples (third-party, never copied into the repository): the folder and what it must hold,
# as its README lists them.
REALDATA_ENV = "REDSUP_REALDATA"
REALDATA_SAMPLES = ("kitti_object/training", "kitti_raw/2011_09_26", "tusimple_velocity/train")


def realdata_root() -> Path:
    """Where the real data samples are: $REDSUP_REALDATA, else ../shared/realdata beside the repository."""
    return Path(os.environ.get(REALDATA_ENV) or ROOT.parent / "shared" / "realdata")


def run_snakemake(workdir, *args, check=True, profile="tiny"):
    """Run the repository's workflow in `workdir` (targets and flags in `args`)."""
    proc = subprocess.run([*SNAKEMAKE, "--directory", str(workdir), *args, "--config", f"profile={profile}"],
                          capture_output=True, text=True, timeout=1800)
    if check and proc.returncode != 0:
        raise AssertionError(f"snakemake {' '.join(args)} failed:\n{proc.stdout[-4000:]}\n{proc.stderr[-8000:]}")
    return proc


@pytest.fixture(scope="session")
def built(tmp_path_factory):
    """A working directory in which `snakemake all` has run under the tiny profile."""
    workdir = tmp_path_factory.mktemp("tiny")
    run_snakemake(workdir, "all")
    return workdir



@pytest.fixture(scope="module")
def tiny(request):
    """The session's tiny build, or a finished one named by $REDSUP_TINY_BUILD (read only)."""
    path = os.environ.get("REDSUP_TINY_BUILD")
    return Path(path) if path else request.getfixturevalue("built")


@pytest.fixture(scope="session")
def realdata() -> Path:
    """The folder of the real data samples (`realdata_root`); the test is skipped, saying where it looked, when
    the folder or one of its samples (REALDATA_SAMPLES) is absent."""
    root = realdata_root()
    if not root.is_dir():
        pytest.skip(f"real data samples not found at {root} (set ${REALDATA_ENV} to their folder)")
    missing = [s for s in REALDATA_SAMPLES if not (root / s).is_dir()]
    if missing:
        pytest.skip(f"real data samples incomplete at {root}: no {', '.join(missing)} "
                    f"(set ${REALDATA_ENV} to a complete copy)")
    return root


_COVERAGE_ROWS: list = []


@pytest.fixture(scope="session")
def coverage_report():
    """Rows of measured interval coverage (tests/test_coverage.py), printed at the end of the run."""
    return _COVERAGE_ROWS


def pytest_terminal_summary(terminalreporter):
    if _COVERAGE_ROWS:
        from redsup.tables.coverage import markdown
        from tests.test_coverage import SIMS

        terminalreporter.write_sep("-", "coverage of the tables' 95 % intervals (simulated, redsup.tables.coverage)")
        terminalreporter.write_line(markdown(_COVERAGE_ROWS, SIMS))
