# LiDAR-only detector trained from 2D detections, SIC loss, multi-cell voting (McCraith ch. 7).

import redsup.lidar_detector.dag as ld_dag

LD = config["lidar_detector"]
LD_RUNS = list(LD["runs"])
LD_TABLES = list(LD["tables"])
# the ch. 6 method on the same split (Table 1's "McCraith et al. [2022] †" row): written by the lifting stage
LD_LIFTING_METRICS = "results/lifting/metrics/full_cityscapes.json"
ld_dag.check_tables(LD)


rule lidar_detector_split:
    input:
        unpack(lambda wc: ld_dag.split_inputs(LD, scenes_of(LD["dataset"]), wc.split)),
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
        unpack(lambda wc: ld_dag.table_inputs(LD, wc.table, LD_LIFTING_METRICS)),
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
