"""Whether the ROS graph changed: the observer node's rcl graph guard condition (ctypes).

rmw triggers a node's graph guard condition whenever its graph cache changes — a participant, a
node, a publisher, subscription, service or client came or went (and a QoS changed in place, which
is an endpoint created again). rclpy does not expose it, so `GraphSignal` waits on it with a zero
timeout through rcl itself, in a wait set of its own. A graph read costs one rclpy query per node
and kind (publishers, subscriptions, services, clients): at 1,000 nodes most of a sample; with
the signal it is done only when something changed. Where the signal cannot be set up
(`available` False, ``why`` says why) every call says "changed", and the graph is read each time.
"""

from __future__ import annotations

import ctypes
from typing import Any

from stream_viz.collect.rcltake import Allocator, rcl_libraries

RET_OK = 0
RET_TIMEOUT = 2  # RCL_RET_TIMEOUT: nothing was ready


class _WaitSet(ctypes.Structure):  # rcl_wait_set_t (Jazzy): six (array, size) pairs, then impl
    _fields_ = [(f"{kind}{part}", typ)
                for kind in ("subscriptions", "guard_conditions", "timers", "clients", "services", "events")
                for part, typ in (("", ctypes.POINTER(ctypes.c_void_p)), ("_size", ctypes.c_size_t))]
    _fields_ += [("impl", ctypes.c_void_p)]


class GraphSignal:
    """Tells whether the graph changed since the last `changed` call, for one rclpy node.

    Parameters
    ----------
    node : rclpy Node
        The observer node. It must not be spun by an executor that waits on its graph guard
        condition (rclpy's do not): a wait elsewhere would take the trigger.
    """

    def __init__(self, node: Any) -> None:
        self.available = False
        self.why = ""
        self._ws: _WaitSet | None = None
        try:
            self._setup(node)
            self.available = True
        except (OSError, AttributeError, ValueError) as e:
            self.why = f"graph change signal unavailable: {e}"

    def _setup(self, node: Any) -> None:
        rcl, rcutils = rcl_libraries()
        rcl.rcl_get_zero_initialized_wait_set.restype = _WaitSet
        rcl.rcl_wait_set_init.argtypes = [ctypes.POINTER(_WaitSet)] + [ctypes.c_size_t] * 6 + [
            ctypes.c_void_p, Allocator]
        rcl.rcl_node_get_graph_guard_condition.restype = ctypes.c_void_p
        rcl.rcl_node_get_graph_guard_condition.argtypes = [ctypes.c_void_p]
        rcl.rcl_wait_set_clear.argtypes = [ctypes.POINTER(_WaitSet)]
        rcl.rcl_wait_set_add_guard_condition.argtypes = [ctypes.POINTER(_WaitSet), ctypes.c_void_p,
                                                         ctypes.c_void_p]
        rcl.rcl_wait.argtypes = [ctypes.POINTER(_WaitSet), ctypes.c_int64]
        rcl.rcl_wait_set_fini.argtypes = [ctypes.POINTER(_WaitSet)]
        self._rcl = rcl
        self._guard = rcl.rcl_node_get_graph_guard_condition(ctypes.c_void_p(node.handle.pointer))
        if not self._guard:
            raise ValueError("the node has no graph guard condition")
        ws = rcl.rcl_get_zero_initialized_wait_set()
        ret = rcl.rcl_wait_set_init(ctypes.byref(ws), 0, 1, 0, 0, 0, 0,
                                    ctypes.c_void_p(node.context.handle.pointer),
                                    rcutils.rcutils_get_default_allocator())
        if ret != RET_OK:
            raise OSError(f"rcl_wait_set_init returned {ret}")
        self._ws = ws

    def changed(self) -> bool:
        """True when the graph changed since the last call (and always when unavailable)."""
        ws = self._ws
        if ws is None:
            return True
        rcl = self._rcl
        if (rcl.rcl_wait_set_clear(ctypes.byref(ws)) != RET_OK
                or rcl.rcl_wait_set_add_guard_condition(ctypes.byref(ws), ctypes.c_void_p(self._guard),
                                                        None) != RET_OK):
            return True
        ret = rcl.rcl_wait(ctypes.byref(ws), 0)
        if ret == RET_TIMEOUT:
            return False
        return ret != RET_OK or bool(ws.guard_conditions[0])

    def close(self) -> None:
        """Free the wait set (before the node and its context are destroyed). Idempotent."""
        ws, self._ws = self._ws, None
        if ws is not None:
            self._rcl.rcl_wait_set_fini(ctypes.byref(ws))
