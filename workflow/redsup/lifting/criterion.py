"""Loss terms of the lifting network and their composition (McCraith ch. 6 eq. 1-8).

A configuration lists the terms it trains with (`terms: [alignment, multiview]`, `[supervised_box]`);
`build_criterion` composes them, so every ablation row is a different list, never a flag inside a trainer.
Each term maps (network outputs, batch) to named scalar components; `Criterion` returns their weighted sum
(weights per component name from `lifting.loss.weights`, default 1) and the components for the curves.

Per-point alignment (the distance d = ||X - X'|| to the nearest point of the posed template):
    `squared`        d^2                                   eq. (1)-(2)
    `outlier_aware`  d^2 / sigma^2(X) + log sigma^2(X)     eq. (3), sigma from the network's Psi head

Alignment terms, by the yaw head of the network:
    bins        eq. (4)-(6): every yaw bin is evaluated at the predicted translation (no gradient); the
                arg-min bin is the cross-entropy target of the yaw logits ("yaw"), and the translation (and
                sigma) are trained through the loss at that bin's yaw ("align").
    vector      Table II (a): the loss at the regressed yaw atan2(x1, x2), gradients into yaw and translation.
    hypotheses  Table II (b) Insafutdinov & Dosovitskiy 2018: M yaw candidates, only the lowest-loss one is
                trained (winner takes all) and a selector learns to pick it;
                Table II (c) Goel et al. 2020: the candidates are weighted by softmax(-loss / temperature)
                (their probability over hypotheses) and the selector learns these probabilities.
                (The thesis only names the two methods; these are their core mechanisms, not their code.)
Multi-frame consistency, eq. (7)-(8): for pairs (i, j) of detections of one 3D track at most K frames apart,
    sum over the centre and front keypoints of ||g_{i<-j} X^j - X^i||^2, summed over pairs and divided by
    the batch size (1/|D| sum_i sum_j). The front keypoint uses the head's differentiable heading vector
    (`MultiViewConsistency`).
Supervised box (fully supervised reference rows, Table III (e), IV): smooth-L1 on the object-frame
    translation ("translation") + cross-entropy to the target's yaw bin ("yaw").
"""
from __future__ import annotations

from typing import Callable

import torch
import torch.nn.functional as F

from redsup.det3d.losses import (best_yaw_bin, masked_mean, outlier_aware, squared_distance, yaw_bin_centers,
                                 yaw_to_bin)
from redsup.det3d.template import Template, distance_to_template
from redsup.lifting.frames import rotate_z, to_vehicle


# ------------------------------------------------------------------------------------ per-point losses
class SquaredPointLoss:
    """Eq. (1): d^2 (the plain one-sided Chamfer term)."""
    name = "squared"

    def __call__(self, d: torch.Tensor, out: dict, detach: bool = False) -> torch.Tensor:
        return squared_distance(d)


class OutlierAwarePointLoss:
    """Eq. (3): d^2 / sigma^2 + log sigma^2 with the network's per-point log sigma^2 (B, P)."""
    name = "outlier_aware"

    def __call__(self, d: torch.Tensor, out: dict, detach: bool = False) -> torch.Tensor:
        log_var = out["log_var"].detach() if detach else out["log_var"]
        while log_var.ndim < d.ndim:          # (B, P) against (B, K, P)
            log_var = log_var[:, None]
        return outlier_aware(d, log_var)


POINT_LOSSES = {"squared": SquaredPointLoss, "outlier_aware": OutlierAwarePointLoss}


# ------------------------------------------------------------------------------------ terms
class AlignmentAtBestBin:
    """Eq. (4)-(6) with the yaw-bin head."""

    def __init__(self, point_loss, template: Template, yaw_head):
        self.point_loss, self.template, self.head = point_loss, template, yaw_head

    def __call__(self, out: dict, batch) -> dict:
        t = out["translation"]
        k = self.head.n_bins
        best, _ = best_yaw_bin(batch.points, t.detach(), k, lambda d: self.point_loss(d, out, detach=True),
                               self.template, batch.mask)
        yaw = yaw_bin_centers(k, dtype=t.dtype, device=t.device)[best]
        d = distance_to_template(self.template, batch.points, t, yaw)
        align = masked_mean(self.point_loss(d, out), batch.mask)
        ce = F.cross_entropy(out["yaw_logits"], best, reduction="none")
        return {"align": align.mean(), "yaw": ce.mean()}


class AlignmentAtPredictedYaw:
    """Table II (a): the loss at the regressed yaw, trained by gradient descent only."""

    def __init__(self, point_loss, template: Template, yaw_head):
        self.point_loss, self.template, self.head = point_loss, template, yaw_head

    def __call__(self, out: dict, batch) -> dict:
        d = distance_to_template(self.template, batch.points, out["translation"], self.head.decode(out))
        return {"align": masked_mean(self.point_loss(d, out), batch.mask).mean()}


