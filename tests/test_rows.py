"""The one row grammar of every stage (redsup.tables.rows): hand cases, and every stage's config reads it."""
import re
from pathlib import Path

import pytest

from redsup import config as config_lib
from redsup.fileio import yaml_load
from redsup.tables.contract import config_sections
from redsup.tables.registry import load_registry
from redsup.tables.rows import expand, fill, run_rows, swept_fields

ROOT = Path(__file__).resolve().parents[1]


def test_sweep_expands_in_order_last_field_fastest_with_refs():
    table = {"lrs": [0.1, 10.0], "steps": 5,
             "rows": [{"label": "baseline", "template": {"groups": []}},
                      {"label": "{lr}/{k}", "template": {"steps": "$steps"}, "sweep": {"lr": "$lrs", "k": [1, 2]}}]}
    rows = expand(table, "t")
    assert [(r.label, r.run, r.fields) for r in rows] == [
        ("baseline", None, {"groups": []}),
        ("{lr}/{k}", None, {"steps": 5, "lr": 0.1, "k": 1}),
        ("{lr}/{k}", None, {"steps": 5, "lr": 0.1, "k": 2}),
        ("{lr}/{k}", None, {"steps": 5, "lr": 10.0, "k": 1}),
        ("{lr}/{k}", None, {"steps": 5, "lr": 10.0, "k": 2})]
    assert [fill(r.label, r.fields) for r in rows[1:]] == ["0.1/1", "0.1/2", "10/1", "10/2"]  # floats as %g


def test_run_rows_format_labels_and_carry_swept_parameters():
    table = {"values": [0.5, 3], "rows": [{"label": "(d) Ours", "run": "ours"},
                                          {"label": "{width}", "run": "ours", "sweep": {"width": "$values"}}]}
    assert run_rows(table, "t") == [("(d) Ours", "ours", {}), ("0.5", "ours", {"width": 0.5}),
                                    ("3", "ours", {"width": 3})]
    assert swept_fields(table) == ["width"]
    assert run_rows({"counts": ["train"]}, "t") == []          # a table without rows
    with pytest.raises(ValueError, match=r"t\.rows: unknown configurations \['nope'\] \(defined: \['ours'\]\)"):
        run_rows({"rows": [{"label": "x", "run": "nope"}, {"label": "y", "run": "ours"}]}, "t", ["ours"])


def test_named_formatters_and_literal_braces():
    assert fill("{lr|power}", {"lr": 0.001}, {"power": lambda v: f"10^{round(__import__('math').log10(v))}"}) \
        == "10^-3"
    assert fill("SIC_{5,2.5}", {}) == "SIC_{5,2.5}"            # not a field: kept as printed
    with pytest.raises(KeyError, match="unknown field 'lr'"):
        fill("{lr}", {})
    with pytest.raises(KeyError, match="unknown formatter 'nope'"):
        fill("{lr|nope}", {"lr": 1.0})


@pytest.mark.parametrize("row, message", [
    ({"label": "x"}, "exactly one of run and template"),
    ({"label": "x", "run": "a", "template": {}}, "exactly one of run and template"),
    ({"run": "a"}, "no label"),
    ({"label": "x", "run": "a", "each": {"lr": [1]}}, r"unknown key\(s\) \['each'\]"),
    ({"label": "x", "run": "a", "sweep": {"lr": "$nope"}}, r"\$nope names no value of the table section"),
    ("a", "a row is a mapping"),
])
def test_malformed_rows_are_named(row, message):
    with pytest.raises(KeyError, match=message) as err:
        expand({"rows": [row]}, "calibration.tables.t")
    assert "calibration.tables.t.rows[0]" in str(err.value)


def test_template_fields_are_checked_when_the_stage_names_them():
    table = {"rows": [{"label": "x", "template": {"lr": 1.0}, "sweep": {"stepz": [1]}}]}
    with pytest.raises(KeyError, match=r"unknown field\(s\) \['stepz'\]"):
        expand(table, "depth.tables.t", template_fields=("lr", "step"))


def test_every_table_with_rows_in_the_config_uses_the_grammar():
    """Each stage's table sections (base and profiles) write rows as a list of {label, run | template, sweep}:
    no other row shape is left in config.yaml."""
    raw = yaml_load((ROOT / "config.yaml").read_text())
    n = 0
    for profile in config_lib.PROFILES:
        cfg = config_lib.resolve({**raw, "profile": profile})
        for section in config_sections(load_registry()):
            for table_id, table in cfg[section]["tables"].items():
                if "rows" not in table:
                    continue
                assert isinstance(table["rows"], list), (profile, section, table_id)
                for row in table["rows"]:
                    assert set(row) <= {"label", "run", "template", "sweep"} and ("run" in row) != ("template" in row)
                    n += 1
                assert expand(table, f"{section}.tables.{table_id}")
    assert n > 100


def test_the_schemas_share_one_row_shape():
    """Every stage's schema reads its rows from rows.schema.yaml, except depth, whose rows have a typed template
    (the same keys)."""
    schemas = ROOT / "workflow" / "schemas"
    shared = yaml_load((schemas / "rows.schema.yaml").read_text())
    assert set(shared["items"]["properties"]) == {"label", "run", "template", "sweep"}
    for name in ("velocity", "calibration", "lifting", "lidar_detector"):
        assert re.search(r"rows: \{\$ref: rows\.schema\.yaml\}", (schemas / f"{name}.schema.yaml").read_text()), name
    depth = yaml_load((schemas / "depth.schema.yaml").read_text())
    assert set(depth["$defs"]["row"]["properties"]) == {"label", "template", "sweep"}
