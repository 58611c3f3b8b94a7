"""How often the tables' 95 % intervals cover the truth: simulated comparisons through the project's own noise
paths (``redsup.tables.noise``), shaped like the real tables.

Each path simulates two rows of a table many times, with a known true difference (0: a null effect, or a
non-null one), builds their cells' noise records with the functions the stages use (``seeds``, ``bootstrap``,
``with_sampling``) and counts how often ``difference_interval`` covers the true difference. The generative model
is a two-way random-effects one: a trained model's seed shifts all its units, a scene shifts all its frames and
the effect itself varies by seed and by scene, frames add their own noise.

    python -m redsup.tables.coverage [--sims N]     # prints the coverage of every path (Markdown)
"""
from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from redsup.tables import noise

TARGET = 0.93  # the coverage every path must reach (nominal 95 %)


@dataclass(frozen=True)
class Shape:
    """One table's shape: seeds a row, test scenes and frames a scene (a sequence: uneven sizes)."""
    seeds: int
    frames: tuple[int, ...]  # frames of each test scene

    def unit_ids(self, clustered: bool) -> list[str]:
        """Unit ids: ``"<scene>/<frame>"`` when the frames are nested in scenes, else one cluster a frame."""
        if clustered:
            return [f"s{g:02d}/{f:03d}" for g, n in enumerate(self.frames) for f in range(n)]
        return [f"f{k:04d}" for k in range(sum(self.frames))]

    def scene_of(self) -> np.ndarray:
        return np.repeat(np.arange(len(self.frames)), self.frames)


# the shapes of the real tables: ch. 4 / 5 depth (3 seeds, 10 test scenes of 10 frames), a grid over few uneven
# scenes (the fewest clusters a verdict is given on; and a harder case, one scene 6x another), velocity-like clips
# of a few vehicles each
SHAPES = {
    "depth": Shape(3, (10,) * 10),
    "few uneven scenes": Shape(3, (5, 15, 8, 12, 10)),
    "few very uneven scenes": Shape(3, (4, 25, 9, 16, 6)),
    "clips": Shape(3, (3, 2, 4, 1, 3, 2, 5, 2, 3, 2, 4, 3, 2, 1, 3, 2, 4, 2, 3, 2)),
}


@dataclass(frozen=True)
class Path:
    """A noise path: which records the two rows carry and how the rows relate."""
    seeds: bool        # rows average several trained models (seed records)
    bootstrap: bool    # cells carry their test-sampling replicates
    paired: bool       # both rows read the same trained models (an adaptation of a baseline) / the same units
    clustered: bool    # frames nested in scenes that share an effect


PATHS = {
    "seeds only": Path(seeds=True, bootstrap=False, paired=False, clustered=False),
    "paired seeds": Path(seeds=True, bootstrap=False, paired=True, clustered=False),
    "bootstrap only (independent frames)": Path(seeds=False, bootstrap=True, paired=True, clustered=False),
    "bootstrap only (clustered units)": Path(seeds=False, bootstrap=True, paired=True, clustered=True),
    "seeds + bootstrap (clustered units)": Path(seeds=True, bootstrap=True, paired=False, clustered=True),
    "paired seeds + bootstrap (clustered units)": Path(seeds=True, bootstrap=True, paired=True, clustered=True),
}

# standard deviations of the effects (Abs Rel-like scale): a seed's shift, a scene's shift, the effect's variation
# by seed and by scene, a frame's noise
SD = {"seed": 0.006, "scene": 0.03, "effect_seed": 0.004, "effect_scene": 0.01, "frame": 0.02}


def _rows(path: Path, shape: Shape, effect: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Per-seed, per-unit values of the two rows (seeds x units): row b = row a's base + the effect."""
    n_seeds = shape.seeds if path.seeds else 1
    scene = shape.scene_of()
    n_units, n_scenes = len(scene), len(shape.frames)
    scene_fx = rng.normal(0, SD["scene"], n_scenes)[scene] if path.clustered else 0.0
    effect_scene = rng.normal(0, SD["effect_scene"], n_scenes)[scene] if path.clustered else 0.0

    def model(n):  # n trained models: a seed shift each, frames' noise
        return (rng.normal(0, SD["seed"] if path.seeds else 0.0, (n, 1)) + scene_fx
                + rng.normal(0, SD["frame"], (n, n_units)))

    a = model(n_seeds)
    effect_seed = rng.normal(0, SD["effect_seed"] if path.seeds else 0.0, (n_seeds, 1))
    if path.paired:  # the same models, changed by the method (e.g. adapted): the effect varies by seed and scene
        b = a + effect + effect_seed + effect_scene + rng.normal(0, SD["frame"] / 2, (n_seeds, n_units))
    else:  # independently trained models of another method
        b = model(n_seeds) + effect + effect_scene
    return a, b


def _records(values: np.ndarray, ids: Sequence[str], path: Path, pair: str) -> dict:
    boots = [noise.bootstrap(dict(zip(ids, v))) for v in values] if path.bootstrap else []
    if not path.seeds:
        return boots[0]
    rec = noise.seeds(values.mean(axis=1), pair)
    return noise.with_sampling(rec, boots) if boots else rec


def coverage(path: Path, shape: Shape, effect: float, sims: int, seed: int = 0) -> float:
    """Share of ``sims`` simulated comparisons whose 95 % interval of (row b - row a) covers ``effect``."""
    rng = np.random.default_rng(seed)
    ids = shape.unit_ids(path.clustered)
    hits = 0
    for _ in range(sims):
        a, b = _rows(path, shape, effect, rng)
        ra = _records(a, ids, path, "base")
        rb = _records(b, ids, path, "base" if path.paired else "other")
        lo, hi, how = noise.difference_interval(float(b.mean()), float(a.mean()), rb, ra)
        if math.isnan(lo):
            raise RuntimeError(f"no interval for {path} on {shape}: {how}")
        hits += lo <= effect <= hi
    return hits / sims


def measure(sims: int = 1000) -> list[dict]:
    """Coverage of every path, for a null effect and a non-null one: paths over clustered units on every shape,
    the others (whose cluster structure plays no part) on the depth tables' shape."""
    out = []
    for name, path in PATHS.items():
        shapes = SHAPES if path.clustered else {"depth": SHAPES["depth"]}
        for shape_name, shape in shapes.items():
            for effect in (0.0, 0.02):
                out.append({"path": name, "shape": shape_name, "effect": effect,
                            "coverage": coverage(path, shape, effect, sims, seed=len(out))})
    return out


def markdown(rows: list[dict], sims: int) -> str:
    lines = [f"| noise path | table shape | true effect | coverage of the 95 % interval ({sims} simulations) |",
             "|---|---|---|---|"]
    lines += [f"| {r['path']} | {r['shape']} | {r['effect']:g} | {100 * r['coverage']:.1f} % |" for r in rows]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m redsup.tables.coverage", description=__doc__.split("\n\n")[0])
    ap.add_argument("--sims", type=int, default=1000, help="simulated comparisons per path, shape and effect")
    args = ap.parse_args(argv)
    print(markdown(measure(args.sims), args.sims))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
