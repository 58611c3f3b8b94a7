# Velocity from tracked boxes and synthetic box tracks (McCraith ch. 3).
#
# velocity_fit_generator  results/velocity/generator_statistics.json    the §IV-B generator, fitted on train
# velocity_baseline       results/velocity/{run}/metrics.json           geometric / constant (no learning)
# velocity_mlp            results/velocity/{run}/{metrics.json,model.pt} one MLP configuration and seed
# velocity_clip_counts    results/velocity/clip_counts.json             Table I's counts
# velocity_figure_numbers results/velocity/figures/{figure}.json  a figure's table rows and plotted data
# velocity_figure         results/figures/{figure}.png              the figure, drawn from its numbers
# The configurations and tables are data (config `velocity.configurations`, `velocity.tables.<table id>`),
# planned by redsup.velocity.plan; rule table builds every table.
import re

import redsup.velocity.plan as velocity_plan

VELOCITY_RUNS = velocity_plan.runs(config)
VELOCITY_BASELINES = [r for r, s in VELOCITY_RUNS.items() if s.get("method") in ("geometric", "constant")]
VELOCITY_MLP = [r for r, s in VELOCITY_RUNS.items() if s.get("method") == "mlp"]
# val: knobs are chosen on it (and the MLP training curves monitor it); test / abnormal: the tables
VELOCITY_EVAL_SPLITS = [s for s in ("val", "test", "abnormal") if s in CLIP_SPLIT_NAMES]
VELOCITY_FIGURES = [t for s in VELOCITY_RUNS.values() if "figure" in s for t in s["tables"]]


rule velocity_fit_generator:
    input:
        tracks="results/prepared/clips/train/medianflow.npz",
        clips="results/raw/clips/train",
    output:
        "results/velocity/generator_statistics.json",
    log:
        "results/logs/velocity/generator_statistics.log",
        run="results/runs/velocity/generator_statistics.json",
    benchmark:
        "results/benchmarks/velocity_fit_generator/velocity/generator_statistics.tsv",
    priority: VELOCITY_CHAIN_PRIORITY
    threads: 1
    resources:
        mem_mb=job_mem_mb(1000),
        runtime=job_runtime(10),
    conda:
        ENVS["velocity"]
    script:
        "../scripts/velocity_fit.py"


rule velocity_baseline:
    input:
        tracks=expand("results/prepared/clips/{split}/medianflow.npz", split=VELOCITY_EVAL_SPLITS),
        clips=expand("results/raw/clips/{split}", split=VELOCITY_EVAL_SPLITS),
        train_tracks="results/prepared/clips/train/medianflow.npz",
        train_clips="results/raw/clips/train",
    output:
        metrics="results/velocity/{run}/metrics.json",
        predictions="results/velocity/{run}/predictions.npz",
    log:
        "results/logs/velocity/{run}/metrics.log",
        run="results/runs/velocity/{run}/metrics.json",
    benchmark:
        "results/benchmarks/velocity_baseline/velocity/{run}/metrics.tsv",
    params:
        run=lambda wc: VELOCITY_RUNS[wc.run],
    wildcard_constraints:
        run="|".join(re.escape(r) for r in VELOCITY_BASELINES) or "(?!)",
    priority: VELOCITY_CHAIN_PRIORITY
    threads: 1
    resources:
        mem_mb=job_mem_mb(1000),
        runtime=job_runtime(10),
    conda:
        ENVS["velocity"]
    script:
        "../scripts/velocity_baseline.py"


rule velocity_mlp:
    input:
        tracks=expand("results/prepared/clips/{split}/medianflow.npz", split=VELOCITY_EVAL_SPLITS),
        clips=expand("results/raw/clips/{split}", split=VELOCITY_EVAL_SPLITS),
        train_tracks="results/prepared/clips/train/medianflow.npz",
        train_clips="results/raw/clips/train",
        # the fitted generator, for configurations trained on synthetic tracks
        generator=lambda wc: (
            ["results/velocity/generator_statistics.json"]
            if velocity_plan.configurations(config)[VELOCITY_RUNS[wc.run]["configuration"]].get("train_on")
            == "synthetic"
            else []
        ),
    output:
        metrics="results/velocity/{run}/metrics.json",
        predictions="results/velocity/{run}/predictions.npz",
        model="results/velocity/{run}/model.pt",
    log:
        "results/logs/velocity/{run}/metrics.log",
        run="results/runs/velocity/{run}/metrics.json",
    benchmark:
        "results/benchmarks/velocity_mlp/velocity/{run}/metrics.tsv",
    params:
        run=lambda wc: VELOCITY_RUNS[wc.run],
    wildcard_constraints:
        run="|".join(re.escape(r) for r in VELOCITY_MLP) or "(?!)",
    priority: VELOCITY_CHAIN_PRIORITY
    threads: COMPUTE_THREADS
    resources:
        mem_mb=job_mem_mb(2000),
        runtime=job_runtime(60),
    conda:
        ENVS["velocity"]
    script:
        "../scripts/velocity_mlp.py"


rule velocity_clip_counts:
    input:
        clips=lambda wc: expand("results/raw/clips/{split}", split=VELOCITY_RUNS["clip_counts"]["splits"]),
    output:
        "results/velocity/clip_counts.json",
    log:
        "results/logs/velocity/clip_counts.log",
        run="results/runs/velocity/clip_counts.json",
    benchmark:
        "results/benchmarks/velocity_clip_counts/velocity/clip_counts.tsv",
    threads: 1
    resources:
        mem_mb=job_mem_mb(1000),
        runtime=job_runtime(10),
    conda:
        ENVS["velocity"]
    script:
        "../scripts/velocity_clip_counts.py"


rule velocity_figure_numbers:
    input:
        tracks="results/prepared/clips/train/medianflow.npz",
        clips="results/raw/clips/train",
        generator="results/velocity/generator_statistics.json",
    output:
        "results/velocity/figures/{figure}.json",
    log:
        "results/logs/velocity/figures/{figure}.log",
        run="results/runs/velocity/figures/{figure}.json",
    benchmark:
        "results/benchmarks/velocity_figure_numbers/velocity/figures/{figure}.tsv",
    wildcard_constraints:
        figure="|".join(VELOCITY_FIGURES) or "(?!)",
    threads: 1
    resources:
        mem_mb=job_mem_mb(1000),
        runtime=job_runtime(10),
    conda:
        ENVS["velocity"]
    script:
        "../scripts/velocity_figure_numbers.py"


rule velocity_figure:
    input:
        numbers="results/velocity/figures/{figure}.json",
        generator="results/velocity/generator_statistics.json",
    output:
        report_figure("results/figures/{figure}.png"),
    log:
        "results/logs/figures/{figure}.log",
        run="results/runs/figures/{figure}.json",
    benchmark:
        "results/benchmarks/velocity_figure/figures/{figure}.tsv",
    wildcard_constraints:
        figure="|".join(VELOCITY_FIGURES) or "(?!)",
    threads: 1
    resources:
        mem_mb=job_mem_mb(1000),
        runtime=job_runtime(10),
    conda:
        ENVS["velocity"]
    script:
        "../scripts/velocity_figure.py"
