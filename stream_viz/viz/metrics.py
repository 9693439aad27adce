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

METRIC_KINDS = ("process", "topic", "host")
VISIBLE = {"topic": ("rate_hz",), "process": ("cpu_percent", "rss_mb"),
           "host": ("machine_cpu_percent", "machine_mem_percent", "cpu_pressure_percent")}


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


# θ is sent with this many mantissa bits (of float64's 52): a relative error of at most 2**-13
# (0.012 %), so every value reads the same to 3 significant digits and within one in the 4th.
# The bits left out are zeros, which the recording's compression (LZ4) mostly takes away.
MANTISSA_BITS = 12


def quantise(x: np.ndarray, bits: int = MANTISSA_BITS) -> np.ndarray:
    """Return ``x`` (float64) rounded to ``bits`` mantissa bits, to nearest; NaN and ±inf kept."""
    x = np.array(x, dtype=np.float64)  # a copy: the caller's rows are left alone
    drop = 52 - bits
    if drop <= 0:
        return x
    u = x.view(np.uint64)
    finite = np.isfinite(x)
    half, mask = np.uint64(1 << (drop - 1)), np.uint64((2**64 - 1) ^ ((1 << drop) - 1))
    # Adding half a step may carry into the exponent: that is the right rounding (0.99.. -> 1.0).
    u[finite] = (u[finite] + half) & mask
    return x


def run_ends(xs: np.ndarray) -> np.ndarray:
    """Return which rows of ``xs`` (T, K) to send: the first and last, and every row that differs
    from the row before or after it (NaN equal to NaN).

    The viewer draws a line between consecutive points: a run of equal rows is drawn flat from
    its first to its last row, as when every row is sent; and latest-at (the value shown at a
    time, the hover) finds the run's value at every time inside it.
    """
    T = len(xs)
    keep = np.ones(T, dtype=bool)
    if T > 2:
        same = np.all((xs[1:] == xs[:-1]) | (np.isnan(xs[1:]) & np.isnan(xs[:-1])), axis=1)
        keep[1:-1] = ~(same[:-1] & same[1:])  # row i equals row i-1 and row i+1: inside a run
    return keep


class _Series:
    """One member's θ rows, in a numpy block that grows: a long batch of a large system stays
    compact (a few bytes of overhead a row, not a Python object per row)."""

    __slots__ = ("n", "sent", "t", "x")

    def __init__(self, width: int) -> None:
        self.t: list[float] = []
        self.x = np.empty((16, width))
        self.n = 0
        self.sent = 0  # rows already sent to the live viewer

    def add(self, t: float, theta: np.ndarray) -> None:
        if self.n == len(self.x):
            self.x = np.concatenate([self.x, np.empty_like(self.x)])
        self.x[self.n] = theta
        self.t.append(t)
        self.n += 1


class MetricBatch:
    """θ rows of processes and topics gathered sample by sample until they are sent.

    Only the rows are kept (not the samples' graphs), so a long batch of a large system is cheap.
    Rows can be sent to the live viewer before the batch is sent to the file (`columns` with
    ``unsent``, then `mark_sent`): the file takes longer batches, which keep it small.
    """

    def __init__(self, kinds: Iterable[str] = METRIC_KINDS) -> None:
        self.kinds = frozenset(kinds)
        self.rows: dict[str, _Series] = {}
        self.first_t: float | None = None
        self.unsent_t: float | None = None  # the first time not yet sent to the live viewer
        self.G: nx.MultiDiGraph | None = None  # the latest graph, for the members' labels

    def add(self, t: float, G: nx.MultiDiGraph) -> None:
        """Take the θ rows of one sample (members of ``kinds`` with a θ of their schema, not all NaN)."""
        for m, data in G._node.items():  # the attribute dicts, not a data view: every member, every sample
            kind, theta = data.get("kind"), data.get("theta")
            if kind not in self.kinds or theta is None or data.get("gone"):
                continue
            if type(theta) is not np.ndarray or theta.dtype != np.float64:
                theta = np.asarray(theta, dtype=float)
            if theta.shape != (len(SCHEMAS[kind]),) or not np.isfinite(theta).any():
                continue
            series = self.rows.get(m)
            if series is None:
                series = self.rows[m] = _Series(len(theta))
            series.add(float(t), theta)
        self.first_t = t if self.first_t is None else self.first_t
        self.unsent_t = t if self.unsent_t is None else self.unsent_t
        self.G = G

    def columns(self, unsent: bool = False) -> dict[str, tuple[np.ndarray, np.ndarray]]:
        """``member -> (times (T,), values (T, len(schema)))``, as `metric_columns` returns; with
        ``unsent``, only the rows not yet sent to the live viewer."""
        out = {}
        for m, s in self.rows.items():
            i = s.sent if unsent else 0
            if i < s.n:
                out[m] = (np.asarray(s.t[i:]), s.x[i:s.n].copy())
        return out

    def mark_sent(self) -> None:
        """Note every row so far as sent to the live viewer."""
        for s in self.rows.values():
            s.sent = s.n
        self.unsent_t = None

    def clear(self) -> None:
        self.rows, self.first_t, self.unsent_t = {}, None, None

    def __len__(self) -> int:
        return len(self.rows)


def log_metrics(rec: rr.RecordingStream, batch: Iterable[Any] | MetricBatch,
                kinds: Iterable[str] = METRIC_KINDS, unsent: bool = False) -> int:
    """Send θ of the batch's processes and topics, one ``send_columns`` per member; return #rows.

    ``batch`` is a `MetricBatch` (with ``unsent``: its rows not yet sent live) or ``(t, G)``
    pairs / samples. Values are `quantise`d and runs of equal rows sent as their ends
    (`run_ends`). New members are styled once (static ``SeriesLines`` with readable names).
    """
    if isinstance(batch, MetricBatch):
        columns, last_G = batch.columns(unsent), batch.G
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
        xs = quantise(xs)
        keep = run_ends(xs)
        rec.send_columns(path, indexes=[rr.TimeColumn(paths.TIME, timestamp=ts[keep])],
                         columns=rr.Scalars.columns(scalars=xs[keep]))
        n += int(keep.sum())
    return n
