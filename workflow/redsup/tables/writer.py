"""Write a reproduced table beside the paper's numbers (CSV, Markdown, LaTeX + score JSON), and gather
every table's score into one scorecard."""
from __future__ import annotations

import json
import math
import re
from collections.abc import Iterable
from pathlib import Path

import pandas as pd

from redsup.tables import noise as noise_lib
from redsup.tables.claims import (COUNTED, DOES_NOT_HOLD, VERDICTS, align_noise, count_verdicts, evaluate_claims,
                                  evaluate_claims_on_paper, headline_tau)
from redsup.tables.registry import (align, as_frame, load_registry, paper_table, paper_values,
                                    table_info)

DASH = "—"
MARK = {"reproduces": "✔", "contradicted": "✘", "inconclusive": "≈", "thesis effect ruled out": "⊘",
        "under-trained systems": "◌", "not testable": "○", "data description": "▫"}


# ------------------------------------------------------------------------------------ formatting
def fmt_value(v, decimals: int | None = None) -> str:
    """Our numbers for display: with ``decimals`` (the paper's precision for that column) when given,
    else integers as such and 4 significant digits (2 decimals from 100 on)."""
    if v is None:
        return DASH
    if isinstance(v, str):
        return v if v.strip() else DASH
    try:
        x = float(v)
    except (TypeError, ValueError):
        return str(v)
    if math.isnan(x):
        return DASH
    if math.isinf(x):
        return "∞" if x > 0 else "−∞"
    if decimals is not None:
        return f"{x:.{decimals}f}"
    if x == int(x) and abs(x) < 1e15:
        return str(int(x))
    if abs(x) >= 100:
        return f"{x:.2f}"
    decimals = max(0, 3 - math.floor(math.log10(abs(x))))
    return f"{x:.{decimals}f}"


def _md_cell(s: str) -> str:
    return str(s).replace("|", "\\|").replace("\n", " ")


_TEX = {
    "\\": r"\textbackslash{}", "&": r"\&", "%": r"\%", "$": r"\$", "#": r"\#", "_": r"\_",
    "{": r"\{", "}": r"\}", "~": r"\textasciitilde{}", "^": r"\textasciicircum{}", "|": r"\textbar{}",
    "<": r"$<$", ">": r"$>$", "δ": r"$\delta$", "τ": r"$\tau$", "α": r"$\alpha$", "β": r"$\beta$",
    "σ": r"$\sigma$", "†": r"\dag{}", "‡": r"\ddag{}", "✔": r"\checkmark{}", "✘": r"$\times$",
    "×": r"$\times$", "≤": r"$\le$", "≥": r"$\ge$", "−": r"$-$", "—": "---", "–": "--", "‘": "`",
    "’": "'", "∞": r"$\infty$", "→": r"$\to$", "ü": r"\"u", "μ": r"$\mu$",
}


_SUPERSCRIPT = re.compile(r"\^\{?([A-Za-z0-9.+-]+)\}?")


def tex_escape(s) -> str:
    """Text for LaTeX: specials escaped, common unicode symbols as commands, ``x^2`` as a superscript."""
    parts = _SUPERSCRIPT.split(str(s))  # even: text, odd: superscript
    out = []
    for i, part in enumerate(parts):
        esc = "".join(_TEX.get(ch, ch) for ch in part)
        out.append(f"\\textsuperscript{{{esc}}}" if i % 2 else esc)
    return "".join(out)


def _decimals(texts) -> int | None:
    """The largest number of decimals among printed paper values (None if there are none)."""
    best = None
    for t in texts:
        t = str(t).strip()
        if not t:
            continue
        d = len(t.split(".", 1)[1]) if "." in t else 0
        best = d if best is None else max(best, d)
    return best


def _plain(v):
    """CSV cell: integer-valued floats as ints, NaN as empty."""
    if isinstance(v, float):
        if math.isnan(v):
            return None
        if v.is_integer() and abs(v) < 1e15:
            return int(v)
    return v


