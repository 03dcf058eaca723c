"""The ahead-of-time serial field kernel (``_aot``) and the lazy ``njit`` (``_jit``).

The module is built by ``./run.sh setup``; if it is missing the fixture builds it (1-5 minutes
once). Correctness only: identical results to the JIT kernel, numba not imported on the small-call
path, fallbacks when the module does not fit; no timing.
"""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ppod_ros.parts import PointPart
from ppod_ros.physics import _aot, _jit, _threads, grid_configs, solve_field, solve_fields
from ppod_ros.physics.settings import SolverSettings
from tests.physics.physics_suite import suite_motion

ROOT = Path(__file__).resolve().parents[2]
#: Modules a small ``ppod field`` call served by the ahead-of-time kernel does not import.
LAZY_MODULES = ("ppod_ros.physics._solve", "ppod_ros.physics.cycle", "ppod_ros.physics.dynamics",
                "ppod_ros.physics._dynamics_kernel", "ppod_ros.physics._closed_form")


@pytest.fixture(scope="module")
def aot_kernel():
    _aot.ensure_built()
    fn = _aot.kernel()
    assert fn is not None, "the ahead-of-time field kernel could not be built here"
    return fn


def _both(monkeypatch, call):
    """``call()`` with the ahead-of-time kernel, then with numba's JIT kernel (PPOD_AOT=0)."""
    monkeypatch.setenv(_aot.ENV_SWITCH, "1")
    a = call()
    monkeypatch.setenv(_aot.ENV_SWITCH, "0")
    b = call()
    monkeypatch.delenv(_aot.ENV_SWITCH)
    return a, b


def _same(a, b):
    assert np.array_equal(a.velocity, b.velocity, equal_nan=True)
    assert np.array_equal(a.cycle_start, b.cycle_start, equal_nan=True)
    assert np.array_equal(a.reason_code, b.reason_code)
    assert np.array_equal(a.periods, b.periods)
    assert np.array_equal(a.stick_fraction, b.stick_fraction, equal_nan=True)


@pytest.mark.parametrize("name", ["Sink", "Stick2D", "LineSinkXPlant", "Swirl3H", "NearContactLoss"])
def test_point_fields_are_bit_for_bit_those_of_the_jit_kernel(aot_kernel, monkeypatch, name):
    motion = suite_motion(name)
    configs = grid_configs(np.linspace(-0.1, 0.1, 9), np.linspace(-0.1, 0.1, 7))
    settings = SolverSettings().replace(cache=False, threads=1)
    a, b = _both(monkeypatch, lambda: solve_field(motion, PointPart(0.3), configs, settings))
    _same(a, b)
    assert a.valid.any()


@pytest.mark.parametrize("integrator", ["bs3", "dop853"])
def test_other_integrators_and_picard_match_too(aot_kernel, monkeypatch, integrator):
    motion = suite_motion("Whirlpool")
    configs = grid_configs(np.linspace(-0.08, 0.08, 5), np.linspace(-0.08, 0.08, 5))
    for fp in ("anderson", "picard"):
        settings = SolverSettings().replace(cache=False, threads=1, integrator=integrator, fixed_point=fp)
        a, b = _both(monkeypatch, lambda s=settings: solve_field(motion, PointPart(0.5, 0.6), configs, s))
        _same(a, b)


def test_rigid_part_matches(aot_kernel, monkeypatch, rigid_part):
    motion = suite_motion("RigidU1")
    configs = [[0.0, 0.0, 0.3], [0.03, -0.02, 1.2], [-0.05, 0.04, 4.0]]
    settings = SolverSettings().replace(cache=False, threads=1)
    a, b = _both(monkeypatch, lambda: solve_field(motion, rigid_part, configs, settings))
    _same(a, b)
    assert a.valid.any()


