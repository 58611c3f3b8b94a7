"""The stand-in detector's confidence (issue 11 §3 "Detector confidence"): a logistic function of what a
detector can see and of a latent quality, never of the IoU with the true instance. Its rank correlation with
the true mask IoU, measured on rendered world scenes, is clearly positive and below 1."""
import copy
from pathlib import Path

import numpy as np
import pytest
from scipy.stats import spearmanr

from redsup import config
from redsup.prep.detections import detect_scene
from redsup.prep.detector import KIND_FALSE_POSITIVE, fault_scale, score_of
from redsup.world.generate import write_scene

ROOT = Path(__file__).resolve().parents[1]
LEVEL = {"score_bias": 1.0, "score_size_px": 400, "score_size_gain": 0.5, "score_visibility_gain": 2.0,
         "score_latent_gain": 1.5, "score_noise": 0.0}


def test_score_by_hand():
    rng = np.random.default_rng(0)
    # 1600 px = 4 x the reference at scale 1: logit = 1 + 0.5 * 2 + 2 * (0.5 - 1) + 1.5 * 0.4 = 1.6
    assert score_of(1600, 0.5, 0.4, LEVEL, rng) == pytest.approx(1 / (1 + np.exp(-1.6)))
    # at half the image height the reference size is a quarter: 400 px is then 4 x the reference
    assert score_of(400, 0.5, 0.4, LEVEL, rng, scale=0.5) == pytest.approx(1 / (1 + np.exp(-1.6)))
    assert score_of(1600, 0.5, 0.4, LEVEL, rng, offset=-1.6) == pytest.approx(0.5)
    assert score_of(10 ** 9, 1.0, 10.0, LEVEL, rng) == 0.999  # clipped
    noisy = {**LEVEL, "score_noise": 1.0}
    draws = [score_of(400, 1.0, 0.0, noisy, np.random.default_rng(k)) for k in range(400)]
    logits = np.log(np.array(draws) / (1 - np.array(draws)))
    assert np.mean(logits) == pytest.approx(1.0, abs=0.15) and np.std(logits) == pytest.approx(1.0, abs=0.1)


def test_fault_scale_has_mean_one_and_falls_with_quality():
    u = np.random.default_rng(0).standard_normal(200000)
    assert np.mean([fault_scale(x, 0.8) for x in u[:20000]]) == pytest.approx(1.0, abs=0.03)
    assert fault_scale(1.0, 0.8) < 1.0 < fault_scale(-1.0, 0.8)
    assert fault_scale(2.0, 0.0) == 1.0


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    """Three rendered kitti_like training scenes of 3 frames (the tiny profile's size)."""
    cfg = config.load(ROOT / "config.yaml", {"profile": "tiny"})
    world = copy.deepcopy(cfg["world"])
    world["frames"] = {"train": 3, "test": 3, "long": 3}
    world["lidar"]["azimuth_steps"] = 256
    root = tmp_path_factory.mktemp("score_world")
    scenes = []
    for i in range(3):
        write_scene(world, "world_kitti", "kitti_like", "train", i, 5, root / f"train_{i:03d}")
        scenes.append(root / f"train_{i:03d}")
    return cfg, scenes


@pytest.mark.parametrize("level", ["coco", "cityscapes"])
def test_score_ranks_true_mask_quality_imperfectly_on_the_world(rendered, level):
    """Spearman(score, best IoU with a ground-truth car) over all output detections, false positives
    included. Measured on 6 train scenes x 4 frames (seed 5) while choosing the settings: 0.69 (coco) / 0.71
    (cityscapes); on this sample (3 x 3 frames) 0.67 / 0.80. It must lie in (0.3, 0.95). Detections scoring
    >= 0.8 are nearly all right (IoU >= 0.5), those below 0.6 much less often."""
    cfg, scenes = rendered
    score, iou, kind = [], [], []
    for k, scene in enumerate(scenes):
        arrays, _ = detect_scene(scene, cfg["detection"], level, seed=k)
        score.append(arrays["score"])
        iou.append(arrays["iou_gt"])
        kind.append(arrays["kind"])
    score, iou, kind = np.concatenate(score), np.concatenate(iou), np.concatenate(kind)
    assert len(score) > 40
    rho = spearmanr(score, iou)[0]
    assert 0.3 < rho < 0.95, rho
    hit = iou >= cfg["detection"]["match_iou"]
    high, low = score >= 0.8, score < 0.6
    assert high.sum() > 10 and low.sum() >= 3
    assert hit[high].mean() > 0.9 and hit[low].mean() < hit[high].mean() - 0.2
    if (kind == KIND_FALSE_POSITIVE).any():
        assert score[kind == KIND_FALSE_POSITIVE].mean() < score[kind != KIND_FALSE_POSITIVE].mean()
