"""2D inputs of real datasets: precomputed instance detections (COCO result format) and semantic label
PNGs (Cityscapes label ids), turned into the scene's `gt/instance` and `gt/semantic` images.

Layout: one file per image at `<root>/<the image's path relative to the dataset path>` with the
extension replaced (`.json` for detections, `.png` for semantic labels); see README.md, "Running on the real datasets".

A detection file is the list Detectron2 / MMDetection write in COCO result format for that image:
``[{"category_id": int, "score": float, "segmentation": RLE or polygons, "bbox": [x, y, w, h], ...}]``
(`image_id` is ignored: the file name says which image). Masks are COCO RLE (compressed string or
counts list, `redsup.adapters.rle`) or polygon lists; their size must be the image size.

The scene keeps every detection's own mask: `gt/detections/<camera>/<frame>.json` lists each kept detection
with its mask as a compressed COCO RLE, and the detection stage reads the masks from there. `gt/instance` is
only the composite (one id per pixel, the better detection owning an overlap), so a detection fully covered
by a better one has no pixel in it; the adapter counts those (`detections_hidden_in_instance_image`).
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from redsup.adapters import rle
from redsup.adapters.common import AdapterError
from redsup.sceneio import read_json


def _polygons_to_mask(polygons, size: tuple[int, int]) -> np.ndarray:
    width, height = size
    mask = np.zeros((height, width), dtype=np.uint8)
    for poly in polygons:
        pts = np.asarray(poly, dtype=np.float64).reshape(-1, 2)
        if len(pts) >= 3:
            cv2.fillPoly(mask, [np.round(pts).astype(np.int32)], 1)
    return mask.astype(bool)


def load_detections(path: str | Path, size: tuple[int, int], categories: dict[int, str],
                    min_score: float) -> list[dict]:
    """Detections of one image kept by category and score: [{mask (H, W) bool, score, cls}], best first.

    Raises AdapterError naming the file for a missing file, bad JSON, a missing field or a mask whose
    size differs from the image's (W, H) = `size`.
    """
    path = Path(path)
    entries = read_json(path, "detection file missing (one COCO-result JSON per image)", AdapterError)
    if not isinstance(entries, list):
        raise AdapterError(f"{path}: expected a list of COCO results (category_id, score, segmentation)")
    out = []
    width, height = size
    for i, entry in enumerate(entries):
        if not isinstance(entry, dict) or not all(k in entry for k in ("category_id", "score", "segmentation")):
            raise AdapterError(f"{path}: entry {i} needs category_id, score and segmentation")
        cls = categories.get(int(entry["category_id"]))
        score = float(entry["score"])
        if cls is None or score < min_score:
            continue
        seg = entry["segmentation"]
        try:
            if isinstance(seg, dict):
                if [int(v) for v in seg.get("size", [])] != [height, width]:
                    raise AdapterError(f"{path}: entry {i}: mask size {seg.get('size')} is not the image's "
                                       f"[h, w] = [{height}, {width}]")
                mask = rle.decode(seg)
            elif isinstance(seg, list):
                mask = _polygons_to_mask(seg, size)
            else:
                raise AdapterError(f"{path}: entry {i}: segmentation must be an RLE dict or polygon list")
        except rle.RLEError as exc:
            raise AdapterError(f"{path}: entry {i}: {exc}") from exc
        if mask.any():
            out.append({"mask": mask, "score": score, "cls": cls})
    out.sort(key=lambda d: -d["score"])
    return out


def mask_box(mask: np.ndarray) -> tuple[float, float, float, float]:
    """x1, y1, x2, y2 outer pixel edges of a mask (columns c0..c1 give x1 = c0 - 0.5, x2 = c1 + 0.5)."""
    rows = np.flatnonzero(mask.any(axis=1))
    cols = np.flatnonzero(mask.any(axis=0))
    return cols[0] - 0.5, rows[0] - 0.5, cols[-1] + 0.5, rows[-1] + 0.5


def box_iou(a, b) -> float:
    ix = max(0.0, min(a[2], b[2]) - max(a[0], b[0]))
    iy = max(0.0, min(a[3], b[3]) - max(a[1], b[1]))
    inter = ix * iy
    union = (a[2] - a[0]) * (a[3] - a[1]) + (b[2] - b[0]) * (b[3] - b[1]) - inter
    return inter / union if union > 0 else 0.0


def instances_from_detections(detections: list[dict], size: tuple[int, int], labels: list[dict] | None,
                              match_iou: float, first_id: int = 1
                              ) -> tuple[np.ndarray, list[dict], int, list[dict]]:
    """(instance image uint16, new boxes.csv rows, number of unmatched detections, detection records).

    With `labels` (boxes.csv rows of a labelled frame), each detection takes the id of the unmatched
    label of the same class (case-insensitive) whose 2D box overlaps its mask box most (IoU >= match_iou,
    greedy in score order). A detection matching no label (a false positive) is kept with a new id
    (from `first_id`) but adds no row (it is no ground truth). Without labels every detection gets a new id
    and a new row with its class and mask box (3D fields unknown). No detection is dropped: filtering by the labels would put ground truth into the
    detections. The records [{track_id, score, cls, segmentation}], best first, keep every detection's own
    score and own mask (compressed COCO RLE). The instance image is their composite: masks are painted lowest
    score first, so the better detection owns overlapping pixels, and one fully covered by a better one has no
    pixel in it (`hidden_instances` counts those); its record still has its whole mask.
    """
    width, height = size
    instance = np.zeros((height, width), dtype=np.uint16)
    assigned: list[tuple[int, dict]] = []
    new_rows: list[dict] = []
    dropped = 0
    used: set[int] = set()
    next_id = first_id
    for det in detections:
        box = mask_box(det["mask"])
        if labels is not None:
            best, best_iou = None, match_iou
            for row in labels:
                if int(row["track_id"]) in used or str(row["cls"]).lower() != det["cls"].lower():
                    continue
                iou = box_iou(box, (row["x1"], row["y1"], row["x2"], row["y2"]))
                if iou >= best_iou:
                    best, best_iou = row, iou
            if best is not None:
                used.add(int(best["track_id"]))
                assigned.append((int(best["track_id"]), det))
                continue
            dropped += 1                   # unmatched: kept below as a new instance
        assigned.append((next_id, det))
        if labels is None:                 # labelled frames: a false positive is no ground-truth row
            new_rows.append({"track_id": next_id, "cls": det["cls"], "x1": box[0], "y1": box[1],
                             "x2": box[2], "y2": box[3]})
        next_id += 1
    for track, det in sorted(assigned, key=lambda a: a[1]["score"]):
        instance[det["mask"]] = track
    records = [{"track_id": int(t), "score": float(d["score"]), "cls": d["cls"],
                "segmentation": rle.encode(d["mask"])} for t, d in assigned]
    return instance, new_rows, dropped, records


def hidden_instances(instance: np.ndarray, track_ids) -> int:
    """How many of `track_ids` have no pixel in the instance image (covered by better detections)."""
    return len(set(int(t) for t in track_ids) - set(np.unique(instance).tolist()))


def instances_from_boxes(labels: list[dict], size: tuple[int, int]) -> np.ndarray:
    """Pseudo instance masks: each labelled object's 2D box filled with its id (pixels whose centre lies
    inside), far objects first so nearer ones own the overlap. DontCare and rows without a box are skipped."""
    width, height = size
    instance = np.zeros((height, width), dtype=np.uint16)
    rows = [r for r in labels if str(r["cls"]).lower() != "dontcare"
            and np.all(np.isfinite([r["x1"], r["y1"], r["x2"], r["y2"]]))]
    rows.sort(key=lambda r: -(np.hypot(r["x"], r["y"]) if np.isfinite(r["x"]) else 0.0))
    for r in rows:
        c0, c1 = int(np.ceil(r["x1"])), int(np.floor(r["x2"]))
        r0, r1 = int(np.ceil(r["y1"])), int(np.floor(r["y2"]))
        c0, r0 = max(c0, 0), max(r0, 0)
        c1, r1 = min(c1, width - 1), min(r1, height - 1)
        if c1 >= c0 and r1 >= r0:
            instance[r0:r1 + 1, c0:c1 + 1] = int(r["track_id"])
    return instance


def load_semantic(path: str | Path, size: tuple[int, int]) -> np.ndarray:
    """A Cityscapes label-id PNG (uint8, single channel, the image's size)."""
    path = Path(path)
    image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if image is None:
        raise AdapterError(f"{path}: semantic label PNG {'unreadable' if path.exists() else 'missing'}")
    if image.ndim != 2:
        raise AdapterError(f"{path}: expected a single-channel PNG of Cityscapes label ids, got shape {image.shape}")
    if (image.shape[1], image.shape[0]) != tuple(size):
        raise AdapterError(f"{path}: label image is {image.shape[1]}x{image.shape[0]}, image is {size[0]}x{size[1]}")
    return image.astype(np.uint8)
