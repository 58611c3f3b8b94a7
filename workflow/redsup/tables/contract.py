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

The stage of a table id comes from ``tables.yaml`` (``stage:``), its plan module from ``stage_modules:``, the
config section that configures it from ``stage_config:``. The ids are written in tables.yaml and, as the keys of
their sections, in config.yaml, nowhere else: the schemas check a section's shape, ``check_config_tables`` its
keys.
"""
from __future__ import annotations

import difflib
import importlib
from dataclasses import dataclass, field
from types import ModuleType
from typing import TYPE_CHECKING

from redsup.config import ConfigError
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


def config_sections(registry: dict | None = None) -> dict[str, list[str]]:
    """config.yaml section -> the stages whose tables its ``tables:`` configures (tables.yaml ``stage_config:``)."""
    reg = registry or load_registry()
    mapping = reg.get("stage_config") or {}
    missing = [s for s in reg["stages"] if s not in mapping]
    if missing:
        raise KeyError(f"tables.yaml: stages {missing} have no entry in stage_config")
    out: dict[str, list[str]] = {}
    for stage, section in mapping.items():
        out.setdefault(section, []).append(stage)
    return out


def _nearest(key: str, here: list[str], everywhere: list[str] = ()) -> str:
    """The ids nearest ``key`` (difflib): of its section first, else of any section; else the section's ids."""
    close = (difflib.get_close_matches(key, here, n=3, cutoff=0.6)
             or difflib.get_close_matches(key, list(everywhere), n=3, cutoff=0.6))
    return f"nearest: {', '.join(close)}" if close else f"ids here: {', '.join(here) or 'none'}"


def check_config_tables(config, registry: dict | None = None, where: str = "config.yaml") -> None:
    """Every key of a section's ``tables:`` is a tables.yaml id of a stage that section configures
    (``stage_config:``), and every such id has its key: rule all builds every id's table, and a table without
    its section would fail only in its own table job. Raises ConfigError naming each wrong or missing key with
    the nearest ids (difflib)."""
    reg = registry or load_registry()
    stage_of = {t: e["stage"] for t, e in reg["tables"].items()}
    problems = []
    for section, stages in config_sections(reg).items():
        tables = (config.get(section) or {}).get("tables") or {}
        here = [t for t, s in stage_of.items() if s in stages]
        for key in tables:
            if key not in stage_of:
                problems.append(f"{section}.tables.{key} is not a table id of tables.yaml "
                                f"({_nearest(key, here, stage_of)})")
            elif stage_of[key] not in stages:
                other = reg["stage_config"][stage_of[key]]
                problems.append(f"{section}.tables.{key} is a table of stage {stage_of[key]}, configured under "
                                f"{other}.tables; {section}.tables holds the ids of stage(s) {', '.join(stages)} "
                                f"({_nearest(key, here)})")
        missing = [t for t in here if t not in tables]
        if missing:
            problems.append(f"{section}.tables has no section for {', '.join(missing)} (tables.yaml ids of "
                            f"stage(s) {', '.join(stages)}: rule all builds every table)")
    if problems:
        raise ConfigError(f"{where}: table sections that do not match workflow/redsup/data/tables.yaml:\n"
                          + "\n".join(f"  - {p}" for p in problems))
