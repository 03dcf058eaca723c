"""`ppod --help` lists the subcommands without importing what their arguments need.

A fresh interpreter (the modules a process imports are the thing under test); no timing.
"""

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def _run(code: str) -> str:
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=240)
    assert out.returncode == 0, out.stderr
    return out.stdout


def test_ppod_help_lists_the_subcommands_without_importing_numba_or_the_benchmarks():
    code = (
        "import contextlib, io, json, sys\n"
        "from ppod_nodes.cli.main import SUBCOMMANDS, main\n"
        "out = io.StringIO()\n"
        "with contextlib.redirect_stdout(out):\n"
        "    try:\n"
        "        main(['--help'])\n"
        "    except SystemExit:\n"
        "        pass\n"
        "heavy = sorted(m for m in ('numba', 'scipy', 'can', 'matplotlib', 'cv2', 'rclpy') if m in sys.modules)\n"
        "bench = sorted(m for m in sys.modules if m.startswith('ppod_bench.'))\n"
        "print(json.dumps([heavy, bench, [n for n in SUBCOMMANDS if n not in out.getvalue()]]))\n"
    )
    heavy, bench, missing = json.loads(_run(code).splitlines()[-1])
    assert (heavy, bench, missing) == ([], [], [])
