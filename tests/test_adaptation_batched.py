"""Batched instance-wise adaptation (adaptation.adapt_batched): per frame the numbers of one-at-a-time adaptation."""
import functools
import math

import numpy as np
import pytest
import torch

from redsup.depth import adaptation, data, experiments, networks, pipeline

torch.set_num_threads(1)
H, W = 32, 64
LOSS_KW = {"noise_std": 1e-5, "min_depth": 0.1, "max_depth": 100.0}   # with the identity noise: per-frame generators
LOSS = functools.partial(pipeline.batch_loss, **LOSS_KW)
# float32 at the thesis' lr 0.1 (3 steps move the predictions by 2e-4 to 2e-3): batched vs one at a time measured
# at most 3e-7 relative on predictions and losses. Where a rounding difference flips a pixel of the auto-mask (or
# of the minimum over sources), that step's gradient changes by the pixel's share: seen once at lr 1.0 (an
# unstable trajectory whose loss rose), 2e-3 on one frame; float arithmetic, not coupling: in float64 the batched
# path gives the one-at-a-time numbers to 4e-16 (test_batched_equals_one_at_a_time_float64)
RTOL = 1e-4
ATOL = 1e-6
LR = 0.1


def _models():
    torch.manual_seed(0)
    models = networks.build_models(base_channels=8)
    models.train()   # non-trivial BatchNorm statistics, as after training
    with torch.no_grad():
        for _ in range(2):
            pipeline.batch_loss(models, _sample(9))
    return models.eval()


def _sample(seed):
    g = torch.Generator().manual_seed(seed)
    base = torch.rand(1, 3, H, W + 4, generator=g)
    K = torch.tensor([[[40.0, 0.0, 31.5], [0.0, 40.0, 15.5], [0.0, 0.0, 1.0]]])
    return {"target": base[..., 2:W + 2].contiguous(), "K": K,
            "sources": {"prev": base[..., 0:W].contiguous(), "next": base[..., 4:W + 4].contiguous()}}


def _gens(n):
    return [torch.Generator().manual_seed(1000 + k) for k in range(n)]


def _predict(models, sample):
    return pipeline.predict_depth(models, sample["target"])


def _one_at_a_time(models, samples, loss_fn, groups, lr, steps):
    """Reference: ``adapt`` per sample from the trained weights, each loss with its own seeded generator."""
    state = adaptation.snapshot(models)
    params = adaptation.select_parameters(models, groups)
    out = []
    try:
        for sample, gen in zip(samples, _gens(len(samples))):
            adaptation.load_snapshot(models, state)
            hist = adaptation.adapt(models, functools.partial(loss_fn, generator=gen), sample, params, lr, steps)
            with torch.no_grad():
                out.append((hist, _predict(models, sample)))
    finally:
        adaptation.load_snapshot(models, state)
    return out


def _close(a, b, rtol=RTOL, atol=ATOL):
    return torch.allclose(torch.as_tensor(a), torch.as_tensor(b), rtol=rtol, atol=atol, equal_nan=True)


def _stereo_sample(seed):
    """An S-mode sample: the stereo partner with its known transform (no pose network)."""
    s = _sample(seed)
    return {"target": s["target"], "K": s["K"], "sources": {"stereo": s["sources"]["next"]},
            "transforms": {"stereo": pipeline.stereo_transform(0.1, s["target"])}}


def _double(tree):
    if isinstance(tree, torch.Tensor):
        return tree.double()
    return {k: _double(v) for k, v in tree.items()}


CASES = [(["depth_encoder", "pose_encoder"], _sample),       # the thesis' choice, M (prev + next)
         (["depth_decoder", "pose_last_block"], _sample),
         (["depth_encoder"], _stereo_sample)]                 # S: a known transform, no pose network


def _rel(a, b):
    return float(((a - b).abs() / b.abs()).max())


def _compare(groups, make, dtype, lr, rtol, atol, min_move):
    models = _models().to(dtype)
    before = {k: v.clone() for k, v in models.state_dict().items()}
    samples = [make(s) for s in (1, 2, 3)]
    samples = [_double(s) for s in samples] if dtype == torch.float64 else samples
    ref = _one_at_a_time(models, samples, LOSS, groups, lr=lr, steps=3)
    state = adaptation.snapshot(models)
    seen = []
    got = adaptation.instance_wise_batched(models, state, samples, LOSS, _predict, groups, lr=lr, steps=3,
                                           batch_size=2, generators=_gens(3),
                                           callback=lambda i, s, loss, t: seen.append((i, s)))
    assert all(torch.equal(before[k], v) for k, v in models.state_dict().items())   # never written
    assert sorted(seen) == [(i, s) for i in range(3) for s in range(4)]
    for (hist, pred), res in zip(ref, got):
        assert len(res["losses"]) == 3 and all(math.isfinite(h) for h in res["losses"])
        assert _close(res["losses"], hist, rtol, atol), (res["losses"], hist)
        assert res["output"].shape == pred.shape and res["output"].dtype == dtype
        assert _close(res["output"], pred, rtol, atol)
        assert res["seconds"] > 0
    # the adaptation did something: every prediction moved, by far more than it differs from one at a time
    assert all(r["losses"][-1] != r["losses"][0] for r in got)
    with torch.no_grad():
        for sample, res, (_, pred) in zip(samples, got, ref):
            moved = _rel(res["output"], _predict(models, sample))
            assert moved > max(min_move, 100 * _rel(res["output"], pred)), moved


