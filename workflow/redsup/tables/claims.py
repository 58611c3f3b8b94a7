"""Kendall's tau of our row ordering vs the paper's, and the thesis' claims checked on a table.

Check types (see data/tables.yaml): order, best, close, range. Every check is decided on the 95 % interval
of its margin, from the measured noise of the cells (redsup.tables.noise: seeds or a paired bootstrap):
``reproduces`` when the whole interval is on the claimed side, ``contradicted`` when it is wholly on the
other side, ``inconclusive`` when it contains zero (a tie is never a win) or a cell is missing.

A claim's verdict is one of VERDICTS: the three above, plus ``not testable`` (the claim is about prior work
whose rows have no value of ours, a property of real data, or a claim the thesis' own table contradicts:
``paper_inconsistent``) and ``data description`` (it holds by how the data were configured) — neither of
the last two is counted as a result. A data description with checks still says whether it holds on our data
(one the world does not share is not hidden behind its category); a not-testable claim's checks are shown as
measured, since they cannot decide it.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import pandas as pd

from redsup.tables import noise as noise_lib
from redsup.tables.registry import (CHECK_TYPES, align, as_frame, column_key, load_registry, numeric,
                                    paper_directions, paper_table, paper_values, row_key, table_info)

REPRODUCES, INCONCLUSIVE, CONTRADICTED = "reproduces", "inconclusive", "contradicted"
RULED_OUT = "thesis effect ruled out"  # the interval holds 0 but excludes the thesis-sized effect: well powered
NOT_TESTABLE, DATA_DESCRIPTION = "not testable", "data description"
UNDER_TRAINED = "under-trained systems"  # compares models far from convergence on val: counted apart
VERDICTS = (REPRODUCES, INCONCLUSIVE, RULED_OUT, CONTRADICTED, UNDER_TRAINED, NOT_TESTABLE, DATA_DESCRIPTION)
COUNTED = (REPRODUCES, INCONCLUSIVE, RULED_OUT, CONTRADICTED)
CATEGORIES = {"not_testable": NOT_TESTABLE, "data_description": DATA_DESCRIPTION, "under_trained": UNDER_TRAINED}
MEASURED_ON_OUR_DATA = ("data_description", "under_trained")  # categories whose checks still say what holds here


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
    """Numeric lookup in one table with lenient row / column matching, with each cell's noise record."""

    def __init__(self, table: pd.DataFrame, directions: Mapping[str, bool], noise: Mapping | None = None,
                 literature: Sequence[str] = (), exact: bool = False):
        self.table = numeric(table)
        self.rows = {row_key(r): r for r in self.table.index}
        self.cols = {column_key(c): c for c in self.table.columns}
        self.directions = {column_key(c): v for c, v in directions.items()}
        self.noise = {(row_key(r), column_key(c)): rec for r, cols in (noise or {}).items()
                      for c, rec in cols.items() if rec}
        self.literature = {row_key(r) for r in literature}
        self.exact = exact  # printed numbers taken as they are (the thesis' own table), not measurements

    def get(self, row, metric) -> float | None:
        r, c = self.rows.get(row_key(row)), self.cols.get(column_key(metric))
        if r is None or c is None:
            return None
        v = self.table.at[r, c]
        return None if pd.isna(v) else float(v)

    def noise_of(self, row, metric) -> dict | None:
        if self.exact:
            return noise_lib.EXACT
        return self.noise.get((row_key(row), column_key(metric)))

    def is_literature(self, row) -> bool:
        """A paper row with no value of ours at all (prior work / reference): claims on it are not testable."""
        return row_key(row) in self.literature and row_key(row) not in self.rows

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


def _rows_of(check: Mapping, metric) -> list[str]:
    kind = check.get("type")
    if kind == "order":
        return [_side(check["better"], metric)[0], _side(check["worse"], metric)[0]]
    if kind == "best":
        return [check["row"], *(check.get("among") or [])]
    if kind == "close":
        return [check["a"], check["b"]]
    return [check["row"]]


def _ival(lo: float, hi: float) -> str:
    return f"[{_fmt(lo)}, {_fmt(hi)}]"


def thesis_effect(paper: "_Cells | None", better: tuple[str, str], worse: tuple[str, str], lower: bool,
                  ours_worse: float) -> float | None:
    """The thesis' effect on our scale: its relative margin of ``better`` over ``worse`` (e.g. 0.115 -> 0.089 is
    23 %) times our value of ``worse``; None when the thesis has no such margin (a cell missing, or no gain)."""
    if paper is None:
        return None
    pb, pw = paper.get(*better), paper.get(*worse)
    if pb is None or pw is None or pw == 0 or not math.isfinite(ours_worse):
        return None
    rel = (pw - pb) / abs(pw) if lower else (pb - pw) / abs(pw)
    return rel * abs(ours_worse) if rel > 0 else None


