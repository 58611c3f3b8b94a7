"""Prepared sequences as samples, checkpoints and the training loop (hand-made sequences, tiny networks)."""
import numpy as np
import pytest
import torch

from redsup.depth import checkpoint, data, networks, pipeline, training

torch.set_num_threads(1)
H, W = 32, 64
K = np.array([[40.0, 0.0, 31.5], [0.0, 40.0, 15.5], [0.0, 0.0, 1.0]])


def _seq(n=5, name="test_000", **kw):
    rng = np.random.default_rng(0)
    images = rng.integers(0, 255, size=(n, H, W, 3), dtype=np.uint8)
    return data.Sequence(name, images, K.copy(), **kw)


def test_missing_neighbour_is_a_reason_not_a_crash():
    seq = _seq(5)
    assert data.sample_sources(seq, 2, ["prev", "next"]) == {"prev": 1, "next": 3}
    first = data.sample_sources(seq, 0, ["prev", "next"])
    assert isinstance(first, str) and "missing neighbour frame -1" in first
    last = data.eval_sample(seq, 4, ["prev", "next"])
    assert isinstance(last, str) and "missing neighbour frame 5" in last
    assert "no stereo partner" in data.sample_sources(seq, 2, ["stereo"])
    assert "does not exist" in data.sample_sources(seq, 7, ["prev"])
    with pytest.raises(KeyError, match="left"):
        data.sample_sources(seq, 2, ["left"])


def test_reversed_sequence_swaps_the_temporal_neighbours():
    seq = _seq(5, reversed=True, camera="cam_back")
    assert data.sample_sources(seq, 2, ["prev", "next"]) == {"prev": 3, "next": 1}
    assert isinstance(data.sample_sources(seq, 4, ["prev"]), str)  # prev of the last frame is frame 5


def test_training_samples_drop_static_and_incomplete_frames():
    speed = np.array([0.0, 0.1, 2.0, 3.0, 0.0, 5.0])
    seq = _seq(6, speed=speed)
    samples, dropped = data.training_samples([seq], ["prev", "next"], min_speed=0.5)
    assert samples == [(0, 2), (0, 3)] and dropped == {"missing_source": 2, "static": 2}
    stereo = _seq(6, speed=speed, stereo=np.zeros((6, H, W, 3), np.uint8), stereo_T=np.eye(4))
    samples, dropped = data.training_samples([stereo], ["stereo"], min_speed=0.5)  # no temporal source
    assert len(samples) == 6 and dropped == {"missing_source": 0, "static": 0}


def test_ego_speed_and_relative_transform():
    poses = np.tile(np.eye(4), (4, 1, 1))
    poses[:, 0, 3] = [0.0, 1.0, 2.0, 4.0]
    assert np.allclose(data.ego_speed(poses, fps=10.0), [10.0, 10.0, 15.0, 20.0])
    left, right = np.eye(4), np.eye(4)
    left[:3, 3], right[:3, 3] = [1.6, 0.0, 1.65], [1.6, -0.54, 1.65]
    # both cameras look along vehicle x; camera x (right) = -vehicle y
    R = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, -1.0], [1.0, 0.0, 0.0]]).T  # camera -> vehicle
    left[:3, :3] = right[:3, :3] = R
    T = data.relative_transform(left, right)  # points of the left camera in the right camera
    assert np.allclose(T[:3, 3], [-0.54, 0.0, 0.0]) and np.allclose(T[:3, :3], np.eye(3))


def test_make_batch_flip_mirrors_image_intrinsics_and_baseline():
    stereo_T = np.eye(4)
    stereo_T[0, 3] = -0.54
    seq = _seq(3, stereo=np.zeros((3, H, W, 3), np.uint8), stereo_T=stereo_T)
    plain = data.make_batch([seq], [(0, 1)], ["prev", "next", "stereo"])
    flipped = data.make_batch([seq], [(0, 1)], ["prev", "next", "stereo"], flips=[True])
    assert plain["target"].shape == (1, 3, H, W) and plain["target"].max() <= 1.0
    assert torch.equal(flipped["target"], plain["target"].flip(-1))
    assert torch.equal(flipped["sources"]["prev"], plain["sources"]["prev"].flip(-1))
    assert flipped["K"][0, 0, 2].item() == pytest.approx(W - 1 - 31.5)
    assert plain["transforms"]["stereo"][0, 0, 3].item() == pytest.approx(-0.54)
    assert flipped["transforms"]["stereo"][0, 0, 3].item() == pytest.approx(0.54)
    with pytest.raises(ValueError, match="missing neighbour"):
        data.make_batch([seq], [(0, 0)], ["prev"])


