"""AdamW with the one-cycle schedule of the detector, without ``torch.optim``.

The first ``torch.optim.Optimizer`` of a process imports ``torch._dynamo`` (about 4 s of CPU on the 2-core
machine, in every training job); this is the same arithmetic as ``torch.optim.AdamW(lr, weight_decay)`` driven
by ``torch.optim.lr_scheduler.OneCycleLR(max_lr=lr, total_steps, pct_start, div_factor, final_div_factor)``
with its defaults (cosine annealing, two phases, beta1 cycled between 0.95 and 0.85), single-tensor form.
``tests/test_lidar_detector.py`` checks it against torch step by step.
"""
from __future__ import annotations

import math

import torch


class OneCycleAdamW:
    def __init__(self, params, lr: float, weight_decay: float, total_steps: int, pct_start: float = 0.3,
                 div_factor: float = 25.0, final_div_factor: float = 1e4, betas=(0.9, 0.999), eps: float = 1e-8,
                 base_momentum: float = 0.85, max_momentum: float = 0.95):
        self.params = [p for p in params if p.requires_grad]
        self.weight_decay, self.eps, self.beta2 = float(weight_decay), float(eps), float(betas[1])
        self.max_lr = float(lr)
        self.initial_lr = self.max_lr / div_factor
        self.min_lr = self.initial_lr / final_div_factor
        self.base_momentum, self.max_momentum = float(base_momentum), float(max_momentum)
        self.total_steps = int(total_steps)
        self.phases = [(float(pct_start * self.total_steps) - 1, (self.initial_lr, self.max_lr),
                        (self.max_momentum, self.base_momentum)),
                       (self.total_steps - 1, (self.max_lr, self.min_lr), (self.base_momentum, self.max_momentum))]
        self.state = [{"step": 0, "m": torch.zeros_like(p), "v": torch.zeros_like(p)} for p in self.params]
        self.last_step = -1
        self.lr, self.beta1 = self.initial_lr, self.max_momentum
        self.schedule_step()                       # the schedule's value at step 0, as OneCycleLR's first step

    @staticmethod
    def _cos(start: float, end: float, pct: float) -> float:
        return end + (start - end) / 2.0 * (math.cos(math.pi * pct) + 1)

    def schedule_step(self) -> None:
        """Advance the one-cycle schedule (``OneCycleLR.step``): the learning rate and beta1 of the next step."""
        self.last_step += 1
        start = 0.0
        for i, (end, lrs, moms) in enumerate(self.phases):
            if self.last_step <= end or i == len(self.phases) - 1:
                pct = (self.last_step - start) / (end - start)
                self.lr, self.beta1 = self._cos(*lrs, pct), self._cos(*moms, pct)
                break
            start = end

    def zero_grad(self) -> None:
        for p in self.params:
            p.grad = None

    @torch.no_grad()
    def step(self) -> None:
        lr, b1, b2 = self.lr, self.beta1, self.beta2
        for p, st in zip(self.params, self.state):
            if p.grad is None:
                continue
            st["step"] += 1
            t = st["step"]
            p.mul_(1 - lr * self.weight_decay)
            st["m"].lerp_(p.grad, 1 - b1)
            st["v"].mul_(b2).addcmul_(p.grad, p.grad, value=1 - b2)
            denom = (st["v"].sqrt() / math.sqrt(1 - b2 ** t)).add_(self.eps)
            p.addcdiv_(st["m"], denom, value=-lr / (1 - b1 ** t))