@pytest.mark.parametrize("groups,make", CASES)
def test_batched_equals_one_at_a_time(groups, make):
    _compare(groups, make, torch.float32, LR, RTOL, ATOL, min_move=1e-4)


@pytest.mark.parametrize("groups,make", CASES)
def test_batched_equals_one_at_a_time_float64(groups, make):
    """In float64 no rounding difference can flip a pixel of the auto-mask: the same numbers to 1e-12 at lr 1.0
    (predictions moving by 0.2-1 %), which only per-sample independence and the same noise draws give."""
    _compare(groups, make, torch.float64, 1.0, 1e-12, 1e-14, min_move=1e-3)


def test_no_cross_sample_coupling():
    models = _models()
    groups = ["depth_encoder", "pose_encoder"]
    params = adaptation.select_parameters(models, groups)
    samples = [_sample(s) for s in (1, 2, 3)]
    changed = [dict(s) for s in samples]
    changed[1] = _sample(7)   # another frame in the middle of the batch
    runs = []
    for batch in (samples, changed):
        hists, copies = adaptation.adapt_batched(models, LOSS, batch, params, 1.0, 3, generators=_gens(3))
        runs.append((hists, copies.map(_predict), copies))
    (h0, p0, c0), (h1, p1, c1) = runs
    for j in (0, 2):   # the other frames: bit-identical trajectories, weights and predictions
        assert h0[j] == h1[j]
        assert torch.equal(p0[j], p1[j])
        assert all(torch.equal(c0.weights[k][j], c1.weights[k][j]) for k in c0.weights)
    assert h0[1] != h1[1] and not torch.equal(p0[1], p1[1])
    # each copy's adapted state has the parameters of the groups only
    st = c0.state(0)
    assert set(st) == {"depth_encoder", "pose_encoder"}
    assert sum(len(v) for v in st.values()) == len(params)


def _poisoned(models_, batch, *, w0, generator=None):
    """LOSS, with per-frame flags in the batch: ``explode`` > 0: +inf once the weights have moved (a finite first
    step, then divergence); ``nan_grad`` > 0: a finite loss whose gradient is NaN (sqrt at 0 times 0)."""
    out = LOSS(models_, batch, generator=generator)
    w = models_["depth_encoder"].conv1.weight
    moved = ((w - w0) ** 2).sum() > 0
    inf = torch.full((), float("inf"))
    loss = out["loss"] + torch.where((batch["explode"] > 0) & moved, inf, torch.zeros(()))
    flag = batch["nan_grad"]
    loss = loss + torch.sqrt(flag * (w * 0.0).sum() + (1.0 - flag)) - (1.0 - flag)
    return {**out, "loss": loss}


