# MLflow: one job creates the store, the experiments (one per stage) and the parent runs before any
# child job starts (parallel jobs on a fresh sqlite store race during schema creation).


rule mlflow_init:
    output:
        REGISTRY,
    log:
        "results/logs/mlflow_init.log",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/mlflow_init.py"
