"""Captions of ``snakemake --report``: for every table and figure, the thesis' table as tables.yaml describes it
(title, what it shows, where it is printed) and our verdict (the claims' outcome from
``results/tables/<id>.score.json`` when that table has been built).

Snakemake reads one caption file per rule and renders it with Jinja2 for each output (``snakemake.wildcards``
is in scope), so ``write_caption_template`` writes one file whose ``{% if %}`` branches hold every id's caption.
The Snakefile writes it when it is parsed (``snakemake --report`` parses first, so the verdicts are those of
the tables on disk) and only when its text changes. Torch-free.
"""
from __future__ import annotations

import json
import os
import re
import tempfile
from collections.abc import Iterable, Mapping
from pathlib import Path

from redsup.tables.registry import load_registry

_RST_SPECIAL = re.compile(r"([\\`*_|])")


def rst_escape(text: str) -> str:
    """Plain text safe inside reStructuredText (no emphasis, links or substitutions by accident)."""
    return _RST_SPECIAL.sub(r"\\\1", str(text))


def _verdict(score: Mapping | None) -> list[str]:
    if score is None:
        return ["*Our verdict*: not built yet (run the table's target, then the report again)."]
    counts = score.get("counts", {})
    claims = score.get("claims", [])
    head = [f"{counts.get(k, 0)} {k.replace('_', ' ')}" for k in
            ("reproduces", "inconclusive", "contradicted", "not_testable", "data_description")]
    lines = [f"*Our verdict* on the thesis' {len(claims)} claims: " + rst_escape(", ".join(head)) + "."]
    if score.get("kendall_tau") is not None:
        lines.append(f"Kendall tau of our row order against the thesis' on {rst_escape(score['headline_metric'])}: "
                     f"{score['kendall_tau']:+.3f} (n = {score['n_rows']} rows).")
    lines.append("")
    for claim in claims:
        lines.append(f"- **{rst_escape(claim.get('verdict', 'n/a'))}**: {rst_escape(claim.get('text', ''))}")
    return lines


def caption(table_id: str, score: Mapping | None = None, registry: dict | None = None) -> str:
    """The reStructuredText caption of one table or figure id of tables.yaml."""
    reg = registry or load_registry()
    info = reg["tables"][table_id]
    lines = [f"**{rst_escape(info['title'])}** ({rst_escape(table_id)}).", "",
             rst_escape(info.get("description", "").rstrip(".")) + "."]
    src = info.get("source")
    if src:
        doc = reg.get("documents", {}).get(src["document"], src["document"])
        lines.append(f"Printed as {rst_escape(src['label'])} in {rst_escape(doc)} (line {src['line']}); "
                     "the thesis' values stand beside ours in the table.")
    else:
        lines.append("Ours only (the thesis has no such table).")
    lines += [""] + _verdict(score)
    return "\n".join(lines) + "\n"


def template(wildcard: str, captions: Mapping[str, str], fallback: str = "") -> str:
    """A Jinja2 caption template choosing ``captions[snakemake.wildcards.<wildcard>]``."""
    out = []
    for i, (key, text) in enumerate(captions.items()):
        keyword = "if" if i == 0 else "elif"
        out.append(f"{{% {keyword} snakemake.wildcards.{wildcard} == {json.dumps(key)} %}}")
        out.append("{% raw %}" + text + "{% endraw %}")
    if captions:
        out.append("{% else %}")
    out.append("{% raw %}" + fallback + "{% endraw %}")
    if captions:
        out.append("{% endif %}")
    return "\n".join(out) + "\n"


def _write_if_changed(path: Path, text: str) -> None:
    if path.is_file() and path.read_text() == text:
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    with os.fdopen(fd, "w") as fh:
        fh.write(text)
    os.replace(tmp, path)  # parallel parses write the same text; none sees half a file


def read_score(tables_dir: str | Path, table_id: str) -> dict | None:
    path = Path(tables_dir) / f"{table_id}.score.json"
    try:
        return json.loads(path.read_text())
    except (OSError, json.JSONDecodeError):
        return None


def write_caption_template(path: str | Path, wildcard: str, ids: Iterable[str],
                           tables_dir: str | Path = "results/tables") -> str:
    """Write (if changed) the caption template of the outputs whose ``wildcard`` is one of ``ids``; returns
    its absolute path (what ``report(caption=...)`` takes)."""
    reg = load_registry()
    captions = {t: caption(t, read_score(tables_dir, t), reg) for t in ids}
    path = Path(path).resolve()
    _write_if_changed(path, template(wildcard, captions, fallback="A result of the reproduction workflow."))
    return str(path)


def write_caption(path: str | Path, text: str) -> str:
    """A fixed caption (an output without wildcards); returns its absolute path."""
    path = Path(path).resolve()
    _write_if_changed(path, text if text.endswith("\n") else text + "\n")
    return str(path)
