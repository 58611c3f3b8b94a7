"""The one table contract: every stage's torch-free ``redsup.<package>.plan`` module provides

``runs(config, scenes_of) -> {run: spec}``
    every job whose result a table row reads (spec: a JSON-able dict the stage's rules use);
``rows(config, scenes_of) -> {table_id: [(row label, run, step)]}``
    the rows of the stage's tables that ``config`` configures (``step``: which checkpoint / step of the run
    the row reads, ``None`` when the run has one result);
``result_path(run) -> str``
    the JSON file the run writes (what ``rule table`` reads);
``table_frame(table_id, config, rows, results) -> TableFrame``
    our table from the rows and ``results`` (run -> parsed JSON). Tables differ only by their config section
    ``<stage>.tables.<table_id>`` (and their rows), never by branching on the id.

The stage of a table id comes from ``tables.yaml`` (``stage:``), its plan module from ``stage_modules:``.
"""
from __future__ import annotations

import importlib
from dataclasses import dataclass, field
from types import ModuleType
from typing import TYPE_CHECKING

from redsup.tables.registry import load_registry, table_info

if TYPE_CHECKING:
    import pandas as pd


@dataclass
class TableFrame:
    """What a stage hands the writer: ``ours`` (rows x metric columns, named as in paper_values.csv),
    ``noise`` ({row: {column: noise record}}, see redsup.tables.noise), a caption ``note`` and claims of its
    own (``extra_claims``, registry form)."""

    ours: pd.DataFrame
    noise: dict = field(default_factory=dict)
    note: str = ""
    extra_claims: list = field(default_factory=list)


def run_id(conf: str, seed: int) -> str:
    """Run id of one configuration trained with seed index ``seed``: ``<conf>/seed<k>``."""
    return f"{conf}/seed{int(seed)}"


def parse_run(run: str) -> tuple[str, int]:
    """``<conf>/seed<k>`` -> (conf, k)."""
    conf, _, seed = run.rpartition("/seed")
    if not conf or not seed.isdigit():
        raise ValueError(f"run id {run!r} is not <configuration>/seed<k>")
    return conf, int(seed)


def training_seed(config, seed: int) -> int:
    """The seed a run trains with: the workflow's ``seed`` plus the run's seed index."""
    return int(config["seed"]) + int(seed)


def plan_module(stage: str, registry: dict | None = None) -> ModuleType:
    reg = registry or load_registry()
    try:
        name = reg["stage_modules"][stage]
    except KeyError:
        raise KeyError(f"tables.yaml: stage {stage!r} has no entry in stage_modules") from None
    return importlib.import_module(name)


def plan_of(table_id: str, registry: dict | None = None) -> ModuleType:
    """The plan module of the stage that builds ``table_id``."""
    reg = registry or load_registry()
    return plan_module(table_info(table_id, reg)["stage"], reg)


def table_ids(kind: str | None = None, registry: dict | None = None) -> list[str]:
    """Ids of tables.yaml (``kind``: 'table' or 'figure'; every figure also has its table)."""
    reg = registry or load_registry()
    return [t for t, e in reg["tables"].items() if kind is None or e.get("kind", "table") == kind]


def all_rows(config, scenes_of, registry: dict | None = None) -> dict[str, list[tuple]]:
    """table id -> rows, over every stage's plan (each plan imported once)."""
    reg = registry or load_registry()
    out: dict[str, list[tuple]] = {}
    for module in dict.fromkeys(reg["stage_modules"].values()):
        for table, rows in importlib.import_module(module).rows(config, scenes_of).items():
            out[table] = [tuple(r) for r in rows]
    return out
