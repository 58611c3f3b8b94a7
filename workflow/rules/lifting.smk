# Lifting 2D masks to 3D boxes with outlier-aware loss and yaw bins (McCraith ch. 6).
#
# lifting_run     results/lifting/{metrics,info}/{conf}/seed{seed}.json + models/{conf}/seed{seed}.pt: one
#                 configuration trained with one seed index (a child run): train on the train + long scenes,
#                 lift and evaluate the test scenes
# lifting_labels  results/lifting/labels/{conf}/seed{seed}.npz   a run's boxes on the training detections (Table IV (iii))
# template_field  results/det3d/template/{stage}.npz   the template car's distance field of a stage (lifting, and
#                 lidar_detector for ch. 7), built once instead of in every training job
# The ch. 6 tables (tables.yaml, stage lifting) are built by rule table (tables.smk) from redsup.lifting.plan: the
# configurations (`lifting.runs`), seeds (`lifting.seeds`) and rows (`lifting.tables.<id>.rows`) are data.
import redsup.lifting.plan as lift_plan


LIFT = config["lifting"]
LIFT_CONFS = list(LIFT["runs"])
LIFT_SEEDS = [str(int(k)) for k in LIFT["seeds"]]


rule template_field:
    output:
        "results/det3d/template/{stage}.npz",
    log:
        "results/logs/det3d/template/{stage}.log",
    benchmark:
        "results/benchmarks/template_field/det3d/template/{stage}.tsv",
    wildcard_constraints:
        stage="lifting|lidar_detector",
    threads: 1
    resources:
        mem_mb=job_mem_mb(2000),
        runtime=job_runtime(10),
    conda:
        ENVS["lifting"]
    script:
        "../scripts/template_field.py"


rule lifting_run:
    input:
        unpack(lambda wc: lift_plan.run_inputs(LIFT, scenes_of(LIFT["dataset"]), wc.conf, int(wc.seed))),
        template="results/det3d/template/lifting.npz",
    output:
        metrics="results/lifting/metrics/{conf}/seed{seed}.json",
        info="results/lifting/info/{conf}/seed{seed}.json",
        model="results/lifting/models/{conf}/seed{seed}.pt",
    log:
        "results/logs/lifting/metrics/{conf}/seed{seed}.log",
        run="results/runs/lifting/metrics/{conf}/seed{seed}.json",
    benchmark:
        "results/benchmarks/lifting_run/lifting/metrics/{conf}/seed{seed}.tsv",
    wildcard_constraints:
        conf="|".join(LIFT_CONFS),
        seed="|".join(LIFT_SEEDS),
    threads: COMPUTE_THREADS
    resources:
        mem_mb=job_mem_mb(3000),
        runtime=job_runtime(60),
    conda:
        ENVS["lifting"]
    script:
        "../scripts/lifting_run.py"


rule lifting_labels:
    input:
        unpack(lambda wc: lift_plan.labels_inputs(LIFT, scenes_of(LIFT["dataset"]), wc.conf, int(wc.seed))),
        template="results/det3d/template/lifting.npz",
    output:
        "results/lifting/labels/{conf}/seed{seed}.npz",
    log:
        "results/logs/lifting/labels/{conf}/seed{seed}.log",
        run="results/runs/lifting/labels/{conf}/seed{seed}.json",
    benchmark:
        "results/benchmarks/lifting_labels/lifting/labels/{conf}/seed{seed}.tsv",
    wildcard_constraints:
        conf="|".join(LIFT_CONFS),
        seed="|".join(LIFT_SEEDS),
    threads: COMPUTE_THREADS
    resources:
        mem_mb=job_mem_mb(2000),
        runtime=job_runtime(20),
    conda:
        ENVS["lifting"]
    script:
        "../scripts/lifting_labels.py"
