"""Snakemake entry point: gather every <table>.score.json into results/tables/scorecard.md."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821

from redsup.tables import write_scorecard  # noqa: E402

sm = snakemake  # noqa: F821
summary = write_scorecard(list(sm.input), sm.output[0])
print(summary)
