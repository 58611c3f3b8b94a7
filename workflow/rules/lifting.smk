# Lifting 2D masks to 3D boxes with outlier-aware loss and yaw bins (McCraith ch. 6).
#
# lifting_run     results/lifting/{metrics,info}/{run}.json + models/{run}.pt   one configuration (a child run):
#                 train on the train + long scenes, lift and evaluate the test scenes
# lifting_labels  results/lifting/labels/{run}.npz   a run's boxes on the training detections (Table IV (iii))
# lifting_table   results/tables/mccraith_ch6_table{1..4}.{md,csv,tex,score.json}
# The configurations (`lifting.runs`) and the rows of each table (`lifting.tables`) are data; the inputs are
# computed by redsup.lifting.plan.
import redsup.lifting.plan as lift_plan


LIFT = config["lifting"]
LIFT_RUNS = list(LIFT["runs"])
LIFT_TABLES = list(LIFT["tables"])


rule lifting_run:
    input:
        unpack(lambda wc: lift_plan.run_inputs(LIFT, scenes_of(LIFT["dataset"]), wc.run)),
    output:
        metrics="results/lifting/metrics/{run}.json",
        info="results/lifting/info/{run}.json",
        model="results/lifting/models/{run}.pt",
    log:
        "results/logs/lifting_run/{run}.log",
        run="results/runs/lifting_run/{run}.json",
    wildcard_constraints:
        run="|".join(LIFT_RUNS),
    threads: LIFT["threads"]
    resources:
        mem_mb=3000,
        runtime=60,
    conda:
        ENV
    script:
        "../scripts/lifting_run.py"


rule lifting_labels:
    input:
        unpack(lambda wc: lift_plan.labels_inputs(LIFT, scenes_of(LIFT["dataset"]), wc.run)),
    output:
        "results/lifting/labels/{run}.npz",
    log:
        "results/logs/lifting_labels/{run}.log",
        run="results/runs/lifting_labels/{run}.json",
    wildcard_constraints:
        run="|".join(LIFT_RUNS),
    threads: LIFT["threads"]
    resources:
        mem_mb=2000,
        runtime=20,
    conda:
        ENV
    script:
        "../scripts/lifting_labels.py"


rule lifting_table:
    input:
        unpack(lambda wc: lift_plan.table_inputs(LIFT, wc.table)),
    output:
        md="results/tables/{table}.md",
        csv="results/tables/{table}.csv",
        tex="results/tables/{table}.tex",
        score="results/tables/{table}.score.json",
    log:
        "results/logs/tables/{table}.log",
        run="results/runs/tables/{table}.json",
    wildcard_constraints:
        table="|".join(LIFT_TABLES),
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/lifting_table.py"
