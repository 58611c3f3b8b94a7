"""Table registry, paper values, Kendall's tau, claim checks, table writer and scorecard."""
from __future__ import annotations

import json
import math

import pandas as pd
import pytest

from redsup import tables
from redsup.tables import (evaluate_claims, kendall_tau, load_registry, paper_table, paper_values,
                           write_scorecard, write_table)
from redsup.tables.claims import _tau_b


def _tight(ours: pd.DataFrame, spread: float = 1e-4) -> dict:
    """Seed records of 3 seeds, v -+ spread, for every numeric cell (a table measured with little noise: claims are
    decided on their intervals, and a cell without a record decides nothing)."""
    df = ours.set_index(ours.columns[0]) if not pd.api.types.is_numeric_dtype(ours.iloc[:, 0]) else ours
    return {str(r): {str(c): tables.noise.seeds([v - spread, v, v + spread]) for c, v in df.loc[r].items()
                     if isinstance(v, (int, float)) and not pd.isna(v)} for r in df.index}

# ------------------------------------------------------------------------------------ Kendall tau
def test_kendall_tau_hand_cases():
    assert kendall_tau([1, 2, 3, 4], [10, 20, 30, 40]) == pytest.approx(1.0)
    assert kendall_tau([1, 2, 3, 4], [4, 3, 2, 1]) == pytest.approx(-1.0)
    # one tie in `ours`: pairs (C, D, ties_x, ties_y) = (5, 0, 1, 0) -> 5 / sqrt(6 * 5)
    assert kendall_tau([1, 2, 2, 3], [1, 2, 3, 4]) == pytest.approx(5 / math.sqrt(30))
    # one swap among four: (5 - 1) / 6
    assert kendall_tau([1, 2, 3, 4], [1, 3, 2, 4]) == pytest.approx(4 / 6)
    assert math.isnan(kendall_tau([1], [1]))
    assert math.isnan(kendall_tau([1, 1, 1], [1, 2, 3]))  # undefined: one side constant


def test_tau_b_matches_scipy():
    from scipy.stats import kendalltau

    x, y = [0.1, 0.3, 0.3, 0.2, 0.5, 0.4], [1, 3, 2, 2, 6, 5]
    assert _tau_b(x, y) == pytest.approx(kendalltau(x, y, variant="b").statistic)


# ------------------------------------------------------------------------------- registry + data
def test_registry_entries_are_complete():
    """Every entry has its stage, title, description and kind; an entry taken from a thesis names the document
    its id starts with (ids are only listed in tables.yaml: no test repeats the list)."""
    reg = load_registry()
    assert reg["tables"] and set(reg["stage_modules"]) == set(reg["stages"]) == set(reg["stage_config"])
    for table_id, entry in reg["tables"].items():
        assert entry["stage"] in reg["stages"], table_id
        for key in ("title", "description", "kind"):
            assert isinstance(entry[key], str) and entry[key].strip(), (table_id, key)
        assert "\n" not in entry["description"]
        assert entry["kind"] in ("table", "figure")
        if entry.get("source"):
            assert entry["source"]["document"] in reg["documents"]
            assert table_id.startswith(entry["source"]["document"] + "_"), table_id


def test_paper_values_cover_registry():
    reg = load_registry()
    pv = paper_values()
    assert list(pv.columns) == ["table_id", "row", "column", "value", "value_text", "unit", "lower_is_better", "note"]
    assert set(pv["table_id"]) <= set(reg["tables"]), "paper_values.csv names an unknown table id"
    for table_id in reg["tables"]:
        n = int((pv["table_id"] == table_id).sum())
        assert (n > 0) if reg["tables"][table_id].get("source") else (n == 0), table_id  # ours only: no thesis
    assert set(pv["lower_is_better"].unique()) <= {0, 1}
    assert not pv.duplicated(["table_id", "row", "column"]).any()
    # every cell is a number, or empty with a note saying why
    empty = pv[pv["value"].isna()]
    assert (empty["note"].str.len() > 0).all()
    # one direction per (table, column)
    assert (pv.groupby(["table_id", "column"])["lower_is_better"].nunique() == 1).all()


def test_paper_values_spot_checks():
    t = paper_table("mccraith_ch3_table2")
    assert t.at["Ours (MLP-synthetic)", "E_v"] == 1.28 and t.at["geometric reprojection", "E_v^far"] == 23.60
    assert paper_table("mccraith_ch4_table1").at["Depth Encoder + Pose Encoder", "Abs Rel"] == 0.097
    assert paper_table("mccraith_ch4_table3").at["100", "Seconds per Image"] == 4.626
    assert paper_table("mccraith_ch6_table3").at["(d) Ours", "AP_3D Easy"] == 83.45
    assert math.isnan(paper_table("mccraith_ch6_table3").at["(b) Zakharov et al. [44]", "AP_BEV Hard"])
    assert paper_table("mccraith_ch7_table3").at["2", "AP_BEV Medium"] == 74.79
    assert paper_table("galteland_table5_1").at["Manydepth | NAP-lab | DDAD", "Abs Rel"] == 0.280
    assert paper_table("galteland_table5_1", text=True).at["Feature Depth | DDAD | DDAD", "RMSE"] == "9.4300"


