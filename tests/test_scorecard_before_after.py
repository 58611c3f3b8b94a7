"""redsup.tables.before_after (tools/scorecard_before_after.py): the old (✔/✘) rules and the five categories on
the same build."""
import pandas as pd

from redsup.tables import before_after as sba


def test_the_old_rules_let_a_tie_win_the_new_ones_do_not():
    old = sba.old_evaluator("52093ff")
    from redsup.tables import claims as new

    tie = pd.DataFrame({"AP_BEV Easy": [0.0] * 5, "AP_BEV Medium": [0.0] * 5, "AP_BEV Hard": [0.0] * 5},
                       index=["||p - p'||^2", "SIC_{1,0}", "SIC_{5,0}", "SIC_{5,2.5}", "SIC_{10,5}"])
    text = "Every SIC parametrisation beats the plain L2 loss (L2 is the worst row)"
    [before] = [c for c in old.evaluate_claims("mccraith_ch7_table2", tie) if c["text"] == text]
    [after] = [c for c in new.evaluate_claims("mccraith_ch7_table2", tie) if c["text"] == text]
    assert before["holds"] is True  # 0 AP everywhere "reproduced" it
    assert after["verdict"] == "inconclusive"


def test_before_and_after_count_the_same_claims(tiny):
    before, after = sba.before_after(tiny, "52093ff")
    assert set(before) == set(after)
    for stage in after:
        assert sum(before[stage].values()) == sum(after[stage].values()), stage
    assert "| total |" in sba.report(before, after, "52093ff")
