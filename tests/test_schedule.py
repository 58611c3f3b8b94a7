"""redsup.schedule against DAGs scheduled by hand: the critical path and greedy list scheduling on 1, 2, 3 and
unboundedly many cores."""
import math

import pytest

from redsup import schedule

# A 4, B 3, C 2, D 5, E 1, F 5; C reads A, D reads B, E reads C and D; F stands alone. Remaining paths:
# E 1, C 2 + 1 = 3, D 5 + 1 = 6, A 4 + 3 = 7, B 3 + 6 = 9, F 5. Job-seconds: 20.
DURATIONS = {"A": 4.0, "B": 3.0, "C": 2.0, "D": 5.0, "E": 1.0, "F": 5.0}
DEPS = {"C": {"A"}, "D": {"B"}, "E": {"C", "D"}}


def test_critical_path_by_hand():
    assert schedule.remaining_paths(DURATIONS, DEPS) == {"A": 7.0, "B": 9.0, "C": 3.0, "D": 6.0, "E": 1.0, "F": 5.0}
    assert schedule.critical_path(DURATIONS, DEPS) == (["B", "D", "E"], 9.0)
    assert schedule.critical_path({}, {}) == ([], 0.0)


def test_makespan_by_hand():
    """1 core: every job in turn, 20 s. 2 cores: B and A start (9 and 7 the longest remaining paths); B ends at 3,
    D (6) starts; A ends at 4, F (5) before C (3); D ends at 8, C runs 8-10; F ends at 9; E waits for C: 10-11.
    3 cores: B, A, F at 0; D at 3, C at 4; D ends at 8, E 8-9, the critical path. Unbounded: the critical path."""
    assert schedule.makespan(DURATIONS, DEPS, 1) == 20.0
    assert schedule.makespan(DURATIONS, DEPS, 2) == 11.0
    assert schedule.makespan(DURATIONS, DEPS, 3) == 9.0
    assert schedule.makespan(DURATIONS, DEPS, math.inf) == 9.0


def test_the_longest_remaining_path_starts_first():
    """x1 (1 s) feeds x2 (10 s); a and b (6 s each) stand alone. On 2 cores, x1 (remaining 11) starts beside a, then
    x2 at 1 (ends 11) and b at 6 (ends 12): 12 s. Starting a and b first, as their names would, takes 6 + 1 + 10 =
    17 s."""
    durations = {"a": 6.0, "b": 6.0, "x1": 1.0, "x2": 10.0}
    deps = {"x2": ["x1"]}
    assert schedule.makespan(durations, deps, 2) == 12.0
    assert schedule.critical_path(durations, deps) == (["x1", "x2"], 11.0)


def test_bad_graphs_are_refused():
    with pytest.raises(ValueError, match="cycle"):
        schedule.makespan({"a": 1.0, "b": 1.0}, {"a": {"b"}, "b": {"a"}}, 2)
    with pytest.raises(ValueError, match="no duration"):
        schedule.critical_path({"a": 1.0}, {"a": {"z"}})
    with pytest.raises(ValueError, match="at least 1"):
        schedule.makespan(DURATIONS, DEPS, 0)
