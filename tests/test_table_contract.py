"""The one table contract: ids from tables.yaml, a config section per id, one rule writes every table, no code
branches on a table id, and the tiny build's scorecard counts the five verdict categories."""
import re
from pathlib import Path

import pytest

from redsup.tables import load_registry
from redsup.tables.contract import plan_module, table_ids

ROOT = Path(__file__).resolve().parents[1]
ID_LITERAL = re.compile(r"""["'](mccraith_ch\d_\w+|galteland_table\d_\d|data_summary)["']""")


def test_every_table_id_is_a_config_key():
    config = (ROOT / "config.yaml").read_text()
    missing = [t for t in table_ids() if not re.search(rf"^\s+{t}:", config, re.M)]
    assert not missing, f"table ids without a section in config.yaml: {missing}"


def test_every_stage_has_a_plan_module():
    reg = load_registry()
    for stage in {e["stage"] for e in reg["tables"].values()}:
        plan = plan_module(stage)
        for name in ("runs", "rows", "result_path", "table_frame"):
            assert callable(getattr(plan, name, None)), (stage, name)


def test_exactly_one_rule_writes_the_tables():
    writers = []
    for smk in sorted((ROOT / "workflow/rules").glob("*.smk")):
        for m in re.finditer(r"rule (\w+):(.*?)(?=\nrule |\Z)", smk.read_text(), re.S):
            output = m.group(2).split("log:")[0]
            if re.search(r'"results/tables/[^"]*\.md"', output):
                writers.append((smk.name, m.group(1)))
    # besides the one table rule: the scorecard and the run-time summary (fixed outputs, no thesis table)
    assert sorted(writers) == [("benchmarks.smk", "benchmark_summary"), ("tables.smk", "scorecard"),
                               ("tables.smk", "table")]


@pytest.mark.parametrize("folder", ["workflow/scripts", "workflow/redsup"])
def test_no_code_names_a_table_id(folder):
    """What differs between tables is configuration, never a branch on the id (ids live in tables.yaml,
    paper_values.csv and config.yaml)."""
    hits = []
    for path in sorted((ROOT / folder).rglob("*.py")):
        for i, line in enumerate(path.read_text().splitlines(), 1):
            if ID_LITERAL.search(line) and not line.lstrip().startswith("#"):
                hits.append(f"{path.relative_to(ROOT)}:{i}: {line.strip()}")
    assert not hits, "\n".join(hits)


def test_scorecard_counts_five_categories(built):
    text = (built / "results/tables/scorecard.md").read_text()
    assert re.search(r"\*\*Total: \d+ reproduces, \d+ inconclusive, \d+ contradicted, \d+ not testable, "
                     r"\d+ data description\*\*", text)
    for t in table_ids():
        assert f"| {t} |" in text, t
