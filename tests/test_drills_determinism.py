"""Drill 1's premise (issue 14): same seed -> same bits on CPU. A rerun after a kill retrains a model from
scratch and must write the tables an uninterrupted run writes, byte for byte, so each training function
called twice with the same seed and thread count must give bit-identical weights (and losses), and a
different seed must not (the comparison can fail)."""
import os

import numpy as np
import pytest
import torch

from redsup import determinism
from redsup import threads as job_threads
from redsup.depth import data, networks, training
from redsup.velocity import mlp


def weights_bytes(modules) -> bytes:
    out = b""
    for module in modules:
        for name, tensor in sorted(module.state_dict().items()):
            out += name.encode() + tensor.detach().cpu().contiguous().numpy().tobytes()
    return out


@pytest.fixture
def threads(monkeypatch):
    """One thread, as every tiny-profile training job (two would also be deterministic, but spin badly on a
    loaded 2-core machine)."""
    before = torch.get_num_threads(), torch.are_deterministic_algorithms_enabled()
    for name in job_threads.THREAD_VARIABLES:      # configure sets them for child processes: undone afterwards
        monkeypatch.setenv(name, os.environ.get(name, ""))
    determinism.configure(1)
    yield 1
    torch.set_num_threads(before[0])
    torch.use_deterministic_algorithms(before[1])


def _depth_run(seed):
    rng = np.random.default_rng(0)
    K = np.array([[40.0, 0.0, 31.5], [0.0, 40.0, 15.5], [0.0, 0.0, 1.0]])
    seq = data.Sequence("test_000", rng.integers(0, 255, size=(6, 32, 64, 3), dtype=np.uint8), K,
                        speed=np.full(6, 5.0))
    torch.manual_seed(seed)                  # what depth_train does before building the networks
    models = networks.build_models(8)
    losses = []
    training.train(models, [seq], ["prev", "next"], steps=3, batch_size=2, lr=1e-3, seed=seed,
                   callback=lambda s, t: losses.append(t["loss"]))
    return weights_bytes(models.values()), losses


def test_depth_training_twice_gives_identical_bits(threads):
    first, second, other = _depth_run(3), _depth_run(3), _depth_run(4)
    assert first[0] == second[0] and first[1] == second[1]
    assert other[0] != first[0]


def _mlp_run(seed):
    rng = np.random.default_rng(1)
    feats = rng.normal(0, 1, (96, 8)).astype(np.float32)
    targets = feats @ rng.normal(0, 1, (8, 2))
    model, curve = mlp.train_mlp(feats, targets, hidden=16, layers=2, dropout=0.1, lr=1e-2, lr_decay=0.9,
                                 epochs=3, batch_size=16, seed=seed)
    return weights_bytes([model]), [row["train_loss"] for row in curve]


def test_velocity_mlp_training_twice_gives_identical_bits(threads):
    first, second, other = _mlp_run(0), _mlp_run(0), _mlp_run(1)
    assert first == second
    assert other[0] != first[0]


def test_configure_sets_the_thread_count_and_deterministic_algorithms(monkeypatch):
    before = torch.get_num_threads(), torch.are_deterministic_algorithms_enabled()
    for name in job_threads.THREAD_VARIABLES:
        monkeypatch.setenv(name, "2")
    try:
        torch.use_deterministic_algorithms(False)
        determinism.configure(1)
        assert torch.get_num_threads() == 1
        assert {os.environ[name] for name in job_threads.THREAD_VARIABLES} == {"1"}
        assert torch.are_deterministic_algorithms_enabled()
        with pytest.raises(ValueError, match="threads must be a positive integer"):
            determinism.configure(0)
    finally:
        torch.set_num_threads(before[0])
        torch.use_deterministic_algorithms(before[1])


def test_configure_does_not_import_the_compiler():
    """torch.use_deterministic_algorithms imports torch._inductor.config (about a second per job); configure
    sets the same switches without it. In a fresh process, since this one may have the compiler loaded."""
    import subprocess
    import sys

    code = ("import sys, torch; from redsup import determinism; determinism.configure(1); "
            "print(torch.are_deterministic_algorithms_enabled(), "
            "torch.is_deterministic_algorithms_warn_only_enabled(), 'torch._inductor.config' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split()
    assert out == ["True", "True", "False"]
