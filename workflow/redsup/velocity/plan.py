"""The velocity stage's tables as data (the table contract, redsup.tables.contract; torch-free).

``velocity.configurations`` are the jobs (one child run each); ``velocity.tables.<table id>`` says what a
table shows:

- ``rows: [configuration names]`` with ``layout: errors | ablation`` (the columns: Table II's E_v per bin,
  runtime and E_p; or the ablation's E_v on the test and abnormal clips): one row per configuration, labelled
  with the configuration's ``label``. An MLP configuration is trained once per seed (``velocity.seeds``):
  runs ``<name>``, ``<name>_seed1``, ...; its row is the seed mean with the seed spread. A configuration
  without learning (geometric, constant) has one run and a paired bootstrap over the test vehicles.
- ``counts: [splits]``: the annotated vehicles per distance bin of those clip splits (Table I).
- ``figure: vehicle_statistics | sequences``: the numbers of a figure (Fig. 3 / Fig. 6), written with its
  PNG by ``velocity_figure`` (run ``figure_<table id>``).
"""
from __future__ import annotations

import re
from collections.abc import Mapping, Sequence

SEED = re.compile(r"^(?P<name>.+?)_seed(?P<k>[1-9][0-9]*)$")
LEARNED = ("mlp",)


def configurations(config: Mapping) -> dict[str, dict]:
    return {c["name"]: c for c in config["velocity"]["configurations"]}


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
        serving = [t for t, tc in tables.items() if name in tc.get("rows", ())]
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
    confs = configurations(config)
    out: dict[str, list[tuple[str, str, None]]] = {}
    for t, tc in config["velocity"]["tables"].items():
        if "rows" in tc:
            out[t] = [(confs[n]["label"], run, None) for n in tc["rows"] for run in seed_runs(config, n)]
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
    tables = [t for t, tc in config["velocity"]["tables"].items() if name in tc.get("rows", ())]
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
