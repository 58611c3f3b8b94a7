# Where the time goes: every rule's benchmark: file (results/benchmarks/<rule>/...), summed per rule and per
# stage (the rule file that defines the rule), and the DAG's critical path and the wall time projected on more
# cores, from Snakemake's record of each job's inputs (.snakemake/metadata). Included after every other rule file,
# so RULE_STAGES sees all.
from pathlib import Path as _Path

RULE_STAGES = {r.name: _Path(r.snakefile).stem for r in workflow.rules}
RUN_TIME_TARGETS = ["results/tables/run_time.md", "results/figures/run_time.png"]


rule benchmark_summary:
    input:
        TABLE_TARGETS,
        FIGURE_TARGETS,
        "results/tables/scorecard.md",
        "results/tables/power.md",  # every other job of `all`, so that none finishes after its count
    output:
        md=report_fixed("results/tables/run_time.md", RUN_TIME_CAPTION, "run_time", "md"),
        png=report_fixed("results/figures/run_time.png", RUN_TIME_CAPTION, "run_time", "png"),
    log:
        "results/logs/tables/run_time.log",
    benchmark:
        "results/benchmarks/benchmark_summary/tables/run_time.tsv",
    params:
        root="results/benchmarks",
        logs="results/logs",
        metadata=".snakemake/metadata",
        rule_stages=RULE_STAGES,
    threads: 1
    resources:
        mem_mb=job_mem_mb(1000),
        runtime=job_runtime(5),
    conda:
        ENVS["tables"]
    script:
        "../scripts/benchmark_summary.py"
