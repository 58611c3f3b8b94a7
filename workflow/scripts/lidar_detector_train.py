"""Snakemake entry point: train one configuration of the ch. 7 detector with one seed and evaluate it on the
test split."""
import sys

sys.stderr = sys.stdout = open(snakemake.log[0], "w", buffering=1)  # noqa: F821  (log first)

# torch / BLAS threads from the configuration, not the executor, and deterministic kernels, before numpy
# and torch load: same seed -> same bits under any --cores or cluster (redsup.determinism)
from redsup.determinism import configure as deterministic_torch  # noqa: E402
deterministic_torch(snakemake.config["jobs"]["compute_threads"])  # noqa: F821

import json  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402

from redsup import checkpoint  # noqa: E402
from redsup.det3d.template import load_template, spec_from_config  # noqa: E402
from redsup.fileio import save_npz_atomic, write_text_atomic  # noqa: E402
from redsup.lidar_detector.augment import AugmentSpec  # noqa: E402
from redsup.lidar_detector.data import load_split  # noqa: E402
from redsup.lidar_detector.evaluate import evaluate_split, sampling_noise  # noqa: E402
from redsup.lidar_detector.figures import bev_image  # noqa: E402
from redsup.lidar_detector import plan  # noqa: E402
from redsup.lidar_detector.grid import GridSpec  # noqa: E402
from redsup.lidar_detector.postprocess import InferSpec  # noqa: E402
from redsup.lidar_detector.train import RunSpec, TrainSpec, train  # noqa: E402
from redsup.runlog import child_run  # noqa: E402
from redsup.mlflow_model import log_model  # noqa: E402

sm = snakemake  # noqa: F821
cfg = sm.config["lidar_detector"]
conf, seed_index = sm.wildcards.conf, int(sm.wildcards.seed)
name = plan.run_id(conf, seed_index)
seed = plan.training_seed(sm.config, seed_index)
tables = plan.tables_of(sm.config, name) or list(cfg["tables"])[:1]    # every table whose rows read this run
device = cfg["device"] if cfg["device"] != "auto" else ("cuda" if torch.cuda.is_available() else "cpu")
run_spec = RunSpec.from_config(cfg["runs"][conf])
grid = GridSpec.from_config(cfg["grid"])
train_spec = TrainSpec.from_config(cfg["train"] | {"min_points": cfg["min_points"], "max_points": cfg["max_points"]})
with child_run(sm.log.run, tables[0], name, rule=sm.rule, wildcards=dict(sm.wildcards), config=sm.config,
               params={"run": cfg["runs"][conf], "tables": tables, "seed": seed, "grid": cfg["grid"],
                       "train": cfg["train"], "augment": cfg["augment"], "network": cfg["network"],
                       "yaw_bins": cfg["yaw_bins"], "device": device}) as run:
    train_data, test_data = load_split(sm.input.train), load_split(sm.input.test)
    print(f"{name}: {run_spec}; {train_data.n_frames} training frames, {test_data.n_frames} test frames; "
          f"data counts train {train_data.counts} test {test_data.counts}")
    template = load_template(sm.input.template, spec_from_config(cfg))

    def log(metrics, step):
        run.log_metrics(metrics, step=step)
        print(f"step {step}: " + ", ".join(f"{k[6:]} {v:.4g}" for k, v in metrics.items()))

    model, summary = train(train_data, run_spec, grid, train_spec, AugmentSpec.from_config(cfg["augment"]), template,
                           n_bins=int(cfg["yaw_bins"]), net=cfg["network"], seed=seed,
                           device=device, log=log)
    metrics, dets = evaluate_split(model, test_data, grid, InferSpec.from_config(cfg["infer"]), template.size,
                                   device=device, iou_thresholds=tuple(cfg["eval"]["iou"]))
    metrics |= summary
    metrics |= {f"data_train_{k}": float(v) for k, v in train_data.counts.items()}
    run.log_metrics({k: v for k, v in metrics.items() if np.isfinite(v)})
    print(json.dumps(metrics, indent=1))

    checkpoint.save(sm.output.model, "lidar_detector", {"net": model}, sm.config,
                    {"configuration": conf, "seed": seed, "run": cfg["runs"][conf], "grid": cfg["grid"],
                     "network": cfg["network"], "yaw_bins": cfg["yaw_bins"], "summary": summary})
    log_model(run, model, sm.output.model, name=f"lidar_detector-{name}")
    counts = [len(d.score) for d in dets]
    save_npz_atomic(sm.output.detections, frame=np.repeat(np.arange(len(dets)), counts),
                    boxes=np.concatenate([d.boxes for d in dets]) if dets else np.zeros((0, 7)),
                    bbox=np.concatenate([d.bbox for d in dets]) if dets else np.zeros((0, 4)),
                    score=np.concatenate([d.score for d in dets]) if dets else np.zeros(0))
    best = int(np.argmax([len(test_data.gt_boxes(f)) for f in range(test_data.n_frames)]))
    run.log_image(bev_image(test_data.points(best), test_data.supervised_boxes(best, 1), dets[best].boxes,
                            dets[best].score, grid, f"{name}: test frame {best} (green: gt seen by the camera, "
                            "red: detections)"), "bev_test_frame.png")
    # the table cells' test-sampling noise: AP_BEV at IoU 0.7 on bootstrap resamples of the test frames
    boot = sampling_noise(test_data, dets, int(cfg["eval"].get("bootstrap", 0)), iou=float(cfg["eval"]["iou"][0]))
    write_text_atomic(sm.output.metrics, json.dumps(metrics | ({"bootstrap": boot} if boot else {}), indent=1,
                                                    sort_keys=True) + "\n")
