"""The tables' 95 % intervals keep their promise: simulated null and non-null comparisons through every noise path
(redsup.tables.coverage) are covered at least 93 % of the time; and the rules the intervals follow, by hand."""
import math

import numpy as np
import pytest

from redsup import stats
from redsup.tables import coverage, noise

SIMS = 1000


def test_every_noise_path_covers_at_least_93_percent(coverage_report):
    rows = coverage.measure(SIMS)
    coverage_report.extend(rows)
    low = [r for r in rows if r["coverage"] < coverage.TARGET]
    assert not low, low
    assert {r["path"] for r in rows} == set(coverage.PATHS)


def test_cluster_bootstrap_draws_whole_scenes():
    ids = [f"s{g}/{f}" for g in range(6) for f in range(3)]
    sets, sorted_ids = stats.resample_sets(ids, 20)
    for s in sets:
        scenes = [stats.cluster_of(sorted_ids[i]) for i in s]
        assert len(s) == 18  # 6 scenes of 3 frames each: every draw takes all 3 frames of a scene
        for scene in set(scenes):
            assert scenes.count(scene) % 3 == 0
    # a function of the ids only: the same draws in another order
    again, _ = stats.resample_sets(list(reversed(ids)), 20)
    assert all(np.array_equal(a, b) for a, b in zip(sets, again))


def test_ids_without_scene_resample_frames_one_by_one():
    draws, ids, members = stats.cluster_draws(["a", "b", "c"], 4)
    assert [list(m) for m in members] == [[0], [1], [2]] and draws.shape == (4, 3)


def test_bootstrap_of_a_mean_over_scenes_by_hand():
    # two scenes of two frames: scene means 1 and 3; per_unit mean over the drawn scenes' frames
    rec = noise.bootstrap({"a/0": 0.0, "a/1": 2.0, "b/0": 2.0, "b/1": 4.0}, n=50)
    assert rec["n_clusters"] == 2 and rec["n_units"] == 4
    assert set(np.round(rec["values"], 12)) <= {1.0, 2.0, 3.0}  # aa, ab/ba, bb


def test_paired_interval_is_t_over_clusters_by_hand():
    # replicate differences with variance v over G = 10 clusters: half width = t(9) * sqrt(v * 10 / 9)
    reps_a = np.linspace(0.0, 1.0, 200)
    rec_a = {"kind": "bootstrap", "values": list(reps_a), "units": "u", "n_units": 40, "n_clusters": 10}
    rec_b = {"kind": "bootstrap", "values": list(reps_a * 0.5), "units": "u", "n_units": 40, "n_clusters": 10}
    lo, hi, how = noise.difference_interval(0.3, 0.1, rec_a, rec_b)
    half = 2.2621571627409915 * math.sqrt(np.var(reps_a * 0.5, ddof=1) * 10 / 9)
    assert (hi - lo) / 2 == pytest.approx(half, rel=1e-9)
    assert (lo + hi) / 2 == pytest.approx(0.2)
    assert "paired cluster bootstrap" in how


def test_fewer_than_five_clusters_decide_nothing():
    rec = {"kind": "bootstrap", "values": [0.1, 0.2, 0.3], "units": "u", "n_units": 300, "n_clusters": 4}
    lo, hi, how = noise.difference_interval(1.0, 0.0, rec, rec)
    assert math.isnan(lo) and math.isnan(hi) and "4 clusters" in how
    seeded = noise.with_sampling(noise.seeds([1.0, 1.1, 0.9]), [rec, rec, rec])
    assert math.isnan(noise.difference_interval(1.0, 0.0, seeded, noise.seeds([0.0, 0.1, -0.1]))[0])


def test_a_cell_without_a_noise_record_decides_nothing():
    lo, hi, how = noise.difference_interval(2.0, 1.0, None, noise.seeds([1.0, 1.2, 0.8]))
    assert math.isnan(lo) and how == noise.NO_RECORD
    assert math.isnan(noise.value_interval(2.0, None)[0])
    assert noise.difference_interval(2.0, 1.0, noise.EXACT, noise.EXACT) == (1.0, 1.0, "exact values")


def test_seeds_and_sampling_add_with_satterthwaite_and_never_narrow():
    s_a, s_b = noise.seeds([1.0, 1.2, 1.4]), noise.seeds([0.0, 0.1, 0.2])
    seeds_only = noise.difference_interval(1.2, 0.1, s_a, s_b)
    boot = {"kind": "bootstrap", "values": list(np.linspace(-0.5, 0.5, 100)), "units": "u", "n_units": 60,
            "n_clusters": 12}
    both = noise.difference_interval(1.2, 0.1, noise.with_sampling(s_a, [boot] * 3),
                                     noise.with_sampling(s_b, [boot] * 3))
    assert both[1] - both[0] >= seeds_only[1] - seeds_only[0]
    # paired replicates on the same units cancel: the sampling part of a - b is 0, the seeds' part remains
    assert both[0] == pytest.approx(seeds_only[0])
