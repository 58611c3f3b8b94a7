"""The depth tables' configurations (rows, shared runs) and the evaluation runners on a hand-made sequence."""
import copy
import math

import numpy as np
import pandas as pd
import pytest
import torch
import yaml

from redsup import config as config_mod
from redsup.depth import configs, data, experiments, networks, plan
from redsup.depth import tables as depth_tables
from redsup.depth.configs import EvalSpec, Row

torch.set_num_threads(1)
H, W = 32, 64


@pytest.fixture(scope="module")
def cfg():
    from pathlib import Path

    raw = yaml.safe_load((Path(__file__).resolve().parents[1] / "config.yaml").read_text())
    raw["profile"] = "default"
    return config_mod.resolve(raw)


def _scenes_of(cfg, drop=()):
    """scenes_of as common.smk counts world scenes; ``drop``: (dataset, split) pairs to leave out."""
    def scenes_of(dataset):
        counts = cfg["datasets"][dataset].get("scenes", {})
        return [f"{s}_{i:03d}" for s in ("train", "val", "test", "long") for i in range(counts.get(s, 0))
                if (dataset, s) not in drop]
    return scenes_of


DEPTH_TABLES = [f"mccraith_ch4_table{i}" for i in range(1, 8)] + ["mccraith_ch4_fig4", "mccraith_ch4_fig5"] + [
    f"galteland_table4_{i}" for i in range(1, 5)] + ["galteland_table5_1"]


def test_rows_of_every_table_at_default(cfg):
    rows = plan.table_rows(cfg, _scenes_of(cfg))
    assert set(rows) == set(DEPTH_TABLES)
    t1 = rows["mccraith_ch4_table1"]
    assert len(t1) == 22 and t1[0].label == "baseline [9] (no instance adaptation)" and t1[0].step == 0
    assert t1[1].label == "whole network"
    assert "Depth Encoder (last residual block) + Pose Encoder (last residual block)" in [r.label for r in t1]
    assert [r.label for r in rows["mccraith_ch4_table2"]][:3] == ["baseline", "10^-5", "10^-4"]
    assert [r.label for r in rows["mccraith_ch4_table3"]][:3] == ["Initial", "5", "10"]
    labels = {r.label for r in rows["mccraith_ch4_table5"]}
    assert labels >= {"ours | M", "ours | S", "ours | MS", "Monodepth V2 [9] | S"}
    assert [r.label for r in rows["mccraith_ch4_table7"]] == ["baseline | 0", "Ours | 20", "Ours | 50"]
    # the domain-shift rows: the Cityscapes-like model on the KITTI-like test data (until 2026-12-06 the rows
    # named no test data, so Table 7 tested the model on its own domain and Fig. 5's CS rows asked for the
    # Cityscapes-like long split, which has no scene, and were dropped)
    assert {(r.spec.model, r.spec.data) for r in rows["mccraith_ch4_table7"]} == {("world_cityscapes/M",
                                                                                   "world_kitti/test")}
    f5 = [r for r in rows["mccraith_ch4_fig5"] if r.label.startswith("CS")]
    assert [r.label for r in f5] == [f"CS | {k}" for k in (0, 5, 10, 20, 50)]
    assert {(r.spec.model, r.spec.data) for r in f5} == {("world_cityscapes/M", "world_kitti/long")}
    # no row of the default is dropped for want of data: every configured row has its model and test scenes
    for t in DEPTH_TABLES:
        assert {r.label for r in rows[t]} == {r.label for r in plan.expand_rows(t, cfg["depth"])}, t
    # every Galteland model trains 3 seeds in default: each row once per seed, under one label
    t51 = rows["galteland_table5_1"]
    assert len({r.label for r in t51}) == 9 + 2  # Manydepth 3 x 3 domains, Feature Depth on Lyft and DDAD
    assert len(t51) == 3 * (9 + 2)
    assert {r.spec.model_mode for r in t51} == {"MD", "FD"}
    t44 = [r for r in rows["galteland_table4_4"] if "/seed" not in r.spec.model]
    assert [r.label for r in t44] == ["Front only", "Front+Back"]
    assert [r.spec.model for r in t44] == ["world_lyft/MD", "world_lyft/MD_frontback"]
    assert sorted(r.spec.model for r in rows["galteland_table4_4"] if r.label == "Front only") == [
        "world_lyft/MD", "world_lyft/MD/seed1", "world_lyft/MD/seed2"]
    t41 = [r for r in rows["galteland_table4_1"] if "/seed" not in r.spec.model]
    assert [r.label for r in t41] == ["Manydepth", "Feature Depth", "Manydepth single-frame teacher (ours)"]
    assert [r.spec.branch for r in t41] == ["", "", "teacher"]
    assert t41[2].spec.name == t41[0].spec.name + "_teacher" and t41[0].spec.key() != t41[2].spec.key()
    assert len(rows["galteland_table4_1"]) == 3 * 3
    available, cameras = plan._available(cfg, _scenes_of(cfg))
    assert available["world_kitti"]["val"] == 2
    models = configs.trained_models(cfg["depth"], {d: a["train"] for d, a in available.items()}, cameras)
    assert set(models) == {"world_kitti/M", "world_kitti/S", "world_kitti/MS", "world_cityscapes/M", "world_kitti/MD",
                           "world_kitti/FD", "world_lyft/MD", "world_lyft/MD_frontback", "world_lyft/FD",
                           "world_ddad/MD", "world_ddad/FD", "world_naplab/MD"}


