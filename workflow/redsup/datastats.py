"""Dataset statistics: McCraith ch. 3 Table I (clips per distance bin) and the prepared-data summary."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd

BIN_EDGES = (20.0, 45.0)  # near < 20 m <= medium < 45 m <= far (TuSimple protocol)
BIN_NAMES = ("near", "medium", "far")


def distance_bin(z, x=0.0, edges: tuple[float, float] = BIN_EDGES) -> np.ndarray:
    """0 near (d < edges[0]), 1 medium, 2 far (d >= edges[1]) with d = ||[z, x]||, the length of the
    ground-truth position (forward z, lateral x), as the TuSimple challenge script
    (`evaluate/velocity.py`, `get_distance_label`: np.linalg.norm(position))."""
    d = np.hypot(np.asarray(z, dtype=float), np.asarray(x, dtype=float))
    return np.digitize(d, edges)


def clip_annotations(split_dir: str | Path) -> pd.DataFrame:
    """One row per annotated vehicle of a TuSimple-shaped split folder."""
    rows = []
    for ann_path in sorted(Path(split_dir).glob("clips/*/annotation.json")):
        for vehicle in json.loads(ann_path.read_text()):
            z, x = vehicle["position"]  # TuSimple order: [forward, lateral]
            vz, vx = vehicle["velocity"]
            rows.append({"clip": ann_path.parent.name, "x": x, "z": z, "vx": vx, "vz": vz})
    return pd.DataFrame(rows, columns=["clip", "x", "z", "vx", "vz"])


def bin_counts(split_dirs: dict[str, str | Path]) -> pd.DataFrame:
    """Table I layout: rows per split (e.g. Train, Test), columns Near, Medium, Far, Total."""
    table = {}
    for name, folder in split_dirs.items():
        ann = clip_annotations(folder)
        bins = distance_bin(ann["z"].to_numpy(), ann["x"].to_numpy())
        counts = np.bincount(bins, minlength=3)
        table[name] = {"Near": counts[0], "Medium": counts[1], "Far": counts[2], "Total": counts.sum()}
    return pd.DataFrame.from_dict(table, orient="index").astype(int)


def prepared_summary(prepared_files: list[str | Path]) -> pd.DataFrame:
    """One row per dataset: scenes, frames, cameras, prepared size, LiDAR density, detections, tracks."""
    per_dataset: dict[str, dict] = {}
    for path in map(Path, prepared_files):
        if path.parts[-3] == "clips":
            continue
        dataset, scene, name = path.parts[-3], path.parts[-2], path.name
        row = per_dataset.setdefault(dataset, {"scenes": set(), "cameras": set(), "frames": 0,
                                               "density": [], "det": {}, "lm": {}, "tracks": {}})
        row["scenes"].add(scene)
        if name.endswith("_depth.npz"):
            with np.load(path) as data:
                row["density"].append(float((data["depth"] > 0).mean()))
        elif name.startswith("cam_"):
            with np.load(path) as data:
                row["cameras"].add(name[:-4])
                if name == "cam_front.npz":
                    row["frames"] += int(data["images"].shape[0])
                    row["size"] = f"{data['images'].shape[2]}x{data['images'].shape[1]}"
        elif name.startswith("detections_"):
            level = name[len("detections_"):-4]
            with np.load(path) as data:
                row["det"][level] = row["det"].get(level, 0) + int(data["score"].shape[0])
                row["lm"].setdefault(level, []).append(np.diff(data["point_offsets"]))
        elif name.startswith("tracks3d_"):
            level = name[len("tracks3d_"):-4]
            tracks = pd.read_csv(path)
            row["tracks"][level] = row["tracks"].get(level, 0) + int(tracks["track"].nunique())
    out = []
    for dataset, row in sorted(per_dataset.items()):
        entry = {"dataset": dataset, "scenes": len(row["scenes"]), "frames (cam_front)": row["frames"],
                 "cameras": " ".join(sorted(row["cameras"])), "prepared size": row.get("size", ""),
                 "LiDAR pixel density %": 100 * float(np.mean(row["density"])) if row["density"] else np.nan}
        for level in sorted(row["det"]):
            sizes = np.concatenate(row["lm"][level]) if row["lm"][level] else np.zeros(0)
            entry[f"detections {level}"] = row["det"][level]
            entry[f"median |L_m| {level}"] = float(np.median(sizes)) if sizes.size else np.nan
            entry[f"3D tracks {level}"] = row["tracks"].get(level, 0)
        out.append(entry)
    return pd.DataFrame(out).set_index("dataset")
