"""``stream-viz agent``'s sampler: this computer's ROS processes, published as one `HostReport`.

It maps the nodes whose participant's GUID prefix carries this host's id to their processes
(`PidResolver`, as the monitor does locally; the /rosout endpoints read only when their number
changes), samples those processes and their ancestors
(`ProcessSampler`) and publishes the report on `AGENT_TOPIC` (best effort, depth 1). Where it
may listen to the kernel's process events (`ExitCodes`), the exit codes of the processes that
ended ride in its next `EXITS_KEPT` reports: one lost report does not lose them. Its node has
no /rosout publisher, no parameter or type-description services and is hidden (``_`` name); it
publishes nothing else and calls nothing.
"""

from __future__ import annotations

import os
import socket
import time
from typing import Any

from rclpy.context import Context
from rclpy.qos import QoSProfile, ReliabilityPolicy

from stream_viz.collect.cgroups import read_mounts
from stream_viz.collect.collector import ObserverNode, end_node, new_node
from stream_viz.collect.diagcdr import diagnostic_array
from stream_viz.collect.exitcodes import ExitCodes
from stream_viz.collect.fastdds import decode_gid
from stream_viz.collect.hostreport import AGENT_TOPIC, HostReport, encode
from stream_viz.collect.oomkills import OomKill, OomWatch
from stream_viz.collect.pidmap import PidResolver
from stream_viz.collect.processes import MachineSampler, ProcessSampler
from stream_viz.collect.readings import ProcessReading
from stream_viz.collect.rosgraph import UNKNOWN_NODE
from stream_viz.errors import CollectError
from stream_viz.model.ids import node_fqn

QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
GIDS_EVERY_S = 30.0  # the /rosout endpoints read again at least this often
UNSURE = ("unknown", "ambiguous", "unverified")  # pid statuses resolved again each sample
IDENTITY_EVERY = 10  # a process's command line, user and start time: when new and every 10th report
EXITS_KEPT = 3  # reports an exit code rides in (and samples its kernel event is waited for)


class AgentNode(ObserverNode):
    """An observer node allowed one publisher: the host reports on `AGENT_TOPIC`."""

    def create_publisher(self, msg_type: Any, topic: str, *args: Any, **kwargs: Any) -> Any:
        if topic == AGENT_TOPIC:
            return super(ObserverNode, self).create_publisher(msg_type, topic, *args, **kwargs)
        return super().create_publisher(msg_type, topic, *args, **kwargs)


