# LiDAR-only detector trained from 2D detections, SIC loss, multi-cell voting (McCraith ch. 7).
#
# lidar_detector_split  results/lidar_detector/data/{train,test}.npz   the cached frames of a split
# lidar_detector_train  results/lidar_detector/{metrics,models,detections}/{conf}/seed{seed}.*   one configuration
#                       trained with one seed index (a child run) and evaluated on the test split
# The ch. 7 tables (tables.yaml, stage detector) are built by rule table (tables.smk) from redsup.lidar_detector.plan:
# configurations (`lidar_detector.runs`), seeds and rows (`lidar_detector.tables.<id>`) are data; Table 1's
# ch. 6 row is read from the lifting stage's runs of `lifting.full_method`.
import redsup.lidar_detector.plan as ld_plan

LD = config["lidar_detector"]
LD_CONFS = list(LD["runs"])
LD_SEEDS = [str(int(k)) for k in LD["seeds"]]
ld_plan.check_tables(LD)


rule lidar_detector_split:
    input:
        unpack(lambda wc: ld_plan.split_inputs(LD, scenes_of(LD["dataset"]), wc.split)),
    output:
        "results/lidar_detector/data/{split}.npz",
    log:
        "results/logs/lidar_detector/data/{split}.log",
        run="results/runs/lidar_detector/data/{split}.json",
    benchmark:
        "results/benchmarks/lidar_detector_split/lidar_detector/data/{split}.tsv",
    wildcard_constraints:
        split="train|test",
    threads: 1
    resources:
        mem_mb=job_mem_mb(3000),
        runtime=job_runtime(20),
    conda:
        ENVS["detector"]
    script:
        "../scripts/lidar_detector_split.py"


rule lidar_detector_train:
    input:
        train="results/lidar_detector/data/train.npz",
        test="results/lidar_detector/data/test.npz",
        template="results/det3d/template/lidar_detector.npz",
    output:
        metrics="results/lidar_detector/metrics/{conf}/seed{seed}.json",
        model="results/lidar_detector/models/{conf}/seed{seed}.pt",
        detections="results/lidar_detector/detections/{conf}/seed{seed}.npz",
    log:
        "results/logs/lidar_detector/metrics/{conf}/seed{seed}.log",
        run="results/runs/lidar_detector/metrics/{conf}/seed{seed}.json",
    benchmark:
        "results/benchmarks/lidar_detector_train/lidar_detector/metrics/{conf}/seed{seed}.tsv",
    wildcard_constraints:
        conf="|".join(LD_CONFS),
        seed="|".join(LD_SEEDS),
    threads: COMPUTE_THREADS
    resources:
        mem_mb=job_mem_mb(4000),
        runtime=job_runtime(60),
    conda:
        ENVS["detector"]
    script:
        "../scripts/lidar_detector_train.py"
