"""The MLflow sync keeps the build's output clean: with a tracking server MLflow prints a "View run" / "View
experiment" pair for every run it ends and a progress bar for every file a logged model copies, and its
``import mlflow.pytorch`` put a handler on the root logger, so that every line of the Snakemake process (whose
sync imports it) was printed twice, once more as ``INFO:snakemake.logging:...``."""
from __future__ import annotations

import json
import logging
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

pytest.importorskip("mlflow")
pytest.importorskip("torch")

from redsup import tracking  # noqa: E402
from redsup.mlflow_model import root_logging_kept  # noqa: E402
from redsup.mlflow_ui import mlflow_server  # noqa: E402
from test_tracking_models import PLAN, _train_and_record  # noqa: E402

WORKFLOW_DIR = str(Path(tracking.__file__).resolve().parents[1])

# the Snakemake process in small: its logger has its own handler (and propagates); a sync runs; a line is logged
SYNC = textwrap.dedent("""
    import json, logging, sys
    from redsup import tracking

    log = logging.getLogger("snakemake.logging")
    log.setLevel(logging.INFO)
    log.addHandler(logging.StreamHandler(sys.stdout))
    out = tracking.sync_records(sys.argv[1], json.loads(sys.argv[2]), "results/runs", "results/mlflow/registry.json")
    log.info("a snakemake line after the sync")
    print(json.dumps({"imported": out["imported"], "root_handlers": len(logging.getLogger().handlers)}))
""")


def test_a_sync_to_a_tracking_server_prints_no_run_links_bars_or_second_log_lines(tmp_path):
    _train_and_record(tmp_path / "results" / "runs", tmp_path / "results")   # a run with an artifact and a model
    env = {k: v for k, v in os.environ.items() if k not in tracking.QUIET_MLFLOW_ENV}   # MLflow's defaults
    env.update(MLFLOW_DISABLE_TELEMETRY="true", PYTHONPATH=os.pathsep.join([WORKFLOW_DIR, env.get("PYTHONPATH", "")]))
    server_dir = tmp_path / "server"
    server_dir.mkdir()
    with mlflow_server(f"sqlite:///{server_dir / 'mlflow.db'}", server_dir, env={"MLFLOW_DISABLE_TELEMETRY": "true"}) \
            as url:
        proc = subprocess.run([sys.executable, "-c", SYNC, url, json.dumps(PLAN)], cwd=tmp_path, env=env,
                              capture_output=True, text=True, timeout=600)
        from mlflow.tracking import MlflowClient

        models = MlflowClient(url).search_logged_models(
            [e.experiment_id for e in MlflowClient(url).search_experiments()])
    output = proc.stdout + proc.stderr
    assert proc.returncode == 0, output
    result = json.loads(proc.stdout.strip().splitlines()[-1])
    assert result["imported"] == 1 and len(models) == 1      # the run ended and its model was uploaded
    assert "View run" not in output and "View experiment" not in output, output
    assert "Downloading artifacts" not in output and "Uploading artifacts" not in output and "it/s]" not in output
    assert output.count("a snakemake line after the sync") == 1, output
    assert "INFO:snakemake.logging" not in output and result["root_handlers"] == 0


def test_quiet_mlflow_leaves_the_users_own_setting():
    environ = {"MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR": "true"}
    assert tracking.quiet_mlflow(environ) == {"MLFLOW_SUPPRESS_PRINTING_URL_TO_STDOUT": "true",
                                              "MLFLOW_ENABLE_ARTIFACTS_PROGRESS_BAR": "true"}


def test_root_logging_kept_undoes_what_basic_config_does():
    root = logging.getLogger()
    before, level = list(root.handlers), root.level
    with root_logging_kept():
        root.addHandler(logging.StreamHandler())          # what logging.basicConfig(level=ERROR) does to a bare root
        root.setLevel(logging.ERROR if level != logging.ERROR else logging.INFO)
    assert root.handlers == before and root.level == level
