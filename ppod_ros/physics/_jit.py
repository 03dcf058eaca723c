"""``njit`` and ``prange`` for the kernel modules, importing numba only when a kernel is first used.

Importing numba and setting up its CPU target costs about 0.4 s of CPU, more than a small
``ppod field`` call's whole solve. With the serial field kernel compiled ahead of time
(:mod:`ppod_ros.physics._aot`) such a call needs numba for nothing, but every kernel module
(``plate``, ``_contact``, ``_rk``, ``_advance``...) is imported on that path for its Python-side
helpers and constants, and ``from numba import njit`` at the top of each would import numba anyway.

Here :func:`njit` records the function and returns a :class:`LazyKernel` in its place. The first
time any kernel is called, or an attribute of one is read (``py_func``, ``signatures``...),
:func:`materialise` imports numba, makes every recorded function a real numba dispatcher with the
same options (so numba's on-disk cache finds the same entries), and replaces each proxy, and every
``prange`` placeholder, in the globals of the ``ppod_ros.physics`` modules imported so far: numba
then compiles the kernels against real dispatchers and ``numba.prange``. Modules imported later
bind the dispatchers directly. Results are the same as with ``from numba import njit``.
"""

from __future__ import annotations

import sys
import threading
from collections.abc import Callable
from typing import Any

#: Modules whose globals are rewritten when the kernels are materialised.
PACKAGE = "ppod_ros.physics"

_lock = threading.RLock()
_pending: list[LazyKernel] = []
_done = False


class _PrangePlaceholder:
    """``prange`` before numba is imported: ``range`` in Python; replaced by ``numba.prange``."""

    def __call__(self, *args: int) -> range:
        return range(*args)

    def __repr__(self) -> str:
        return "prange (numba not imported yet)"


prange = _PrangePlaceholder()


class LazyKernel:
    """A function decorated with :func:`njit` before numba is imported; calls the dispatcher."""

    def __init__(self, func: Callable[..., Any], options: dict[str, Any]) -> None:
        self.py_func = func
        self.options = options
        self.dispatcher = None
        self.__wrapped__ = func
        self.__doc__ = func.__doc__
        self.__name__ = func.__name__
        self.__qualname__ = func.__qualname__
        self.__module__ = func.__module__

    def __call__(self, *args: Any, **kwargs: Any) -> Any:
        return (self.dispatcher or _dispatcher_of(self))(*args, **kwargs)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.dispatcher or _dispatcher_of(self), name)

    def __repr__(self) -> str:
        return f"<lazy numba kernel {self.__module__}.{self.__qualname__}>"


def njit(**options: Any) -> Callable[[Callable[..., Any]], Any]:
    """``numba.njit(**options)``; lazy until numba is imported by :func:`materialise`."""

    def wrap(func: Callable[..., Any]) -> Any:
        with _lock:
            if _done:
                import numba

                return numba.njit(**options)(func)
            kernel = LazyKernel(func, options)
            _pending.append(kernel)
            return kernel

    return wrap


def _dispatcher_of(kernel: LazyKernel) -> Any:
    materialise()
    return kernel.dispatcher


def is_materialised() -> bool:
    """Whether numba was imported for the kernels in this process."""
    return _done


def materialise() -> None:
    """Import numba, make every recorded kernel a dispatcher and rebind the proxies (idempotent)."""
    global _done
    with _lock:
        if _done:
            return
        from ppod_ros.physics import _numba_start, _params

        # numba checks a cached function against its own source file only, and callers are
        # compiled with (or linked from) their callees' cached code: after an edit of one kernel
        # module, code from the old version could load silently (the ahead-of-time build, run
        # before any JIT call, linked the old sticking test under the new sources' key). Every
        # dispatcher is made here, so the package's cache is checked here, once per process.
        _params._drop_stale_cache()
        _numba_start.prepare()
        import numba

        for kernel in _pending:
            kernel.dispatcher = numba.njit(**kernel.options)(kernel.py_func)
        _done = True
        for name, module in list(sys.modules.items()):
            if module is None or not (name == PACKAGE or name.startswith(PACKAGE + ".")):
                continue
            names = vars(module)
            for key, value in list(names.items()):
                if isinstance(value, LazyKernel):
                    names[key] = value.dispatcher
                elif value is prange and name != __name__:
                    names[key] = numba.prange
        _pending.clear()


__all__ = ["LazyKernel", "is_materialised", "materialise", "njit", "prange"]
