"""The control tests reuse the estimation tests' independent rigid-body simulation (plate_sim.py)."""

import sys
from pathlib import Path

_ESTIMATION_TESTS = str(Path(__file__).resolve().parents[1] / "estimation")
if _ESTIMATION_TESTS not in sys.path:
    sys.path.insert(0, _ESTIMATION_TESTS)
