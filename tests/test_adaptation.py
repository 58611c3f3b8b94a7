"""Test-time adaptation: only the selected modules change, BatchNorm is untouched, resets are explicit."""
import copy
import math
import functools

import pytest
import torch

from redsup.depth import adaptation, networks, pipeline, warping

torch.set_num_threads(1)
H, W = 32, 64
LOSS = functools.partial(pipeline.batch_loss, noise_std=0.0)


def _models():
    torch.manual_seed(0)
    models = networks.build_models(base_channels=8)
    # give BatchNorm non-trivial statistics, as after training
    models.train()
    with torch.no_grad():
        for _ in range(2):
            pipeline.batch_loss(models, _sample(9))
    return models


def _sample(seed):
    g = torch.Generator().manual_seed(seed)
    base = torch.rand(1, 3, H, W + 4, generator=g)
    K = torch.tensor([[[40.0, 0.0, 31.5], [0.0, 40.0, 15.5], [0.0, 0.0, 1.0]]])
    return {"target": base[..., 2:W + 2], "K": K,
            "sources": {"prev": base[..., 0:W], "next": base[..., 4:W + 4]}}


def _state(models):
    return {f"{name}.{k}": v.detach().clone() for name, m in models.items() for k, v in m.state_dict().items()}


def test_group_selection():
    models = networks.build_models(8)
    first = adaptation.select_parameters(models, ["depth_first_layer"])
    assert len(first) == 1 and first[0] is models["depth_encoder"].conv1.weight
    assert len(adaptation.select_parameters(models, ["depth_first_layer"], include_batchnorm=True)) == 3
    everything = adaptation.select_parameters(models, ["all"])
    n_bn = sum(2 for m in models.modules() if isinstance(m, torch.nn.BatchNorm2d))
    assert len(everything) == len(list(models.parameters())) - n_bn
    enc = adaptation.select_parameters(models, ["depth_encoder", "depth_last_block"])  # overlap counted once
    assert len(enc) == len({id(p) for p in enc})
    assert len(adaptation.TABLE1_ROWS) == 22
    for _, groups in adaptation.TABLE1_ROWS:
        adaptation.select_parameters(models, groups)
    with pytest.raises(KeyError, match="first_layr"):
        adaptation.select_parameters(models, ["first_layr"])


@pytest.mark.parametrize("groups,changed_prefixes", [
    (["depth_encoder"], ["depth_encoder."]),
    (["depth_first_layer"], ["depth_encoder.conv1.weight"]),
    (["pose_last_block", "depth_decoder"], ["pose_encoder.layer4.", "depth_decoder."]),
])
def test_adapt_changes_only_selected_modules(groups, changed_prefixes):
    models = _models()
    models.train()
    before = _state(models)
    flags = {id(p): p.requires_grad for p in models.parameters()}
    params = adaptation.select_parameters(models, groups)
    steps = []
    history = adaptation.adapt(models, LOSS, _sample(1), params, lr=0.1, steps=2,
                               callback=lambda s, loss, t: steps.append((s, loss)))
    after = _state(models)
    assert [s for s, _ in steps] == [0, 1, 2] and steps[0][1] is None and len(history) == 2
    selected = {id(p) for p in params}
    named = {f"{n}.{k}": p for n, m in models.items() for k, p in m.named_parameters()}
    n_changed = 0
    for key, value in before.items():
        is_selected = key in named and id(named[key]) in selected
        if is_selected:
            assert any(key.startswith(pfx) for pfx in changed_prefixes)
            n_changed += not torch.equal(value, after[key])
        else:  # BatchNorm running_mean/var/num_batches and affine, all other modules: bit-identical
            assert torch.equal(value, after[key]), key
    assert n_changed == len(params)
    assert all(p.requires_grad == flags[id(p)] for p in models.parameters()) and models.training
    assert all(p.grad is None for p in models.parameters())


def test_freeze_batchnorm_sets_eval_mode():
    models = _models()
    models.train()
    layers = adaptation.freeze_batchnorm(models["depth_encoder"])
    assert layers and all(not m.training for m in layers)
    assert models["depth_encoder"].layer1[0].conv1.training and models["depth_decoder"].training


def _predict(models, sample):
    return pipeline.predict_depth(models, sample["target"])


