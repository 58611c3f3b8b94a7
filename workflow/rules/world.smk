# The embedded driving world: scenes in the canonical raw-scene format, and motorway clips in the
# TuSimple shape. Generation is deterministic given config seed, dataset, split and index.


rule world_scene:
    input:
    output:
        directory("results/raw/{dataset}/{scene}"),
    wildcard_constraints:
        dataset=_names_regex(WORLD_DATASETS),  # real datasets: adapt_scene (adapters.smk)
    log:
        "results/logs/raw/{dataset}/{scene}.log",
        run="results/runs/raw/{dataset}/{scene}.json",
    benchmark:
        "results/benchmarks/world_scene/raw/{dataset}/{scene}.tsv",
    threads: 1
    resources:
        mem_mb=job_mem_mb(3000),
        runtime=job_runtime(60),
    conda:
        ENVS["data"]
    script:
        "../scripts/world_scene.py"


rule world_clips:
    input:
    output:
        directory("results/raw/clips/{split}"),
    wildcard_constraints:
        split=_names_regex(WORLD_CLIP_SPLITS),  # splits of velocity_clips.source: adapt_clips (adapters.smk)
    log:
        "results/logs/raw/clips/{split}.log",
        run="results/runs/raw/clips/{split}.json",
    benchmark:
        "results/benchmarks/world_clips/raw/clips/{split}.tsv",
    threads: COMPUTE_THREADS
    resources:
        mem_mb=job_mem_mb(3000),
        runtime=job_runtime(60),
    conda:
        ENVS["data"]
    script:
        "../scripts/world_clips.py"
