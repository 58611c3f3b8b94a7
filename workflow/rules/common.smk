# Configuration resolution and the lists of targets, derived from config as data.
import redsup.config

_resolved = redsup.config.resolve(config)
config.clear()
config.update(_resolved)

ENV = "../../envs/redsup.yaml"
SPLITS = ("train", "test", "long")
CLIP_SPLIT_NAMES = list(config["velocity_clips"]["splits"])
DET_LEVELS = ("coco", "cityscapes")


wildcard_constraints:
    dataset=r"[A-Za-z0-9_]+",
    scene=r"(train|test|long)_\d{3}",
    camera=r"cam_front|cam_front_right|cam_back",
    level=r"coco|cityscapes",
    split="|".join(CLIP_SPLIT_NAMES),


def scenes_of(dataset):
    """Scene ids of one dataset (kind=world: <split>_<index>)."""
    counts = config["datasets"][dataset].get("scenes", {})
    return [f"{split}_{i:03d}" for split in SPLITS for i in range(counts.get(split, 0))]


def cameras_of(dataset):
    """Cameras prepared for a dataset: the configured ones its domain renders."""
    spec = config["datasets"][dataset]
    rendered = config["world"]["domains"][spec["domain"]]["cameras"]
    return [c for c in config["prepare"]["cameras"] if c in rendered]


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
# Each stage's .smk appends the ids of the tables and figures it builds; tables.smk (included last)
# turns them into targets and the scorecard.
TABLE_IDS = ["data_summary", "mccraith_ch3_table1"]
FIGURE_IDS = ["world_frame_overview"]
# the scene shown in the overview figure: the first test scene of the first dataset that has one
OVERVIEW_SCENE = next((f"{d}/{s}" for d, s in ALL_SCENES if s.startswith("test")), None)



def sync_mlflow():
    """Import the run records of this invocation (and any earlier ones) into the MLflow store."""
    import redsup.tracking

    try:
        out = redsup.tracking.sync_from_config(config)
        print(f"MLflow: {out['imported']} new runs from {out['records']} records -> {out['tracking_uri']}")
    except Exception as exc:  # tracking must never cost the user their results
        print(f"MLflow sync failed ({type(exc).__name__}: {exc}); rerun `python -m redsup.tracking`")