def test_every_claim_check_is_well_formed():
    """Each check names known rows/metrics of the paper table (or is explicitly about our own metric)
    and the registry claims evaluate on the paper's own numbers without error."""
    reg = load_registry()
    for table_id, entry in reg["tables"].items():
        results = tables.evaluate_claims_on_paper(table_id)
        assert len(results) == len(entry["claims"])
        for claim in entry["claims"]:
            assert claim["text"].strip()
            checks = claim.get("check") or []
            for check in checks if isinstance(checks, list) else [checks]:
                assert check["type"] in tables.registry.CHECK_TYPES, (table_id, check)


def test_claims_on_paper_numbers():
    """Every testable claim reproduces on the paper's own numbers (where the paper prints the cells it
    needs); the two the thesis' table contradicts are contradicted there and marked paper_inconsistent."""
    marked = {("mccraith_ch6_table2", "64 bins is the optimal number of discrete rotations"),
              ("mccraith_ch7_table2", "The best parameter values are α = 5 and β = 0")}
    reg = load_registry()
    contradicted, inconsistent = set(), set()
    for table_id, entry in reg["tables"].items():
        for claim, c in zip(entry["claims"], tables.evaluate_claims_on_paper(table_id)):
            if claim.get("paper_inconsistent"):
                inconsistent.add((table_id, c["text"]))
            if claim.get("category"):
                continue
            if c["verdict"] == "contradicted":
                contradicted.add((table_id, c["text"]))
            elif c["verdict"] != "reproduces":  # inconclusive only where the paper lacks a cell
                assert "missing" in c["evidence"], (table_id, c)
    assert contradicted == marked == inconsistent


def test_label_matching():
    assert tables.row_key("10^-1") == tables.row_key("0.1") == tables.row_key(0.1) == tables.row_key("1e-1")
    assert tables.row_key("Ours (MLP-tracker)") == tables.row_key("ours  (mlp-tracker)")
    assert tables.column_key("abs_rel") == tables.column_key("Abs Rel")
    assert tables.column_key("a1") == tables.column_key("δ < 1.25") == tables.column_key("delta < 1.25^1")


# --------------------------------------------------------------------------------------- writer
@pytest.fixture()
def ours_ch4_table2():
    # learning-rate ablation, labels spelled differently from the paper on purpose
    return pd.DataFrame({"row": ["baseline", "0.1", "10", "0.5"],
                         "abs_rel": [0.1201, 0.1003, 0.30, 0.2],
                         "a1": [0.85, 0.88, 0.5, 0.6]})


def test_write_table_places_paper_beside_ours(tmp_path, ours_ch4_table2):
    md, csv, tex = tmp_path / "t.md", tmp_path / "t.csv", tmp_path / "t.tex"
    score = write_table("mccraith_ch4_table2", ours_ch4_table2, md, csv, tex, note="profile tiny",
                        noise=_tight(ours_ch4_table2))

    df = pd.read_csv(csv, dtype=str, keep_default_na=False).set_index("row")
    assert {"Abs Rel (ours)", "Abs Rel (paper)", "δ < 1.25 (ours)", "δ < 1.25 (paper)", "RMSE (paper)",
            "status"} <= set(df.columns)
    assert "RMSE (ours)" not in df.columns
    assert df.at["10^-1", "Abs Rel (ours)"] == "0.1003" and df.at["10^-1", "Abs Rel (paper)"] == "0.097"
    assert df.at["10", "δ < 1.25 (paper)"] == "0.314"
    assert df.at["10^-5", "Abs Rel (ours)"] == "" and df.at["10^-5", "status"].startswith("paper only")
    assert df.at["0.5", "status"] == "ours only"
    assert list(df.index[:8]) == list(paper_table("mccraith_ch4_table2").index)  # paper order first

    text = md.read_text()
    assert text.startswith("# Instance adaptation learning rate")
    assert "| 10^-1 | 0.100 ± 0.000 | 0.097 |" in text  # ours at the paper's precision, paper as printed
    assert "| 10^-5 | — | 0.115 |" in text
    assert "profile tiny" in text
    assert "Kendall τ" in text and "(n = 3 rows)" in text
    assert "✔ reproduces: Learning rate 0.1 gives the most significant improvement" in text
    assert "≈ inconclusive: Too low a learning rate" in text

    latex = tex.read_text()
    assert "\\begin{tabular}" in latex and "\\caption{" in latex and "\\label{tab:mccraith_ch4_table2}" in latex
    assert "10\\textsuperscript{-1} & 0.100 ± 0.000 & 0.097" in latex
    assert "$\\delta$ $<$ 1.25 (ours)" in latex

    saved = json.loads((tmp_path / "mccraith_ch4_table2.score.json").read_text())
    assert saved == json.loads(json.dumps(score, ensure_ascii=False, default=str))
    assert saved["kendall_tau"] == pytest.approx(1.0) and saved["n_rows"] == 3
    assert saved["claims_total"] == 3
    assert saved["counts"] == {"reproduces": 2, "inconclusive": 1, "thesis_effect_ruled_out": 0, "contradicted": 0,
                               "under-trained_systems": 0, "not_testable": 0, "data_description": 0}
    margin = saved["claims"][0]["margins"][0]  # the decided comparison, for the power report
    assert margin["verdict"] == "reproduces" and margin["seeds"] == 3 and margin["clusters"] is None
    # the thesis' effect on our scale: 10^-1 0.097 vs its closest row as a relative margin, times ours
    assert margin["thesis_effect"] is not None and margin["thesis_effect"] > 0


