# Tables and figures that the data stage itself produces, and the scorecard gathering every table.
# Included last: by now every stage has appended its ids to TABLE_IDS / FIGURE_IDS.
TABLE_TARGETS = expand("results/tables/{table}.{ext}", table=TABLE_IDS, ext=("md", "csv", "tex"))
FIGURE_TARGETS = expand("results/figures/{figure}.png", figure=FIGURE_IDS)


rule data_summary:
    input:
        prepared=PREPARED_TARGETS,
    output:
        md="results/tables/data_summary.md",
        csv="results/tables/data_summary.csv",
        tex="results/tables/data_summary.tex",
        score="results/tables/data_summary.score.json",
    log:
        "results/logs/tables/data_summary.log",
        run="results/runs/tables/data_summary.json",
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/data_summary.py"


rule mccraith_ch3_table1:
    input:
        clips=expand("results/raw/clips/{split}", split=("train", "test")),
    output:
        md="results/tables/mccraith_ch3_table1.md",
        csv="results/tables/mccraith_ch3_table1.csv",
        tex="results/tables/mccraith_ch3_table1.tex",
        score="results/tables/mccraith_ch3_table1.score.json",
    log:
        "results/logs/tables/mccraith_ch3_table1.log",
        run="results/runs/tables/mccraith_ch3_table1.json",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/ch3_table1.py"


rule world_frame_overview:
    input:
        scene=f"results/raw/{OVERVIEW_SCENE}",
        detections=f"results/prepared/{OVERVIEW_SCENE}/detections_cityscapes.npz",
    output:
        "results/figures/world_frame_overview.png",
    log:
        "results/logs/figures/world_frame_overview.log",
        run="results/runs/figures/world_frame_overview.json",
    threads: 1
    resources:
        mem_mb=2000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/frame_overview.py"


rule scorecard:
    input:
        expand("results/tables/{table}.score.json", table=TABLE_IDS),
    output:
        "results/tables/scorecard.md",
    log:
        "results/logs/tables/scorecard.log",
    threads: 1
    resources:
        mem_mb=500,
        runtime=5,
    conda:
        ENV
    script:
        "../scripts/scorecard.py"
