"""What every node of the AMR shares: QoS by topic, freshness of inputs, a diagnostic updater, fault hooks.

Every callback goes through :meth:`Behaviour.gate` (``hang`` blocks there, ``slow_service`` sleeps
in the service callback) and every publish through :meth:`Behaviour.send` (``degrade`` keeps
every 4th message, ``flap`` drops everything during its off phases, ``delay`` hands the already
stamped message to a thread that publishes it 300 ms later; a ``FaultSpec.size`` changes the
fraction kept and the delay). ``qos`` re-creates the node's
best-effort subscriptions as reliable (:meth:`Behaviour.misconfigure_qos`); ``diag`` turns the
node's first updater task to ERROR. The process-wide faults are in :mod:`.process`.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable
from typing import Any

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data

from stream_viz.demo.amr.topology import BEST_EFFORT, DIAG, LATCHED, UPDATERS, T
from stream_viz.demo.faults import DEGRADE_KEEP, STOP, keeps
from stream_viz.demo.messages import load_type
from stream_viz.demo.topology import NodeSpec

DELAY_S = 0.3  # the "delay" fault without a size: how much older than usual messages arrive
FLAP_S = 4.0  # the "flap" fault: seconds off, then seconds on
SLOW_SERVICE_S = 5.0  # the "slow_service" fault: time per call (clients give up after 3 s)

RELIABLE = QoSProfile(depth=10)
LATCHED_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL, history=HistoryPolicy.KEEP_LAST)


def qos_for(topic: str) -> QoSProfile:
    """The QoS a node of this robot uses on ``topic`` (publishers and subscribers alike)."""
    if topic in BEST_EFFORT:
        return qos_profile_sensor_data
    if topic in LATCHED:
        return LATCHED_QOS
    return RELIABLE


class Delayer:
    """Publishes handed-over messages ``delay_s`` after they were handed over, in order, from a thread."""

    def __init__(self, delay_s: float = DELAY_S) -> None:
        self.delay_s = delay_s
        self._q: queue.Queue = queue.Queue()
        threading.Thread(target=self._run, daemon=True, name="delay").start()

    def put(self, pub: Any, msg: Any) -> None:
        self._q.put((time.monotonic() + self.delay_s, pub, msg))

    def _run(self) -> None:
        while not STOP.is_set():
            try:
                due, pub, msg = self._q.get(timeout=0.5)
            except queue.Empty:
                continue
            if STOP.wait(max(0.0, due - time.monotonic())):
                return
            try:
                pub.publish(msg)
            except Exception:  # the node is being destroyed
                return


class Behaviour:
    """One node of the AMR: a real rclpy node, its topics by name, and the fault hooks.

    Subclasses build their endpoints in :meth:`setup` (and override :meth:`make_node` for
    another node class). Callbacks get the message only; the time of the last delivery per input is in
    ``self.last`` (monotonic s).
    """

    def __init__(self, spec: NodeSpec, context: Any) -> None:
        ns, _, short = spec.name.rpartition("/")
        self.spec, self.short = spec, short
        self.node = self.make_node(short, ns or "/", context)
        self.log = self.node.get_logger()
        self.cg = MutuallyExclusiveCallbackGroup()  # one per node: a hang holds one executor thread
        self.fault: str | None = None
        self.diag_error = False
        self.last: dict[str, float] = {}
        self._pubs: dict[str, Any] = {}
        self._subs: dict[str, tuple[Any, Callable, str]] = {}
        self._count: dict[str, int] = {}
        self._keep = DEGRADE_KEEP  # the "degrade" fault: fraction of messages still published
        self._delayer: Delayer | None = None
        self._flap_since = 0.0
        self._flap_off = False
        self.setup()
        if spec.name in UPDATERS:
            self._diag_pub = self.node.create_publisher(load_type(T["diag"]), DIAG, 1)
            self.timer(1.0, self._update_diagnostics)

    def make_node(self, name: str, namespace: str, context: Any) -> Any:
        return Node(name, namespace=namespace, context=context)

    def setup(self) -> None:
        """Create the node's endpoints and timers."""

    # -- endpoints ---------------------------------------------------------------------------
    def publisher(self, topic: str, type_key: str) -> Any:
        self._pubs[topic] = self.node.create_publisher(load_type(T[type_key]), topic, qos_for(topic))
        return self._pubs[topic]

    def subscribe(self, topic: str, type_key: str, callback: Callable[[Any], None] | None = None) -> None:
        """Subscribe with the topic's QoS; every delivery is noted in ``self.last``."""
        def on_msg(msg: Any) -> None:
            if not self.gate():
                return
            self.last[topic] = time.monotonic()
            if callback is not None:
                callback(msg)

        sub = self.node.create_subscription(load_type(T[type_key]), topic, on_msg, qos_for(topic),
                                            callback_group=self.cg)
        self._subs[topic] = (sub, on_msg, type_key)

    def timer(self, period: float, callback: Callable[[], None]) -> Any:
        def on_timer() -> None:
            if self.gate():
                callback()

        return self.node.create_timer(period, on_timer, callback_group=self.cg)

    def stale(self, max_age: float, *inputs: str) -> list[str]:
        """Those of ``inputs`` not delivered within ``max_age`` s."""
        now = time.monotonic()
        return [i for i in inputs if now - self.last.get(i, -1e9) > max_age]

    def stamp(self) -> Any:
        return self.node.get_clock().now().to_msg()

    # -- fault hooks -------------------------------------------------------------------------
    def gate(self) -> bool:
        """Run first in every callback; False: skip it. A hung node blocks here until shutdown."""
        if self.fault == "hang":
            STOP.wait()
            return False
        return not STOP.is_set()

    def send(self, topic: str, msg: Any) -> None:
        """Publish ``msg`` on ``topic`` unless a fault of this node withholds or delays it."""
        pub = self._pubs[topic]
        if self.fault == "degrade":
            self._count[topic] = self._count.get(topic, 0) + 1
            if not keeps(self._count[topic], self._keep):
                return
        elif self.fault == "flap":
            off = int((time.monotonic() - self._flap_since) / FLAP_S) % 2 == 0
            if off and not self._flap_off:
                self.log.warn("lost connection to the device; reconnecting")
            self._flap_off = off
            if off:
                return
        elif self.fault == "delay":
            self._delayer.put(pub, msg)
            return
        pub.publish(msg)

    def set_fault(self, fault: str, size: float | None = None) -> None:
        """Start ``fault`` (hang, degrade, delay, flap, slow_service, qos, diag) of ``size`` in this node.

        ``size`` (FaultSpec.size, None: the default): degrade's fraction kept, delay's ms.
        """
        if fault == "delay":
            self._delayer = Delayer(DELAY_S if size is None else size / 1e3)
        elif fault == "degrade" and size is not None:
            self._keep = size
        elif fault == "flap":
            self._flap_since = time.monotonic()
        elif fault == "qos":
            self.misconfigure_qos()
            return
        elif fault == "diag":
            self.diag_error = True
            return
        self.fault = fault

    def misconfigure_qos(self) -> None:
        """Re-create every best-effort subscription as reliable: DDS matches none of their publishers."""
        for topic, (sub, on_msg, type_key) in list(self._subs.items()):
            if topic not in BEST_EFFORT:
                continue
            self.node.destroy_subscription(sub)
            new = self.node.create_subscription(load_type(T[type_key]), topic, on_msg, RELIABLE,
                                                callback_group=self.cg)
            self._subs[topic] = (new, on_msg, type_key)

    def slow_service(self) -> None:
        """Run first in a service callback: the ``slow_service`` fault makes every call take 5 s."""
        if self.fault == "slow_service":
            STOP.wait(SLOW_SERVICE_S)

    # -- diagnostics -------------------------------------------------------------------------
    def diagnostics(self) -> list[tuple[int, str]]:
        """(level, message) per updater task of this node, in ``UPDATERS`` order; all OK by default."""
        return [(0, "OK")] * len(UPDATERS[self.spec.name])

    def _update_diagnostics(self) -> None:
        # as diagnostic_updater publishes: one array per node, names "<node name>: <task>"
        dm = load_type(T["diag"])
        status_type = load_type(T["diag_status"])
        arr = dm()
        arr.header.stamp = self.stamp()
        for i, ((task, hw), (level, text)) in enumerate(zip(UPDATERS[self.spec.name], self.diagnostics(),
                                                              strict=True)):
            if i == 0 and self.diag_error:
                level, text = 2, "device reports a fault (error code 0x21)"
            arr.status.append(status_type(level=bytes([level]), name=f"{self.short}: {task}",
                                          message=text, hardware_id=hw))
        self._diag_pub.publish(arr)

    def finish(self) -> None:
        """Called before the node is destroyed at a normal end (one-shot jobs log their result)."""

    def destroy(self) -> None:
        self.node.destroy_node()