def test_claims_hold_and_fail(ours_ch4_table2):
    good = {c["text"]: c for c in evaluate_claims("mccraith_ch4_table2", ours_ch4_table2,
                                                  noise=_tight(ours_ch4_table2))}
    best = good["Learning rate 0.1 gives the most significant improvement"]
    assert best["verdict"] == "reproduces" and "10^-1 0.1003" in best["evidence"]
    diverge = good["Too high a learning rate results in quick divergence"]
    assert diverge["verdict"] == "reproduces" and "0.1201 < 10 0.3" in diverge["evidence"]

    bad = ours_ch4_table2.copy()
    bad.loc[bad["row"] == "0.1", "abs_rel"] = 0.15  # worse than the baseline: 0.1 no longer best
    bad.loc[bad["row"] == "10", "abs_rel"] = 0.11  # high LR now better than the baseline
    res = {c["text"]: c for c in evaluate_claims("mccraith_ch4_table2", bad, noise=_tight(bad))}
    assert res["Learning rate 0.1 gives the most significant improvement"]["verdict"] == "contradicted"
    assert "closest 10 0.11" in res["Learning rate 0.1 gives the most significant improvement"]["evidence"]
    assert res["Too high a learning rate results in quick divergence"]["verdict"] == "contradicted"


def test_check_types_and_extra_claims():
    ours = pd.DataFrame({"AP_BEV Easy": [80.0, 70.0, 79.0], "AP_BEV Moderate": [75.0, 60.0, 74.5]},
                        index=["(e) 2D Mask, outlier-aware, multi-view", "(b) 2D Mask", "(c) 2D Mask, multi-view"])
    extra = [
        {"text": "close", "check": {"type": "close", "a": "(c) 2D Mask, multi-view",
                                    "b": "(e) 2D Mask, outlier-aware, multi-view", "tol": 1.0}},
        {"text": "relative close fails", "check": {"type": "close", "a": "(b) 2D Mask",
                                                   "b": "(c) 2D Mask, multi-view", "tol": 0.1, "relative": True}},
        {"text": "range", "check": {"type": "range", "row": "(b) 2D Mask", "metric": "AP_BEV Easy", "min": 60, "max": 75}},
        {"text": "worst", "check": {"type": "best", "row": "(b) 2D Mask", "worst": True}},
        {"text": "two metrics", "check": {"type": "order", "better": "(e) 2D Mask, outlier-aware, multi-view",
                                          "worse": "(b) 2D Mask", "metric": ["AP_BEV Easy", "AP_BEV Moderate"]}},
        {"text": "cells", "check": {"type": "order", "better": {"row": "(b) 2D Mask", "metric": "AP_BEV Easy"},
                                    "worse": {"row": "(b) 2D Mask", "metric": "AP_BEV Moderate"}}},
        {"text": "pre-evaluated", "verdict": "contradicted", "evidence": "computed by the caller"},
    ]
    res = {c["text"]: c["verdict"] for c in evaluate_claims("mccraith_ch6_table1", ours, extra_claims=extra,
                                                            noise=_tight(ours.reset_index()))}
    R, I, C = "reproduces", "inconclusive", "contradicted"
    assert res == {
        "Masking LiDAR points with the 2D mask is a substantial improvement over the 2D box": I,  # no (a)
        "Multi-view consistency alone gives no noticeable benefit": C,  # |74.5 - 60| > 1.5
        "Discounting outliers with the probabilistic loss increases accuracy substantially": I,  # no (d)
        "With outlier discounting, multi-view consistency helps and the full model is best": I,  # no (d), best ok
        "close": R, "relative close fails": C, "range": R, "worst": R, "two metrics": R,
        "cells": R, "pre-evaluated": C,
    }


