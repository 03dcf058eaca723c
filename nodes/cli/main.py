"""``ppod``: the PPOD stack's command line.

Each subcommand lives in its own module under :mod:`ppod_nodes.cli` and exposes

    HELP: str                       one line for ``ppod --help``
    add_arguments(parser) -> None   fills its argparse parser (description and examples in the
                                    module docstring, shown by ``ppod NAME --help``)
    run(args) -> int                does the work; returns the exit status

Modules are imported only when their subcommand runs, so ``ppod field`` never loads rclpy.
Errors from the core (:class:`ppod_ros.errors.PpodError`) become one line on stderr and exit 2.
"""

from __future__ import annotations

import argparse
import importlib
import logging
import sys
from collections.abc import Sequence

#: name -> module under ppod_nodes.cli. Order is the order shown in ``ppod --help``.
SUBCOMMANDS: dict[str, str] = {
    "up": "up",
    "demo": "demo",
    "goal": "goal",
    "estop": "estop",
    "field": "field",
    "echo": "echo",
    "record": "record",
    "view": "view",
    "replay": "replay",
    "bench": "bench",
    "calibrate": "calibrate",
    "move": "move",
}

EPILOG = """examples:
  ppod up --sim                      start every node against the simulated device
  ppod field ppod_ros/data/motions/LineSinkX.yaml --plot field.png
  ppod goal --preset LineSinkX
  ppod estop                         emergency stop: the top-priority frame, straight on the bus
  ppod echo /ppod/plate_motion_status
  ppod SUBCOMMAND --help             details and examples for one subcommand
"""


def _load(name: str):
    return importlib.import_module(f"ppod_nodes.cli.{SUBCOMMANDS[name]}")


def _available() -> dict[str, object]:
    """Subcommand modules that exist in this installation (later issues add more)."""
    out = {}
    for name in SUBCOMMANDS:
        try:
            out[name] = _load(name)
        except ModuleNotFoundError as exc:
            if exc.name != f"ppod_nodes.cli.{SUBCOMMANDS[name]}":
                raise
    return out


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="ppod",
        description="Command line of the PPOD control stack (ROS 2 Jazzy).",
        epilog=EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("-v", "--verbose", action="count", default=0, help="more log output (-vv: debug)")
    sub = parser.add_subparsers(dest="command", metavar="SUBCOMMAND")
    modules = {only: _load(only)} if only else _available()
    for name, module in modules.items():
        p = sub.add_parser(
            name,
            help=getattr(module, "HELP", ""),
            description=module.__doc__,
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        if only:  # a listing (`ppod --help`) needs no subcommand's arguments, nor what they import
            module.add_arguments(p)
        p.set_defaults(_module=module)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    # Build only the chosen subcommand's parser when we can tell it, so `ppod field` stays light.
    first = next((a for a in argv if not a.startswith("-")), None)
    parser = build_parser(first if first in SUBCOMMANDS and _exists(first) else None)
    args = parser.parse_args(argv)
    logging.basicConfig(
        level=logging.WARNING - 10 * min(args.verbose, 2),
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
    if not getattr(args, "_module", None):
        parser.print_help()
        return 0
    from ppod_ros.errors import PpodError

    try:
        return int(args._module.run(args) or 0)
    except PpodError as exc:
        print(f"ppod {args.command}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"ppod {args.command}: interrupted", file=sys.stderr)
        return 130


def _exists(name: str) -> bool:
    return importlib.util.find_spec(f"ppod_nodes.cli.{SUBCOMMANDS[name]}") is not None


if __name__ == "__main__":
    sys.exit(main())
