# LiDAR-only detector trained from 2D detections, SIC loss, multi-cell voting (McCraith ch. 7).
# Appends its ids to TABLE_IDS / FIGURE_IDS (see common.smk).
TABLE_IDS += ["mccraith_ch7_table1", "mccraith_ch7_table2", "mccraith_ch7_table3"]

LD = config["lidar_detector"]
LD_RUNS = list(LD["runs"])
LD_TABLES = list(LD["tables"])
# the ch. 6 method on the same split (Table 1's "McCraith et al. [2022] †" row): written by the lifting stage
LD_LIFTING_METRICS = "results/lifting/metrics/full_cityscapes.json"
for _table, _rows in LD["tables"].items():
    _unknown = sorted(set(_rows.values()) - set(LD_RUNS))
    if _unknown:
        raise ValueError(f"config.yaml lidar_detector.tables.{_table}: unknown configurations {_unknown} "
                         f"(defined: {LD_RUNS})")


def _ld_split_scenes(split):
    """Scenes of the detector's dataset used for a split: train = train + long scenes, test = test scenes."""
    prefixes = ("train_", "long_") if split == "train" else ("test_",)
    return [s for s in scenes_of(LD["dataset"]) if s.startswith(prefixes)]


def _ld_split_inputs(wildcards):
    scenes = _ld_split_scenes(wildcards.split)
    return {
        "scenes": [f"results/raw/{LD['dataset']}/{s}" for s in scenes],
        "detections": [f"results/prepared/{LD['dataset']}/{s}/detections_{LD['level']}.npz" for s in scenes],
    }


def _ld_table_inputs(wildcards):
    runs = sorted(set(LD["tables"][wildcards.table].values()))
    out = {"metrics": expand("results/lidar_detector/metrics/{run}.json", run=runs)}
    if wildcards.table == "mccraith_ch7_table1":
        out["lifting"] = LD_LIFTING_METRICS
    return out


rule lidar_detector_split:
    input:
        unpack(_ld_split_inputs),
    output:
        "results/lidar_detector/data/{split}.npz",
    log:
        "results/logs/lidar_detector/data/{split}.log",
        run="results/runs/lidar_detector_split/{split}.json",
    wildcard_constraints:
        split="train|test",
    threads: 1
    resources:
        mem_mb=3000,
        runtime=20,
    conda:
        ENV
    script:
        "../scripts/lidar_detector_split.py"


rule lidar_detector_train:
    input:
        train="results/lidar_detector/data/train.npz",
        test="results/lidar_detector/data/test.npz",
    output:
        metrics="results/lidar_detector/metrics/{run}.json",
        model="results/lidar_detector/models/{run}.pt",
        detections="results/lidar_detector/detections/{run}.npz",
    log:
        "results/logs/lidar_detector/train/{run}.log",
        run="results/runs/lidar_detector_train/{run}.json",
    wildcard_constraints:
        run="|".join(LD_RUNS),
    threads: LD["threads"]
    resources:
        mem_mb=4000,
        runtime=60,
    conda:
        ENV
    script:
        "../scripts/lidar_detector_train.py"


rule lidar_detector_table:
    input:
        unpack(_ld_table_inputs),
    output:
        md="results/tables/{table}.md",
        csv="results/tables/{table}.csv",
        tex="results/tables/{table}.tex",
        score="results/tables/{table}.score.json",
    log:
        "results/logs/tables/{table}.log",
        run="results/runs/tables/{table}.json",
    wildcard_constraints:
        table="|".join(LD_TABLES),
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/lidar_detector_table.py"
