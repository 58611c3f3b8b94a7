"""Prepared camera sequences as training and test samples for the depth networks (numpy in, torch out).

A ``Sequence`` is one camera of one prepared scene (``results/prepared/<dataset>/<scene>/<camera>.npz``):
uint8 images (T, H, W, 3) and the adjusted intrinsics K, optionally the stereo partner
(``cam_front_right``) with the known target->source transform, the ego speed per frame (to drop static
frames from monocular training, as Zhou et al.'s split that Monodepth2 and McCraith ch. 4 §4.1 use) and a
``reversed`` flag: a backward-facing camera read in reversed temporal order moves forward like the front
camera (Galteland §4.6: "the relative index j was reversed").

Sources of a sample at frame t (``pipeline`` names): ``prev`` = frame t-1 and ``next`` = t+1 (swapped for a
reversed sequence), ``stereo`` = the partner image at t. A sample whose source is missing (first / last frame,
no stereo partner) is not built: ``sample_sources`` returns the reason instead, which callers count and
report.
"""
from __future__ import annotations

import json
from collections.abc import Sequence as Seq
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from redsup import sceneio

TEMPORAL = ("prev", "next")
KNOWN_SOURCES = ("prev", "next", "stereo")


@dataclass
class Sequence:
    """One camera of one scene at the prepared resolution."""

    name: str
    images: np.ndarray  # (T, H, W, 3) uint8
    K: np.ndarray  # (3, 3) at the prepared resolution
    stereo: np.ndarray | None = None  # (T, H, W, 3) uint8 partner images (same K, rectified)
    stereo_T: np.ndarray | None = None  # (4, 4) target->partner transform (points of this camera -> partner)
    speed: np.ndarray | None = None  # (T,) ego speed m/s (None: unknown, every frame counts as moving)
    reversed: bool = False
    camera: str = "cam_front"
    extra: dict = field(default_factory=dict)

    @property
    def n_frames(self) -> int:
        return len(self.images)

    @property
    def size(self) -> tuple[int, int]:
        """(H, W)."""
        return self.images.shape[1], self.images.shape[2]


