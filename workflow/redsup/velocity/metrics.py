"""The TuSimple velocity-estimation protocol (McCraith ch. 3 eq. (4)), as the challenge script
(TuSimple/tusimple-benchmark `evaluate/velocity.py`, `bench_one_submit`).

E_v^S = mean over the vehicles of distance bin S of ||V - V_hat||^2, bins by the length of the
ground-truth position ||[z, x]|| (near < 20 m, medium 20-45 m, far >= 45 m; `datastats.distance_bin`),
E_v = mean of the three bin errors. The position error E_p is defined the same way on the last-frame
position. Empty bins: the challenge script's mean of an empty bin is NaN and so is its total
(`empty_bins="nan"`, what the command below prints); the workflow's tables use `empty_bins="skip"` (the
mean of the non-empty bins, `n_bins` says how many) so that a small profile without far vehicles still
has a total; on data where every bin has vehicles the two agree.

Command: ``python -m redsup.velocity.metrics --gt gt.json --pred pred.json`` (see `CLI_HELP`).
"""
from __future__ import annotations

import numpy as np

from redsup.datastats import distance_bin

BIN_NAMES = ("near", "medium", "far")
EMPTY_BINS = ("skip", "nan")


def squared_error(pred: np.ndarray, true: np.ndarray) -> np.ndarray:
    """Unreduced ||pred - true||^2 per row of (N, 2) arrays."""
    diff = np.asarray(pred, dtype=np.float64) - np.asarray(true, dtype=np.float64)
    return (diff * diff).sum(axis=-1)


def binned_error(errors: np.ndarray, bins: np.ndarray, prefix: str, empty_bins: str = "skip") -> dict[str, float]:
    """{prefix}_{near,medium,far}, {prefix} (mean of the bins; see `empty_bins`), n_{bin} counts."""
    if empty_bins not in EMPTY_BINS:
        raise ValueError(f"empty_bins must be one of {EMPTY_BINS}, not {empty_bins!r}")
    errors, bins = np.asarray(errors, dtype=np.float64), np.asarray(bins)
    out: dict[str, float] = {}
    per_bin = []
    for i, name in enumerate(BIN_NAMES):
        sel = errors[bins == i]
        value = float(sel.mean()) if sel.size else float("nan")
        out[f"{prefix}_{name}"] = value
        out[f"n_{name}"] = int(sel.size)
        if sel.size:
            per_bin.append(value)
    if empty_bins == "nan" and len(per_bin) < len(BIN_NAMES):
        out[prefix] = float("nan")
    else:
        out[prefix] = float(np.mean(per_bin)) if per_bin else float("nan")
    out["n_bins"] = len(per_bin)
    return out


def tusimple_metrics(v_pred, v_true, bins, p_pred=None, p_true=None, empty_bins: str = "skip") -> dict[str, float]:
    """Flat dict: E_v, E_v_near/medium/far, n_near/medium/far, n_bins, n; with positions also E_p and
    E_p_near/medium/far (vehicles whose predicted position is not finite are left out of E_p and counted
    in n_p_undefined)."""
    out = binned_error(squared_error(v_pred, v_true), bins, "E_v", empty_bins)
    out["n"] = int(len(np.asarray(bins)))
    if p_pred is not None:
        err = squared_error(p_pred, p_true)
        finite = np.isfinite(err)
        pos = binned_error(err[finite], np.asarray(bins)[finite], "E_p", empty_bins)
        out.update({k: v for k, v in pos.items() if k.startswith("E_p")})
        out["n_p_undefined"] = int((~finite).sum())
    return out


