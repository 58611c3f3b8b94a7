"""The lifting network (McCraith ch. 6 Fig. 2), Frustum-PointNet style, on one object's points at a time.

- `PointEncoder`: a shared per-point MLP (Phi's trunk); the object feature is the max over the real points
  (padding is masked out, so any number of points >= 1 and batch size 1 work).
- `translation`: MLP on the object feature -> (3,) translation of the template in the object frame
  (`redsup.lifting.frames`); with `context_dim` > 0 the head also sees where the object is
  (`frames.context_features`: viewing azimuth, range, height), which the object frame hides.
- a yaw head (on its own MLP branch of the object feature), one of
    `BinYawHead`         K logits over the bins of `redsup.det3d.losses.yaw_bin_centers` (Phi_r, sec. III-C),
    `VectorYawHead`      (x1, x2) with yaw = atan2(x1, x2) (Table II row a, "arctan"),
    `HypothesisYawHead`  M (x1, x2) candidates and M selection logits (Table II rows b, c);
  each knows its test-time yaw (`decode`) and a differentiable heading vector for the consistency loss
  (`direction`: bins give the expected unit vector under the softmax, which is short when the head is unsure,
  so the front keypoint stays well defined where an angle would not be).
- `variance`: Psi, per point from [point feature, object feature] -> log sigma^2(X) of eq. (3), squashed
  into [log_var_min, log_var_max] (a floor keeps sigma away from 0, where eq. (3) is unbounded below).

Outputs are a dict: translation (B, 3), log_var (B, P), and the yaw head's entries (logits / vector /
vectors + select).
"""
from __future__ import annotations

import math

import torch
from torch import nn

from redsup.det3d.losses import yaw_bin_centers

CONTEXT_DIM = 4   # frames.context_features


def mlp(sizes: list[int], last_activation: bool = True) -> nn.Sequential:
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[i], sizes[i + 1]))
        if last_activation or i < len(sizes) - 2:
            layers.append(nn.ReLU())
    return nn.Sequential(*layers)


