"""A process's CPU quota from its cgroup: a container's ``docker --cpus``, a Kubernetes limit,
a systemd ``CPUQuota``, read from cgroup v2 (``cpu.max``, ``cpu.stat``) or v1
(``cpu.cfs_quota_us``, ``cpu.stat``, ``cpuacct.usage``); and its memory group, whose count of
processes the OOM killer ended tells a kill for memory from any other (`memory_group_of`).

A robot held to 1.5 CPUs is saturated when its group uses 1.5, however idle the machine's
cores: its tasks then wait for the next quota period (throttled), which the machine's own
pressure (PSI) does not count. Parsing is pure (`parse_proc_cgroup`, `parse_mountinfo`,
`parse_stat`); `quota_of` and `QuotaReading` read the files.
"""

from __future__ import annotations

import os
from collections.abc import Iterator
from dataclasses import dataclass
from typing import NamedTuple


class Mount(NamedTuple):
    """A cgroup hierarchy's mount: where it is (``point``), which cgroup it shows (``root``), and
    its controllers (``cpu``, ``cpuacct``; ``{""}`` for the unified v2 hierarchy)."""

    point: str
    root: str
    controllers: frozenset[str]


@dataclass(frozen=True)
class Quota:
    """The tightest CPU quota over a process: the cgroup that holds it (``path``), its share in
    CPUs (quota / period), and the files of that group's CPU time (``usage``, in ``usage_s``
    seconds a unit; empty: unreadable) and enforcement periods (``stat``)."""

    path: str
    cpus: float
    usage: str
    usage_s: float
    stat: str


def parse_proc_cgroup(text: str) -> dict[str, str]:
    """Return controller -> cgroup path of a ``/proc/<pid>/cgroup`` text; the unified (v2)
    hierarchy's path under ``""``."""
    out: dict[str, str] = {}
    for line in text.splitlines():
        parts = line.split(":", 2)
        if len(parts) == 3:
            for c in parts[1].split(",") if parts[1] else [""]:
                out[c] = parts[2]
    return out


def parse_mountinfo(text: str) -> list[Mount]:
    """Return the cgroup mounts of a ``/proc/self/mountinfo`` text."""
    out = []
    for line in text.splitlines():
        head, sep, tail = line.partition(" - ")
        fields, rest = head.split(), tail.split()
        if not sep or len(fields) < 5 or len(rest) < 3:
            continue
        if rest[0] == "cgroup2":
            out.append(Mount(fields[4], fields[3], frozenset({""})))
        elif rest[0] == "cgroup":
            names = {o for o in rest[2].split(",") if o in ("cpu", "cpuacct", "memory")}
            if names:
                out.append(Mount(fields[4], fields[3], frozenset(names)))
    return out


def read_mounts(path: str = "/proc/self/mountinfo") -> list[Mount]:
    """Return this machine's cgroup mounts; none where there is no mountinfo (not Linux)."""
    try:
        with open(path) as f:
            return parse_mountinfo(f.read())
    except OSError:
        return []


def parse_stat(text: str) -> dict[str, int]:
    """Return the ``key value`` lines of a cgroup ``cpu.stat`` text."""
    out = {}
    for line in text.splitlines():
        key, _, value = line.partition(" ")
        if value.strip().isdigit():
            out[key] = int(value)
    return out


def cgroup_dir(mounts: list[Mount], controller: str, groups: dict[str, str]) -> tuple[str, str] | None:
    """Return (directory, mount point) of the cgroup ``groups`` gives for ``controller`` (``""``:
    v2), or None when no mount shows it (a path outside the mount's root)."""
    path = groups.get(controller)
    if path is None:
        return None
    for m in mounts:
        if controller in m.controllers:
            root = m.root.rstrip("/")
            if path == m.root or path.startswith(root + "/"):
                return os.path.join(m.point, path[len(root):].lstrip("/")).rstrip("/"), m.point
    return None


