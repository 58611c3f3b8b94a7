"""One-off generator of the KITTI AP fixture (not run by the suite; its outputs are committed).

    python tests/data/kitti_official/make_fixture.py PORT_DIR

writes gt/ and det/ (KITTI label_2 files; detections with the score in field 16) and expected.json: the
AP of the *official python port of the devkit* (github.com/traveller59/kitti-object-eval-python, its
eval.py / kitti_common.py / rotate_iou.py in PORT_DIR, with `second.core...nms_gpu` imported as
`rotate_iou` and skimage not needed; numba's CUDA simulator: NUMBA_ENABLE_CUDASIM=1). Keys as
`redsup.det3d.kitti_eval.evaluate`: `{cls}_{2d|bev|3d|aos}_{thr}/{easy|moderate|hard}_{R11|R40}`, thresholds
per class: the standard one (Car/Van 0.7, others 0.5) and 0.5. R40 = mean of the port's precision[1:41]; aos:
the port's orientation similarity of the 2d metric (`eval_class(..., compute_aos=True)`), sampled the same way.

    python tests/data/kitti_official/make_fixture.py PORT_DIR --expected-only

recomputes expected.json from the committed gt/ and det/ without writing them again.
"""
from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
FX, CX, CY, W, H = 721.5377, 609.5593, 172.854, 1242, 375
CLASSES = {"Car": (1.5, 1.6, 3.9, 0.55), "Pedestrian": (1.75, 0.6, 0.8, 0.15), "Cyclist": (1.7, 0.6, 1.8, 0.1),
           "Van": (2.2, 1.9, 5.0, 0.1), "Person_sitting": (1.2, 0.6, 0.9, 0.1)}
STANDARD = {"Car": 0.7, "Van": 0.7, "Pedestrian": 0.5, "Cyclist": 0.5, "Person_sitting": 0.5}
PORT_CLASS = {"Car": 0, "Pedestrian": 1, "Cyclist": 2, "Van": 3, "Person_sitting": 4}


def bbox_of(cx, cy, cz, h, w, l, ry):
    xs, zs = np.array([1, 1, -1, -1]) * l / 2, np.array([1, -1, -1, 1]) * w / 2
    c, s = math.cos(ry), math.sin(ry)
    px = np.concatenate([c * xs + s * zs] * 2) + cx
    pz = np.concatenate([-s * xs + c * zs] * 2) + cz
    py = np.concatenate([np.zeros(4), -np.full(4, h)]) + cy
    u, v = FX * px / pz + CX, FX * py / pz + CY
    raw = np.array([u.min(), v.min(), u.max(), v.max()])
    box = np.clip(raw, [0, 0, 0, 0], [W - 1, H - 1, W - 1, H - 1])
    area = (raw[2] - raw[0]) * (raw[3] - raw[1])
    trunc = 1 - (box[2] - box[0]) * (box[3] - box[1]) / area if area > 0 else 1.0
    return box, float(np.clip(trunc, 0, 1))


def line(cls, trunc, occ, box, h, w, l, cx, cy, cz, ry, score=None):
    alpha = ry - math.atan2(cx, cz)
    f = [cls, f"{trunc:.2f}", str(occ), f"{alpha:.2f}", *(f"{v:.2f}" for v in box), f"{h:.2f}", f"{w:.2f}",
         f"{l:.2f}", f"{cx:.2f}", f"{cy:.2f}", f"{cz:.2f}", f"{ry:.2f}"]
    return " ".join(f + ([f"{score:.4f}"] if score is not None else []))


