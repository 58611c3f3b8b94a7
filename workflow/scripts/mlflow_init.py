"""Snakemake entry point: create the MLflow store, one experiment per stage and the parent runs.

Runs once before every other job (parallel jobs racing on a fresh sqlite store fail during schema
creation). The plan comes from redsup/data/tables.yaml plus the `world` and `data_preparation` parents.
"""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821

import json  # noqa: E402

from redsup.tables import mlflow_plan  # noqa: E402
from redsup.tracking import init_store, resolve_tracking_uri  # noqa: E402

sm = snakemake  # noqa: F821
settings = sm.config["mlflow"]
registry = init_store(
    resolve_tracking_uri(settings["tracking_uri"]),
    mlflow_plan(),
    sm.output[0],
    artifact_root=settings["artifact_root"],
    experiment_prefix=settings["experiment_prefix"],
)
print(json.dumps(registry, indent=2, sort_keys=True))