def test_shared_runs(cfg):
    rows = plan.table_rows(cfg, _scenes_of(cfg))
    runs, row_runs = configs.plan(rows, order=list(rows))
    traj = row_runs["mccraith_ch4_table3"][1]  # the 5-step row: the one trajectory
    spec, parent = runs[traj]
    assert parent == "mccraith_ch4_table1" and spec.groups == ("depth_encoder", "pose_encoder")
    # the contract: every table a run serves lists it, and each row names its run and step
    served = plan.runs(cfg, _scenes_of(cfg))[traj]["tables"]
    assert set(served) >= {"mccraith_ch4_table1", "mccraith_ch4_table2", "mccraith_ch4_table3",
                           "mccraith_ch4_table5", "mccraith_ch4_table6"}
    contract_rows = plan.rows(cfg, _scenes_of(cfg))
    assert ("10^-1", traj, 10) in contract_rows["mccraith_ch4_table2"]
    assert set(spec.checkpoints) >= {5, 10, 25, 50, 75, 100, 150, 200}
    t1 = dict(zip([r.label for r in rows["mccraith_ch4_table1"]], row_runs["mccraith_ch4_table1"]))
    assert t1["Depth Encoder + Pose Encoder"] == traj
    # every baseline row reads step 0 of one adaptation run on the same model, data and frames
    base = t1["baseline [9] (no instance adaptation)"]
    assert 0 in runs[base][0].checkpoints and runs[base][0].groups
    assert t1["Depth Decoder"] != traj
    t2 = dict(zip([r.label for r in rows["mccraith_ch4_table2"]], row_runs["mccraith_ch4_table2"]))
    assert t2["10^-1"] == traj and t2["baseline"] == base
    t6 = dict(zip([r.label for r in rows["mccraith_ch4_table6"]], row_runs["mccraith_ch4_table6"]))
    assert t6["Eigen [16] | ours (instance-wise)"] == traj
    assert runs[t6["Odometry | ours (sequence-wise)"]][0].kind == "sequential"
    f5 = dict(zip([r.label for r in rows["mccraith_ch4_fig5"]], row_runs["mccraith_ch4_fig5"]))
    assert f5["K | 50"] == t6["Odometry | ours (instance-wise)"]  # same lr and frames: one run
    g = row_runs["galteland_table4_4"][0]
    assert g in row_runs["galteland_table5_1"]  # Front only = Lyft | Lyft
    # every run is used, names are unique and file-safe
    used = {n for names in row_runs.values() for n in names}
    assert used == set(runs) and all(" " not in n and "/" not in n for n in runs)


