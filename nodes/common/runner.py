"""The one ``main()`` shape every PPOD node uses (STYLE.md rule 10).

:func:`run_node` confines DDS to loopback (unless configured otherwise), initialises a private
rclpy context, builds the node, spins it in a thread, and waits for Ctrl-C, SIGTERM, an external
context shutdown or a crashed executor. On the way out it brings a lifecycle node to a safe,
finalized state (deactivate, then shutdown) while the executor still runs, so the node can still
publish its final status, and then tears down in the order that never aborts (ROS_NOTES.md), the
spin thread stopped first: ``halt.set(); spin_thread.join(); executor.shutdown();
node.destroy_node(); context.try_shutdown()`` (see :func:`spin_until_halted`).
A second Ctrl-C during that clean-up exits at once.

A launcher asks for real-time scheduling with ``PPOD_REALTIME_PRIORITY`` (the launch configuration's
``realtime_priority``): the process takes SCHED_FIFO at that priority before rclpy starts its
threads, which inherit it, and its node logs whether it got it (docs/ros.md). Threads started
earlier, at import (BLAS workers), keep normal priority: ``NodeSpec.env`` gives such a node one BLAS
thread.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import traceback
from collections.abc import Callable, Sequence

import rclpy
from rclpy.context import Context
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.signals import SignalHandlerOptions

from ppod_nodes.ros_env import REALTIME_ENV, configure_ros_environment


def take_realtime_priority(environ=os.environ) -> tuple[str, str] | None:
    """Take the real-time priority ``environ[REALTIME_ENV]`` asks for, for this thread and every
    thread it starts from now on; returns (level, message) for the node's log, None when none is asked.
    Never raises: without the permission (CAP_SYS_NICE or an RLIMIT_RTPRIO this high) the process
    runs on at normal priority and the message says so."""
    raw = environ.get(REALTIME_ENV, "").strip()
    if raw in ("", "0"):
        return None
    try:
        priority = int(raw)
    except ValueError:
        priority = -1
    if not 1 <= priority <= 99:
        return "warning", f"{REALTIME_ENV}={raw!r}: expected an integer 1-99; normal scheduling"
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        return "warning", (f"real-time priority {priority} not granted ({reason}): normal scheduling, so on a "
                           f"loaded machine this node's threads can wait for a core (grant it with CAP_SYS_NICE "
                           f"or an rtprio limit; docs/ros.md)")
    return "info", f"real-time priority {priority} (SCHED_FIFO) for the node's threads"


def spin_until_halted(executor: SingleThreadedExecutor, failure: list[Exception], halt: threading.Event) -> None:
    """Spin one callback at a time until ``halt`` is set or the context shuts down. The executor is
    shut down only after this returns: rclpy 7.1's ``Executor.shutdown()`` does not wait for the
    callback being dispatched and destroys the guard condition its handler then triggers
    (``InvalidHandle: cannot use Destroyable because destruction was requested``, seen once in a
    demo's viz node on the way out)."""
    try:
        while not halt.is_set() and executor.context.ok():
            executor.spin_once(timeout_sec=0.1)
    except ExternalShutdownException:
        pass
    except Exception as exc:  # a callback raised: report it, the main thread shuts down
        failure.append(exc)
        traceback.print_exc()


def stop_spinning(executor: SingleThreadedExecutor | None, halt: threading.Event,
                  thread: threading.Thread | None, timeout_s: float = 5.0) -> None:
    """Halt :func:`spin_until_halted` and join its thread; the executor is woken (an empty task
    triggers its guard condition), so an idle ``spin_once`` returns at once, not after its timeout."""
    halt.set()
    if executor is not None:
        # An executor already shut down has no guard condition: the thread then ends by its timeout.
        with contextlib.suppress(Exception):
            executor.create_task(lambda: None)
    if thread is not None:
        thread.join(timeout=timeout_s)


def run_node(factory: Callable[..., object], argv: Sequence[str] | None = None) -> int:
    """Run one node until asked to stop; returns the process exit status.

    Parameters
    ----------
    factory : callable
        Called as ``factory(context=context)``; returns an rclpy Node (lifecycle or not).
    argv : sequence of str, optional
        Command line including ``--ros-args ...`` (default: ``sys.argv``).
    """
    argv = list(sys.argv if argv is None else argv)
    ours = argv[1:argv.index("--ros-args")] if "--ros-args" in argv else argv[1:]
    if "-h" in ours or "--help" in ours:
        print(node_help(factory, os.path.basename(argv[0]) if argv else "node"))
        return 0
    configure_ros_environment()
    realtime = take_realtime_priority()   # before rclpy starts its threads: they inherit it
    context = Context()
    rclpy.init(args=argv, context=context, signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    signals_seen = []

    def on_signal(signum, _frame):
        signals_seen.append(signum)
        if len(signals_seen) > 1:
            os._exit(128 + signum)  # second signal: the user insists
        stop.set()

    previous = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    node = None
    executor = None
    thread = None
    failure: list[Exception] = []
    halt = threading.Event()
    status = 0
    try:
        node = factory(context=context)
        if realtime is not None:
            getattr(node.get_logger(), realtime[0])(realtime[1])
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        thread = threading.Thread(target=spin_until_halted, args=(executor, failure, halt), name="spin", daemon=True)
        thread.start()
        autostart = getattr(node, "autostart", None)
        if autostart is not None and not autostart():
            node.get_logger().error("autostart failed; see the messages above")
            status = 1
            stop.set()
        while not stop.wait(0.1):
            if not context.ok() or not thread.is_alive():
                break
        if failure:
            status = 1
    finally:
        if node is not None and hasattr(node, "finalize") and context.ok():
            try:
                node.finalize()
            except Exception:  # noqa: BLE001 - keep tearing down; the traceback is printed
                traceback.print_exc()
                status = status or 1
        stop_spinning(executor, halt, thread)
        if executor is not None:
            executor.shutdown()
        if node is not None:
            node.destroy_node()
        context.try_shutdown()
        for s, h in previous.items():
            signal.signal(s, h)
    return status


def node_help(factory: Callable[..., object], prog: str) -> str:
    """What ``NODE --help`` prints: the node module's docstring, its parameters and how to run it."""
    module = sys.modules.get(getattr(factory, "__module__", ""), None)
    lines = [f"usage: {prog} [--ros-args -r __node:=NAME --params-file FILE -p NAME:=VALUE ...]", ""]
    lines.append((getattr(module, "__doc__", None) or getattr(factory, "__doc__", None) or "").strip())
    params = list(getattr(factory, "COMMON_PARAMS", ())) + list(getattr(factory, "PARAMS", ()))
    if params:
        lines += ["", "parameters (ros__parameters; 'runtime': ros2 param set applies it at once, "
                  "otherwise read-only after start-up):"]
        for p in params:
            runtime = getattr(p, "runtime", False) or p.name in getattr(factory, "RUNTIME_PARAMS", ())
            when = "runtime" if runtime else "startup"
            lines.append(f"  {p.name} = {p.default!r}  [{when}]  {p.description}")
    lifecycle = any(p.name == "autostart" for p in params)
    lines += ["", "example:", f"  {prog} --ros-args " + ("-p autostart:=true" if lifecycle else "--params-file FILE")]
    return "\n".join(lines)


def make_main(factory: Callable[..., object]) -> Callable[[Sequence[str] | None], int]:
    """A console-script entry point for ``factory`` (see pyproject's [project.scripts])."""

    def main(argv: Sequence[str] | None = None) -> int:
        return run_node(factory, argv)

    main.__doc__ = f"Run {getattr(factory, '__name__', 'the node')} (see its module docstring)."
    return main
