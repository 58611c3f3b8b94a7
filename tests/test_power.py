"""The power report projects each undecided claim's interval to more seeds and test clusters and applies the
claim's own verdict rules (redsup.tables.power), checked against hand-computed thresholds."""
import json
import math

import pandas as pd
import pytest

from redsup.tables import noise
from redsup.tables.claims import _Cells, evaluate_check
from redsup.tables.power import claim_power, decided_at, write_power

Z = 1.959963984540054  # the normal 97.5 % quantile: a part with df 1e9 is normal


def _margin(centre, seed_parts=(), sampling_parts=(), effect=None, clusters=10, seeds=None, **extra):
    half = noise.half_width(list(seed_parts), list(sampling_parts)) if seed_parts or sampling_parts else 0.0
    return {"comparison": "a vs b", "check": "order", "lo": centre - half, "hi": centre + half, "margin": centre,
            "thesis_effect": effect, "floor": None, "clusters": clusters, "seeds": seeds, "how": "x",
            "seed_parts": [list(p) for p in seed_parts], "sampling_parts": [list(p) for p in sampling_parts],
            "verdict": "inconclusive"} | extra


def _claim(verdict, *margins):
    return {"text": "t", "verdict": verdict, "margins": list(margins)}


def test_t_quantile_takes_one_df_or_an_array():
    from redsup.stats import t_quantile

    # printed t tables: t(2) 4.303, t(9) 2.262, t(39) 2.023; no df / infinite: the normal 1.960; df < 1 counts as 1
    assert t_quantile(9) == pytest.approx(2.262157, rel=1e-6) and isinstance(t_quantile(9), float)
    assert t_quantile(None) == t_quantile(math.inf) == pytest.approx(Z) and t_quantile(0.5) == t_quantile(1)
    many = t_quantile([2, 39, math.inf])
    assert many == pytest.approx([4.302653, 2.022691, Z], rel=1e-6)


def test_more_clusters_decide_a_bootstrap_margin_where_sqrt_k_passes_t():
    # centre 0.01, sd 0.01 over 10 clusters (df 9): half t(9) 0.01 = 0.0226 holds 0. At k x the clusters the half
    # width is t(10k - 1) 0.01 / sqrt(k): still >= 0.01 at k = 4 (t(39) = 2.023 > 2), below it at k = 4.2
    # (t(41) = 2.020 < 2.049)
    row = claim_power("t1", _claim("inconclusive", _margin(0.01, sampling_parts=[(1e-4, 9)])))
    assert 4.0 < row["factor"] <= 4.2
    assert row["clusters needed"] in (41, 42) and row["seeds needed"] is None  # no seed part: seeds cannot
    assert row["half width"] == pytest.approx(2.262157 * 0.01, rel=1e-5) and row["seed share"] == 0.0
    assert row["status"] == (f"needs about {row['factor']:.1f}x the units; more seeds alone would not; "
                             f"{row['clusters needed']} test clusters with the seeds as they are")


def test_ruling_out_the_thesis_effect_decides_before_the_sign_does():
    # centre 0.005, normal sd 0.01: [-0.0146, 0.0246] holds 0 and the thesis' 0.02. The sign needs
    # half < 0.005, (Z 0.01 / 0.005)^2 = 15.4x; ruling out needs 0.005 + half < 0.02, (Z 0.01 / 0.015)^2 = 1.71x
    m = _margin(0.005, sampling_parts=[(1e-4, 1e9)], effect=0.02)
    assert claim_power("t", _claim("inconclusive", m))["factor"] == pytest.approx((Z / 1.5) ** 2, abs=0.035)
    assert decided_at([m | {"thesis_effect": None}]) == pytest.approx((Z / 0.5) ** 2, rel=0.02)


def test_a_seed_dominated_margin_is_decided_by_seeds_not_by_test_clusters():
    # seed part 4e-4 over 3 seeds (df 2), sampling 1e-5 (df 9): the seeds alone give t(2) 0.02 = 0.086 > the
    # margin 0.02 at any number of clusters. Seeds alone: t(3k - 1) 0.02 / sqrt(k) < 0.02 first near k = 5
    # (t(14) = 2.145 < sqrt(5) = 2.236; 4.5: t(12.5) = 2.17 > 2.12), a little later with the sampling part
    m = _margin(0.02, seed_parts=[(4e-4, 2)], sampling_parts=[(1e-5, 9)], seeds=3)
    row = claim_power("t", _claim("inconclusive", m))
    assert row["clusters needed"] is None and 14 <= row["seeds needed"] <= 20
    assert row["seed share"] == pytest.approx(4e-4 / 4.1e-4)
    assert "more test clusters alone would not" in row["status"]


def test_closeness_and_range_margins_are_sized_by_their_tolerance():
    # a - b = 0.001 against +-0.01, sd 0.005 over 10 clusters: inside once 0.001 + t(10k - 1) 0.005 / sqrt(k)
    # <= 0.01: not at k = 1.4 (t(13) 0.5556 = 1.200 > 1.183), at k = 1.5 (t(14) 0.5556 = 1.192 < 1.225)
    close = _margin(0.001, sampling_parts=[(2.5e-5, 9)]) | {"check": "close", "tol": 0.01}
    assert 1.4 < claim_power("t", _claim("inconclusive", close))["factor"] <= 1.5
    # a value 1.05 that must be >= 1: normal sd 0.05 gives [0.952, 1.148]; inside at half < 0.05, (Z)^2 = 3.84x
    rng = _margin(1.05, sampling_parts=[(2.5e-3, 1e9)]) | {"check": "range", "min": 1.0, "max": None}
    assert claim_power("t", _claim("inconclusive", rng))["factor"] == pytest.approx(Z ** 2, abs=0.08)