def test_tables_shrink_with_missing_data(cfg):
    cfg = copy.deepcopy(cfg)
    cfg["prepare"]["cameras"] = ["cam_front", "cam_back"]  # no stereo partner: no S / MS models
    drop = {("world_ddad", s) for s in ("train", "test", "long")} | {("world_kitti", "long")}
    rows = plan.table_rows(cfg, _scenes_of(cfg, drop))
    assert not rows["mccraith_ch4_fig4"]
    assert not any(r.label.startswith("Odometry") for r in rows["mccraith_ch4_table6"])
    assert {r.label for r in rows["mccraith_ch4_table5"]} == {"ours | M", "Monodepth V2 [9] | M"}
    # Manydepth Lyft / NAP-lab x Lyft / NAP-lab, Feature Depth Lyft; each row once per seed (3 in default)
    assert len({r.label for r in rows["galteland_table5_1"]}) == 4 + 1 and len(rows["galteland_table5_1"]) == 3 * 5


def test_labels():
    assert configs.lr_label(1e-5) == "10^-5" and configs.lr_label(0.1) == "10^-1" and configs.lr_label(10.0) == "10"
    assert configs.groups_label(("pose_encoder", "depth_encoder")) == "Depth Encoder + Pose Encoder"
    assert configs.groups_label(()) == "baseline [9] (no instance adaptation)"


# ------------------------------------------------------------------------------------------ runners
def _eval_seq(n=4, empty_gt_frame=None):
    rng = np.random.default_rng(1)
    base = rng.integers(0, 255, size=(H, W + 8, 3), dtype=np.uint8)
    images = np.stack([base[:, i:i + W] for i in range(n)])  # a sideways pan
    K = np.array([[40.0, 0.0, 31.5], [0.0, 40.0, 15.5], [0.0, 0.0, 1.0]])
    gt = np.zeros((n, 2 * H, 2 * W), np.float32)
    gt[:, 40:60, 10:120] = np.linspace(5.0, 30.0, 110)[None, None]
    if empty_gt_frame is not None:
        gt[empty_gt_frame] = 0.0
    return experiments.EvalSequence(data.Sequence("test_000", images, K), gt)


@pytest.fixture(scope="module")
def model():
    torch.manual_seed(0)
    models = networks.build_models(8).eval()
    meta = {"min_depth": 0.1, "max_depth": 100.0, "sources": ["prev", "next"]}
    return models, meta


EVAL = {"min_depth": 1e-3, "max_depth": 80.0, "crop": "garg"}
LOSS = {"noise_std": 0.0, "min_depth": 0.1, "max_depth": 100.0}


def test_instance_run_checkpoints_and_bad_frames(model):
    models, meta = model
    before = {k: v.clone() for k, v in models.state_dict().items()}
    seq = _eval_seq(4, empty_gt_frame=2)
    frames = [(0, 0), (0, 1), (0, 2)]  # frame 0 has no previous frame, frame 2 no valid ground truth
    records, curve = experiments.run_instance(models, meta, [seq], frames, sources=["prev", "next"],
                                              groups=["depth_encoder", "pose_encoder"], lr=0.1, checkpoints=[0, 2],
                                              eval_cfg=EVAL, loss_kwargs=LOSS, metric_scale=False)
    assert all(torch.equal(before[k], v) for k, v in models.state_dict().items())  # reset afterwards
    by = {(r["frame"], r["step"]): r for r in records}
    assert "missing neighbour frame -1" in by[(0, 0)]["reason"] and "metrics" not in by[(0, 0)]
    assert "no valid ground-truth pixel" in by[(2, 2)]["reason"]
    assert by[(1, 0)]["metrics"]["abs_rel"] != by[(1, 2)]["metrics"]["abs_rel"]
    assert by[(1, 2)]["seconds"] > by[(1, 0)]["seconds"] and len(curve) == 2
    summary = experiments.summarise(records)
    assert summary[2]["n_frames"] == 1 and summary[2]["n_skipped"] == 2 and len(summary[2]["skip_reasons"]) == 2
    assert all(math.isfinite(v) for k, v in summary[2].items() if isinstance(v, float))