def test_table_without_paper_values_and_scorecard(tmp_path, ours_ch4_table2):
    summary = pd.DataFrame({"dataset": ["world_kitti"], "frames": [120], "cameras": ["cam_front, cam_back"]})
    s1 = write_table("data_summary", summary, tmp_path / "d.md", tmp_path / "d.csv", tmp_path / "d.tex")
    assert s1["kendall_tau"] is None and s1["claims"] == [] and not s1["has_paper"]
    assert "| dataset | frames | cameras |" in (tmp_path / "d.md").read_text()
    assert pd.read_csv(tmp_path / "d.csv").columns.tolist() == ["dataset", "frames", "cameras"]
    write_table("mccraith_ch4_table2", ours_ch4_table2, tmp_path / "t.md", tmp_path / "t.csv", tmp_path / "t.tex",
                noise=_tight(ours_ch4_table2))

    out = tmp_path / "scorecard.md"
    result = write_scorecard([tmp_path / "mccraith_ch4_table2.score.json", tmp_path / "data_summary.score.json"], out)
    text = out.read_text()
    assert result["tables"] == 2
    assert result["counts"] == {"reproduces": 2, "inconclusive": 1, "thesis_effect_ruled_out": 0, "contradicted": 0,
                                "under-trained_systems": 0, "not_testable": 0, "data_description": 0}
    assert "| mccraith_ch4_table2 | depth | Abs Rel | +1.000 (3) | 2 | 1 | 0 | 0 | 0 | 0 | 0 |" in text
    assert "| data_summary | data | — | n/a (0) | 0 | 0 | 0 | 0 | 0 | 0 | 0 |" in text
    assert "| depth | 2 | 1 | 0 | 0 | 0 | 0 | 0 |" in text  # per stage
    assert ("**Total: 2 reproduces, 1 inconclusive, 0 thesis effect ruled out, 0 contradicted, 0 under-trained "
            "systems, 0 not testable, 0 data description**") in text
    assert text.index("data_summary |") < text.index("mccraith_ch4_table2 |")  # registry order
    assert "Not built: mccraith_ch3_table1" in text
    assert "- ✔ **reproduces**: Learning rate 0.1 gives the most significant improvement" in text


def test_mlflow_plan():
    plan = tables.mlflow_plan()
    names = [p["name"] for p in plan["parents"]]
    assert names[:2] == ["world", "data_preparation"] and set(load_registry()["tables"]) <= set(names)
    assert len(names) == len(set(names))
    assert all(p["stage"] in plan["stages"] for p in plan["parents"])


# ------------------------------------------------------------------------- verdicts and noise
def _constant_tables(value: float = 1.0) -> dict[str, pd.DataFrame]:
    """Every paper table with every cell of ours set to the same value."""
    out = {}
    for table_id in load_registry()["tables"]:
        paper = paper_table(table_id)
        if not paper.empty:
            out[table_id] = pd.DataFrame(value, index=paper.index, columns=paper.columns)
    return out


def test_constant_tables_reproduce_no_order_or_best_claim():
    """With every cell of ours equal, no order / best claim of any table can reproduce (ties never win)."""
    reg = load_registry()
    n_checked = 0
    for table_id, ours in _constant_tables().items():
        for claim, c in zip(reg["tables"][table_id]["claims"], evaluate_claims(table_id, ours)):
            checks = claim.get("check") or []
            kinds = {k["type"] for k in (checks if isinstance(checks, list) else [checks])}
            if kinds & {"order", "best"}:
                n_checked += 1
                assert c["verdict"] != "reproduces", (table_id, c)
    assert n_checked > 40
    n_close = 0
    for table_id, ours in _constant_tables(0.0).items():  # all at 0: no close claim holds on a floor
        for claim, c in zip(reg["tables"][table_id]["claims"], evaluate_claims(table_id, ours)):
            checks = claim.get("check") or []
            if any(k["type"] == "close" for k in (checks if isinstance(checks, list) else [checks])):
                n_close += 1
                assert c["verdict"] != "reproduces", (table_id, c)
    assert n_close >= 5


def test_listed_claims_say_whether_they_hold_on_our_data(tmp_path):
    """A data description (listed, not counted) keeps its category, and its evidence says whether the
    statement is true of our numbers: Medium 247 < Far 345 in ch. 3 Table I does not hold; 706 > 200 does.
    The scorecard lists the ones that do not hold."""
    far_heavy = pd.DataFrame({"Near": [114.0, 30.0], "Medium": [247.0, 61.0], "Far": [345.0, 109.0],
                              "Total": [706.0, 200.0]}, index=["Train", "Test"])
    res = {c["text"][:6]: c for c in evaluate_claims("mccraith_ch3_table1", far_heavy, noise=_tight(far_heavy))}
    medium, sizes = res["Medium"], res["The tr"]
    assert medium["verdict"] == sizes["verdict"] == "data description"
    assert (medium["on_our_data"], sizes["on_our_data"]) == ("does not hold on our data", "holds on our data")
    write_table("mccraith_ch3_table1", far_heavy.reset_index(names="split"), tmp_path / "t.md", tmp_path / "t.csv",
                tmp_path / "t.tex", noise=_tight(far_heavy))
    result = write_scorecard([tmp_path / "mccraith_ch3_table1.score.json"], tmp_path / "scorecard.md")
    assert result["counts"]["data_description"] == 2 and result["counts"]["contradicted"] == 0
    assert result["listed_not_holding"] == [("mccraith_ch3_table1", medium["text"])]
    assert ("Listed (uncounted) claims that do not hold on our data: mccraith_ch3_table1: Medium-range vehicles"
            in (tmp_path / "scorecard.md").read_text())
    assert "; does not hold on our data (measured: Train [Medium] 247 < Train [Far] 345" in medium["evidence"]
    assert "the split sizes are configuration (velocity_clips.splits); holds on our data (measured:" \
        in sizes["evidence"]
    medium_heavy = far_heavy.assign(Medium=[400.0, 150.0])
    res = {c["text"][:6]: c for c in evaluate_claims("mccraith_ch3_table1", medium_heavy,
                                                     noise=_tight(medium_heavy))}
    assert "; holds on our data (measured:" in res["Medium"]["evidence"]
    no_check = [{"text": "listed without checks", "category": "not_testable", "reason": "a visual statement"},
                {"text": "not testable, checked", "category": "not_testable", "reason": "about prior work",
                 "check": {"type": "order", "better": "Train", "worse": "Test", "metric": "Total"}}]
    c, d = evaluate_claims("mccraith_ch3_table1", far_heavy, extra_claims=no_check, noise=_tight(far_heavy))[-2:]
    assert c["verdict"] == "not testable" and c["evidence"] == "a visual statement (measured: not machine-checked)"
    assert d["verdict"] == "not testable" and "on_our_data" not in d    # its checks cannot decide it
    assert d["evidence"].startswith("about prior work (measured: Total: Train 706 > Test 200")


