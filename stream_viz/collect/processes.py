"""Process sampler: metrics of the nodes' processes and all their ancestors, exits noticed fast.

psutil finds a process and its identity (name, command line, user, start time). The metrics of
a tracked process are read every sample: on Linux straight from ``/proc/<pid>/{stat,status,io,fd}``
(psutil's own sources, with the same formulas, at a fraction of its CPU: bench/bench_collect_parts.py,
figures in docs/collector.md), elsewhere through psutil. On Linux, every ``probe_every`` samples
(and at a process's first two), its threads that ran in between are counted, the middleware's own
aside (`MIDDLEWARE_THREADS`): ``running_threads``; every sample for its first few, as its
start-up ends. When one runs, it is a single-threaded
executor's (wherever ``rclpy.spin`` is called), and its CPU is read every sample from its
``schedstat`` (ns): ``executor_cpu_percent``. A blocked callback stops it: it then uses none.
A process we may not fully read keeps what could be read (the rest NaN, listed in
``unreadable``); one that exits mid-read is reported as gone, never raised.
"""

from __future__ import annotations

import math
import os
import time
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import psutil

from stream_viz.collect.cgroups import (
    MemoryGroup,
    Quota,
    QuotaReading,
    memory_group_of,
    quota_of,
    quota_use,
    read_memory_use,
    read_mounts,
    read_quota,
)
from stream_viz.collect.readings import ProcessReading

MB = 1024.0 * 1024.0
PROCFS = os.path.exists("/proc/self/stat") and hasattr(os, "sysconf")
CLK_TCK = os.sysconf("SC_CLK_TCK") if PROCFS else 100
PAGE = os.sysconf("SC_PAGE_SIZE") if PROCFS else 4096
CHUNK = 16384  # a read takes a whole /proc/<pid>/status (about 1.5 kB) at once


class ProcStat(NamedTuple):
    """The fields of ``/proc/<pid>/stat`` the sampler uses."""

    state: str
    ppid: int
    cpu_s: float  # user + system time of the process itself, s
    threads: int
    start: int  # start time after boot in clock ticks: with the pid, the process's identity
    rss_bytes: int


class Counters(NamedTuple):
    """A process's raw counters, read from /proc or through psutil; metrics are derived from two."""

    ppid: int | None
    cpu_s: float  # user + system time, s
    rss_bytes: int
    threads: int
    ctx: int  # voluntary + involuntary context switches
    fds: int | None  # None: we may not read them
    io: tuple[int, int] | None  # (read_bytes, write_bytes); None: we may not read them


# Thread names of the DDS implementations' own threads (Fast DDS ``dds.*``; Cyclone DDS receive,
# timed-event, delivery, transmit and lease threads): they run whether the executor does or not.
MIDDLEWARE_THREADS = ("dds.", "recv", "tev", "dq.", "xmit", "lease", "gc")
RAN_SHARE = 1e-3  # a thread that ran less than this share of a core between two probes is idle
# ... or less than this share of the busiest thread's CPU: a main thread that woke once while the
# executor worked (or as it blocked) is not a second executor thread. An rclpy multi-threaded
# executor's workers each use many times less CPU than its dispatching main thread (docs/collector.md).
RAN_OF_BUSIEST = 0.01
# A main thread that used this many times the CPU of each other thread that ran, with at least two
# of them running, dispatches a multi-threaded executor: rclpy's spin loop in the main thread hands
# callbacks to a pool of workers (11-17x at a light load, docs/collector.md).
DISPATCH_RATIO = 5.0
# Seen dispatching at this many probes, a process's main thread still does while it stays its
# busiest thread: an executor's kind is fixed for its life, and a starved probe shows only one
# worker that ran, or the main thread fewer times busier than the workers.
DISPATCH_SEEN = 2
RISE_PROBE = 25.0  # a process's CPU up this many points since the last sample: probe it now and next
FIRST_PROBES = 4
PROBE_MIN_S = 0.5  # probes closer than this say nothing (the sampler is called between samples too)


