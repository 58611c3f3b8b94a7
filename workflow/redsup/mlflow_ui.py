"""Looking at a store through MLflow's own UI: a consistent copy of a sqlite store, `mlflow server` on a free
port of 127.0.0.1, and the headless browser that renders its pages (the UI test, tools/make_screenshot.py)."""
from __future__ import annotations

import contextlib
import os
import shutil
import signal
import socket
import sqlite3
import subprocess
import sys
import time
import urllib.request
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path

BROWSERS = ("chromium", "chromium-browser", "google-chrome", "google-chrome-stable")


def find_chromium() -> str | None:
    """$REDSUP_CHROMIUM, else the first Chromium / Chrome on PATH, else None."""
    for name in (os.environ.get("REDSUP_CHROMIUM"), *BROWSERS):
        path = name and shutil.which(name)
        if path:
            return path
    return None


def copy_store(db: str | Path, dst: str | Path) -> Path:
    """A consistent copy of the sqlite store ``db`` at ``dst`` (sqlite's backup; ``db`` is only read): a server
    may migrate or write to the store it serves."""
    src = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
    out = sqlite3.connect(dst)
    try:
        src.backup(out)
    finally:
        src.close()
        out.close()
    return Path(dst)


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@contextlib.contextmanager
def mlflow_server(uri: str, workdir: str | Path, cli: Sequence[str] | None = None,
                  env: Mapping[str, str] | None = None, timeout: float = 120) -> Iterator[str]:
    """`mlflow server` over the store ``uri`` on a free port of 127.0.0.1 (log: ``workdir/server.log``); yields
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
                raise RuntimeError(f"mlflow server exited:\n{(workdir / 'server.log').read_text()}")
            try:
                with urllib.request.urlopen(f"{base}/health", timeout=2) as resp:
                    if resp.status == 200:
                        break
            except OSError:
                pass
            if time.monotonic() > deadline:
                raise RuntimeError(f"mlflow server not up in {timeout} s:\n{(workdir / 'server.log').read_text()}")
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
