"""Processes on this computer that take part in our ROS domain but were never discovered.

A node the observer does not discover is missing from the model without a trace: no alert can
name it. That happens on a LOCALHOST domain crowded enough that a late joiner finds only part of
it (docs/robustness.md, *Notes*), with a discovery range or discovery server the observer does
not share, or with a firewall. So every ``every_s`` the collector lists this computer's processes
that have Fast DDS loaded and our ``ROS_DOMAIN_ID`` in their environment, and names those of them
whose PID no discovered participant's GUID prefix carries (`collect.pidmap`: the prefix holds the
low 16 bits of the PID the process sees itself as).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass

import psutil

from stream_viz.collect.fastdds import decode_gid
from stream_viz.collect.pidmap import inner_pid

# The Fast DDS libraries themselves: loaded when rclpy.init() loads rmw_fastrtps, not on import.
PARTICIPANT_MARKERS = (b"libfastrtps", b"libfastdds")
RANGE_VARS = ("ROS_AUTOMATIC_DISCOVERY_RANGE", "ROS_LOCALHOST_ONLY", "ROS_STATIC_PEERS",
              "ROS_DISCOVERY_SERVER")


@dataclass(frozen=True)
class Participant:
    """A local process with Fast DDS loaded on our domain: our PID, its own, its name, its start,
    and the discovery settings of its environment (``RANGE_VARS`` that are set)."""

    pid: int
    inner: int
    name: str
    started: float
    discovery: tuple[tuple[str, str], ...] = ()


def discovered_low16(gids: Iterable[bytes], own_host: int | None) -> set[int]:
    """Return the PID bits of every participant of this computer among endpoint ``gids``.

    Parameters
    ----------
    gids : iterable of bytes
        Endpoint gids read from the graph (other vendors' are skipped).
    own_host : int or None
        This computer's Fast DDS host id; None keeps every Fast DDS gid.
    """
    out = set()
    for g in gids:
        info = decode_gid(g)
        if info is not None and (own_host is None or info.host_id == own_host):
            out.add(info.pid_low16)
    return out


def undiscovered(participants: Iterable[Participant], low16: set[int], now: float, grace_s: float,
                 since: Mapping[int, float] | None = None) -> list[Participant]:
    """Return the ``participants`` whose PID bits are not in ``low16`` and that have been in DDS
    for ``grace_s``: since ``since[pid]`` (its participant first seen), else since it started."""
    since = since or {}
    return sorted((p for p in participants if p.inner & 0xFFFF not in low16
                   and now - since.get(p.pid, p.started) >= grace_s), key=lambda p: p.pid)


def explain(p: Participant, domain_id: int, ours: Mapping[str, str], grace_s: float) -> str:
    """Say why ``p`` may be unseen and what to do, from its discovery settings and ``ours``."""
    text = (f"process {p.pid} ({p.name}) has Fast DDS loaded with ROS_DOMAIN_ID={domain_id}, but no "
            f"participant of it was discovered in {grace_s:.0f} s: its nodes are not in the model "
            "(said again if they are discovered later)")
    theirs = dict(p.discovery)
    differ = sorted(k for k in RANGE_VARS if theirs.get(k, "") != ours.get(k, ""))
    if differ:
        return text + "; its discovery settings differ from the monitor's: " + ", ".join(
            f"{k}={theirs.get(k, '(unset)')} (monitor: {ours.get(k, '(unset)')})" for k in differ)
    if theirs.get("ROS_AUTOMATIC_DISCOVERY_RANGE", "").upper() == "LOCALHOST":
        return text + ("; on a LOCALHOST domain a participant that joins after some 30 others may "
                       "not discover them all: start the monitor before the robot, or use SUBNET")
    return text


def explain_late(p: Participant, discovered_at: float) -> str:
    """Say that ``p``, named undiscovered before, was discovered at ``discovered_at``."""
    return (f"process {p.pid} ({p.name}) was discovered {discovered_at - p.started:.0f} s after it "
            "started: its nodes are in the model")


class UndiscoveredWatch:
    """Every ``every_s``, the local participants of ``domain_id`` that were never discovered.

    A process discovered once is not named again: its nodes leaving the graph while it runs (a
    stopped process's lease ending) is a symptom the model shows, not a blind spot. One named and
    discovered later (it loaded a model or waited for its hardware before creating its nodes) is
    in ``late`` with the time it was discovered: what was said of it no longer holds.

    A process's environment is read once while it lives; its memory maps until Fast DDS shows in
    them or it is older than ``grace_s`` (rclpy loads Fast DDS at ``init``, not on import). The
    grace counts from when its participant first showed (a UDP socket, `_in_dds`): rmw creates it
    with the first node, which a process may create long after ``init`` (loading a model).
    """

    def __init__(self, domain_id: int, every_s: float = 10.0, grace_s: float = 10.0) -> None:
        self.domain_id, self.every_s, self.grace_s = domain_id, every_s, grace_s
        self._own = os.getpid()
        self._known: dict[int, Participant | float | None] = {}  # None: not one; float: look again after
        self._due = 0.0
        self.found: list[Participant] = []
        self._ever: set[int] = set()  # pids discovered once: their leaving is the model's to show
        self.late: dict[int, tuple[Participant, float]] = {}  # named, then discovered: when
        self._in_dds_since: dict[int, float] = {}  # pid -> its participant first seen

    def update(self, read_gids: Callable[[], Iterable[bytes]], own_host: int | None,
               now: float | None = None) -> list[Participant]:
        """Return the local participants not discovered, looked for again when due (else the last).

        ``read_gids`` returns the gids of endpoints every participant has (called only when due).
        """
        now = time.time() if now is None else now
        if now < self._due:
            return self.found
        self._due = now + self.every_s
        live = set(psutil.pids()) - {self._own}
        known = self._known
        self._known = {p: self._read(p, now) if p not in known or _again(known[p], now) else known[p]
                       for p in live}
        found = [p for p in self._known.values() if isinstance(p, Participant)]
        try:
            low16 = discovered_low16(read_gids(), own_host) if found else set()
        except Exception:  # the graph unreadable now (rclpy shutting down): say nothing new
            return self.found
        self._ever = {p.pid for p in found if p.inner & 0xFFFF in low16} | (self._ever & live)
        self.late = {pid: v for pid, v in self.late.items() if pid in live}  # a pid may be reused
        self.late.update((p.pid, (p, now)) for p in self.found if p.pid in self._ever)
        unseen = [p for p in found if p.pid not in self._ever and p.inner & 0xFFFF not in low16]
        in_dds = {p.pid for p in unseen if _in_dds(p.pid)}
        self._in_dds_since = {pid: self._in_dds_since.get(pid, now) for pid in in_dds}
        self.found = undiscovered([p for p in unseen if p.pid in in_dds], low16, now, self.grace_s,
                                  self._in_dds_since)
        return self.found

    def _read(self, pid: int, now: float) -> Participant | float | None:
        try:
            with open(f"/proc/{pid}/environ", "rb") as f:
                env = dict(kv.split(b"=", 1) for kv in f.read().split(b"\0") if b"=" in kv)
            if int(env.get(b"ROS_DOMAIN_ID", b"0").strip() or 0) != self.domain_id:
                return None
            proc = psutil.Process(pid)
            started = proc.create_time()
            with open(f"/proc/{pid}/maps", "rb") as f:
                maps = f.read()
            if not any(m in maps for m in PARTICIPANT_MARKERS):
                return None if now - started >= self.grace_s else now + self.every_s
            discovery = tuple((k, env[k.encode()].decode(errors="replace")) for k in RANGE_VARS
                              if k.encode() in env)
            return Participant(pid, inner_pid(pid), proc.name(), started, discovery)
        except (OSError, ValueError, psutil.Error):  # gone, not ours to read, or a malformed value
            return None


def _in_dds(pid: int) -> bool:
    """True while ``pid`` runs with a UDP socket open: a participant always has one (discovery
    traffic), an exited process (a zombie) or one after ``rclpy.shutdown()`` has none."""
    try:
        proc = psutil.Process(pid)
        return proc.status() != psutil.STATUS_ZOMBIE and bool(proc.net_connections(kind="udp"))
    except (psutil.Error, OSError):
        return False


def _again(entry: Participant | float | None, now: float) -> bool:
    return isinstance(entry, float) and now >= entry
