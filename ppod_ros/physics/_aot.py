"""The serial field kernel compiled ahead of time: small calls without importing numba.

A small ``ppod field`` call (21 x 21 Sink: 0.02 s of solving) spent about 0.45 s of CPU importing
numba, setting up its CPU target and loading the serial kernel from numba's cache. The same kernel
(``_solve.solve_motions_serial``, both part kinds: ``kind`` is an argument) compiled once with
``numba.pycc`` into an extension module next to numba's cache is imported in under a millisecond,
and with the kernel modules' lazy ``njit`` (:mod:`ppod_ros.physics._jit`) the call imports no numba.

Compiled with the same LLVM for this machine's CPU (``target_cpu = "host"``, as numba's JIT), the
module gives bit-for-bit the results of the JIT kernel (tested). It is used only when its key
matches: a digest of the kernel sources (``_params.KERNEL_SOURCES``), :data:`FORMAT`, the versions of
Python, numpy, numba and llvmlite, and this CPU's model and feature flags. Anything else (not
built, stale, another CPU, ``PPOD_AOT=0``, arrays not as exported) falls back to the JIT kernel,
with the same results. ``./run.sh setup`` builds it (:func:`ensure_built`, 1-5 minutes once);
``python -c "from ppod_ros.physics import _aot; _aot.main()"`` does the same by hand.

``numba.pycc`` is deprecated in numba but still shipped and working in 0.68; if a numba release
drops it, :func:`ensure_built` reports that and everything runs on the JIT kernels as before.
"""

from __future__ import annotations

import hashlib
import importlib.machinery
import importlib.util
import logging
import os
import shutil
import sys
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np

_log = logging.getLogger(__name__)

#: Extension module name (its ``PyInit_`` symbol) and the exported function's name.
MODULE = "_ppod_field_aot"
EXPORT = "solve_motions_serial"
#: Environment variable: "0" disables the ahead-of-time kernel (the JIT kernel is used).
ENV_SWITCH = "PPOD_AOT"
#: Part of the key: bump it when the export (``ARG_TYPES``, ``EXPORT``, build options) changes.
FORMAT = "1"
#: Exported argument types of ``solve_motions_serial``: (numpy dtype, ndim), 0 = scalar int64.
ARG_TYPES: tuple[tuple[str, int], ...] = (
    ("int64", 0), ("float64", 3), ("int64", 1), ("float64", 3), ("float64", 3), ("bool", 2), ("float64", 2),
    ("float64", 4), ("float64", 4), ("int64", 2), ("float64", 1), ("int64", 1),
    ("float64", 2), ("float64", 1), ("float64", 1), ("float64", 1), ("float64", 1), ("float64", 1),
    ("float64", 3), ("float64", 3), ("int64", 2), ("int64", 2), ("float64", 2), ("float64", 2),
    ("float64", 4), ("float64", 4), ("int64", 2))
#: Age (s) after which a build folder left by an interrupted build is deleted.
STALE_BUILD_S = 3600.0
_HERE = Path(__file__).resolve().parent

_lock = threading.Lock()
_loaded: dict[str, Any] = {}


def enabled() -> bool:
    """Whether the ahead-of-time kernel may be used (``PPOD_AOT`` is not "0")."""
    return os.environ.get(ENV_SWITCH, "1").strip() != "0"


def _file_digest(h: Any, path: Path) -> None:
    h.update(str(path.name).encode())
    try:
        h.update(path.read_bytes())
    except OSError:
        h.update(b"<missing>")


def _package_file(name: str, rel: str) -> Path | None:
    """A file inside an installed package, found without importing the package."""
    try:
        spec = importlib.util.find_spec(name)
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.submodule_search_locations:
        return None
    return Path(next(iter(spec.submodule_search_locations))) / rel


def _cpu_signature() -> bytes | None:
    """This CPU's model and feature flags (the module is compiled for them); None if unknown."""
    try:
        text = Path("/proc/cpuinfo").read_text(errors="replace")
    except OSError:
        return None
    keep = [line for line in text.splitlines() if line.split(":")[0].strip() in ("model name", "flags")]
    return "\n".join(sorted(set(keep))).encode() or None


def key() -> str | None:
    """The digest the module must be built for in this environment (None: not usable here)."""
    from ppod_ros.physics._params import KERNEL_SOURCES

    cpu = _cpu_signature()
    if cpu is None:
        return None
    h = hashlib.sha256()
    h.update(FORMAT.encode())
    for name in KERNEL_SOURCES:
        _file_digest(h, _HERE / name)
    for pkg in ("numba", "llvmlite"):
        path = _package_file(pkg, "_version.py")
        if path is None:
            return None
        _file_digest(h, path)
    h.update(f"{sys.version}|{np.__version__}|{sys.platform}".encode())
    h.update(cpu)
    return h.hexdigest()[:24]


def _suffix() -> str:
    return importlib.machinery.EXTENSION_SUFFIXES[0]


def cache_dirs() -> list[Path]:
    """Where the module is looked for, first the package's own cache (as numba's), then the user's."""
    user = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "ppod" / "aot"
    return [_HERE / "__pycache__" / "aot", user]


def module_path(k: str | None = None) -> Path | None:
    """The built module for this environment, or None if there is none."""
    k = k or key()
    if k is None:
        return None
    for d in cache_dirs():
        path = d / k / f"{MODULE}{_suffix()}"
        if path.is_file():
            return path
    return None