# ------------------------------------------------------------------------------------------------ command
CLI_HELP = """E_v and E_p of the TuSimple velocity challenge, printed as one JSON object.

Both files are the challenge's JSON: a list with one entry per clip, each a list of vehicles
  {"bbox": {"top": t, "left": l, "bottom": b, "right": r},
   "velocity": [v_forward, v_lateral], "position": [forward, lateral]}     (metres, m/s)
As the challenge script: every ground-truth vehicle is matched to the prediction of its clip whose bbox
is nearest (sum of |differences| of top, left, bottom, right; more than 10 px is an error); it is binned
by the length of its ground-truth position (near < 20 m, medium < 45 m, far); E_v / E_p per bin are the
mean squared error norms; E_v / E_p are the mean of the three bins, NaN when a bin is empty.
Output keys: E_v, E_v_near, E_v_medium, E_v_far, E_p, E_p_near, E_p_medium, E_p_far, n_near, n_medium,
n_far, n_bins, n.
"""


class ChallengeFileError(ValueError):
    """A challenge JSON file that cannot be evaluated, with its path."""


def _bbox(vehicle: dict, path, clip: int) -> np.ndarray:
    try:
        b = vehicle["bbox"]
        return np.array([b["top"], b["left"], b["bottom"], b["right"]], dtype=np.float64)
    except (KeyError, TypeError) as exc:
        raise ChallengeFileError(f"{path}: clip {clip}: vehicle without a bbox {{top, left, bottom, right}}") from exc


def match_files(gt_path, pred_path) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(v_pred, v_true, p_pred, p_true), each (N, 2), one row per ground-truth vehicle."""
    import json
    from pathlib import Path
    data = {}
    for key, path in (("gt", gt_path), ("pred", pred_path)):
        try:
            data[key] = json.loads(Path(path).read_text())
        except (OSError, ValueError) as exc:
            raise ChallengeFileError(f"{path}: cannot read JSON ({exc})") from exc
        if not isinstance(data[key], list):
            raise ChallengeFileError(f"{path}: expected a list of clips (each a list of vehicles)")
    if len(data["gt"]) != len(data["pred"]):
        raise ChallengeFileError(f"{pred_path}: {len(data['pred'])} clips, {gt_path} has {len(data['gt'])}")
    rows = {k: [] for k in ("vp", "vt", "pp", "pt")}
    for c, (gts, preds) in enumerate(zip(data["gt"], data["pred"])):
        boxes = np.array([_bbox(p, pred_path, c) for p in preds]).reshape(-1, 4)
        for gt in gts:
            diff = np.abs(boxes - _bbox(gt, gt_path, c)).sum(axis=1)
            if not len(diff) or diff.min() > 10:
                raise ChallengeFileError(f"{pred_path}: clip {c}: no prediction within 10 px of the ground-truth "
                                         f"bbox {gt['bbox']}")
            pred = preds[int(np.argmin(diff))]
            if "velocity" not in pred or "position" not in pred:
                raise ChallengeFileError(f"{pred_path}: clip {c}: prediction without position or velocity")
            rows["vp"].append(pred["velocity"])
            rows["vt"].append(gt["velocity"])
            rows["pp"].append(pred["position"])
            rows["pt"].append(gt["position"])
    return tuple(np.array(rows[k], dtype=np.float64).reshape(-1, 2) for k in ("vp", "vt", "pp", "pt"))


def evaluate_files(gt_path, pred_path) -> dict[str, float]:
    v_pred, v_true, p_pred, p_true = match_files(gt_path, pred_path)
    bins = distance_bin(p_true[:, 0], p_true[:, 1])
    out = tusimple_metrics(v_pred, v_true, bins, p_pred, p_true, empty_bins="nan")
    out.pop("n_p_undefined", None)
    return out


def main(argv: list[str] | None = None) -> int:
    import argparse
    import json
    import sys
    ap = argparse.ArgumentParser(prog="python -m redsup.velocity.metrics", description=CLI_HELP,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--gt", required=True, help="ground-truth JSON (list of clips of vehicles)")
    ap.add_argument("--pred", required=True, help="prediction JSON, same layout and bboxes")
    args = ap.parse_args(argv)
    try:
        result = evaluate_files(args.gt, args.pred)
    except ChallengeFileError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    print(json.dumps(result, indent=1, sort_keys=True))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
