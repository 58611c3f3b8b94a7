"""The depth systems as components: the trainer takes a criterion, validation passes select the best epoch,
checkpoints rebuild each system, reduced input sizes and the FPS column."""
import numpy as np
import pytest
import torch

from redsup.depth import checkpoint, data, experiments, featdepth, losses, manydepth, networks, systems, training
from redsup.depth import tables as depth_tables
from redsup.depth.configs import EvalSpec, Row, train_settings

torch.set_num_threads(1)


def _seq(n=6, h=32, w=48, seed=0):
    rng = np.random.default_rng(seed)
    base = rng.integers(0, 255, size=(h, w + 2 * n, 3), dtype=np.uint8)
    images = np.stack([base[:, i:i + w] for i in range(n)])
    K = np.array([[30.0, 0.0, (w - 1) / 2], [0.0, 30.0, (h - 1) / 2], [0.0, 0.0, 1.0]])
    return data.Sequence("train_000", images, K)


def test_resize_sequence_pixel_centre_intrinsics_and_area_images():
    seq = _seq(2, 32, 48)
    small = data.resize_sequence(seq, (16, 24))
    assert small.images.shape == (2, 16, 24, 3) and small.images.dtype == np.uint8
    # u' = (u + 0.5) / 2 - 0.5: cx 23.5 -> 11.5, f 30 -> 15
    assert small.K[0, 0] == pytest.approx(15.0) and small.K[0, 2] == pytest.approx(11.5)
    assert small.K[1, 2] == pytest.approx(7.5)
    block = seq.images[0, :2, :2].astype(float).mean(axis=(0, 1))
    assert np.allclose(small.images[0, 0, 0], np.round(block), atol=1)
    assert data.resize_sequence(seq, (32, 48)) is seq


def test_trainer_takes_the_criterion_and_keeps_the_best_validation_pass():
    torch.manual_seed(0)
    models = manydepth.build_models(base_channels=4, n_bins=4)
    crit = manydepth.ManydepthLoss(generator=torch.Generator().manual_seed(0), noise_std=0.0)
    scores = {2: 0.5, 4: 0.3, 6: 0.4}  # the second pass is the best
    states = {}

    def validate(step):
        states[step] = {k: v.clone() for k, v in models["depth_decoder"].state_dict().items()}
        return {"abs_rel": scores[step], "rmse": 1.0}

    calls = []
    summary = training.train(models, [_seq()], ["prev", "next"], steps=6, batch_size=2, lr=1e-3, seed=0,
                             criterion=lambda m, b, step: (calls.append(step), crit(m, b, step))[1],
                             validate=validate, validate_every=2)
    assert calls == [1, 2, 3, 4, 5, 6]  # the criterion sees the step (Manydepth's freeze)
    assert summary["best_step"] == 4 and summary["best_val_abs_rel"] == pytest.approx(0.3)
    assert [h["step"] for h in summary["validation"]] == [2, 4, 6]
    assert all("train_loss" in h and "train_consistency" in h for h in summary["validation"])
    restored = models["depth_decoder"].state_dict()
    assert all(torch.equal(restored[k], states[4][k]) for k in restored)
    assert not all(torch.equal(restored[k], states[6][k]) for k in restored)


def test_decay_at_several_fractions():
    torch.manual_seed(0)
    lrs = []
    training.train(featdepth.build_models(base_channels=4), [_seq()], ["prev", "next"], steps=4, batch_size=2,
                   lr=1e-3, decay_at=[0.25, 0.5], gamma=0.5, seed=0,
                   criterion=featdepth.FeatDepthLoss(noise_std=0.0), callback=lambda s, t: lrs.append(t["lr"]))
    assert lrs == pytest.approx([1e-3, 5e-4, 2.5e-4, 2.5e-4])
    lrs.clear()                                   # decay_at 1: after every step, i.e. never
    training.train(featdepth.build_models(base_channels=4), [_seq()], ["prev", "next"], steps=3, batch_size=2,
                   lr=1e-3, decay_at=1.0, gamma=0.5, seed=0,
                   criterion=featdepth.FeatDepthLoss(noise_std=0.0), callback=lambda s, t: lrs.append(t["lr"]))
    assert lrs == pytest.approx([1e-3, 1e-3, 1e-3])


