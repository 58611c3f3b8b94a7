# Configuration resolution and the lists of targets, derived from config as data.
import re

import redsup.adapters
import redsup.config
import redsup.jobs
import redsup.tables.contract as table_contract

_resolved = redsup.config.resolve(config)
# the schemas check each table section's shape; its key must be a tables.yaml id of the section's stages
table_contract.check_config_tables(_resolved)
config.clear()
config.update(_resolved)

# What a job asks for (config jobs, redsup.jobs): a rule's job_mem_mb(3000) / job_runtime(60) are its values at the
# default profile, scaled to the size profile; the rules that run a network take COMPUTE_THREADS threads, the same
# number their torch / BLAS pools get whatever the executor grants (redsup.determinism)
COMPUTE_THREADS = config["jobs"]["compute_threads"]
job_mem_mb = redsup.jobs.resource(config["jobs"], "mem_mb")
job_runtime = redsup.jobs.resource(config["jobs"], "runtime")
# Among ready jobs the greedy scheduler starts those with the largest input files first, so the clip shards (no
# input) waited to the end of a 2-core build and the velocity chain after them (merge, MedianFlow, generator fit,
# MLPs) ran last, beside nothing (docs/performance.md#job-order). Its rules start first whenever they are ready.
VELOCITY_CHAIN_PRIORITY = 1

# conda env of each stage's rules (envs/<stage>.yaml, pinned; used with --sdm conda, e.g. the SLURM profile)
ENVS = {stage: f"../../envs/{stage}.yaml" for stage in ("data", "velocity", "depth", "calibration", "lifting",
                                                          "detector", "tables")}
SPLITS = ("train", "val", "test", "long")
CLIP_SPLIT_NAMES = list(config["velocity_clips"]["splits"])
DET_LEVELS = ("coco", "cityscapes")


# which rule writes results/raw/{dataset}/{scene} (world_scene or adapt_scene) and results/raw/clips/{split}
# (world_clips or adapt_clips): each rule's wildcard is restricted to the names of its kind


def _names_regex(names):
    return "|".join(re.escape(n) for n in names) or "(?!)"


WORLD_DATASETS = [d for d, spec in config["datasets"].items() if spec["kind"] == "world"]
ADAPTER_DATASETS = [d for d, spec in config["datasets"].items() if spec["kind"] != "world"]
CLIP_SOURCE = config["velocity_clips"].get("source")
SOURCE_CLIP_SPLITS = [s for s in CLIP_SPLIT_NAMES if CLIP_SOURCE and s in CLIP_SOURCE["splits"]]
WORLD_CLIP_SPLITS = [s for s in CLIP_SPLIT_NAMES if s not in SOURCE_CLIP_SPLITS]
_unknown_clip_splits = sorted(set(CLIP_SOURCE["splits"]) - set(CLIP_SPLIT_NAMES)) if CLIP_SOURCE else []
if _unknown_clip_splits:
    raise redsup.config.ConfigError(
        f"config.yaml: velocity_clips.source.splits names {_unknown_clip_splits}, which are not clip splits "
        f"(velocity_clips.splits: {CLIP_SPLIT_NAMES})")


wildcard_constraints:
    dataset=r"[A-Za-z0-9_]+",
    scene=r"(train|val|test|long)_[A-Za-z0-9_]+",
    camera=r"cam_front|cam_front_right|cam_back",
    level=r"coco|cityscapes",
    split="|".join(CLIP_SPLIT_NAMES),


def scenes_of(dataset):
    """Scene ids of one dataset (kind=world: <split>_<index>; real datasets: <split>_<source name>, listed
    from the dataset's folder and split files when the workflow is parsed)."""
    spec = config["datasets"][dataset]
    if spec["kind"] != "world":
        return redsup.adapters.scene_ids(dataset, spec)
    counts = spec.get("scenes", {})
    return [f"{split}_{i:03d}" for split in SPLITS for i in range(counts.get(split, 0))]


def cameras_of(dataset):
    """Cameras prepared for a dataset: the configured ones its domain renders (or the real dataset has)."""
    spec = config["datasets"][dataset]
    if spec["kind"] != "world":
        present = redsup.adapters.cameras(spec)
    else:
        present = config["world"]["domains"][spec["domain"]]["cameras"]
    return [c for c in config["prepare"]["cameras"] if c in present]


ALL_SCENES = [(d, s) for d in config["datasets"] for s in scenes_of(d)]
RAW_SCENES = [f"results/raw/{d}/{s}" for d, s in ALL_SCENES]
CLIP_SPLITS = expand("results/raw/clips/{split}", split=CLIP_SPLIT_NAMES)
PREPARED_TARGETS = (
    [
        f"results/prepared/{d}/{s}/{c}{suffix}"
        for d, s in ALL_SCENES
        for c in cameras_of(d)
        for suffix in (".npz", "_depth.npz")
    ]
    + [
        f"results/prepared/{d}/{s}/{kind}_{level}.{ext}"
        for d, s in ALL_SCENES
        for level in DET_LEVELS
        for kind, ext in (("detections", "npz"), ("tracks3d", "csv"))
    ]
    + [f"results/prepared/{d}/{s}/road.npz" for d, s in ALL_SCENES]
    + expand("results/prepared/clips/{split}/medianflow.npz", split=CLIP_SPLIT_NAMES)
)
# Every table and figure id comes from tables.yaml (workflow/redsup/data); a figure also has its table.
TABLE_IDS = table_contract.table_ids()
FIGURE_IDS = table_contract.table_ids("figure") + ["world_frame_overview"]
# table id -> [(row label, run, step)] from every stage's plan (redsup.tables.contract); rule table's inputs
TABLE_ROWS = table_contract.all_rows(config, scenes_of)


def get_table_inputs(wildcards):
    """The result file of every run the table's rows read, each once."""
    plan = table_contract.plan_of(wildcards.table)
    return list(dict.fromkeys(plan.result_path(run) for _, run, _ in TABLE_ROWS.get(wildcards.table, [])))


# the scene shown in the overview figure: the first test scene of the first dataset that has one
OVERVIEW_SCENE = next((f"{d}/{s}" for d, s in ALL_SCENES if s.startswith("test")), None)



def sync_mlflow():
    """Import the run records of this invocation (and any earlier ones) into the MLflow store."""
    import redsup.tracking

    try:
        out = redsup.tracking.sync_from_config(config, final=True)  # no job of this invocation runs any more
        print(f"MLflow: {out['imported']} new runs from {out['records']} records -> {out['tracking_uri']}")
    except Exception as exc:  # tracking must never cost the user their results
        print(f"MLflow sync failed ({type(exc).__name__}: {exc}); rerun `python -m redsup.tracking`")
