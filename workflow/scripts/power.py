"""Snakemake entry point: every table's counted claims sized in results/tables/power.md / .csv."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821

from redsup.tables.power import write_power  # noqa: E402

sm = snakemake  # noqa: F821
print(write_power(list(sm.input), sm.output.md, sm.output.csv))
