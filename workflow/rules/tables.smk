# Every table through one rule (the table contract, redsup.tables.contract): its rows come from the stage's
# plan, its inputs are the result files of their runs, one script writes it beside the thesis' numbers.
# Included last. TABLE_IDS / FIGURE_IDS come from tables.yaml alone (common.smk); the figures of rule all
# are those and Galteland's progression / qualitative figures (depth.figures, GALTELAND_FIGURES of depth.smk).
TABLE_TARGETS = expand("results/tables/{table}.{ext}", table=TABLE_IDS, ext=("md", "csv", "tex"))
FIGURE_TARGETS = expand(
    "results/figures/{figure}.png", figure=FIGURE_IDS + [f for f in GALTELAND_FIGURES if f not in FIGURE_IDS]
)


rule table:
    input:
        get_table_inputs,
    output:
        md=report_table("results/tables/{table}.md", "md"),
        csv=report_table("results/tables/{table}.csv", "csv"),
        tex="results/tables/{table}.tex",
        score="results/tables/{table}.score.json",
    log:
        "results/logs/tables/{table}.log",
        run="results/runs/tables/{table}.json",
    benchmark:
        "results/benchmarks/table/tables/{table}.tsv",
    params:
        rows=lambda wildcards: [list(r) for r in TABLE_ROWS.get(wildcards.table, [])],
    wildcard_constraints:
        table="|".join(TABLE_IDS),
    threads: 1
    resources:
        mem_mb=job_mem_mb(1000),
        runtime=job_runtime(10),
    conda:
        ENVS["tables"]
    script:
        "../scripts/table.py"

rule data_summary:
    input:
        prepared=PREPARED_TARGETS,
    output:
        "results/data/summary.json",
    log:
        "results/logs/data/summary.log",
        run="results/runs/data/summary.json",
    benchmark:
        "results/benchmarks/data_summary/data/summary.tsv",
    threads: 1
    resources:
        mem_mb=job_mem_mb(2000),
        runtime=job_runtime(10),
    conda:
        ENVS["tables"]
    script:
        "../scripts/data_summary.py"


rule world_frame_overview:
    input:
        scene=f"results/raw/{OVERVIEW_SCENE}",
        detections=f"results/prepared/{OVERVIEW_SCENE}/detections_cityscapes.npz",
    output:
        report_fixed("results/figures/world_frame_overview.png", OVERVIEW_CAPTION, "world_frame_overview", "png"),
    log:
        "results/logs/figures/world_frame_overview.log",
        run="results/runs/figures/world_frame_overview.json",
    benchmark:
        "results/benchmarks/world_frame_overview/figures/world_frame_overview.tsv",
    threads: 1
    resources:
        mem_mb=job_mem_mb(2000),
        runtime=job_runtime(10),
    conda:
        ENVS["tables"]
    script:
        "../scripts/frame_overview.py"


rule scorecard:
    input:
        expand("results/tables/{table}.score.json", table=TABLE_IDS),
    output:
        report_fixed("results/tables/scorecard.md", SCORECARD_CAPTION, "scorecard", "md"),
    log:
        "results/logs/tables/scorecard.log",
    benchmark:
        "results/benchmarks/scorecard/tables/scorecard.tsv",
    threads: 1
    resources:
        mem_mb=job_mem_mb(500),
        runtime=job_runtime(5),
    conda:
        ENVS["tables"]
    script:
        "../scripts/scorecard.py"


rule power:
    input:
        expand("results/tables/{table}.score.json", table=TABLE_IDS),
    output:
        md="results/tables/power.md",
        csv="results/tables/power.csv",
    log:
        "results/logs/tables/power.log",
    benchmark:
        "results/benchmarks/power/tables/power.tsv",
    threads: 1
    resources:
        mem_mb=job_mem_mb(500),
        runtime=job_runtime(5),
    conda:
        ENVS["tables"]
    script:
        "../scripts/power.py"
