"""Node → PID: decode the Fast DDS GUID prefix of each node's /rosout publisher, confirm with psutil.

The prefix only carries the low 16 bits of the PID, so every live process with those bits is a
candidate; a candidate without Fast DDS in its memory maps is dropped, and one whose
``ROS_DOMAIN_ID`` matches ours is preferred. Results are cached per GUID prefix (one participant =
one process), so the /proc reads happen once per process.

The PID in the prefix is the one the process sees itself as: in a container with its own PID
namespace (Docker's default, even with ``--network host``) that is its PID in there (1, 7, …),
not ours. So a process is matched by its innermost PID (the last of ``NSpid`` in
``/proc/<pid>/status``), and known by ours.
"""

from __future__ import annotations

from pathlib import Path

import psutil

from stream_viz.collect.fastdds import decode_gid
from stream_viz.collect.readings import PidInfo

RMW_MARKERS = ("fastrtps", "fastdds", "librmw")


def _has_fastdds(pid: int) -> bool | None:
    """True/False if /proc/<pid>/maps shows (no) Fast DDS; None if we may not read it."""
    maps = Path(f"/proc/{pid}/maps")
    try:
        text = maps.read_text(errors="replace")
    except FileNotFoundError:
        try:  # not Linux-like /proc: fall back to psutil (slower)
            text = "\n".join(m.path for m in psutil.Process(pid).memory_maps())
        except (psutil.Error, OSError, NotImplementedError):
            return None
    except OSError:
        return None
    return any(m in text for m in RMW_MARKERS)


def _domain_matches(pid: int, domain_id: int) -> bool | None:
    try:
        env = psutil.Process(pid).environ()
    except (psutil.Error, OSError):
        return None
    return env.get("ROS_DOMAIN_ID", "0").strip() == str(domain_id)


def inner_pid(pid: int) -> int:
    """Return the PID ``pid`` has in its own PID namespace (``pid`` itself outside containers,
    or where ``/proc/<pid>/status`` has no ``NSpid``: Linux < 4.1, not Linux, gone)."""
    try:
        with open(f"/proc/{pid}/status", "rb") as f:
            for line in f:
                if line.startswith(b"NSpid:"):
                    return int(line.split()[-1])
    except (OSError, ValueError):
        pass
    return pid


class InnerPids:
    """Our PID → its innermost PID for every process, read once per new PID (a PID's namespace
    does not change while it lives)."""

    def __init__(self) -> None:
        self._inner: dict[int, int] = {}

    def update(self, pids: list[int]) -> dict[int, int]:
        """Return PID → innermost PID for ``pids`` (the live ones), forgetting the others."""
        old = self._inner
        self._inner = {p: old[p] if p in old else inner_pid(p) for p in pids}
        return self._inner


def candidates(low16: int, inner: dict[int, int], exclude: int | None = None) -> list[int]:
    """Return our PIDs of the processes whose own PID has the low 16 bits ``low16``.

    Parameters
    ----------
    low16 : int
        The PID bits of a Fast DDS GUID prefix.
    inner : dict
        Our PID → its PID in its own namespace (`InnerPids`; equal outside containers).
    exclude : int, optional
        A PID never to return (our own).
    """
    return sorted(p for p, q in inner.items() if q & 0xFFFF == low16 and p != exclude)


def choose(low16: int, inner: dict[int, int], domain_id: int, exclude: int | None = None) -> PidInfo:
    """Return the process holding a participant whose prefix says ``low16`` (see module doc);
    ``inner``: our PID → its innermost PID (`InnerPids`)."""
    cands = candidates(low16, inner, exclude)
    checked = [(p, _has_fastdds(p)) for p in cands]
    cands = [p for p, rmw in checked if rmw is not False]
    if not cands:
        return PidInfo(None, "unknown")
    if len(cands) > 1:
        env_ok = [p for p in cands if _domain_matches(p, domain_id)]
        if len(env_ok) == 1:
            return PidInfo(env_ok[0], "confirmed", tuple(cands))
        return PidInfo(None, "ambiguous", tuple(cands))
    p = cands[0]
    rmw = dict(checked)[p]
    if rmw and _domain_matches(p, domain_id) is not False:
        return PidInfo(p, "confirmed", (p,))
    return PidInfo(p, "unverified", (p,))


class PidResolver:
    """Maps node names to pids via their /rosout publisher gids, cached per GUID prefix.

    Parameters
    ----------
    domain_id : int
        Our ROS_DOMAIN_ID (a candidate process on another domain is less likely ours).
    own_host : int or None
        Our Fast DDS host id; participants from another host get status ``remote``.
    """

    def __init__(self, domain_id: int, own_host: int | None = None) -> None:
        self.domain_id, self.own_host = domain_id, own_host
        self._cache: dict[str, PidInfo] = {}
        self._inner = InnerPids()

    def resolve(self, rosout_gids: dict[str, bytes]) -> dict[str, PidInfo]:
        """Return node fqn → `PidInfo` for every node given (unknown when the gid is not Fast DDS)."""
        out: dict[str, PidInfo] = {}
        pids: dict[int, int] | None = None
        for fqn, gid in rosout_gids.items():
            info = decode_gid(gid)
            if info is None:
                out[fqn] = PidInfo(None, "unknown")
                continue
            cached = self._cache.get(info.prefix)
            if cached is None or cached.status in ("unknown", "ambiguous", "unverified"):
                if self.own_host is not None and info.host_id != self.own_host:
                    cached = PidInfo(None, "remote", prefix=info.prefix)
                else:
                    if pids is None:
                        pids = self._inner.update(psutil.pids())
                    found = choose(info.pid_low16, pids, self.domain_id)
                    cached = PidInfo(found.pid, found.status, found.candidates, info.prefix)
                self._cache[info.prefix] = cached
            out[fqn] = cached
        return out

    def forget(self, live_prefixes: set[str]) -> None:
        """Drop cached prefixes no longer in the graph (bounds the cache)."""
        for p in list(self._cache):
            if p not in live_prefixes:
                del self._cache[p]
