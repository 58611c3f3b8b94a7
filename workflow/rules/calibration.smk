# Depth scale from the camera height: per-frame road-plane fit (McCraith ch. 5).
#
# calibration_eval   results/calibration/{dataset}/{mode}/{method}.json   one scaling method / road box (a child run)
# calibration_table  results/tables/mccraith_ch5_table{1..4}.{md,csv,tex,score.json}
# calibration_fig1   results/figures/mccraith_ch5_fig1.png (+ its summary table)
# Inference-free on top of the depth stage's raw predictions (rule predict_depth). The methods are data:
# config calibration.lengths / widths expanded by redsup.calib.plan.table_methods.
import redsup.calib.plan as calib_plan


CALIB = config["calibration"]
CALIB_SPLIT = CALIB["figure_split"]


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
    wildcard_constraints:
        mode=r"[A-Za-z]+",
        method=calib_plan.METHOD_PATTERN,
    threads: 1
    resources:
        mem_mb=2000,
        runtime=15,
    conda:
        ENV
    script:
        "../scripts/calibration_eval.py"


rule calibration_table:
    input:
        lambda wc: calib_plan.result_files(CALIB, wc.table),
    output:
        md="results/tables/{table}.md",
        csv="results/tables/{table}.csv",
        tex="results/tables/{table}.tex",
        score="results/tables/{table}.score.json",
    log:
        "results/logs/tables/{table}.log",
        run="results/runs/tables/{table}.json",
    wildcard_constraints:
        table="|".join(calib_plan.TABLES),
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/calibration_table.py"


rule calibration_fig1:
    input:
        pred=calib_plan.scene_files(config, scenes_of(CALIB["dataset"]), "pred", CALIB_SPLIT),
        gt=calib_plan.scene_files(config, scenes_of(CALIB["dataset"]), "gt", CALIB_SPLIT),
        road=calib_plan.scene_files(config, scenes_of(CALIB["dataset"]), "road", CALIB_SPLIT),
        raw=calib_plan.scene_files(config, scenes_of(CALIB["dataset"]), "raw", CALIB_SPLIT),
        single=f"results/calibration/{CALIB['dataset']}/{CALIB['mode']}/single_train.json",
    output:
        png="results/figures/mccraith_ch5_fig1.png",
        md="results/tables/mccraith_ch5_fig1.md",
        csv="results/tables/mccraith_ch5_fig1.csv",
        tex="results/tables/mccraith_ch5_fig1.tex",
        score="results/tables/mccraith_ch5_fig1.score.json",
    log:
        "results/logs/figures/mccraith_ch5_fig1.log",
        run="results/runs/figures/mccraith_ch5_fig1.json",
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/calibration_fig1.py"
