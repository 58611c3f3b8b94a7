"""The data stage's table (the table contract, redsup.tables.contract; torch-free): the prepared-data summary.

One run, ``data_summary``: ``rule data_summary`` writes one line per prepared dataset to
``results/data/summary.json``; the table has no paper values.
"""
from __future__ import annotations

from collections.abc import Mapping, Sequence

def runs(config: Mapping, scenes_of) -> dict[str, dict]:
    return {"summary": {"datasets": list(config["datasets"])}}


def rows(config: Mapping, scenes_of) -> dict[str, list[tuple[str, str, None]]]:
    """Each table of ``prepare.tables``: one row per dataset with scenes, all from the one summary run."""
    datasets = [d for d in config["datasets"] if scenes_of(d)]
    return {t: [(d, "summary", None) for d in datasets] for t in config["prepare"].get("tables", {})}


def result_path(run: str) -> str:
    return f"results/data/{run}.json"


def table_frame(table_id: str, config: Mapping, rows: Sequence[tuple], results: Mapping[str, Mapping]):
    import pandas as pd

    from redsup.tables.contract import TableFrame

    lines = {line["dataset"]: line for run in dict.fromkeys(r[1] for r in rows) for line in results[run]["rows"]}
    ours = pd.DataFrame([lines[label] for label, _, _ in rows if label in lines])
    note = f"Profile {config.get('profile')}; one line per configured dataset with prepared scenes"
    return TableFrame(ours, {}, note)