def parse_stat(text: bytes) -> ProcStat:
    """Parse ``/proc/<pid>/stat`` (proc(5)); the name in parentheses may hold spaces and ``)``."""
    rest = text[text.rindex(b")") + 2:].split()
    return ProcStat(state=rest[0].decode(), ppid=int(rest[1]),
                    cpu_s=(int(rest[11]) + int(rest[12])) / CLK_TCK, threads=int(rest[17]),
                    start=int(rest[19]), rss_bytes=int(rest[21]) * PAGE)


def parse_fields(text: bytes, names: tuple[bytes, ...]) -> tuple[int, ...]:
    """Return the integer values of ``name: value`` lines (``/proc/<pid>/status`` or ``io``)."""
    text = b"\n" + text  # every field, the first too, starts after a newline
    out = []
    for name in names:
        key = b"\n" + name + b":"
        i = text.find(key)
        if i < 0:
            raise KeyError(name.decode())
        end = text.find(b"\n", i + len(key))
        out.append(int(text[i + len(key):end if end >= 0 else None]))
    return tuple(out)


CTX_FIELDS = (b"voluntary_ctxt_switches", b"nonvoluntary_ctxt_switches")
IO_FIELDS = (b"read_bytes", b"write_bytes")


def read_file(path: str) -> bytes:
    """Return the content of ``path`` (a /proc file) in one read: through ``os`` rather than a
    Python file object, whose reads cost 1.5 × as much (bench/bench_collect_parts.py, part 3)."""
    fd = os.open(path, os.O_RDONLY | os.O_CLOEXEC)
    try:
        parts = [os.read(fd, CHUNK)]
        while len(parts[-1]) == CHUNK:  # longer than a chunk: a seq file returns what fits each time
            parts.append(os.read(fd, CHUNK))
        return b"".join(parts)
    finally:
        os.close(fd)


def count_fds(pid: int) -> int:
    """Open file descriptors of ``pid``: Linux >= 6.2 gives the count as the size of its fd
    directory (no listing; a ROS process holds ~100), older kernels say 0 and we list it."""
    path = f"/proc/{pid}/fd"
    return os.stat(path).st_size or len(os.listdir(path))


@dataclass
class _Tracked:
    proc: psutil.Process
    info: ProcessReading
    t: float = 0.0
    ctx: int | None = None
    io: tuple[int, int] | None = None
    start: int | None = None  # /proc start ticks (PROCFS only)
    cpu_s: float | None = None  # process CPU time at `t`
    thread_ns: dict[int, int] | None = None  # its threads' CPU time (ns) at the last probe
    probe_t: float = -1e9  # when (monotonic)
    running: float = float("nan")  # threads that ran between the last two probes
    probes: int = 0
    worker: tuple[int, float, float] | None = None  # the one that ran: (tid, when, its CPU time s)
    main: tuple[float, float] | None = None  # its main thread: (when, its CPU time s)
    dispatching: float = float("nan")  # 1.0: its main thread dispatched at the last probe; 0.0: not
    dispatched: int = 0  # probes that saw it dispatch
    rise_probes: int = 0  # probes still due for a CPU rise
    last_cpu: float = float("nan")


@dataclass
class ProcSample:
    """What one `ProcessSampler.sample` found."""

    processes: dict[int, ProcessReading] = field(default_factory=dict)
    exited: dict[int, ProcessReading] = field(default_factory=dict)  # tracked last time, gone now
    errors: dict[int, str] = field(default_factory=dict)  # pid -> why it could not be read at all


