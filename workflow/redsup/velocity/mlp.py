"""The learned velocity estimator of McCraith ch. 3 §III-B and §V: an MLP on the flattened box track.

Psi(b) = MLP(vec(g(b))): g is the temporal Gaussian filter (`redsup.velocity.smoothing`), the boxes are
expressed in standardised image coordinates (footnote 2 of the chapter: (x - cx) / fx, (y - cy) / fy,
w / fx, h / fy, so the model does not depend on the image resolution), flattened frame by frame to a 4T
vector and standardised with the mean / std of the training inputs (kept in the model). The MLP has
`layers` hidden layers of `hidden` units, each Linear -> CReLU (written here: [relu(x), relu(-x)], doubling
the width) -> Dropout, and a linear output (vx, vz). Loss: ||V - Psi(b)||^2 per track (MSE on (vx, vz)),
Adam with exponential learning-rate decay per epoch.
"""
from __future__ import annotations

import statistics
import time
from collections.abc import Callable

import numpy as np
import torch
from torch import nn
from tqdm import tqdm

from redsup.optim import Adam
from redsup.velocity.geometry import Calibration
from redsup.velocity.smoothing import gaussian_smooth


class CReLU(nn.Module):
    """Concatenated ReLU (Shang et al. 2016): [relu(x), relu(-x)] along the last axis."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.cat([torch.relu(x), torch.relu(-x)], dim=-1)


class VelocityMLP(nn.Module):
    """in_dim -> `layers` x (Linear(., hidden), CReLU, Dropout) -> Linear(2 hidden, 2)."""

    def __init__(self, in_dim: int, hidden: int = 70, layers: int = 4, dropout: float = 0.2, out_dim: int = 2):
        super().__init__()
        self.register_buffer("mean", torch.zeros(in_dim))
        self.register_buffer("std", torch.ones(in_dim))
        blocks: list[nn.Module] = []
        width = in_dim
        for _ in range(layers):
            blocks += [nn.Linear(width, hidden), CReLU(), nn.Dropout(dropout)]
            width = 2 * hidden
        blocks.append(nn.Linear(width, out_dim))
        self.net = nn.Sequential(*blocks)
        self.config = {"in_dim": in_dim, "hidden": hidden, "layers": layers, "dropout": dropout, "out_dim": out_dim}

    def set_normalisation(self, features: np.ndarray) -> None:
        """Input standardisation from the training inputs (N, in_dim)."""
        x = torch.as_tensor(np.asarray(features), dtype=torch.float32)
        self.mean.copy_(x.mean(dim=0))
        self.std.copy_(x.std(dim=0, unbiased=False).clamp_min(1e-6))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net((x - self.mean) / self.std)


FEATURES = ("absolute", "relative", "relative_metric")


def box_features(boxes: np.ndarray, calib: Calibration, sigma: float, mode: str = "absolute") -> np.ndarray:
    """vec(g(b)) of tracks (N, T, 4) in standardised image coordinates: float32 (N, 4T).

    mode "absolute" (the thesis): the T standardised boxes. mode "relative": the same track as the last
    standardised box (4 values: where and how large the vehicle is) followed by every frame's change from
    the last box divided by the last box's standardised height (4T values: motion relative to the apparent
    size, the scale-free form of dZ / Z), so the motion is not a small difference of large, strongly
    correlated inputs: (N, 4T + 4). mode "relative_metric": the relative features followed by every change divided
    by the last standardised height once more (4T values: a box of height h = f H / Z changes by dh = -f H dZ / Z^2,
    so dh / h^2 = -dZ / (f H), proportional to the metric displacement, the quantity v_z is linear in):
    (N, 8T + 4)."""
    if mode not in FEATURES:
        raise ValueError(f"unknown box feature mode {mode!r} (have {FEATURES})")
    b = gaussian_smooth(boxes, sigma)
    norm = np.stack([(b[..., 0] - calib.cx) / calib.fx, (b[..., 1] - calib.cy) / calib.fy,
                     b[..., 2] / calib.fx, b[..., 3] / calib.fy], axis=-1)
    n, T = norm.shape[0], norm.shape[-2]
    if mode == "absolute":
        return norm.reshape(n, T * 4).astype(np.float32)
    last = norm[:, -1, :]
    scale = np.maximum(last[:, 3:4], 1e-4)[:, None, :]
    rel = (norm - last[:, None, :]) / scale
    parts = [last, rel.reshape(n, T * 4)]
    if mode == "relative_metric":
        parts.append((rel / scale).reshape(n, T * 4))
    return np.concatenate(parts, axis=1).astype(np.float32)


def velocity_loss(pred: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """Unreduced ||V - Psi(b)||^2 per track."""
    return ((pred - target) ** 2).sum(dim=-1)


def train_mlp(features: np.ndarray, targets: np.ndarray, *, hidden: int, layers: int, dropout: float, lr: float,
              lr_decay: float, epochs: int, batch_size: int, seed: int,
              eval_sets: dict[str, tuple[np.ndarray, np.ndarray]] | None = None,
              on_epoch: Callable[[int, dict], None] | None = None,
              device: str = "cpu", select_on: str | None = None) -> tuple[VelocityMLP, list[dict]]:
    """Train from scratch; returns the model (eval mode) and one dict per epoch: train_loss (mean
    ||V - Psi(b)||^2 over the epoch's batches, dropout on), lr, and `<name>_loss` for every eval set (dropout
    off). ``select_on``: the name of an eval set whose loss picks the epoch whose weights are returned (the
    lowest; ``best`` marks it in the curve); None: the last epoch's."""
    if len(features) == 0:
        raise ValueError("no training tracks")
    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    x = torch.as_tensor(features, dtype=torch.float32, device=device)
    y = torch.as_tensor(targets, dtype=torch.float32, device=device)
    model = VelocityMLP(x.shape[1], hidden, layers, dropout)
    model.set_normalisation(features)
    model.to(device)
    opt = Adam(model.parameters(), lr=lr)
    evals = {k: (torch.as_tensor(a, dtype=torch.float32, device=device),
                 torch.as_tensor(b, dtype=torch.float32, device=device))
             for k, (a, b) in (eval_sets or {}).items() if len(a)}
    if select_on is not None and select_on not in evals:
        raise ValueError(f"select_on={select_on!r} is not an eval set (have {sorted(evals)})")
    curve = []
    best: tuple[float, int, dict] | None = None
    n = len(x)
    for epoch in tqdm(range(epochs), desc="train velocity MLP", unit="epoch", mininterval=5):
        opt.lr = lr * lr_decay ** epoch                        # exponential decay per epoch
        model.train()
        order = torch.randperm(n, generator=gen).to(device)
        total = 0.0
        for start in range(0, n, batch_size):
            idx = order[start:start + batch_size]
            loss = velocity_loss(model(x[idx]), y[idx]).mean()
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            total += loss.detach().item() * len(idx)
        row = {"train_loss": total / n, "lr": opt.lr}
        if evals:
            model.eval()
            with torch.no_grad():
                for name, (ex, ey) in evals.items():
                    row[f"{name}_loss"] = float(velocity_loss(model(ex), ey).mean())
        curve.append(row)
        if select_on is not None and (best is None or row[f"{select_on}_loss"] < best[0]):
            best = (row[f"{select_on}_loss"], epoch, {k: v.detach().clone() for k, v in model.state_dict().items()})
        if on_epoch is not None:
            on_epoch(epoch, row)
    if best is not None:
        model.load_state_dict(best[2])
        for epoch, row in enumerate(curve):
            row["best"] = float(epoch == best[1])
    model.eval()
    return model, curve


