"""redsup.studies.write_study, where the val studies of studies/ store their numbers, and the rule that tests import
the package only: benchmarks/, studies/, drills/ and tools/ are command lines over it."""
import json
import re
from pathlib import Path

import numpy as np

from redsup.studies import write_study

ROOT = Path(__file__).resolve().parents[1]


def test_write_study_stores_numpy_values_as_json(tmp_path):
    path = write_study("knob/seed0", {"e": np.float32(0.5), "n": np.int64(3), "bins": np.array([1.0, 2.0]),
                                      "path": Path("a/b"), "nan": float("nan")}, out_dir=tmp_path)
    assert path == tmp_path / "knob" / "seed0.json"
    back = json.loads(path.read_text())
    assert back["e"] == 0.5 and back["n"] == 3 and back["bins"] == [1.0, 2.0] and back["path"] == "a/b"
    assert np.isnan(back["nan"])


def test_every_study_stores_its_output():
    for script in sorted((ROOT / "studies").glob("*.py")):
        assert "write_study(" in script.read_text(), f"{script.name} does not write results/studies/<name>.json"


def test_tests_import_no_script_folder():
    folders = ("benchmarks", "studies", "drills", "tools", "docs")
    pattern = re.compile(r"""(sys\.path\.insert|spec_from_file_location|PYTHONPATH).*["'/](%s)["'/]""" % "|".join(folders))
    for test in sorted(Path(__file__).parent.glob("test_*.py")):
        hits = [line for line in test.read_text().splitlines() if pattern.search(line)]
        assert not hits, f"{test.name}: {hits}"