def _beats(cells: _Cells, a: tuple[str, str, float], b: tuple[str, str, float], lower: bool,
           paper: "_Cells | None" = None, min_effect: float | None = None) -> dict:
    """'a beats b': the verdict on the 95 % interval [lo, hi] of the margin by which it does, with the thesis'
    effect on our scale (``thesis_effect``). An interval around 0 that excludes the thesis-sized effect is
    RULED_OUT; with ``min_effect`` (a fraction of the thesis' effect: "substantially") the margin must exceed that
    floor to reproduce, and an interval wholly below the floor rules the claimed size out (only the opposite effect
    beyond the noise contradicts)."""
    (ar, am, av), (br, bm, bv) = a, b
    na, nb = cells.noise_of(ar, am), cells.noise_of(br, bm)
    d, seed_parts, sampling_parts, how = noise_lib.difference_parts(av, bv, na, nb)
    lo, hi, how = noise_lib.interval(d, seed_parts, sampling_parts, how)
    if lower:  # margin = b - a
        lo, hi = -hi, -lo
    effect = thesis_effect(paper, (ar, am), (br, bm), lower, bv)
    floor = (min_effect * effect if effect is not None else 0.0) if min_effect is not None else None
    return {"verdict": margin_verdict(lo, hi, effect, floor), "lo": lo, "hi": hi, "how": how,
            "margin": (bv - av) if lower else (av - bv), "thesis_effect": effect, "floor": floor,
            **_sample_size(na, nb), **_parts(seed_parts, sampling_parts)}


def margin_verdict(lo: float, hi: float, effect: float | None, floor: float | None = None) -> str:
    """The verdict of "a beats b" on the 95 % interval [lo, hi] of its margin (``_beats``): ``effect`` the thesis'
    effect on our scale (None: unknown), ``floor`` the minimum effect of a "substantially" claim (None: none; 0
    when the thesis' table cannot size it, which then cannot reproduce)."""
    f = floor or 0.0
    verdict = noise_lib.verdict_of_interval(lo, hi) or INCONCLUSIVE
    if verdict == REPRODUCES and lo <= f:
        verdict = RULED_OUT if hi < f else INCONCLUSIVE  # an effect, but not shown to reach the minimum
    if verdict == INCONCLUSIVE and effect is not None and lo <= 0 <= hi and hi < max(effect, f):
        verdict = RULED_OUT
    if floor is not None and effect is None and verdict == REPRODUCES:
        verdict = INCONCLUSIVE  # a minimum effect the thesis' own table cannot size: not decided
    return verdict


def close_verdict(lo: float, hi: float, tol: float) -> str:
    """The verdict of "a is close to b" on the 95 % interval [lo, hi] of a - b against the tolerance ``tol``."""
    if math.isnan(lo) or math.isnan(hi):
        return INCONCLUSIVE
    if -tol - 1e-12 <= lo and hi <= tol + 1e-12:
        return REPRODUCES
    if lo > tol or hi < -tol:
        return CONTRADICTED
    return INCONCLUSIVE


def range_verdict(lo: float, hi: float, low_bound: float = -math.inf, high_bound: float = math.inf) -> str:
    """The verdict of "the value lies in [low_bound, high_bound]" on its 95 % interval [lo, hi]."""
    if low_bound <= lo and hi <= high_bound:
        return REPRODUCES
    if hi < low_bound or lo > high_bound:
        return CONTRADICTED
    return INCONCLUSIVE


def _parts(seed_parts: list | None, sampling_parts: list | None) -> dict:
    """A margin's variance parts as JSON lists ([variance, df] each; None when it has no interval): what the power
    report projects to more seeds or test clusters."""
    if seed_parts is None or sampling_parts is None:
        return {"seed_parts": None, "sampling_parts": None}
    return {"seed_parts": [[float(v), float(df)] for v, df in seed_parts],
            "sampling_parts": [[float(v), float(df)] for v, df in sampling_parts]}


def _sample_size(*records) -> dict:
    """Test clusters and seeds behind a margin (the smallest of its two cells)."""
    clusters = [int(r.get("n_clusters", r.get("n_units", 0))) for r in records
                if r and (r["kind"] == "bootstrap" or r.get("boot") is not None)]
    seeds = [len(r["values"]) for r in records if r and r["kind"] == "seeds"]
    return {"clusters": min(clusters) if clusters else None, "seeds": min(seeds) if seeds else None}


