"""The per-frame 2D ground-truth images of an adapted scene (`gt/instance`, `gt/semantic`), from the
dataset spec's `instances` and `road` settings, shared by every adapter kind."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from redsup.adapters import masks
from redsup.adapters.common import SceneWriter, empty_box_row, mirrored
from redsup.sceneio import frame_name

COCO_CATEGORIES = {3: "car"}  # COCO category id 3 = car (the ids Detectron2 / MMDetection write)


def instance_settings(spec: dict) -> dict:
    cfg = dict(spec.get("instances") or {})
    cfg.setdefault("source", "none")
    cfg.setdefault("min_score", 0.5)
    cfg.setdefault("match_iou", 0.5)
    cats = cfg.get("categories") or COCO_CATEGORIES
    cfg["categories"] = {int(k): str(v) for k, v in cats.items()}
    return cfg


class Frames2D:
    """Writes gt/instance/<camera>/NNNNNN.png and gt/semantic/<camera>/NNNNNN.png for every frame.

    instances.source: `detections` (COCO-result JSON per image under instances.path), `label_boxes`
    (pseudo-masks: the labelled 2D boxes filled, KITTI object only), `none` (all 0). road.path: Cityscapes
    label-id PNGs per image, else all 0 (no class). Detections of unlabelled scenes add boxes.csv rows.
    Detections also go to gt/detections/<camera>/NNNNNN.json with their own masks; `stats` counts those
    the composite instance image hides entirely (`detections_hidden_in_instance_image`).
    """

    def __init__(self, spec: dict, dataset_root: str | Path):
        self.inst = instance_settings(spec)
        self.road = (spec.get("road") or {}).get("path")
        self.root = Path(dataset_root)
        self.stats = {"detections_kept": 0, "detections_unmatched": 0, "detections_hidden_in_instance_image": 0,
                      "semantic_frames": 0}

    def write(self, writer: SceneWriter, camera: str, frame: int, image_path: Path, size: tuple[int, int],
              labels: list[dict] | None, labelled: bool) -> list[dict]:
        """Write both images of one frame; returns boxes.csv rows to add (detections of unlabelled data)."""
        width, height = size
        relative = Path(image_path).resolve().relative_to(self.root.resolve()) \
            if Path(image_path).is_absolute() else Path(image_path)
        new_rows: list[dict] = []
        source = self.inst["source"]
        if source == "detections":
            dets = masks.load_detections(mirrored(self.inst["path"], relative, ".json"), size,
                                         self.inst["categories"], self.inst["min_score"])
            instance, added, unmatched, records = masks.instances_from_detections(
                dets, size, labels if labelled else None, self.inst["match_iou"],
                first_id=1 + max([int(r["track_id"]) for r in (labels or [])] + [0]))
            self.stats["detections_kept"] += len(dets)
            self.stats["detections_unmatched"] += unmatched
            self.stats["detections_hidden_in_instance_image"] += masks.hidden_instances(
                instance, [r["track_id"] for r in records])
            writer.write_json(f"gt/detections/{camera}/{frame_name(frame, 'json')}", records)
            for r in added:
                row = empty_box_row(frame, r["track_id"], r["cls"])
                row.update({k: r[k] for k in ("x1", "y1", "x2", "y2")})
                row["visible_px"] = float(np.count_nonzero(instance == r["track_id"]))
                new_rows.append(row)
        elif source == "label_boxes" and labels:
            instance = masks.instances_from_boxes(labels, size)
        else:
            instance = np.zeros((height, width), dtype=np.uint16)
        if labels:
            ids, counts = np.unique(instance, return_counts=True)
            visible = dict(zip(ids.tolist(), counts.tolist()))
            for r in labels:
                if source != "none" and str(r["cls"]).lower() != "dontcare":
                    r["visible_px"] = float(visible.get(int(r["track_id"]), 0))
        writer.write_png(f"gt/instance/{camera}/{frame_name(frame, 'png')}", instance)
        if self.road:
            semantic = masks.load_semantic(mirrored(self.road, relative, ".png"), size)
            self.stats["semantic_frames"] += 1
        else:
            semantic = np.zeros((height, width), dtype=np.uint8)
        writer.write_png(f"gt/semantic/{camera}/{frame_name(frame, 'png')}", semantic)
        return new_rows

    def meta(self) -> dict:
        return {"instances": self.inst["source"], "semantic": "png" if self.road else "none",
                "detections_supplied": self.inst["source"] == "detections"}
