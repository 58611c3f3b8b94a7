"""The table registry (data/tables.yaml) and the thesis' numbers (data/paper_values.csv).

Row and column labels are matched leniently: case and whitespace are ignored, numeric labels match by
value ("0.1" == "10^-1" == "1e-1"), and the usual depth-metric spellings are aliases
("abs_rel" == "Abs Rel", "a1" == "δ < 1.25", "delta < 1.25^2" == "δ < 1.25^2").
"""
from __future__ import annotations

import functools
import math
import re
from pathlib import Path
from typing import TYPE_CHECKING

from redsup.fileio import yaml_load

if TYPE_CHECKING:  # pandas is imported where it is used: the stage plans read this module in every job
    import pandas as pd

DATA_DIR = Path(__file__).resolve().parents[1] / "data"
REGISTRY_YAML = DATA_DIR / "tables.yaml"
PAPER_VALUES_CSV = DATA_DIR / "paper_values.csv"
PAPER_COLUMNS = ["table_id", "row", "column", "value", "unit", "lower_is_better", "note"]
CHECK_TYPES = ("order", "best", "close", "range")


# ------------------------------------------------------------------------------------- loading
@functools.lru_cache(maxsize=4)
def _load_registry(path: str) -> dict:
    reg = yaml_load(Path(path).read_text())
    for table_id, entry in reg["tables"].items():
        entry.setdefault("claims", [])
        entry.setdefault("headline_metric", None)
        entry["id"] = table_id
    return reg


def load_registry(path: str | Path | None = None) -> dict:
    """tables.yaml as a dict: ``documents``, ``stages`` and ``tables`` (id -> entry, in file order).

    Cached; treat the result as read-only.
    """
    return _load_registry(str(path or REGISTRY_YAML))


def table_ids(path: str | Path | None = None) -> list[str]:
    return list(load_registry(path)["tables"])


def table_info(table_id: str, registry: dict | None = None) -> dict:
    reg = registry or load_registry()
    try:
        return reg["tables"][table_id]
    except KeyError:
        raise KeyError(f"unknown table id {table_id!r} (see {REGISTRY_YAML})") from None


@functools.lru_cache(maxsize=4)
def _load_paper_values(path: str) -> pd.DataFrame:
    import pandas as pd

    df = pd.read_csv(path, dtype=str, keep_default_na=False)
    if list(df.columns) != PAPER_COLUMNS:
        raise ValueError(f"{path}: columns must be {PAPER_COLUMNS}, got {list(df.columns)}")
    df = df.rename(columns={"value": "value_text"})
    df["value"] = pd.to_numeric(df["value_text"].replace("", math.nan), errors="raise")
    df["lower_is_better"] = df["lower_is_better"].astype(int)
    return df[["table_id", "row", "column", "value", "value_text", "unit", "lower_is_better", "note"]]


def paper_values(table_id: str | None = None, path: str | Path | None = None) -> pd.DataFrame:
    """Long-form paper values (one cell per line, document order): table_id, row, column, value (float,
    NaN where the document prints a dash), value_text (as printed), unit, lower_is_better (0/1), note."""
    df = _load_paper_values(str(path or PAPER_VALUES_CSV))
    if table_id is not None:
        df = df[df["table_id"] == table_id]
    return df.reset_index(drop=True).copy()


def paper_table(table_id: str, text: bool = False) -> pd.DataFrame:
    """The paper's table in wide form: index = rows, columns = metrics, both in document order.

    ``text=True`` gives the values as printed (strings, "" where missing) instead of floats.
    """
    long = paper_values(table_id)
    rows = list(dict.fromkeys(long["row"]))
    cols = list(dict.fromkeys(long["column"]))
    wide = long.pivot(index="row", columns="column", values="value_text" if text else "value")
    wide = wide.reindex(index=rows, columns=cols)
    wide.index.name = "row"
    wide.columns.name = None
    return wide.fillna("") if text else wide.astype(float)


def paper_directions(table_id: str) -> dict[str, bool]:
    """column -> lower_is_better for one table."""
    long = paper_values(table_id)
    return {c: bool(v) for c, v in zip(long["column"], long["lower_is_better"])}


# ------------------------------------------------------------------------------------- matching
_COLUMN_ALIASES = {
    "absrel": "absrel", "abs_rel": "absrel", "sqrel": "sqrel", "sq_rel": "sqrel",
    "rmse": "rmse", "rmselog": "rmselog", "rmse_log": "rmselog",
    "a1": "δ<1.25", "a2": "δ<1.25^2", "a3": "δ<1.25^3", "δ<1.25^1": "δ<1.25",
}


def _number(label: str) -> float | None:
    s = label.replace("{", "").replace("}", "").replace("$", "").replace(" ", "")
    m = re.fullmatch(r"10\^(-?\d+)", s)
    if m:
        return 10.0 ** int(m.group(1))
    try:
        return float(s)
    except ValueError:
        return None


def row_key(label) -> str:
    """Normalised row label: numbers by value, text lower-cased without whitespace."""
    if isinstance(label, (int, float)) and not isinstance(label, bool):
        return f"#{float(label):.12g}"
    s = str(label).strip()
    num = _number(s)
    if num is not None and math.isfinite(num):
        return f"#{num:.12g}"
    return re.sub(r"\s+", "", s).lower()


def column_key(label) -> str:
    s = re.sub(r"[\s$]+", "", str(label)).lower()
    s = s.replace("\\delta", "δ").replace("delta", "δ").replace("²", "^2").replace("³", "^3")
    s = s.replace("^{", "^").replace("}", "")
    return _COLUMN_ALIASES.get(s, s)


def as_frame(ours) -> pd.DataFrame:
    """Our results as a wide DataFrame indexed by row label.

    Accepts a DataFrame indexed by row label, or one with a ``row`` column, or one whose first column
    holds text labels; a dict of dicts {row: {column: value}} works too.
    """
    import pandas as pd

    if isinstance(ours, dict):
        ours = pd.DataFrame.from_dict(ours, orient="index")
    df = ours.copy()
    if isinstance(df.index, pd.RangeIndex) or df.index.name is None and list(df.index) == list(range(len(df))):
        if "row" in df.columns:
            df = df.set_index("row")
        elif len(df.columns) and not pd.api.types.is_numeric_dtype(df[df.columns[0]]):
            df = df.set_index(df.columns[0])
    name = df.index.name
    df.index = [str(i) for i in df.index]
    df.index.name = name if name not in (None, "index") else "row"
    df.columns = [str(c) for c in df.columns]
    return df


def align(ours: pd.DataFrame, paper: pd.DataFrame) -> pd.DataFrame:
    """``ours`` with each row / column label that matches a paper label (by key) renamed to it."""
    rows = {row_key(r): r for r in paper.index}
    cols = {column_key(c): c for c in paper.columns}
    out = ours.copy()
    out.index = [rows.get(row_key(r), r) for r in out.index]
    out.index.name = ours.index.name or "row"
    out.columns = [cols.get(column_key(c), c) for c in out.columns]
    return out


def numeric(df: pd.DataFrame) -> pd.DataFrame:
    """Every column coerced to float (text cells become NaN)."""
    import pandas as pd

    return df.apply(pd.to_numeric, errors="coerce").astype(float)
