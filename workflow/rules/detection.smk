# Stand-ins for pretrained 2D perception (instance segmenter at two quality levels, road segmenter),
# L_m point sets, 3D tracks across frames, and MedianFlow box tracks of the velocity clips.


rule detect_instances:
    input:
        scene="results/raw/{dataset}/{scene}",
    output:
        "results/prepared/{dataset}/{scene}/detections_{level}.npz",
    log:
        "results/logs/prepared/{dataset}/{scene}/detections_{level}.log",
        run="results/runs/prepared/{dataset}/{scene}/detections_{level}.json",
    benchmark:
        "results/benchmarks/detect_instances/prepared/{dataset}/{scene}/detections_{level}.tsv",
    threads: 1
    resources:
        mem_mb=job_mem_mb(2000),
        runtime=job_runtime(30),
    conda:
        ENVS["data"]
    script:
        "../scripts/detect_instances.py"


rule segment_road:
    input:
        scene="results/raw/{dataset}/{scene}",
    output:
        "results/prepared/{dataset}/{scene}/road.npz",
    log:
        "results/logs/prepared/{dataset}/{scene}/road.log",
        run="results/runs/prepared/{dataset}/{scene}/road.json",
    benchmark:
        "results/benchmarks/segment_road/prepared/{dataset}/{scene}/road.tsv",
    threads: 1
    resources:
        mem_mb=job_mem_mb(2000),
        runtime=job_runtime(30),
    conda:
        ENVS["data"]
    script:
        "../scripts/segment_road.py"


rule tracks3d:
    input:
        scene="results/raw/{dataset}/{scene}",
        detections="results/prepared/{dataset}/{scene}/detections_{level}.npz",
    output:
        "results/prepared/{dataset}/{scene}/tracks3d_{level}.csv",
    log:
        "results/logs/prepared/{dataset}/{scene}/tracks3d_{level}.log",
        run="results/runs/prepared/{dataset}/{scene}/tracks3d_{level}.json",
    benchmark:
        "results/benchmarks/tracks3d/prepared/{dataset}/{scene}/tracks3d_{level}.tsv",
    threads: 1
    resources:
        mem_mb=job_mem_mb(1000),
        runtime=job_runtime(20),
    conda:
        ENVS["data"]
    script:
        "../scripts/tracks3d.py"


rule medianflow:
    input:
        clips="results/raw/clips/{split}",
    output:
        "results/prepared/clips/{split}/medianflow.npz",
    log:
        "results/logs/prepared/clips/{split}/medianflow.log",
        run="results/runs/prepared/clips/{split}/medianflow.json",
    benchmark:
        "results/benchmarks/medianflow/prepared/clips/{split}/medianflow.tsv",
    priority: VELOCITY_CHAIN_PRIORITY
    threads: 1
    resources:
        mem_mb=job_mem_mb(2000),
        runtime=job_runtime(60),
    conda:
        ENVS["data"]
    script:
        "../scripts/medianflow.py"
