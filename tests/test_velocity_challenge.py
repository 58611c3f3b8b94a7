"""TuSimple velocity metrics against a hand-computed case (tests/data/tusimple_velocity), the challenge
script's rules: nearest-bbox matching, bins by ||[z, x]||, NaN total when a bin is empty.

Vehicles (gt position -> bin by norm; squared velocity / position errors):
  A [19, 6]  |.|=19.92 near     E_v 1  E_p 1
  B [18, 9]  |.|=20.12 medium   E_v 2  E_p 4     (z alone would say near)
  C [50, 0]  far                E_v 9  E_p 4
  D [30, -2] medium             E_v 4  E_p 1
E_v = (1 + (2 + 4)/2 + 9)/3 = 13/3, E_p = (1 + (4 + 1)/2 + 4)/3 = 2.5.
"""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from conftest import ROOT
from redsup.datastats import distance_bin
from redsup.velocity.metrics import ChallengeFileError, evaluate_files, main, tusimple_metrics

DATA = ROOT / "tests" / "data" / "tusimple_velocity"


def test_bins_by_the_length_of_the_position():
    assert list(distance_bin([19, 18, 50, 30], [6, 9, 0, -2])) == [0, 1, 2, 1]
    assert list(distance_bin([18, 19.99, 20.0, 44.99, 45.0])) == [0, 0, 1, 1, 2]


def test_hand_computed_fixture():
    m = evaluate_files(DATA / "gt.json", DATA / "pred.json")
    assert m["E_v_near"] == pytest.approx(1) and m["E_v_medium"] == pytest.approx(3) and m["E_v_far"] == pytest.approx(9)
    assert m["E_v"] == pytest.approx(13 / 3)
    assert m["E_p_near"] == pytest.approx(1) and m["E_p_medium"] == pytest.approx(2.5) and m["E_p_far"] == pytest.approx(4)
    assert m["E_p"] == pytest.approx(2.5)
    assert (m["n_near"], m["n_medium"], m["n_far"], m["n"]) == (1, 2, 1, 4)


def test_empty_bin_total_is_nan_as_the_challenge_but_skipped_in_the_workflow():
    v = np.array([[1.0, 0.0], [0.0, 0.0]])
    challenge = tusimple_metrics(v, np.zeros((2, 2)), np.array([0, 1]), empty_bins="nan")
    workflow = tusimple_metrics(v, np.zeros((2, 2)), np.array([0, 1]))
    assert np.isnan(challenge["E_v"]) and workflow["E_v"] == pytest.approx(0.5) and workflow["n_bins"] == 2


def test_unmatched_prediction_is_an_error(tmp_path):
    pred = json.loads((DATA / "pred.json").read_text())
    pred[0][0]["bbox"]["top"] += 30
    (tmp_path / "pred.json").write_text(json.dumps(pred))
    with pytest.raises(ChallengeFileError, match="no prediction within 10 px"):
        evaluate_files(DATA / "gt.json", tmp_path / "pred.json")


def test_command_prints_the_flat_dict(capsys):
    assert main(["--gt", str(DATA / "gt.json"), "--pred", str(DATA / "pred.json")]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["E_v"] == pytest.approx(13 / 3) and out["E_p"] == pytest.approx(2.5)
    help_text = subprocess.run([sys.executable, "-m", "redsup.velocity.metrics", "--help"], capture_output=True,
                               text=True, check=True, env={**os.environ, "PYTHONPATH": str(ROOT / "workflow")}).stdout
    assert "bbox" in help_text and "position" in help_text and "NaN" in help_text