def _groups_of(pid: int, proc: str) -> dict[str, str] | None:
    """`parse_proc_cgroup` of process ``pid``; None when it is gone or unreadable."""
    try:
        with open(f"{proc}/{pid}/cgroup") as f:
            return parse_proc_cgroup(f.read())
    except OSError:
        return None


def _upwards(d: str, top: str) -> Iterator[str]:
    """``d`` and its ancestors up to the mount point ``top``: where a limit over ``d`` may be set."""
    while True:
        yield d
        if d == top or len(d) <= len(top):
            return
        d = os.path.dirname(d)


def quota_of(pid: int, mounts: list[Mount], proc: str = "/proc") -> Quota | None:
    """Return the tightest CPU quota over process ``pid`` (on its cgroup or an ancestor), or None
    when it has none (or its cgroup cannot be read)."""
    groups = _groups_of(pid, proc)
    if groups is None:
        return None
    v2 = cgroup_dir(mounts, "", groups) if any("" in m.controllers for m in mounts) else None
    where = cgroup_dir(mounts, "cpu", groups) or v2
    if where is None:
        return None
    top = where[1]
    best: tuple[float, str] | None = None
    for d in _upwards(*where):
        cpus = _cpus_of(d)
        if cpus is not None and (best is None or cpus < best[0]):
            best = (cpus, d)
    if best is None:
        return None
    cpus, d = best
    if os.path.exists(os.path.join(d, "cpu.max")):  # v2: usage in its own cpu.stat
        return Quota(d, cpus, os.path.join(d, "cpu.stat"), 1e-6, os.path.join(d, "cpu.stat"))
    usage = ""
    acct = cgroup_dir(mounts, "cpuacct", groups)
    if acct is not None:  # v1: the same group in the cpuacct hierarchy (often the same mount)
        rel = os.path.relpath(d, top)
        candidate = os.path.normpath(os.path.join(acct[1], rel, "cpuacct.usage"))
        usage = candidate if os.path.exists(candidate) else ""
    return Quota(d, cpus, usage, 1e-9, os.path.join(d, "cpu.stat"))


def _cpus_of(d: str) -> float | None:
    """The quota of cgroup directory ``d`` in CPUs, or None (none set, or unreadable)."""
    try:
        with open(os.path.join(d, "cpu.max")) as f:
            quota, _, period = f.read().strip().partition(" ")
    except OSError:
        try:
            with open(os.path.join(d, "cpu.cfs_quota_us")) as f:
                quota = f.read().strip()
            with open(os.path.join(d, "cpu.cfs_period_us")) as f:
                period = f.read().strip()
        except OSError:
            return None
    try:
        q, p = int(quota), int(period)
    except ValueError:  # "max": none
        return None
    return q / p if q > 0 and p > 0 else None


class QuotaReading(NamedTuple):
    """A quota group's counters at one time: CPU seconds used (NaN: unreadable), enforcement
    periods and throttled periods."""

    t: float
    used_s: float
    periods: int
    throttled: int


def read_quota(q: Quota, t: float) -> QuotaReading | None:
    """Read ``q``'s counters at monotonic time ``t``; None when its group is gone."""
    try:
        with open(q.stat) as f:
            stat = parse_stat(f.read())
        if q.usage == q.stat:
            used = stat.get("usage_usec", -1) * q.usage_s
        elif q.usage:
            with open(q.usage) as f:
                used = int(f.read().strip()) * q.usage_s
        else:
            used = float("nan")
    except (OSError, ValueError):
        return None
    return QuotaReading(t, used if used >= 0 else float("nan"), stat.get("nr_periods", 0),
                        stat.get("nr_throttled", 0))


