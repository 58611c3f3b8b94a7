"""Adding a table is data (docs/adding_a_stage.md, "Add a table"; this test is its worked example).

A toy ch. 5 table, a road-box width sweep over two of Table 4's widths, is added to a copy of the workflow by
two edits and nothing else: its entry (with a claim) appended to tables.yaml, and its section appended to
``calibration.tables`` in config.yaml. The copy then builds the toy under the tiny profile in a working directory
that starts from the session's tiny build (conftest ``tiny``): the toy reuses Table 4's calibration runs, so the
only job is the toy's ``table`` job, and its numbers are Table 4's. Had the toy needed code (an id list in a
rule, a schema or a module), the copy would fail to parse or to build it.
"""
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
import yaml

from conftest import ROOT
from redsup import config as redsup_config
from redsup.fileio import yaml_load
from redsup.tables.claims import COUNTED

pytestmark = pytest.mark.workflow

TOY = "toy_ch5_width"
REFERENCE = "mccraith_ch5_table4"   # the real table whose runs (widths 1 and 3 m of the tiny profile) the toy reads
# the toy's config section: calibration.tables.toy_ch5_width (the one row grammar: a row of `ours` swept over widths)
TOY_WIDTHS = [1, 3]
TOY_CONFIG = {"rows": [{"label": "{width}", "run": "ours", "sweep": {"width": TOY_WIDTHS}}],
              "note": "toy: road points with |X| < width and Z < {length:g} m"}
CLAIM = "Toy: the 3 m road box beats the 1 m one"
# its tables.yaml entry (no paper values: the table shows ours only, as data_summary does)
TOY_ENTRY = f"""
  {TOY}:
    title: "Toy road-box width sweep"
    kind: table
    stage: calibration
    source: null
    description: "Two widths of Table 4's road box, added through tables.yaml and config.yaml alone"
    headline_metric: Abs Rel
    row_key: "width in metres"
    claims:
      - text: "{CLAIM}"
        check: {{type: order, better: "3", worse: "1", direction: lower}}
"""
METRICS = ("Abs Rel", "Sq Rel", "RMSE", "RMSE log", "δ < 1.25", "δ < 1.25^2", "δ < 1.25^3")
# written in place by the MLflow sync: copied; every other result file is only ever replaced, so it is linked
COPIED = ("mlflow.db", "mlflow", "mlartifacts")


def _copy_workflow(dst: Path) -> None:
    """The repository's workflow (Snakefile, config, envs, Snakemake profiles, workflow/) without caches."""
    dst.mkdir(parents=True)
    for name in ("Snakefile", "config.yaml"):
        shutil.copy2(ROOT / name, dst / name)
    ignore = shutil.ignore_patterns("__pycache__", "*.egg-info")
    for name in ("envs", "profiles", "workflow"):
        shutil.copytree(ROOT / name, dst / name, ignore=ignore)


def _add_toy(repo: Path) -> None:
    """The two edits of "Add a table": the tables.yaml entry and the config section (appended last, so the
    calibration runs the toy shares keep Table 4 as their MLflow parent and nothing of theirs changes)."""
    registry = repo / "workflow" / "redsup" / "data" / "tables.yaml"
    text = registry.read_text()
    assert list(yaml_load(text))[-1] == "tables", "tables.yaml no longer ends with its tables: section"
    registry.write_text(text.rstrip("\n") + "\n" + TOY_ENTRY)
    config_path = repo / "config.yaml"
    config = yaml_load(config_path.read_text())
    sweep = redsup_config.resolve({**config, "profile": "tiny"})["calibration"]["tables"][REFERENCE]
    assert set(TOY_WIDTHS) <= set(sweep["values"]), \
        f"the tiny profile's {REFERENCE} no longer has the widths {TOY_WIDTHS} the toy reuses: {sweep}"
    tiny = config["profiles"]["tiny"].get("calibration", {}).get("tables", {})
    assert TOY not in config["calibration"]["tables"] and TOY not in tiny
    config["calibration"]["tables"][TOY] = TOY_CONFIG
    config_path.write_text(yaml.safe_dump(config, sort_keys=False, allow_unicode=True))


def _link_tree(src: Path, dst: Path) -> None:
    try:
        shutil.copytree(src, dst, copy_function=os.link, symlinks=True)
    except OSError:  # another file system: copy
        shutil.rmtree(dst, ignore_errors=True)
        shutil.copytree(src, dst, symlinks=True)


def _start_from(build: Path, work: Path) -> None:
    """A working directory holding the build's results (linked; the MLflow store copied) and Snakemake's
    metadata (copied: Snakemake rewrites a record in place), so that only new jobs run."""
    (work / "results").mkdir(parents=True)
    for entry in (build / "results").iterdir():
        target = work / "results" / entry.name
        if entry.name in COPIED:
            (shutil.copytree if entry.is_dir() else shutil.copy2)(entry, target)
        elif entry.is_dir():
            _link_tree(entry, target)
        else:
            os.link(entry, target)
    shutil.copytree(build / ".snakemake", work / ".snakemake", ignore=shutil.ignore_patterns("locks"))


