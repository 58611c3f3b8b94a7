"""The depth stage's outputs in the session's tiny build (conftest fixture `built`)."""
import json
import math

import numpy as np
import pandas as pd
import pytest

from redsup.depth import checkpoint
from redsup.tables import load_registry

TABLES = [t for t, e in load_registry()["tables"].items() if e["stage"] in ("depth", "galteland")]
FIGURES = [t for t in TABLES if load_registry()["tables"][t]["kind"] == "figure"]


def test_models_load_with_their_meta(built):
    models = sorted((built / "results/depth/models").glob("*/*.pt"))
    names = {f"{p.parent.name}/{p.stem}" for p in models}
    assert {"world_kitti/M", "world_kitti/S", "world_kitti/MS", "world_cityscapes/M", "world_kitti/MD",
            "world_kitti/FD", "world_lyft/MD", "world_lyft/MD_frontback", "world_lyft/FD", "world_ddad/MD"} <= names
    nets, meta = checkpoint.load(built / "results/depth/models/world_kitti/M.pt")
    assert set(nets) == {"depth_encoder", "depth_decoder", "pose_encoder", "pose_decoder"}
    # depth.modes.M.input_scale 1.0: M trains at the prepared 32 x 104, as S does (MD below: half of it)
    assert meta["mode"] == "M" and meta["sources"] == ["prev", "next"] and (meta["height"], meta["width"]) == (32, 104)
    assert meta["min_depth"] == 0.1 and meta["max_depth"] == 100.0 and meta["train"]["steps"] == 12
    _, meta = checkpoint.load(built / "results/depth/models/world_kitti/S.pt")
    assert meta["sources"] == ["stereo"] and (meta["height"], meta["width"]) == (32, 104)


def test_galteland_systems_select_on_val_and_log_the_metrics_per_step(built):
    nets, meta = checkpoint.load(built / "results/depth/models/world_kitti/MD.pt")
    assert meta["system"] == "manydepth" and {"teacher_encoder", "depth_range"} <= set(nets)
    assert (meta["height"], meta["width"]) == (16, 52)  # input_scale 0.5 of the prepared 32 x 104
    epochs, steps = meta["train"]["epochs"], meta["train"]["steps"]
    assert [h["step"] for h in meta["validation"]] == [steps // epochs * (k + 1) for k in range(epochs)]
    best = min(meta["validation"], key=lambda h: h["abs_rel"])
    assert meta["best_step"] == best["step"] and meta["scenes"] and all("train_" in s for s in meta["scenes"])
    record = json.loads((built / "results/runs/depth/models/world_kitti/MD.json").read_text())
    for m in ("abs_rel", "sq_rel", "rmse", "rmse_log", "a1", "a2", "a3"):
        assert sorted(s for k, _, s, _ in record["metrics"] if k == f"val_{m}") == [h["step"] for h in meta["validation"]]
    nets, meta = checkpoint.load(built / "results/depth/models/world_kitti/FD.pt")
    assert meta["system"] == "featdepth" and "feature_encoder" in nets and len(meta["validation"]) == meta["train"]["epochs"]
    for fig in ("galteland_fig4_1", "galteland_fig4_2", "galteland_fig4_3", "galteland_fig4_10", "galteland_fig4_11"):
        png = built / f"results/figures/{fig}.png"
        assert png.stat().st_size > 1000 and png.read_bytes()[:4] == b"\x89PNG", fig
    t41 = (built / "results/tables/galteland_table4_1.md").read_text()
    assert "FPS" in t41 and "torch thread" in t41 and "stand-in" not in t41
    assert "stand-in" not in (built / "results/tables/galteland_table5_1.md").read_text()


def test_predictions_are_raw_depth_of_every_frame(built):
    preds = sorted((built / "results/depth/predictions").glob("*/*/*.npz"))
    if not preds:
        pytest.skip("no stage of this build asked for predictions")
    for path in preds:
        with np.load(path) as d:
            depth, K = d["depth"], d["K"]
        scene = path.stem
        with np.load(built / f"results/prepared/{path.parent.parent.name}/{scene}/cam_front.npz") as p:
            assert depth.shape == p["images"].shape[:3] and np.allclose(K, p["K"])
        assert depth.dtype == np.float32 and np.isfinite(depth).all() and (depth >= 0.1 - 1e-4).all()


@pytest.mark.parametrize("table", TABLES)
def test_tables_written_with_paper_values_and_score(built, table):
    md = (built / f"results/tables/{table}.md").read_text()
    assert md.startswith("# ") and "(paper)" in md and "Profile tiny" in md
    score = json.loads((built / f"results/tables/{table}.score.json").read_text())
    assert score["table_id"] == table and score["has_paper"]
    df = pd.read_csv(built / f"results/tables/{table}.csv")
    ours = df[df["status"].isin(["ours + paper", "ours only"])]
    assert len(ours) >= 1
    assert not ours["Abs Rel (ours)"].isna().any()  # NaN-free: skipped frames are counted, not averaged


def test_figures_and_eval_records(built):
    for fig in FIGURES:
        png = built / f"results/figures/{fig}.png"
        assert png.stat().st_size > 1000 and png.read_bytes()[:4] == b"\x89PNG"
    runs = sorted((built / "results/depth/eval").glob("*.json"))
    assert len(runs) >= 10
    reasons = []
    for path in runs:
        result = json.loads(path.read_text())
        for step, agg in result["summary"].items():
            assert all(math.isfinite(v) for k, v in agg.items() if isinstance(v, float) and k != "seconds")
            reasons += agg["skip_reasons"]
        record = json.loads((built / f"results/runs/depth/eval/{path.stem}.json").read_text())
        assert record["status"] == "FINISHED" and record["parent"] in TABLES
        assert json.loads(record["params"]["tables"])[0] == record["parent"]
    # sequential runs cannot adapt the first and last frame of a sequence: reported, not crashed
    assert any("missing neighbour frame" in r for r in reasons)
