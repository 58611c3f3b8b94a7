"""Issue 15: the MLflow UI, checked as a person would see it.

`mlflow server` over a copy of the tiny build's store (results/mlflow.db; the experiments' artifact
locations are absolute, so they still point into the build, read only), three pages rendered by headless
Chromium (`--dump-dom` waits for the React app through `--virtual-time-budget`, which pauses while the
app's requests are pending):

1. the experiments list shows every `redsup/` experiment;
2. a table's parent run shows its name, its experiment and every child run (`mlflow.parentRunId`) under
   "Child runs", each a link to the child's page;
3. a child's metric page (a training curve such as a loss) shows the run, the metric and a plotted line
   through every logged (step, value) point, with the latest / min / max values of the store.

What should be seen is read from the store with MlflowClient first. Skips only where no Chromium is found
($REDSUP_CHROMIUM, chromium, chromium-browser, google-chrome).
"""
import json
import math
import re
import subprocess
import time
from html.parser import HTMLParser
from urllib.parse import quote

import numpy as np
import pytest

from redsup.mlflow_ui import copy_store, find_chromium, mlflow_server

pytestmark = pytest.mark.workflow

TABLE_PARENT = "mccraith_ch7_table3"        # preferred; any table parent with children otherwise


@pytest.fixture(scope="module")
def chromium():
    path = find_chromium()
    if path is None:
        pytest.skip("no Chromium found (apt-get install chromium, or set $REDSUP_CHROMIUM)")
    return path


@pytest.fixture(scope="module")
def store(tiny, tmp_path_factory):
    """A consistent copy of the build's store (sqlite backup: the server may migrate or write to it)."""
    return copy_store(tiny / "results" / "mlflow.db", tmp_path_factory.mktemp("mlflow_ui") / "mlflow.db")


@pytest.fixture(scope="module")
def server(chromium, store):
    """`mlflow server` over the copy, on a free port of 127.0.0.1; its URL."""
    with mlflow_server(f"sqlite:///{store}", store.parent,
                       env={"MLFLOW_DISABLE_TELEMETRY": "true", "DO_NOT_TRACK": "true"}) as url:
        yield url


# ----------------------------------------------------------------------------- what should be seen
@pytest.fixture(scope="module")
def expected(store):
    """Experiment names, one table parent with its children, one child's step curve, from the store."""
    from mlflow.tracking import MlflowClient

    client = MlflowClient(tracking_uri=f"sqlite:///{store}")
    experiments = {e.experiment_id: e.name for e in client.search_experiments()}
    redsup = sorted(n for n in experiments.values() if n.startswith("redsup/"))
    assert redsup, experiments
    runs = client.search_runs(list(experiments), max_results=50000)
    by_id = {r.info.run_id: r for r in runs}
    children = {}
    for r in runs:
        parent = r.data.tags.get("mlflow.parentRunId")
        if parent in by_id:
            children.setdefault(parent, []).append(r)
    assert children, "no run has children (mlflow.parentRunId)"

    def rank(parent_id):
        name = by_id[parent_id].info.run_name
        return (name != TABLE_PARENT, "table" not in name, not 2 <= len(children[parent_id]) <= 20, name)

    parent = by_id[min(children, key=rank)]

    curve = None
    candidates = sorted(((k != "loss", r.info.run_name, r.info.run_id, k)
                         for kids in children.values() for r in kids for k in r.data.metrics if "loss" in k))
    for _, name, run_id, key in candidates[:40]:
        history = client.get_metric_history(run_id, key)
        steps = {m.step for m in history}
        if len(history) == len(steps) >= 5 and all(math.isfinite(m.value) for m in history):
            curve = {"run": by_id[run_id], "key": key, "history": sorted(history, key=lambda m: m.step)}
            break
    assert curve, f"no child run with a finite step curve of a loss among {len(candidates)} candidates"
    return {"experiments": redsup, "by_experiment": experiments, "parent": parent,
            "children": sorted(children[parent.info.run_id], key=lambda r: r.info.run_name), "curve": curve}


# --------------------------------------------------------------------------------- the browser
class _Text(HTMLParser):
    """The visible text of a page: text nodes outside script / style, whitespace collapsed."""

    def __init__(self):
        super().__init__()
        self.parts, self._skip = [], 0

    def handle_starttag(self, tag, attrs):
        self._skip += tag in ("script", "style", "noscript")

    def handle_endtag(self, tag):
        self._skip -= tag in ("script", "style", "noscript") and self._skip > 0

    def handle_data(self, data):
        if not self._skip and data.strip():
            self.parts.append(data.strip())


def page(chromium, tmp_path, url, *must_show):
    """The DOM of `url` once the app has rendered (html, visible text); loaded again with a longer
    budget if something in `must_show` is missing (a busy machine)."""
    for budget in (15000, 40000):
        profile = tmp_path / f"chrome-{time.monotonic_ns()}"
        proc = subprocess.run([chromium, "--headless=new", "--no-sandbox", "--disable-gpu", "--no-first-run",
                               "--disable-extensions", f"--user-data-dir={profile}", "--window-size=1400,900",
                               f"--virtual-time-budget={budget}", "--dump-dom", url],
                              capture_output=True, text=True, timeout=120)
        parser = _Text()
        parser.feed(proc.stdout)
        text = " ".join(parser.parts)
        if all(s in text for s in must_show):
            break
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc.stdout, text