# ------------------------------------------------------------------------------------ the table
def _status(row: str, in_ours: bool, in_paper: bool, notes: dict[str, str]) -> str:
    if in_ours and in_paper:
        return "ours + paper"
    if in_ours:
        return "ours only"
    note = notes.get(row, "")
    if "literature" in note:
        return "paper only: literature, not reproduced"
    if "reference" in note:
        return "paper only: reference"
    return "paper only: not reproduced"


def build_table(table_id: str, ours, noise=None) -> tuple[pd.DataFrame, pd.DataFrame, dict]:
    """(display table of strings, CSV table with raw numbers, layout info) for ``table_id``.

    ``noise`` ({row: {column: record}}): cells with a spread show ``mean ± std`` (seeds: std over seeds;
    bootstrap: the standard error), and the CSV gets a ``<column> (ours) std`` column beside each such one.
    """
    ours = as_frame(ours)
    paper = paper_table(table_id)
    paper_txt = paper_table(table_id, text=True)
    has_paper = not paper.empty
    if has_paper:
        ours = align(ours, paper)
        noise = align_noise(noise, paper)
    spreads = {(str(r), str(c)): noise_lib.spread(rec) for r, cs in (noise or {}).items() for c, rec in cs.items()}
    spreads = {k: v for k, v in spreads.items() if v is not None}
    spread_cols = {c for _, c in spreads}
    if ours.index.has_duplicates:
        raise ValueError(f"{table_id}: duplicate row labels {sorted(set(ours.index[ours.index.duplicated()]))}")
    rows = list(paper.index) + [r for r in ours.index if r not in paper.index]
    columns = list(paper.columns) + [c for c in ours.columns if c not in paper.columns]
    long = paper_values(table_id)
    notes = {r: "; ".join(sorted(set(long.loc[long["row"] == r, "note"]))) for r in paper.index}

    header: list[str] = [ours.index.name or "row"]
    sources: list[tuple[str, str]] = []  # (kind, column)
    for c in columns:
        if not has_paper:
            header.append(c)
            sources.append(("ours", c))
            if c in spread_cols:
                sources.append(("std", c))
            continue
        if c in ours.columns:
            header.append(f"{c} (ours)")
            sources.append(("ours", c))
        if c in spread_cols:
            sources.append(("std", c))
        if c in paper.columns:
            header.append(f"{c} (paper)")
            sources.append(("paper", c))
    display, raw = [], []
    decimals = {c: _decimals(paper_txt[c]) for c in paper.columns}
    for r in rows:
        in_ours, in_paper = r in ours.index, r in paper.index
        d_line, r_line = [r], [r]
        for kind, c in sources:
            if kind == "ours":
                v = ours.at[r, c] if in_ours else None
                text = fmt_value(v, decimals.get(c))
                sd = spreads.get((r, c))
                if sd is not None and text != DASH:
                    text += f" ± {fmt_value(sd, decimals.get(c))}"
                d_line.append(text)
                r_line.append(_plain(v))
            elif kind == "std":
                r_line.append(spreads.get((r, c)))
            else:
                t = paper_txt.at[r, c] if in_paper else ""
                d_line.append(t if t != "" else DASH)
                r_line.append(t if t != "" else None)
        if has_paper:
            status = _status(r, in_ours, in_paper, notes)
            d_line.append(status)
            r_line.append(status)
        display.append(d_line)
        raw.append(r_line)
    if has_paper:
        header.append("status")
    raw_header = [header[0]]
    hi = 1
    for kind, c in sources:
        if kind == "std":
            raw_header.append(f"{c} (ours) std" if has_paper else f"{c} std")
        else:
            raw_header.append(header[hi])
            hi += 1
    raw_header += header[hi:]
    display_df = pd.DataFrame(display, columns=header)
    raw_df = pd.DataFrame(raw, columns=raw_header, dtype=object)
    info = {"rows_paper": len(paper.index), "rows_ours": len(ours.index),
            "rows_both": sum(r in paper.index for r in ours.index), "has_paper": has_paper}
    return display_df, raw_df, info


