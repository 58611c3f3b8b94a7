# Depth scale from the camera height: per-frame road-plane fit (McCraith ch. 5).
# Appends its ids to TABLE_IDS / FIGURE_IDS (see common.smk).
# Inference-free on top of the depth stage's raw predictions (rule predict_depth): every scaling method and
# every road-box configuration is one `calibration_eval` job (one child run), fanned out from config lists.
TABLE_IDS += ["mccraith_ch5_fig1", "mccraith_ch5_table1", "mccraith_ch5_table2", "mccraith_ch5_table3",
              "mccraith_ch5_table4"]
FIGURE_IDS += ["mccraith_ch5_fig1"]

CALIB = config["calibration"]
CALIB_TABLES = ("mccraith_ch5_table1", "mccraith_ch5_table2", "mccraith_ch5_table3", "mccraith_ch5_table4")


def calib_road_method(length, width):
    return f"road_L{float(length):g}_W{float(width):g}"


CALIB_OURS = calib_road_method(CALIB["length"], CALIB["width"])
# the methods each table needs (Table 3 varies the length at the default width, Table 4 the width)
CALIB_METHODS = {
    "mccraith_ch5_table1": ["single_train", "single_test", "fixed_plane", CALIB_OURS, "gt_median"],
    "mccraith_ch5_table2": ["gt_median", CALIB_OURS],
    "mccraith_ch5_table3": [calib_road_method(l, CALIB["width"]) for l in CALIB["lengths"]],
    "mccraith_ch5_table4": [calib_road_method(CALIB["length"], w) for w in CALIB["widths"]],
}


def calib_files(kind, split, dataset=CALIB["dataset"], mode=CALIB["mode"]):
    """Prediction / ground-truth / road files of every scene of one split of a dataset."""
    cam = config["detection"]["camera"]
    pattern = {
        "pred": "results/depth/predictions/{d}/{m}/{s}.npz",
        "gt": "results/prepared/{d}/{s}/{cam}_depth.npz",
        "road": "results/prepared/{d}/{s}/road.npz",
    }[kind]
    scenes = [s for s in scenes_of(dataset) if s.startswith(split + "_")]
    return [pattern.format(d=dataset, m=mode, s=s, cam=cam) for s in scenes]


def calib_eval_inputs(wildcards):
    d, m = wildcards.dataset, wildcards.mode
    files = {k: calib_files(k, "test", d, m) for k in ("pred", "gt", "road")}
    if wildcards.method == "single_train":
        files.update(train_pred=calib_files("pred", "train", d, m), train_gt=calib_files("gt", "train", d, m))
    return files


rule calibration_eval:
    input:
        unpack(calib_eval_inputs),
    output:
        "results/calibration/{dataset}/{mode}/{method}.json",
    log:
        "results/logs/calibration/{dataset}/{mode}/{method}.log",
        run="results/runs/calibration/{dataset}/{mode}/{method}.json",
    wildcard_constraints:
        mode=r"[A-Za-z]+",
        method=r"gt_median|single_train|single_test|fixed_plane|road_L[0-9.]+_W[0-9.]+",
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
        lambda wc: expand(
            "results/calibration/{d}/{m}/{method}.json",
            d=CALIB["dataset"],
            m=CALIB["mode"],
            method=CALIB_METHODS[wc.table],
        ),
    output:
        md="results/tables/{table}.md",
        csv="results/tables/{table}.csv",
        tex="results/tables/{table}.tex",
        score="results/tables/{table}.score.json",
    log:
        "results/logs/tables/{table}.log",
        run="results/runs/tables/{table}.json",
    wildcard_constraints:
        table="|".join(CALIB_TABLES),
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
        pred=calib_files("pred", CALIB["figure_split"]),
        gt=calib_files("gt", CALIB["figure_split"]),
        road=calib_files("road", CALIB["figure_split"]),
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
