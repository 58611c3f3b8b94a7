# The embedded driving world: scenes in the canonical raw-scene format, and motorway clips in the
# TuSimple shape. Generation is deterministic given config seed, dataset, split and index.
import redsup.world.shards as clip_shards


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


# A split's clips render in shards of velocity_clips.shard_size, one job each (the default train split: 8 jobs of
# about 3 min instead of one of half an hour); world_clips hard-links them into the split's folder. A clip depends only
# on (seed, split, clip), so the files are those of one job for the whole split. A killed build keeps its finished
# shards; a shard is written atomically, so a failed one leaves nothing. CLIP_SHARDS: split -> its shards' names
# (consecutive clips, redsup.world.shards).
CLIP_SHARDS = {
    split: clip_shards.names(config["velocity_clips"]["splits"][split]["clips"], config["velocity_clips"]["shard_size"])
    for split in WORLD_CLIP_SPLITS
}


rule world_clips_shard:
    input:
    output:
        temp(directory("results/raw/clip_shards/{split}/{shard}")),
    wildcard_constraints:
        split=_names_regex(WORLD_CLIP_SPLITS),
        shard=r"\d+-\d+",
    log:
        "results/logs/raw/clip_shards/{split}/{shard}.log",
        run="results/runs/raw/clip_shards/{split}/{shard}.json",
    benchmark:
        "results/benchmarks/world_clips_shard/raw/clip_shards/{split}/{shard}.tsv",
    priority: VELOCITY_CHAIN_PRIORITY
    threads: COMPUTE_THREADS
    resources:
        mem_mb=job_mem_mb(3000),
        runtime=job_runtime(15),
    conda:
        ENVS["data"]
    script:
        "../scripts/world_clips_shard.py"


rule world_clips:
    input:
        lambda wc: expand("results/raw/clip_shards/{split}/{shard}", split=wc.split, shard=CLIP_SHARDS[wc.split]),
    output:
        directory("results/raw/clips/{split}"),
    wildcard_constraints:
        split=_names_regex(WORLD_CLIP_SPLITS),  # splits of velocity_clips.source: adapt_clips (adapters.smk)
    log:
        "results/logs/raw/clips/{split}.log",
        run="results/runs/raw/clips/{split}.json",
    benchmark:
        "results/benchmarks/world_clips/raw/clips/{split}.tsv",
    priority: VELOCITY_CHAIN_PRIORITY
    threads: 1
    resources:
        mem_mb=job_mem_mb(1000),
        runtime=job_runtime(10),
    conda:
        ENVS["data"]
    script:
        "../scripts/world_clips.py"
