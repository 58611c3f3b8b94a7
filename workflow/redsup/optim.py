"""Adam and plain SGD written out, the same arithmetic as ``torch.optim.Adam(lr, betas, eps)`` and
``torch.optim.SGD(lr)`` (no momentum, no weight decay), single-tensor form.

Constructing any ``torch.optim`` optimiser imports ``torch._dynamo``: 0.9-1.7 s of CPU in every training job,
more than the training itself in the tiny profile, for a compiler no job here uses. The learning rate is the
attribute ``lr``; a schedule is the caller's (set ``lr`` before a step). ``tests/test_optim.py`` checks both
against torch step by step. The detector's AdamW with its one-cycle schedule is
``redsup.lidar_detector.optim``.
"""
from __future__ import annotations

import math

import torch


class Adam:
    """Adam (Kingma & Ba 2015) with bias correction, as torch.optim.Adam(lr, betas, eps), no weight decay."""

    def __init__(self, params, lr: float, betas=(0.9, 0.999), eps: float = 1e-8):
        self.params = [p for p in params if p.requires_grad]
        self.lr, self.betas, self.eps = float(lr), betas, float(eps)
        self.m = [torch.zeros_like(p) for p in self.params]
        self.v = [torch.zeros_like(p) for p in self.params]
        self.t = 0

    def zero_grad(self, set_to_none: bool = True) -> None:
        for p in self.params:
            if set_to_none or p.grad is None:
                p.grad = None
            else:
                p.grad.zero_()

    @torch.no_grad()
    def step(self) -> None:
        self.t += 1
        b1, b2 = self.betas
        c1, c2 = 1 - b1 ** self.t, 1 - b2 ** self.t
        for p, m, v in zip(self.params, self.m, self.v):
            if p.grad is None:
                continue
            m.mul_(b1).add_(p.grad, alpha=1 - b1)
            v.mul_(b2).addcmul_(p.grad, p.grad, value=1 - b2)
            p.addcdiv_(m, (v.sqrt() / math.sqrt(c2)).add_(self.eps), value=-self.lr / c1)


class SGD:
    """Plain gradient descent, as torch.optim.SGD(lr): p <- p - lr * grad."""

    def __init__(self, params, lr: float):
        self.params = [p for p in params if p.requires_grad]
        self.lr = float(lr)

    def zero_grad(self, set_to_none: bool = True) -> None:
        Adam.zero_grad(self, set_to_none)

    @torch.no_grad()
    def step(self) -> None:
        for p in self.params:
            if p.grad is not None:
                p.add_(p.grad, alpha=-self.lr)