class MachineSampler:
    """The whole computer: CPU in use (% of the cores the robot may use), memory in use (%) and
    CPU pressure (% of the time some task was ready to run and waited for a CPU), a host's θ.

    What a process's own metrics cannot say: a computer saturated by something outside the robot
    (or by all its processes together) slows every node on it. Pressure tells a computer that is
    merely full (every core busy, nobody waiting) from one that starves its tasks; it is Linux's
    PSI (``/proc/pressure/cpu``), unknown (NaN) where the kernel has none. The cores counted are
    those the robot's processes may run on (their affinity: a container's cpuset, a ``taskset``):
    a robot held to 2 of 8 cores is saturated when those 2 are full, with the machine at 25 %.
    A CPU quota over all of them (one cgroup's: a container's ``--cpus``, `cgroups`) binds the
    same way: when its group uses more of its quota than the cores are used, the CPU is that
    share (``cpus`` the quota), and its throttled periods count as tasks waiting. So does a memory
    limit over all of them (a container's ``--memory``): when its group uses more of its limit
    than the machine's memory is used, the memory in use is that share (``mem_limit_mb`` the
    limit; the group's inactive file cache not counted, `cgroups.parse_memory_use`).
    """

    def __init__(self, pressure: str = "/proc/pressure/cpu") -> None:
        psutil.cpu_percent(None, percpu=True)  # the first call only starts the interval
        self._pressure = pressure
        self._stalled = (time.monotonic(), _read_pressure(pressure))
        self._affinity: dict[int, frozenset[int]] = {}
        self._quotas: dict[int, Quota | None] = {}
        self._counted: tuple[Quota, QuotaReading] | None = None
        self._memory: dict[int, MemoryGroup | None] = {}
        self._mounts = read_mounts()

    def sample(self, pids: Iterable[int] = ()) -> dict[str, float]:
        """CPU and pressure since the last call and memory now, under the host θ names, and the
        number of CPUs counted (``cpus``, an attribute of the host): those the processes ``pids``
        may run on, every CPU when none is known."""
        now, stalled = time.monotonic(), _read_pressure(self._pressure)
        (then, before), self._stalled = self._stalled, (now, stalled)
        per_cpu = psutil.cpu_percent(None, percpu=True)
        pids = set(pids)
        mine = cores_of(len(per_cpu), self._cpus(pids))
        out = {"machine_cpu_percent": sum(per_cpu[c] for c in mine) / len(mine) if mine else math.nan,
               "machine_mem_percent": psutil.virtual_memory().percent,
               "cpu_pressure_percent": pressure_percent(before, stalled, now - then),
               "cpus": float(len(mine) or 1)}
        used, throttled, cpus = self._quota_use(pids, now)
        if used == used and not used < out["machine_cpu_percent"]:  # the quota binds first
            out["machine_cpu_percent"], out["cpus"] = used, cpus
        if throttled == throttled and not throttled <= out["cpu_pressure_percent"]:
            out["cpu_pressure_percent"] = throttled
        held, limit = self._memory_use(pids)
        if held == held and not held <= out["machine_mem_percent"]:  # the limit binds first
            out["machine_mem_percent"], out["mem_limit_mb"] = held, limit / MB
        return out

    def _memory_use(self, pids: set[int]) -> tuple[float, float]:
        """(% of the limit in use, the limit in bytes) of the memory limit that holds every process
        of ``pids``; NaNs otherwise."""
        self._memory = {p: g for p, g in self._memory.items() if p in pids}
        for pid in pids - self._memory.keys():  # read once, as the quota
            self._memory[pid] = memory_group_of(pid, self._mounts)
        limits = {(g.limited, g.limit) if g is not None else None for g in self._memory.values()}
        if len(limits) != 1 or None in limits:
            return math.nan, math.nan
        (limited, limit), = limits
        used = read_memory_use(limited) if limited and limit else None
        return (math.nan, math.nan) if used is None else (used / limit * 100.0, float(limit))

    def _quota_use(self, pids: set[int], now: float) -> tuple[float, float, float]:
        """(% of the quota used, % of its periods throttled, its CPUs) since the last call, when
        one quota group holds every process of ``pids``; NaNs otherwise."""
        self._quotas = {p: q for p, q in self._quotas.items() if p in pids}
        for pid in pids - self._quotas.keys():  # a process's cgroup seldom changes: read once
            self._quotas[pid] = quota_of(pid, self._mounts)
        groups = set(self._quotas.values())
        q = groups.pop() if len(groups) == 1 else None
        reading = read_quota(q, now) if q is not None else None
        before, self._counted = self._counted, (q, reading) if reading is not None else None
        if q is None or reading is None or before is None or before[0] != q:
            return math.nan, math.nan, math.nan
        return (*quota_use(q, before[1], reading), q.cpus)

    def _cpus(self, pids: Iterable[int]) -> frozenset[int]:
        # An affinity seldom changes: read once per process (a syscall each), forgotten with it.
        seen = set(pids)
        self._affinity = {p: c for p, c in self._affinity.items() if p in seen}
        for pid in seen - self._affinity.keys():
            try:
                self._affinity[pid] = frozenset(os.sched_getaffinity(pid))
            except (OSError, AttributeError):  # gone, not ours to read, or not Linux
                continue
        return frozenset().union(*self._affinity.values())