def test_warm_started_batches_with_secants_match(aot_kernel, monkeypatch):
    from ppod_ros.physics import WarmStarts

    motions = [suite_motion("Sink"), suite_motion("Whirlpool")]
    configs = np.random.default_rng(3).uniform(-0.06, 0.06, (37, 2))
    settings = SolverSettings().replace(cache=False, threads=1)

    def twice():
        warm = WarmStarts()
        solve_fields(motions, PointPart(0.3), configs, settings, warm=warm)
        return solve_fields(motions, PointPart(0.3), configs + 1e-4, settings, warm=warm)

    a, b = _both(monkeypatch, twice)
    assert np.array_equal(a.velocity, b.velocity, equal_nan=True)
    assert np.array_equal(a.periods, b.periods)


def test_arguments_that_do_not_fit_the_export_go_to_the_jit_kernel(aot_kernel):
    n = 4
    good = [1, np.zeros((1, 2, 3)), np.zeros(1, np.int64), np.zeros((1, n, 7)), np.zeros((1, n, 2)),
            np.zeros((1, n), np.bool_), np.ones((1, n)), np.zeros((1, n, 0, 2)), np.zeros((1, n, 0, 2)),
            np.zeros((1, n), np.int64), np.ones(1), np.ones(1, np.int64), np.zeros((3, 3)), np.zeros(3),
            np.zeros(3), np.zeros(4), np.zeros(4), np.zeros(40), np.zeros((1, n, 2)), np.zeros((1, n, 2)),
            np.zeros((1, n), np.int64), np.zeros((1, n), np.int64), np.zeros((1, n)), np.zeros((1, n)),
            np.zeros((1, n, 0, 2)), np.zeros((1, n, 0, 2)), np.zeros((1, n), np.int64)]
    assert _aot.fits(tuple(good))
    for i, bad in ((3, np.zeros((1, 2 * n, 7))[:, ::2]), (5, np.zeros((1, n))), (10, np.ones(1, np.float32)),
                   (0, 1.0), (0, True)):
        args = list(good)
        args[i] = bad
        assert not _aot.fits(tuple(args)), i
    assert not _aot.fits(tuple(good[:-1]))


def test_the_key_follows_the_kernel_sources_and_a_stale_module_is_not_used(aot_kernel, monkeypatch):
    from ppod_ros.physics import _params

    k = _aot.key()
    assert _aot.module_path(k) is not None
    monkeypatch.setattr(_params, "KERNEL_SOURCES", _params.KERNEL_SOURCES[:-1])
    other = _aot.key()
    assert other != k
    assert _aot.module_path(other) is None


def test_numbas_cache_of_changed_kernel_sources_is_dropped_before_any_dispatcher_is_made():
    # Regression: numba checks a cached function against its own file only, and the ahead-of-time
    # module is compiled from the cached callees. Built without a JIT call before it, after an edit
    # of _contact.py, the module linked the old _contact code (a stick test made to fail everywhere
    # left every planner row as it was) and was stored under the new sources' key. Every JIT path
    # (the build, ensure_compiled, cycle.limit_cycle's direct kernel calls) makes its dispatchers in
    # _jit.materialise, which checks the cache first: in a fresh process, before numba's dispatchers.
    code = (
        "from ppod_ros.physics import _jit, _params, _aot, _contact\n"
        "seen = []\n"
        "_params._drop_stale_cache = lambda: seen.append(_jit.is_materialised())\n"
        "assert not _jit.is_materialised()\n"
        "_jit.materialise()\n"
        "_jit.materialise()\n"
        "print(seen, type(_contact.stick_ratio).__name__)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["[False]", "CPUDispatcher"]   # once, before the dispatchers


def test_disabled_or_missing_module_gives_no_kernel(monkeypatch):
    monkeypatch.setenv(_aot.ENV_SWITCH, "0")
    assert _aot.kernel() is None
    assert _aot.ensure_built() == 0.0


def test_lazy_kernels_become_numba_dispatchers_everywhere():
    from ppod_ros.physics import _contact, _rk, _solve

    _jit.materialise()
    import numba
    from numba.core.registry import CPUDispatcher

    assert _jit.is_materialised()
    for fn in (_solve.solve_chunk, _solve.solve_motions, _rk.rk_step, _contact.rhs):
        assert isinstance(fn, CPUDispatcher), fn
    assert _solve.prange is numba.prange
    late = _jit.njit(cache=False)(lambda x: x + 1)
    assert isinstance(late, CPUDispatcher) and late(1) == 2


def test_available_threads_is_numbas_setting():
    code = ("import sys\nfrom ppod_ros.physics import _threads\nmine = _threads.available_threads()\n"
            "assert 'numba' not in sys.modules\nimport numba\nprint(mine, numba.config.NUMBA_NUM_THREADS)\n")
    for env in ({}, {"NUMBA_NUM_THREADS": "1"}):
        environ = {k: v for k, v in os.environ.items() if k != "NUMBA_NUM_THREADS"} | env
        out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120,
                             env=environ)
        assert out.returncode == 0, out.stderr
        mine, numbas = out.stdout.split()
        assert mine == numbas
    assert _threads.available_threads() >= 1