def test_sequential_and_direct_runs(model):
    models, meta = model
    seq = _eval_seq(4)
    recs, losses = experiments.run_sequential(models, meta, [seq], sources=["prev", "next"], groups=["depth_encoder"],
                                              lr=0.1, steps=2, eval_cfg=EVAL, loss_kwargs=LOSS, metric_scale=False)
    assert [("metrics" in r) for r in recs] == [False, True, True, False] and len(losses) == 4
    inst, _ = experiments.run_instance(models, meta, [seq], [(0, 1)], sources=["prev", "next"],
                                       groups=["depth_encoder"], lr=0.1, checkpoints=[2], eval_cfg=EVAL,
                                       loss_kwargs=LOSS, metric_scale=False)
    # the first adapted frame of a sequence starts from the trained weights, as instance-wise
    assert recs[1]["metrics"]["abs_rel"] == pytest.approx(inst[0]["metrics"]["abs_rel"], rel=1e-4)
    direct, curve = experiments.run_direct(models, meta, [seq], [(0, 1), (0, 3)], sources=["prev", "next"], lr=1.0,
                                           steps=2, eval_cfg=EVAL, loss_kwargs=LOSS, metric_scale=False)
    assert "metrics" in direct[0] and "missing neighbour" in direct[1]["reason"] and len(curve) == 2


def test_prediction_only_needs_no_pair_and_resizing(model):
    models, meta = model
    seq = _eval_seq(3)
    recs, _ = experiments.run_instance(models, meta, [seq], [(0, 0), (0, 2)], sources=(), groups=(), lr=0.0,
                                       checkpoints=[0], eval_cfg=EVAL, loss_kwargs=LOSS, metric_scale=True)
    assert all("metrics" in r for r in recs) and recs[0]["metrics"]["median_ratio"] == 1.0
    depth = experiments.predict_sequence(models, seq.seq.images, meta)
    assert depth.shape == (3, H, W) and depth.dtype == np.float32
    up = experiments.resize_depth(np.full((H, W), 4.0, np.float32), (2 * H, 2 * W))
    assert up.shape == (2 * H, 2 * W) and np.allclose(up, 4.0)


def test_table_frame_averages_common_frames():
    spec_a = EvalSpec("instance", "d/M", "d/test", "short", ("prev", "next"), ("depth_encoder",), 0.1, 0, (0, 5))
    spec_b = EvalSpec("sequential", "d/M", "d/test", "all", ("prev", "next"), ("depth_encoder",), 0.1, 5)

    def rec(frame, step, value=None, reason=None):
        r = {"sequence": "s", "frame": frame, "step": step, "seconds": 0.5}
        if value is None:
            r["reason"] = reason
        else:
            r["metrics"] = {k: value for k in configs.METRIC_COLUMNS}
        return r

    res_a = {"records": [rec(1, 0, 0.2), rec(3, 0, 0.4), rec(1, 5, 0.1), rec(3, 5, 0.3)]}
    res_b = {"records": [rec(0, 5, reason="missing neighbour"), rec(1, 5, 0.15), rec(2, 5, 0.9), rec(3, 5, 0.25)]}
    rows = [Row("base", spec_a, 0, "g"), Row("inst", spec_a, 5, "g"), Row("seq", spec_b, 5, "g")]
    df, noise, info = depth_tables.table_frame(rows, [res_a, res_a, res_b], time_column="time [s]")
    assert df.loc["base", "Abs Rel"] == pytest.approx(0.3) and df.loc["seq", "Abs Rel"] == pytest.approx(0.2)
    # paired bootstrap over the group's common frames (s/1, s/3): the same units for every row
    assert len({noise[r]["Abs Rel"]["units"] for r in ("base", "inst", "seq")}) == 1
    reps = noise["base"]["Abs Rel"]["values"]
    assert set(np.round(reps, 6)) <= {0.2, 0.3, 0.4}  # means of two draws from {0.2, 0.4}
    inst = np.array(noise["inst"]["Abs Rel"]["values"])
    assert np.allclose(np.array(reps) - inst, 0.1)  # inst is 0.1 better on both frames: every replicate
    assert list(df["frames"]) == [2, 2, 2] and list(df["skipped"]) == [0, 0, 1]
    assert df.loc["inst", "time [s]"] == pytest.approx(0.5) and info["groups"] == {"g": 2}
    assert depth_tables.last_quarter(rows, [res_a, res_a, res_b]) == pytest.approx([0.4, 0.3, 0.25])