def cores_of(listed: int, cpus: Iterable[int]) -> list[int]:
    """Return the CPUs numbered ``cpus`` among the ``listed`` ones psutil reports, sorted; every
    listed CPU when ``cpus`` names none of them."""
    return sorted(c for c in set(cpus) if 0 <= c < listed) or list(range(listed))


def _read_pressure(path: str) -> int | None:
    try:
        with open(path) as f:
            return parse_pressure(f.read())
    except OSError:
        return None


def parse_pressure(text: str) -> int | None:
    """Return the ``some`` line's ``total`` (µs any task waited for a CPU) of a PSI file's ``text``."""
    for line in text.splitlines():
        kind, _, fields = line.partition(" ")
        if kind == "some":
            for f in fields.split():
                if f.startswith("total="):
                    return int(f[6:])
    return None


def pressure_percent(before: int | None, after: int | None, seconds: float) -> float:
    """Return the share of ``seconds`` (%) that some task waited, from two PSI totals (µs)."""
    if before is None or after is None or seconds <= 0 or after < before:
        return float("nan")
    return min(100.0, (after - before) / 1e4 / seconds)


class ProcessSampler:
    """Samples the given pids and their ancestors up to the top of the process tree.

    Ancestors that host no given pid (the launch tree above the nodes: a launcher, a shell,
    init) are read on every ``ancestors_every``-th call, their rates over the whole interval;
    in between they stay in the tree with no metrics (unknown, not a repeated value that would
    flatten their baselines). They are half the processes of a typical robot and seldom the fault.
    """

    def __init__(self, ancestors_every: int = 5, procfs: bool = PROCFS, probe_every: int = 30) -> None:
        self._tracked: dict[int, _Tracked] = {}
        self.ancestors_every, self.procfs, self.probe_every = ancestors_every, procfs, probe_every
        self._calls = 0

    def sample(self, pids: Iterable[int]) -> ProcSample:
        """Read ``pids`` and every ancestor; report tracked processes that have gone since last time."""
        out = ProcSample()
        given = {p for p in pids if p is not None}
        self._calls += 1
        reread = self.ancestors_every <= 1 or self._calls % self.ancestors_every == 1
        todo = list(given)
        while todo:
            pid = todo.pop()
            if pid in out.processes or pid in out.errors or pid <= 0:
                continue
            tr = self._tracked.get(pid)
            if tr is not None and not reread and pid not in given:
                r: ProcessReading | None = replace(tr.info, metrics={})
                out.processes[pid] = r
            else:
                r = self._read(pid, out)
            if r is not None and r.ppid:
                todo.append(r.ppid)
        for pid in list(self._tracked):
            if pid in out.processes:
                continue
            tr = self._tracked.pop(pid)
            if not _running(tr.proc):
                tr.info.alive = False
                out.exited[pid] = tr.info
        return out

    def _read(self, pid: int, out: ProcSample) -> ProcessReading | None:
        tr = self._tracked.get(pid)
        if self.procfs:
            return self._read_procfs(pid, tr, out)
        try:
            proc = psutil.Process(pid) if tr is None else tr.proc
            with proc.oneshot():  # the status file `_running` reads serves `_measure` too
                if not _running(proc):  # gone (or a zombie, or its pid reused)
                    if tr is None:
                        out.errors[pid] = "process is not running"
                    else:
                        self._gone(pid, out, "process exited")
                    return None
                tr = tr or self._track(proc)
                r = self._measure(tr, _psutil_counters(proc))
        except psutil.NoSuchProcess:
            self._gone(pid, out, "process exited while being read")
            return None
        except psutil.AccessDenied:
            out.errors[pid] = "access denied"
            return None
        out.processes[pid] = r
        return r

    def _read_procfs(self, pid: int, tr: _Tracked | None, out: ProcSample) -> ProcessReading | None:
        try:
            st = parse_stat(read_file(f"/proc/{pid}/stat"))
            if st.state == "Z" or (tr is not None and st.start != tr.start):  # a zombie, a reused pid
                raise ProcessLookupError
            if tr is None:
                tr = self._track(psutil.Process(pid))
                tr.start = st.start
            r = self._measure(tr, _procfs_counters(pid, st))
            # Its first probes every sample: its start-up (the interpreter, imports) ends soon. A CPU
            # rise is probed as it starts and a sample on, a span of the rise only: which thread rose.
            cpu = r.metrics.get("cpu_percent", math.nan)
            if cpu - tr.last_cpu >= RISE_PROBE:
                tr.rise_probes = 2
            tr.last_cpu = cpu
            due = tr.probes < FIRST_PROBES or self._calls % self.probe_every == 0
            if (due or tr.rise_probes > 0) and time.monotonic() - tr.probe_t >= PROBE_MIN_S:
                _probe_threads(pid, tr, executor=due)
                tr.rise_probes = max(0, tr.rise_probes - 1)
            if tr.running == tr.running:
                r.metrics["running_threads"] = tr.running
            if tr.dispatching == tr.dispatching:
                r.metrics["dispatching"] = tr.dispatching
            if tr.worker is not None:
                _measure_worker(pid, tr, r.metrics)
            _measure_main(pid, tr, r.metrics)
        except (FileNotFoundError, ProcessLookupError, psutil.NoSuchProcess):
            if tr is None:
                out.errors[pid] = "process is not running"
            else:
                self._gone(pid, out, "process exited")
            return None
        except (PermissionError, psutil.AccessDenied):
            out.errors[pid] = "access denied"
            return None
        out.processes[pid] = r
        return r

    def _gone(self, pid: int, out: ProcSample, why: str) -> None:
        out.errors[pid] = why
        tr = self._tracked.pop(pid, None)
        if tr is not None:
            tr.info.alive = False
            out.exited[pid] = tr.info

    def _track(self, p: psutil.Process) -> _Tracked:
        pid = p.pid
        with p.oneshot():
            info = ProcessReading(pid=pid, ppid=p.ppid() or None, name=p.name(), create_time=p.create_time())
            try:
                info.cmdline = " ".join(p.cmdline())[:200]
            except psutil.AccessDenied:
                info.unreadable.append("cmdline")
            try:
                info.username = p.username()
            except (psutil.AccessDenied, KeyError):
                pass
        tr = _Tracked(p, info)
        self._tracked[pid] = tr
        return tr

    def _measure(self, tr: _Tracked, c: Counters) -> ProcessReading:
        """psutil's formulas (cpu_percent, per-second rates) over two readings of the counters."""
        now = time.monotonic()
        dt = now - tr.t
        m: dict[str, float] = {"rss_mb": c.rss_bytes / MB, "threads": float(c.threads)}
        denied = [f for f in tr.info.unreadable if f == "cmdline"]
        if tr.cpu_s is not None and dt > 0:  # the first reading only sets the reference point
            m["cpu_percent"] = 100.0 * (c.cpu_s - tr.cpu_s) / dt
            m["ctx_switches_per_s"] = (c.ctx - tr.ctx) / dt
        if c.fds is None:
            denied.append("open_files")
        else:
            m["open_files"] = float(c.fds)
        if c.io is None:
            denied.append("io")
        elif tr.io is not None and dt > 0:
            m["io_read_kBps"] = (c.io[0] - tr.io[0]) / dt / 1000.0
            m["io_write_kBps"] = (c.io[1] - tr.io[1]) / dt / 1000.0
        tr.cpu_s, tr.ctx, tr.io, tr.t = c.cpu_s, c.ctx, c.io or tr.io, now
        tr.info.ppid = c.ppid
        tr.info.metrics, tr.info.unreadable = m, denied
        return tr.info


