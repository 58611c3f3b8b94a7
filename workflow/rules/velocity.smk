# Velocity from tracked boxes and synthetic box tracks (McCraith ch. 3).

# the configurations (config velocity.configurations) as data: one job and one child run each
VELOCITY_CONFIGS = {c["name"]: c for c in config["velocity"]["configurations"]}
VELOCITY_BASELINES = [n for n, c in VELOCITY_CONFIGS.items() if c["method"] in ("geometric", "constant")]
VELOCITY_MLP = [n for n, c in VELOCITY_CONFIGS.items() if c["method"] == "mlp"]
VELOCITY_EVAL_SPLITS = [s for s in ("test", "abnormal") if s in CLIP_SPLIT_NAMES]


# metrics of the configurations whose parent run is Table II, and of all of them (the ablation table)
VELOCITY_TABLE2_METRICS = expand(
    "results/velocity/{config}/metrics.json",
    config=[n for n, c in VELOCITY_CONFIGS.items() if c["table"] == "mccraith_ch3_table2"],
)
VELOCITY_ALL_METRICS = expand("results/velocity/{config}/metrics.json", config=list(VELOCITY_CONFIGS))


rule velocity_fit_generator:
    input:
        tracks="results/prepared/clips/train/medianflow.npz",
        clips="results/raw/clips/train",
    output:
        "results/velocity/generator_statistics.json",
    log:
        "results/logs/velocity/fit_generator.log",
        run="results/runs/velocity/fit_generator.json",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/velocity_fit.py"


rule velocity_baseline:
    input:
        tracks=expand("results/prepared/clips/{split}/medianflow.npz", split=VELOCITY_EVAL_SPLITS),
        clips=expand("results/raw/clips/{split}", split=VELOCITY_EVAL_SPLITS),
        train_tracks="results/prepared/clips/train/medianflow.npz",
        train_clips="results/raw/clips/train",
    output:
        metrics="results/velocity/{config}/metrics.json",
        predictions="results/velocity/{config}/predictions.npz",
    log:
        "results/logs/velocity/{config}.log",
        run="results/runs/velocity/{config}.json",
    wildcard_constraints:
        config="|".join(VELOCITY_BASELINES),
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/velocity_baseline.py"


rule velocity_mlp:
    input:
        tracks=expand("results/prepared/clips/{split}/medianflow.npz", split=VELOCITY_EVAL_SPLITS),
        clips=expand("results/raw/clips/{split}", split=VELOCITY_EVAL_SPLITS),
        train_tracks="results/prepared/clips/train/medianflow.npz",
        train_clips="results/raw/clips/train",
        # the fitted generator, for configurations trained on synthetic tracks
        generator=lambda wc: (
            ["results/velocity/generator_statistics.json"]
            if VELOCITY_CONFIGS[wc.config].get("train_on") == "synthetic"
            else []
        ),
    output:
        metrics="results/velocity/{config}/metrics.json",
        predictions="results/velocity/{config}/predictions.npz",
        model="results/velocity/{config}/model.pt",
    log:
        "results/logs/velocity/{config}.log",
        run="results/runs/velocity/{config}.json",
    wildcard_constraints:
        config="|".join(VELOCITY_MLP),
    threads: 1
    resources:
        mem_mb=2000,
        runtime=60,
    conda:
        ENV
    script:
        "../scripts/velocity_mlp.py"


rule mccraith_ch3_table2:
    input:
        metrics=VELOCITY_TABLE2_METRICS,
    output:
        md="results/tables/mccraith_ch3_table2.md",
        csv="results/tables/mccraith_ch3_table2.csv",
        tex="results/tables/mccraith_ch3_table2.tex",
        score="results/tables/mccraith_ch3_table2.score.json",
    log:
        "results/logs/tables/mccraith_ch3_table2.log",
        run="results/runs/tables/mccraith_ch3_table2.json",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/velocity_table.py"


rule mccraith_ch3_synthetic_ablation:
    input:
        metrics=VELOCITY_ALL_METRICS,
    output:
        md="results/tables/mccraith_ch3_synthetic_ablation.md",
        csv="results/tables/mccraith_ch3_synthetic_ablation.csv",
        tex="results/tables/mccraith_ch3_synthetic_ablation.tex",
        score="results/tables/mccraith_ch3_synthetic_ablation.score.json",
    log:
        "results/logs/tables/mccraith_ch3_synthetic_ablation.log",
        run="results/runs/tables/mccraith_ch3_synthetic_ablation.json",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/velocity_table.py"


rule mccraith_ch3_fig3:
    input:
        tracks="results/prepared/clips/train/medianflow.npz",
        clips="results/raw/clips/train",
        generator="results/velocity/generator_statistics.json",
    output:
        png="results/figures/mccraith_ch3_fig3.png",
        md="results/tables/mccraith_ch3_fig3.md",
        csv="results/tables/mccraith_ch3_fig3.csv",
        tex="results/tables/mccraith_ch3_fig3.tex",
        score="results/tables/mccraith_ch3_fig3.score.json",
    log:
        "results/logs/figures/mccraith_ch3_fig3.log",
        run="results/runs/figures/mccraith_ch3_fig3.json",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/velocity_fig3.py"


rule mccraith_ch3_fig6:
    input:
        tracks="results/prepared/clips/train/medianflow.npz",
        clips="results/raw/clips/train",
        generator="results/velocity/generator_statistics.json",
    output:
        png="results/figures/mccraith_ch3_fig6.png",
        md="results/tables/mccraith_ch3_fig6.md",
        csv="results/tables/mccraith_ch3_fig6.csv",
        tex="results/tables/mccraith_ch3_fig6.tex",
        score="results/tables/mccraith_ch3_fig6.score.json",
    log:
        "results/logs/figures/mccraith_ch3_fig6.log",
        run="results/runs/figures/mccraith_ch3_fig6.json",
    threads: 1
    resources:
        mem_mb=1000,
        runtime=10,
    conda:
        ENV
    script:
        "../scripts/velocity_fig6.py"
