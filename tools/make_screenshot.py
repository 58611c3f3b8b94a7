"""The README's MLflow screenshot (docs/mlflow_ui.png) from a finished build, by hand:

    python tools/make_screenshot.py BUILD_DIR [--table mccraith_ch7_table3] [--out docs/mlflow_ui.png]

Copies BUILD_DIR/results/mlflow.db (the build is only read), serves it (`redsup.mlflow_ui`) and has headless Chromium photograph the table's parent run page (its child runs, duration,
description with the tag filter).
"""
from __future__ import annotations

import argparse
import subprocess
import tempfile
from pathlib import Path

from redsup.mlflow_ui import copy_store, find_chromium, mlflow_server

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("build", type=Path)
    parser.add_argument("--table", default="mccraith_ch7_table3")
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "mlflow_ui.png")
    args = parser.parse_args()
    chromium = find_chromium()
    if chromium is None:
        raise SystemExit("no Chromium found (apt-get install chromium, or set $REDSUP_CHROMIUM)")
    from mlflow.tracking import MlflowClient

    with tempfile.TemporaryDirectory(prefix="redsup_shot_") as tmp:
        uri = f"sqlite:///{copy_store(args.build / 'results' / 'mlflow.db', Path(tmp) / 'mlflow.db')}"
        client = MlflowClient(uri)
        exps = [e.experiment_id for e in client.search_experiments()]
        [parent] = client.search_runs(exps, f"tags.`redsup.parent` = '{args.table}' and tags.`redsup.role` = 'parent'")
        with mlflow_server(uri, tmp) as base:
            url = (f"{base}/#/experiments/{parent.info.experiment_id}/runs/{parent.info.run_id}"
                   "?workflowType=machine_learning")  # the "Model training" view, not GenAI
            subprocess.run([chromium, "--headless=new", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                            "--window-size=1400,900", "--virtual-time-budget=20000",
                            f"--screenshot={args.out.resolve()}", url], check=True, timeout=180,
                           stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    print(f"wrote {args.out} ({args.out.stat().st_size // 1024} KB): parent run {args.table} ({parent.info.run_id})")


if __name__ == "__main__":
    main()
