"""The README's MLflow screenshot (docs/mlflow_ui.png) from a finished build, by hand:

    python docs/make_screenshot.py BUILD_DIR [--table mccraith_ch7_table3] [--out docs/mlflow_ui.png]

Copies BUILD_DIR/results/mlflow.db (sqlite backup: the build is only read), starts `mlflow server` on a free
port of 127.0.0.1 and has headless Chromium photograph the table's parent run page (its child runs, duration,
description with the tag filter).
"""
from __future__ import annotations

import argparse
import os
import shutil
import signal
import socket
import sqlite3
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("build", type=Path)
    parser.add_argument("--table", default="mccraith_ch7_table3")
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "mlflow_ui.png")
    args = parser.parse_args()
    chromium = next((shutil.which(b) for b in ("chromium", "chromium-browser", "google-chrome") if shutil.which(b)),
                    None)
    if chromium is None:
        raise SystemExit("no Chromium found (apt-get install chromium)")
    from mlflow.tracking import MlflowClient

    with tempfile.TemporaryDirectory(prefix="redsup_shot_") as tmp:
        db = Path(tmp) / "mlflow.db"
        src = sqlite3.connect(f"file:{args.build / 'results' / 'mlflow.db'}?mode=ro", uri=True)
        dst = sqlite3.connect(db)
        src.backup(dst)
        src.close()
        dst.close()
        uri = f"sqlite:///{db}"
        client = MlflowClient(uri)
        exps = [e.experiment_id for e in client.search_experiments()]
        [parent] = client.search_runs(exps, f"tags.`redsup.parent` = '{args.table}' and tags.`redsup.role` = 'parent'")
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        server = subprocess.Popen([sys.executable, "-m", "mlflow", "server", "--backend-store-uri", uri, "--host",
                                   "127.0.0.1", "--port", str(port), "--workers", "1"], cwd=tmp,
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
        try:
            base = f"http://127.0.0.1:{port}"
            deadline = time.monotonic() + 120
            while True:
                try:
                    with urllib.request.urlopen(f"{base}/health", timeout=2):
                        break
                except OSError:
                    if time.monotonic() > deadline or server.poll() is not None:
                        raise SystemExit("mlflow server did not come up") from None
                    time.sleep(0.5)
            url = (f"{base}/#/experiments/{parent.info.experiment_id}/runs/{parent.info.run_id}"
                   "?workflowType=machine_learning")  # the "Model training" view, not GenAI
            subprocess.run([chromium, "--headless=new", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                            "--window-size=1400,900", "--virtual-time-budget=20000",
                            f"--screenshot={args.out.resolve()}", url], check=True, timeout=180,
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        finally:
            os.killpg(server.pid, signal.SIGTERM)
            server.wait(timeout=30)
    print(f"wrote {args.out} ({args.out.stat().st_size // 1024} KB): parent run {args.table} ({parent.info.run_id})")


if __name__ == "__main__":
    main()
