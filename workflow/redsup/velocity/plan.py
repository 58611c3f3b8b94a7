"""The velocity stage's tables as data (the table contract, redsup.tables.contract; torch-free).

``velocity.configurations`` are the jobs (one child run each); ``velocity.tables.<table id>`` says what a
table shows:

- ``rows:`` in the one row grammar of every stage (``redsup.tables.rows``: ``{label, run}``, ``run`` a
  configuration name) with ``layout: errors | ablation`` (the columns: Table II's E_v per bin, runtime and E_p;
  or the ablation's E_v on the test and abnormal clips): one row per configuration. An MLP configuration is trained once per seed (``velocity.seeds``):
  runs ``<name>``, ``<name>_seed1``, ...; its row is the seed mean with the seed spread. A configuration
  without learning (geometric, constant) has one run and a paired bootstrap over the test vehicles.
- ``counts: [splits]``: the annotated vehicles per distance bin of those clip splits (Table I).
- ``figure: vehicle_statistics | sequences``: the numbers of a figure (Fig. 3 / Fig. 6), written with its
  PNG by ``velocity_figure`` (run ``figure_<table id>``).
"""
from __future__ import annotations

import re
from collections.abc import Mapping, Sequence

from redsup.tables.rows import run_rows

SEED = re.compile(r"^(?P<name>.+?)_seed(?P<k>[1-9][0-9]*)$")
LEARNED = ("mlp",)


def configurations(config: Mapping) -> dict[str, dict]:
    return {c["name"]: c for c in config["velocity"]["configurations"]}


def table_rows(config: Mapping, table_id: str) -> list[tuple[str, str]]:
    """(row label, configuration) of a rows table (empty for a counts or figure table)."""
    tc = config["velocity"]["tables"][table_id]
    if "rows" not in tc:
        return []
    return [(label, run) for label, run, _ in run_rows(tc, f"velocity.tables.{table_id}", configurations(config))]


def showing(config: Mapping, name: str) -> list[str]:
    """The tables whose rows show configuration ``name``."""
    return [t for t in config["velocity"]["tables"] if any(run == name for _, run in table_rows(config, t))]


def seed_runs(config: Mapping, name: str) -> list[str]:
    """The runs of one configuration: one per seed for learned methods, one otherwise."""
    c = configurations(config)[name]
    n = int(config["velocity"].get("seeds", 1)) if c["method"] in LEARNED else 1
    return [name] + [f"{name}_seed{k}" for k in range(1, n)]


def parse_run(run: str) -> tuple[str, int]:
    """(configuration name, seed index) of a run name."""
    m = SEED.match(run)
    return (m.group("name"), int(m.group("k"))) if m else (run, 0)


def runs(config: Mapping, scenes_of=None) -> dict[str, dict]:
    """run -> {"configuration", "seed_index", "tables"} for every configuration run, plus the clip counts
    and figure runs the tables read."""
    tables = config["velocity"]["tables"]
    out: dict[str, dict] = {}
    for name, c in configurations(config).items():
        serving = showing(config, name)
        for run in seed_runs(config, name):
            out[run] = {"configuration": name, "seed_index": parse_run(run)[1], "method": c["method"],
                        "tables": serving}
    for t, tc in tables.items():
        if "counts" in tc:
            out["clip_counts"] = {"splits": list(tc["counts"]), "tables": [t]}
        if "figure" in tc:
            out[f"figure_{t}"] = {"figure": tc["figure"], "tables": [t]}
    return out


def rows(config: Mapping, scenes_of=None) -> dict[str, list[tuple[str, str, None]]]:
    out: dict[str, list[tuple[str, str, None]]] = {}
    for t, tc in config["velocity"]["tables"].items():
        if "rows" in tc:
            out[t] = [(label, run, None) for label, n in table_rows(config, t) for run in seed_runs(config, n)]
        elif "counts" in tc:
            out[t] = [(split.capitalize(), "clip_counts", None) for split in tc["counts"]]
        else:
            out[t] = [("table", f"figure_{t}", None)]
    return out


def result_path(run: str) -> str:
    if run == "clip_counts":
        return "results/velocity/clip_counts.json"
    if run.startswith("figure_"):
        return f"results/velocity/figures/{run[len('figure_'):]}.json"
    return f"results/velocity/{run}/metrics.json"


def parent(config: Mapping, name: str) -> str:
    """The MLflow parent of a configuration's runs: the first table that shows it."""
    tables = showing(config, name)
    return tables[0] if tables else next(iter(config["velocity"]["tables"]))


def table_frame(table_id: str, config: Mapping, rows: Sequence[tuple], results: Mapping[str, Mapping]):
    from redsup.tables import noise as noise_lib
    from redsup.tables.contract import TableFrame
    from redsup.velocity import tables as velocity_tables

    tc = config["velocity"]["tables"][table_id]
    if "rows" in tc:
        ours, noise = velocity_tables.configuration_table(tc["layout"], rows, results)
    elif "counts" in tc:  # the rendered clips' own vehicle counts: exact, not estimates
        ours = velocity_tables.counts_table(results["clip_counts"])
        noise = {str(r): {str(c): noise_lib.EXACT for c in ours.columns} for r in ours.index}
    else:
        ours, noise = velocity_tables.figure_table(results[f"figure_{table_id}"]), {}
    return TableFrame(ours, noise, velocity_tables.table_note(config, tc, results))