def generate(n_frames=90, seed=13):
    rng = np.random.default_rng(seed)
    names, probs = list(CLASSES), np.array([v[3] for v in CLASSES.values()])
    (HERE / "gt").mkdir(exist_ok=True)
    (HERE / "det").mkdir(exist_ok=True)
    for k in range(n_frames):
        gt, det = [], []
        for _ in range(rng.integers(3, 9)):
            cls = str(rng.choice(names, p=probs / probs.sum()))
            h0, w0, l0, _ = CLASSES[cls]
            h, w, l = (round(v * (1 + 0.08 * rng.standard_normal()), 2) for v in (h0, w0, l0))
            cz, cx = round(rng.uniform(4, 55), 2), round(rng.uniform(-14, 14), 2)
            cy, ry = round(1.65 + 0.1 * rng.standard_normal(), 2), round(rng.uniform(-math.pi, math.pi), 2)
            if cz < 2 + abs(cx) * 0.3:
                continue
            box, trunc = bbox_of(cx, cy, cz, h, w, l, ry)
            if box[2] - box[0] < 2:
                continue
            occ = int(rng.choice([0, 1, 2, 3], p=[0.6, 0.25, 0.1, 0.05]))
            gt.append(line(cls, trunc, occ, box, h, w, l, cx, cy, cz, ry))
            if rng.random() < 0.88:
                dx, dy, dz = 0.25 * rng.standard_normal(), 0.1 * rng.standard_normal(), 0.3 * rng.standard_normal()
                dh, dw, dl = (v * (1 + 0.05 * rng.standard_normal()) for v in (h, w, l))
                dry = ry + 0.06 * rng.standard_normal()
                dbox = np.clip(box + 3 * rng.standard_normal(4), 0, [W - 1, H - 1, W - 1, H - 1])
                q = math.exp(-(dx * dx + dz * dz) / 0.2)
                score = float(np.clip(0.5 * q + 0.5 * rng.random(), 0.01, 0.999))
                det.append(line(cls, 0, 0, dbox, dh, dw, dl, cx + dx, cy + dy, cz + dz, dry, score))
        for _ in range(rng.integers(0, 3)):                            # false positives
            cls = str(rng.choice(names, p=probs / probs.sum()))
            h, w, l, _ = CLASSES[cls]
            cx, cz, ry = rng.uniform(-12, 12), rng.uniform(6, 50), rng.uniform(-3, 3)
            box, _ = bbox_of(cx, 1.65, cz, h, w, l, ry)
            if box[2] - box[0] > 2:
                det.append(line(cls, 0, 0, box, h, w, l, cx, 1.65, cz, ry, float(rng.uniform(0.01, 0.7))))
        if rng.random() < 0.3:
            gt.append("DontCare -1 -1 -10 " + " ".join(f"{v:.2f}" for v in (500, 160, 560, 200))
                      + " -1 -1 -1 -1000 -1000 -1000 -10")
        (HERE / "gt" / f"{k:06d}.txt").write_text("\n".join(gt) + "\n")
        (HERE / "det" / f"{k:06d}.txt").write_text("\n".join(det) + ("\n" if det else ""))


def official(port_dir: str) -> dict:
    sys.path.insert(0, port_dir)
    import eval as port            # noqa: E402  (the official port, outside this project)
    import kitti_common as kc      # noqa: E402
    ids = list(range(len(list((HERE / "gt").glob("*.txt")))))
    gts = kc.get_label_annos(str(HERE / "gt"), ids)
    dts = kc.get_label_annos(str(HERE / "det"), ids)
    present = sorted({n for a in gts for n in a["name"] if n in PORT_CLASS}, key=PORT_CLASS.get)
    out = {}
    for metric, mname in enumerate(("2d", "bev", "3d")):
        for cls in present:
            thrs = sorted({STANDARD[cls], 0.5}, reverse=True)
            mo = np.zeros((len(thrs), 3, 1))
            mo[:, metric, 0] = thrs
            ret = port.eval_class(gts, dts, [PORT_CLASS[cls]], [0, 1, 2], metric, mo, compute_aos=metric == 0)
            curves = {mname: ret["precision"]} | ({"aos": ret["orientation"]} if metric == 0 else {})
            for name, curve in curves.items():        # (1, 3, T, 41)
                for d, dname in enumerate(("easy", "moderate", "hard")):
                    for t, thr in enumerate(thrs):
                        key = f"{cls}_{name}_{thr:g}/{dname}"
                        out[f"{key}_R11"] = float(curve[0, d, t, 0::4].sum() / 11 * 100)
                        out[f"{key}_R40"] = float(curve[0, d, t, 1:].sum() / 40 * 100)
    return out


if __name__ == "__main__":
    if "--expected-only" not in sys.argv[2:]:
        generate()
    (HERE / "expected.json").write_text(json.dumps(official(sys.argv[1]), indent=1, sort_keys=True) + "\n")