def test_experiments_list_shows_every_redsup_experiment(chromium, server, expected, tmp_path):
    _, text = page(chromium, tmp_path, f"{server}/#/experiments", *expected["experiments"])
    missing = [n for n in expected["experiments"] if n not in text]
    assert not missing, f"experiments not shown: {missing}\n{text[:3000]}"


def test_table_parent_shows_its_children(chromium, server, expected, tmp_path):
    parent, kids = expected["parent"], expected["children"]
    exp = parent.info.experiment_id
    names = [k.info.run_name for k in kids]
    html, text = page(chromium, tmp_path, f"{server}/#/experiments/{exp}/runs/{parent.info.run_id}"
                      "?workflowType=machine_learning", parent.info.run_name, "Child runs", *names)
    assert parent.info.run_name in text and expected["by_experiment"][exp] in text, text[:3000]
    assert "Child runs" in text, text[:3000]
    shown = text.split("Child runs", 1)[1]
    missing = [n for n in names if n not in shown]
    assert not missing, f"children of {parent.info.run_name} not shown: {missing}\n{text[:3000]}"
    for kid in kids:                                      # each child a link to its own page
        link = f'href="#/experiments/{kid.info.experiment_id}/runs/{kid.info.run_id}"'
        assert re.search(re.escape(link) + r"[^>]*>\s*" + re.escape(kid.info.run_name), html), kid.info.run_name


def line_misses(path: str, history, tol_px: float = 2.0) -> list:
    """The logged (step, value) points that an SVG polyline "x,yLx,y..." does not pass within ``tol_px``.

    Plotly drops a vertex that lies on the straight line between its neighbours (``line.simplify``), so the
    line may have fewer vertices than steps; what it must do is pass through every point. The x axis spans the
    first to the last step; the y axis' linear map (range padding unknown) is fitted on the vertices, whose
    x must each fall on a logged step. An empty list: the line draws the history."""
    xy = np.array([[float(v) for v in p.split(",")] for p in path.split("L")])
    steps = np.array([h.step for h in history], float)
    values = np.array([h.value for h in history], float)
    if len(xy) < 2 or xy[-1, 0] <= xy[0, 0]:
        return ["fewer than two vertices"]
    px_of_step = xy[0, 0] + (steps - steps[0]) / (steps[-1] - steps[0]) * (xy[-1, 0] - xy[0, 0])
    at = np.abs(xy[:, 0][:, None] - px_of_step[None, :]).argmin(axis=1)
    if np.abs(xy[:, 0] - px_of_step[at]).max() > tol_px or len(set(at)) != len(at):
        return ["vertices off the logged steps"]
    slope, offset = np.polyfit(values[at], xy[:, 1], 1)
    if slope >= 0:                                        # larger values are higher up: smaller SVG y
        return ["y axis not increasing upwards"]
    drawn = np.interp(px_of_step, xy[:, 0], xy[:, 1])
    return [int(s) for s, d, v in zip(steps, drawn, values) if abs(d - (slope * v + offset)) > tol_px]


def test_line_misses_by_hand():
    """A 4-step history on a 300 px wide, 100 px tall plot: y = 100 - 100 value."""
    hist = [type("M", (), {"step": s, "value": v}) for s, v in [(1, 0.0), (2, 0.5), (3, 1.0), (4, 0.2)]]
    assert line_misses("0,100L100,50L200,0L300,80", hist) == []
    assert line_misses("0,100L200,0L300,80", hist) == []          # step 2 dropped: it lies on the line
    hist[1].value = 0.9                                                   # now it does not
    assert line_misses("0,100L200,0L300,80", hist) == [2]
    assert line_misses("0,100L150,30L300,80", hist) == ["vertices off the logged steps"]


def test_child_metric_page_plots_the_step_curve(chromium, server, expected, tmp_path):
    run, key, history = expected["curve"]["run"], expected["curve"]["key"], expected["curve"]["history"]
    as_json = lambda v: quote(json.dumps(v, separators=(",", ":")), safe="")     # as MLflow's own links
    query = {"runs": as_json([run.info.run_id]), "metric": as_json(key),
             "experiments": as_json([run.info.experiment_id]), "plot_metric_keys": as_json([key]),
             "plot_layout": "{}", "x_axis": "step", "y_axis_scale": "linear", "line_smoothness": "1",
             "show_point": "false", "deselected_curves": "[]", "last_linear_y_axis_range": "[]"}
    url = f"{server}/#/metric?" + "&".join(f"{k}={v}" for k, v in query.items())
    html, text = page(chromium, tmp_path, url, run.info.run_name, f"{run.info.run_name} ({key})")
    assert run.info.run_name in text and f"{run.info.run_name} ({key})" in text, text[:3000]   # the legend
    # the plotted line (plotly): every logged point lies on it
    lines = re.findall(r'<path class="js-line" d="M([^"]*)"', html)
    assert lines, "no plotted line"
    misdrawn = [line_misses(line, history) for line in lines]
    assert [] in misdrawn, (misdrawn, lines)
    # the summary table: latest, min and max with their steps, as in the store
    m = re.search(re.escape(key) + r" (\S+) \(step=(\d+)\) (\S+) \(step=(\d+)\) (\S+) \(step=(\d+)\)",
                  text.split("Latest", 1)[-1])
    assert m, text[:3000]
    latest, lo, hi = history[-1], min(history, key=lambda h: h.value), max(history, key=lambda h: h.value)
    for (value, step), want in zip([m.group(1, 2), m.group(3, 4), m.group(5, 6)], (latest, lo, hi)):
        assert math.isclose(float(value), want.value, rel_tol=1e-9) and int(step) == want.step, (m.group(0), want)
