"""Shared fixtures: one tiny build of the whole workflow per test session; an `mlflow server` for a test."""
import contextlib
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request
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


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def mlflow_server(uri, workdir, cli=None, env=None, timeout=120):
    """`mlflow server` over the store `uri` on a free port of 127.0.0.1 (log: workdir/server.log); yields
    its URL once /health answers, and stops it (with its uvicorn worker) on leaving."""
    workdir = Path(workdir)
    port = free_port()
    log = (workdir / "server.log").open("w")
    proc = subprocess.Popen(
        [*(cli or [sys.executable, "-m", "mlflow"]), "server", "--backend-store-uri", uri, "--host", "127.0.0.1",
         "--port", str(port), "--workers", "1", "--default-artifact-root", str(workdir / "server-artifacts")],
        cwd=workdir, env={**os.environ, **(env or {})}, stdout=log, stderr=subprocess.STDOUT,
        start_new_session=True)  # own process group: the server forks a uvicorn worker
    base = f"http://127.0.0.1:{port}"
    try:
        deadline = time.monotonic() + timeout
        while True:
            if proc.poll() is not None:
                raise AssertionError(f"mlflow server exited:\n{(workdir / 'server.log').read_text()}")
            try:
                with urllib.request.urlopen(f"{base}/health", timeout=2) as resp:
                    if resp.status == 200:
                        break
            except OSError:
                pass
            if time.monotonic() > deadline:
                raise AssertionError(f"mlflow server not up in {timeout} s:\n{(workdir / 'server.log').read_text()}")
            time.sleep(0.5)
        yield base
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGTERM)
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
        log.close()
