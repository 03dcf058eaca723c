"""Run a benchmark program from benchmarks/ and print its tables (plots go to --out).

Each benchmark is a module ``ppod_bench.NAME`` with ``HELP``, ``add_arguments(parser)`` and
``run(args) -> int``. Benchmarks measure speed and accuracy; tests never assert on wall-clock time.

examples:
  ppod bench --list
  ppod bench solver --quick
  ppod bench can --out out/bench
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil

HELP = "run a benchmark (solver, can, feedback, tracker, ...) and print its tables"


def _benchmarks() -> dict[str, object]:
    import ppod_bench

    out = {}
    for info in pkgutil.iter_modules(ppod_bench.__path__):
        if info.name.startswith("_") or info.ispkg:
            continue
        module = importlib.import_module(f"ppod_bench.{info.name}")
        if hasattr(module, "run") and hasattr(module, "add_arguments"):
            out[info.name] = module
    return out


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--list", action="store_true", help="list the available benchmarks")
    sub = parser.add_subparsers(dest="bench", metavar="NAME")
    for name, module in sorted(_benchmarks().items()):
        # argparse %-formats help strings: a literal '%' (as in "iterations to 1 %") must be doubled.
        p = sub.add_parser(name, help=getattr(module, "HELP", "").replace("%", "%%"), description=module.__doc__,
                           formatter_class=argparse.RawDescriptionHelpFormatter)
        p.add_argument("--out", default="out/bench", help="folder for plots and tables (default: %(default)s)")
        module.add_arguments(p)
        p.set_defaults(_bench_module=module)


def run(args: argparse.Namespace) -> int:
    if args.list or not getattr(args, "_bench_module", None):
        for name, module in sorted(_benchmarks().items()):
            print(f"{name:12s} {getattr(module, 'HELP', '')}")
        return 0
    return int(args._bench_module.run(args) or 0)