def test_identical_cells_without_spread_do_not_show_closeness():
    """Two rows both at 0 AP with no spread over seeds (a floor: nothing detected) are not evidence that they
    are close; 60.0 vs 60.5 or 60.0 vs 60.0 measured with little noise inside the tolerance are; without noise
    records nothing is decided."""
    rows = ["(b) 2D Mask", "(c) 2D Mask, multi-view"]
    claim = [{"text": "close", "check": {"type": "close", "a": rows[1], "b": rows[0], "tol": 1.0}}]
    floor = pd.DataFrame({"AP_BEV Moderate": [0.0, 0.0]}, index=rows)
    c = evaluate_claims("mccraith_ch6_table1", floor, extra_claims=claim, noise=_tight(floor, 0.0))[-1]
    assert c["verdict"] == "inconclusive" and "equivalence not shown" in c["evidence"]
    near = pd.DataFrame({"AP_BEV Moderate": [60.0, 60.5]}, index=rows)
    assert evaluate_claims("mccraith_ch6_table1", near, extra_claims=claim,
                           noise=_tight(near))[-1]["verdict"] == "reproduces"
    same = pd.DataFrame({"AP_BEV Moderate": [60.0, 60.0]}, index=rows)
    assert evaluate_claims("mccraith_ch6_table1", same, extra_claims=claim,
                           noise=_tight(same))[-1]["verdict"] == "reproduces"
    bare = evaluate_claims("mccraith_ch6_table1", near, extra_claims=claim)[-1]
    assert bare["verdict"] == "inconclusive" and "without a noise record" in bare["evidence"]


def test_tie_is_inconclusive_not_a_win():
    ours = pd.DataFrame({"row": ["baseline", "0.1", "10"], "abs_rel": [0.12, 0.12, 0.12]})
    res = {c["text"]: c for c in evaluate_claims("mccraith_ch4_table2", ours)}
    assert res["Learning rate 0.1 gives the most significant improvement"]["verdict"] == "inconclusive"
    assert res["Too high a learning rate results in quick divergence"]["verdict"] == "inconclusive"


def test_best_needs_every_row_of_its_pool():
    """A `best` among rows we do not have is not decided among the few we have: literature rows make it
    not testable, a missing row of ours makes it inconclusive."""
    t5 = paper_table("mccraith_ch4_table5")
    ours = pd.DataFrame({"Abs Rel": [0.10, 0.12]}, index=["ours | M", "Monodepth V2 [9] | M"])
    res = {c["text"]: c for c in evaluate_claims("mccraith_ch4_table5", ours)}
    claim = res["Ours (M) beats all previous self-supervised monocular methods"]
    assert claim["verdict"] == "not testable" and "prior work" in claim["evidence"]
    assert "Zhou [3]† | M" in t5.index
    # a pool row that is ours but not built: inconclusive, with the row named
    ours3 = pd.DataFrame({"AP_BEV Moderate": [70.0, 60.0]}, index=["(f) Ours, 64 bins", "(d) Ours, 16 bins"])
    res3 = {c["text"]: c for c in evaluate_claims("mccraith_ch6_table2", ours3)}
    # 64 bins is marked paper_inconsistent: never counted, whatever ours say
    assert res3["64 bins is the optimal number of discrete rotations"]["verdict"] == "not testable"
    extra = [{"text": "pool", "check": {"type": "best", "row": "(f) Ours, 64 bins",
                                        "among": ["(d) Ours, 16 bins", "(g) Ours, 128 bins"]}}]
    pool = evaluate_claims("mccraith_ch6_table2", ours3, extra_claims=extra)[-1]
    assert pool["verdict"] == "inconclusive" and "missing (g) Ours, 128 bins" in pool["evidence"]


