"""The world's car population (issue 11 §3 "Cars"): KITTI-like size spread from a mixture of body styles,
styles with different rendered shapes, and a 3D template that stays one fixed mean car of its own."""
import ast
from pathlib import Path

import numpy as np
import pytest

from redsup import config
from redsup.det3d import template as det3d_template
from redsup.world.common import derive_rng, pose
from redsup.world.layout import build_world, make_style, sample_cars
from redsup.world.prims import STYLE_INDEX, STYLES, car_prims
from redsup.world.road import Road
from redsup.world.sensors import Camera, intrinsics
from redsup.world.shade import SceneView, render_camera

ROOT = Path(__file__).resolve().parents[1]
# KITTI object training labels, class Car: mean and std of (l, w, h) in metres
KITTI_CAR = {"mean": np.array([3.88, 1.63, 1.53]), "std": np.array([0.43, 0.10, 0.14])}


@pytest.fixture(scope="module")
def cfg():
    return config.load(ROOT / "config.yaml", {"profile": "tiny"})


@pytest.fixture(scope="module")
def population(cfg):
    """Every car (parked, following, oncoming) of 30 urban kitti_like scenes, as the generator places them."""
    w = cfg["world"]
    sizes, styles = [], []
    for i in range(30):
        world = build_world(w, w["domains"]["kitti_like"], derive_rng(1, "population", i), 2)
        sizes.append(world.cars["size"])
        styles.append(world.cars["style"])
    return np.concatenate(sizes), np.concatenate(styles)


def test_car_population_has_the_size_spread_of_kitti_cars(population):
    """Measured on 3722 cars: mean (3.874, 1.633, 1.527) m, std (0.435, 0.100, 0.134) m against KITTI's
    (3.88, 1.63, 1.53) +- (0.43, 0.10, 0.14). Tolerance: 0.05 m on the means, 12 % on the stds."""
    sizes, _ = population
    assert len(sizes) > 2000
    assert np.all(np.abs(sizes.mean(0) - KITTI_CAR["mean"]) < 0.05), sizes.mean(0)
    assert np.all(np.abs(sizes.std(0) / KITTI_CAR["std"] - 1.0) < 0.12), sizes.std(0)
    # not one Gaussian: the height distribution is skewed by the tall SUVs / vans
    h = sizes[:, 2]
    assert np.mean(((h - h.mean()) / h.std()) ** 3) > 0.5


def test_at_least_three_body_styles_each_a_tenth_of_the_cars(population):
    _, styles = population
    share = np.bincount(styles, minlength=len(STYLES)) / len(styles)
    assert np.sum(share >= 0.1) >= 3, dict(zip([s.name for s in STYLES], share))
    # the styles differ in size, not only in shape: SUVs / vans are taller than hatchbacks
    sizes, _ = population
    assert sizes[styles == STYLE_INDEX["suv_van"], 2].mean() > sizes[styles == STYLE_INDEX["hatchback"], 2].mean() + 0.2


def test_sample_cars_refuses_an_unknown_style():
    with pytest.raises(ValueError, match="unknown body style"):
        sample_cars(np.random.default_rng(0), 3, {"limousine": {"share": 1.0, "length": [5, 0.1],
                                                              "width": [1.8, 0.1], "height": [1.4, 0.1]}})


def _profile(cfg, style: int, size=(4.0, 1.7, 1.5)):
    """Rendered surface height above the road (m) along the car's centre line, seen by a camera looking
    straight down from 12 m (its z-depth is the vertical distance): (x in the car frame, height, instance)
    per image row of the centre column."""
    road = Road(np.array([-1000.0, 1000.0]), np.zeros(2), np.zeros(2), 0.0, 50.0, 0.0)
    dom = cfg["world"]["domains"]["kitti_like"]
    look = make_style(3, dom, cfg["world"]["road"], [[0.0, 0.12, 3.0, 6.0]], [1.75, -1.75], [], 50.0, 3.5)
    table = {"track_id": np.array([1]), "size": np.array([size]), "style": np.array([style]),
             "colour": np.array([[0.6, 0.1, 0.1]]), "phase": np.zeros(1)}
    prims = car_prims([[0.0, 0.0, 0.0]], np.eye(3)[None], np.array([size]), np.array([0]), np.array([style]))
    down = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])  # columns: camera x, y, z in world
    cam = Camera("cam_top", intrinsics(41, 161, 10.0), 41, 161, np.eye(4))
    out = render_camera(cam, pose(down, [0.0, 0.0, 12.0]), prims, SceneView(road, look, table, {}),
                        dom["appearance"], 0.0, 200.0, 350.0, derive_rng(0))
    depth = out["depth"][:, 20].astype(np.float64)
    x = -(np.arange(cam.height) - cam.K[1, 2]) / cam.K[1, 1] * depth  # camera y points along world -x
    return x, 12.0 - depth, out["instance"][:, 20]


def test_body_styles_have_different_rendered_shapes(cfg):
    """Same overall size, different proportions: every style's rendered roof line reaches the full height,
    its bonnet the style's body height, and the roof lines differ between styles; near the tail a sedan
    shows its boot (body height), a hatchback its cabin (full height)."""
    size = (4.0, 1.7, 1.5)
    profiles = {}
    for s in STYLES:
        i = STYLE_INDEX[s.name]
        x, height, inst = _profile(cfg, i, size)
        on = inst > 0
        assert on.sum() > 60 and size[0] - 0.25 < np.ptp(x[on]) < size[0]  # a cabin can hide the tail's last cm
        assert height[on].max() == pytest.approx(size[2], abs=0.01)
        front = on & (x > 0.4 * size[0] - 0.2) & (x < 0.5 * size[0] - 0.05)
        assert front.any() and np.allclose(height[front], s.body_height * size[2], atol=0.01)
        # the rows are the same for every style (one camera): profiles compare row by row
        profiles[s.name] = (np.where(on, height, 0.0), x)
    names = list(profiles)
    for a in range(len(names)):
        for b in range(a + 1, len(names)):
            diff = np.abs(profiles[names[a]][0] - profiles[names[b]][0])
            assert np.sum(diff > 0.05) >= 3, (names[a], names[b])
    for name, tail_is_cabin in (("sedan", False), ("hatchback", True)):
        h, x = profiles[name]
        tail = (x < -0.45 * size[0]) & (x > -0.5 * size[0] + 0.03) & (h > 0)
        assert tail.any()
        expected = size[2] if tail_is_cabin else STYLES[STYLE_INDEX[name]].body_height * size[2]
        assert np.allclose(h[tail], expected, atol=0.01), (name, h[tail])


def test_template_is_one_fixed_mean_car_of_its_own(population):
    """The methods' prior (det3d/template.py) is one fixed car, near the population mean, and its code does
    not read the world generator (no import of redsup.world)."""
    source = Path(det3d_template.__file__).read_text()
    imported = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            imported |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            imported.add(node.module or "")
    assert not any("world" in name for name in imported), imported
    spec = det3d_template.TemplateSpec()
    size = np.array([spec.length, spec.width, spec.height])
    sizes, _ = population
    assert np.all(np.abs(size / sizes.mean(0) - 1.0) < 0.03)
    assert np.all(np.abs(size - KITTI_CAR["mean"]) < 0.05)