def _job_stats(log: str) -> dict[str, int]:
    """Snakemake's 'Job stats' block: rule -> number of jobs (empty when nothing ran)."""
    lines = log.splitlines()
    if "Job stats:" not in lines:
        return {}
    out = {}
    for line in lines[lines.index("Job stats:") + 3:]:
        parts = line.split()
        if len(parts) != 2 or parts[0] == "total":
            break
        out[parts[0]] = int(parts[1])
    return out


def _frame(path: Path) -> pd.DataFrame:
    df = pd.read_csv(path, dtype=str, keep_default_na=False)
    return df.set_index(df.columns[0])


@pytest.fixture(scope="module")
def toy(tiny, tmp_path_factory):
    """(working directory, Snakemake's output) after building the toy table with the edited copy."""
    if not (tiny / "results" / "tables" / f"{REFERENCE}.csv").exists():
        pytest.fail(f"{tiny} is not a finished tiny build (no {REFERENCE}.csv)")
    base = tmp_path_factory.mktemp("toy_table")
    repo, work = base / "repo", base / "work"
    _copy_workflow(repo)
    _add_toy(repo)
    _start_from(tiny, work)
    # the Snakefile process imports the copy's redsup (PYTHONPATH comes before the venv's editable install);
    # the Snakefile puts the same folder first on the jobs' PYTHONPATH (redsup.jobenv.put_on_pythonpath)
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        p for p in (str(repo / "workflow"), os.environ.get("PYTHONPATH")) if p)}
    proc = subprocess.run(
        [sys.executable, "-m", "snakemake", "--snakefile", str(repo / "Snakefile"), "--cores", "2",
         "--directory", str(work), f"results/tables/{TOY}.md", "--config", "profile=tiny"],
        capture_output=True, text=True, timeout=1200, env=env, cwd=base)
    log = proc.stdout + proc.stderr
    assert proc.returncode == 0, f"building the toy table failed:\n{log[-8000:]}"
    return work, log


def test_the_toy_is_built_by_its_table_job_alone(toy, tiny):
    work, log = toy
    assert _job_stats(log) == {"table": 1}, log[-4000:]
    tables = work / "results" / "tables"
    for ext in ("md", "csv", "tex", "score.json"):
        assert (tables / f"{TOY}.{ext}").stat().st_size > 0, ext
    assert "Toy road-box width sweep" in (tables / f"{TOY}.md").read_text()
    assert list(_frame(tables / f"{TOY}.csv").index) == ["1", "3"]   # one row per configured width, in order
    # the calibration results it reads are the build's own files, not rewritten
    reads = sorted((work / "results" / "calibration").rglob("road_L*_W[13].json"))
    assert reads, "no road-box results of widths 1 and 3"
    for path in reads:
        assert path.samefile(tiny / path.relative_to(work)), path
    # the real table was not rebuilt either
    assert (tables / f"{REFERENCE}.csv").samefile(tiny / "results" / "tables" / f"{REFERENCE}.csv")


def test_the_toy_rows_are_those_of_table_4(toy):
    work, _ = toy
    tables = work / "results" / "tables"
    ours, ref = _frame(tables / f"{TOY}.csv"), _frame(tables / f"{REFERENCE}.csv")
    assert ours.index.name == ref.index.name == "Width (m)"
    assert "status" not in ours.columns and not any("(paper)" in c for c in ours.columns)  # no paper values
    for metric in METRICS:
        for row in ("1", "3"):
            assert ours.at[row, metric] != "", (row, metric)
            assert float(ours.at[row, metric]) == float(ref.at[row, f"{metric} (ours)"]), (row, metric)
            assert float(ours.at[row, f"{metric} std"]) == float(ref.at[row, f"{metric} (ours) std"]), (row, metric)


def test_the_toy_claim_is_decided_on_its_rows(toy):
    work, _ = toy
    tables = work / "results" / "tables"
    score = json.loads((tables / f"{TOY}.score.json").read_text())
    assert (score["table_id"], score["stage"], score["has_paper"], score["rows_ours"]) == (TOY, "calibration",
                                                                                           False, 2)
    (claim,) = score["claims"]
    assert claim["text"] == CLAIM
    assert claim["verdict"] in COUNTED, claim  # decided on our numbers (not 'not testable', no paper needed)
    assert claim["evidence"].startswith("Abs Rel: 3 "), claim["evidence"]
    (margin,) = claim["margins"]
    ours = _frame(tables / f"{TOY}.csv")
    assert margin["comparison"] == "3 vs 1"
    assert margin["margin"] == pytest.approx(float(ours.at["1", "Abs Rel"]) - float(ours.at["3", "Abs Rel"]))
    assert sum(score["counts"].values()) == 1 and score["counts"][claim["verdict"].replace(" ", "_")] == 1
    assert CLAIM in (tables / f"{TOY}.md").read_text()