def test_seed_noise_decides_the_verdict():
    """0.439 vs 0.437 over 3 seeds with std ~0.02 is inside the noise, and the interval excludes the thesis' own
    effect (baseline 0.115 vs whole network 0.207 in its table: 44 % of the compared-against row, on ours 0.195): that
    effect is ruled out here; 0.30 vs 0.44 is beyond the noise."""
    ours = pd.DataFrame({"Abs Rel": [0.437, 0.439]},
                        index=["baseline [9] (no instance adaptation)", "whole network"])
    noise = {"baseline [9] (no instance adaptation)": {"Abs Rel": tables.noise.seeds([0.417, 0.437, 0.457])},
             "whole network": {"Abs Rel": tables.noise.seeds([0.419, 0.439, 0.459])}}
    text = "Updating all network parameters at inference makes accuracy significantly worse than the baseline"
    c = {x["text"]: x for x in evaluate_claims("mccraith_ch4_table1", ours, noise=noise)}[text]
    assert c["verdict"] == "thesis effect ruled out" and "seeds" in c["evidence"]
    # by hand: difference 0.002, se = sqrt(2 * 0.02^2 / 3) = 0.01633, Welch df = 4 -> t = 2.7764
    lo, hi, _ = tables.noise.difference_interval(0.439, 0.437, noise["whole network"]["Abs Rel"],
                                                 noise["baseline [9] (no instance adaptation)"]["Abs Rel"])
    assert lo == pytest.approx(0.002 - 2.7764 * 0.016330, abs=1e-5)
    assert hi == pytest.approx(0.002 + 2.7764 * 0.016330, abs=1e-5)
    ours2 = ours.copy()
    ours2.loc["whole network", "Abs Rel"] = 0.70
    noise["whole network"]["Abs Rel"] = tables.noise.seeds([0.68, 0.70, 0.72])
    c2 = {x["text"]: x for x in evaluate_claims("mccraith_ch4_table1", ours2, noise=noise)}[text]
    assert c2["verdict"] == "reproduces"
    # 'significantly' sets a minimum effect: half the thesis' 44.4 % on ours, 0.5 x 0.4444 x 0.60 = 0.1333; a margin
    # of 0.163 -+ 0.045 is beyond the noise but not shown beyond that floor
    ours2.loc["whole network", "Abs Rel"] = 0.60
    noise["whole network"]["Abs Rel"] = tables.noise.seeds([0.58, 0.60, 0.62])
    c2b = {x["text"]: x for x in evaluate_claims("mccraith_ch4_table1", ours2, noise=noise)}[text]
    assert c2b["verdict"] == "inconclusive" and "minimum effect 0.1333" in c2b["evidence"]
    # the opposite effect beyond the noise is a contradiction
    ours3 = ours.copy()
    ours3.loc["whole network", "Abs Rel"] = 0.30
    noise["whole network"]["Abs Rel"] = tables.noise.seeds([0.29, 0.30, 0.31])
    c3 = {x["text"]: x for x in evaluate_claims("mccraith_ch4_table1", ours3, noise=noise)}[text]
    assert c3["verdict"] == "contradicted"


def test_paired_bootstrap_sees_a_consistent_small_gain():
    """A gain of 0.01 on every frame is certain under a paired bootstrap, although the per-frame spread
    (0.1 .. 0.5) is far larger than the gain; shuffled (unpaired) it would be inside the noise. Frame ids without a
    scene: each frame is a cluster of its own."""
    frames = [f"f{i:02d}" for i in range(40)]
    base = {f: 0.1 + 0.4 * i / 39 for i, f in enumerate(frames)}
    adapted = {f: v - 0.01 for f, v in base.items()}
    nb, na = tables.noise.bootstrap(base), tables.noise.bootstrap(adapted)
    assert nb["units"] == na["units"]
    lo, hi, how = tables.noise.difference_interval(sum(adapted.values()) / 40, sum(base.values()) / 40, na, nb)
    assert how == "paired cluster bootstrap, 40 clusters" and lo == pytest.approx(-0.01) and hi == pytest.approx(-0.01)
    other = tables.noise.bootstrap({f"g{i}": v for i, v in enumerate(adapted.values())})  # other units
    lo2, hi2, how2 = tables.noise.difference_interval(sum(adapted.values()) / 40, sum(base.values()) / 40,
                                                      other, nb)
    assert how2 == "cluster bootstrap" and lo2 < 0 < hi2


def test_bootstrap_statistic_and_spread_display(tmp_path):
    units = ["a", "b", "c", "d"]
    rec = tables.noise.bootstrap(unit_ids=units, statistic=lambda us: sum(u in ("a", "b") for u in us) / len(us))
    assert len(rec["values"]) == tables.noise.N_BOOTSTRAP and 0.0 <= min(rec["values"]) <= max(rec["values"]) <= 1.0
    assert rec["units"] == tables.noise.units_digest(["d", "c", "b", "a"])  # order-free
    ours = pd.DataFrame({"row": ["baseline", "0.1"], "abs_rel": [0.12, 0.10]})
    noise = {"0.1": {"abs_rel": tables.noise.seeds([0.09, 0.10, 0.11])}}
    write_table("mccraith_ch4_table2", ours, tmp_path / "t.md", tmp_path / "t.csv", tmp_path / "t.tex", noise=noise)
    assert "| 10^-1 | 0.100 ± 0.010 | 0.097 |" in (tmp_path / "t.md").read_text()
    df = pd.read_csv(tmp_path / "t.csv").set_index("row")
    assert df.at["10^-1", "Abs Rel (ours) std"] == pytest.approx(0.01)


