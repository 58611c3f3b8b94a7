# Self-supervised depth, test-time instance adaptation, Galteland's tables (McCraith ch. 4).
#
# train_depth    results/depth/models/{dataset}/{mode}[/seed{k}].pt one model (M, S, MS, M_frontback, ...) per seed,
#                and .json beside it: its meta (sizes, training summary, validation history) and configuration
# predict_depth  results/depth/predictions/{dataset}/{mode}[/seed{k}]/{scene}.npz   raw network depth of every
#                frame (the mode's model of calibration.model_dataset when set, else of the dataset; seed k)
# depth_eval     results/depth/eval/{run}.json                      one configuration (a child run)
# depth_figure   results/figures/<id>.png                           Figs. 4 and 5 (their tables: rule table)
# galteland_figure results/figures/galteland_fig4_<n>.png           Galteland's progression / qualitative figures
#                (depth.figures; training runs of Manydepth / Feature Depth log val metrics per epoch)
# The tables are data (config `depth.tables.<table id>`), expanded by redsup.depth.plan; rows that need the
# same run share one depth_eval job.
import re

import redsup.depth.plan as depth_plan

DEPTH_RUNS = depth_plan.runs(config, scenes_of)
DEPTH_MODELS = depth_plan.models(config, scenes_of)  # <dataset>/<mode>[/seed<k>]
DEPTH_FIGURES = [t for t in FIGURE_IDS if "figure" in config["depth"]["tables"].get(t, {})]
# depth.figures: progression / qualitative PNGs (targets of rule all with the tables' figures: tables.smk)
GALTELAND_FIGURES = depth_plan.figures(config, scenes_of)


rule train_depth:
    input:
        unpack(lambda wc: depth_plan.train_files(config, wc.model, scenes_of)),
    output:
        model="results/depth/models/{model}.pt",
        meta="results/depth/models/{model}.json",
    log:
        "results/logs/depth/models/{model}.log",
        run="results/runs/depth/models/{model}.json",
    benchmark:
        "results/benchmarks/train_depth/depth/models/{model}.tsv",
    wildcard_constraints:
        model="|".join(re.escape(m) for m in DEPTH_MODELS) or "(?!)",
    threads: COMPUTE_THREADS
    resources:
        mem_mb=job_mem_mb(3000),
        runtime=job_runtime(60),
    conda:
        ENVS["depth"]
    script:
        "../scripts/depth_train.py"


rule predict_depth:
    input:
        model=lambda wc: depth_plan.prediction_model(config, wc.dataset, wc.mode, scenes_of),
        images="results/prepared/{dataset}/{scene}/cam_front.npz",
    output:
        "results/depth/predictions/{dataset}/{mode}/{scene}.npz",
    log:
        "results/logs/depth/predictions/{dataset}/{mode}/{scene}.log",
        run="results/runs/depth/predictions/{dataset}/{mode}/{scene}.json",
    benchmark:
        "results/benchmarks/predict_depth/depth/predictions/{dataset}/{mode}/{scene}.tsv",
    wildcard_constraints:
        mode=r"[A-Za-z0-9_]+(/seed[1-9][0-9]*)?",
    threads: COMPUTE_THREADS
    resources:
        mem_mb=job_mem_mb(2000),
        runtime=job_runtime(20),
    conda:
        ENVS["depth"]
    script:
        "../scripts/depth_predict.py"


rule depth_eval:
    input:
        unpack(lambda wc: depth_plan.eval_files(config, DEPTH_RUNS[wc.run], scenes_of)),
    output:
        "results/depth/eval/{run}.json",
    params:
        run=lambda wc: DEPTH_RUNS[wc.run],
    log:
        "results/logs/depth/eval/{run}.log",
        run="results/runs/depth/eval/{run}.json",
    benchmark:
        "results/benchmarks/depth_eval/depth/eval/{run}.tsv",
    wildcard_constraints:
        run="|".join(re.escape(r) for r in sorted(DEPTH_RUNS)) or "no_depth_runs",
    threads: COMPUTE_THREADS
    resources:
        mem_mb=job_mem_mb(3000),
        runtime=job_runtime(60),
    conda:
        ENVS["depth"]
    script:
        "../scripts/depth_eval.py"


rule depth_figure:
    input:
        lambda wc: [depth_plan.result_path(run) for run in dict.fromkeys(r[1] for r in TABLE_ROWS.get(wc.figure, []))],
    output:
        report_figure("results/figures/{figure}.png"),
    log:
        "results/logs/figures/{figure}.log",
        run="results/runs/figures/{figure}.json",
    benchmark:
        "results/benchmarks/depth_figure/figures/{figure}.tsv",
    params:
        rows=lambda wc: [list(r) for r in TABLE_ROWS.get(wc.figure, [])],
    wildcard_constraints:
        figure="|".join(DEPTH_FIGURES) or "(?!)",
    threads: 1
    resources:
        mem_mb=job_mem_mb(1000),
        runtime=job_runtime(10),
    conda:
        ENVS["depth"]
    script:
        "../scripts/depth_figure.py"


rule galteland_figure:
    input:
        unpack(lambda wc: depth_plan.figure_files(config, wc.figure, scenes_of)),
    output:
        "results/figures/{figure}.png",
    log:
        "results/logs/figures/{figure}.log",
        run="results/runs/figures/{figure}.json",
    benchmark:
        "results/benchmarks/galteland_figure/figures/{figure}.tsv",
    wildcard_constraints:
        figure="|".join(GALTELAND_FIGURES) or "(?!)",
    threads: 1
    resources:
        mem_mb=job_mem_mb(2000),
        runtime=job_runtime(10),
    conda:
        ENVS["depth"]
    script:
        "../scripts/depth_galteland_figure.py"
