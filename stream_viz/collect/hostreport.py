"""What a `stream-viz agent` tells the monitor about its computer, as plain status rows. Pure.

One report per sample: a ``diagnostic_msgs/DiagnosticArray`` whose first status describes the
host (``name`` = `HOST_STATUS`, ``hardware_id`` = the host name, key-values ``host_id``, ``seq``,
``period_s``) and whose other statuses are one per process (``name`` = ``process <pid>``, level
OK when alive, ERROR once it ended, ``message`` = the process name, key-values its parent, its
participants' GUID prefixes, identity and θ metrics). ROS tools display it as any diagnostics.
`encode` and `decode` work on `StatusRow` tuples so this module needs no ROS.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

from stream_viz.collect.readings import ProcessReading
from stream_viz.model.theta import SCHEMAS

AGENT_TOPIC = "/_stream_viz/hosts"  # hidden: the monitor's model leaves it out, as its own node
SCHEMA = "stream-viz.agent/v1"
HOST_STATUS = "stream_viz/host"
OK, ERROR = 0, 2
CMDLINE_MAX = 120  # characters of a command line kept in a report (the message stays small)


class StatusRow(NamedTuple):
    """One ``DiagnosticStatus``: level, name, message, hardware id, key-values."""

    level: int
    name: str
    message: str
    hardware_id: str
    values: list[tuple[str, str]]


@dataclass
class HostReport:
    """One agent's sample of its host.

    ``participants`` maps a GUID prefix (hex of its 12 bytes) to the pid of the process holding
    it; ``processes`` are the nodes' processes and their ancestors, ended ones (``alive=False``)
    kept while DDS still lists their nodes.
    """

    host: str
    host_id: int
    seq: int = 0
    period_s: float = 1.0
    participants: dict[str, int] = field(default_factory=dict)
    processes: dict[int, ProcessReading] = field(default_factory=dict)


def encode(report: HostReport) -> list[StatusRow]:
    """Return the status rows of ``report`` (the host first, then its processes by pid)."""
    head = [("schema", SCHEMA), ("host_id", str(report.host_id)), ("seq", str(report.seq)),
            ("period_s", f"{report.period_s:g}")]
    rows = [StatusRow(OK, HOST_STATUS, f"{len(report.processes)} processes", report.host, head)]
    by_pid: dict[int, list[str]] = {}
    for prefix, pid in sorted(report.participants.items()):
        by_pid.setdefault(pid, []).append(prefix)
    for pid, p in sorted(report.processes.items()):
        kv = [("pid", str(pid)), ("ppid", str(p.ppid or 0)), ("alive", "1" if p.alive else "0")]
        if pid in by_pid:
            kv.append(("participants", ",".join(by_pid[pid])))
        if p.create_time is not None:
            kv.append(("create_time", f"{p.create_time:.2f}"))
        if p.cmdline:
            kv.append(("cmdline", p.cmdline[:CMDLINE_MAX]))
        if p.username:
            kv.append(("username", p.username))
        if p.unreadable:
            kv.append(("unreadable", ",".join(p.unreadable)))
        kv += [(k, f"{v:.4g}") for k, v in sorted(p.metrics.items()) if math.isfinite(v)]
        rows.append(StatusRow(OK if p.alive else ERROR, f"process {pid}", p.name, report.host, kv))
    return rows


def decode(rows: list[StatusRow]) -> HostReport | None:
    """Return the report the rows carry, None when they are not an agent's (no host status first)."""
    if not rows or rows[0].name != HOST_STATUS:
        return None
    head = dict(rows[0].values)
    if head.get("schema") != SCHEMA:
        return None
    report = HostReport(rows[0].hardware_id, int(head["host_id"]), int(head.get("seq", 0)),
                        float(head.get("period_s", 1.0)))
    metrics = set(SCHEMAS["process"])
    for row in rows[1:]:
        kv = dict(row.values)
        pid = int(kv["pid"])
        ct = kv.get("create_time")
        p = ProcessReading(pid, int(kv.get("ppid", 0)) or None, row.message, kv.get("cmdline", ""),
                           float(ct) if ct else None, kv.get("username"),
                           {k: float(v) for k, v in kv.items() if k in metrics},
                           alive=kv.get("alive", "1") == "1",
                           unreadable=[u for u in kv.get("unreadable", "").split(",") if u])
        report.processes[pid] = p
        for prefix in kv.get("participants", "").split(","):
            if prefix:
                report.participants[prefix] = pid
    return report


def host_of_prefix(prefix: str) -> int:
    """Return the Fast DDS host id of a GUID prefix given as hex (bytes 2–3, as `decode_gid`)."""
    return int(prefix[4:8], 16)