def test_too_few_clusters_and_float_ties_are_inconclusive():
    one = tables.noise.bootstrap({f"scene{g}/{f}": 0.40 + 0.01 * f for g in range(4) for f in range(5)})
    other = tables.noise.bootstrap({f"scene{g}/{f}": 0.39 + 0.01 * f for g in range(4) for f in range(5)})
    lo, hi, how = tables.noise.difference_interval(0.41, 0.42, other, one)  # 20 frames, but from 4 scenes
    assert math.isnan(lo) and "4 clusters (fewer than 5)" in how
    tight = tables.noise.seeds([0.3992, 0.3992, 0.3992])
    assert tables.noise.verdict_of_interval(*tables.noise.difference_interval(0.3992, 0.3992 + 1e-12, tight,
                                                                              tight)[:2]) == "inconclusive"


def test_seed_records_of_the_same_models_pair_seed_by_seed():
    """Adapted 0.142 / 0.129 / 0.137 vs baseline 0.164 / 0.142 / 0.150 (ch. 4 Table 5's MS rows, 3 seeds): per-seed
    differences -0.022 / -0.013 / -0.013, mean -0.016, sd 0.0051962; half width t(2) 4.302653 x 0.0051962 / sqrt(3)
    = 0.012908, so [-0.028908, -0.003092]: the gain is beyond the noise when paired. Unpaired (Welch: variances
    43e-6 and 124e-6, of the means 55.67e-6, df 3.238 -> t 3.0540) the same numbers give -0.016 -+ 0.022786
    (inconclusive), and so do records of different models."""
    a, b = [0.142, 0.129, 0.137], [0.164, 0.142, 0.150]
    ma, mb = sum(a) / 3, sum(b) / 3
    na, nb = tables.noise.seeds(a, "world_kitti/MS"), tables.noise.seeds(b, "world_kitti/MS")
    assert na["pair"] == "world_kitti/MS" and "pair" not in tables.noise.seeds(a)
    lo, hi, how = tables.noise.difference_interval(ma, mb, na, nb)
    assert how == "paired seeds"
    assert lo == pytest.approx(-0.016 - 0.012908, abs=2e-6) and hi == pytest.approx(-0.016 + 0.012908, abs=2e-6)
    assert tables.noise.verdict_of_interval(-hi, -lo) == "reproduces"  # lower is better: margin b - a > 0
    for other in (tables.noise.seeds(b, "world_kitti/M"), tables.noise.seeds(b)):
        lo2, hi2, how2 = tables.noise.difference_interval(ma, mb, na, other)
        assert how2 == "seeds" and lo2 < 0 < hi2
        assert lo2 == pytest.approx(-0.016 - 0.022786, abs=2e-6) and hi2 == pytest.approx(-0.016 + 0.022786, abs=2e-6)
    # a different number of seeds cannot pair
    _, _, how3 = tables.noise.difference_interval(ma, mb, na, tables.noise.seeds(b[:2], "world_kitti/MS"))
    assert how3 == "seeds"


def _boot(values, units="u10", n_units=10):
    return {"kind": "bootstrap", "values": list(values), "units": units, "n_units": n_units}