def test_stereo_models_use_the_fixed_baseline_factor():
    gt = np.zeros((16, 32), np.float32)
    gt[10:14, 4:28] = 10.0
    pred = np.full((16, 32), 2.0, np.float32)  # network units; x 5.4 (0.54 m / 0.1) = 10.8 m
    stereo = experiments.evaluate_depth(gt, pred, EVAL, 5.4)
    assert stereo.metrics["abs_rel"] == pytest.approx(0.08, rel=1e-4) and stereo.metrics["median_ratio"] == 1.0
    mono = experiments.evaluate_depth(gt, pred, EVAL, False)
    assert mono.metrics["abs_rel"] == pytest.approx(0.0, abs=1e-6) and mono.metrics["scale"] == pytest.approx(5.0)


def test_seed_rows_are_averaged_with_their_spread(cfg):
    """A row whose model has several training seeds shows the seed mean; its noise record holds the seeds."""
    def result(value):
        return {"records": [{"sequence": "s", "frame": f, "step": 0, "seconds": 0.1,
                             "metrics": {k: value + 0.01 * f for k in configs.METRIC_COLUMNS}} for f in range(5)]}

    rows = [("Front only", "a0", 0), ("Front only", "a1", 0), ("Front only", "a2", 0),
            ("Front+Back", "b0", 0), ("Front+Back", "b1", 0), ("Front+Back", "b2", 0)]
    results = {"a0": result(0.20), "a1": result(0.22), "a2": result(0.24),
               "b0": result(0.50), "b1": result(0.40), "b2": result(0.60)}
    frame = plan.table_frame("galteland_table4_4", cfg, rows, results)
    assert frame.ours.at["Front only", "Abs Rel"] == pytest.approx(0.24)  # mean of 0.22, 0.24, 0.26
    assert frame.ours.at["Front+Back", "Abs Rel"] == pytest.approx(0.52)
    rec = frame.noise["Front+Back"]["Abs Rel"]
    assert rec["kind"] == "seeds" and rec["values"] == pytest.approx([0.52, 0.42, 0.62])
    assert "3 seeds" in frame.note
    # the seed mean's test-sampling noise: every seed resamples the same 5 frames the same way, so replicate r of
    # each row is its seed mean's frame offsets resampled, and the two rows differ by 0.52 - 0.24 in every replicate
    other = frame.noise["Front only"]["Abs Rel"]
    assert rec["units"] == other["units"] and len(rec["boot"]) == len(other["boot"]) == 200
    assert np.asarray(rec["boot"]) - np.asarray(other["boot"]) == pytest.approx(np.full(200, 0.28))
    assert min(other["boot"]) >= 0.22 - 1e-9 and max(other["boot"]) <= 0.26 + 1e-9  # 0.22 + 0.01 x (0 .. 4)
    # the seed model ids and their checkpoints
    assert configs.seed_models("world_lyft/M", 3) == ["world_lyft/M", "world_lyft/M/seed1", "world_lyft/M/seed2"]
    assert configs.parse_model("world_lyft/M_frontback/seed2") == ("world_lyft", "M_frontback", 2)
    with pytest.raises(ValueError, match="not a depth model id"):
        configs.parse_model("world_lyft/M/2")
    t44 = plan.rows(cfg, _scenes_of(cfg))["galteland_table4_4"]  # (label, run, step), once per seed of 3
    assert [r[0] for r in t44] == ["Front only"] * 3 + ["Front+Back"] * 3
    assert t44[3][1].startswith("baseline_world_lyft-MD_frontback_on_")
    assert t44[4][1].startswith("baseline_world_lyft-MD_frontback-seed1_on_")
    assert configs.seed_models("world_lyft/MD", 2)[1] == "world_lyft/MD/seed1"


