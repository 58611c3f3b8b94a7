"""The power report sizes each counted claim from its decided margin (redsup.tables.power), by hand."""
import json

import pandas as pd
import pytest

from redsup.tables.power import claim_power, write_power


def _claim(verdict, lo, hi, clusters=10, seeds=3, margin=None, effect=0.02):
    return {"text": "t", "verdict": verdict,
            "margins": [{"comparison": "a vs b", "lo": lo, "hi": hi, "margin": margin if margin is not None else
                         (lo + hi) / 2, "thesis_effect": effect, "clusters": clusters, "seeds": seeds, "how": "x"}]}


def test_an_undecided_margin_needs_half_width_over_centre_squared_units():
    # centre 0.01, half width 0.02: (0.02 / 0.01)^2 = 4x: 40 clusters, 12 seeds
    row = claim_power("t1", _claim("inconclusive", -0.01, 0.03))
    assert row["half width"] == pytest.approx(0.02) and row["factor"] == pytest.approx(4.0)
    assert (row["clusters needed"], row["seeds needed"]) == (40, 12)
    assert row["status"] == "needs about 4.0x the units"


def test_decided_ruled_out_and_unsized_claims():
    assert claim_power("t", _claim("reproduces", 0.01, 0.03))["status"] == "decided"
    assert "ruled out" in claim_power("t", _claim("thesis effect ruled out", -0.01, 0.01))["status"]
    assert claim_power("t", {"text": "c", "verdict": "inconclusive"})["status"].startswith("no margin")
    nan = claim_power("t", _claim("inconclusive", None, None, margin=0.0))
    assert nan["status"].startswith("no interval") and nan["factor"] is None


def test_write_power_counts_only_counted_claims(tmp_path):
    score = {"table_id": "x", "claims": [_claim("inconclusive", -0.01, 0.03), _claim("inconclusive", -0.09, 0.11),
                                         {"text": "d", "verdict": "data description"}]}
    (tmp_path / "x.score.json").write_text(json.dumps(score))
    summary = write_power([tmp_path / "x.score.json"], tmp_path / "p.md", tmp_path / "p.csv")
    assert summary == {"counted": 2, "inconclusive": 2, "decidable_at_4x": 1, "decidable_at_16x": 1}  # 4x and 100x
    df = pd.read_csv(tmp_path / "p.csv")
    assert list(df["factor"]) == pytest.approx([4.0, 100.0])
    assert "| x | t | inconclusive | a vs b |" in (tmp_path / "p.md").read_text()
