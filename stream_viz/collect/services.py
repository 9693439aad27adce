"""Service calls seen on service event topics (service introspection), without calling anything.

Where a system turns service introspection on (Jazzy: ``configure_introspection`` on a server or
a client), every call shows on ``<service>/_service_event`` as events of type REQUEST_SENT and
RESPONSE_RECEIVED (from the client) and REQUEST_RECEIVED and RESPONSE_SENT (from the server),
each with the client's gid and the call's sequence number. A call is open from its first request
event until its first response event; an open call is a client waiting, a closed one has a
response time. Times are our receive stamps of the events (the events' own stamps come from the
publishers' clocks, which may be simulated).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, field

from stream_viz.collect.cdr import REQUEST_RECEIVED, REQUEST_SENT

EVENT_SUFFIX = "/_service_event"


@dataclass
class Call:
    """An open call: when its request was first seen, by whom."""

    t_ns: int
    client_gid: bytes
    server_gid: bytes | None = None  # the server's event writer, when the server reported it


@dataclass
class ServiceStats:
    """A service's calls over the window: responses per second, their mean time, the open calls."""

    calls_per_s: float
    response_ms: float
    open_calls: list[tuple[float, bytes, bytes | None]] = field(default_factory=list)
    # (waited s, client gid, server gid or None), longest first


class ServiceCalls:
    """Open and answered calls per service, from the events of its event topic.

    Parameters
    ----------
    window_s : float
        Responses counted over this long.
    forget_s : float
        An open call older than this is dropped (its client has long given up, or we missed its
        response): it is counted in ``abandoned``.
    """

    def __init__(self, window_s: float = 3.0, forget_s: float = 60.0) -> None:
        self.window_ns, self.forget_ns = int(window_s * 1e9), int(forget_s * 1e9)
        self.open: dict[str, dict[tuple[bytes, int], Call]] = {}
        self.done: dict[str, deque[tuple[int, int]]] = {}  # (response t ns, response time ns)
        self._answered: dict[str, dict[tuple[bytes, int], int]] = {}  # key -> t ns, recently
        self.abandoned = 0
        self.seen_since: dict[str, int] = {}  # service -> first event t ns

    def add(self, service: str, t_ns: int, event_type: int, client_gid: bytes, seq: int,
            writer_gid: bytes | None = None) -> None:
        """Take one event of ``service`` received at ``t_ns`` (``writer_gid``: who published it)."""
        self.seen_since.setdefault(service, t_ns)
        key = (client_gid, seq)
        calls = self.open.setdefault(service, {})
        answered = self._answered.setdefault(service, {})
        server_side = event_type == REQUEST_RECEIVED
        if event_type in (REQUEST_SENT, REQUEST_RECEIVED):
            if key in answered:
                return  # a request event arriving after its response (another writer)
            call = calls.get(key)
            if call is None:
                calls[key] = Call(t_ns, client_gid, writer_gid if server_side else None)
            elif server_side and call.server_gid is None:
                call.server_gid = writer_gid
            return
        call = calls.pop(key, None)
        if key in answered:
            return  # the other side's response event of a call already answered
        answered[key] = t_ns
        if call is not None:
            self.done.setdefault(service, deque()).append((t_ns, t_ns - call.t_ns))

    def stats(self, now_ns: int) -> dict[str, ServiceStats]:
        """Return the stats of every service seen, forgetting what is older than the window."""
        out = {}
        for service in list(self.seen_since):
            done = self.done.setdefault(service, deque())
            while done and done[0][0] < now_ns - self.window_ns:
                done.popleft()
            answered = self._answered.get(service, {})
            for key in [k for k, t in answered.items() if t < now_ns - self.forget_ns]:
                del answered[key]
            calls = self.open.get(service, {})
            for key in [k for k, c in calls.items() if now_ns - c.t_ns > self.forget_ns]:
                del calls[key]
                self.abandoned += 1
            span = min(self.window_ns, now_ns - self.seen_since[service])
            rate = len(done) / (span / 1e9) if span > 0 else float("nan")
            mean = sum(d for _, d in done) / len(done) / 1e6 if done else float("nan")
            waiting = sorted(((now_ns - c.t_ns) / 1e9, c.client_gid, c.server_gid) for c in calls.values())
            out[service] = ServiceStats(rate, mean, waiting[::-1])
        return out

    def forget(self, services: set[str]) -> None:
        """Drop what we keep of services no longer observed."""
        for d in (self.open, self.done, self._answered, self.seen_since):
            for s in [s for s in d if s not in services]:
                del d[s]


def party(gid: bytes | None, prefixes: Mapping[bytes, list[str]], among: list[str]) -> str | None:
    """Return the node of ``among`` (a service's clients or servers) that ``gid`` belongs to.

    A gid's first 12 bytes are its DDS participant's GUID prefix, shared by the nodes of one
    process (``prefixes``: prefix → nodes, from the nodes' /rosout gids). Without a gid, or
    when the participant holds none of ``among``, the only one of ``among``; else None.
    """
    if gid is not None:
        found = [n for n in prefixes.get(gid[:12], ()) if n in among]
        if found:
            return found[0] if len(found) == 1 else None
    return among[0] if len(among) == 1 else None
