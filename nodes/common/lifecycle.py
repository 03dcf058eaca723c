"""Base class of the PPOD lifecycle nodes.

Nodes that own hardware follow the ROS 2 managed-node contract (STYLE.md rule 9):

    unconfigured --configure--> inactive --activate--> active
    active --deactivate--> inactive --cleanup--> unconfigured;  any --shutdown--> finalized

* configure: read the declared parameters, build the frozen core config, open devices.
* activate: start streaming (lifecycle publishers become active).
* deactivate: stop streaming; hardware is brought to a safe state (e.g. ramp to zero).
* cleanup: close devices.
* shutdown: make hardware safe from any state; called on Ctrl-C / SIGTERM by :func:`run_node`.

Subclasses implement ``on_configure_node(params)``, ``on_activate_node()``,
``on_deactivate_node()``, ``on_cleanup_node()`` and ``on_shutdown_node()``. Core errors
(:class:`ppod_ros.errors.PpodError`) turn into a FAILURE of the transition, a log line and an
ERROR diagnostic; the node stays in its previous state. Other exceptions are bugs: they propagate.

An invalid lifecycle request (activate while active, configure while inactive, an unknown id)
answers ``success: false`` and leaves the node as it was: rclpy 7.1.6 lets the state machine's
RCLError escape the change_state service callback, which kills the executor and the node, so the
callback is wrapped here (:meth:`PpodLifecycleNode._guarded_change_state`).
"""

from __future__ import annotations

from typing import Any

from rcl_interfaces.msg import SetParametersResult
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.lifecycle import Node as LifecycleNode
from rclpy.lifecycle import State, TransitionCallbackReturn

from ppod_nodes.common import diagnostics as diag
from ppod_nodes.common.events import QuietPublishers
from ppod_nodes.common.params import Param, checked, declare, read, with_runtime
from ppod_ros.errors import PpodError

#: Parameters every PPOD lifecycle node has.
COMMON_PARAMS = (
    Param("autostart", False, "configure and activate on start-up (when run without the launcher)"),
)


