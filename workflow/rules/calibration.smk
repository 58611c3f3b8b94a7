# Depth scale from the camera height: per-frame road-plane fit (McCraith ch. 5).
#
# calibration_eval    results/calibration/{dataset}/{mode}/{method}.json        one scaling method / road box
# calibration_series  results/calibration/{dataset}/{mode}/series_{split}.json  Fig. 1's per-frame scales
# calibration_fig1    results/figures/{figure}.png                              Fig. 1 (its table: rule table)
# Inference-free on top of the depth stage's raw predictions (rule predict_depth). Tables 1-4 and Fig. 1's
# table go through rule table (tables.smk) with redsup.calib.plan; their rows are config
# calibration.tables.<table id>. Camera heights and fps come from each scene's extrinsics / scene.json.
import redsup.calib.plan as calib_plan


CALIB_FIGURES = calib_plan.figure_series(config)


rule calibration_eval:
    input:
        unpack(
            lambda wc: calib_plan.eval_inputs(config, scenes_of(wc.dataset), wc.dataset, wc.mode, wc.method)
        ),
    output:
        "results/calibration/{dataset}/{mode}/{method}.json",
    log:
        "results/logs/calibration/{dataset}/{mode}/{method}.log",
        run="results/runs/calibration/{dataset}/{mode}/{method}.json",
    benchmark:
        "results/benchmarks/calibration_eval/calibration/{dataset}/{mode}/{method}.tsv",
    params:
        parent=lambda wc: calib_plan.parent_of(config, scenes_of, wc.dataset, wc.mode, wc.method),
    wildcard_constraints:
        mode=calib_plan.SEED_MODE,
        method=calib_plan.METHOD_PATTERN,
    threads: 1
    resources:
        mem_mb=job_mem_mb(2000),
        runtime=job_runtime(15),
    conda:
        ENVS["calibration"]
    script:
        "../scripts/calibration_eval.py"


rule calibration_series:
    input:
        unpack(
            lambda wc: calib_plan.series_inputs(config, scenes_of(wc.dataset), wc.dataset, wc.mode, wc.split)
        ),
    output:
        "results/calibration/{dataset}/{mode}/series_{split}.json",
    log:
        "results/logs/calibration/{dataset}/{mode}/series_{split}.log",
        run="results/runs/calibration/{dataset}/{mode}/series_{split}.json",
    benchmark:
        "results/benchmarks/calibration_series/calibration/{dataset}/{mode}/series_{split}.tsv",
    params:
        parent=lambda wc: calib_plan.parent_of(config, scenes_of, wc.dataset, wc.mode, f"series_{wc.split}"),
    wildcard_constraints:
        mode=calib_plan.SEED_MODE,
        split=r"train|test|long",
    threads: 1
    resources:
        mem_mb=job_mem_mb(2000),
        runtime=job_runtime(10),
    conda:
        ENVS["calibration"]
    script:
        "../scripts/calibration_series.py"


rule calibration_fig1:
    input:
        series=lambda wc: calib_plan.result_path(CALIB_FIGURES[wc.figure]),
    output:
        png=report_figure("results/figures/{figure}.png"),
    log:
        "results/logs/figures/{figure}.log",
        run="results/runs/figures/{figure}.json",
    benchmark:
        "results/benchmarks/calibration_fig1/figures/{figure}.tsv",
    wildcard_constraints:
        figure="|".join(CALIB_FIGURES) or "(?!)",
    threads: 1
    resources:
        mem_mb=job_mem_mb(1000),
        runtime=job_runtime(10),
    conda:
        ENVS["calibration"]
    script:
        "../scripts/calibration_fig1.py"