def test_seed_means_carry_their_test_sampling_noise():
    """Three seeds evaluated on the same test units: the seed spread says nothing about which units those are.
    By hand, B = 4 replicates over 10 units, each its own cluster (G = 10): the sampling variance is the replicates'
    variance x 10 / 9 at 9 df (t 2.262157). (1) Every seed lowers the error by exactly 0.03 (seed variance 0), but
    the seed means' replicates differ by 0 / 0.1 / 0.2 / 0.3 (variance 0.0166667, x 10 / 9 = 0.0185185): seeds
    alone give the point -0.03, with the sampling noise -0.03 -+ 2.262157 x 0.136083 = 0.307841 (inconclusive).
    (2) Per-seed differences -0.02 / -0.01 / -0.03 (variance of the mean 1e-4 / 3, df 2) and replicate differences
    -0.005 / 0.005 / -0.005 / 0.005 (3.7037e-5 at df 9): Welch-Satterthwaite over both would give 2.366 x 0.0083887
    = 0.019846, narrower than the seeds' own 4.302653 x 0.0057735 = 0.024841: the half width is the larger, so the
    interval stays the seeds' [-0.044841, 0.004841]. (3) Per-seed differences -0.020 / -0.021 / -0.019 (variance of
    the mean 3.3333e-7) and replicate differences -0.01 / 0.01 / -0.01 / 0.01 (1.48148e-4): total 1.48481e-4 at
    df 9.04, half width 0.027546, against the seeds' 4.302653 x 5.7735e-4 = 0.002484 alone: the sampling noise
    decides (inconclusive instead of reproduces)."""
    noise = tables.noise
    a1, b1 = [0.10, 0.12, 0.14], [0.13, 0.15, 0.17]
    ra = noise.with_sampling(noise.seeds(a1, "m"), [_boot([0.1, 0.2, 0.3, 0.4])] * 3)
    rb = noise.with_sampling(noise.seeds(b1, "m"), [_boot([0.1, 0.1, 0.1, 0.1])] * 3)
    assert ra["boot"] == pytest.approx([0.1, 0.2, 0.3, 0.4]) and ra["units"] == "u10" and ra["values"] == a1
    lo0, hi0, how0 = noise.difference_interval(0.12, 0.15, noise.seeds(a1, "m"), noise.seeds(b1, "m"))
    assert how0 == "paired seeds" and lo0 == pytest.approx(-0.03) and hi0 == pytest.approx(-0.03)
    lo, hi, how = noise.difference_interval(0.12, 0.15, ra, rb)
    assert how == "paired seeds + paired cluster bootstrap, 10 clusters"
    assert lo == pytest.approx(-0.03 - 0.307841, abs=1e-6) and hi == pytest.approx(-0.03 + 0.307841, abs=1e-6)
    assert noise.verdict_of_interval(-hi, -lo) == "inconclusive"
    a2, b2 = [0.10, 0.12, 0.14], [0.12, 0.13, 0.17]
    ra2 = noise.with_sampling(noise.seeds(a2, "m"), [_boot([0.0, 0.01, 0.0, 0.01])] * 3)
    rb2 = noise.with_sampling(noise.seeds(b2, "m"), [_boot([0.005, 0.005, 0.005, 0.005])] * 3)
    lo2, hi2, _ = noise.difference_interval(0.12, 0.14, ra2, rb2)
    assert lo2 == pytest.approx(-0.044841, abs=2e-6) and hi2 == pytest.approx(0.004841, abs=2e-6)
    lo2s, hi2s, _ = noise.difference_interval(0.12, 0.14, noise.seeds(a2, "m"), noise.seeds(b2, "m"))
    assert (lo2s, hi2s) == pytest.approx((lo2, hi2))
    a5, b5 = [0.100, 0.120, 0.140], [0.120, 0.141, 0.159]
    ra5 = noise.with_sampling(noise.seeds(a5, "m"), [_boot([0.0, 0.02, 0.0, 0.02])] * 3)
    rb5 = noise.with_sampling(noise.seeds(b5, "m"), [_boot([0.01] * 4)] * 3)
    lo5, hi5, _ = noise.difference_interval(0.12, 0.14, ra5, rb5)
    assert lo5 == pytest.approx(-0.02 - 0.027546, abs=2e-6) and hi5 == pytest.approx(-0.02 + 0.027546, abs=2e-6)
    lo5s, hi5s, _ = noise.difference_interval(0.12, 0.14, noise.seeds(a5, "m"), noise.seeds(b5, "m"))
    assert hi5s == pytest.approx(-0.02 + 0.002484, abs=2e-6)
    assert noise.verdict_of_interval(-hi5s, -lo5s) == "reproduces" and noise.verdict_of_interval(-hi5, -lo5) == \
        "inconclusive"
    # replicates over other units do not pair: their variances add
    rb3 = noise.with_sampling(noise.seeds(b2, "m"), [_boot([0.005, 0.015, 0.005, 0.015], units="other")] * 3)
    _, _, how3 = noise.difference_interval(0.12, 0.14, ra2, rb3)
    assert how3 == "paired seeds + cluster bootstrap"
    # the seeds' replicates must share their units (else the record keeps its seeds only)
    mixed = noise.with_sampling(noise.seeds(a2), [_boot([0, 1, 0, 1]), _boot([0, 1, 0, 1], units="v"),
                                                  _boot([0, 1, 0, 1])])
    assert "boot" not in mixed
    few = noise.with_sampling(noise.seeds(a2), [_boot([0, 1, 0, 1], n_units=2)] * 3)  # 2 units measure nothing:
    assert math.isnan(noise.difference_interval(0.12, 0.0, few, noise.seeds(b2))[0])  # no verdict on them
    # a one-seed row's bootstrap record against a seed mean with replicates on the same units pairs its replicates
    lo4, hi4, how4 = noise.difference_interval(0.12, 0.14, ra2, _boot([0.005, 0.005, 0.005, 0.005]))
    assert how4 == "seeds + paired cluster bootstrap, 10 clusters"
    # by hand: seeds 0.10 / 0.12 / 0.14, variance of the mean 4e-4 / 3 (df 2); replicate differences -0.005 / 0.005
    # / -0.005 / 0.005 (variance 3.7037e-5 at df 9); the total's interval is below the seeds' own
    # 4.302653 x 0.0115470 = 0.049683, which is the half width
    assert lo4 == pytest.approx(-0.02 - 0.049683, abs=2e-6) and hi4 == pytest.approx(-0.02 + 0.049683, abs=2e-6)


def test_comparisons_of_under_trained_systems_are_counted_apart():
    """Galteland's accuracy claims compare systems that val shows far from convergence: their category keeps them
    out of the counted outcomes, and their evidence still says what our numbers show."""
    ours = pd.DataFrame({"Abs Rel": [0.30, 0.20]}, index=["Manydepth", "Feature Depth"])
    res = {c["text"][:23]: c for c in evaluate_claims("galteland_table4_1", ours, noise=_tight(ours))}
    fd = res["Feature Depth reaches a"]
    assert fd["verdict"] == "under-trained systems" and fd["on_our_data"] == "holds on our data"
    assert "between under-trained systems" in fd["evidence"]
    assert "under-trained systems" not in tables.claims.COUNTED
