# Self-supervised depth, test-time instance adaptation, Galteland's tables (McCraith ch. 4).
#
# train_depth    results/depth/models/{dataset}/{mode}.pt           one model (M, S, MS, M_frontback, ...)
# predict_depth  results/depth/predictions/{dataset}/{mode}/{scene}.npz   raw network depth of every frame
# depth_eval     results/depth/eval/{run}.json                      one configuration (a child run)
# depth_table    results/tables/<id>.{md,csv,tex,score.json}        one table from its runs
# depth_figure   results/figures/<id>.png (+ the table beside it)   Figs. 4 and 5
# The configurations are data (config `depth.tables`, `depth.galteland`), expanded by
# redsup.depth.configs.table_rows; rows that need the same run share one depth_eval job.
import re

import redsup.depth.configs as depth_configs

DEPTH = config["depth"]
DEPTH_TABLE_IDS = [t for t in depth_configs.TABLES if t not in depth_configs.FIGURES]

DEPTH_AVAILABLE, DEPTH_CAMERAS = depth_configs.availability(config)  # as scenes_of / cameras_of count them
DEPTH_ROWS = depth_configs.table_rows(DEPTH, DEPTH_AVAILABLE, DEPTH_CAMERAS)
DEPTH_RUNS, DEPTH_ROW_RUNS = depth_configs.plan(DEPTH_ROWS)


rule train_depth:
    input:
        unpack(lambda wc: depth_configs.train_inputs(config, wc.dataset, wc.mode)),
    output:
        "results/depth/models/{dataset}/{mode}.pt",
    log:
        "results/logs/depth/train/{dataset}/{mode}.log",
        run="results/runs/depth/train/{dataset}/{mode}.json",
    wildcard_constraints:
        mode=r"[A-Za-z0-9_]+",
    threads: 1
    resources:
        mem_mb=3000,
        runtime=60,
    conda:
        ENV
    script:
        "../scripts/depth_train.py"


rule predict_depth:
    input:
        model="results/depth/models/{dataset}/{mode}.pt",
        images="results/prepared/{dataset}/{scene}/cam_front.npz",
    output:
        "results/depth/predictions/{dataset}/{mode}/{scene}.npz",
    log:
        "results/logs/depth/predict/{dataset}/{mode}/{scene}.log",
        run="results/runs/depth/predict/{dataset}/{mode}/{scene}.json",
    wildcard_constraints:
        mode=r"[A-Za-z0-9_]+",
    threads: 1
    resources:
        mem_mb=2000,
        runtime=20,
    conda:
        ENV
    script:
        "../scripts/depth_predict.py"


rule depth_eval:
    input:
        unpack(lambda wc: depth_configs.eval_inputs(config, DEPTH_RUNS[wc.run][0])),
    output:
        "results/depth/eval/{run}.json",
    log:
        "results/logs/depth/eval/{run}.log",
        run="results/runs/depth/eval/{run}.json",
    wildcard_constraints:
        run="|".join(re.escape(r) for r in sorted(DEPTH_RUNS)) or "no_depth_runs",
    threads: 1
    resources:
        mem_mb=3000,
        runtime=60,
    conda:
        ENV
    script:
        "../scripts/depth_eval.py"


rule depth_table:
    input:
        lambda wc: depth_configs.table_inputs(DEPTH_ROW_RUNS, wc.table),
    output:
        md="results/tables/{table}.md",
        csv="results/tables/{table}.csv",
        tex="results/tables/{table}.tex",
        score="results/tables/{table}.score.json",
    log:
        "results/logs/tables/{table}.log",
        run="results/runs/tables/{table}.json",
    wildcard_constraints:
        table="|".join(DEPTH_TABLE_IDS),
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/depth_table.py"


rule depth_figure:
    input:
        lambda wc: depth_configs.table_inputs(DEPTH_ROW_RUNS, wc.table),
    output:
        png="results/figures/{table}.png",
        md="results/tables/{table}.md",
        csv="results/tables/{table}.csv",
        tex="results/tables/{table}.tex",
        score="results/tables/{table}.score.json",
    log:
        "results/logs/figures/{table}.log",
        run="results/runs/figures/{table}.json",
    wildcard_constraints:
        table="|".join(depth_configs.FIGURES),
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/depth_table.py"
