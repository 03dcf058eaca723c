"""Numba's one-time set-up without importing ``scipy.linalg``.

Before the first compiled function of a process runs (also when it is loaded from numba's on-disk
cache), numba sets up its CPU target, which imports ``numba.np.arraymath``. That module checks at
import that a BLAS exists by importing ``scipy.linalg.cython_blas``, and a submodule import runs its
package first: all of ``scipy.linalg``, scipy's array-API layer and ``numpy.f2py``, 0.15-0.2 s of
CPU, more than the whole solve of ``ppod field``'s default 21 x 21 grid. Nothing of it is used.

:func:`prepare` loads the ``cython_blas`` extension module alone (scipy's own file, under its own
name), lets ``numba.np.arraymath`` find it, then takes it out of ``sys.modules`` again: a later
``import scipy.linalg`` runs the package as usual and gets the same module back (a Cython module
re-imported returns its one instance). Numba's own checks still run on the real module (its BLAS
check, and the LP64/ILP64 check against ``scipy.__config__``), and kernels that call LAPACK
(``np.linalg`` in the rigid-part contact code) import ``scipy.linalg`` when they first call it, as
before. Whenever anything is unusual (scipy absent or laid out differently, numba already set up,
``scipy.linalg`` already imported) :func:`prepare` does nothing and numba imports as it always did.
"""

from __future__ import annotations

import importlib.machinery
import importlib.util
import logging
import sys
from pathlib import Path

_log = logging.getLogger(__name__)

#: The module numba's BLAS check imports, and the module that runs that check at import.
BLAS_MODULE = "scipy.linalg.cython_blas"
CHECKING_MODULE = "numba.np.arraymath"


def prepare() -> bool:
    """Import numba's array lowering with the BLAS check served by ``cython_blas`` alone.

    Returns whether it did (False: nothing to do or not possible; numba then behaves as usual).
    """
    if CHECKING_MODULE in sys.modules or "scipy.linalg" in sys.modules or BLAS_MODULE in sys.modules:
        return False
    module = _load_blas_module()
    if module is None:
        return False
    try:
        importlib.import_module(CHECKING_MODULE)
    finally:
        if sys.modules.get(BLAS_MODULE) is module:
            del sys.modules[BLAS_MODULE]
    return True


def _load_blas_module():
    """scipy's ``linalg/cython_blas`` extension, executed under its own name; None if not found."""
    try:
        spec = importlib.util.find_spec("scipy")
    except (ImportError, ValueError):
        return None
    if spec is None or not spec.submodule_search_locations:
        return None
    folder = Path(next(iter(spec.submodule_search_locations))) / "linalg"
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        path = folder / f"cython_blas{suffix}"
        if path.is_file():
            break
    else:
        return None
    try:
        blas_spec = importlib.util.spec_from_file_location(BLAS_MODULE, path)
        module = importlib.util.module_from_spec(blas_spec)
        sys.modules[BLAS_MODULE] = module
        blas_spec.loader.exec_module(module)
    except (ImportError, OSError) as exc:  # fall back to numba's own import
        sys.modules.pop(BLAS_MODULE, None)
        _log.debug("cython_blas not preloaded (%s); numba imports scipy.linalg", exc)
        return None
    return module