def test_timing_cells_of_seed_rows_hold_the_jobs_spread_only(cfg):
    """An FPS cell of a row with several seeds: the mean of the seeds' FPS, its noise the seeds' values alone
    (unpaired, no test-sampling part), so 2 test scenes (fewer than 5 clusters) still give the timing an interval;
    the metric cells keep their scene-cluster bootstrap."""
    from redsup.tables import noise as noise_lib

    def result(seconds, value):
        return {"records": [{"sequence": f"s{f % 2}", "frame": f, "step": 0, "seconds": seconds,
                             "metrics": {k: value for k in configs.METRIC_COLUMNS}} for f in range(6)]}

    labels = [r.label for r in plan.expand_rows("galteland_table4_2", cfg["depth"])][:2]
    rows = [(labels[0], "a0", 0), (labels[0], "a1", 0), (labels[0], "a2", 0),
            (labels[1], "b0", 0), (labels[1], "b1", 0), (labels[1], "b2", 0)]
    results = {"a0": result(0.010, 0.2), "a1": result(0.011, 0.2), "a2": result(0.012, 0.2),
               "b0": result(0.004, 0.3), "b1": result(0.0045, 0.3), "b2": result(0.005, 0.3)}
    frame = plan.table_frame("galteland_table4_2", cfg, rows, results)
    fps = frame.noise[labels[0]]["FPS"]
    assert fps == {"kind": "seeds", "values": pytest.approx([100.0, 1000 / 11, 1000 / 12])}
    assert frame.ours.at[labels[0], "FPS"] == pytest.approx((100 + 1000 / 11 + 1000 / 12) / 3)
    assert frame.noise[labels[0]]["Abs Rel"]["n_clusters"] == 2          # the metrics: 2 scenes, no verdict
    lo, hi, _ = noise_lib.difference_interval(frame.ours.at[labels[1], "FPS"], frame.ours.at[labels[0], "FPS"],
                                              frame.noise[labels[1]]["FPS"], fps)
    assert 0 < lo < hi                                                     # 224.1 against 91.4 FPS, decided
    assert plan.timing_columns(cfg["depth"]["tables"]["galteland_table4_2"]) == ["FPS"]


def test_a_table_caps_the_seeds_its_rows_read(cfg):
    """world_kitti/M with 3 training seeds: a table without ``seeds`` reads every seed's run (3 rows per label),
    one with ``seeds: 1`` only seed 0's."""
    import copy

    c = copy.deepcopy(cfg)
    c["depth"]["models"] = [dict(m, seeds=3) if (m["dataset"], m["mode"]) == ("world_kitti", "M") else m
                            for m in c["depth"]["models"]]
    c["depth"]["tables"]["mccraith_ch4_table5"].pop("seeds", None)
    c["depth"]["tables"]["mccraith_ch4_table2"]["seeds"] = 1
    rows = plan.rows(c, _scenes_of(c))
    m_rows = [run for label, run, _ in rows["mccraith_ch4_table5"] if label.endswith("| M")]
    assert len(m_rows) == 6                                                 # baseline + ours, 3 seeds each
    assert [sum(f"M-seed{k}_" in r for r in m_rows) for k in (1, 2)] == [2, 2]
    assert len(rows["mccraith_ch4_table2"]) == len(plan.expand_rows("mccraith_ch4_table2", c["depth"]))


def test_model_seed_is_the_training_seed_of_a_model_id():
    """Seed index 0: base + crc32("<dataset>/<mode>") mod 1e5 (crc32(b"world_kitti/M") = ...72623); index k adds
    crc32 of the whole id mod 1e5 (b"world_kitti/M/seed2": ...22484). A change here retrains every model."""
    assert configs.model_seed(2026, "world_kitti/M") == 2026 + 72623
    assert configs.model_seed(2026, "world_kitti/M/seed2") == 2026 + 72623 + 22484
    assert configs.model_seed(0, "world_kitti/M") == 72623
    with pytest.raises(ValueError, match="not a depth model id"):
        configs.model_seed(0, "world_kitti")


