"""`snakemake --report` on the tiny build (conftest.built): every table and figure of tables.yaml is in it, with
the thesis' caption and our verdict, one category per stage; and the caption templates on hand-made scores."""
from __future__ import annotations

import base64
import json
import re
import zlib

import pytest

from conftest import run_snakemake
from redsup import report as report_captions
from redsup.tables.registry import load_registry


def test_caption_has_the_thesis_table_and_our_verdict():
    reg = load_registry()
    score = {"counts": {"reproduces": 1, "inconclusive": 0, "contradicted": 1, "not_testable": 0,
                        "data_description": 0},
             "claims": [{"text": "A beats B", "verdict": "reproduces"}, {"text": "C_x *is* best", "verdict": "contradicted"}],
             "kendall_tau": 0.5, "headline_metric": "E_v", "n_rows": 3}
    text = report_captions.caption("mccraith_ch3_table2", score, reg)
    assert "**Vehicle velocity estimation error E\\_v (McCraith ch. 3, Table II)**" in text
    assert "Ch. 3 TABLE II" in text and "(line 471)" in text
    assert "1 reproduces, 0 inconclusive, 1 contradicted" in text and "+0.500 (n = 3 rows)" in text
    assert "- **contradicted**: C\\_x \\*is\\* best" in text
    assert "not built yet" in report_captions.caption("mccraith_ch3_table2", None, reg)


def test_caption_template_renders_per_wildcard(tmp_path):
    import jinja2

    path = report_captions.write_caption_template(tmp_path / "t.rst", "table", ["data_summary", "mccraith_ch3_table1"],
                                                  tables_dir=tmp_path)
    mtime = (tmp_path / "t.rst").stat().st_mtime_ns
    report_captions.write_caption_template(tmp_path / "t.rst", "table", ["data_summary", "mccraith_ch3_table1"],
                                           tables_dir=tmp_path)
    assert (tmp_path / "t.rst").stat().st_mtime_ns == mtime  # unchanged text: not rewritten
    template = jinja2.Environment(trim_blocks=True, lstrip_blocks=True).from_string(open(path).read())

    class Job:
        def __init__(self, table):
            self.wildcards = type("W", (), {"table": table})()

    assert "Annotated vehicles per distance range" in template.render(snakemake=Job("mccraith_ch3_table1"))
    assert "Prepared data summary" in template.render(snakemake=Job("data_summary"))
    assert "Prepared data summary" not in template.render(snakemake=Job("mccraith_ch3_table1"))
    assert template.render(snakemake=Job("other")).strip() == "A result of the reproduction workflow."


def _report_payload(html: str) -> str:
    """The report's text plus any embedded base64 / zlib blobs decoded (Snakemake embeds its data in the page)."""
    parts = [html]
    for blob in re.findall(r"[A-Za-z0-9+/=]{200,}", html):
        try:
            raw = base64.b64decode(blob)
        except ValueError:
            continue
        for decode in (lambda b: b, zlib.decompress, lambda b: zlib.decompress(b, 16 + zlib.MAX_WBITS)):
            try:
                parts.append(decode(raw).decode("utf-8", "ignore"))
            except zlib.error:
                pass
    return "\n".join(parts)


@pytest.mark.workflow
def test_report_lists_every_table_and_figure(built):
    out = built / "results" / "report.html"
    run_snakemake(built, "--report", str(out))
    html = _report_payload(out.read_text())
    reg = load_registry()
    for table_id, info in reg["tables"].items():
        assert f"{table_id}.md" in html and f"{table_id}.csv" in html, table_id
        if info.get("kind") == "figure":
            assert f"{table_id}.png" in html, table_id
        assert json.dumps(info["title"])[1:-1].split(" (")[0] in html or info["title"].split(" (")[0] in html, table_id
    assert html.count("Our verdict") >= len(reg["tables"])
    assert "not built yet" not in html
    for stage in {info["stage"] for info in reg["tables"].values()}:
        assert f"{stage}:" in html or f'"{stage}"' in html, stage
    for name in ("run_time.md", "run_time.png", "scorecard.md", "world_frame_overview.png"):
        assert name in html