def _margin_text(m: dict) -> str:
    extra = f"; thesis' effect here {_fmt(m['thesis_effect'])}" if m["thesis_effect"] is not None else ""
    if m.get("floor") is not None:
        extra += f"; minimum effect {_fmt(m['floor'])}"
    return f"margin 95 % {_ival(m['lo'], m['hi'])}, {m['how']}{extra}"


def evaluate_check(check: Mapping, cells: _Cells, headline: str | None,
                   paper: _Cells | None = None) -> tuple[str, str, list[dict]]:
    """(verdict, evidence, margins) of one check on one table: reproduces / inconclusive / contradicted /
    thesis-sized effect ruled out (``paper``: the thesis' own table, which sizes its effect), or not testable when
    it needs a literature row that has no value of ours. ``margins``: one record a result (a metric of the check):
    its comparison, interval, verdict and variance parts (what the power report projects), or why it has none."""
    kind = check.get("type")
    if kind not in CHECK_TYPES:
        raise ValueError(f"unknown check type {kind!r} (known: {CHECK_TYPES})")
    min_effect = check.get("min_effect")
    results: list[tuple[str, str]] = []
    margins: list[dict] = []
    for metric in _metrics(check, headline):
        prefix = "" if metric is None else f"{metric}: "
        lit = [r for r in _rows_of(check, metric) if cells.is_literature(r)]
        if lit:
            results.append((NOT_TESTABLE, f"{prefix}needs {', '.join(lit)} (prior work / reference, no value of "
                                          "ours: cannot be tested on the embedded world)"))
            continue
        if kind == "order":
            (br, bm), (wr, wm) = _side(check["better"], metric), _side(check["worse"], metric)
            b, w = cells.get(br, bm), cells.get(wr, wm)
            lower = cells.lower_is_better(bm, check)
            cellwise = bm != metric or wm != metric
            label = f"{br} [{bm}]" if cellwise else br
            wlabel = f"{wr} [{wm}]" if cellwise else wr
            if b is None or w is None:
                missing = [x for x, v in ((label, b), (wlabel, w)) if v is None]
                _unsized(results, margins, kind, f"{prefix}missing {', '.join(missing)}")
                continue
            m = _beats(cells, (br, bm, b), (wr, wm, w), lower, paper, min_effect)
            margins.append({"comparison": f"{label} vs {wlabel}", "check": kind, **m})
            rel = "<" if b < w else ">" if b > w else "="
            results.append((m["verdict"], f"{prefix}{label} {_fmt(b)} {rel} {wlabel} {_fmt(w)} "
                                          f"({'lower' if lower else 'higher'} is better; {_margin_text(m)})"))
        elif kind == "best":
            row, worst = check["row"], bool(check.get("worst", False))
            lower = cells.lower_is_better(metric, check) != worst  # the "winning" direction
            among = check.get("among")
            pool = cells.column_rows(metric)
            if among is not None:
                keys = {row_key(a) for a in among} | {row_key(row)}
                pool = [r for r in pool if row_key(r) in keys]
                absent = [a for a in among if row_key(a) not in {row_key(r) for r in pool}]
            else:
                absent = []
            v = cells.get(row, metric)
            word = "worst" if worst else "best"
            if v is None:
                _unsized(results, margins, kind, f"{metric}: missing {row}")
                continue
            others = [r for r in pool if row_key(r) != row_key(row)]
            if not others or absent:
                why = f"missing {', '.join(absent)}" if absent else "no other row to compare"
                _unsized(results, margins, kind, f"{metric}: {row} {_fmt(v)}; {why}")
                continue
            verdicts = {r: _beats(cells, (row, metric, v), (r, metric, cells.get(r, metric)), lower, paper,
                                  min_effect) for r in others}
            verdict, _ = _combine([(x["verdict"], "") for x in verdicts.values()])
            closest = min(verdicts, key=lambda r: (math.inf if math.isnan(verdicts[r]["lo"]) else verdicts[r]["lo"]))
            m = verdicts[closest]  # the smallest lower margin bound
            margins.append({"comparison": f"{row} vs {closest}", "check": kind, **m})
            results.append((verdict, f"{metric}: {row} {_fmt(v)}; {word} of {len(pool)} rows; closest "
                                     f"{closest} {_fmt(cells.get(closest, metric))} ({_margin_text(m)})"))
        elif kind == "close":
            a, b = cells.get(check["a"], metric), cells.get(check["b"], metric)
            if a is None or b is None:
                missing = [x for x, v in ((check["a"], a), (check["b"], b)) if v is None]
                _unsized(results, margins, kind, f"{metric}: missing {', '.join(missing)}")
                continue
            tol = float(check["tol"]) * (abs(b) if check.get("relative") else 1.0)
            na, nb = cells.noise_of(check["a"], metric), cells.noise_of(check["b"], metric)
            d, seed_parts, sampling_parts, how = noise_lib.difference_parts(a, b, na, nb)
            lo, hi, how = noise_lib.interval(d, seed_parts, sampling_parts, how)
            floor = a == b == 0.0 and lo == hi  # both cells 0 without any spread: a floor, not an equivalence
            if floor:
                verdict = INCONCLUSIVE
                how = how + "; both 0 without spread (a floor): equivalence not shown"
            else:
                verdict = close_verdict(lo, hi, tol)
            margins.append({"comparison": f"{check['a']} − {check['b']}", "check": "close", "verdict": verdict,
                            "lo": lo, "hi": hi, "how": how, "margin": a - b, "tol": tol, **_sample_size(na, nb),
                            **(_parts(None, None) if floor else _parts(seed_parts, sampling_parts))})
            results.append((verdict, f"{metric}: {check['a']} {_fmt(a)} − {check['b']} {_fmt(b)} = "
                                     f"{_fmt(a - b)} (95 % {_ival(lo, hi)}, {how}) vs ±{_fmt(tol)}"))
        elif kind == "range":
            v = cells.get(check["row"], metric)
            if v is None:
                _unsized(results, margins, kind, f"{metric}: missing {check['row']}")
                continue
            lo_b, hi_b = check.get("min", -math.inf), check.get("max", math.inf)
            nv = cells.noise_of(check["row"], metric)
            _, seed_parts, sampling_parts, how = noise_lib.value_parts(v, nv)
            lo, hi, how = noise_lib.interval(v, seed_parts, sampling_parts, how)
            verdict = range_verdict(lo, hi, lo_b, hi_b)
            margins.append({"comparison": check["row"], "check": "range", "verdict": verdict, "lo": lo, "hi": hi,
                            "how": how, "margin": v, "min": check.get("min"), "max": check.get("max"),
                            **_sample_size(nv), **_parts(seed_parts, sampling_parts)})
            bounds = " and ".join(x for x in [f"≥ {lo_b}" if "min" in check else "",
                                               f"≤ {hi_b}" if "max" in check else ""] if x)
            results.append((verdict, f"{metric}: {check['row']} {_fmt(v)} (95 % {_ival(lo, hi)}) vs {bounds}"))
    verdict, evidence = _combine(results)
    return verdict, evidence, margins


