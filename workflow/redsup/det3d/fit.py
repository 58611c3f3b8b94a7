"""Direct minimisation of the plain one-sided Chamfer loss of McCraith ch. 6 eq. (1) over the translation of the
template at a given yaw: what the loss itself prefers for one point set, without a network. Used to separate
the loss's pull by outliers from how well a network learns it (studies/inmask_outliers.py --optimum)."""
from __future__ import annotations

import torch

from redsup.det3d.losses import masked_mean
from redsup.det3d.template import Template, distance_to_template


def squared_fit_translation(template: Template, points: torch.Tensor, mask: torch.Tensor, start: torch.Tensor,
                            yaw: torch.Tensor, steps: int = 300, lr: float = 0.05) -> torch.Tensor:
    """(B, 3) translations minimising mean d^2 (eq. 1) of each point set, by Adam from ``start``.

    points (B, P, 3) with mask (B, P) (padded entries finite), start (B, 3), yaw (B,); the local minimum
    nearest ``start`` (started at the true centre: the minimum a network that had learnt the truth would be
    pulled into)."""
    t = start.detach().clone().requires_grad_(True)
    opt = torch.optim.Adam([t], lr=lr)
    for _ in range(int(steps)):
        opt.zero_grad()
        masked_mean(distance_to_template(template, points, t, yaw) ** 2, mask).sum().backward()
        opt.step()
    return t.detach()
