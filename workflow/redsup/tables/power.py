"""The power report: for every counted claim, the margin it was decided on, its 95 % half width, the thesis' effect
on our scale, and how many more seeds or test clusters would decide it at the observed effect.

A margin's interval is built from variance parts (``redsup.tables.noise``): the spread over training seeds and the
test-sampling spread over clusters of test units (scenes, clips). Each part's variance falls as 1 / n in its own
units, so the report projects the claim's interval to k times the seeds, k times the test clusters, or both, at the
same spread per unit and the same observed margins, and applies the claim's own verdict rules to it (a ruled-out
thesis effect, a minimum effect, a closeness tolerance and a range included): the smallest k that decides the
claim. That is a first-order projection from the build's own replicates, not a promise: it assumes the observed
margins are the true ones. It is how the build's budget is meant to be allocated: to the claims that more units
would decide, in the units (seeds or test scenes) that would decide them.
"""
from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from pathlib import Path

import numpy as np
import pandas as pd

from redsup.tables.claims import (CONTRADICTED, COUNTED, INCONCLUSIVE, REPRODUCES, RULED_OUT, close_verdict,
                                  combine_verdicts, margin_verdict, range_verdict)
from redsup.tables.noise import half_width

COLUMNS = ["table", "claim", "verdict", "comparison", "margin", "half width", "thesis effect", "clusters", "seeds",
           "seed share", "factor", "seeds needed", "clusters needed", "status"]
MAX_FACTOR = 10_000.0
#: the multiples of the units tried, 1 to MAX_FACTOR in steps of 2 %
SCALES = 1.02 ** np.arange(0, math.ceil(math.log(MAX_FACTOR) / math.log(1.02)) + 1)


def _has_interval(m: Mapping) -> bool:
    return m.get("seed_parts") is not None and m.get("sampling_parts") is not None and m.get("lo") is not None \
        and m.get("hi") is not None


def _projected(m: Mapping, seed_scale, sampling_scale) -> list[str]:
    """The margin's verdict at each of the scales (arrays of one length): its interval re-centred on the observed
    value with the half width of k times the seeds / clusters, judged by the margin's own rule."""
    n = len(np.atleast_1d(seed_scale * sampling_scale))
    if not _has_interval(m):
        return [m.get("verdict") or INCONCLUSIVE] * n
    seed, sampling = m["seed_parts"], m["sampling_parts"]
    half = (np.broadcast_to(half_width(seed, sampling, seed_scale, sampling_scale), (n,)) if seed or sampling
            else np.zeros(n))
    c = (m["lo"] + m["hi"]) / 2
    kind = m.get("check")
    if kind == "close":
        return [close_verdict(c - h, c + h, m["tol"]) for h in half]
    if kind == "range":
        lo_b = -math.inf if m.get("min") is None else m["min"]
        hi_b = math.inf if m.get("max") is None else m["max"]
        return [range_verdict(c - h, c + h, lo_b, hi_b) for h in half]
    return [margin_verdict(c - h, c + h, m.get("thesis_effect"), m.get("floor")) for h in half]


def decided_at(margins: list[Mapping], seeds: bool = True, clusters: bool = True) -> float | None:
    """The smallest multiple k (of ``SCALES``) of the seeds (``seeds``) and / or the test clusters (``clusters``)
    behind every margin at which the claim's combined verdict is decided; None when not within MAX_FACTOR."""
    ones = np.ones_like(SCALES)
    per_margin = [_projected(m, SCALES if seeds else ones, SCALES if clusters else ones) for m in margins]
    for i, k in enumerate(SCALES):
        if combine_verdicts([v[i] for v in per_margin]) in (REPRODUCES, CONTRADICTED, RULED_OUT):
            return float(k)
    return None


def _seed_share(m: Mapping) -> float | None:
    if not _has_interval(m):
        return None
    seed = sum(v for v, _ in m["seed_parts"])
    total = seed + sum(v for v, _ in m["sampling_parts"])
    return seed / total if total > 0 else None


