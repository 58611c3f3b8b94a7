"""The fixed template car ("average car", McCraith ch. 6 S_0 / ch. 7 M) and its distance field.

The template is a two-box body (lower body + cabin) of 3.9 x 1.6 x 1.5 m sampled as surface points on a
regular spacing, origin at the centre of its tight bounding box, x forward, z up: one fixed "average car"
(the thesis' weak prior; KITTI's mean Car is 3.88 x 1.63 x 1.53 m) with generic sedan proportions (body
56 % of the height, cabin half the length, centred 7 % of the length behind the middle, 88 % of the width).
It is the methods' prior, not read from the world generator: the world's cars are a mixture of body styles
and sizes (redsup.world.prims.STYLES, world.traffic.car_size) that the template matches only on average.

The one-sided Chamfer term min_{X' in S} ||X - X'|| is precomputed once as the exact distance from every
node of a regular 3D grid around the template to the nearest surface point (scipy cKDTree), so posing the
template for B objects x K yaw candidates x P points costs one trilinear lookup per point, independent of
the number of template vertices. `distance_to_template` transforms points into the template frame of
each candidate pose and samples the grid with `torch.nn.functional.grid_sample` (differentiable w.r.t.
points, translation and yaw). Outside the grid the value grows linearly: d(clamp(p)) + ||p - clamp(p)||
(an upper bound of the true distance, tight far away).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F


@dataclass(frozen=True)
class TemplateSpec:
    length: float = 3.9
    width: float = 1.6
    height: float = 1.5
    body_height_frac: float = 0.56
    cabin_length_frac: float = 0.5
    cabin_centre_x_frac: float = -0.07
    cabin_width_frac: float = 0.88
    spacing: float = 0.05        # surface sampling step (m)
    voxel: float = 0.05          # distance-field grid step (m)
    margin: float = 1.5          # grid extends this far beyond the bounding box (m)


@dataclass(frozen=True)
class Template:
    """Surface points (V, 3) and distance field (nz, ny, nx) on the grid origin + voxel * (ix, iy, iz)."""
    spec: TemplateSpec
    points: np.ndarray
    field: torch.Tensor          # (nz, ny, nx) distances in metres
    origin: np.ndarray           # (3,) grid coordinates of node (0, 0, 0): x, y, z
    voxel: float

    @property
    def size(self) -> np.ndarray:
        """(l, w, h) of the tight box B_0 around the template (the predicted box size)."""
        return np.array([self.spec.length, self.spec.width, self.spec.height])

    @property
    def upper(self) -> np.ndarray:
        """(3,) coordinates (x, y, z) of the last grid node."""
        nz, ny, nx = self.field.shape
        return self.origin + self.voxel * np.array([nx - 1, ny - 1, nz - 1])

    def to(self, device=None, dtype=None) -> "Template":
        """Copy with the field on another device / dtype (the points stay numpy)."""
        return Template(self.spec, self.points, self.field.to(device=device, dtype=dtype), self.origin, self.voxel)


def _box_parts(spec: TemplateSpec) -> list[tuple[np.ndarray, np.ndarray]]:
    """(centre, half extent) of the lower body and the cabin, template frame (origin at the box centre)."""
    z0 = -spec.height / 2
    hb = spec.body_height_frac * spec.height
    body = (np.array([0.0, 0.0, z0 + hb / 2]), np.array([spec.length, spec.width, hb]) / 2)
    overlap = 0.05 * hb   # the cabin reaches into the body so the shared face is interior to the union
    cab_h = spec.height - hb + overlap
    cabin = (np.array([spec.cabin_centre_x_frac * spec.length, 0.0, spec.height / 2 - cab_h / 2]),
             np.array([spec.cabin_length_frac * spec.length, spec.cabin_width_frac * spec.width, cab_h]) / 2)
    return [body, cabin]


def _box_sdf(points: np.ndarray, centre: np.ndarray, half: np.ndarray) -> np.ndarray:
    q = np.abs(points - centre) - half
    outside = np.linalg.norm(np.maximum(q, 0.0), axis=-1)
    inside = np.minimum(q.max(axis=-1), 0.0)
    return outside + inside


def _face_samples(centre: np.ndarray, half: np.ndarray, spacing: float) -> np.ndarray:
    out = []
    for axis in range(3):
        a, b = [k for k in range(3) if k != axis]
        na = max(2, int(np.ceil(2 * half[a] / spacing)) + 1)
        nb = max(2, int(np.ceil(2 * half[b] / spacing)) + 1)
        ua, ub = np.meshgrid(np.linspace(-half[a], half[a], na), np.linspace(-half[b], half[b], nb),
                             indexing="ij")
        for sign in (-1.0, 1.0):
            p = np.zeros((ua.size, 3))
            p[:, axis] = sign * half[axis]
            p[:, a] = ua.ravel()
            p[:, b] = ub.ravel()
            out.append(p + centre)
    return np.unique(np.round(np.concatenate(out), 9), axis=0)


def template_surface(spec: TemplateSpec = TemplateSpec()) -> np.ndarray:
    """(V, 3) points on the surface of the union of body and cabin, spaced about `spec.spacing` apart."""
    parts = _box_parts(spec)
    pts = np.concatenate([_face_samples(c, h, spec.spacing) for c, h in parts])
    sdf = np.min(np.stack([_box_sdf(pts, c, h) for c, h in parts]), axis=0)
    return pts[sdf > -1e-9]


def build_template(spec: TemplateSpec = TemplateSpec(), workers: int = 1) -> Template:
    """Sample the template surface and precompute its distance field (a second or two at 5 cm)."""
    pts = template_surface(spec)
    half = np.array([spec.length, spec.width, spec.height]) / 2
    n = np.ceil(2 * (half + spec.margin) / spec.voxel).astype(int) + 1          # nodes per axis x, y, z
    origin = -(n - 1) * spec.voxel / 2
    axes = [origin[k] + spec.voxel * np.arange(n[k]) for k in range(3)]
    zz, yy, xx = np.meshgrid(axes[2], axes[1], axes[0], indexing="ij")
    nodes = np.stack([xx.ravel(), yy.ravel(), zz.ravel()], axis=1)
    from scipy.spatial import cKDTree  # ~1 s of import, needed only when a template grid is built

    dist, _ = cKDTree(pts).query(nodes, workers=workers)
    field = torch.from_numpy(dist.reshape(n[2], n[1], n[0]).astype(np.float32))
    return Template(spec, pts, field, origin, float(spec.voxel))


def spec_from_config(section) -> TemplateSpec:
    """The template of a stage's config section: ``lifting`` (``template: {voxel, margin}``) or
    ``lidar_detector`` (``template_voxel``); the car itself is always the default `TemplateSpec`."""
    if "template" in section:
        return TemplateSpec(voxel=float(section["template"]["voxel"]), margin=float(section["template"]["margin"]))
    return TemplateSpec(voxel=float(section["template_voxel"]))


def save_template(path, template: Template) -> None:
    """The template (surface points, distance field, grid) and its spec as one npz, written atomically: built
    once per stage by rule ``template_field`` instead of in every training job (the k-d tree's import alone
    is half a second)."""
    import json
    from dataclasses import asdict

    from redsup.fileio import save_npz_atomic

    save_npz_atomic(path, points=template.points, field=template.field.numpy(), origin=template.origin,
                    voxel=np.float64(template.voxel), spec=np.array(json.dumps(asdict(template.spec), sort_keys=True)))


def load_template(path, spec: TemplateSpec) -> Template:
    """A template written by `save_template`; it must have been built from ``spec`` (the caller's config),
    else a ValueError names the file and the differing fields."""
    import json
    from dataclasses import asdict

    try:
        with np.load(path, allow_pickle=False) as z:
            saved = json.loads(str(z["spec"]))
            points, field, origin, voxel = z["points"], z["field"], z["origin"], float(z["voxel"])
    except (OSError, KeyError, ValueError) as exc:
        raise ValueError(f"{path}: not a template file ({type(exc).__name__}: {exc})") from None
    want = asdict(spec)
    diff = sorted(k for k in set(want) | set(saved) if want.get(k) != saved.get(k))
    if diff:
        raise ValueError(f"{path}: built for another template ({', '.join(f'{k} {saved.get(k)} != {want.get(k)}' for k in diff)}); "
                         "rebuild it (rule template_field)")
    return Template(spec, points, torch.from_numpy(np.ascontiguousarray(field, dtype=np.float32)), origin, voxel)


def _rotate_into_template(points: torch.Tensor, translation: torch.Tensor, yaw: torch.Tensor) -> torch.Tensor:
    """Points (..., P, 3) in the template frame of poses (translation (..., 3), yaw (...)): R(-yaw)(p - t)."""
    rel = points - translation.unsqueeze(-2)
    c = torch.cos(yaw).unsqueeze(-1)
    s = torch.sin(yaw).unsqueeze(-1)
    x, y = rel[..., 0], rel[..., 1]
    return torch.stack([c * x + s * y, -s * x + c * y, rel[..., 2].expand_as(c * x)], dim=-1)


def sample_field(template: Template, local: torch.Tensor) -> torch.Tensor:
    """Distance (...,) of template-frame points (..., 3): trilinear inside the grid, linear growth outside."""
    field = template.field.to(device=local.device, dtype=local.dtype)
    lo = torch.as_tensor(template.origin, device=local.device, dtype=local.dtype)
    hi = torch.as_tensor(template.upper, device=local.device, dtype=local.dtype)
    clamped = torch.minimum(torch.maximum(local, lo), hi)
    outside = torch.linalg.vector_norm(local - clamped, dim=-1)
    grid = (2 * (clamped - lo) / (hi - lo) - 1).reshape(1, -1, 1, 1, 3)
    inside = F.grid_sample(field[None, None], grid, mode="bilinear", padding_mode="border", align_corners=True)
    return inside.reshape(local.shape[:-1]) + outside


def distance_to_template(template: Template, points, translation, yaw):
    """Distance of points to the nearest template surface point for a batch of poses.

    points (..., P, 3), translation (..., 3), yaw (...) broadcast over their leading dimensions, e.g.
    points (B, 1, P, 3), translation (B, 1, 3) and yaw (B, K) give (B, K, P). Torch inputs keep autograd;
    numpy inputs return numpy (float64 math).
    """
    is_numpy = not isinstance(points, torch.Tensor)
    if is_numpy:
        points = torch.as_tensor(np.asarray(points, dtype=np.float64))
    dtype, device = points.dtype, points.device
    translation = torch.as_tensor(translation, dtype=dtype, device=device)
    yaw = torch.as_tensor(yaw, dtype=dtype, device=device)
    d = sample_field(template, _rotate_into_template(points, translation, yaw))
    return d.numpy() if is_numpy else d


def nearest_template_point_distance_bruteforce(template: Template, points, translation, yaw,
                                               chunk: int = 8192, exact: bool = True):
    """Reference for `distance_to_template`: min over all template points (same broadcasting).

    Cost grows with the template's vertex count; for tests and the benchmark only. exact=False uses
    torch.cdist's faster matrix-product formula (about 1e-4 m error near zero distance).
    """
    is_numpy = not isinstance(points, torch.Tensor)
    if is_numpy:
        points = torch.as_tensor(np.asarray(points, dtype=np.float64))
    dtype, device = points.dtype, points.device
    translation = torch.as_tensor(translation, dtype=dtype, device=device)
    yaw = torch.as_tensor(yaw, dtype=dtype, device=device)
    local = _rotate_into_template(points, translation, yaw)
    flat = local.reshape(-1, 3)
    surf = torch.as_tensor(template.points, dtype=dtype, device=device)
    out = torch.empty(flat.shape[0], dtype=dtype, device=device)
    mode = "donot_use_mm_for_euclid_dist" if exact else "use_mm_for_euclid_dist"
    for s in range(0, flat.shape[0], chunk):
        out[s:s + chunk] = torch.cdist(flat[s:s + chunk], surf, compute_mode=mode).min(dim=1).values
    d = out.reshape(local.shape[:-1])
    return d.numpy() if is_numpy else d
