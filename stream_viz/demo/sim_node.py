"""One simulated ROS node, driven entirely by its :class:`~stream_viz.demo.topology.NodeSpec`.

Each node has its own mutually exclusive callback group, so on the process's multi-threaded
executor a hung node blocks only itself (and one executor thread). Fault hooks live here: every
callback passes :meth:`SimNode._gate` (hang, delay) and every publish :meth:`SimNode._publish`
(degrade); the process-wide faults (crash, cpu, leak, errlog) are in ``robot_process``.
"""

from __future__ import annotations

import random
import time
from functools import partial
from typing import Any

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node

from stream_viz.demo.faults import DEGRADE_KEEP, STOP, keeps
from stream_viz.demo.messages import factory, fill_response, load_type
from stream_viz.demo.topology import NodeSpec, PubSpec

_DIAG = "diagnostic_msgs/msg/DiagnosticArray"


class SimNode:
    """A real rclpy node publishing, subscribing, serving and calling as its spec says."""

    def __init__(self, spec: NodeSpec, context: Any, all_nodes: list[str]) -> None:
        ns, _, name = spec.name.rpartition("/")
        self.spec = spec
        self.node = Node(name, namespace=ns or "/", context=context)
        self.log = self.node.get_logger()
        self.fault: str | None = None  # hang | degrade | delay, set by the fault scheduler (set_fault)
        self.fault_size: float | None = None  # FaultSpec.size (None: the kind's default)
        self.diag_errors: set[str] = set()  # nodes this diag monitor reports as ERROR
        self.last: dict[str, float] = {}  # input (topic / service) -> monotonic time of last delivery
        self._seq = 0
        self._count = 0  # publishes attempted, for "degrade"
        self._rng = random.Random(hash(spec.name))
        self._pending: tuple[Any, float] | None = None
        cg = MutuallyExclusiveCallbackGroup()
        self._pubs: dict[str, tuple[Any, Any]] = {}
        self._triggered: dict[str, list[PubSpec]] = {}
        for p in spec.pubs:
            pub = self.node.create_publisher(load_type(p.type), p.topic, 10)
            self._pubs[p.topic] = (pub, factory(p.type))
            if p.trigger:
                self._triggered.setdefault(p.trigger, []).append(p)
            else:
                self.node.create_timer(1.0 / p.rate, partial(self._on_timer, p), callback_group=cg)
        for s in spec.subs:
            self.node.create_subscription(load_type(s.type), s.topic, partial(self._on_msg, s.topic), 10,
                                          callback_group=cg)
        for s in spec.services:
            self.node.create_service(load_type(s.type), s.name, partial(self._serve, s.type),
                                     callback_group=cg)
        self._clients = []
        for c in spec.clients:
            cls = load_type(c.type)
            client = self.node.create_client(cls, c.name, callback_group=cg)
            self._clients.append(client)
            self.node.create_timer(c.period, partial(self._call, c, client, cls), callback_group=cg)
        if spec.diag_monitor:
            self._all_nodes = all_nodes
            self._diag_pub = self.node.create_publisher(load_type(_DIAG), "/diagnostics", 10)
            self.node.create_timer(1.0, self._on_diag, callback_group=cg)

    # -- fault hooks ------------------------------------------------------------------------
    def set_fault(self, fault: str, size: float | None = None) -> None:
        """Start ``fault`` (hang, degrade, delay) of ``size`` (FaultSpec.size) in this node."""
        self.fault, self.fault_size = fault, size

    def _gate(self) -> bool:
        """Run at the start of every callback; False means skip it (hang released at shutdown)."""
        if self.fault == "hang":
            STOP.wait()
            return False
        if self.fault == "delay":  # a size: exactly that many ms; none: a random 50-400 ms
            time.sleep(self._rng.uniform(0.05, 0.4) if self.fault_size is None else self.fault_size / 1e3)
        return not STOP.is_set()

    def _publish(self, p: PubSpec) -> None:
        now = time.monotonic()
        stale = [r for r in p.requires if now - self.last.get(r, -1e9) > p.max_age]
        if stale:
            self.log.warn(f"not publishing {p.topic}: no fresh {', '.join(stale)}", throttle_duration_sec=5.0)
            return
        self._count += 1
        keep = DEGRADE_KEEP if self.fault_size is None else self.fault_size
        if self.fault == "degrade" and not keeps(self._count, keep):
            return
        pub, make = self._pubs[p.topic]
        self._seq += 1
        pub.publish(make(self.node.get_clock().now().to_msg(), self._seq))

    # -- callbacks --------------------------------------------------------------------------
    def _on_timer(self, p: PubSpec) -> None:
        if self._gate():
            self._publish(p)

    def _on_msg(self, topic: str, _msg: Any) -> None:
        if not self._gate():
            return
        self.last[topic] = time.monotonic()
        for p in self._triggered.get(topic, ()):
            self._publish(p)

    def _serve(self, type_name: str, _request: Any, response: Any) -> Any:
        self._gate()  # a hung server never answers: the caller times out
        return fill_response(type_name, response)

    def _call(self, c: Any, client: Any, cls: type) -> None:
        if not self._gate():
            return
        now = time.monotonic()
        if self._pending is not None:
            future, sent = self._pending
            if not future.done() and now - sent < c.timeout:
                return
            if not future.done():
                client.remove_pending_request(future)
                self.log.warn(f"{c.name} timed out after {c.timeout:.0f} s")
            self._pending = None
        if not client.service_is_ready():
            self.log.warn(f"waiting for service {c.name}", throttle_duration_sec=5.0)
            return
        future = client.call_async(cls.Request())
        future.add_done_callback(lambda f, name=c.name: self._answered(name, f))
        self._pending = (future, now)

    def _answered(self, name: str, future: Any) -> None:
        if not future.cancelled() and future.result() is not None:
            self.last[name] = time.monotonic()

    def _on_diag(self) -> None:
        if not self._gate():
            return
        dm = __import__("diagnostic_msgs.msg", fromlist=["DiagnosticArray"])
        arr = dm.DiagnosticArray()
        arr.header.stamp = self.node.get_clock().now().to_msg()
        for name in self._all_nodes:
            st = dm.DiagnosticStatus(name=name, hardware_id=name)
            if name in self.diag_errors:
                st.level, st.message = dm.DiagnosticStatus.ERROR, f"{name}: injected fault (diag)"
            else:
                st.level, st.message = dm.DiagnosticStatus.OK, "ok"
            arr.status.append(st)
        self._diag_pub.publish(arr)

    def destroy(self) -> None:
        """Destroy the rclpy node (its endpoints leave the graph)."""
        self.node.destroy_node()