def _unsized(results: list, margins: list, kind: str, evidence: str) -> None:
    """An inconclusive check result without a margin (a cell missing, no row to compare): its margin record says
    so, so that the power report does not size the claim on its other checks alone."""
    results.append((INCONCLUSIVE, evidence))
    margins.append({"comparison": None, "check": kind, "verdict": INCONCLUSIVE, "lo": math.nan, "hi": math.nan,
                    "how": evidence, "seed_parts": None, "sampling_parts": None})


def combine_verdicts(verdicts: Sequence[str]) -> str:
    """A claim's verdict from its checks': not testable, contradicted or ruled out when any check is, reproduces
    when every check does, else inconclusive."""
    if any(v == NOT_TESTABLE for v in verdicts):
        return NOT_TESTABLE
    if any(v == CONTRADICTED for v in verdicts):
        return CONTRADICTED
    if any(v == RULED_OUT for v in verdicts):
        return RULED_OUT
    if verdicts and all(v == REPRODUCES for v in verdicts):
        return REPRODUCES
    return INCONCLUSIVE


def _combine(results: list[tuple[str, str]]) -> tuple[str, str]:
    return combine_verdicts([v for v, _ in results]), "; ".join(e for _, e in results)


# a data description's own checks still say whether its statement is true of our data
DOES_NOT_HOLD = "does not hold on our data"
_ON_OUR_DATA = {REPRODUCES: "holds on our data", CONTRADICTED: DOES_NOT_HOLD,
                RULED_OUT: "undecided on our data (no effect of the thesis' size)",
                INCONCLUSIVE: "undecided on our data (inside the noise or a cell missing)"}