def _md_table(df: pd.DataFrame) -> str:
    head = "| " + " | ".join(_md_cell(c) for c in df.columns) + " |"
    align_row = "|" + "|".join(":---" if i == 0 or c == "status" else "---:"
                               for i, c in enumerate(df.columns)) + "|"
    lines = [head, align_row]
    lines += ["| " + " | ".join(_md_cell(x) for x in row) + " |" for row in df.itertuples(index=False)]
    return "\n".join(lines)


def _tex_table(df: pd.DataFrame, title: str, caption: str, table_id: str, score_lines: list[str]) -> str:
    spec = "".join("l" if i == 0 or c == "status" else "r" for i, c in enumerate(df.columns))
    out = [
        f"% {table_id}: generated by redsup.tables.write_table; needs \\usepackage{{booktabs,amssymb}}",
        "\\begin{table}[t]", "\\centering", "\\small",
        f"\\caption{{{tex_escape(title)}. {tex_escape(caption)}}}",
        f"\\label{{tab:{table_id}}}",
        f"\\begin{{tabular}}{{{spec}}}", "\\toprule",
        " & ".join(tex_escape(c) for c in df.columns) + " \\\\", "\\midrule",
    ]
    out += [" & ".join(tex_escape(x) for x in row) + " \\\\" for row in df.itertuples(index=False)]
    out += ["\\bottomrule", "\\end{tabular}"]
    if score_lines:
        out += ["\\par\\smallskip", "\\begin{minipage}{\\linewidth}\\footnotesize"]
        out += [tex_escape(line) + " \\\\" for line in score_lines[:-1]] + [tex_escape(score_lines[-1])]
        out += ["\\end{minipage}"]
    out += ["\\end{table}", ""]
    return "\n".join(out)


def _caption(info: dict, registry: dict, note: str | None) -> str:
    parts = [info.get("description", "").rstrip(".") + "."]
    src = info.get("source")
    if src:
        doc = registry.get("documents", {}).get(src["document"], src["document"])
        parts.append(f"Paper values: {src['label']} of {doc} (line {src['line']}), as printed.")
        parts.append("'—' = not reported or not reproduced.")
    else:
        parts.append("Ours only (no paper values).")
    if note:
        parts.append(note.rstrip(".") + ".")
    return " ".join(p for p in parts if p.strip(". "))


def _score_lines(score: dict) -> list[str]:
    lines = []
    if score["has_paper"]:
        if score["kendall_tau"] is None:
            why = "no headline metric" if not score["headline_metric"] else f"n = {score['n_rows']} rows in both"
            lines.append(f"Scorecard: Kendall τ on {score['headline_metric'] or '—'}: n/a ({why}).")
        else:
            lines.append(f"Scorecard: Kendall τ of our row order vs the paper's on {score['headline_metric']}: "
                         f"{score['kendall_tau']:+.3f} (n = {score['n_rows']} rows).")
    if score["claims"]:
        lines.append("Claims: " + _counts_text(score["counts"]) + ".")
    for c in score["claims"]:
        paper = f" [on the paper's numbers: {c['verdict_on_paper']}]" if "verdict_on_paper" in c else ""
        lines.append(f"{MARK[c['verdict']]} {c['verdict']}: {c['text']} — {c['evidence']}{paper}")
    return lines


def _counts_text(counts: dict) -> str:
    return ", ".join(f"{counts[v.replace(' ', '_')]} {v}" for v in VERDICTS)