def _procfs_counters(pid: int, st: ProcStat) -> Counters:
    """The counters from ``/proc/<pid>/{stat,status,io}`` and the size of ``fd/``."""
    ctx = sum(parse_fields(read_file(f"/proc/{pid}/status"), CTX_FIELDS))
    try:
        fds: int | None = count_fds(pid)
    except PermissionError:
        fds = None
    try:
        io: tuple[int, int] | None = parse_fields(read_file(f"/proc/{pid}/io"), IO_FIELDS)
    except (PermissionError, KeyError):
        io = None
    return Counters(st.ppid or None, st.cpu_s, st.rss_bytes, st.threads, ctx, fds, io)


def _probe_threads(pid: int, tr: _Tracked, executor: bool = True) -> None:
    """Count the threads of ``pid`` (the middleware's aside) that ran since the last probe; keep the
    one when one did, and what was known when none did; whether its main thread dispatches. A
    probe of a CPU rise (not ``executor``) says only that: a runaway thread running beside a
    single-threaded executor does not make it another (its CPU tells the rise beside it)."""
    now: dict[int, int] = {}
    for name in os.listdir(f"/proc/{pid}/task"):
        try:
            comm = read_file(f"/proc/{pid}/task/{name}/comm").decode(errors="replace")
            if comm.startswith(MIDDLEWARE_THREADS):
                continue
            now[int(name)] = _thread_ns(pid, int(name))
        except (OSError, ValueError, IndexError):
            continue  # a thread that ended, or no schedstat: not counted
    t = time.monotonic()
    ran = None if tr.thread_ns is None else threads_that_ran(tr.thread_ns, now, t - tr.probe_t)
    # Nothing ran: an idle or blocked executor is still the one it was (kept), and its CPU (none)
    # is what tells a blocked callback.
    if ran:
        seen = dispatches(tr.thread_ns or {}, now, t - tr.probe_t, pid)
        tr.dispatched += seen
        kept = tr.dispatched >= DISPATCH_SEEN and leads(tr.thread_ns or {}, now, pid)
        tr.dispatching = float(seen or kept)
    if executor and ran is not None and (ran or tr.running != tr.running):
        tr.running = float(len(ran))
        if len(ran) != 1:
            tr.worker = None
        elif tr.worker is None or tr.worker[0] != ran[0]:
            tr.worker = (ran[0], t, now[ran[0]] / 1e9)
    tr.thread_ns, tr.probe_t, tr.probes = now, t, tr.probes + 1