def _evaluate(claims, table: pd.DataFrame, directions, headline, noise=None, literature=(),
              paper: pd.DataFrame | None = None, exact: bool = False) -> list[dict]:
    cells = _Cells(table, directions, noise, literature, exact=exact)
    paper_cells = cells if exact else (_Cells(paper, directions) if paper is not None and not paper.empty else None)
    out = []
    for claim in claims:
        base = {"text": claim["text"], "note": claim.get("note", "")}
        category = claim.get("category")
        if category is not None and category not in CATEGORIES:
            raise ValueError(f"claim {claim['text']!r}: unknown category {category!r} (known: {list(CATEGORIES)})")
        if "verdict" in claim:  # pre-evaluated extra claim
            if claim["verdict"] not in VERDICTS:
                raise ValueError(f"claim {claim['text']!r}: unknown verdict {claim['verdict']!r}")
            out.append({**base, "verdict": claim["verdict"], "evidence": claim.get("evidence", "")})
            continue
        check = claim.get("check")
        checks = (check if isinstance(check, list) else [check]) if check else []
        decided = [evaluate_check(c, cells, headline, paper_cells) for c in checks]
        verdict, evidence = _combine([(v, e) for v, e, _ in decided]) if checks else \
            (INCONCLUSIVE, "not machine-checked")
        margins = [_plain_margin(m) for _, _, ms in decided for m in ms]
        if category:
            held = _ON_OUR_DATA.get(verdict) if checks and category in MEASURED_ON_OUR_DATA else None
            verdict = CATEGORIES[category]
            evidence = "; ".join(p for p in (claim.get("reason", ""), held) if p) + f" (measured: {evidence})"
            if held:
                base["on_our_data"] = held
        elif claim.get("paper_inconsistent"):
            verdict = NOT_TESTABLE
            evidence = f"the thesis' own table disagrees with its text: {claim['paper_inconsistent']} " \
                       f"(measured: {evidence})"
        out.append({**base, "verdict": verdict, "evidence": evidence, **({"margins": margins} if margins else {})})
    return out


def _plain_margin(m: Mapping) -> dict:
    """A decided comparison as JSON-able numbers (None for NaN): what the power report reads."""
    return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in m.items()}


def _literature_rows(table_id: str) -> list[str]:
    long = paper_values(table_id)
    notes = long.groupby("row")["note"].apply(lambda x: " ".join(x))
    return [r for r, n in notes.items() if "literature" in n or "reference" in n]


def evaluate_claims(table_id: str, ours, extra_claims=None, registry: dict | None = None,
                    noise: Mapping | None = None) -> list[dict]:
    """The thesis' claims about ``table_id`` (plus ``extra_claims``) decided on our table.

    Returns ``[{"text", "verdict" (one of VERDICTS), "evidence", "note"}]``. ``noise``: {row: {column:
    record}} of our cells (redsup.tables.noise). ``extra_claims`` entries are registry-style ``{"text",
    "check"}`` or already decided ``{"text", "verdict", "evidence"}``.
    """
    info = table_info(table_id, registry or load_registry())
    claims = list(info.get("claims") or []) + list(extra_claims or [])
    paper = paper_table(table_id)
    ours = align(as_frame(ours), paper)
    return _evaluate(claims, ours, paper_directions(table_id), info.get("headline_metric"),
                     align_noise(noise, paper), _literature_rows(table_id), paper)


def align_noise(noise: Mapping | None, paper: pd.DataFrame) -> dict:
    """Noise records keyed by the paper's row / column labels where ours match them (as ``align``)."""
    rows = {row_key(r): r for r in paper.index}
    cols = {column_key(c): c for c in paper.columns}
    return {rows.get(row_key(r), r): {cols.get(column_key(c), c): rec for c, rec in cs.items()}
            for r, cs in (noise or {}).items()}


def evaluate_claims_on_paper(table_id: str, registry: dict | None = None) -> list[dict]:
    """The same claims decided on the paper's own numbers, taken as exact (a transcription / consistency check; a
    tie is inconclusive)."""
    info = table_info(table_id, registry or load_registry())
    paper = paper_table(table_id)
    if paper.empty:
        return [{"text": c["text"], "verdict": INCONCLUSIVE, "evidence": "no paper values", "note": ""}
                for c in info.get("claims") or []]
    claims = [{k: v for k, v in c.items() if k not in ("category", "paper_inconsistent")}
              for c in info.get("claims") or []]
    return _evaluate(claims, paper, paper_directions(table_id), info.get("headline_metric"), exact=True)


def count_verdicts(claims: Sequence[Mapping]) -> dict[str, int]:
    """{verdict key: count} over VERDICTS (keys with underscores: reproduces, not_testable, ...)."""
    return {v.replace(" ", "_"): sum(c["verdict"] == v for c in claims) for v in VERDICTS}
