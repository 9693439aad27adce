"""psutil sampler: metrics of the nodes' processes and all their ancestors, exits noticed fast.

``psutil.Process`` objects are cached (``cpu_percent`` and the per-second rates need the previous
reading). A process we may not fully read keeps what could be read (the rest NaN, listed in
``unreadable``); one that exits mid-read is reported as gone, never raised.
"""

from __future__ import annotations

import time
from collections.abc import Iterable
from dataclasses import dataclass, field, replace

import psutil

from stream_viz.collect.readings import ProcessReading

MB = 1024.0 * 1024.0


@dataclass
class _Tracked:
    proc: psutil.Process
    info: ProcessReading
    t: float = 0.0
    ctx: float | None = None
    io: tuple[float, float] | None = None
    cpu_primed: bool = False


@dataclass
class ProcSample:
    """What one `ProcessSampler.sample` found."""

    processes: dict[int, ProcessReading] = field(default_factory=dict)
    exited: dict[int, ProcessReading] = field(default_factory=dict)  # tracked last time, gone now
    errors: dict[int, str] = field(default_factory=dict)  # pid -> why it could not be read at all


class ProcessSampler:
    """Samples the given pids and their ancestors up to the top of the process tree.

    Ancestors that host no given pid (the launch tree above the nodes: a launcher, a shell,
    init) are read on every ``ancestors_every``-th call, their rates over the whole interval;
    in between they stay in the tree with no metrics (unknown, not a repeated value that would
    flatten their baselines). They are half the processes of a typical robot and seldom the fault.
    """

    def __init__(self, ancestors_every: int = 5) -> None:
        self._tracked: dict[int, _Tracked] = {}
        self.ancestors_every = ancestors_every
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
        try:
            proc = psutil.Process(pid) if tr is None else tr.proc
            with proc.oneshot():  # the status file `_running` reads serves `_measure` too
                if not _running(proc):  # gone (or a zombie, or its pid reused)
                    if tr is None:
                        out.errors[pid] = "process is not running"
                    else:
                        self._gone(pid, out, "process exited")
                    return None
                r = self._measure(tr or self._track(proc))
        except psutil.NoSuchProcess:
            self._gone(pid, out, "process exited while being read")
            return None
        except psutil.AccessDenied:
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

    def _measure(self, tr: _Tracked) -> ProcessReading:
        p, now = tr.proc, time.monotonic()
        m: dict[str, float] = {}
        denied = [f for f in tr.info.unreadable if f == "cmdline"]
        with p.oneshot():
            tr.info.ppid = p.ppid() or None
            cpu = p.cpu_percent(None)
            if tr.cpu_primed:  # the first call only sets the reference point
                m["cpu_percent"] = cpu
            tr.cpu_primed = True
            m["rss_mb"] = p.memory_info().rss / MB
            m["threads"] = float(p.num_threads())
            c = p.num_ctx_switches()
            ctx = float(c.voluntary + c.involuntary)
            dt = now - tr.t
            if tr.ctx is not None and dt > 0:
                m["ctx_switches_per_s"] = (ctx - tr.ctx) / dt
            tr.ctx = ctx
            try:
                m["open_files"] = float(p.num_fds())
            except (psutil.AccessDenied, AttributeError):
                denied.append("open_files")
            try:
                io = p.io_counters()
                cur = (float(io.read_bytes), float(io.write_bytes))
                if tr.io is not None and dt > 0:
                    m["io_read_kBps"] = (cur[0] - tr.io[0]) / dt / 1000.0
                    m["io_write_kBps"] = (cur[1] - tr.io[1]) / dt / 1000.0
                tr.io = cur
            except (psutil.AccessDenied, AttributeError):
                denied.append("io")
        tr.t = now
        tr.info.metrics, tr.info.unreadable = m, denied
        return tr.info


def _running(p: psutil.Process) -> bool:
    # is_running also compares the create time, so a reused pid counts as a new process.
    try:
        return p.is_running() and p.status() != psutil.STATUS_ZOMBIE
    except psutil.Error:
        return False