def _field_json(tmp_path: Path, tag: str, **env: str) -> tuple[dict, list[str]]:
    target = tmp_path / f"{tag}.json"
    code = (f"import json, sys\nLAZY = {sorted(LAZY_MODULES)!r}\nfrom ppod_nodes.cli.main import main\n"
            f"status = main(['field', 'config/motions/Sink.yaml', '--json', {str(target)!r}, '--quiet'])\n"
            "print(json.dumps([status, sorted(m for m in sys.modules if m.split('.')[0] in "
            "{'numba', 'llvmlite'} or m in LAZY)]))\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=240,
                         env={**os.environ, **env})
    assert out.returncode == 0, out.stderr
    status, modules = json.loads(out.stdout.splitlines()[-1])
    assert status == 0
    return json.loads(target.read_text()), modules


def test_ppod_field_json_imports_no_numba_and_writes_the_jit_result(aot_kernel, tmp_path):
    aot, aot_modules = _field_json(tmp_path, "aot")
    jit, jit_modules = _field_json(tmp_path, "jit", PPOD_AOT="0")
    assert aot_modules == []
    assert "numba" in jit_modules and "ppod_ros.physics._solve" in jit_modules
    timing = {"seconds", "setup_seconds"}
    assert {k: v for k, v in aot.items() if k not in timing} == {k: v for k, v in jit.items() if k not in timing}
    assert len(aot["velocity"]) == 21 * 21


def test_startup_benchmark_runs_both_kernels_and_compares_their_fields(aot_kernel, capsys):
    from ppod_bench.solver_startup import VARIANTS, measure

    rows = measure(1)
    assert [r[0] for r in rows] == list(VARIANTS)
    assert all(float(r[2]) > 0 and float(r[4]) > 0 for r in rows)
    assert "outputs identical" in capsys.readouterr().out


def test_kernel_modules_take_njit_from_jit_not_numba():
    # A module-level numba import would bring numba back onto the small-call path, and a numba
    # function compiled before the lazy kernels are materialised would see their proxies.
    import ast

    physics = ROOT / "ppod_ros" / "physics"
    offenders = []
    for path in sorted(physics.glob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in tree.body:
            names = ([a.name for a in node.names] if isinstance(node, ast.Import)
                     else [node.module or ""] if isinstance(node, ast.ImportFrom) else [])
            if any(n == "numba" or n.startswith("numba.") for n in names):
                offenders.append(path.name)
    assert offenders == []


def test_without_a_built_module_solve_field_runs_on_the_jit_kernel(monkeypatch, tmp_path):
    from ppod_ros.physics import _params

    monkeypatch.setattr(_aot, "cache_dirs", lambda: [tmp_path / "empty"])
    monkeypatch.setattr(_aot, "_loaded", {})
    monkeypatch.setenv(_aot.ENV_SWITCH, "1")
    assert _aot.module_path() is None and _aot.kernel() is None
    r = solve_field(suite_motion("Sink"), PointPart(0.3), [[0.02, 0.01], [-0.03, 0.04]],
                    SolverSettings().replace(cache=False, threads=1))
    assert r.valid.all()
    assert _params.is_loaded(("field", 0, False))