class AlignmentOverHypotheses:
    """Table II (b) (mode "min") and (c) (mode "soft", temperature in the loss units)."""

    def __init__(self, point_loss, template: Template, yaw_head, mode: str, temperature: float = 1.0):
        if mode not in ("min", "soft"):
            raise ValueError(f"hypothesis mode must be 'min' or 'soft', not {mode!r}")
        self.point_loss, self.template, self.head = point_loss, template, yaw_head
        self.mode, self.temperature = mode, float(temperature)

    def __call__(self, out: dict, batch) -> dict:
        cand = self.head.candidates(out)                                            # (B, M)
        t = out["translation"]
        d = distance_to_template(self.template, batch.points[:, None], t[:, None], cand)   # (B, M, P)
        per_h = masked_mean(self.point_loss(d, out), batch.mask[:, None, :])        # (B, M)
        logp = torch.log_softmax(out["yaw_select"], dim=1)
        if self.mode == "min":
            best = per_h.detach().argmin(dim=1)
            align = per_h.gather(1, best[:, None])[:, 0]
            select = F.nll_loss(logp, best, reduction="none")
        else:
            w = torch.softmax(-per_h.detach() / self.temperature, dim=1)
            align = (w * per_h).sum(dim=1)
            select = -(w * logp).sum(dim=1)
        return {"align": align.mean(), "yaw": select.mean()}


class MultiViewConsistency:
    """Eq. (7)-(8) over the batch's frame pairs with the template's centre and front keypoints.

    Keypoints of a prediction (vehicle frame of its frame): X_centre = t, X_front = t + (l / 2) d, with d the
    head's heading vector rotated into the vehicle frame. For the bin head d is the expected unit vector
    under the softmax (= the unit vector of the yaw for a confident head, as in `losses.posed_keypoints`),
    which keeps the term smooth where the head hesitates between a heading and its reverse (an angle would
    be undefined there and its gradient unbounded).
    """

    def __init__(self, yaw_head, length: float):
        self.head = yaw_head
        self.length = float(length)

    def keypoints(self, out: dict, batch) -> torch.Tensor:
        """(B, 2, 3) centre and front keypoints in each object's vehicle frame."""
        t = out["translation"]
        d = self.head.direction(out)
        d3 = torch.cat([d, torch.zeros_like(d[:, :1])], dim=-1)
        centre, _ = to_vehicle(t, torch.zeros_like(t[:, 0]), batch.centre, batch.azimuth)
        front = centre + (self.length / 2) * rotate_z(d3, batch.azimuth)
        return torch.stack([centre, front], dim=1)

    def __call__(self, out: dict, batch) -> dict:
        t = out["translation"]
        if batch.pairs is None or len(batch.pairs[0]) == 0:
            return {"multiview": t.sum() * 0.0}
        i, j, T_i_from_j = batch.pairs
        kp = self.keypoints(out, batch)
        T = T_i_from_j.to(t.dtype)
        kp_j_in_i = kp[j] @ T[:, :3, :3].transpose(-1, -2) + T[:, None, :3, 3]
        per_kp = ((kp_j_in_i - kp[i]) ** 2).sum(dim=-1)                       # (n, 2): ||g_{i<-j} X^j - X^i||^2
        return {"multiview": per_kp.sum() / t.shape[0]}


class SupervisedBox:
    """Fully supervised reference: smooth-L1 translation + yaw-bin cross-entropy to box targets."""

    def __init__(self, yaw_head, beta: float = 0.1):
        if getattr(yaw_head, "kind", None) != "bins":
            raise ValueError("supervised_box needs the yaw-bin head")
        self.head, self.beta = yaw_head, float(beta)

    def __call__(self, out: dict, batch) -> dict:
        if batch.target_translation is None:
            raise ValueError("supervised_box: the batch carries no box targets")
        trans = F.smooth_l1_loss(out["translation"], batch.target_translation, beta=self.beta,
                                 reduction="none").sum(dim=-1)
        target = yaw_to_bin(batch.target_yaw, self.head.n_bins)
        return {"translation": trans.mean(), "yaw": F.cross_entropy(out["yaw_logits"], target)}


# ------------------------------------------------------------------------------------ composition
class Criterion:
    """Weighted sum of the components of the configured terms."""

    def __init__(self, terms: dict[str, Callable], weights: dict[str, float] | None = None):
        self.terms = terms
        self.weights = dict(weights or {})

    def __call__(self, out: dict, batch) -> tuple[torch.Tensor, dict[str, float]]:
        total = None
        parts: dict[str, float] = {}
        for name, term in self.terms.items():
            for comp, value in term(out, batch).items():
                key = f"{name}/{comp}"
                weighted = self.weights.get(comp, 1.0) * value
                total = weighted if total is None else total + weighted
                parts[key] = float(value.detach())
        parts["total"] = float(total.detach())
        return total, parts


def build_criterion(spec: dict, loss_cfg: dict, template: Template, yaw_head) -> Criterion:
    """Compose the criterion of one configuration.

    spec: the configuration (`terms`, `point_loss`, `yaw`); loss_cfg: `lifting.loss` (weights,
    hypothesis_temperature, supervised_beta).
    """
    point_loss = POINT_LOSSES[spec.get("point_loss", "squared")]()
    terms: dict[str, Callable] = {}
    for name in spec["terms"]:
        if name == "alignment":
            kind = spec["yaw"]["kind"]
            if kind == "bins":
                terms[name] = AlignmentAtBestBin(point_loss, template, yaw_head)
            elif kind == "vector":
                terms[name] = AlignmentAtPredictedYaw(point_loss, template, yaw_head)
            else:
                terms[name] = AlignmentOverHypotheses(point_loss, template, yaw_head, spec["yaw"]["mode"],
                                                      loss_cfg["hypothesis_temperature"])
        elif name == "multiview":
            terms[name] = MultiViewConsistency(yaw_head, template.spec.length)
        elif name == "supervised_box":
            terms[name] = SupervisedBox(yaw_head, loss_cfg["supervised_beta"])
        else:
            raise ValueError(f"unknown loss term {name!r} (alignment, multiview, supervised_box)")
    return Criterion(terms, loss_cfg.get("weights"))