class PpodLifecycleNode(QuietPublishers, LifecycleNode):
    """A lifecycle node with declared parameters, diagnostics and PpodError handling."""

    #: Parameters every lifecycle node has (listed by ``NODE --help``).
    COMMON_PARAMS: tuple[Param, ...] = COMMON_PARAMS
    #: The node's parameters (declared once, with descriptors).
    PARAMS: tuple[Param, ...] = ()
    #: Parameters a running node applies at once when changed (``ros2 param set``); every other one
    #: is declared read-only. The change updates ``self.params``, is logged, and is handed to
    #: :meth:`apply_parameter` (override it when more than ``self.params`` must change).
    RUNTIME_PARAMS: tuple[str, ...] = ()
    #: hardware_id used in diagnostics.
    HARDWARE_ID = "ppod"

    def __init__(self, node_name: str, **kwargs: Any):
        super().__init__(node_name, **kwargs)
        self._declared = {p.name: p for p in with_runtime(COMMON_PARAMS + tuple(self.PARAMS), self.RUNTIME_PARAMS)}
        declare(self, self._declared.values())
        self.add_on_set_parameters_callback(self._check_parameters)
        self.add_post_set_parameters_callback(self._parameters_set)
        self.lifecycle_state = "unconfigured"
        self.params: dict[str, Any] = {}
        self.diagnostics = diag.Diagnostics(self, self.HARDWARE_ID)
        self.diagnostics.set("lifecycle", diag.OK, "unconfigured")
        service = getattr(self, "_service_change_state", None)
        if service is not None:
            self._rclpy_change_state = service.callback
            service.callback = self._guarded_change_state

    def _guarded_change_state(self, request, response):
        """The change_state service, answering an invalid transition with failure (module docstring)."""
        try:
            return self._rclpy_change_state(request, response)
        except _rclpy.RCLError as exc:
            label = request.transition.label or f"id {request.transition.id}"
            message = f"invalid lifecycle transition {label} in state {self.lifecycle_state}: {exc}"
            self.get_logger().warning(message.splitlines()[0])
            self.diagnostics.set("lifecycle", diag.WARN, message.splitlines()[0], state=self.lifecycle_state)
            response.success = False
            return response

    # --------------------------------------------------------------- runtime parameters
    def _check_parameters(self, parameters) -> SetParametersResult:
        # Read-only ones never get here (rclpy refuses them); runtime ones are checked like at configure.
        for param in parameters:
            p = self._declared.get(param.name)
            if p is None:
                continue
            try:
                checked(p, param.value)
                self.check_parameter(param.name, param.value)
            except PpodError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
        return SetParametersResult(successful=True)

    def _parameters_set(self, parameters) -> None:
        for param in parameters:
            p = self._declared.get(param.name)
            if p is None or not p.runtime:
                continue
            value = checked(p, param.value)
            old = self.params.get(p.name, p.default)
            self.params[p.name] = value
            self.apply_parameter(p.name, value)
            self.get_logger().info(f"parameter {p.name}: {old!r} -> {value!r} (applied)")

    def check_parameter(self, name: str, value: Any) -> None:
        """Refuse a runtime change (raise PpodError) beyond the declared range and choices."""

    def apply_parameter(self, name: str, value: Any) -> None:
        """Apply a runtime parameter change; ``self.params`` already holds the new value."""

    # --------------------------------------------------------------- subclass hooks
    def on_configure_node(self, params: dict[str, Any]) -> None:
        """Build the core config from ``params`` and open resources. Raise PpodError to fail."""

    def on_activate_node(self) -> None:
        """Start streaming."""

    def on_deactivate_node(self) -> None:
        """Stop streaming; bring hardware to a safe state."""

    def on_cleanup_node(self) -> None:
        """Release what configure opened."""

    def on_shutdown_node(self) -> None:
        """Make hardware safe and release everything, from any state."""

    def release_on_destroy(self) -> None:
        """Release threads and devices of a node destroyed without its shutdown transition (in-process:
        a test harness, a container), without the steps that need the executor. Default: nothing."""

    def destroy_node(self) -> None:
        # A node destroyed while configured or active must not leave its threads behind: a waveform
        # generator's heartbeat thread outliving its node kept the device's watchdog fed with no node
        # in charge of the plate (found in the node tests: every generator left one running).
        if self.lifecycle_state != "finalized":
            try:
                self.release_on_destroy()
            except PpodError as exc:
                self.get_logger().error(f"release on destroy failed: {exc}")
        super().destroy_node()

    # --------------------------------------------------------------- rclpy callbacks
    def _run(self, transition: str, fn, new_state: str) -> TransitionCallbackReturn:
        try:
            fn()
        except PpodError as exc:
            self.get_logger().error(f"{transition} failed: {exc}")
            self.diagnostics.set("lifecycle", diag.ERROR, f"{transition} failed: {exc}", state=self.lifecycle_state)
            return TransitionCallbackReturn.FAILURE
        self.lifecycle_state = new_state
        self.diagnostics.set("lifecycle", diag.OK, new_state)
        self.get_logger().info(f"{transition}: now {new_state}")
        return TransitionCallbackReturn.SUCCESS

    def on_configure(self, state: State) -> TransitionCallbackReturn:
        def configure() -> None:
            self.params = read(self, self.PARAMS)
            self.on_configure_node(self.params)

        ret = self._run("configure", configure, "inactive")
        return ret if ret != TransitionCallbackReturn.SUCCESS else super().on_configure(state)

    def on_activate(self, state: State) -> TransitionCallbackReturn:
        # Managed publishers first, so the node can publish from its activate hook.
        ret = super().on_activate(state)
        if ret != TransitionCallbackReturn.SUCCESS:
            return ret
        ret = self._run("activate", self.on_activate_node, "active")
        if ret != TransitionCallbackReturn.SUCCESS:
            super().on_deactivate(state)
        return ret

    def on_deactivate(self, state: State) -> TransitionCallbackReturn:
        ret = self._run("deactivate", self.on_deactivate_node, "inactive")
        super().on_deactivate(state)
        return ret

    def on_cleanup(self, state: State) -> TransitionCallbackReturn:
        ret = self._run("cleanup", self.on_cleanup_node, "unconfigured")
        return ret if ret != TransitionCallbackReturn.SUCCESS else super().on_cleanup(state)

    def on_shutdown(self, state: State) -> TransitionCallbackReturn:
        # Shutdown must always reach a safe state; a failure is logged but not retried.
        self._run("shutdown", self.on_shutdown_node, "finalized")
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state: State) -> TransitionCallbackReturn:
        self.get_logger().error(f"error during a transition from {state.label}; making hardware safe")
        try:
            self.on_shutdown_node()
        except PpodError as exc:
            self.get_logger().error(f"shutdown after error failed: {exc}")
        self.lifecycle_state = "unconfigured"
        self.diagnostics.set("lifecycle", diag.ERROR, f"error in transition from {state.label}")
        return TransitionCallbackReturn.SUCCESS

    # --------------------------------------------------------------- used by run_node
    def autostart(self) -> bool:
        """Configure and activate now if the ``autostart`` parameter is set; False if a step failed."""
        if not self.get_parameter("autostart").value:
            return True
        for trigger in (self.trigger_configure, self.trigger_activate):
            trigger()
            if self.lifecycle_state == "unconfigured" or (trigger == self.trigger_activate
                                                           and self.lifecycle_state != "active"):
                return False
        return True

    def finalize(self) -> None:
        """Bring the node to 'finalized' from wherever it is (deactivating first if active)."""
        if self.lifecycle_state == "active":
            self.trigger_deactivate()
        if self.lifecycle_state != "finalized":
            self.trigger_shutdown()