class PointEncoder(nn.Module):
    """Shared point MLP; returns (early per-point features (B, P, C0), object feature (B, C))."""

    def __init__(self, widths: list[int], in_channels: int = 3):
        super().__init__()
        self.early = mlp([in_channels, widths[0]])
        self.late = mlp(list(widths))
        self.out_channels = widths[-1]

    def forward(self, points: torch.Tensor, mask: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        early = self.early(points)
        late = self.late(early)
        neg = torch.finfo(late.dtype).min
        pooled = torch.where(mask[..., None], late, torch.full_like(late, neg)).max(dim=1).values
        return early, pooled


def _unit(v: torch.Tensor) -> torch.Tensor:
    return v / torch.linalg.vector_norm(v, dim=-1, keepdim=True).clamp_min(1e-6)


class BinYawHead(nn.Module):
    """K yaw-bin logits; test yaw = the arg-max bin's centre, soft yaw = angle of the expected unit vector."""
    kind = "bins"

    def __init__(self, in_channels: int, n_bins: int):
        super().__init__()
        self.n_bins = n_bins
        self.fc = nn.Linear(in_channels, n_bins)

    def forward(self, feature: torch.Tensor) -> dict:
        return {"yaw_logits": self.fc(feature)}

    def bin_centers(self, like: torch.Tensor) -> torch.Tensor:
        return yaw_bin_centers(self.n_bins, dtype=like.dtype, device=like.device)

    def decode(self, out: dict) -> torch.Tensor:
        logits = out["yaw_logits"]
        return self.bin_centers(logits)[logits.argmax(dim=1)]

    def direction(self, out: dict) -> torch.Tensor:
        """(B, 2) expected heading unit vector (cos, sin) under the softmax; shorter when uncertain."""
        logits = out["yaw_logits"]
        p = torch.softmax(logits, dim=1)
        yaws = self.bin_centers(logits)
        return torch.stack([(p * torch.cos(yaws)).sum(1), (p * torch.sin(yaws)).sum(1)], dim=-1)


class VectorYawHead(nn.Module):
    """(x1, x2) regression, yaw = atan2(x1, x2) (Table II (a): "theta = arctan(x1 / x2)")."""
    kind = "vector"

    def __init__(self, in_channels: int):
        super().__init__()
        self.fc = nn.Linear(in_channels, 2)

    def forward(self, feature: torch.Tensor) -> dict:
        return {"yaw_vector": self.fc(feature)}

    def decode(self, out: dict) -> torch.Tensor:
        v = out["yaw_vector"]
        return torch.atan2(v[..., 0], v[..., 1])

    def direction(self, out: dict) -> torch.Tensor:
        yaw = self.decode(out)
        return torch.stack([torch.cos(yaw), torch.sin(yaw)], dim=-1)


class HypothesisYawHead(nn.Module):
    """M (x1, x2) yaw candidates and M selection logits; test yaw = the selected candidate's angle."""
    kind = "hypotheses"

    def __init__(self, in_channels: int, n_hypotheses: int):
        super().__init__()
        self.n = n_hypotheses
        self.fc = nn.Linear(in_channels, 2 * n_hypotheses)
        self.select = nn.Linear(in_channels, n_hypotheses)
        # spread the initial candidates around the circle (diverse hypotheses from the start)
        with torch.no_grad():
            ang = torch.arange(n_hypotheses, dtype=torch.float32) * (2 * math.pi / n_hypotheses)
            self.fc.bias.copy_(torch.stack([torch.sin(ang), torch.cos(ang)], dim=1).reshape(-1))

    def forward(self, feature: torch.Tensor) -> dict:
        v = self.fc(feature).reshape(feature.shape[0], self.n, 2)
        return {"yaw_vectors": v, "yaw_select": self.select(feature)}

    def candidates(self, out: dict) -> torch.Tensor:
        v = out["yaw_vectors"]
        return torch.atan2(v[..., 0], v[..., 1])                        # (B, M)

    def decode(self, out: dict) -> torch.Tensor:
        cand = self.candidates(out)
        return cand.gather(1, out["yaw_select"].argmax(dim=1, keepdim=True))[:, 0]

    def direction(self, out: dict) -> torch.Tensor:
        yaw = self.candidates(out).gather(1, out["yaw_select"].argmax(dim=1, keepdim=True).detach())[:, 0]
        return torch.stack([torch.cos(yaw), torch.sin(yaw)], dim=-1)


def make_yaw_head(spec: dict, in_channels: int) -> nn.Module:
    """spec: {kind: bins, n_bins: K} | {kind: vector} | {kind: hypotheses, n_hypotheses: M}."""
    kind = spec["kind"]
    if kind == "bins":
        return BinYawHead(in_channels, int(spec["n_bins"]))
    if kind == "vector":
        return VectorYawHead(in_channels)
    if kind == "hypotheses":
        return HypothesisYawHead(in_channels, int(spec["n_hypotheses"]))
    raise ValueError(f"unknown yaw head kind {kind!r} (bins, vector, hypotheses)")


class LiftingNet(nn.Module):
    """Phi (translation + yaw head) and Psi (per-point log variance) on a shared point MLP."""

    def __init__(self, yaw_spec: dict, point_widths=(64, 128, 256), head_widths=(256, 128),
                 variance_widths=(128, 64), log_var_range=(-6.0, 2.0), context_dim: int = 0):
        super().__init__()
        self.encoder = PointEncoder(list(point_widths))
        c = self.encoder.out_channels
        self.context_dim = int(context_dim)
        # two branches on the object feature: the translation's gradients (large, from the alignment loss)
        # do not crowd out the yaw classifier's in a shared head
        self.head = mlp([c + self.context_dim, *head_widths])
        self.yaw_branch = mlp([c + self.context_dim, *head_widths])
        self.translation = nn.Linear(head_widths[-1], 3)
        self.yaw = make_yaw_head(yaw_spec, head_widths[-1])
        self.variance = nn.Sequential(mlp([point_widths[0] + c, *variance_widths]), nn.Linear(variance_widths[-1], 1))
        self.log_var_min, self.log_var_max = (float(v) for v in log_var_range)

    def forward(self, points: torch.Tensor, mask: torch.Tensor, context: torch.Tensor | None = None) -> dict:
        """points (B, P, 3) in the object frames, mask (B, P) bool (at least one True per row), context
        (B, context_dim) when the network was built with one."""
        early, pooled = self.encoder(points, mask)
        g = pooled
        if self.context_dim:
            if context is None or context.shape[-1] != self.context_dim:
                raise ValueError(f"this network needs a (B, {self.context_dim}) context (frames.context_features)")
            g = torch.cat([pooled, context.to(pooled.dtype)], dim=-1)
        out = {"translation": self.translation(self.head(g))}
        out.update(self.yaw(self.yaw_branch(g)))
        per_point = torch.cat([early, pooled[:, None, :].expand(-1, early.shape[1], -1)], dim=-1)
        raw = self.variance(per_point)[..., 0]
        span = self.log_var_max - self.log_var_min
        out["log_var"] = self.log_var_min + span * torch.sigmoid(raw)
        return out


def build_model(net_cfg: dict, yaw_spec: dict) -> LiftingNet:
    """The network of one configuration from the `lifting.network` section and the run's yaw spec."""
    return LiftingNet(yaw_spec, point_widths=tuple(net_cfg["point_mlp"]), head_widths=tuple(net_cfg["head_mlp"]),
                      variance_widths=tuple(net_cfg["variance_mlp"]),
                      log_var_range=(math.log(net_cfg["sigma_min"] ** 2), math.log(net_cfg["sigma_max"] ** 2)),
                      context_dim=CONTEXT_DIM if net_cfg.get("position_input", False) else 0)
