"""Diagnose the instability of the monocular (M) Monodepth2 model trained from scratch, and compare recipes on
the validation split (issue: "find out why M is unstable from scratch before adding steps").

Trains one ``<dataset>/M`` model from the prepared data of a finished build exactly as
``workflow/scripts/depth_train.py`` does (same data, seeds, networks, ``training.train``, loss settings), with
some recipe knobs overridden from the command line, and records

- per step: the loss terms (loss, photometric, smoothness, automask_fraction), the effective learning rate, and
  the pose network's translation magnitude / rotation angle next to the true camera ego-motion between the same
  frames (ego poses + extrinsics of the raw scenes; *measurement only*, nothing of it reaches the model);
- every ``--val-every`` steps: the project's validation metrics (``experiments.validation_metrics``, median
  scaling, the ``depth.eval.frames.val`` frames; also on every val frame), the median-scale factor of the
  depth, and the pose on consecutive val frames: ratio of |t_pred| x depth scale factor to |t_true| (1 = pose
  and depth agree on scale), correlation of |t_pred| with |t_true|, direction cosine, rotation angles.

Usage (one training at a time; 1 thread):
  nice -n 5 python studies/diag_depth_m.py --results /work/def/results --tag base --seed-index 0
  nice -n 5 python studies/diag_depth_m.py --results /work/def/results --tag lr5e-4_wu50 --lr 5e-4 \
      --warmup 50 --seed-index 1
  python studies/diag_depth_m.py --summarize          # table over results/studies/diag_depth_m/*.json: recipe x seed
  python studies/diag_depth_m.py --oracle --results /work/def/results   # loss of the true geometry
Outputs (--out, default results/studies/diag_depth_m): <tag>_seed<k>.json (everything), <tag>_seed<k>_steps.csv
(per step), <tag>_seed<k>_val.csv (per validation pass); --oracle: oracle.json.
"""
from __future__ import annotations

import argparse
import csv
import glob
import json
import math
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "workflow"))

from redsup import config as rconfig  # noqa: E402
from redsup.studies import STUDIES_ROOT, write_study  # noqa: E402


def parse_args(argv=None):
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--config", default=str(ROOT / "config.yaml"), help="config.yaml (resolved with its profile)")
    p.add_argument("--profile", default="default", help="size profile to resolve (default: default)")
    p.add_argument("--results", default="/work/def/results", help="results/ of a build with the prepared data")
    p.add_argument("--dataset", default="world_kitti")
    p.add_argument("--mode", default="M")
    p.add_argument("--seed-index", type=int, default=0, help="the project's seed index k (model <ds>/M[/seed<k>])")
    p.add_argument("--seed", type=int, default=None, help="explicit seed (overrides --seed-index)")
    p.add_argument("--tag", default="base", help="recipe name (output file prefix)")
    p.add_argument("--out", default=f"{STUDIES_ROOT}/diag_depth_m")
    # recipe knobs (default: the resolved config's value)
    p.add_argument("--steps", type=int, default=None)
    p.add_argument("--batch", type=int, default=None)
    p.add_argument("--lr", type=float, default=None)
    p.add_argument("--warmup", type=int, default=0, help="linear lr warm-up over this many steps (0 = none)")
    p.add_argument("--decay-at", type=float, nargs="+", default=None, help="fractions of the steps: lr x gamma")
    p.add_argument("--gamma", type=float, default=None)
    p.add_argument("--smoothness", type=float, default=None, help="smoothness weight")
    p.add_argument("--flip", type=int, choices=(0, 1), default=None)
    p.add_argument("--min-speed", type=float, default=None)
    p.add_argument("--width", type=int, default=None, help="base_channels of the networks")
    p.add_argument("--input-scale", type=float, default=None)
    p.add_argument("--init-disparity", type=float, default=None, help="initial sigmoid output (depth.modes.*)")
    p.add_argument("--curriculum", type=int, default=0,
                   help="resolution curriculum: first this many steps at half the input size (no lr decay; the "
                        "auto-masking warm-up --automask-from in this phase), then --steps")
    p.add_argument("--automask-from", type=int, default=None,
                   help="auto-masking off for the first N steps (every pixel in the loss), then as configured "
                        "(default: the mode's automask_after)")
    p.add_argument("--val-every", type=int, default=50)
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--dump", action="store_true",
                   help="also write <tag>_seed<k>_val_depth.npz: the final model's val predictions (median-scaled "
                        "per frame), the LiDAR depth and the images, and <tag>_seed<k>_val_depth.png")
    p.add_argument("--summarize", action="store_true", help="only print the table of the runs in --out")
    p.add_argument("--oracle", action="store_true",
                   help="only measure the training loss of the true geometry (rendered GT depth + true ego-motion) "
                        "and of a constant 8 m depth with the true motion, on the train scenes (no training)")
    return p.parse_args(argv)


