"""redsup.tables.before_after (tools/scorecard_before_after.py): the old (✔/✘) rules and the five categories on
the same build.

The old rules are read from the git history (``git show OLD:...``): where the checkout has no history (a
tarball or a copy without .git, a shallow clone without OLD, no git at all) those tests skip, saying why."""
import shutil
import subprocess
from pathlib import Path

import pandas as pd
import pytest

from redsup.tables import before_after as sba

OLD = "52093ff"  # the last commit before the three-way verdicts (sba's default)
OLD_CLAIMS = "workflow/redsup/tables/claims.py"


def missing_history(root: Path, commit: str, path: str = OLD_CLAIMS) -> str | None:
    """Why ``git show commit:path`` cannot work in ``root``, or None when it can."""
    if not (root / ".git").exists():
        return f"no git history at {root} (a tarball or a copy without .git)"
    if shutil.which("git") is None:
        return "git is not installed"
    for obj, what in ((f"{commit}^{{commit}}", f"commit {commit}"), (f"{commit}:{path}", f"{path} at {commit}")):
        if subprocess.run(["git", "-C", str(root), "cat-file", "-e", obj], capture_output=True).returncode != 0:
            return f"{what} is not in the git history at {root} (a shallow clone?)"
    return None


@pytest.fixture(scope="session")
def old_commit() -> str:
    """OLD, or a skip where the checkout's history does not hold it."""
    reason = missing_history(sba.ROOT, OLD)
    if reason:
        pytest.skip(f"the old claims evaluator needs {OLD}: {reason}")
    return OLD


def test_missing_history_says_why(tmp_path):
    assert "no git history" in missing_history(tmp_path, OLD)
    if (sba.ROOT / ".git").exists() and shutil.which("git"):
        assert "0000000 is not in the git history" in missing_history(sba.ROOT, "0000000")


def test_the_old_rules_let_a_tie_win_the_new_ones_do_not(old_commit):
    old = sba.old_evaluator(old_commit)
    from redsup.tables import claims as new

    tie = pd.DataFrame({"AP_BEV Easy": [0.0] * 5, "AP_BEV Medium": [0.0] * 5, "AP_BEV Hard": [0.0] * 5},
                       index=["||p - p'||^2", "SIC_{1,0}", "SIC_{5,0}", "SIC_{5,2.5}", "SIC_{10,5}"])
    text = "Every SIC parametrisation beats the plain L2 loss (L2 is the worst row)"
    [before] = [c for c in old.evaluate_claims("mccraith_ch7_table2", tie) if c["text"] == text]
    [after] = [c for c in new.evaluate_claims("mccraith_ch7_table2", tie) if c["text"] == text]
    assert before["holds"] is True  # 0 AP everywhere "reproduced" it
    assert after["verdict"] == "inconclusive"


def test_before_and_after_count_the_same_claims(old_commit, tiny):
    before, after = sba.before_after(tiny, old_commit)
    assert set(before) == set(after)
    for stage in after:
        assert sum(before[stage].values()) == sum(after[stage].values()), stage
    assert "| total |" in sba.report(before, after, old_commit)
