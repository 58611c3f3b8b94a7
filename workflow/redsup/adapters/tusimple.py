"""TuSimple velocity clips as the `results/raw/clips/<split>` folders of the DAG.

The embedded world already writes clips in TuSimple's layout and annotation order (`clips/<n>/imgs/001…040`,
`annotation.json` with position [z, x] and velocity [vz, vx] — the numbers TuSimple's README calls
"[x, y]" with x along the optical axis), so a real split is used nearly in place: each `clips/<n>/imgs`
is linked (or copied), `annotation.json` is rewritten with the box as a {top, left, bottom, right} dict
(the test "indication" files give [top, left, bottom, right]) and, for the test split, velocity and
position merged from the ground-truth file, and `calibration.txt` is rewritten in the canonical
`fx fy cx cy` / `camera height` form from TuSimple's "Intrinsic matrix: … Camera Height: 1.80m" text.
"""
from __future__ import annotations

import json
import os
import re
import shutil
from pathlib import Path

from redsup.adapters.common import AdapterError
from redsup.sceneio import read_json

NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
CLIP_FRAMES = 40  # every TuSimple velocity clip: imgs/001 ... 040 at 20 fps, annotated in the last


def check_clip_frames(imgs: Path, n_frames: int = CLIP_FRAMES) -> None:
    """AdapterError naming `imgs` and the missing frame numbers unless 001..n_frames (.jpg or .png) exist."""
    if not imgs.is_dir():
        raise AdapterError(f"{imgs}: missing")
    have = {p.stem for p in imgs.iterdir() if p.suffix.lower() in (".jpg", ".png")}
    missing = [f"{k:03d}" for k in range(1, n_frames + 1) if f"{k:03d}" not in have]
    if missing:
        shown = ", ".join(missing[:8]) + (f" and {len(missing) - 8} more" if len(missing) > 8 else "")
        raise AdapterError(f"{imgs}: {len(missing)} of {n_frames} frames missing ({shown}); a TuSimple clip has "
                           f"{n_frames} (001.jpg ... {n_frames:03d}.jpg)")


def read_calibration(path: str | Path) -> dict:
    """{fx, fy, cx, cy, height} from a TuSimple calibration.txt or the canonical `fx fy cx cy` / `height`."""
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError as exc:
        raise AdapterError(f"{path}: calibration.txt missing (camera intrinsics and height)") from exc
    lines = [ln for ln in text.splitlines() if ln.strip()]
    numbers = [[float(x) for x in re.findall(NUMBER, ln)] for ln in lines]
    if lines and len(numbers[0]) == 4 and not re.search(r"[A-Za-z]", lines[0]):
        fx, fy, cx, cy = numbers[0]
        height = numbers[1][0] if len(numbers) > 1 and numbers[1] else float("nan")
        return {"fx": fx, "fy": fy, "cx": cx, "cy": cy, "height": height}
    try:
        k = next(i for i, ln in enumerate(lines) if "intrinsic" in ln.lower())
        rows = [r for r in numbers[k + 1:] if len(r) == 3][:3]
        h = next(i for i, ln in enumerate(lines) if "height" in ln.lower())
        height = next(r[0] for r in numbers[h:] if r)
        if len(rows) != 3:
            raise StopIteration
    except StopIteration as exc:
        raise AdapterError(f"{path}: expected 'fx fy cx cy' / height, or TuSimple's 'Intrinsic matrix:' with "
                           f"3 rows and 'Camera Height:' with a value") from exc
    return {"fx": rows[0][0], "fy": rows[1][1], "cx": rows[0][2], "cy": rows[1][2], "height": height}


def normalise_bbox(bbox, where: str) -> dict:
    if isinstance(bbox, dict) and all(k in bbox for k in ("top", "left", "bottom", "right")):
        return {k: float(bbox[k]) for k in ("top", "left", "bottom", "right")}
    if isinstance(bbox, (list, tuple)) and len(bbox) == 4:
        return dict(zip(("top", "left", "bottom", "right"), (float(v) for v in bbox)))
    raise AdapterError(f"{where}: bbox must be {{top, left, bottom, right}} or [top, left, bottom, right]")