@pytest.mark.parametrize("system", ["manydepth", "featdepth", "monodepth2"])
def test_checkpoint_rebuilds_each_system(tmp_path, system):
    meta = {"system": system, "base_channels": 4, "num_scales": 4, "height": 32, "width": 48, "min_depth": 0.1,
            "max_depth": 100.0, "mode": "X", "n_bins": 4}
    torch.manual_seed(0)
    models = systems.build(meta)
    if system == "manydepth":
        models["depth_range"].update(torch.full((1, 1, 4, 4), 3.0))
    checkpoint.save(tmp_path / "m.pt", models, meta)
    loaded, meta2 = checkpoint.load(tmp_path / "m.pt")
    assert set(loaded) == set(models)
    seq = _seq(3)
    batch = experiments.prediction_batch(seq, 1, meta2)
    assert ("prev" in batch) == (system == "manydepth")
    d = experiments.predict_frame(loaded, batch, meta2)
    ref = systems.predict_depth(models.eval(), meta, batch["target"], batch.get("prev"), batch["K"])
    assert d.shape == (32, 48) and np.allclose(d, ref[0, 0].numpy(), rtol=1e-5)
    if system == "manydepth":
        assert loaded["depth_range"].d_min.item() == pytest.approx(models["depth_range"].d_min.item())
        teacher = experiments.predict_frame(loaded, experiments.prediction_batch(seq, 1, meta2, "teacher"), meta2,
                                            "teacher")
        assert not np.allclose(teacher, d)
    else:
        with pytest.raises(ValueError, match="branch"):
            systems.predict_depth(loaded, meta2, batch["target"], branch="teacher")


def test_multi_frame_predict_sequence_uses_the_previous_frame():
    torch.manual_seed(0)
    meta = {"system": "manydepth", "min_depth": 0.1, "max_depth": 100.0}
    models = manydepth.build_models(base_channels=4, n_bins=4).eval()
    seq = _seq(4)
    out = experiments.predict_sequence(models, seq.images, meta, batch_size=3, K=seq.K)
    for t in range(4):
        ref = experiments.predict_frame(models, experiments.prediction_batch(seq, t, meta), meta)
        assert np.allclose(out[t], ref, rtol=1e-4)
    with pytest.raises(ValueError, match="intrinsics"):
        experiments.predict_sequence(models, seq.images, meta)


def test_fps_column_is_one_over_the_mean_seconds():
    rec = [{"sequence": "s", "frame": f, "step": 0, "seconds": s, "metrics": {"abs_rel": 0.1, "sq_rel": 0.1,
            "rmse": 1.0, "rmse_log": 0.1, "a1": 0.9, "a2": 0.95, "a3": 0.99}} for f, s in enumerate([0.02, 0.03])]
    row = Row("Manydepth", EvalSpec("instance", "d/MD", "d/test", "all"))
    df, _, _ = depth_tables.table_frame([row], [{"records": rec}], fps_column="FPS")
    assert df.at["Manydepth", "FPS"] == pytest.approx(40.0)


def test_train_settings_override_per_system():
    cfg = {"model": {"base_channels": 16, "num_scales": 4, "min_depth": 0.1, "max_depth": 100.0,
                     "init_disparity": None},
           "train": {"steps": 600, "batch_size": 4, "lr": 1e-4, "decay_at": 0.75, "gamma": 0.1},
           "modes": {"MD": {"sources": ["prev", "next"], "cameras": ["cam_front"], "system": "manydepth"},
                     "M": {"sources": ["prev", "next"], "cameras": ["cam_front"]}},
           "systems": {"manydepth": {"base_channels": 8, "n_bins": 16, "steps": 300, "epochs": 20}},
           "models": [{"dataset": "d", "mode": "MD", "steps": 50}]}
    model, train = train_settings(cfg, "d", "MD")
    assert model["system"] == "manydepth" and model["base_channels"] == 8 and model["n_bins"] == 16
    assert train["steps"] == 50 and train["epochs"] == 20 and train["batch_size"] == 4
    model, train = train_settings(cfg, "d", "M")
    assert model["system"] == "monodepth2" and model["base_channels"] == 16 and train["epochs"] == 0
    assert systems.input_size((64, 208), 0.5) == (32, 104)
    assert isinstance(systems.build({**model, "height": 1, "width": 1, "mode": "M"})["depth_encoder"],
                      networks.ResNetEncoder)