def claim_power(table_id: str, claim: Mapping) -> dict:
    """One row of the report for one counted claim: its first undecided margin with an interval (else its first
    margin), and for an inconclusive claim the multiples of the units that would decide it: ``factor`` (seeds and
    test clusters together), ``seeds needed`` (the test set as it is) and ``clusters needed`` (the seeds as they
    are); None where that alone would not decide it within MAX_FACTOR."""
    row = {c: None for c in COLUMNS} | {"table": table_id, "claim": claim["text"], "verdict": claim["verdict"]}
    margins = claim.get("margins") or []
    if not margins:
        return row | {"status": "no margin to size (a cell missing, or not machine-checked)"}
    shown = next((m for m in margins if m.get("verdict") == INCONCLUSIVE and _has_interval(m)), margins[0])
    row |= {"comparison": shown.get("comparison"), "margin": shown.get("margin"),
            "thesis effect": shown.get("thesis_effect"), "clusters": shown.get("clusters"),
            "seeds": shown.get("seeds"), "seed share": _seed_share(shown)}
    if shown.get("lo") is not None and shown.get("hi") is not None:
        row["half width"] = (shown["hi"] - shown["lo"]) / 2
    if claim["verdict"] in (REPRODUCES, CONTRADICTED):
        return row | {"status": "decided"}
    if claim["verdict"] == RULED_OUT:
        return row | {"status": "decided: the thesis-sized effect is ruled out"}
    factor = decided_at(margins)
    if factor is None:
        missing = next((m for m in margins if not _has_interval(m) and m.get("verdict") == INCONCLUSIVE), None)
        return row | {"status": f"no interval: {missing['how']}" if missing else
                      f"not decided within {MAX_FACTOR:.0f}x the units (an effect about 0)"}
    k_seeds, k_clusters = decided_at(margins, clusters=False), decided_at(margins, seeds=False)
    row["factor"] = round(factor, 2)
    row["seeds needed"] = math.ceil(shown["seeds"] * k_seeds - 1e-9) if k_seeds and shown.get("seeds") else None
    row["clusters needed"] = (math.ceil(shown["clusters"] * k_clusters - 1e-9)
                              if k_clusters and shown.get("clusters") else None)
    alone = [f"{row['seeds needed']} seeds with the test set as it is" if row["seeds needed"] else
             "more seeds alone would not", f"{row['clusters needed']} test clusters with the seeds as they are"
             if row["clusters needed"] else "more test clusters alone would not"]
    return row | {"status": f"needs about {factor:.1f}x the units; " + "; ".join(alone)}


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
    undecided = df[df["verdict"] == INCONCLUSIVE]
    factor = undecided["factor"]
    summary = {"counted": len(df), "inconclusive": len(undecided), "decidable_at_4x": int((factor <= 4).sum()),
               "decidable_at_16x": int((factor <= 16).sum()),
               "by_seeds_alone": int(undecided["seeds needed"].notna().sum()),
               "by_clusters_alone": int(undecided["clusters needed"].notna().sum())}
    md = ["# Power: what would decide each counted claim", "",
          f"{summary['counted']} counted claims, {summary['inconclusive']} inconclusive: at the observed margins, "
          f"{summary['decidable_at_4x']} of those would be decided with at most 4x the seeds and test clusters, "
          f"{summary['decidable_at_16x']} with at most 16x; {summary['by_seeds_alone']} could be decided by more "
          f"seeds alone and {summary['by_clusters_alone']} by more test clusters alone.", "",
          "Margin: the claimed-better side's advantage (positive = as the thesis says; for a closeness check the "
          "difference, for a range check the value); half width of its 95 % interval; thesis effect: the thesis' "
          "relative margin on our baseline; seed share: the part of the interval's variance that is the spread over "
          "training seeds (the rest is test sampling); factor: the smallest multiple k of both the seeds and the test "
          "clusters at which the claim's own verdict rules would decide it, its interval projected at the same "
          "spread per unit and the observed margins (a projection, not a promise); seeds needed / clusters needed: "
          "the seeds with the test set as it is, and the test clusters with the seeds as they are, that would "
          "decide it ('—': that alone would not).", "",
          "| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    for r in df.to_dict("records"):
        md.append("| " + " | ".join(_fmt(r[c]).replace("|", "/") for c in COLUMNS) + " |")
    Path(out_md).write_text("\n".join(md) + "\n")
    return summary
