"""The scorecard under the old rules beside the current one, on one finished build's tables (issue 10).

Command line: python tools/scorecard_before_after.py BUILD_DIR [OLD_COMMIT] (or python -m redsup.tables.before_after)

"Before" is the claims evaluator of OLD_COMMIT (default 52093ff, the last one before the three-way verdicts):
a claim holds (✔) or fails (✘) on single numbers, ties win a `best` check, literature rows drop out of the
pool, and data descriptions and claims the thesis' own table contradicts are counted like any other. It is run
on the same numbers, the means (ours) in BUILD_DIR/results/tables/*.csv, with the same claims
(redsup/data/tables.yaml; the old evaluator ignores the keys it does not know). "After" is the five-category
count the build itself wrote in its *.score.json. The two differ only in how a claim is decided.
"""
from __future__ import annotations

import collections
import json
import subprocess
import sys
import types
from pathlib import Path

from redsup.tables import registry

ROOT = Path(__file__).resolve().parents[3]   # the checkout whose history holds OLD_COMMIT


def old_evaluator(commit: str) -> types.ModuleType:
    """The claims module of ``commit``, run against today's registry (it imports only helpers that exist)."""
    source = subprocess.run(["git", "-C", str(ROOT), "show", f"{commit}:workflow/redsup/tables/claims.py"],
                            check=True, capture_output=True, text=True).stdout
    module = types.ModuleType(f"claims_{commit}")
    exec(compile(source, f"{commit}:claims.py", "exec"), module.__dict__)  # noqa: S102 - our own history
    return module


def ours_frame(csv: Path):
    """The table's means as the old evaluator took them: one column per metric, rows by the first column."""
    import pandas as pd

    df = pd.read_csv(csv)
    cols = {c[: -len(" (ours)")]: df[c] for c in df.columns if c.endswith(" (ours)")}
    return pd.DataFrame(cols).set_axis(df[df.columns[0]].astype(str)) if cols else None


def before_after(build: Path, commit: str) -> tuple[dict, dict]:
    claims = old_evaluator(commit)
    reg = registry.load_registry()
    before: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    after: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    for score in sorted((build / "results" / "tables").glob("*.score.json")):
        s = json.loads(score.read_text())
        table, stage = s["table_id"], s["stage"]
        for counts in (before, after):  # every stage is listed, with or without claims
            counts.setdefault(stage, collections.Counter())
        for c in s["claims"]:
            after[stage][c["verdict"]] += 1
        frame = ours_frame(score.with_name(f"{table}.csv"))
        if frame is None:
            before[stage]["n/a"] += len(s["claims"])
            continue
        for c in claims.evaluate_claims(table, frame, registry=reg):
            before[stage][{True: "✔", False: "✘", None: "n/a"}[c["holds"]]] += 1
    return before, after


def report(before: dict, after: dict, commit: str) -> str:
    b_keys, a_keys = ["✔", "✘", "n/a"], ["reproduces", "inconclusive", "contradicted", "not testable",
                                          "data description"]
    head = (f"| stage | before ({commit}): {' / '.join(b_keys)} | after: {' / '.join(a_keys)} |\n"
            "|:---|:---|:---|\n")
    rows = []
    for stage in sorted(set(before) | set(after)) + ["total"]:
        b = sum(before.values(), collections.Counter()) if stage == "total" else before[stage]
        a = sum(after.values(), collections.Counter()) if stage == "total" else after[stage]
        rows.append(f"| {stage} | {' / '.join(str(b[k]) for k in b_keys)} | "
                    f"{' / '.join(str(a[k]) for k in a_keys)} |")
    return head + "\n".join(rows)


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if not argv:
        sys.exit(__doc__)
    commit = argv[1] if len(argv) > 1 else "52093ff"
    print(report(*before_after(Path(argv[0]), commit), commit))
    return 0


if __name__ == "__main__":
    sys.exit(main())
