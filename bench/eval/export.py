"""The metric time series the monitor saw, as the one wide table RCAEval and PyRCA take.

Columns are ``time`` and ``<service>_<metric>`` with exactly one underscore: a service name is a
member id without underscores (``node:/lidar_driver`` → ``node.lidar-driver``; a process is named
after its group, ``proc.navigation``), a metric a short name (``rate``, ``cpu``, ``mem`` …).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

# The θ attributes exported per member kind (schema name → short metric name).
METRICS: dict[str, dict[str, str]] = {
    "topic": {"rate_hz": "rate", "jitter_ms": "jitter", "latency_ms": "latency", "bandwidth_kBps": "bw"},
    "process": {"cpu_percent": "cpu", "rss_mb": "mem", "threads": "threads", "ctx_switches_per_s": "ctx"},
    "node": {"publishers": "pubs", "subscriptions": "subs"},
}
SKIP_TOPICS = ("topic:/rosout", "topic:/parameter_events")


def service_name(member: str, process_names: Mapping[str, str] | None = None) -> str:
    """A member id as a service name without underscores (unique for distinct members)."""
    if process_names and member in process_names:
        return "proc." + process_names[member].replace("_", "-")
    kind, _, name = member.partition(":")
    kind = {"process": "proc"}.get(kind, kind)
    return kind + "." + name.strip("/").replace("_", "-").replace("/", ".")


def wide_table(
    series: Mapping[str, tuple[np.ndarray, np.ndarray]],
    schemas: Mapping[str, Sequence[str]],
    process_names: Mapping[str, str] | None = None,
) -> tuple[np.ndarray, list[str], np.ndarray, dict[str, str]]:
    """Align per-member θ series on the union of their sample times.

    Parameters
    ----------
    series : mapping
        Member id → ``(times (n,), values (n, dim))`` as :class:`History` gives them.
    schemas : mapping
        Member kind → θ attribute names (``theta.SCHEMAS``).
    process_names : mapping, optional
        ``process:<pid>`` → a stable name (the group).

    Returns
    -------
    times, columns, matrix, services
        ``matrix[i, j]`` is column ``j`` at ``times[i]``; ``services`` maps service name → member.
        Before a member's first sample its first value is used; after its last (it vanished) 0 —
        a crashed process has no CPU and a silent topic no rate; gaps and NaN carry forward.
    """
    times = np.unique(np.concatenate([np.asarray(t, float) for t, _ in series.values()] or [np.zeros(0)]))
    columns: list[str] = []
    cols: list[np.ndarray] = []
    services: dict[str, str] = {}
    for svc, (member, t, v) in _by_service(series, process_names).items():
        kind = member.partition(":")[0]
        services[svc] = member
        idx = np.searchsorted(t, times, side="right") - 1  # last sample at or before each time
        for attr, short in METRICS[kind].items():
            j = list(schemas[kind]).index(attr)
            col = _ffill(v[:, j])
            out = col[np.clip(idx, 0, None)]
            out[times > t[-1]] = 0.0
            columns.append(f"{svc}_{short}")
            cols.append(np.nan_to_num(out, nan=0.0))
    matrix = np.column_stack(cols) if cols else np.zeros((len(times), 0))
    return times, columns, matrix, services


def _by_service(
    series: Mapping[str, tuple[np.ndarray, np.ndarray]], process_names: Mapping[str, str] | None
) -> dict[str, tuple[str, np.ndarray, np.ndarray]]:
    """Service name → (its first member, times, values) of the exported members with samples.

    Members with one service name (the processes a respawned group ran as) are one series.
    """
    out: dict[str, tuple[str, np.ndarray, np.ndarray]] = {}
    for member in sorted(series):
        if member.partition(":")[0] not in METRICS or member in SKIP_TOPICS:
            continue
        t, v = (np.asarray(x, float) for x in series[member])
        if len(t) == 0:
            continue
        svc = service_name(member, process_names)
        if svc in out:
            first, t0, v0 = out[svc]
            t, v = np.concatenate([t0, t]), np.vstack([v0, v])
            order = np.argsort(t, kind="stable")
            member, t, v = first, t[order], v[order]
        out[svc] = (member, t, v)
    return out


def _ffill(x: np.ndarray) -> np.ndarray:
    """Carry the last finite value forward; leading NaN take the first finite value."""
    x = x.copy()
    ok = np.isfinite(x)
    if not ok.any():
        return np.zeros_like(x)
    idx = np.where(ok, np.arange(len(x)), 0)
    np.maximum.accumulate(idx, out=idx)
    x = x[idx]
    first = np.argmax(ok)
    x[:first] = x[first]
    return x


def column_graph(columns: Sequence[str], service_edges: Sequence[tuple[str, str]]) -> dict[str, list[str]]:
    """Column-level DAG for HT / random walk: every metric of ``a`` → every metric of ``b`` per edge.

    Edges that would close a cycle (at service level, in the given order) are left out.
    """
    by_svc: dict[str, list[str]] = {}
    for c in columns:
        by_svc.setdefault(c.partition("_")[0], []).append(c)
    kept: list[tuple[str, str]] = []
    reach: dict[str, set[str]] = {}
    for a, b in service_edges:
        if a not in by_svc or b not in by_svc or a == b:
            continue
        if a in _reachable(reach, b):
            continue
        kept.append((a, b))
        reach.setdefault(a, set()).add(b)
    parents: dict[str, list[str]] = {c: [] for c in columns}
    for a, b in kept:
        for cb in by_svc[b]:
            parents[cb].extend(by_svc[a])
    return parents


def _reachable(adj: Mapping[str, set[str]], start: str) -> set[str]:
    seen, stack = {start}, [start]
    while stack:
        for n in adj.get(stack.pop(), ()):
            if n not in seen:
                seen.add(n)
                stack.append(n)
    return seen
