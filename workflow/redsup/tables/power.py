"""The power report: for every counted claim, the margin it was decided on, its 95 % half width, the thesis' effect
on our scale, and how many more test clusters or seeds would decide it at the observed effect.

An interval's half width shrinks about as 1 / sqrt(n) in the number of independent units behind it (test scenes,
training seeds), so a margin m with half width h is decided at about (h / |m|)^2 times the units it had. That is a
first-order projection from the build's own replicates, not a promise: it assumes the observed margin is the true
one. It is how the build's budget is meant to be allocated: to the claims that more units would decide.
"""
from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from pathlib import Path

import pandas as pd

from redsup.tables.claims import (CONTRADICTED, COUNTED, INCONCLUSIVE, REPRODUCES, RULED_OUT)

COLUMNS = ["table", "claim", "verdict", "comparison", "margin", "half width", "thesis effect", "clusters", "seeds",
           "factor", "clusters needed", "seeds needed", "status"]


def claim_power(table_id: str, claim: Mapping) -> dict:
    """One row of the report for one counted claim (its first decided comparison)."""
    row = {c: None for c in COLUMNS} | {"table": table_id, "claim": claim["text"], "verdict": claim["verdict"]}
    margins = claim.get("margins") or []
    if not margins:
        return row | {"status": "no margin to size (a closeness or range check, or a cell missing)"}
    m = margins[0]
    lo, hi = m.get("lo"), m.get("hi")
    row |= {"comparison": m.get("comparison"), "margin": m.get("margin"), "thesis effect": m.get("thesis_effect"),
            "clusters": m.get("clusters"), "seeds": m.get("seeds")}
    if lo is None or hi is None:
        return row | {"status": f"no interval: {m.get('how')}"}
    half = (hi - lo) / 2
    row["half width"] = half
    if claim["verdict"] in (REPRODUCES, CONTRADICTED):
        return row | {"status": "decided"}
    if claim["verdict"] == RULED_OUT:
        return row | {"status": "decided: the thesis-sized effect is ruled out"}
    centre = (hi + lo) / 2
    if centre == 0 or half == 0:
        return row | {"status": "effect 0: only ruling out the thesis' effect could decide it"}
    factor = round((half / abs(centre)) ** 2, 9)  # float noise must not tip a ceiling
    row["factor"] = factor
    row["clusters needed"] = math.ceil(m["clusters"] * factor) if m.get("clusters") else None
    row["seeds needed"] = math.ceil(m["seeds"] * factor) if m.get("seeds") else None
    return row | {"status": f"needs about {factor:.1f}x the units"}


def power_table(scores: Iterable[Mapping]) -> pd.DataFrame:
    rows = [claim_power(s["table_id"], c) for s in scores for c in s["claims"] if c["verdict"] in COUNTED]
    return pd.DataFrame(rows, columns=COLUMNS)


def _fmt(v) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return "—"
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def write_power(score_jsons: Iterable[str | Path], out_md: str | Path, out_csv: str | Path) -> dict:
    """Write the report (Markdown and CSV) from the tables' ``<id>.score.json``; returns counts by status kind."""
    scores = [json.loads(Path(p).read_text()) for p in score_jsons]
    df = power_table(scores)
    Path(out_csv).parent.mkdir(parents=True, exist_ok=True)
    df.to_csv(out_csv, index=False)
    factor = df.loc[df["verdict"] == INCONCLUSIVE, "factor"]
    summary = {"counted": len(df), "inconclusive": len(factor), "decidable_at_4x": int((factor <= 4).sum()),
               "decidable_at_16x": int((factor <= 16).sum())}
    md = ["# Power: what would decide each counted claim", "",
          f"{summary['counted']} counted claims, {summary['inconclusive']} inconclusive: at the observed margin, "
          f"{summary['decidable_at_4x']} of those would be decided with at most 4x the test units (or seeds), "
          f"{summary['decidable_at_16x']} with at most 16x. Margin: the claimed-better side's advantage (positive "
          "= as the thesis says); half width of its 95 % interval; thesis effect: the thesis' relative margin on our "
          "baseline; factor: (half width / |centre|)^2, the multiple of the units behind the interval that would "
          "decide it if the observed margin were the true one (a projection).", "",
          "| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    for r in df.to_dict("records"):
        md.append("| " + " | ".join(_fmt(r[c]).replace("|", "/") for c in COLUMNS) + " |")
    Path(out_md).write_text("\n".join(md) + "\n")
    return summary