def write_table(table_id: str, ours, out_md, out_csv, out_tex, extra_claims=None, *,
                note: str | None = None, registry: dict | None = None, noise=None) -> dict:
    """Write our table with the paper's value beside each cell as CSV, Markdown and LaTeX, plus
    ``<table_id>.score.json`` beside ``out_md``. Returns the score dict.

    ``ours``: DataFrame indexed by row label (or with a ``row`` column), one column per metric, named as
    in paper_values.csv (matching is lenient, see redsup.tables.registry). ``noise``: {row: {column:
    record}} (redsup.tables.noise): shown as ± std and used to decide the claims. ``extra_claims``: claims
    added by the caller (registry form ``{"text", "check"}`` or decided ``{"text", "verdict",
    "evidence"}``). ``note``: appended to the caption (e.g. profile and seed).
    """
    registry = registry or load_registry()
    info = table_info(table_id, registry)
    display, raw, layout = build_table(table_id, ours, noise)
    paper = paper_table(table_id)
    aligned = align(as_frame(ours), paper) if layout["has_paper"] else as_frame(ours)
    tau = headline_tau(aligned, paper, info.get("headline_metric"))
    claims = evaluate_claims(table_id, ours, extra_claims=extra_claims, registry=registry, noise=noise)
    on_paper = evaluate_claims_on_paper(table_id, registry) if layout["has_paper"] else []
    for c, p in zip(claims, on_paper):  # extra claims come last and have no paper check
        c["verdict_on_paper"], c["evidence_paper"] = p["verdict"], p["evidence"]
    counts = count_verdicts(claims)
    score = {
        "table_id": table_id, "title": info["title"], "stage": info["stage"], "kind": info.get("kind", "table"),
        "headline_metric": info.get("headline_metric"), "has_paper": layout["has_paper"],
        "kendall_tau": tau["kendall_tau"], "n_rows": tau["n_rows"], "tau_rows": tau["rows"],
        "rows_paper": layout["rows_paper"], "rows_ours": layout["rows_ours"], "rows_both": layout["rows_both"],
        "claims": claims, "claims_total": len(claims), "counts": counts,
        "outputs": {"md": str(out_md), "csv": str(out_csv), "tex": str(out_tex)},
    }
    caption = _caption(info, registry, note)
    if noise:
        caption += (" Ours: mean ± std (over training seeds, or the bootstrap standard error over the test "
                    "units); claims are decided on 95 % intervals of these (see the README, 'Verdicts').")
    lines = _score_lines(score)
    for path in (out_md, out_csv, out_tex):
        Path(path).parent.mkdir(parents=True, exist_ok=True)
    raw.to_csv(out_csv, index=False)
    md = [f"# {info['title']}", "", caption, "", _md_table(display), ""]
    if lines:
        md += [f"**{lines[0]}**" if lines[0].startswith("Scorecard") else f"- {lines[0]}"]
        md += [f"- {line}" for line in lines[1:]]
        md += [""]
    Path(out_md).write_text("\n".join(md))
    Path(out_tex).write_text(_tex_table(display, info["title"], caption, table_id, lines))
    score_path = Path(out_md).with_name(f"{table_id}.score.json")
    score["outputs"]["score"] = str(score_path)
    score_path.write_text(json.dumps(score, indent=2, ensure_ascii=False, default=str) + "\n")
    return score