def threads_that_ran(before: dict[int, int], now: dict[int, int], span_s: float) -> list[int]:
    """The threads that worked between two probes.

    Parameters
    ----------
    before, now : dict
        Thread id -> its CPU time (ns) at each probe; a thread new since ``before`` started at 0.
    span_s : float
        Seconds between the probes.

    Returns
    -------
    list of int
        The threads (in ``now``'s order) that used at least ``RAN_SHARE`` of a core and at least
        ``RAN_OF_BUSIEST`` of the busiest thread's CPU time.
    """
    used = {tid: ns - before.get(tid, 0) for tid, ns in now.items()}
    least = max(RAN_SHARE * 1e9 * span_s, RAN_OF_BUSIEST * max(used.values(), default=0))
    return [tid for tid, ns in used.items() if ns >= least]


def dispatches(before: dict[int, int], now: dict[int, int], span_s: float, main: int) -> bool:
    """True when ``main`` dispatches a multi-threaded executor: it and at least two other threads
    used ``RAN_SHARE`` of a core between two probes, and it used at least ``DISPATCH_RATIO`` × the
    CPU of each of them. The workers' share of the busiest thread (`threads_that_ran`) is no test
    here: while the dispatcher spins they use 1 % of what it does, or less.

    Parameters
    ----------
    before, now : dict
        Thread id -> its CPU time (ns) at each probe, as `threads_that_ran` reads them.
    span_s : float
        Seconds between the probes.
    main : int
        The main thread's id (the process id).
    """
    least = RAN_SHARE * 1e9 * span_s
    used = _used(before, now)
    others = [ns for tid, ns in used.items() if tid != main and ns >= least]
    if used.get(main, 0) < least or len(others) < 2:
        return False
    return used[main] >= DISPATCH_RATIO * max(others)