def test_instance_wise_resets_and_sequential_accumulates():
    models = _models()
    state = adaptation.snapshot(models)
    state_copy = copy.deepcopy(state)
    a, b = _sample(1), _sample(2)
    kw = dict(loss_fn=LOSS, predict_fn=_predict, groups=["depth_encoder", "pose_encoder"], lr=1.0, steps=2)
    inst = adaptation.instance_wise(models, state, [a, b], **kw)
    inst_b = adaptation.instance_wise(models, state, [b], **kw)
    assert torch.allclose(inst[1]["output"], inst_b[0]["output"], rtol=1e-5, atol=1e-6)
    seq, final = adaptation.sequential(models, state, [a, b], **kw)
    assert torch.allclose(seq[0]["output"], inst[0]["output"], rtol=1e-5, atol=1e-6)
    assert (seq[1]["output"] - inst[1]["output"]).abs().max() > 1e-4  # started from the weights adapted on a
    assert len(seq[1]["losses"]) == 2 and seq[1]["seconds"] > 0
    # the caller's snapshot is untouched, the models are back at the snapshot, the final state differs
    for name in state:
        for k in state[name]:
            assert torch.equal(state[name][k], state_copy[name][k])
            assert torch.equal(models[name].state_dict()[k], state[name][k])
    assert not torch.equal(final["depth_encoder"]["conv1.weight"], state["depth_encoder"]["conv1.weight"])
    assert torch.equal(final["depth_decoder"]["dispconv.0.weight"], state["depth_decoder"]["dispconv.0.weight"])


def test_direct_optimisation_of_outputs():
    models = _models().eval()
    sample = _sample(3)
    variables = pipeline.output_variables(models, sample)
    assert set(variables) == {"disp_0", "disp_1", "disp_2", "disp_3", "axisangle_prev", "translation_prev",
                              "axisangle_next", "translation_next"}
    original = {k: v.clone() for k, v in variables.items()}
    loss_fn = functools.partial(pipeline.variables_loss, sample, noise_std=0.0)
    optimised, history = adaptation.direct_optimisation(variables, loss_fn, lr=10.0, steps=3,
                                                        project=pipeline.clamp_disparities)
    assert len(history) == 3 and all(torch.equal(variables[k], original[k]) for k in variables)
    assert not torch.equal(optimised["disp_0"], original["disp_0"])
    assert not torch.equal(optimised["translation_next"], original["translation_next"])
    assert all(((v >= 0) & (v <= 1)).all() for k, v in optimised.items() if k.startswith("disp_"))
    # the known-transform (stereo) case has no pose variables
    stereo = {"target": sample["target"], "K": sample["K"], "sources": {"stereo": sample["sources"]["next"]},
              "transforms": {"stereo": warping.translation_transform(torch.tensor([[-0.1, 0.0, 0.0]]))}}
    assert set(pipeline.output_variables(models, stereo)) == {"disp_0", "disp_1", "disp_2", "disp_3"}


def test_direct_optimisation_depth_only_keeps_pose():
    models = _models().eval()
    sample = _sample(4)
    variables = pipeline.output_variables(models, sample)
    loss_fn = functools.partial(pipeline.variables_loss, sample, noise_std=0.0)
    free = [k for k in variables if k.startswith("disp_")]
    optimised, _ = adaptation.direct_optimisation(variables, loss_fn, lr=10.0, steps=1, free=free)
    assert torch.equal(optimised["translation_prev"], variables["translation_prev"])
    assert not torch.equal(optimised["disp_0"], variables["disp_0"])
    with pytest.raises(KeyError, match="nope"):
        adaptation.direct_optimisation(variables, loss_fn, lr=1.0, steps=1, free=["nope"])


def test_divergence_keeps_last_finite_weights_and_records_nan():
    models = _models()
    sample = _sample(5)
    calls = []

    def exploding(models_, batch):  # a finite loss at the first step, then +inf (as at lr >= 1)
        out = LOSS(models_, batch)
        if len(calls) >= 1:
            out["loss"] = out["loss"] * float("inf")
        calls.append(1)
        return out

    params = adaptation.select_parameters(models, ["depth_encoder"])
    history = adaptation.adapt(models, exploding, sample, params, lr=0.1, steps=4)
    assert len(history) == 4 and math.isfinite(history[0]) and all(math.isnan(h) for h in history[1:])
    after_first = {id(p): p.detach().clone() for p in params}
    assert all(torch.isfinite(p).all() for p in params)
    assert len(calls) == 2  # no forward (and no backward) after the divergence
    # a second call with a finite loss but non-finite gradients leaves the parameters untouched
    poisoned = functools.partial(_nan_grad_loss, LOSS)
    adaptation.adapt(models, poisoned, sample, params, lr=0.1, steps=2)
    assert all(torch.equal(p, after_first[id(p)]) for p in params)


def _nan_grad_loss(loss_fn, models_, batch):
    """The loss plus sqrt(0 * sum(w)): the value stays finite (+0), the gradient is inf * 0 = NaN."""
    out = loss_fn(models_, batch)
    w = models_["depth_encoder"].conv1.weight
    out["loss"] = out["loss"] + torch.sqrt((w * 0.0).sum())
    assert torch.isfinite(out["loss"])
    return out
