# Camera images cropped and resized with adjusted intrinsics, and sparse LiDAR depth maps per camera.


rule prepare_camera:
    input:
        scene="results/raw/{dataset}/{scene}",
    output:
        "results/prepared/{dataset}/{scene}/{camera}.npz",
    log:
        "results/logs/prepared/{dataset}/{scene}/{camera}.log",
        run="results/runs/prepared/{dataset}/{scene}/{camera}.json",
    benchmark:
        "results/benchmarks/prepare_camera/prepared/{dataset}/{scene}/{camera}.tsv",
    threads: 1
    resources:
        mem_mb=job_mem_mb(2000),
        runtime=job_runtime(30),
    conda:
        ENVS["data"]
    script:
        "../scripts/prepare_camera.py"


rule lidar_depth:
    input:
        scene="results/raw/{dataset}/{scene}",
    output:
        "results/prepared/{dataset}/{scene}/{camera}_depth.npz",
    log:
        "results/logs/prepared/{dataset}/{scene}/{camera}_depth.log",
        run="results/runs/prepared/{dataset}/{scene}/{camera}_depth.json",
    benchmark:
        "results/benchmarks/lidar_depth/prepared/{dataset}/{scene}/{camera}_depth.tsv",
    threads: 1
    resources:
        mem_mb=job_mem_mb(2000),
        runtime=job_runtime(30),
    conda:
        ENVS["data"]
    script:
        "../scripts/lidar_depth.py"
