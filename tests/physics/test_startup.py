"""Start-up of a small call: `ppod field ... --json` loads only what it needs.

Each test runs a fresh interpreter (the modules a process imports are the thing under test);
correctness only, no timing.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

#: Modules the field command's start-up must not import (heavy, and none of them used there).
#: ``scipy`` itself is imported by ``import numba`` (a version check) and stays allowed.
NOT_ON_THE_FIELD_PATH = ("scipy.linalg", "scipy.integrate", "scipy.optimize", "scipy.sparse", "scipy.special",
                         "numpy.f2py", "matplotlib", "cv2", "rclpy", "ppod_ros.planning")


def _run(code: str, **env: str) -> str:
    environ = {**os.environ, **env}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=240,
                         env=environ)
    assert out.returncode == 0, out.stderr
    return out.stdout


def test_ppod_field_json_imports_no_scipy_linalg_plotting_vision_or_ros(tmp_path):
    target = tmp_path / "f.json"
    code = (
        "import json, sys\n"
        "from ppod_nodes.cli.main import main\n"
        f"status = main(['field', 'config/motions/Sink.yaml', '--json', {str(target)!r}, '--quiet'])\n"
        f"print(json.dumps([status, sorted(m for m in sys.modules if m.split('.')[0] in "
        f"{{'scipy', 'numpy', 'matplotlib', 'cv2', 'rclpy', 'ppod_ros'}})]))\n"
    )
    status, modules = json.loads(_run(code).splitlines()[-1])
    assert status == 0
    loaded = [m for m in modules if any(m == bad or m.startswith(bad + ".") for bad in NOT_ON_THE_FIELD_PATH)]
    assert loaded == []
    field = json.loads(target.read_text())
    assert len(field["velocity"]) == 21 * 21


def test_scipy_linalg_imported_after_the_kernels_load_is_complete_and_numba_keeps_blas():
    # The JIT kernel (PPOD_AOT=0): _numba_start.prepare serves numba's BLAS check.
    code = (
        "import numpy as np\n"
        "from ppod_ros.motion import PlateMotion\n"
        "from ppod_ros.parts import PointPart\n"
        "from ppod_ros.physics import solve_field\n"
        "m = PlateMotion.from_yaml('config/motions/Sink.yaml')\n"
        "solve_field(m, PointPart(0.3), [[0.02, 0.0]])\n"
        "import sys\n"
        "assert 'scipy.linalg' not in sys.modules and 'scipy.linalg.cython_blas' not in sys.modules\n"
        "import numba, numba.np.arraymath\n"
        "assert numba.np.arraymath._HAVE_BLAS\n"
        "# BLAS and LAPACK from compiled code, scipy.linalg imported by numba itself at the first call\n"
        "f = numba.njit(lambda a, b: (a @ b, np.linalg.solve(a, b[:, 0])))\n"
        "a = np.array([[2.0, 1.0], [1.0, 3.0]]); b = np.array([[1.0], [2.0]])\n"
        "prod, sol = f(a, b)\n"
        "assert np.allclose(prod, [[4.0], [7.0]]) and np.allclose(sol, [0.2, 0.6])\n"
        "import scipy.linalg, scipy.linalg.cython_blas as blas\n"
        "assert scipy.linalg.cython_blas is blas and 'dgemm' in blas.__pyx_capi__\n"
        "assert np.allclose(scipy.linalg.solve(a, b[:, 0]), sol)\n"
        "print('ok')\n"
    )
    assert _run(code, PPOD_AOT="0").strip().endswith("ok")