# ------------------------------------------------------------------------------------ scorecard
def write_scorecard(score_jsons: Iterable[str | Path], out_md, registry: dict | None = None) -> dict:
    """Gather ``<id>.score.json`` files into one Markdown scorecard: per table and in total, how many claims
    reproduce, are inconclusive, are contradicted, are not testable here, or are data descriptions; then
    every claim with its evidence.

    Returns a summary dict (counts). Registry tables without a score file are listed as not built.
    """
    registry = registry or load_registry()
    order = {t: i for i, t in enumerate(registry["tables"])}
    scores = [json.loads(Path(p).read_text()) for p in score_jsons]
    scores.sort(key=lambda s: (order.get(s["table_id"], len(order)), s["table_id"]))
    built = {s["table_id"] for s in scores}
    keys = [v.replace(" ", "_") for v in VERDICTS]
    total = {k: sum(s["counts"][k] for s in scores) for k in keys}
    by_stage: dict[str, dict[str, int]] = {}
    for s in scores:
        st = by_stage.setdefault(s["stage"], {k: 0 for k in keys})
        for k in keys:
            st[k] += s["counts"][k]
    taus = [s["kendall_tau"] for s in scores if s["kendall_tau"] is not None]
    paper_bad = [(s["table_id"], c["text"]) for s in scores for c in s["claims"]
                 if c["verdict"] in COUNTED and c.get("verdict_on_paper") not in (None, "reproduces")]
    listed_false = [(s["table_id"], c["text"]) for s in scores for c in s["claims"]
                    if c.get("on_our_data") == DOES_NOT_HOLD]
    tested = sum(total[v.replace(" ", "_")] for v in COUNTED)
    head = " | ".join(VERDICTS)
    md = ["# Scorecard: paper vs ours", "",
          f"{len(scores)} tables. Each claim of the theses is decided on our numbers with the measured noise "
          "(95 % Student-t intervals over the training seeds and, where a row keeps per-unit results, a cluster "
          "bootstrap over the test scenes; each verdict names what its interval covers; a cell without a noise "
          "record, or measured on fewer than 5 scenes, decides nothing): **reproduces** (the claimed effect is "
          "beyond the noise), **inconclusive** (inside the noise, a tie, or a cell missing: we could not tell), "
          "**thesis effect ruled out** (no effect beyond the noise, and the interval excludes the thesis' own "
          "effect on our scale), **contradicted** (the opposite effect is beyond the noise); **under-trained systems** "
          "(a comparison of models that val shows far from convergence: its measured outcome is shown, not counted); "
          "**not testable** (about prior "
          "work, real data, or contradicted by the thesis' own table) and **data description** (true by how "
          "the data were configured) are listed but not counted as results. Kendall τ = tau-b of our row "
          "ordering vs the paper's on the headline metric (n = rows in both).", "",
          f"**Total: {_counts_text(total)}**", "",
          f"{total['reproduces']} of {tested} counted claims reproduce"
          + (f"; mean τ {sum(taus) / len(taus):+.3f} over {len(taus)} tables." if taus else "."), "",
          "| stage | " + head + " |", "|:---|" + "---:|" * len(VERDICTS)]
    for stage, c in by_stage.items():
        md.append(f"| {stage} | " + " | ".join(str(c[k]) for k in keys) + " |")
    md += ["", "| table | stage | headline metric | τ (n) | " + head + " |",
           "|:---|:---|:---|---:|" + "---:|" * len(VERDICTS)]
    for s in scores:
        tau = f"{s['kendall_tau']:+.3f} ({s['n_rows']})" if s["kendall_tau"] is not None else f"n/a ({s['n_rows']})"
        md.append(f"| {s['table_id']} | {s['stage']} | {_md_cell(s['headline_metric'] or '—')} | {tau} | "
                  + " | ".join(str(s["counts"][k]) for k in keys) + " |")
    missing = [t for t in registry["tables"] if t not in built]
    if missing:
        md += ["", f"Not built: {', '.join(missing)}."]
    if paper_bad:
        md += ["", "Counted claims that do not reproduce on the paper's own numbers (transcription check): "
               + "; ".join(f"{t}: {x}" for t, x in paper_bad) + "."]
    if listed_false:
        md += ["", "Listed (uncounted) claims that do not hold on our data: "
               + "; ".join(f"{t}: {x}" for t, x in listed_false) + "."]
    md += ["", "## Claims", ""]
    for s in scores:
        if not s["claims"]:
            continue
        md += [f"### {s['table_id']}: {s['title']}", ""]
        for c in s["claims"]:
            paper = f" *(on the paper's numbers: {c['verdict_on_paper']})*" if "verdict_on_paper" in c else ""
            md.append(f"- {MARK[c['verdict']]} **{c['verdict']}**: {c['text']} — {c['evidence']}{paper}")
        md.append("")
    Path(out_md).parent.mkdir(parents=True, exist_ok=True)
    Path(out_md).write_text("\n".join(md))
    return {"tables": len(scores), "counts": total, "by_stage": by_stage, "paper_not_reproducing": paper_bad,
            "listed_not_holding": listed_false, "not_built": missing}
