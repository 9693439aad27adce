"""``/metrics/<kind>/<member>/theta``: θ of processes, topics and hosts as time series, sent in batches.

One entity per member holds all its θ series (one column each, named in a static
``SeriesLines``): per-row overhead (row id, time) is shared by the whole vector, which keeps a
recording much smaller than one entity per attribute (docs/viz.md). The key series (a topic's rate,
a process's CPU and memory) are visible by default; the others are one click in the legend.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import networkx as nx
import numpy as np
import rerun as rr

from stream_viz.model.ids import kind_of, name_of
from stream_viz.model.theta import SCHEMAS
from stream_viz.viz import paths, style

METRIC_KINDS = ("process", "topic", "host")  # a host's θ: only with several computers
VISIBLE = {"topic": ("rate_hz",), "process": ("cpu_percent", "rss_mb"),
           "host": ("machine_cpu_percent", "machine_mem_percent")}


def _t_graph(sample: Any) -> tuple[float, nx.MultiDiGraph]:
    if isinstance(sample, tuple):
        return float(sample[0]), sample[1]
    return float(sample.t), sample.graph


def metric_columns(
    batch: Iterable[Any], kinds: Iterable[str] = METRIC_KINDS
) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Return ``member -> (times (T,), values (T, len(schema)))`` from a batch of samples.

    Rows where θ is entirely unknown (NaN) are left out; a NaN inside a row stays (a gap).

    Parameters
    ----------
    batch : iterable
        ``(t, G)`` pairs or `stream_viz.records.Sample` objects, θ on the members of ``G``.
    kinds : iterable of str
        Member kinds whose θ is sent.
    """
    acc = MetricBatch(kinds)
    for sample in batch:
        acc.add(*_t_graph(sample))
    return acc.columns()


def member_label(G: nx.MultiDiGraph | None, member: str) -> str:
    """Return a readable name of a member for legends (a process: ``name (pid)``)."""
    label = name_of(member)
    if G is not None and member in G:
        data = G.nodes[member]
        if data.get("kind") == "process":
            name = data.get("name") or data.get("exe")
            return f"{name} ({label})" if name else f"pid {label}"
        label = str(data.get("label") or label)
    return label


def style_series(rec: rr.RecordingStream, G: nx.MultiDiGraph | None, member: str) -> None:
    """Log the static ``SeriesLines`` of a member's θ entity (names, colours, visible series)."""
    kind = kind_of(member)
    schema = SCHEMAS[kind]
    label = member_label(G, member)
    rec.log(
        paths.metrics_path(member, paths.THETA),
        rr.SeriesLines(names=[f"{label} {a}" for a in schema],
                       colors=[style.rgb_for_index(i) for i in range(len(schema))],
                       visible_series=[a in VISIBLE.get(kind, schema[:1]) for a in schema]),
        static=True,
    )


class MetricBatch:
    """θ rows of processes and topics gathered sample by sample until they are sent.

    Only the rows are kept (not the samples' graphs), so a long batch of a large system is cheap.
    """

    def __init__(self, kinds: Iterable[str] = METRIC_KINDS) -> None:
        self.kinds = frozenset(kinds)
        self.rows: dict[str, tuple[list[float], list[np.ndarray]]] = {}
        self.first_t: float | None = None
        self.G: nx.MultiDiGraph | None = None  # the latest graph, for the members' labels

    def add(self, t: float, G: nx.MultiDiGraph) -> None:
        """Take the θ rows of one sample (members of ``kinds`` with a θ of their schema, not all NaN)."""
        for m, data in G.nodes(data=True):
            kind, theta = data.get("kind"), data.get("theta")
            if kind not in self.kinds or theta is None or data.get("gone"):
                continue
            theta = np.asarray(theta, dtype=float)
            if theta.shape != (len(SCHEMAS[kind]),) or not np.isfinite(theta).any():
                continue
            rt, rx = self.rows.setdefault(m, ([], []))
            rt.append(float(t))
            rx.append(theta)
        self.first_t = t if self.first_t is None else self.first_t
        self.G = G

    def columns(self) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """``member -> (times (T,), values (T, len(schema)))``, as `metric_columns` returns."""
        return {m: (np.asarray(ts), np.vstack(xs)) for m, (ts, xs) in self.rows.items()}

    def clear(self) -> None:
        self.rows, self.first_t = {}, None

    def __len__(self) -> int:
        return len(self.rows)


def log_metrics(rec: rr.RecordingStream, batch: Iterable[Any] | MetricBatch,
                kinds: Iterable[str] = METRIC_KINDS) -> int:
    """Send θ of the batch's processes and topics, one ``send_columns`` per member; return #rows.

    ``batch`` is a `MetricBatch` or ``(t, G)`` pairs / samples. New members are styled once
    (static ``SeriesLines`` with readable names).
    """
    if isinstance(batch, MetricBatch):
        columns, last_G = batch.columns(), batch.G
    else:
        batch = list(batch)
        if not batch:
            return 0
        columns, last_G = metric_columns(batch, kinds), _t_graph(batch[-1])[1]
    styled = style.styled(rec)
    n = 0
    for member, (ts, xs) in sorted(columns.items()):
        path = paths.metrics_path(member, paths.THETA)
        if path not in styled:
            style_series(rec, last_G, member)
            styled.add(path)
        rec.send_columns(path, indexes=[rr.TimeColumn(paths.TIME, timestamp=ts)],
                         columns=rr.Scalars.columns(scalars=xs))
        n += len(ts)
    return n