def test_systems_start_auto_masking_at_a_fraction_of_their_steps():
    """depth.systems.<system>.automask_at is a fraction of the model's steps (so the paper profile's 20000 steps
    keep the same schedule); a mode's automask_after (steps) overrides it; without either it is 0."""
    cfg = {"model": {"base_channels": 16, "num_scales": 4, "min_depth": 0.1, "max_depth": 100.0},
           "train": {"steps": 600, "batch_size": 4, "lr": 1e-4, "decay_at": 0.75, "gamma": 0.1},
           "modes": {"MD": {"sources": ["prev", "next"], "cameras": ["cam_front"], "system": "manydepth"},
                     "FD": {"sources": ["prev", "next"], "cameras": ["cam_front"], "system": "featdepth",
                            "automask_after": 7},
                     "M": {"sources": ["prev", "next"], "cameras": ["cam_front"]}},
           "systems": {"manydepth": {"steps": 300, "automask_at": 0.333}, "featdepth": {"automask_at": 0.5}},
           "models": [{"dataset": "b", "mode": "MD", "steps": 30}]}
    assert train_settings(cfg, "a", "MD")[1]["automask_after"] == 100        # round(0.333 x 300)
    assert train_settings(cfg, "b", "MD")[1]["automask_after"] == 10         # round(0.333 x 30)
    assert train_settings(cfg, "a", "FD")[1]["automask_after"] == 7          # the mode's steps win
    assert train_settings(cfg, "a", "M")[1]["automask_after"] == 0


