"""redsup: reproduction of McCraith (2022) and Galteland (2021) as a Snakemake workflow.

Small modules: `config` (schema + size profiles), `geometry` (pure camera / pose maths),
`sceneio` (the canonical raw-scene format, validated on read), `world` (the embedded driving world),
`prep` (data preparation), `tracking` (MLflow), `tables` (paper-vs-ours tables and scorecard).
"""

__version__ = "0.1.0"
