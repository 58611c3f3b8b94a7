"""The one row grammar of every stage's tables (config.yaml ``<section>.tables.<table id>.rows``).

``rows`` is a list; each entry gives one row, or one row per combination of its ``sweep``:

    label     the row label as the thesis prints it; ``{field}`` or ``{field|formatter}`` take a field's value
    run       a run of the stage, by name (a velocity / lifting / detector configuration, a calibration method)
    template  or: the fields of a run the stage plans from them (depth: dataset, mode, groups, lr, steps, ...)
    sweep     optional ``{field: list}``: one row per combination, in order (the last field fastest); each
              swept value is set on the row (in its template, or as a parameter of its run)

Exactly one of ``run`` and ``template``. A string ``$key`` anywhere in a row stands for the table-level value
``key`` of the same table section, so a size profile overrides one list, not the rows. Labels are formatted by
:func:`fill`: without a formatter a float prints as ``%g``, anything else as ``str``; a stage passes its own named
formatters (depth: ``modules``, ``power``, ``initial``, ``name``). Table-level keys other than ``rows`` (notes,
layouts, figure kinds, the values that ``$key`` names) are each stage's own.
"""
from __future__ import annotations

import itertools
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field

ROW_KEYS = ("label", "run", "template", "sweep")
_FIELD = re.compile(r"\{(\w+)(?:\|(\w+))?\}")


@dataclass(frozen=True)
class TableRow:
    """One expanded row: its label (not yet formatted), its run name (run rows) and its fields: the template
    with the swept values (template rows) or the swept values alone (run rows)."""

    label: str
    run: str | None
    fields: dict = field(default_factory=dict)


def default_format(value) -> str:
    return f"{value:g}" if isinstance(value, float) else str(value)


def fill(text: str, values: Mapping, formatters: Mapping[str, Callable] | None = None) -> str:
    """``text`` with each ``{field}`` / ``{field|formatter}`` replaced by the formatted value of that field."""
    fmt = dict(formatters or {})

    def one(m):
        name, how = m.group(1), m.group(2)
        if name not in values:
            raise KeyError(f"row label {text!r}: unknown field {name!r} (known: {sorted(values)})")
        if how is None:
            return default_format(values[name])
        if how not in fmt:
            raise KeyError(f"row label {text!r}: unknown formatter {how!r} (known: {sorted(fmt)})")
        return fmt[how](values[name])
    return _FIELD.sub(one, str(text))


def _ref(value, table_cfg: Mapping, where: str):
    if isinstance(value, str) and value.startswith("$"):
        key = value[1:]
        if key not in table_cfg or key == "rows":
            raise KeyError(f"{where}: {value} names no value of the table section (its keys: "
                           f"{sorted(k for k in table_cfg if k != 'rows')})")
        return table_cfg[key]
    if isinstance(value, list):
        return [_ref(v, table_cfg, where) for v in value]
    return value


def expand(table_cfg: Mapping, where: str, template_fields: Sequence[str] | None = None) -> list[TableRow]:
    """Every row of one table section, sweeps expanded and ``$key`` resolved, labels left unformatted.

    ``where`` names the section in errors (``depth.tables.<id>``); ``template_fields``, when given, are the
    fields a template (and a sweep) may set."""
    out = []
    for i, row in enumerate(table_cfg.get("rows") or ()):
        at = f"{where}.rows[{i}]"
        if not isinstance(row, Mapping):
            raise KeyError(f"{at}: a row is a mapping with keys {list(ROW_KEYS)}, got {row!r}")
        unknown = sorted(set(row) - set(ROW_KEYS))
        if unknown:
            raise KeyError(f"{at}: unknown key(s) {unknown} (a row has {list(ROW_KEYS)})")
        if ("run" in row) == ("template" in row):
            raise KeyError(f"{at}: give exactly one of run and template")
        if "label" not in row:
            raise KeyError(f"{at}: no label")
        template = {k: _ref(v, table_cfg, at) for k, v in (row.get("template") or {}).items()}
        sweep = {k: list(_ref(v, table_cfg, at)) for k, v in (row.get("sweep") or {}).items()}
        if template_fields is not None:
            bad = sorted((set(template) | set(sweep)) - set(template_fields))
            if bad:
                raise KeyError(f"{at}: unknown field(s) {bad} (known: {list(template_fields)})")
        run = _ref(row["run"], table_cfg, at) if "run" in row else None
        for combo in itertools.product(*sweep.values()) if sweep else [()]:
            out.append(TableRow(str(row["label"]), run, {**template, **dict(zip(sweep, combo))}))
    return out


def run_rows(table_cfg: Mapping, where: str, known_runs=None) -> list[tuple[str, str, dict]]:
    """(formatted label, run, swept fields) of a table whose rows all name runs; ``known_runs`` (when given)
    are the names a row may name (a ValueError lists every other one)."""
    rows = expand(table_cfg, where)
    if any(r.run is None for r in rows):
        raise KeyError(f"{where}: rows of this stage name a run (run: <name>), not a template")
    unknown = sorted({r.run for r in rows} - set(known_runs)) if known_runs is not None else []
    if unknown:
        raise ValueError(f"config.yaml {where}.rows: unknown configurations {unknown} (defined: {sorted(known_runs)})")
    return [(fill(r.label, r.fields), r.run, r.fields) for r in rows]


def swept_fields(table_cfg: Mapping) -> list[str]:
    """The fields the rows of a table sweep, in order of first appearance."""
    return list(dict.fromkeys(k for row in table_cfg.get("rows") or () for k in (row.get("sweep") or {})))


__all__ = ["ROW_KEYS", "TableRow", "default_format", "fill", "expand", "run_rows", "swept_fields"]
