"""Street furniture (world.clutter, issue 11 §4 "Ch. 7 Table 1: too easy"): objects that are not cars on
the sidewalks, seen by camera and LiDAR, never labelled as cars."""
import copy
from pathlib import Path

import numpy as np
import pytest

from redsup import config
from redsup.world.common import derive_rng
from redsup.world.layout import build_world, frame_state
from redsup.world.prims import KIND_BARRIER
from redsup.world.sensors import make_rig
from redsup.world.shade import SceneView, render_camera

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def cfg():
    return config.load(ROOT / "config.yaml", {"profile": "tiny"})


def _clutter(world):
    st = world.static
    sel = st.kind == KIND_BARRIER
    return st.center[sel], st.half[sel]


def test_clutter_count_sizes_and_place(cfg):
    w = cfg["world"]
    rc = w["road"]
    hw, sw = rc["lane_width"] + rc["parking_width"], rc["sidewalk_width"]
    counts, spans = [], []
    for i in range(12):
        world = build_world(w, w["domains"]["kitti_like"], derive_rng(3, "clutter", i), 2)
        centre, half = _clutter(world)
        counts.append(len(centre))
        reach = w["render_distance"] + 30.0  # the scenery's x extent (layout.build_world)
        spans.append(float(world.ego.s[-1]) + 2 * reach)
        ay = np.abs(centre[:, 1])
        assert np.all(ay - half[:, 1] >= hw + 0.3 - 1e-9) and np.all(ay + half[:, 1] <= hw + sw + 1e-9)
        ground = world.road.height(centre[:, 0], centre[:, 1])
        assert np.allclose(centre[:, 2] - half[:, 2], ground - 0.1)  # standing on the (raised) sidewalk
        lo = min(k["height"][0] for k in w["clutter"]["kinds"].values())
        hi = max(k["height"][1] for k in w["clutter"]["kinds"].values())
        assert np.all((2 * half[:, 2] - 0.1 >= lo - 1e-9) & (2 * half[:, 2] - 0.1 <= hi + 1e-9))
        cars = world.cars["pos"]  # parked cars stand in the parking lane, never on clutter
        if len(cars) and len(centre):
            assert np.min(np.abs(np.abs(cars[:, 1])[:, None] - ay[None, :])) > 0.5
    expected = 2 * w["clutter"]["per_100m"] * np.array(spans) / 100.0
    assert sum(counts) == pytest.approx(expected.sum(), rel=0.15)


def test_clutter_is_seen_but_never_a_car(cfg):
    w = copy.deepcopy(cfg["world"])
    w["clutter"] = dict(w["clutter"], per_100m=30.0)  # dense, so the camera surely sees some
    dom = w["domains"]["kitti_like"]
    world = build_world(w, dom, derive_rng(3, "clutter", "view"), 2)
    cams, _ = make_rig(dom, w["rig"], w["lidar"])
    state = frame_state(world, 0, w["render_distance"] + 30.0)
    cam = cams[0]
    out = render_camera(cam, state.T_world_vehicle @ cam.T_vehicle_sensor, state.prims,
                        SceneView(world.road, world.style, world.cars, world.buildings), dom["appearance"], 0.0,
                        w["render_distance"], w["fog_distance"], derive_rng(0))
    hits = out["hits"]
    on_clutter = np.zeros(cam.n_rays, bool)
    box = (hits.prim >= 0) & (hits.prim < state.prims.n_box)
    on_clutter[box] = state.prims.kind[hits.prim[box]] == KIND_BARRIER
    assert on_clutter.sum() > 50
    assert np.all(out["instance"].ravel()[on_clutter] == 0)
