"""Table ids are listed in tables.yaml and appear elsewhere only as the config keys of their rows: the schemas
check a table section's shape without naming an id, ``redsup.tables.contract.check_config_tables`` (called by
common.smk right after ``redsup.config.resolve``) checks that each key of a section's ``tables:`` is an id of
the section's stages (tables.yaml ``stage_config:``) and that every such id has its section."""
import copy
import re
from pathlib import Path

import pytest

from conftest import run_snakemake
from redsup import config as config_lib
from redsup.fileio import yaml_load
from redsup.tables import load_registry
from redsup.tables.contract import check_config_tables, config_sections

ROOT = Path(__file__).resolve().parents[1]
SCHEMAS = ROOT / "workflow" / "schemas"


def raw_config() -> dict:
    return yaml_load((ROOT / "config.yaml").read_text())


def load_as_the_workflow(raw: dict) -> dict:
    """What common.smk does with the config: resolve the profile, then check the table sections."""
    cfg = config_lib.resolve(raw)
    check_config_tables(cfg)
    return cfg


def test_no_schema_names_a_table_id():
    ids = sorted(load_registry()["tables"], key=len, reverse=True)
    pattern = re.compile(r"(?<![A-Za-z0-9_])(" + "|".join(map(re.escape, ids)) + r")(?![A-Za-z0-9_])")
    hits = [f"{path.name}:{i}: {line.strip()}"
            for path in sorted(SCHEMAS.glob("*.yaml"))
            for i, line in enumerate(path.read_text().splitlines(), 1) if pattern.search(line)]
    assert not hits, "\n".join(hits)


def test_every_stage_has_a_config_section_with_tables():
    reg = load_registry()
    sections = config_sections(reg)
    assert sorted(s for stages in sections.values() for s in stages) == sorted(reg["stages"])
    schema = config_lib.load_schema()
    for section in sections:
        assert "tables" in schema["properties"][section]["properties"], section
    # and no section outside stage_config has tables (they would go unchecked)
    with_tables = {s for s, body in raw_config().items() if isinstance(body, dict) and "tables" in body}
    assert with_tables == set(sections)


@pytest.mark.parametrize("profile", config_lib.PROFILES)
def test_the_real_config_passes(profile):
    cfg = load_as_the_workflow({**raw_config(), "profile": profile})
    assert cfg["profile"] == profile


def test_a_misspelled_table_key_is_named_with_the_nearest_id():
    raw = raw_config()
    tables = raw["calibration"]["tables"]
    tables["mccraith_ch5_tabel1"] = tables.pop("mccraith_ch5_table1")
    with pytest.raises(config_lib.ConfigError) as err:
        load_as_the_workflow(raw)
    text = str(err.value)
    assert "config.yaml" in text
    assert "calibration.tables.mccraith_ch5_tabel1 is not a table id" in text
    assert re.search(r"nearest: mccraith_ch5_table1\b", text), text
    # the id it replaced is now missing, and that is said too
    assert re.search(r"calibration\.tables has no section for mccraith_ch5_table1\b", text), text


def test_an_id_of_another_stage_is_rejected():
    raw = raw_config()
    raw["calibration"]["tables"]["mccraith_ch4_table1"] = {"series": "test"}  # a valid calibration shape
    config_lib.resolve(copy.deepcopy(raw))  # the schema lets the shape through ...
    with pytest.raises(config_lib.ConfigError,
                       match=r"calibration\.tables\.mccraith_ch4_table1 is a table of stage depth, "
                             r"configured under depth\.tables"):
        load_as_the_workflow(raw)                # ... the table contract does not


def test_galteland_ids_belong_to_the_depth_section():
    raw = raw_config()
    raw["lifting"]["tables"]["galteland_table4_1"] = {"rows": [{"label": "x", "run": next(iter(raw["lifting"]["runs"]))}]}
    with pytest.raises(config_lib.ConfigError, match=r"stage galteland, configured under depth\.tables"):
        load_as_the_workflow(raw)


def test_an_id_without_its_section_is_named():
    raw = raw_config()
    del raw["lifting"]["tables"]["mccraith_ch6_table2"]
    with pytest.raises(config_lib.ConfigError, match=r"lifting\.tables has no section for mccraith_ch6_table2\b"):
        load_as_the_workflow(raw)


def test_a_misspelled_key_inside_a_table_section_is_still_named():
    """A stage with several table shapes (oneOf): the error names the key of the shape the section meant."""
    raw = raw_config()
    raw["velocity"]["tables"]["mccraith_ch3_table2"]["layot"] = "errors"
    with pytest.raises(config_lib.ConfigError,
                       match=r"velocity\.tables\.mccraith_ch3_table2: .*'layot' was unexpected"):
        config_lib.resolve(raw)


def test_the_workflow_stops_on_a_misspelled_table_key(tmp_path):
    """common.smk calls the check: a dry run with a misspelled table key fails at parse time, naming it."""
    extra = tmp_path / "extra.yaml"
    extra.write_text("calibration:\n  tables:\n    mccraith_ch5_tabel1: {series: test}\n")
    proc = run_snakemake(tmp_path / "w", "-n", "-q", "all", "--configfile", str(ROOT / "config.yaml"), str(extra),
                         check=False)
    assert proc.returncode != 0
    out = proc.stdout + proc.stderr
    assert "calibration.tables.mccraith_ch5_tabel1 is not a table id" in out, out[-3000:]
    assert "nearest: mccraith_ch5_table1" in out