def quota_use(q: Quota, before: QuotaReading, after: QuotaReading) -> tuple[float, float]:
    """Return (% of the quota used, % of its enforcement periods throttled) between two readings;
    NaN where unknown."""
    dt = after.t - before.t
    used = (after.used_s - before.used_s) / (dt * q.cpus) * 100.0 if dt > 0 else float("nan")
    periods = after.periods - before.periods
    throttled = (after.throttled - before.throttled) / periods * 100.0 if periods > 0 else float("nan")
    return (min(100.0, used) if used == used else used), throttled


NO_LIMIT = 2**60  # v1 writes "no limit" as a page-rounded 2^63 - 1


@dataclass(frozen=True)
class MemoryGroup:
    """A process's memory cgroup: its directory, the file counting the processes in it that the
    OOM killer ended (``events``: v2 ``memory.events``, v1 ``memory.oom_control``; their
    ``oom_kill`` line), the tightest memory limit over it in bytes (None: none) and the directory
    that sets it (``limited``: its use is what the limit binds)."""

    path: str
    events: str
    limit: int | None
    limited: str | None = None


def parse_oom_kills(text: str) -> int | None:
    """Return the ``oom_kill`` count of a ``memory.events`` or ``memory.oom_control`` text (None:
    a kernel that does not count them, before 4.13)."""
    return parse_stat(text).get("oom_kill")


def memory_group_of(pid: int, mounts: list[Mount], proc: str = "/proc") -> MemoryGroup | None:
    """Return process ``pid``'s memory cgroup (v1's memory hierarchy, else v2's), or None when no
    mount shows it or it has no OOM count."""
    groups = _groups_of(pid, proc)
    if groups is None:
        return None
    where = cgroup_dir(mounts, "memory", groups)
    if where is None and any("" in m.controllers for m in mounts):
        where = cgroup_dir(mounts, "", groups)
    if where is None:
        return None
    d = where[0]
    events = next((os.path.join(d, n) for n in ("memory.events", "memory.oom_control")
                   if os.path.exists(os.path.join(d, n))), None)
    if events is None:
        return None
    limits = [(x, at) for at in _upwards(*where) if (x := _memory_limit(at)) is not None]
    limit, limited = min(limits, default=(None, None))  # the tightest binds
    return MemoryGroup(d, events, limit, limited)


def _memory_limit(d: str) -> int | None:
    """The memory limit set on cgroup directory ``d`` in bytes, or None (none, or unreadable)."""
    for name in ("memory.max", "memory.limit_in_bytes"):
        try:
            with open(os.path.join(d, name)) as f:
                value = f.read().strip()
        except OSError:
            continue
        return int(value) if value.isdigit() and int(value) < NO_LIMIT else None
    return None


def parse_memory_use(usage: str, stat: str) -> int | None:
    """Return the bytes a memory cgroup uses that it cannot give back, from its ``memory.current``
    (v2) or ``memory.usage_in_bytes`` (v1) text and its ``memory.stat`` text: the usage less the
    inactive file cache, as ``docker stats`` counts it (a group that writes files fills its
    limit with cache the kernel reclaims before any OOM kill)."""
    if not usage.strip().isdigit():
        return None
    s = parse_stat(stat)
    cache = s.get("total_inactive_file", s.get("inactive_file", 0))  # v1: the hierarchy's, as its usage
    return max(0, int(usage) - cache)


def read_memory_use(d: str) -> int | None:
    """The bytes memory cgroup directory ``d`` uses (`parse_memory_use`); None: unreadable."""
    try:
        for name in ("memory.current", "memory.usage_in_bytes"):
            if os.path.exists(usage := os.path.join(d, name)):
                with open(usage) as f, open(os.path.join(d, "memory.stat")) as st:
                    return parse_memory_use(f.read(), st.read())
    except OSError:
        return None
    return None


def read_oom_kills(g: MemoryGroup) -> int | None:
    """The count of processes in ``g`` the OOM killer ended; None when unreadable or gone."""
    try:
        with open(g.events) as f:
            return parse_oom_kills(f.read())
    except OSError:
        return None