def camera_poses(scene_dir: Path, camera: str) -> np.ndarray:
    """(T, 4, 4) T_world_camera of a raw scene (measurement only)."""
    from redsup import sceneio

    poses = sceneio.read_poses(scene_dir / "ego_poses.txt")
    return poses @ sceneio.read_extrinsics(scene_dir / "extrinsics.json")[camera][None]


def true_transform(Twc: np.ndarray, t: int, j: int) -> np.ndarray:
    """Target (frame t) -> source (frame j) camera transform: points of camera t into camera j."""
    from redsup.geometry import invert_pose

    return invert_pose(Twc[j]) @ Twc[t]


def rot_angle_deg(R: np.ndarray) -> np.ndarray:
    c = (np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0
    return np.degrees(np.arccos(np.clip(c, -1.0, 1.0)))


def pose_stats(pred_T: np.ndarray, true_T: np.ndarray, scale: float = 1.0) -> dict:
    """Predicted vs true target->source transforms (N, 4, 4): magnitudes, ratio, correlation, direction."""
    tp, tt = pred_T[:, :3, 3], true_T[:, :3, 3]
    np_, nt = np.linalg.norm(tp, axis=1), np.linalg.norm(tt, axis=1)
    ok = nt > 1e-3
    cos = np.sum(tp * tt, axis=1) / np.maximum(np_ * nt, 1e-12)
    out = {"t_pred": float(np.median(np_)), "t_true": float(np.median(nt)),
           "t_ratio": float(np.median(scale * np_[ok] / nt[ok])) if ok.any() else float("nan"),
           "t_cos": float(np.mean(cos[ok])) if ok.any() else float("nan"),
           "rot_pred_deg": float(np.mean(rot_angle_deg(pred_T[:, :3, :3]))),
           "rot_true_deg": float(np.mean(rot_angle_deg(true_T[:, :3, :3])))}
    out["t_corr"] = (float(np.corrcoef(np_, nt)[0, 1])
                     if len(np_) > 2 and np.std(np_) > 0 and np.std(nt) > 0 else float("nan"))
    return out


def main(argv=None) -> int:
    args = parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.summarize:
        return summarize(out)
    if args.oracle:
        return oracle(args)

    from redsup.determinism import configure
    configure(args.threads)
    import torch

    from redsup.depth import data, evaluation, experiments, pipeline, systems, training
    from redsup.depth.configs import model_seed, split_of, train_settings

    cfg = rconfig.load(args.config, {"profile": args.profile})
    dcfg = cfg["depth"]
    if args.smoothness is not None:
        dcfg["loss"]["smoothness_weight"] = float(args.smoothness)
    ds, mode = args.dataset, args.mode
    mode_cfg = dcfg["modes"][mode]
    sources = list(mode_cfg["sources"])
    model_cfg, tcfg = train_settings(dcfg, ds, mode)
    if args.width is not None:
        model_cfg["base_channels"] = args.width
    if args.input_scale is not None:
        model_cfg["input_scale"] = args.input_scale
    if args.init_disparity is not None:
        model_cfg["init_disparity"] = args.init_disparity
    for key, val in (("steps", args.steps), ("batch_size", args.batch), ("lr", args.lr), ("gamma", args.gamma),
                     ("min_speed", args.min_speed)):
        if val is not None:
            tcfg[key] = val
    if args.decay_at is not None:
        tcfg["decay_at"] = args.decay_at if len(args.decay_at) > 1 else args.decay_at[0]
    if args.flip is not None:
        tcfg["flip"] = bool(args.flip)
    model_id = f"{ds}/{mode}" + (f"/seed{args.seed_index}" if args.seed_index else "")
    seed = args.seed if args.seed is not None else model_seed(cfg["seed"], model_id)   # as depth_train
    steps = int(tcfg["steps"])
    automask_after = int(tcfg["automask_after"] if args.automask_from is None else args.automask_from)
    tcfg["automask_after"] = automask_after

    # ---- data: as depth_train.py (train scenes), plus the val scenes with their LiDAR depth
    res = Path(args.results)
    scenes = sorted(p.name for p in (res / "raw" / ds).iterdir() if p.is_dir())
    train_scenes, val_scenes = split_of(scenes, "train"), split_of(scenes, "val")
    expected = dict(cfg["datasets"][ds].get("scenes", {}))
    if len(train_scenes) != expected.get("train", len(train_scenes)) or \
            len(val_scenes) != expected.get("val", len(val_scenes)):
        raise SystemExit(f"{res}: {len(train_scenes)} train / {len(val_scenes)} val scenes, expected {expected}")
    seqs, train_Twc = [], []
    for cam in mode_cfg["cameras"]:
        for s in train_scenes:
            sd = res / "raw" / ds / s
            stereo = res / "prepared" / ds / s / "cam_front_right.npz" if cam == "cam_front" and "stereo" in sources \
                else None   # S / MS: the partner camera, as depth_train.py
            seqs.append(data.load_sequence(res / "prepared" / ds / s / f"{cam}.npz", scene_dir=sd,
                                           reversed_order=(cam == "cam_back"), camera=cam, stereo_npz=stereo,
                                           stereo_baseline=tcfg["stereo_baseline"] if stereo else None))
            train_Twc.append(camera_poses(sd, cam))
    h, w = systems.input_size(seqs[0].size, float(model_cfg.get("input_scale", 1.0)))
    seqs = [data.resize_sequence(s, (h, w)) for s in seqs]
    ecam = dcfg["eval"]["camera"]
    val, val_Twc = [], []
    for s in val_scenes:
        sd = res / "raw" / ds / s
        val.append(experiments.EvalSequence(
            data.resize_sequence(data.load_sequence(res / "prepared" / ds / s / f"{ecam}.npz", scene_dir=sd), (h, w)),
            data.read_gt_depth(res / "prepared" / ds / s / f"{ecam}_depth.npz")))
        val_Twc.append(camera_poses(sd, ecam))
    meta = {**model_cfg, "height": h, "width": w, "mode": mode, "sources": sources, "cameras": list(mode_cfg["cameras"]),
            "dataset": ds, "train": dict(tcfg), "loss": dict(dcfg["loss"]), "seed": seed}
    if "stereo" in sources:   # S / MS are validated at the fixed stereo scale, as depth_train.py's meta makes them
        meta.update(stereo_baseline=tcfg["stereo_baseline"],
                    stereo_scale_factor=seqs[0].extra["stereo_baseline_m"] / tcfg["stereo_baseline"])
    torch.manual_seed(seed)
    models = systems.build(meta)
    loss_kwargs = experiments.loss_settings(dcfg)

    # ---- instrumentation (measurement only: nothing here changes what the model sees)
    rec: dict = {"items": None, "flips": None, "pose": {}}
    orig_make_batch, orig_pose = data.make_batch, pipeline.predict_pose_parameters

    def make_batch(seqs_, items, sources_, flips=None):
        rec["items"], rec["flips"] = list(items), (list(flips) if flips is not None else None)
        return orig_make_batch(seqs_, items, sources_, flips)

    def predict_pose_parameters(models_, target, source, name):
        aa, tr = orig_pose(models_, target, source, name)
        rec["pose"][name] = (aa.detach(), tr.detach())
        return aa, tr

    data.make_batch = make_batch
    pipeline.predict_pose_parameters = predict_pose_parameters

    warmup = int(args.warmup)

    class WarmupAdam(training.Adam):
        """The project's Adam; the step size is lr x min(1, t / warmup) (linear warm-up, Goyal et al. 2017)."""

        def step(self):
            factor = min(1.0, (self.t + 1) / warmup) if warmup > 0 else 1.0
            base = self.lr
            self.lr = base * factor
            rec["eff_lr"] = self.lr
            try:
                super().step()
            finally:
                self.lr = base

    training.Adam = WarmupAdam

    step_rows: list[dict] = []
    val_rows: list[dict] = []

    def on_step(step, terms):
        items, flips = rec["items"], rec["flips"] or [False] * len(rec["items"])
        pred, true = [], []
        for name in sources:
            if name not in rec["pose"]:
                continue
            aa, tr = rec["pose"][name]
            pred.append(pipeline.pose_transform(aa, tr, name).numpy())
            for (i, t), f in zip(items, flips):
                T = true_transform(train_Twc[i], t, data.source_index(seqs[i], t, name))
                true.append(data.flip_transform(T) if f else T)
        row = {"step": step, **{k: float(v) for k, v in terms.items()}, "eff_lr": rec.get("eff_lr", terms["lr"])}
        if pred:
            row.update(pose_stats(np.concatenate(pred), np.stack(true)))
        step_rows.append(row)
        if step % 50 == 0 or step == 1:
            print(f"step {step}: loss {row['loss']:.4f} automask {row['automask_fraction']:.3f} "
                  f"|t| {row.get('t_pred', float('nan')):.4f} (true {row.get('t_true', float('nan')):.3f} m) "
                  f"rot {row.get('rot_pred_deg', float('nan')):.2f} deg (true {row.get('rot_true_deg', float('nan')):.2f}) "
                  f"lr {row['eff_lr']:.2e}", flush=True)

    frames_val = dcfg["eval"]["frames"].get("val", dcfg["eval"]["frames"]["all"])

    def validate(step):
        metrics = experiments.validation_metrics(models, meta, val, dcfg["eval"], frames_val)
        allm = experiments.validation_metrics(models, meta, val, dcfg["eval"], dcfg["eval"]["frames"]["all"])
        row = {"step": step, **metrics, **{f"all_{k}": v for k, v in allm.items()}}
        # pose of consecutive val frames (target t -> source t+1, as the "next" source) and the depth spread
        preds, trues, log_std, log_std_valid, gt_log_std = [], [], [], [], []
        ev = dcfg["eval"]
        with torch.no_grad():
            for es, Twc in zip(val, val_Twc):
                ims = data.to_tensor(es.seq.images)
                for t in range(es.seq.n_frames - 1):
                    aa, tr = orig_pose(models, ims[t:t + 1], ims[t + 1:t + 2], "next")
                    preds.append(pipeline.pose_transform(aa, tr, "next")[0].numpy())
                    trues.append(true_transform(Twc, t, t + 1))
                depth = experiments.predict_sequence(models, es.seq.images, meta)
                log_std += np.std(np.log(depth.reshape(len(depth), -1)), axis=1).tolist()
                for d, g in zip(depth, es.gt):  # on the evaluated pixels (GT valid, Garg crop), GT alongside
                    m = evaluation.valid_mask(g, min_depth=ev["min_depth"], max_depth=ev["max_depth"], crop=ev["crop"])
                    if m.any():
                        log_std_valid.append(float(np.std(np.log(experiments.resize_depth(d, g.shape)[m]))))
                        gt_log_std.append(float(np.std(np.log(g[m]))))
        scale = float(allm.get("median_ratio", float("nan")))
        row.update({f"val_{k}": v for k, v in pose_stats(np.stack(preds), np.stack(trues), scale).items()})
        row["val_depth_log_std"] = float(np.mean(log_std))
        row["val_depth_log_std_valid"] = float(np.mean(log_std_valid)) if log_std_valid else float("nan")
        row["val_gt_log_std_valid"] = float(np.mean(gt_log_std)) if gt_log_std else float("nan")
        row["train_loss_window"] = float(np.mean([r["loss"] for r in step_rows[-args.val_every:]]))
        row["train_automask_window"] = float(np.mean([r["automask_fraction"] for r in step_rows[-args.val_every:]]))
        val_rows.append(row)
        print(f"val @ {step}: abs_rel {metrics['abs_rel']:.4f} a1 {metrics['a1']:.3f} (all frames: abs_rel "
              f"{allm['abs_rel']:.4f}) scale {scale:.3g} | pose x scale / true {row['val_t_ratio']:.3f} "
              f"corr {row['val_t_corr']:.2f} cos {row['val_t_cos']:.2f} rot {row['val_rot_pred_deg']:.2f}/"
              f"{row['val_rot_true_deg']:.2f} deg | depth log-std {row['val_depth_log_std']:.3f} (GT pixels "
              f"{row['val_depth_log_std_valid']:.3f}, GT {row['val_gt_log_std_valid']:.3f})", flush=True)
        return metrics

    print(f"{ds}/{mode} seed {seed} (index {args.seed_index}) tag {args.tag}: {len(seqs)} train seqs "
          f"{h}x{w}, val {val_scenes}; train {tcfg}; loss {loss_kwargs}; warmup {warmup}", flush=True)
    t0 = time.perf_counter()
    if args.curriculum > 0:   # coarse-to-fine: the same networks (fully convolutional) on half-size frames first
        coarse = [data.resize_sequence(s_, (h // 2, w // 2)) for s_ in seqs]
        print(f"curriculum: {args.curriculum} steps at {h // 2}x{w // 2}", flush=True)
        training.train(models, coarse, sources, steps=args.curriculum, batch_size=int(tcfg["batch_size"]),
                       lr=float(tcfg["lr"]), decay_at=2.0, gamma=float(tcfg["gamma"]), flip=tcfg["flip"],
                       min_speed=tcfg["min_speed"], seed=seed + 1, loss_kwargs=loss_kwargs, callback=on_step,
                       device="cpu", criterion=None, automask_after=automask_after)
        validate(0)
    fine_automask_after = 0 if args.curriculum > 0 else automask_after   # the warm-up belongs to the coarse phase
    summary = training.train(models, seqs, sources, steps=steps, batch_size=int(tcfg["batch_size"]),
                             lr=float(tcfg["lr"]), decay_at=tcfg["decay_at"], gamma=float(tcfg["gamma"]),
                             flip=tcfg["flip"], min_speed=tcfg["min_speed"], seed=seed, loss_kwargs=loss_kwargs,
                             callback=on_step, device="cpu", criterion=None, validate=validate,
                             validate_every=args.val_every, automask_after=fine_automask_after)
    wall = time.perf_counter() - t0
    final, best = val_rows[-1], min(val_rows, key=lambda r: r["abs_rel"])
    result = {"tag": args.tag, "seed_index": args.seed_index, "seed": seed, "wall_s": wall,
              "recipe": {"steps": steps, "batch": int(tcfg["batch_size"]), "lr": float(tcfg["lr"]), "warmup": warmup,
                         "automask_after": automask_after,
                         "decay_at": tcfg["decay_at"], "gamma": float(tcfg["gamma"]), "flip": bool(tcfg["flip"]),
                         "min_speed": float(tcfg["min_speed"]), "smoothness": loss_kwargs["smoothness_weight"],
                         "width": int(model_cfg["base_channels"]), "size": [h, w]},
               "final": {k: final[k] for k in ("step", "abs_rel", "a1")},
               "best": {k: best[k] for k in ("step", "abs_rel", "a1")},
               "summary": {k: v for k, v in summary.items() if k != "validation"},
               "val": val_rows, "steps": step_rows, "argv": sys.argv}
    stem = out / f"{args.tag}_seed{args.seed_index}"
    write_study(stem.name, result, out_dir=out)
    for rows, suffix in ((step_rows, "_steps.csv"), (val_rows, "_val.csv")):
        keys = list(dict.fromkeys(k for r in rows for k in r))
        with open(f"{stem}{suffix}", "w", newline="") as f:
            wr = csv.DictWriter(f, keys)
            wr.writeheader()
            wr.writerows(rows)
    if args.dump:
        dump_val(models, meta, val, dcfg["eval"], f"{stem}_val_depth")
    print(f"done {args.tag} seed{args.seed_index}: final abs_rel {final['abs_rel']:.4f} a1 {final['a1']:.3f}; "
          f"best {best['abs_rel']:.4f} @ {best['step']}; wall {wall:.0f} s -> {stem}.json", flush=True)
    return 0


def dump_val(models, meta, val, ev, stem: str) -> None:
    """The final model's val depth, median-scaled per frame on the LiDAR pixels, beside the LiDAR depth: an npz,
    and a PNG (image / prediction / LiDAR-vs-prediction error) of every 5th frame; prints the error split by
    LiDAR depth bin and the signed log error (over- vs under-estimation)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from redsup.depth import evaluation, experiments
    images, preds, gts = [], [], []
    for es in val:
        depth = experiments.predict_sequence(models, es.seq.images, meta)
        for im, d, g in zip(es.seq.images, depth, es.gt):
            d = experiments.resize_depth(d, g.shape)
            m = evaluation.valid_mask(g, min_depth=ev["min_depth"], max_depth=ev["max_depth"], crop=ev["crop"])
            if m.any():
                d = d * np.median(g[m]) / np.median(d[m])
            images.append(im), preds.append(d), gts.append(np.where(m, g, 0.0))
    np.savez_compressed(f"{stem}.npz", images=np.stack(images), pred=np.stack(preds), gt=np.stack(gts))
    pred, gt = np.stack(preds), np.stack(gts)
    m = gt > 0
    err = np.abs(pred[m] - gt[m]) / gt[m]
    sl = np.log(pred[m] / gt[m])
    for lo, hi in ((0, 10), (10, 20), (20, 40), (40, 80)):
        b = (gt[m] >= lo) & (gt[m] < hi)
        if b.any():
            print(f"GT {lo}-{hi} m: {b.mean():.2f} of pixels, abs_rel {err[b].mean():.3f}, mean log(pred/gt) "
                  f"{sl[b].mean():+.3f}", flush=True)
    rows = list(range(0, len(images), 5))
    fig, ax = plt.subplots(len(rows), 3, figsize=(12, 1.4 * len(rows)), squeeze=False)
    for r, i in enumerate(rows):
        ax[r, 0].imshow(images[i])
        ax[r, 1].imshow(1.0 / np.maximum(preds[i], 0.1), cmap="magma")
        e = np.where(gts[i] > 0, np.log(np.maximum(preds[i], 1e-3) / np.maximum(gts[i], 1e-3)), np.nan)
        ax[r, 2].imshow(e, cmap="coolwarm", vmin=-1, vmax=1)
        for a in ax[r]:
            a.axis("off")
    ax[0, 2].set_title("log(pred / LiDAR): red = too far")
    fig.tight_layout()
    fig.savefig(f"{stem}.png", dpi=80)
    plt.close(fig)


def oracle(args) -> int:
    """Monodepth2's scale-0 masked min-reprojection loss and auto-mask fraction of the *true* geometry (the raw
    scenes' rendered depth gt/depth/<camera>/*.png cropped and resized like the images, the true camera motion),
    of a constant 8 m depth with the true motion and of the identity: what the self-supervised objective would
    reach at the right answer (measurement only)."""
    import torch

    from redsup import sceneio
    from redsup.depth import data, losses, warping
    from redsup.depth.configs import split_of

    torch.set_num_threads(args.threads)
    cfg = rconfig.load(args.config, {"profile": args.profile})
    spec, tcfg = cfg["datasets"][args.dataset], cfg["depth"]["train"]
    res = Path(args.results)
    scenes = split_of(sorted(p.name for p in (res / "raw" / args.dataset).iterdir()), "train")
    crop = spec["crop"]
    acc: dict[str, list] = {}
    for s in scenes:
        sd = res / "raw" / args.dataset / s
        seq = data.load_sequence(res / "prepared" / args.dataset / s / "cam_front.npz", scene_dir=sd)
        Twc = camera_poses(sd, "cam_front")
        K = torch.tensor(seq.K[None], dtype=torch.float32)
        for t in range(1, seq.n_frames - 1):
            if seq.speed[t] < float(tcfg["min_speed"]):
                continue
            d = sceneio.read_depth_png(sd / "gt" / "depth" / "cam_front" / f"{t:06d}.png")
            d = d[crop["top"]:d.shape[0] - crop["bottom"], crop["left"]:d.shape[1] - crop["right"]]
            d = np.where(d > 0, d, 1000.0)  # no value (sky): far
            disp = torch.nn.functional.interpolate(torch.from_numpy(1.0 / d).float()[None, None], size=seq.size,
                                                   mode="area")
            tgt = data.to_tensor(seq.images[t:t + 1])
            errs = {"oracle": [], "const8m": [], "identity": []}
            for j in (t - 1, t + 1):
                src = data.to_tensor(seq.images[j:j + 1])
                T = torch.tensor(true_transform(Twc, t, j)[None], dtype=torch.float32)
                errs["oracle"].append(losses.photometric_error(warping.warp(src, 1.0 / disp, K, T), tgt))
                errs["const8m"].append(losses.photometric_error(warping.warp(src, torch.full_like(disp, 8.0), K, T),
                                                                tgt))
                errs["identity"].append(losses.photometric_error(src, tgt))
            ident = losses.min_reprojection(errs["identity"])
            for k in ("oracle", "const8m"):
                e = losses.min_reprojection(errs[k])
                m = (e < ident).float()
                acc.setdefault(f"{k}_loss", []).append(float((m * e).mean()))
                acc.setdefault(f"{k}_automask", []).append(float(m.mean()))
            acc.setdefault("identity_error", []).append(float(ident.mean()))
    result = {k: float(np.mean(v)) for k, v in acc.items()}
    result["n_frames"] = len(acc.get("identity_error", []))
    print(json.dumps(result, indent=1))
    write_study("oracle", result, out_dir=args.out)
    return 0


def summarize(out: Path) -> int:
    runs = [json.loads(Path(p).read_text()) for p in sorted(glob.glob(str(out / "*_seed*.json")))]
    by_tag: dict[str, list] = {}
    print(f"{'recipe':24s} {'seed':>4s} {'final AbsRel':>12s} {'a1':>6s} {'best AbsRel':>11s} {'@':>4s} {'a1':>6s} "
          f"{'wall s':>7s} {'t_ratio':>7s} {'t_corr':>6s} {'automask':>8s}")
    for r in runs:
        by_tag.setdefault(r["tag"], []).append(r)
        v = r["val"][-1]
        print(f"{r['tag']:24s} {r['seed_index']:4d} {r['final']['abs_rel']:12.4f} {r['final']['a1']:6.3f} "
              f"{r['best']['abs_rel']:11.4f} {r['best']['step']:4d} {r['best']['a1']:6.3f} {r['wall_s']:7.0f} "
              f"{v['val_t_ratio']:7.3f} {v['val_t_corr']:6.2f} {v['train_automask_window']:8.3f}")
    print()
    for tag, rs in by_tag.items():
        f = np.array([r["final"]["abs_rel"] for r in rs])
        b = np.array([r["best"]["abs_rel"] for r in rs])
        a = np.array([r["final"]["a1"] for r in rs])
        print(f"{tag:24s} n={len(rs)} final AbsRel {f.mean():.4f} +- {f.std(ddof=1) if len(f) > 1 else math.nan:.4f} "
              f"(a1 {a.mean():.3f}); best {b.mean():.4f} +- {b.std(ddof=1) if len(b) > 1 else math.nan:.4f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