def test_system_criteria_keep_every_pixel_until_auto_masking_starts():
    """Each system's criterion passes automasking=False to its Monodepth2 losses up to step automask_after, so
    every pixel is in the loss (Feature Depth's automask_fraction is then exactly 1; Manydepth's multi-frame
    fraction is its reliable share, 1 - unreliable_fraction); auto-masking drops pixels from the next step on."""
    assert losses.masking_at({"automasking": True, "alpha": 0.85}, 3, 3) == {"automasking": False, "alpha": 0.85}
    assert losses.masking_at({"automasking": True, "alpha": 0.85}, 4, 3) == {"automasking": True, "alpha": 0.85}
    assert losses.masking_at({"automasking": True}, 1, 0) == {"automasking": True}
    torch.manual_seed(0)
    g = torch.Generator().manual_seed(1)
    b, h, w = 2, 32, 48
    K = torch.tensor([[40.0, 0.0, 23.5], [0.0, 40.0, 15.5], [0.0, 0.0, 1.0]]).expand(b, 3, 3).clone()
    prev = torch.rand(b, 3, h, w, generator=g)
    batch = {"target": prev.clone(), "K": K, "sources": {"prev": prev, "next": torch.rand(b, 3, h, w, generator=g)}}
    batch["target"][:, :, :, : w // 2] = torch.rand(b, 3, h, w // 2, generator=g)   # half the image is static
    meta = {"system": "featdepth", "alpha": 1e-3, "beta": 1e-3, "feature_weight": 1.0}
    crit = systems.criterion(meta, {"automasking": True, "noise_std": 0.0}, 10, 0, automask_after=2)
    models = featdepth.build_models(base_channels=4)
    with torch.no_grad():
        fractions = [crit(models, batch, step)["automask_fraction"].item() for step in (1, 2, 3)]
    assert fractions[0] == fractions[1] == 1.0
    assert fractions[2] < 0.9           # the static half (target == prev: identity error 0) is masked out
    meta = {"system": "manydepth", "freeze_at": None, "static_prob": 0.0, "zero_prob": 0.0, "consistency_weight": 1.0}
    crit = systems.criterion(meta, {"automasking": True, "noise_std": 0.0}, 10, 0, automask_after=1)
    models = manydepth.build_models(base_channels=4, n_bins=4)
    with torch.no_grad():
        first, second = crit(models, batch, 1), crit(models, batch, 2)
    assert first["automask_fraction"].item() == pytest.approx(1.0 - first["unreliable_fraction"].item(), abs=1e-6)
    assert second["automask_fraction"].item() < 1.0 - second["unreliable_fraction"].item() - 0.1


def test_train_settings_mode_recipe_between_base_and_model_entry():
    """A mode's input_scale / steps / lr / decay_at override depth.model / depth.train; a models entry's steps
    override the mode's."""
    cfg = {"model": {"base_channels": 16, "num_scales": 4, "min_depth": 0.1, "max_depth": 100.0},
           "train": {"steps": 600, "batch_size": 4, "lr": 1e-4, "decay_at": 0.75, "gamma": 0.1},
           "modes": {"M": {"sources": ["prev", "next"], "cameras": ["cam_front"], "input_scale": 0.5, "steps": 2400,
                           "lr": 3e-4},
                     "S": {"sources": ["stereo"], "cameras": ["cam_front"]}},
           "models": [{"dataset": "a", "mode": "M"}, {"dataset": "b", "mode": "M", "steps": 30},
                      {"dataset": "a", "mode": "S"}]}
    model, train = train_settings(cfg, "a", "M")
    assert model["input_scale"] == 0.5 and train["steps"] == 2400 and train["lr"] == 3e-4
    assert train["decay_at"] == 0.75 and train["batch_size"] == 4
    assert train_settings(cfg, "b", "M")[1]["steps"] == 30
    model, train = train_settings(cfg, "a", "S")
    assert model.get("input_scale", 1.0) == 1.0 and train["steps"] == 600 and train["lr"] == 1e-4
    assert train["decay_at"] == 0.75
    cfg["modes"]["M"]["decay_at"] = 1.0        # never: lr stays 3e-4 for all 2400 steps
    assert train_settings(cfg, "a", "M")[1]["decay_at"] == 1.0


def test_a_mode_may_select_its_best_validation_pass():
    """depth.modes.<mode>.epochs: validation passes (best kept) for a Monodepth2 mode, and over its system's
    epochs; the training job then reads the val scenes' images and LiDAR depth, a mode without passes does not."""
    from redsup.depth.configs import train_inputs

    cfg = {"model": {"base_channels": 16, "num_scales": 4, "min_depth": 0.1, "max_depth": 100.0},
           "train": {"steps": 600, "batch_size": 4, "lr": 1e-4, "decay_at": 0.75, "gamma": 0.1},
           "modes": {"M": {"sources": ["prev", "next"], "cameras": ["cam_front"], "epochs": 12},
                     "S": {"sources": ["stereo"], "cameras": ["cam_front"]},
                     "MD": {"sources": ["prev", "next"], "cameras": ["cam_front"], "system": "manydepth", "epochs": 0},
                     "MD2": {"sources": ["prev", "next"], "cameras": ["cam_front"], "system": "manydepth"}},
           "systems": {"manydepth": {"epochs": 20}},
           "eval": {"camera": "cam_front"},
           "models": []}
    assert [train_settings(cfg, "a", m)[1]["epochs"] for m in ("M", "S", "MD", "MD2")] == [12, 0, 0, 20]
    scenes = ["train_000", "val_000", "test_000"]
    files = train_inputs({"depth": cfg}, "a", "M", scenes)
    assert files["scenes"] == ["results/raw/a/train_000"]
    assert files["val_images"] == ["results/prepared/a/val_000/cam_front.npz"]
    assert files["val_gt"] == ["results/prepared/a/val_000/cam_front_depth.npz"]
    assert "val_images" not in train_inputs({"depth": cfg}, "a", "S", scenes)
    assert "val_images" not in train_inputs({"depth": cfg}, "a", "M", ["train_000", "test_000"])


def test_figures_draw_without_validation_history(tmp_path):
    from redsup.depth import galteland_figures as gf

    history = [{"step": s, "train_loss": 0.1 / s, "abs_rel": 0.3, "sq_rel": 2.0, "rmse": 7.0, "rmse_log": 0.5,
                "a1": 0.3, "a2": 0.6, "a3": 0.8} for s in (2, 4)]
    assert list(gf.epoch_table(history)["step"]) == [2, 4]
    for runs in ([("a", history, 4)], [("a", [], 4)]):  # no val scenes: an annotated, empty figure
        gf.progression(runs, "t").savefig(tmp_path / "f.png")
        assert (tmp_path / "f.png").stat().st_size > 1000
    assert gf.qualitative_frames(30, 3) == [1, 15, 29] and gf.qualitative_frames(1, 3) == [0]
    specs = {"a": {"kind": "progression", "models": ["d/MD"]},
             "b": {"kind": "qualitative", "models": ["d/MD"], "test": "e"}}
    assert gf.available_figures(specs, ["d/MD"], {"e": 0}) == ["a"]


def test_progression_figure_reads_the_json_sidecar_without_torch(tmp_path):
    """The progression figures read a model's meta from the JSON beside its checkpoint; a missing or foreign
    file is named in the error; the labels are the spec's or "<system> (<dataset's display name>)"."""
    import json
    import subprocess
    import sys

    from redsup.depth import galteland_figures as gf

    history = [{"step": s, "train_loss": 1.0 / s, "abs_rel": 0.3 - 0.01 * s} for s in (2, 4)]
    side = tmp_path / "MD.json"
    side.write_text(json.dumps({"meta": {"system": "manydepth", "dataset": "world_kitti", "validation": history,
                                         "best_step": 4}, "config": {"profile": "tiny"}}))
    assert gf.read_sidecar(str(side))["best_step"] == 4
    assert gf.figure_labels({}, [gf.read_sidecar(str(side))], {"world_kitti": "KITTI-like"}) == [
        "Manydepth (KITTI-like)"]
    assert gf.figure_labels({"labels": ["x"]}, [{}]) == ["x"]
    (tmp_path / "bad.json").write_text("{}")
    with pytest.raises(ValueError, match="bad.json: not a depth model sidecar"):
        gf.read_sidecar(str(tmp_path / "bad.json"))
    script = ("import sys; from redsup.depth import galteland_figures as gf; "
              f"gf.draw({{'kind': 'progression', 'models': ['d/MD']}}, [{str(side)!r}]).savefig({str(tmp_path / 'p.png')!r}); "
              "print('torch' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "False" and (tmp_path / "p.png").stat().st_size > 1000


def test_the_caption_names_where_a_system_departs_from_the_thesis():
    """The Galteland captions' recipe line states Feature Depth's feature-metric weight against eq. 3.22's 1 and the
    auto-masking schedule, and says nothing of either for a system that keeps the defaults."""
    from redsup.depth.plan import _system_recipe
    cfg = {"depth": {"model": {"base_channels": 16}, "train": {"steps": 600, "batch_size": 4},
                     "systems": {"featdepth": {"feature_weight": 1e-3, "automask_at": 0.333, "steps": 300},
                                 "manydepth": {"n_bins": 32, "automask_at": 0.0}}}}
    fd, md = _system_recipe(cfg, "featdepth"), _system_recipe(cfg, "manydepth")
    assert "feature-metric loss x 0.001 (the thesis' eq. 3.22: x 1)" in fd
    assert "auto-masking after the first 33% of the steps" in fd and "300 steps of batch 4" in fd
    assert "auto-masking" not in md and "feature-metric" not in md and "32 cost-volume bins" in md