def read_gt(path: str | Path) -> dict[int, list]:
    """Test ground truth: {clip number: vehicles}. Accepts a JSON object keyed by clip number or a list
    whose k-th entry is clip k+1 (each entry a list of {bbox, velocity, position}), or JSON lines with
    one such list per clip."""
    path = Path(path)
    try:
        text = path.read_text()
    except FileNotFoundError as exc:
        raise AdapterError(f"{path}: ground-truth file missing (velocity_clips.source.splits.<split>.gt)") from exc
    try:
        data = json.loads(text)
    except json.JSONDecodeError:
        try:
            data = [json.loads(ln) for ln in text.splitlines() if ln.strip()]
        except json.JSONDecodeError as exc:
            raise AdapterError(f"{path}: neither JSON nor JSON lines: {exc}") from exc
    if isinstance(data, dict):
        return {int(k): v for k, v in data.items()}
    return {k + 1: v for k, v in enumerate(data)}


def _vehicles(annotations, where: str, gt: list | None) -> list[dict]:
    if not isinstance(annotations, list):
        raise AdapterError(f"{where}: expected a list of annotated vehicles")
    out = []
    for k, a in enumerate(annotations):
        entry = {"bbox": normalise_bbox(a.get("bbox") if isinstance(a, dict) else a, where)}
        source = a if isinstance(a, dict) else {}
        if gt is not None and "velocity" not in source:
            matches = [g for g in gt if normalise_bbox(g["bbox"], where) == entry["bbox"]]
            source = matches[0] if matches else (gt[k] if k < len(gt) else {})
        for key in ("velocity", "position"):
            if key not in source:
                raise AdapterError(f"{where}: vehicle {k} has no {key} (test clips need the ground-truth file: "
                                   f"velocity_clips.source.splits.<split>.gt)")
            entry[key] = [float(v) for v in source[key]]
        entry["track_id"] = int(source.get("track_id", k))
        out.append(entry)
    return out


def adapt_clips(source: dict, split: str, out_dir: str | Path) -> dict:
    """Write `out_dir` = results/raw/clips/<split> from the TuSimple folder of that split."""
    cfg = (source.get("splits") or {}).get(split)
    if cfg is None:
        raise AdapterError(f"velocity_clips.source.splits has no '{split}'")
    root = Path(cfg["path"])
    clips_root = root / "clips"
    if not clips_root.is_dir():
        raise AdapterError(f"{clips_root}: missing (a TuSimple split folder holds clips/<n>/ and calibration.txt)")
    calibration = read_calibration(Path(cfg.get("calibration") or root / "calibration.txt"))
    gt = read_gt(cfg["gt"]) if cfg.get("gt") else None
    dirs = [p for p in clips_root.iterdir() if p.is_dir()]
    bad = [p.name for p in dirs if not p.name.isdigit()]
    if bad:
        raise AdapterError(f"{clips_root}: clip folders must be numbered, found {bad[:5]}")
    out = Path(out_dir)
    tmp = out.parent / f".{out.name}.tmp{os.getpid()}"
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    n_vehicles = 0
    try:
        (tmp / "calibration.txt").write_text(
            f"{calibration['fx']:.6f} {calibration['fy']:.6f} {calibration['cx']:.6f} {calibration['cy']:.6f}\n"
            f"{calibration['height']:.6f}\n")
        for clip in sorted(dirs, key=lambda p: int(p.name)):
            ann_path = clip / "annotation.json"
            check_clip_frames(clip / "imgs")
            annotations = read_json(ann_path, error=AdapterError)
            vehicles = _vehicles(annotations, str(ann_path), None if gt is None else gt.get(int(clip.name), []))
            n_vehicles += len(vehicles)
            dst = tmp / "clips" / clip.name
            dst.mkdir(parents=True)
            if cfg.get("copy_files", False):
                shutil.copytree(clip / "imgs", dst / "imgs")
            else:
                os.symlink((clip / "imgs").resolve(), dst / "imgs", target_is_directory=True)
            (dst / "annotation.json").write_text(json.dumps(vehicles, indent=1))
        if out.exists():
            shutil.rmtree(out)
        tmp.rename(out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return {"clips": len(dirs), "vehicles": n_vehicles, "fx": calibration["fx"], "camera_height": calibration["height"]}
