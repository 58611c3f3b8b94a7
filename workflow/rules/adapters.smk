# Real datasets as drop-in inputs (README.md, "Running on the real datasets"): KITTI raw, KITTI object and scene-folder datasets
# converted into the canonical raw-scene format where world_scene would have rendered them, and TuSimple
# velocity splits into the clip folders. Which datasets / clip splits these rules serve is decided by the
# wildcard constraints built in common.smk from config (kind != world; velocity_clips.source.splits).


rule adapt_scene:
    input:
    output:
        directory("results/raw/{dataset}/{scene}"),
    wildcard_constraints:
        dataset=_names_regex(ADAPTER_DATASETS),
    log:
        "results/logs/raw/{dataset}/{scene}.log",
        run="results/runs/raw/{dataset}/{scene}.json",
    benchmark:
        "results/benchmarks/adapt_scene/raw/{dataset}/{scene}.tsv",
    threads: 1
    resources:
        mem_mb=job_mem_mb(2000),
        runtime=job_runtime(30),
    conda:
        ENVS["data"]
    script:
        "../scripts/adapt_scene.py"


rule adapt_clips:
    input:
    output:
        directory("results/raw/clips/{split}"),
    wildcard_constraints:
        split=_names_regex(SOURCE_CLIP_SPLITS),
    log:
        "results/logs/raw/clips/{split}.log",
        run="results/runs/raw/clips/{split}.json",
    benchmark:
        "results/benchmarks/adapt_clips/raw/clips/{split}.tsv",
    threads: 1
    resources:
        mem_mb=job_mem_mb(1000),
        runtime=job_runtime(30),
    conda:
        ENVS["data"]
    script:
        "../scripts/adapt_clips.py"