def test_checkpoint_roundtrip(tmp_path):
    torch.manual_seed(0)
    models = networks.build_models(8)
    meta = {"base_channels": 8, "num_scales": 4, "height": H, "width": W, "min_depth": 0.1, "max_depth": 100.0,
            "mode": "M", "sources": ["prev", "next"], "train": {"steps": 1}}
    path = tmp_path / "m" / "M.pt"
    checkpoint.save(path, models, meta)
    assert path.exists() and not list(path.parent.glob("M.pt*.part"))
    loaded, meta2 = checkpoint.load(path)
    assert meta2 == meta and not loaded["depth_encoder"].training
    x = torch.rand(1, 3, H, W)
    models.eval()
    with torch.no_grad():
        assert torch.equal(pipeline.predict_depth(models, x), pipeline.predict_depth(loaded, x))
    with pytest.raises(ValueError, match="lacks"):
        checkpoint.save(tmp_path / "bad.pt", models, {"mode": "M"})
    (tmp_path / "junk.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match="junk.pt"):
        checkpoint.load(tmp_path / "junk.pt")


def test_batches_cover_every_sample_each_epoch():
    rng = np.random.default_rng(0)
    out = np.concatenate(list(training.batches(5, 2, 5, rng)))
    assert sorted(out[:5].tolist()) == [0, 1, 2, 3, 4] and len(out) == 10
    with pytest.raises(ValueError):
        next(training.batches(0, 2, 1, rng))


def test_train_runs_logs_and_decays():
    seq = _seq(6, speed=np.full(6, 5.0))
    models = networks.build_models(8)
    seen = []
    summary = training.train(models, [seq], ["prev", "next"], steps=4, batch_size=2, lr=1e-3, decay_at=0.5,
                             loss_kwargs={"noise_std": 0.0}, callback=lambda s, t: seen.append((s, t["lr"], t["loss"])))
    assert [s for s, _, _ in seen] == [1, 2, 3, 4]
    assert [lr for _, lr, _ in seen] == pytest.approx([1e-3, 1e-3, 1e-4, 1e-4])
    assert all(np.isfinite(loss) for _, _, loss in seen)
    assert summary["samples"] == 4 and summary["dropped_missing_source"] == 2 and summary["static_fallback"] == 0
    assert not models["depth_encoder"].training
    static = _seq(6, speed=np.zeros(6))  # every frame static: trained anyway, and said so
    assert training.train(networks.build_models(8), [static], ["prev", "next"], steps=1, batch_size=2, lr=1e-4,
                          min_speed=0.5, loss_kwargs={"noise_std": 0.0})["static_fallback"] == 1
    with pytest.raises(ValueError, match="no complete training sample"):
        training.train(networks.build_models(8), [_seq(1)], ["prev"], steps=1, batch_size=1, lr=1e-4)


def test_automask_after_keeps_every_pixel_in_the_loss_first():
    """automask_after = 2: the kept-pixel fraction is exactly 1 in steps 1-2 (no auto-masking), and the identity
    reprojection masks pixels from step 3 on (random frames: the warp is no better than no warp for many)."""
    seq = _seq(6, speed=np.full(6, 5.0))
    seen = []
    training.train(networks.build_models(8), [seq], ["prev", "next"], steps=4, batch_size=2, lr=1e-3,
                   loss_kwargs={"noise_std": 0.0}, automask_after=2,
                   callback=lambda s, t: seen.append(t["automask_fraction"]))
    assert seen[:2] == [1.0, 1.0]
    assert all(f < 1.0 for f in seen[2:])
    with pytest.raises(ValueError, match="Monodepth2 loss only"):
        training.train(networks.build_models(8), [seq], ["prev", "next"], steps=1, batch_size=2, lr=1e-3,
                       automask_after=1, criterion=lambda m, b, s: {"loss": torch.zeros(())})


def _scene(tmp_path, n=4):
    import json

    scene = tmp_path / "raw" / "train_000"
    scene.mkdir(parents=True)
    (scene / "scene.json").write_text(json.dumps({"scene": "train_000", "n_frames": n, "fps": 10.0,
                                                 "cameras": ["cam_front", "cam_front_right"], "lidars": []}))
    poses = np.tile(np.eye(4)[:3].reshape(1, 12), (n, 1))
    poses[:, 3] = np.arange(n)  # 1 m per frame along x: 10 m/s
    np.savetxt(scene / "ego_poses.txt", poses)
    R = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # camera -> vehicle
    left, right = np.eye(4), np.eye(4)
    left[:3, :3] = right[:3, :3] = R
    left[:3, 3], right[:3, 3] = [1.6, 0.0, 1.65], [1.6, -0.54, 1.65]
    (scene / "extrinsics.json").write_text(json.dumps({"cam_front": left.tolist(), "cam_front_right": right.tolist()}))
    rng = np.random.default_rng(0)
    for cam in ("cam_front", "cam_front_right"):
        np.savez(tmp_path / f"{cam}.npz", images=rng.integers(0, 255, (n, H, W, 3), dtype=np.uint8), K=K)
    return scene


def test_load_sequence_speed_and_stereo_baseline_units(tmp_path):
    scene = _scene(tmp_path)
    seq = data.load_sequence(tmp_path / "cam_front.npz", scene_dir=scene, stereo_npz=tmp_path / "cam_front_right.npz")
    assert np.allclose(seq.speed, 10.0) and np.allclose(seq.stereo_T[:3, 3], [-0.54, 0.0, 0.0])
    units = data.load_sequence(tmp_path / "cam_front.npz", scene_dir=scene,
                               stereo_npz=tmp_path / "cam_front_right.npz", stereo_baseline=0.1)
    assert np.allclose(units.stereo_T[:3, 3], [-0.1, 0.0, 0.0])
    assert units.extra["stereo_baseline_m"] == pytest.approx(0.54)
    np.savez(tmp_path / "short.npz", images=np.zeros((3, H, W, 3), np.uint8), K=K)
    with pytest.raises(ValueError, match="4 ego poses but 3 frames"):
        data.load_sequence(tmp_path / "short.npz", scene_dir=scene)
    (tmp_path / "broken.npz").write_bytes(b"nope")
    with pytest.raises(ValueError, match="broken.npz"):
        data.read_prepared(tmp_path / "broken.npz")
