"""Which ended processes the OOM killer ended: a process killed for memory (its container's
limit, or the machine's) exits as a SIGKILL does, and nothing of it says why. Its memory cgroup
counts the processes the OOM killer ended (`stream_viz.collect.cgroups.memory_group_of`): a
count that rose over a sample in which processes of that group ended names them, the largest
first (the OOM killer picks by memory). The count is read after the processes are: a process
killed in between is counted one sample before it is seen gone, so a rise that named no process
waits one sample for it.

`attribute` is pure; `OomWatch` reads the groups, once per process, and their counts each sample.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

from stream_viz.collect.cgroups import MemoryGroup, Mount, memory_group_of, read_oom_kills
from stream_viz.collect.processes import MB


@dataclass(frozen=True)
class OomKill:
    """A process the OOM killer ended: its memory group's directory and limit (bytes; None: the
    machine's memory ran out, not a limit of its own)."""

    group: str
    limit: int | None

    def describe(self) -> str:
        at = f"its group's limit of {self.limit / MB:.0f} MB" if self.limit else "the machine's memory"
        return f"killed by the OOM killer at {at} (cgroup {self.group})"

    def data(self) -> dict[str, object]:
        """What an exit event carries of it."""
        return {"oom_kill": True, "memory_group": self.group,
                "memory_limit_mb": self.limit / MB if self.limit else None}

    def said(self, text: str, data: dict[str, object]) -> tuple[str, str, dict[str, object]]:
        """An exit event's level, text and data once it is known to be this kill: an error, with
        or without nodes."""
        return "error", f"{text}: {self.describe()}", data | self.data()


def attribute(rose: Mapping[str, int], exited: Mapping[int, tuple[str, float]]) -> dict[int, str]:
    """Return pid -> group for the ended processes the OOM killer ended.

    Parameters
    ----------
    rose : how much each group's OOM count rose over the sample.
    exited : pid -> (its group, its last RSS) of the processes that ended in it.
    """
    out = {}
    for group, n in rose.items():
        ended = sorted((-rss, pid) for pid, (g, rss) in exited.items() if g == group)
        out.update((pid, group) for _, pid in ended[:max(0, n)])
    return out


class OomWatch:
    """The memory groups of the processes followed and their OOM counts, sample to sample."""

    def __init__(self, mounts: list[Mount]) -> None:
        self._mounts = mounts
        self._groups: dict[int, MemoryGroup | None] = {}
        self._counts: dict[str, int] = {}
        self._pending: dict[str, int] = {}  # rises of the last call that named no process

    def update(self, pids: Iterable[int], exited: Mapping[int, float]) -> dict[int, OomKill]:
        """Follow ``pids`` (their groups read once); return the processes of ``exited`` (pid -> its
        last RSS) that the OOM killer ended since the last call."""
        live = set(pids)
        for pid in live - self._groups.keys():
            self._groups[pid] = memory_group_of(pid, self._mounts)
        groups = {g.path: g for p, g in self._groups.items() if g is not None and (p in live or p in exited)}
        carried, fresh = self._pending, {}
        for path, g in groups.items():
            count = read_oom_kills(g)
            if count is None:
                continue
            before = self._counts.get(path)
            self._counts[path] = count
            if before is not None and count > before:
                fresh[path] = count - before
        rose = {p: carried.get(p, 0) + fresh.get(p, 0) for p in carried.keys() | fresh.keys()}
        ended = {p: (g.path, exited[p]) for p in exited if (g := self._groups.get(p)) is not None}
        killed = attribute(rose, ended)
        named = list(killed.values())
        # Only this call's rises wait a sample more (the older ones were named first).
        self._pending = {p: k for p, n in fresh.items() if (k := min(n, rose[p] - named.count(p))) > 0}
        self._groups = {p: g for p, g in self._groups.items() if p in live}
        kept = {g.path for g in self._groups.values() if g is not None}
        self._counts = {k: v for k, v in self._counts.items() if k in kept}
        return {pid: OomKill(path, groups[path].limit) for pid, path in killed.items()}
