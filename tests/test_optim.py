"""redsup.optim: Adam and SGD give torch.optim's numbers step by step, without importing torch._dynamo."""
import subprocess
import sys

import pytest
import torch

from redsup.optim import SGD, Adam


def _pair(seed=0):
    torch.manual_seed(seed)
    a, b = torch.nn.Linear(3, 2), torch.nn.Linear(3, 2)
    b.load_state_dict(a.state_dict())
    return a, b


@pytest.mark.parametrize("make", [lambda p, lr: (Adam(p, lr=lr), torch.optim.Adam(p, lr=lr, foreach=False)),
                                  lambda p, lr: (SGD(p, lr=lr), torch.optim.SGD(p, lr=lr, foreach=False))])
def test_matches_torch_with_a_schedule_set_through_lr(make):
    a, b = _pair()
    mine, _ = make(list(a.parameters()), 3e-3)
    _, ref = make(list(b.parameters()), 3e-3)
    x = torch.randn(5, 3)
    for step in range(6):
        lr = 3e-3 * 0.5 ** (step // 2)                  # a step decay, set by the caller
        mine.lr = lr
        for group in ref.param_groups:
            group["lr"] = lr
        for net, opt in ((a, mine), (b, ref)):
            opt.zero_grad()
            (net(x) ** 2).sum().backward()
            opt.step()
    assert torch.allclose(a.weight, b.weight, atol=1e-7) and torch.allclose(a.bias, b.bias, atol=1e-7)


def test_sgd_by_hand_and_frozen_parameters_are_left_alone():
    w = torch.nn.Parameter(torch.tensor([1.0, 2.0]))
    frozen = torch.nn.Parameter(torch.tensor([5.0]), requires_grad=False)
    opt = SGD([w, frozen], lr=0.1)
    w.grad = torch.tensor([10.0, -20.0])
    opt.step()                                          # 1 - 0.1 * 10 = 0, 2 + 0.1 * 20 = 4
    assert w.tolist() == pytest.approx([0.0, 4.0], abs=1e-6) and frozen.item() == 5.0
    opt.zero_grad(set_to_none=False)
    assert w.grad.tolist() == [0.0, 0.0]
    opt.zero_grad()
    assert w.grad is None


def test_a_training_step_does_not_import_the_compiler():
    code = ("import sys, torch; from redsup.optim import Adam; m = torch.nn.Linear(2, 1); o = Adam(m.parameters(), 1e-3); "
            "m(torch.ones(1, 2)).sum().backward(); o.step(); print('torch._dynamo' in sys.modules)")
    assert subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True).stdout.strip() == "False"
