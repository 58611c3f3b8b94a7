"""Shared fixtures: one tiny build of the whole workflow per test session (`built`, or `tiny`: a finished
build named by $REDSUP_TINY_BUILD)."""
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SNAKEMAKE = [sys.executable, "-m", "snakemake", "--snakefile", str(ROOT / "Snakefile"), "--cores", "2"]


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
