"""The one table contract: ids from tables.yaml, a config section per id, one rule writes every table, no code
branches on a table id (whole or in part: ``table_id.endswith("table2")`` is a branch on an id too), and the tiny
build's scorecard counts the five verdict categories."""
import ast
import re
from pathlib import Path

import pytest

from redsup.tables import load_registry
from redsup.tables.contract import plan_module, table_ids

ROOT = Path(__file__).resolve().parents[1]
ID_LITERAL = re.compile(r"""["'](mccraith_ch\d_\w+|galteland_table\d_\d|data_summary)["']""")
# str methods that match a string against a literal: a table id matched this way is matched in part
MATCHERS = {"startswith", "endswith", "removeprefix", "removesuffix", "find", "rfind"}


def id_part(text: str, ids) -> str | None:
    """The table id that ``text`` is, or is a part of that names tables (a part with a digit, 'table2', 'ch7_',
    or with a word on each side of an underscore, 'mccraith_ch'); None when it is neither."""
    if text in ids:
        return text
    if len(text) < 3 or not (re.search(r"\d", text) or re.search(r"[a-z]_[a-z]", text)):
        return None
    return next((t for t in ids if text in t), None)


def _strings(node: ast.AST) -> list[ast.Constant]:
    """The string constants of a literal: itself, the items of a tuple / list / set, the fixed parts of an
    f-string."""
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        return [c for e in node.elts for c in _strings(e)]
    if isinstance(node, ast.JoinedStr):
        return [c for c in node.values if isinstance(c, ast.Constant)]
    return [node] if isinstance(node, ast.Constant) and isinstance(node.value, str) else []


def id_matches(source: str, ids) -> list[tuple[int, str, str]]:
    """(line, literal, table id) of every string literal that something is matched against (an argument of
    ``startswith`` / ``endswith`` / ..., a side of ==, !=, in, not in) and that is a table id, whole or in
    part (`id_part`)."""
    out = []
    for node in ast.walk(ast.parse(source)):
        operands: list[ast.AST] = []
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in MATCHERS:
            operands = node.args
        elif isinstance(node, ast.Compare) and any(isinstance(op, (ast.Eq, ast.NotEq, ast.In, ast.NotIn))
                                                   for op in node.ops):
            operands = [node.left, *node.comparators]
        for operand in operands:
            for const in _strings(operand):
                table = id_part(const.value, ids)
                if table is not None:
                    out.append((const.lineno, const.value, table))
    return sorted(out)


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
    # besides the one table rule: the scorecard, the power report and the run-time summary (fixed outputs, no
    # thesis table)
    assert sorted(writers) == [("benchmarks.smk", "benchmark_summary"), ("tables.smk", "power"),
                               ("tables.smk", "scorecard"), ("tables.smk", "table")]


@pytest.mark.parametrize("folder", ["workflow/scripts", "workflow/redsup"])
def test_no_code_names_a_table_id(folder):
    """What differs between tables is configuration, never a branch on the id (ids live in tables.yaml,
    paper_values.csv and config.yaml)."""
    ids = set(table_ids())
    hits = []
    for path in sorted((ROOT / folder).rglob("*.py")):
        text = path.read_text()
        for i, line in enumerate(text.splitlines(), 1):
            if ID_LITERAL.search(line) and not line.lstrip().startswith("#"):
                hits.append(f"{path.relative_to(ROOT)}:{i}: {line.strip()}")
        hits += [f"{path.relative_to(ROOT)}:{i}: matches {literal!r} (of {table})"
                 for i, literal, table in id_matches(text, ids)]
    assert not hits, "\n".join(hits)


@pytest.mark.parametrize("code", [
    'if table_id.endswith("table2"): pass',
    'if table_id.endswith(("_table2", "_table3")): pass',
    'if table_id.startswith("mccraith_ch7"): pass',
    'if table_id.startswith(f"galteland_table{k}"): pass',
    'if "ch7_table" in table_id: pass',
    'if table_id == "mccraith_ch7_table2": pass',
    'x = [t for t in ids if t.removesuffix("_fig6") != t]',
])
def test_a_table_id_matched_in_part_is_caught(code):
    """A branch on part of an id names the table as surely as the whole id: the check above rejects it."""
    assert id_matches(code, set(table_ids())), code


@pytest.mark.parametrize("code", [
    'if kind == "table": pass',
    'if run.startswith("figure_"): pass',
    'if table_id in config["depth"]["tables"]: pass',
    'rng = derive_seed(seed, "velocity", "fig6")',  # a name, not a match against an id
    'if name.endswith("_seed1"): pass',
])
def test_matching_what_is_no_table_id_is_not_caught(code):
    assert not id_matches(code, set(table_ids())), code


def test_id_part_is_whole_or_a_naming_part():
    ids = {"mccraith_ch7_table2", "galteland_table4_1", "data_summary"}
    assert id_part("mccraith_ch7_table2", ids) == "mccraith_ch7_table2"
    assert id_part("table2", ids) == id_part("_table2", ids) == id_part("mccraith_ch", ids) == "mccraith_ch7_table2"
    assert id_part("table4_1", ids) == "galteland_table4_1"
    assert id_part("mccraith_ch7_table22", ids) is None  # longer than an id: not a part of one
    assert id_part("table", ids) is None and id_part("summary", ids) is None and id_part("e2", ids) is None


def test_scorecard_counts_seven_categories(built):
    text = (built / "results/tables/scorecard.md").read_text()
    assert re.search(r"\*\*Total: \d+ reproduces, \d+ inconclusive, \d+ thesis effect ruled out, \d+ contradicted, "
                     r"\d+ under-trained systems, \d+ not testable, \d+ data description\*\*", text)
    for t in table_ids():
        assert f"| {t} |" in text, t
