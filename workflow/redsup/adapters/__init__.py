"""Real datasets as drop-in inputs: adapters that convert KITTI raw drives, KITTI object frames and
scene-folder datasets (Lyft / DDAD / NAP-lab after extraction) into the canonical raw-scene format
(README.md, "The canonical raw-scene format"), and TuSimple velocity splits into the clip folders of the DAG.

Conversion (rather than reading in place) keeps every downstream rule unchanged: `adapt_scene` writes
`results/raw/<dataset>/<scene>/` exactly where `world_scene` writes it for the embedded world. Images and
LiDAR sweeps that are already in the canonical encoding (PNG, KITTI float32 records) are symlinked by
default (`copy_files: true` copies), everything else (intrinsics, extrinsics, poses, boxes, masks) is
written. Scene ids are `<split>_<source name>` and are listed when the workflow is parsed (split files
are read then); missing roots, split files or drives fail at that point, missing or malformed files of one
scene fail its `adapt_scene` job, each with an AdapterError naming the file.
"""
from __future__ import annotations

from redsup.adapters import kitti, scene_folder
from redsup.adapters.common import AdapterError

KINDS = ("kitti_raw", "kitti_object", "scene_folder")

__all__ = ["KINDS", "AdapterError", "scene_table", "scene_ids", "cameras", "adapt_scene"]


def _check_kind(name: str, spec: dict) -> str:
    kind = spec.get("kind")
    if kind not in KINDS:
        raise AdapterError(f"datasets.{name}: kind '{kind}' has no adapter (adapter kinds: {list(KINDS)})")
    return kind


def scene_table(name: str, spec: dict) -> dict[str, dict]:
    """{scene id: where it comes from} of an adapter dataset, read from the folders and split files."""
    kind = _check_kind(name, spec)
    try:
        if kind == "kitti_raw":
            return kitti.raw_scene_table(spec)
        if kind == "kitti_object":
            return kitti.object_scene_table(spec)
        return scene_folder.scene_table(spec)
    except AdapterError as exc:
        raise AdapterError(f"datasets.{name} (kind {kind}): {exc}") from exc


def scene_ids(name: str, spec: dict) -> list[str]:
    return sorted(scene_table(name, spec))


def cameras(spec: dict) -> list[str]:
    """Canonical names of the cameras an adapter dataset provides."""
    if spec["kind"] == "scene_folder":
        return list(scene_folder.camera_settings(spec))
    return list(spec.get("cameras") or ["cam_front"])


def adapt_scene(name: str, spec: dict, scene: str, out_dir, seed: int = 0) -> dict:
    """Write one scene of an adapter dataset into `out_dir` (canonical format); returns summary numbers."""
    kind = _check_kind(name, spec)
    fn = {"kitti_raw": kitti.adapt_raw, "kitti_object": kitti.adapt_object, "scene_folder": scene_folder.adapt}[kind]
    return fn(name, spec, scene, out_dir, seed=seed)