def test_divergence_per_frame_as_one_at_a_time():
    models = _models()
    groups = ["depth_encoder"]
    loss_fn = functools.partial(_poisoned, w0=models["depth_encoder"].conv1.weight.detach().clone())
    samples = []
    for k, (explode, nan_grad) in enumerate([(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (0.0, 0.0)]):
        s = _sample(k + 1)
        s["explode"], s["nan_grad"] = torch.tensor([explode]), torch.tensor([nan_grad])
        samples.append(s)
    ref = _one_at_a_time(models, samples, loss_fn, groups, lr=0.1, steps=3)
    assert math.isfinite(ref[1][0][0]) and all(math.isnan(h) for h in ref[1][0][1:])   # diverges at step 2
    assert all(math.isnan(h) for h in ref[2][0])                                         # at step 1
    params = adaptation.select_parameters(models, groups)
    hists, copies = adaptation.adapt_batched(models, loss_fn, samples, params, 0.1, 3, generators=_gens(4))
    preds = copies.map(_predict)
    for j, (hist, pred) in enumerate(ref):
        assert [math.isnan(h) for h in hists[j]] == [math.isnan(h) for h in hist], j
        assert _close(hists[j], hist), (j, hists[j], hist)
        assert torch.isfinite(pred).all() and _close(preds[j], pred), j
    for w in copies.weights.values():
        assert torch.isfinite(w).all()
    # frame 2 never updated: its copy is the trained weights
    trained = dict(adaptation._Call(models).named_parameters())
    assert all(torch.equal(copies.weights[k][2], trained[k]) for k in copies.weights)


def _eval_seq(n=5, empty_gt_frame=None):
    rng = np.random.default_rng(1)
    base = rng.integers(0, 255, size=(H, W + 8, 3), dtype=np.uint8)
    images = np.stack([base[:, i:i + W] for i in range(n)])   # a sideways pan
    K = np.array([[40.0, 0.0, 31.5], [0.0, 40.0, 15.5], [0.0, 0.0, 1.0]])
    gt = np.zeros((n, 2 * H, 2 * W), np.float32)
    gt[:, 40:60, 10:120] = np.linspace(5.0, 30.0, 110)[None, None]
    if empty_gt_frame is not None:
        gt[empty_gt_frame] = 0.0
    return experiments.EvalSequence(data.Sequence("test_000", images, K), gt)


@pytest.mark.parametrize("groups", [["depth_encoder", "pose_encoder"], ["depth_decoder"]])
def test_run_instance_batched_records_equal_one_at_a_time(groups):
    models = _models()
    meta = {"min_depth": 0.1, "max_depth": 100.0, "sources": ["prev", "next"]}
    before = {k: v.clone() for k, v in models.state_dict().items()}
    seq = _eval_seq(5, empty_gt_frame=2)
    frames = [(0, t) for t in range(5)]   # frame 0: no previous frame, frame 4: no next, frame 2: no ground truth
    kw = dict(sources=["prev", "next"], groups=groups, lr=LR, checkpoints=[0, 1, 3],
              eval_cfg={"min_depth": 1e-3, "max_depth": 80.0, "crop": "garg"}, loss_kwargs=LOSS_KW,
              metric_scale=False)
    done = []
    one, curve1 = experiments.run_instance(models, meta, [seq], frames, batch_size=1, **kw)
    many, curve3 = experiments.run_instance(models, meta, [seq], frames, batch_size=3,
                                            progress=lambda i, n: done.append(i), **kw)
    assert all(torch.equal(before[k], v) for k, v in models.state_dict().items())
    assert done == [2, 3, 4]   # the three complete frames, adapted as one batch
    assert [(r["frame"], r["step"], r.get("reason")) for r in one] == \
        [(r["frame"], r["step"], r.get("reason")) for r in many]
    assert sum("metrics" in r for r in many) == 6   # frames 1 and 3 at 3 checkpoints
    for a, b in zip(one, many):
        assert ("metrics" in a) == ("metrics" in b)
        if "metrics" in a:
            ma, mb = a["metrics"], b["metrics"]
            # the error metrics to RTOL; a1-a3 count pixels under a threshold, where a rounding difference can
            # move one pixel across (one pixel of the ~2000 valid ones: 5e-4): 2 pixels' worth
            assert {k: ma[k] for k in ("abs_rel", "sq_rel", "rmse", "rmse_log")} == pytest.approx(
                {k: mb[k] for k in ("abs_rel", "sq_rel", "rmse", "rmse_log")}, rel=RTOL, abs=ATOL)
            assert {k: ma[k] for k in ("a1", "a2", "a3")} == pytest.approx(
                {k: mb[k] for k in ("a1", "a2", "a3")}, abs=1e-3)
            assert b["seconds"] > 0
    assert curve3 == pytest.approx(curve1, rel=RTOL, abs=ATOL) and len(curve3) == 3
    steps = {(r["frame"], r["step"]): r for r in many}
    assert steps[(1, 0)]["metrics"]["abs_rel"] != steps[(1, 3)]["metrics"]["abs_rel"]
    assert steps[(1, 3)]["seconds"] > steps[(1, 0)]["seconds"]
    # batches of 2: frames 1 + 2 together, frame 3 alone, which takes the one-at-a-time path (the same bits)
    pairs, _ = experiments.run_instance(models, meta, [seq], frames, batch_size=2, **kw)
    assert [r.get("metrics") for r in pairs if r["frame"] == 3] == [r.get("metrics") for r in one if r["frame"] == 3]
    assert [r["metrics"]["abs_rel"] for r in pairs if r["frame"] == 1] == pytest.approx(
        [r["metrics"]["abs_rel"] for r in one if r["frame"] == 1], rel=RTOL)   # kernels differ by batch size


def test_batch_chunks_follow_size_and_signature():
    a, b = _sample(1), _sample(2)
    small = {"target": torch.zeros(1, 3, 16, 32), "K": a["K"], "sources": {"prev": torch.zeros(1, 3, 16, 32)}}
    samples = [a, b, a, small, small, a]
    assert adaptation.batch_chunks(samples, 2) == [[0, 1], [2], [3, 4], [5]]
    assert adaptation.batch_chunks(samples, 8) == [[0, 1, 2], [3, 4], [5]]
    assert adaptation.batch_chunks(samples, 1) == [[i] for i in range(6)]
    with pytest.raises(ValueError):
        adaptation.batch_chunks(samples, 0)