def kernel() -> Any | None:
    """The ahead-of-time ``solve_motions_serial``, or None (disabled, not built, stale)."""
    if not enabled():
        return None
    with _lock:
        if "fn" in _loaded:
            return _loaded["fn"]
        fn = None
        try:
            path = module_path()
            if path is not None:
                loader = importlib.machinery.ExtensionFileLoader(MODULE, str(path))
                spec = importlib.util.spec_from_file_location(MODULE, path, loader=loader)
                module = importlib.util.module_from_spec(spec)
                loader.exec_module(module)
                fn = getattr(module, EXPORT)
        except (ImportError, OSError, AttributeError) as exc:
            _log.warning("ahead-of-time field kernel not loaded (%s); using the JIT kernel", exc)
            fn = None
        _loaded["fn"] = fn
        return fn


def fits(args: tuple[Any, ...]) -> bool:
    """Whether ``args`` match the exported signature exactly (dtype, ndim, C-contiguous)."""
    if len(args) != len(ARG_TYPES):
        return False
    for value, (dtype, ndim) in zip(args, ARG_TYPES):
        if ndim == 0:
            if not isinstance(value, (int, np.integer)) or isinstance(value, bool):
                return False
            continue
        if not (isinstance(value, np.ndarray) and value.ndim == ndim and value.dtype == np.dtype(dtype)
                and value.flags.c_contiguous):
            return False
    return True


def _signature() -> Any:
    from numba import types

    scalar = {"int64": types.int64, "float64": types.float64, "bool": types.boolean}
    args = [types.int64 if nd == 0 else types.Array(scalar[dt], nd, "C") for dt, nd in ARG_TYPES]
    return types.void(*args)


def build(out_dir: Path | None = None, verbose: bool = False) -> Path:
    """Compile the module for this environment into ``out_dir`` (default: the first writable cache
    directory); returns its path. Takes 1-5 minutes; raises RuntimeError when it cannot be built."""
    import tempfile  # only here: it imports random and hashlib's sha512 (about 5 ms)
    import warnings

    k = key()
    if k is None:
        raise RuntimeError("ahead-of-time kernel: this platform's CPU is unknown (no /proc/cpuinfo)")
    from ppod_ros.physics import _jit

    _jit.materialise()   # drops numba's cache of changed kernel sources first (_params._drop_stale_cache)
    from ppod_ros.physics import _solve

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # numba.pycc's pending-deprecation notice
        try:
            from numba.pycc import CC
        except ImportError as exc:
            raise RuntimeError(f"ahead-of-time kernel: numba.pycc is not available ({exc})") from exc
        targets = [out_dir] if out_dir is not None else cache_dirs()
        last: Exception | None = None
        for base in targets:
            final = Path(base) / k
            try:
                final.parent.mkdir(parents=True, exist_ok=True)
                work = Path(tempfile.mkdtemp(prefix="build-", dir=final.parent))
            except OSError as exc:
                last = exc
                continue
            try:
                cc = CC(MODULE)
                cc.output_dir = str(work)
                cc.target_cpu = "host"  # as numba's JIT: same code, same results
                cc.verbose = verbose
                cc.export(EXPORT, _signature())(_solve.solve_motions_serial.py_func)
                cc.compile()
                built = work / f"{MODULE}{_suffix()}"
                if not built.is_file():
                    raise RuntimeError(f"ahead-of-time kernel: numba.pycc wrote no {built.name}")
                final.mkdir(exist_ok=True)
                os.replace(built, final / built.name)
                _drop_others(final)
                return final / built.name
            except OSError as exc:
                last = exc
            finally:
                shutil.rmtree(work, ignore_errors=True)
        raise RuntimeError(f"ahead-of-time kernel: no writable cache directory ({last})")


def _drop_others(keep: Path) -> None:
    """Delete modules built for other keys (stale sources or versions) next to ``keep``, and build
    folders of interrupted builds older than :data:`STALE_BUILD_S`."""
    now = time.time()
    for other in keep.parent.iterdir():
        if other == keep or not other.is_dir():
            continue
        try:
            old = now - other.stat().st_mtime > STALE_BUILD_S
        except OSError:
            continue
        if not other.name.startswith("build-") or old:
            shutil.rmtree(other, ignore_errors=True)


def ensure_built(verbose: bool = False) -> float:
    """Build the module unless it exists for this environment; returns the seconds spent (0 if it
    existed or cannot be built here: the JIT kernels are used then, and the reason is logged)."""
    if not enabled() or module_path() is not None:
        return 0.0
    t0 = time.perf_counter()
    try:
        build(verbose=verbose)
    except Exception as exc:  # any failure leaves the JIT kernels in use, which is always correct
        _log.warning("%s", exc)
        print(f"[setup] ahead-of-time field kernel not built ({exc}); the JIT kernel is used", file=sys.stderr)
        return 0.0
    _loaded.clear()
    return time.perf_counter() - t0


def main() -> int:
    """Build the module for this environment unless it is up to date (progress on stderr); exit status."""
    path = module_path()
    if path is not None:
        print(f"ahead-of-time field kernel up to date: {path}", file=sys.stderr)
        return 0
    print("ahead-of-time field kernel: compiling (1-5 minutes)...", file=sys.stderr, flush=True)
    spent = ensure_built()
    path = module_path()
    if path is None:
        return 1
    print(f"ahead-of-time field kernel built in {spent:.0f} s: {path}", file=sys.stderr)
    return 0


__all__ = ["ENV_SWITCH", "build", "cache_dirs", "enabled", "ensure_built", "fits", "kernel", "key", "module_path"]