def test_prediction_batches_go_to_the_networks_device(monkeypatch):
    # a training job builds its validation batches on the CPU; _predict hands them to the networks' device
    # (on CUDA the first validation pass of M / MD / FD failed before). Here the networks sit on the meta device.
    seen = {}

    def fake_predict(models, meta, target, prev, K, branch):
        seen.update(target=target.device, prev=prev.device, K=K.device)
        return torch.zeros(1, 1, *target.shape[-2:])

    monkeypatch.setattr(experiments.systems, "predict_depth", fake_predict)
    models = torch.nn.ModuleDict({"depth_encoder": torch.nn.Linear(2, 2, device="meta")})
    batch = {"target": torch.rand(1, 3, 4, 6), "prev": torch.rand(1, 3, 4, 6), "K": torch.eye(3)[None]}
    depth = experiments._predict(models, batch, {})
    assert seen == {"target": torch.device("meta"), "prev": torch.device("meta"), "K": torch.device("meta")}
    assert depth.shape == (4, 6)


def test_table_note_joins_a_list_of_notes(cfg):
    """A table's note may be a list (tables share explanations through YAML anchors): its items become sentences
    of the caption, in order, each once; the default's ch. 4 Table 6 carries the Eigen / Odometry naming and the
    time definition, Fig. 4 the time definition (one anchor, two tables)."""
    one = plan.table_note(cfg, {"note": "first part."}, {})
    two = plan.table_note(cfg, {"note": ["first part.", "second part"]}, {})
    assert "; first part; " in one and "; first part. second part; " in two
    t6 = plan.table_note(cfg, cfg["depth"]["tables"]["mccraith_ch4_table6"], {})
    assert t6.count("Eigen = the test scenes, Odometry = the long scenes") == 1
    assert t6.count("time = seconds per frame of adaptation + prediction") == 1
    f4 = plan.table_note(cfg, cfg["depth"]["tables"]["mccraith_ch4_fig4"], {})
    assert "time = seconds per frame of adaptation + prediction" in f4 and "Eigen = the test scenes" not in f4


def test_figures_read_a_row_with_several_seeds_as_its_seed_mean():
    """Figs. 4 and 5 with a label per training seed (the paper profile's 3 seeds): Fig. 4 plots per frame the mean
    over a label's runs, Fig. 5 one point per label from the seed-mean table."""
    from types import SimpleNamespace

    def res(values):
        return {"records": [{"step": 0, "sequence": "long_000", "frame": f, "metrics": {"abs_rel": v}}
                            for f, v in enumerate(values)]}

    base, seq = SimpleNamespace(label="baseline", step=0), SimpleNamespace(label="ours", step=0)
    rows = [base, base, seq]
    curves = depth_tables.seed_mean_curves(rows, [res([0.1, 0.3]), res([0.2, 0.5]), res([0.4, 0.4])])
    assert list(curves) == ["baseline", "ours"]
    assert curves["baseline"] == [("long_000", 0, pytest.approx(0.15)), ("long_000", 1, pytest.approx(0.4))]
    assert curves["ours"] == [("long_000", 0, 0.4), ("long_000", 1, 0.4)]
    fig = depth_tables.fig4(rows, [res([0.1, 0.3]), res([0.2, 0.5]), res([0.4, 0.4])])
    assert [t.get_text() for t in fig.axes[0].get_legend().get_texts()] == [
        "baseline (mean 0.275, mean of 2 seeds)", "ours (mean 0.400)"]
    cs = [SimpleNamespace(label=f"CS | {s}") for s in (0, 50)]
    table = pd.DataFrame({"Abs Rel": [0.21, 0.19]}, index=["CS | 0", "CS | 50"])
    line = depth_tables.fig5([cs[0], cs[0], cs[1], cs[1]], table).axes[0].get_lines()[0]
    assert list(line.get_xdata()) == [0, 50] and list(line.get_ydata()) == [0.21, 0.19]