def leads(before: dict[int, int], now: dict[int, int], main: int) -> bool:
    """True when ``main`` used more CPU between two probes than each other thread (as in
    `dispatches`): a dispatcher seen before still dispatches; a runaway thread beside it does not.
    """
    used = _used(before, now)
    return used.get(main, 0) > max((ns for tid, ns in used.items() if tid != main), default=0)


def _used(before: dict[int, int], now: dict[int, int]) -> dict[int, int]:
    """Each thread's CPU time (ns) between two probes; a thread new since ``before`` from 0."""
    return {tid: ns - before.get(tid, 0) for tid, ns in now.items()}


def _thread_ns(pid: int, tid: int) -> int:
    """CPU time (ns) of thread ``tid`` of ``pid``: the first field of its ``schedstat``."""
    return int(read_file(f"/proc/{pid}/task/{tid}/schedstat").split()[0])


def _measure_worker(pid: int, tr: _Tracked, m: dict[str, float]) -> None:
    """``executor_cpu_percent``: the CPU of the process's one running thread since the last sample."""
    tid, t0, s0 = tr.worker
    try:
        s1, t1 = _thread_ns(pid, tid) / 1e9, time.monotonic()
    except (OSError, ValueError, IndexError):
        tr.worker = None  # it ended
        return
    if t1 > t0 and s0 <= s1:
        m["executor_cpu_percent"] = 100.0 * (s1 - s0) / (t1 - t0)
    tr.worker = (tid, t1, s1)


def _measure_main(pid: int, tr: _Tracked, m: dict[str, float]) -> None:
    """``main_cpu_percent``: the CPU of the process's main thread since the last sample, when it is
    the one running thread (its ``executor_cpu_percent``) or more than one ran (read); not read
    while another thread is the one running, nor before a probe counted them."""
    if tr.worker is not None:
        if tr.worker[0] == pid and "executor_cpu_percent" in m:
            m["main_cpu_percent"] = m["executor_cpu_percent"]
        tr.main = None  # read afresh should more threads run
        return
    if not tr.running >= 2:
        tr.main = None
        return
    try:
        s1, t1 = _thread_ns(pid, pid) / 1e9, time.monotonic()
    except (OSError, ValueError, IndexError):
        return  # no schedstat (a kernel without it): unknown
    if tr.main is not None and t1 > tr.main[0] and tr.main[1] <= s1:
        m["main_cpu_percent"] = 100.0 * (s1 - tr.main[1]) / (t1 - tr.main[0])
    tr.main = (t1, s1)


def _psutil_counters(p: psutil.Process) -> Counters:
    """The same counters through psutil (call inside ``p.oneshot()``)."""
    try:
        fds: int | None = p.num_fds()
    except (psutil.AccessDenied, AttributeError):
        fds = None
    try:
        i = p.io_counters()
        io: tuple[int, int] | None = (i.read_bytes, i.write_bytes)
    except (psutil.AccessDenied, AttributeError):
        io = None
    t, c = p.cpu_times(), p.num_ctx_switches()
    return Counters(p.ppid() or None, t.user + t.system, p.memory_info().rss, p.num_threads(),
                    c.voluntary + c.involuntary, fds, io)


def _running(p: psutil.Process) -> bool:
    # is_running also compares the create time, so a reused pid counts as a new process.
    try:
        return p.is_running() and p.status() != psutil.STATUS_ZOMBIE
    except psutil.Error:
        return False