def test_a_claim_needs_every_check_and_one_without_interval_is_not_sized():
    quick, slow = _margin(0.01, sampling_parts=[(1e-4, 1e9)]), _margin(0.01, sampling_parts=[(4e-4, 1e9)])
    # each alone: (Z 0.01 / 0.01)^2 = 3.84x and (Z 0.02 / 0.01)^2 = 15.4x; both must reproduce
    assert claim_power("t", _claim("inconclusive", quick, slow))["factor"] == pytest.approx(4 * Z ** 2, rel=0.02)
    missing = {"comparison": None, "check": "order", "verdict": "inconclusive", "lo": None, "hi": None,
               "how": "x: missing b", "seed_parts": None, "sampling_parts": None}
    row = claim_power("t", _claim("inconclusive", quick, missing))
    assert row["factor"] is None and row["status"] == "no interval: x: missing b"
    # ... unless another check decides the claim against the thesis on its own (any contradicted check does)
    against = _margin(-0.01, sampling_parts=[(1e-4, 1e9)])
    assert claim_power("t", _claim("inconclusive", against, missing))["factor"] == pytest.approx(Z ** 2, abs=0.08)


def test_decided_ruled_out_and_unsized_claims():
    assert claim_power("t", _claim("reproduces", _margin(0.03, sampling_parts=[(1e-6, 9)])))["status"] == "decided"
    assert "ruled out" in claim_power("t", _claim("thesis effect ruled out", _margin(0.0)))["status"]
    assert claim_power("t", {"text": "c", "verdict": "inconclusive"})["status"].startswith("no margin")
    flat = claim_power("t", _claim("inconclusive", _margin(0.0, sampling_parts=[(1e-4, 9)])))
    assert flat["factor"] is None and flat["status"].startswith("not decided within 10000x")


def test_claim_margins_carry_the_parts_the_report_projects():
    # a beats b by 0.1 over 3 paired seeds with differences 0.0 / 0.1 / 0.2: variance 0.01 / 3, df 2,
    # interval 0.1 -+ t(2) 0.0577 = [-0.148, 0.348]
    cells = _Cells(pd.DataFrame({"x": [1.1, 1.0]}, index=["a", "b"]), {"x": False},
                   noise={"a": {"x": noise.seeds([1.0, 1.1, 1.2], pair="m")},
                          "b": {"x": noise.seeds([1.0, 1.0, 1.0], pair="m")}})
    verdict, _, (m,) = evaluate_check({"type": "order", "better": "a", "worse": "b", "metric": "x"}, cells, None)
    assert verdict == "inconclusive" and m["seed_parts"] == [[pytest.approx(0.01 / 3), 2.0]]
    assert m["sampling_parts"] == [] and m["hi"] == pytest.approx(0.1 + 4.302653 * math.sqrt(0.01 / 3), rel=1e-6)
    row = claim_power("t", _claim("inconclusive", m))
    # the seeds alone: 6 give t(5) 0.0577 / sqrt(2) = 0.105 > 0.1, 7 give t(6) 0.0577 / sqrt(7 / 3) = 0.092
    assert row["clusters needed"] is None and row["seeds needed"] == 7
    # a closeness check and a missing cell leave margin records too
    _, _, (c,) = evaluate_check({"type": "close", "a": "a", "b": "b", "metric": "x", "tol": 0.5}, cells, None)
    assert c["check"] == "close" and c["tol"] == 0.5 and c["verdict"] == "reproduces" and c["seed_parts"]
    _, _, (gone,) = evaluate_check({"type": "order", "better": "a", "worse": "z", "metric": "x"}, cells, None)
    assert gone["seed_parts"] is None and "missing z" in gone["how"]


def test_write_power_counts_only_counted_claims(tmp_path):
    score = {"table_id": "x", "claims": [_claim("inconclusive", _margin(0.01, sampling_parts=[(1e-4, 1e9)])),
                                         _claim("inconclusive", _margin(0.01, sampling_parts=[(1e-2, 1e9)])),
                                         {"text": "d", "verdict": "data description"}]}
    (tmp_path / "x.score.json").write_text(json.dumps(score))
    summary = write_power([tmp_path / "x.score.json"], tmp_path / "p.md", tmp_path / "p.csv")
    # (Z 0.01 / 0.01)^2 = 3.84x and (Z 0.1 / 0.01)^2 = 384x
    assert summary == {"counted": 2, "inconclusive": 2, "decidable_at_4x": 1, "decidable_at_16x": 1,
                       "by_seeds_alone": 0, "by_clusters_alone": 2}
    df = pd.read_csv(tmp_path / "p.csv")
    assert list(df["factor"]) == pytest.approx([Z ** 2, 100 * Z ** 2], rel=0.02)
    assert "| x | t | inconclusive | a vs b |" in (tmp_path / "p.md").read_text()