class Agent:
    """Samples this host's ROS processes and publishes one report per `step`.

    Parameters
    ----------
    domain_id : int
        The ROS_DOMAIN_ID of the robot.
    period_s : float
        The sampling period (said in each report, so the monitor knows when one is late).
    host : str, optional
        The name this host goes by (default: its host name).
    """

    def __init__(self, domain_id: int, period_s: float = 1.0, host: str | None = None) -> None:
        self.domain_id, self.period_s = domain_id, period_s
        self.host = host or socket.gethostname()
        self.name = f"_stream_viz_agent_{os.getpid()}"
        self.sampler = ProcessSampler()
        self.machine = MachineSampler()
        self._count, self._read_at, self._unsure = -1, 0.0, True
        self._gids: dict[str, bytes] = {}
        self._mine: dict[str, int] = {}
        self.seq = 0
        self._ctx: Context | None = None
        self.node: AgentNode | None = None
        self.pub: Any = None
        self.host_id: int | None = None
        self.resolver: PidResolver | None = None
        self._dead: dict[int, ProcessReading] = {}
        self.ooms = OomWatch(read_mounts())
        self._killed: dict[int, OomKill] = {}  # of the ended processes kept in the reports
        self.last_size = 0  # bytes of the last report published
        self._sent: set[int] = set()  # processes of the last report (their identity was sent)
        self.exits: ExitCodes | None = None
        self._ended: dict[int, tuple[int, int | None]] = {}  # pid → (report it ended in, exit code)

    def start(self) -> None:
        """Create our own Context, node and the one publisher."""
        from diagnostic_msgs.msg import DiagnosticArray

        try:
            self._ctx, self.node = new_node(AgentNode, self.name, self.domain_id)
            self.pub = self.node.create_publisher(DiagnosticArray, AGENT_TOPIC, QOS)
        except Exception as e:  # rclpy raises RCLError/RuntimeError kinds we cannot name portably
            self.close()
            raise CollectError(f"cannot start the agent on domain {self.domain_id}: {e}") from e
        self.host_id = self._own_host()
        self.resolver = PidResolver(self.domain_id, self.host_id)
        self.exits = ExitCodes()

    def _own_host(self) -> int:
        # Our own publisher's gid carries our participant's prefix, hence this host's id.
        me = node_fqn("/", self.name)
        for i in self.node.get_publishers_info_by_topic(AGENT_TOPIC):
            if node_fqn(i.node_namespace, i.node_name) == me:
                info = decode_gid(bytes(i.endpoint_gid))
                if info is not None:
                    return info.host_id
        raise CollectError("the agent cannot read its own Fast DDS GUID (is the RMW Fast DDS?)")

    def sample(self) -> HostReport:
        """Read this host's nodes' processes now."""
        mine = self._participants()
        ps = self.sampler.sample(set(mine.values()))
        if ps.exited:  # a node restarted under its old name has a new gid
            self._count = -1
        self._killed.update(self.ooms.update(ps.processes, {p: r.metrics.get("rss_mb", 0.0)
                                                            for p, r in ps.exited.items()}))
        # An ended process stays (alive=False) while DDS still lists its nodes, as in the monitor.
        self._dead.update(ps.exited)
        listed = set(mine.values())
        self._dead = {p: r for p, r in self._dead.items() if p in listed and p not in ps.processes}
        self._killed = {p: k for p, k in self._killed.items() if p in self._dead}
        processes = dict(ps.processes)
        for pid, r in self._dead.items():
            r.alive = False
            processes[pid] = r
        self.seq += 1
        return HostReport(self.host, self.host_id, self.seq, self.period_s, mine, processes,
                          self.machine.sample(mine.values()), dict(self._killed),
                          self._exit_codes(ps.exited))

    def _exit_codes(self, exited: dict[int, ProcessReading]) -> dict[int, int]:
        """The exit codes known of the processes that ended in the last `EXITS_KEPT` reports (the
        kernel's event may come a moment after the process is seen gone)."""
        self._ended.update({pid: (self.seq, None) for pid in exited})
        self._ended = {p: e for p, e in self._ended.items() if e[0] > self.seq - EXITS_KEPT}
        for pid, (seq, code) in self._ended.items():
            if code is None and self.exits is not None:
                self._ended[pid] = (seq, self.exits.take(pid))
        return {pid: code for pid, (_, code) in self._ended.items() if code is not None}

    def _participants(self) -> dict[str, int]:
        """GUID prefix → pid of this host's participants. The /rosout endpoints are read again
        only when their number changed, a process exited, a name was not discovered yet, or every
        `GIDS_EVERY_S`; pids are resolved again while one is unsure. A graph read costs the agent
        more than sampling 50 processes."""
        now = time.monotonic()
        count = self.node.count_publishers("/rosout")
        if count != self._count or now - self._read_at >= GIDS_EVERY_S:
            infos = self.node.get_publishers_info_by_topic("/rosout")
            self._gids = {node_fqn(i.node_namespace, i.node_name): bytes(i.endpoint_gid)
                          for i in infos if i.node_name != UNKNOWN_NODE}
            self._count = count if len(self._gids) == len(infos) else -1
            self._read_at, self._unsure = now, True
        if self._unsure:
            pids = self.resolver.resolve(self._gids)
            self.resolver.forget({p.prefix for p in pids.values() if p.prefix})
            self._mine = {p.prefix: p.pid for p in pids.values() if p.pid is not None and p.prefix}
            self._unsure = any(p.status in UNSURE for p in pids.values())
        return self._mine

    def step(self) -> None:
        """Sample and publish one report (its size in bytes, CDR, in ``last_size``)."""
        report = self.sample()
        known = set() if report.seq % IDENTITY_EVERY == 1 else self._sent
        raw = diagnostic_array(time.time_ns(), encode(report, known))
        self._sent = set(report.processes)
        self.pub.publish(raw)
        self.last_size = len(raw)

    def close(self) -> None:
        """Destroy the node and shut our Context. Idempotent."""
        node, ctx, self.node, self._ctx = self.node, self._ctx, None, None
        end_node(node, ctx)
        if self.exits is not None:
            self.exits.close()

    def __enter__(self) -> Agent:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