def read_prepared(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """(images (T, H, W, 3) uint8, K (3, 3)) of a prepared camera file, with the file named on error."""
    path = Path(path)
    try:
        with np.load(path) as data:
            images, K = data["images"], data["K"].astype(np.float64)
    except (OSError, KeyError, ValueError) as exc:
        raise ValueError(f"{path}: not a prepared camera file ({type(exc).__name__}: {exc})") from exc
    if images.ndim != 4 or images.shape[-1] != 3 or images.dtype != np.uint8:
        raise ValueError(f"{path}: images must be (T, H, W, 3) uint8, got {images.shape} {images.dtype}")
    return images, K


def read_gt_depth(path: str | Path) -> np.ndarray:
    """LiDAR depth maps (T, h, w) float32 of a prepared ``<camera>_depth.npz`` (0 = no return)."""
    path = Path(path)
    try:
        with np.load(path) as data:
            return data["depth"].astype(np.float32)
    except (OSError, KeyError, ValueError) as exc:
        raise ValueError(f"{path}: not a prepared depth file ({type(exc).__name__}: {exc})") from exc


def ego_speed(poses: np.ndarray, fps: float) -> np.ndarray:
    """Per-frame ego speed (m/s) from (T, 4, 4) T_world_vehicle: central differences, one-sided at the ends."""
    pos = np.asarray(poses)[:, :3, 3]
    if len(pos) < 2:
        return np.zeros(len(pos))
    return np.linalg.norm(np.gradient(pos, axis=0), axis=1) * float(fps)


def relative_transform(T_vehicle_target: np.ndarray, T_vehicle_source: np.ndarray) -> np.ndarray:
    """Points of the target camera -> source camera: inv(T_vehicle_source) @ T_vehicle_target."""
    return np.linalg.inv(np.asarray(T_vehicle_source, float)) @ np.asarray(T_vehicle_target, float)


def load_sequence(camera_npz: str | Path, *, scene_dir: str | Path | None = None, stereo_npz: str | Path | None = None,
                  reversed_order: bool = False, camera: str = "cam_front", stereo_camera: str = "cam_front_right",
                  name: str | None = None, stereo_baseline: float | None = None) -> Sequence:
    """A ``Sequence`` from a prepared camera file; ``scene_dir`` (the raw scene) supplies the ego poses and,
    with ``stereo_npz``, the stereo extrinsics. ``stereo_baseline`` rescales the stereo translation to that
    length in network units (Monodepth2 trains with 0.1 and multiplies by 5.4 = 0.54 m / 0.1 at evaluation);
    the metric baseline is kept in ``extra["stereo_baseline_m"]``."""
    images, K = read_prepared(camera_npz)
    seq = Sequence(name or str(Path(camera_npz).parent.name), images, K, reversed=reversed_order, camera=camera)
    if scene_dir is not None:
        scene_dir = Path(scene_dir)
        meta = sceneio.read_meta(scene_dir)
        poses = sceneio.read_poses(scene_dir / "ego_poses.txt")
        if len(poses) != len(images):
            raise ValueError(f"{scene_dir}: {len(poses)} ego poses but {len(images)} frames in {camera_npz}")
        seq.speed = ego_speed(poses, meta["fps"])
    if stereo_npz is not None:
        s_images, s_K = read_prepared(stereo_npz)
        if s_images.shape != images.shape:
            raise ValueError(f"{stereo_npz}: stereo images {s_images.shape} differ from {camera_npz} {images.shape}")
        if not np.allclose(s_K, K, rtol=1e-4, atol=1e-3):
            raise ValueError(f"{stereo_npz}: the stereo partner's intrinsics differ from {camera_npz} (not rectified)")
        if scene_dir is None:
            raise ValueError("a stereo partner needs scene_dir for the extrinsics")
        extr = json.loads((Path(scene_dir) / "extrinsics.json").read_text())
        seq.stereo = s_images
        seq.stereo_T = relative_transform(np.array(extr[camera]), np.array(extr[stereo_camera]))
        metric = float(np.linalg.norm(seq.stereo_T[:3, 3]))
        seq.extra["stereo_baseline_m"] = metric
        if stereo_baseline is not None and metric > 0:
            seq.stereo_T[:3, 3] *= float(stereo_baseline) / metric
    return seq


def source_index(seq: Sequence, t: int, source: str) -> int:
    """Frame index of temporal source ``source`` for target frame t (may be out of range)."""
    step = -1 if source == "prev" else 1
    return t - step if seq.reversed else t + step


def sample_sources(seq: Sequence, t: int, sources: Seq[str]) -> dict[str, int] | str:
    """{source: frame index} of a complete sample at frame t, or the reason why there is none."""
    if not 0 <= t < seq.n_frames:
        return f"{seq.name}: frame {t} does not exist ({seq.n_frames} frames)"
    out = {}
    for src in sources:
        if src in TEMPORAL:
            j = source_index(seq, t, src)
            if not 0 <= j < seq.n_frames:
                return f"{seq.name}/{seq.camera} frame {t}: missing neighbour frame {j} ({src})"
            out[src] = j
        elif src == "stereo":
            if seq.stereo is None:
                return f"{seq.name}/{seq.camera} frame {t}: no stereo partner"
            out[src] = t
        else:
            raise KeyError(f"unknown source {src!r} (known: {KNOWN_SOURCES})")
    return out


def training_samples(seqs: Seq[Sequence], sources: Seq[str], min_speed: float = 0.0
                     ) -> tuple[list[tuple[int, int]], dict[str, int]]:
    """Every (sequence index, frame) with a complete sample; frames where the ego vehicle moves slower than
    ``min_speed`` m/s are dropped when temporal sources are used (static frames). Returns the samples and the
    counts of dropped frames by cause (``missing_source``, ``static``)."""
    samples, dropped = [], {"missing_source": 0, "static": 0}
    temporal = any(s in TEMPORAL for s in sources)
    for i, seq in enumerate(seqs):
        for t in range(seq.n_frames):
            if isinstance(sample_sources(seq, t, sources), str):
                dropped["missing_source"] += 1
            elif temporal and min_speed > 0 and seq.speed is not None and seq.speed[t] < min_speed:
                dropped["static"] += 1
            else:
                samples.append((i, t))
    return samples, dropped


def to_tensor(images: np.ndarray) -> torch.Tensor:
    """uint8 (..., H, W, 3) -> float (..., 3, H, W) in [0, 1]."""
    x = torch.from_numpy(np.ascontiguousarray(images)).float().div_(255.0)
    return x.movedim(-1, -3)


def flip_K(K: np.ndarray, width: int) -> np.ndarray:
    """Intrinsics of the horizontally mirrored image (u -> W - 1 - u)."""
    K = np.array(K, dtype=np.float64, copy=True)
    K[0, 2] = width - 1 - K[0, 2]
    return K


def flip_transform(T: np.ndarray) -> np.ndarray:
    """A rigid transform seen in mirrored cameras (x -> -x on both sides): S T S with S = diag(-1, 1, 1, 1)."""
    S = np.diag([-1.0, 1.0, 1.0, 1.0])
    return S @ np.asarray(T, float) @ S


def make_batch(seqs: Seq[Sequence], items: Seq[tuple[int, int]], sources: Seq[str],
               flips: Seq[bool] | None = None) -> dict:
    """The ``pipeline`` batch of the given (sequence, frame) items; every item must be complete
    (``sample_sources``). ``flips[b]`` mirrors item b horizontally (images, K, stereo transform)."""
    flips = list(flips) if flips is not None else [False] * len(items)
    targets, Ks, srcs, stereo_T = [], [], {s: [] for s in sources}, []
    for (i, t), flip in zip(items, flips):
        seq = seqs[i]
        idx = sample_sources(seq, t, sources)
        if isinstance(idx, str):
            raise ValueError(idx)
        f = (lambda a: a[:, ::-1]) if flip else (lambda a: a)
        targets.append(f(seq.images[t]))
        Ks.append(flip_K(seq.K, seq.size[1]) if flip else seq.K)
        for s in sources:
            srcs[s].append(f(seq.stereo[t] if s == "stereo" else seq.images[idx[s]]))
        if "stereo" in sources:
            stereo_T.append(flip_transform(seq.stereo_T) if flip else seq.stereo_T)
    batch = {"target": to_tensor(np.stack(targets)), "K": torch.tensor(np.stack(Ks), dtype=torch.float32),
             "sources": {s: to_tensor(np.stack(v)) for s, v in srcs.items()}}
    if "stereo" in sources:
        batch["transforms"] = {"stereo": torch.tensor(np.stack(stereo_T), dtype=torch.float32)}
    return batch


def eval_sample(seq: Sequence, t: int, sources: Seq[str]) -> dict | str:
    """The batch-of-one test pair of frame t (no flip), or the reason it cannot be built."""
    idx = sample_sources(seq, t, sources)
    if isinstance(idx, str):
        return idx
    return make_batch([seq], [(0, t)], sources)


def resize_sequence(seq: Sequence, size: tuple[int, int]) -> Sequence:
    """The sequence at another input size (H, W): images (and the stereo partner) area-resampled, K rescaled with
    pixel (0, 0) at the centre of the top-left pixel (u' = (u + 0.5) s - 0.5). The same sequence if the size
    already matches. Systems that train at a reduced resolution see their data through this, at training and
    at test time (the prediction is resized to the ground truth by the evaluation)."""
    h, w = int(size[0]), int(size[1])
    if seq.size == (h, w):
        return seq

    def images(a: np.ndarray) -> np.ndarray:
        x = torch.nn.functional.interpolate(to_tensor(a), size=(h, w), mode="area")
        return (x.movedim(-3, -1) * 255.0).round().clamp(0, 255).to(torch.uint8).numpy()

    sy, sx = h / seq.size[0], w / seq.size[1]
    K = np.array(seq.K, dtype=np.float64, copy=True)
    K[0] *= sx
    K[1] *= sy
    K[0, 2] += 0.5 * sx - 0.5
    K[1, 2] += 0.5 * sy - 0.5
    return Sequence(seq.name, images(seq.images), K, None if seq.stereo is None else images(seq.stereo),
                    seq.stereo_T, seq.speed, seq.reversed, seq.camera, dict(seq.extra))