def model_device(model: nn.Module) -> torch.device:
    return next(model.parameters()).device


def resolve_device(name: str) -> str:
    """cpu | cuda | auto (cuda when available)."""
    if name == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    return name


def predict(model: VelocityMLP, features: np.ndarray) -> np.ndarray:
    """(N, 2) velocity estimates [vx, vz] (eval mode, no gradients)."""
    model.eval()
    with torch.no_grad():
        x = torch.as_tensor(features, dtype=torch.float32, device=model_device(model))
        return model(x).cpu().numpy().astype(np.float64)


def save_model(model: VelocityMLP, path, config: dict | None = None, extra: dict | None = None) -> None:
    """The one checkpoint format (redsup.checkpoint, kind "velocity_mlp"): the state, the construction
    arguments and ``extra`` in meta, the resolved workflow ``config`` beside them (written atomically)."""
    from redsup import checkpoint

    checkpoint.save(path, "velocity_mlp", {"net": model}, config or {}, {"network": model.config, **(extra or {})})


def load_model(path) -> tuple[VelocityMLP, dict]:
    """(model in eval mode, meta) of a checkpoint written by ``save_model``."""
    from redsup import checkpoint

    data = checkpoint.load(path, "velocity_mlp")
    model = VelocityMLP(**data["meta"]["network"])
    model.load_state_dict(data["state"]["net"])
    model.eval()
    return model, data["meta"]


def forward_time_ms(model: VelocityMLP, boxes: np.ndarray, calib: Calibration, sigma: float,
                    repeats: int = 200, mode: str = "absolute") -> dict[str, float]:
    """Time per track of the whole estimator Psi (smoothing, features, forward pass, result back on the
    CPU), one track at a time, on the model's device and the current torch threads: median and 90th
    percentile over `repeats` calls (after 10 warm-up calls)."""
    model.eval()
    track = np.asarray(boxes[:1], dtype=np.float64)
    device = model_device(model)

    def once():
        with torch.no_grad():
            model(torch.from_numpy(box_features(track, calib, sigma, mode)).to(device)).cpu()

    for _ in range(10):
        once()
    times = []
    for _ in range(max(repeats, 1)):
        start = time.perf_counter()
        once()
        times.append((time.perf_counter() - start) * 1000.0)
    return {"forward_ms_median": statistics.median(times), "forward_ms_p90": float(np.percentile(times, 90))}
