"""The scorecard under the old rules beside the current one, on one finished build's tables (issue 10):
a command-line wrapper over `redsup.tables.before_after`.

Usage: python tools/scorecard_before_after.py BUILD_DIR [OLD_COMMIT]
"""
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "workflow"))

from redsup.tables.before_after import main  # noqa: E402

if __name__ == "__main__":
    sys.exit(main())
