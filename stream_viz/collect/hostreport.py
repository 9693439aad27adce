"""What a `stream-viz agent` tells the monitor about its computer, as plain status rows. Pure.

One report per sample: a ``diagnostic_msgs/DiagnosticArray`` whose first status describes the
host (``name`` = `HOST_STATUS`, ``hardware_id`` = the host name, key-values ``schema``,
``host_id``, ``seq``, ``period_s``, ``machine``: the whole computer's CPU and memory in use as
``machine_cpu_percent=97 machine_mem_percent=41``, and ``exits``: the exit codes of processes
that ended in its last few reports, where the agent reads them, as ``4242=0 4250=-9``) and whose
other statuses are one per process
(``name`` =
``process <pid>``, level OK when alive, ERROR once it ended, ``message`` = the process name,
key-values ``ppid``, ``participants`` (its GUID prefixes), ``metrics`` (its θ as
``cpu_percent=12.5 rss_mb=40 …``: one string, not one key-value each, keeps the report small and
cheap to build), and its identity,
``create_time``, ``cmdline``, ``username``, only when the agent did not send them in its last
report or every tenth report: a receiver keeps them from the report before; ``oom_kill`` on an
ended process the OOM killer ended, as ``<limit bytes, 0: none> <memory cgroup>``). ROS tools
display it as any diagnostics.
`encode` and `decode` work on `StatusRow` tuples so this module needs no ROS.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import NamedTuple

from stream_viz.collect.oomkills import OomKill
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
    kept while DDS still lists their nodes; ``ooms`` those of the ended ones the OOM killer ended.
    """

    host: str
    host_id: int
    seq: int = 0
    period_s: float = 1.0
    participants: dict[str, int] = field(default_factory=dict)
    processes: dict[int, ProcessReading] = field(default_factory=dict)
    machine: dict[str, float] = field(default_factory=dict)  # the host's own θ (`MachineSampler`)
    ooms: dict[int, OomKill] = field(default_factory=dict)
    exits: dict[int, int] = field(default_factory=dict)  # pid → exit code (`exitcodes.exit_code`)


def encode(report: HostReport, known: set[int] | frozenset[int] = frozenset()) -> list[StatusRow]:
    """Return the status rows of ``report`` (the host first, then its processes by pid); the
    identity of the processes in ``known`` is left out."""
    head = [("schema", SCHEMA), ("host_id", str(report.host_id)), ("seq", str(report.seq)),
            ("period_s", f"{report.period_s:g}")]
    if report.machine:
        head.append(("machine", _metrics_text(report.machine)))
    if report.exits:
        head.append(("exits", " ".join(f"{pid}={code}" for pid, code in sorted(report.exits.items()))))
    rows = [StatusRow(OK, HOST_STATUS, f"{len(report.processes)} processes", report.host, head)]
    by_pid: dict[int, list[str]] = {}
    for prefix, pid in sorted(report.participants.items()):
        by_pid.setdefault(pid, []).append(prefix)
    for pid, p in sorted(report.processes.items()):
        kv = [("ppid", str(p.ppid or 0))]
        if pid in by_pid:
            kv.append(("participants", ",".join(by_pid[pid])))
        if pid not in known:
            if p.create_time is not None:
                kv.append(("create_time", f"{p.create_time:.2f}"))
            if p.cmdline:
                kv.append(("cmdline", p.cmdline[:CMDLINE_MAX]))
            if p.username:
                kv.append(("username", p.username))
        if p.unreadable:
            kv.append(("unreadable", ",".join(p.unreadable)))
        metrics = _metrics_text(p.metrics)
        if metrics:
            kv.append(("metrics", metrics))
        if (oom := report.ooms.get(pid)) is not None:
            kv.append(("oom_kill", f"{oom.limit or 0} {oom.group}"))
        rows.append(StatusRow(OK if p.alive else ERROR, f"process {pid}", p.name, report.host, kv))
    return rows


def decode(rows: list[StatusRow], before: HostReport | None = None) -> HostReport | None:
    """Return the report the rows carry, None when they are not an agent's (no host status first);
    a process's identity left out is taken from ``before`` (the same agent's previous report)."""
    if not rows or rows[0].name != HOST_STATUS:
        return None
    head = dict(rows[0].values)
    if head.get("schema") != SCHEMA:
        return None
    report = HostReport(rows[0].hardware_id, int(head["host_id"]), int(head.get("seq", 0)),
                        float(head.get("period_s", 1.0)))
    report.machine = _metrics(head.get("machine", ""), {*SCHEMAS["host"], "cpus", "mem_limit_mb"})
    report.exits = _exits(head.get("exits", ""))
    names = set(SCHEMAS["process"])
    for row in rows[1:]:
        kv = dict(row.values)
        pid = int(row.name.rpartition(" ")[2])
        old = before.processes.get(pid) if before is not None and before.host == report.host else None
        if "create_time" not in kv and old is not None and old.name == row.message:
            ct, cmdline, user = old.create_time, old.cmdline, old.username
        else:
            ct = float(kv["create_time"]) if "create_time" in kv else None
            cmdline, user = kv.get("cmdline", ""), kv.get("username")
        p = ProcessReading(pid, int(kv.get("ppid", 0)) or None, row.message, cmdline, ct, user,
                           _metrics(kv.get("metrics", ""), names),
                           alive=row.level != ERROR,
                           unreadable=[u for u in kv.get("unreadable", "").split(",") if u])
        report.processes[pid] = p
        if (oom := _oom_kill(kv.get("oom_kill", ""))) is not None:
            report.ooms[pid] = oom
        for prefix in kv.get("participants", "").split(","):
            if prefix:
                report.participants[prefix] = pid
    return report


def _oom_kill(text: str) -> OomKill | None:
    limit, _, group = text.partition(" ")
    return OomKill(group, int(limit) or None) if limit.isdigit() and group else None


def _exits(text: str) -> dict[int, int]:
    """``4242=0 4250=-9`` → {4242: 0, 4250: -9} (a malformed item left out)."""
    out = {}
    for item in text.split():
        pid, _, code = item.partition("=")
        if pid.isdigit() and code.lstrip("-").isdigit():
            out[int(pid)] = int(code)
    return out


def _metrics_text(values: dict[str, float]) -> str:
    """Named values as one ``name=value …`` string (unknown ones left out)."""
    return " ".join(f"{k}={v:.4g}" for k, v in sorted(values.items()) if math.isfinite(v))


def _metrics(text: str, names: set[str]) -> dict[str, float]:
    """``cpu_percent=12.5 rss_mb=40`` → their values (names outside the θ schema left out)."""
    out = {}
    for item in text.split():
        k, _, v = item.partition("=")
        if k in names:
            out[k] = float(v)
    return out


def host_of_prefix(prefix: str) -> int:
    """Return the Fast DDS host id of a GUID prefix given as hex (bytes 2–3, as `decode_gid`)."""
    return int(prefix[4:8], 16)
