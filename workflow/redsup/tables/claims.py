"""Kendall's tau of our row ordering vs the paper's, and the thesis' claims checked on a table.

Check types (see data/tables.yaml): order, best, close, range. A claim holds when all its checks hold,
fails when one fails, and is n/a (None) otherwise (a cell it needs is missing or it has no check).
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import pandas as pd

from redsup.tables.registry import (CHECK_TYPES, align, as_frame, column_key, load_registry, numeric,
                                    paper_directions, paper_table, row_key, table_info)


# ------------------------------------------------------------------------------------ Kendall tau
def kendall_tau(ours: Sequence[float], paper: Sequence[float]) -> float:
    """Kendall's tau-b between two equally long value lists (ties handled); NaN if undefined (n < 2 or
    one side constant). Only the ordering matters, so raw metric values can be passed."""
    x = [float(v) for v in ours]
    y = [float(v) for v in paper]
    if len(x) != len(y):
        raise ValueError(f"kendall_tau: lengths differ ({len(x)} vs {len(y)})")
    if len(x) < 2:
        return math.nan
    return _tau_b(x, y)  # tables are small: O(n^2) pure Python beats importing scipy per job


def _tau_b(x: list[float], y: list[float]) -> float:
    concordant = discordant = ties_x = ties_y = 0
    for i in range(len(x)):
        for j in range(i + 1, len(x)):
            dx, dy = x[i] - x[j], y[i] - y[j]
            if dx == 0 and dy == 0:
                continue
            if dx == 0:
                ties_x += 1
            elif dy == 0:
                ties_y += 1
            elif (dx > 0) == (dy > 0):
                concordant += 1
            else:
                discordant += 1
    denom = math.sqrt((concordant + discordant + ties_x) * (concordant + discordant + ties_y))
    return (concordant - discordant) / denom if denom else math.nan


def headline_tau(ours: pd.DataFrame, paper: pd.DataFrame, metric: str | None) -> dict:
    """tau over the rows that have the headline metric in both tables (ours already aligned)."""
    if not metric or metric not in paper.columns or metric not in ours.columns:
        return {"kendall_tau": None, "n_rows": 0, "rows": [], "metric": metric}
    o = numeric(ours)[metric]
    p = paper[metric]
    rows = [r for r in paper.index if r in o.index and pd.notna(o[r]) and pd.notna(p[r])]
    tau = kendall_tau([o[r] for r in rows], [p[r] for r in rows]) if len(rows) >= 2 else math.nan
    return {"kendall_tau": None if math.isnan(tau) else round(tau, 4), "n_rows": len(rows),
            "rows": rows, "metric": metric}


# ------------------------------------------------------------------------------------------ claims
def _fmt(v: float) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "—"
    return f"{v:.4g}"


class _Cells:
    """Numeric lookup in one table with lenient row / column matching."""

    def __init__(self, table: pd.DataFrame, directions: Mapping[str, bool]):
        self.table = numeric(table)
        self.rows = {row_key(r): r for r in self.table.index}
        self.cols = {column_key(c): c for c in self.table.columns}
        self.directions = {column_key(c): v for c, v in directions.items()}

    def get(self, row, metric) -> float | None:
        r, c = self.rows.get(row_key(row)), self.cols.get(column_key(metric))
        if r is None or c is None:
            return None
        v = self.table.at[r, c]
        return None if pd.isna(v) else float(v)

    def lower_is_better(self, metric: str, check: Mapping) -> bool:
        if "direction" in check:
            return check["direction"] == "lower"
        key = column_key(metric)
        if key in self.directions:
            return self.directions[key]
        # metric we add beside a paper one, e.g. "Abs Rel (last quarter)" -> direction of "Abs Rel"
        for k, v in sorted(self.directions.items(), key=lambda kv: -len(kv[0])):
            if key.startswith(k):
                return v
        raise ValueError(f"no direction for metric {metric!r}: give `direction: lower|higher` in the check")

    def column_rows(self, metric) -> list[str]:
        c = self.cols.get(column_key(metric))
        if c is None:
            return []
        return [r for r in self.table.index if pd.notna(self.table.at[r, c])]


def _side(spec, metric) -> tuple[str, str]:
    if isinstance(spec, Mapping):
        return spec["row"], spec.get("metric", metric)
    return spec, metric


def _metrics(check: Mapping, headline: str | None) -> list[str | None]:
    m = check.get("metric", headline)
    sides = [check.get("better"), check.get("worse")]
    if m is None and all(isinstance(x, Mapping) and "metric" in x for x in sides):
        return [None]  # an order check between two explicit cells
    if m is None:
        raise ValueError(f"check {dict(check)} has no metric and the table no headline metric")
    return list(m) if isinstance(m, (list, tuple)) else [m]


def evaluate_check(check: Mapping, cells: _Cells, headline: str | None) -> tuple[bool | None, str]:
    """(holds, evidence) of one check on one table."""
    kind = check.get("type")
    if kind not in CHECK_TYPES:
        raise ValueError(f"unknown check type {kind!r} (known: {CHECK_TYPES})")
    results: list[tuple[bool | None, str]] = []
    for metric in _metrics(check, headline):
        if kind == "order":
            (br, bm), (wr, wm) = _side(check["better"], metric), _side(check["worse"], metric)
            b, w = cells.get(br, bm), cells.get(wr, wm)
            lower = cells.lower_is_better(bm, check)
            cellwise = bm != metric or wm != metric
            label = f"{br} [{bm}]" if cellwise else br
            wlabel = f"{wr} [{wm}]" if cellwise else wr
            prefix = "" if metric is None else f"{metric}: "
            if b is None or w is None:
                missing = [x for x, v in ((label, b), (wlabel, w)) if v is None]
                results.append((None, f"{prefix}missing {', '.join(missing)}"))
                continue
            ok = b < w if lower else b > w
            rel = ("<" if b < w else ">" if b > w else "=")
            how = (f"expected {'lower' if lower else 'higher'}" if "direction" in check
                   else f"{'lower' if lower else 'higher'} is better")
            results.append((ok, f"{prefix}{label} {_fmt(b)} {rel} {wlabel} {_fmt(w)} ({how})"))
        elif kind == "best":
            row, worst = check["row"], bool(check.get("worst", False))
            lower = cells.lower_is_better(metric, check) != worst  # the "winning" direction
            among = check.get("among")
            pool = cells.column_rows(metric)
            if among is not None:
                keys = {row_key(a) for a in among} | {row_key(row)}
                pool = [r for r in pool if row_key(r) in keys]
            v = cells.get(row, metric)
            if v is None:
                results.append((None, f"{metric}: missing {row}"))
                continue
            if len(pool) < 2:
                results.append((None, f"{metric}: fewer than two rows to compare"))
                continue
            vals = {r: cells.get(r, metric) for r in pool}
            winner = min(vals, key=vals.get) if lower else max(vals, key=vals.get)
            ok = vals[winner] == v
            word = "worst" if worst else "best"
            ev = f"{metric}: {row} {_fmt(v)}; {word} of {len(pool)} rows"
            ev += "" if ok else f" is {winner} {_fmt(vals[winner])}"
            if ok:
                others = sorted((x for r, x in vals.items() if row_key(r) != row_key(row)),
                                reverse=not lower)
                ev += f" (next {_fmt(others[0])})" if others else ""
            results.append((ok, ev))
        elif kind == "close":
            a, b = cells.get(check["a"], metric), cells.get(check["b"], metric)
            if a is None or b is None:
                missing = [x for x, v in ((check["a"], a), (check["b"], b)) if v is None]
                results.append((None, f"{metric}: missing {', '.join(missing)}"))
                continue
            tol = float(check["tol"]) * (abs(b) if check.get("relative") else 1.0)
            ok = abs(a - b) <= tol + 1e-12
            results.append((ok, f"{metric}: |{check['a']} {_fmt(a)} − {check['b']} {_fmt(b)}| = "
                                f"{_fmt(abs(a - b))} {'≤' if ok else '>'} {_fmt(tol)}"))
        elif kind == "range":
            v = cells.get(check["row"], metric)
            if v is None:
                results.append((None, f"{metric}: missing {check['row']}"))
                continue
            lo, hi = check.get("min", -math.inf), check.get("max", math.inf)
            ok = lo <= v <= hi
            bounds = " and ".join(x for x in [f"≥ {lo}" if "min" in check else "",
                                               f"≤ {hi}" if "max" in check else ""] if x)
            results.append((ok, f"{metric}: {check['row']} {_fmt(v)} {'within' if ok else 'not'} {bounds}"))
    return _combine(results)


def _combine(results: list[tuple[bool | None, str]]) -> tuple[bool | None, str]:
    holds = [h for h, _ in results]
    if any(h is False for h in holds):
        verdict = False
    elif holds and all(h is True for h in holds):
        verdict = True
    else:
        verdict = None
    return verdict, "; ".join(e for _, e in results)


def _evaluate(claims, table: pd.DataFrame, directions, headline) -> list[dict]:
    cells = _Cells(table, directions)
    out = []
    for claim in claims:
        if "check" not in claim and "holds" in claim:  # pre-evaluated extra claim
            out.append({"text": claim["text"], "holds": claim["holds"],
                        "evidence": claim.get("evidence", ""), "note": claim.get("note", "")})
            continue
        check = claim.get("check")
        if not check:
            out.append({"text": claim["text"], "holds": None, "evidence": "not machine-checked",
                        "note": claim.get("note", "")})
            continue
        checks = check if isinstance(check, list) else [check]
        holds, evidence = _combine([evaluate_check(c, cells, headline) for c in checks])
        out.append({"text": claim["text"], "holds": holds, "evidence": evidence,
                    "note": claim.get("note", "")})
    return out


def evaluate_claims(table_id: str, ours, extra_claims=None, registry: dict | None = None) -> list[dict]:
    """The thesis' claims about ``table_id`` (plus ``extra_claims``) checked on our table.

    Returns ``[{"text", "holds": True|False|None, "evidence", "note"}]``. ``extra_claims`` entries are
    either registry-style ``{"text", "check"}`` or already evaluated ``{"text", "holds", "evidence"}``.
    """
    info = table_info(table_id, registry or load_registry())
    claims = list(info.get("claims") or []) + list(extra_claims or [])
    paper = paper_table(table_id)
    ours = align(as_frame(ours), paper)
    return _evaluate(claims, ours, paper_directions(table_id), info.get("headline_metric"))


def evaluate_claims_on_paper(table_id: str, registry: dict | None = None) -> list[dict]:
    """The same claims checked on the paper's own numbers (a transcription / consistency check)."""
    info = table_info(table_id, registry or load_registry())
    paper = paper_table(table_id)
    if paper.empty:
        return [{"text": c["text"], "holds": None, "evidence": "no paper values", "note": ""}
                for c in info.get("claims") or []]
    return _evaluate(info.get("claims") or [], paper, paper_directions(table_id), info.get("headline_metric"))
