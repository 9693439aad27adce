"""One topic's messages over a sliding window, with running sums: its metrics cost O(1) a sample.

Every record is ``(received ns, source ns, size bytes, sequence number or None, publisher gid or
None, message age ns or None)`` in arrival order; the age is received minus the message's own
``header.stamp`` (None when the type has no Header or the stamp is unset). All sums are Python
ints of nanoseconds, so adding and removing never drifts: the metrics equal a fresh computation
over the records in the window.
"""

from __future__ import annotations

import itertools
import math
from collections import Counter, deque
from collections.abc import Sequence

import numpy as np

RECENT = 5  # intervals behind `rate_recent_hz`, at least
# ... and at least those of this span: the last 5 intervals of a 500 Hz IMU are 10 ms, which one
# scheduling hiccup of the publisher or of the monitor halves
RECENT_NS = 500_000_000
# (received ns, source ns, size, sequence number, publisher gid, received − header.stamp ns)
Record = tuple[int, int, int, int | None, bytes | None, int | None]
RESET_NS = 1_000_000_000  # stamps going back further than this: a restarted time, not reordering
WARMUP_S = 1.0  # a fresh subscription has seen too little to call a rate (0 would read as silence)


class TopicWindow:
    """Records of one topic, oldest first, and the running sums its metrics need."""

    __slots__ = ("age_by_gid", "buf", "by_gid", "gap_ns", "gaps", "last_stamp", "n_age", "no_seq", "resets",
                 "s_age", "s_d", "s_d2", "s_recv", "s_size", "s_src")

    def __init__(self) -> None:
        self.buf: deque[Record] = deque()
        self.s_recv = self.s_src = self.s_size = 0
        self.s_d = self.s_d2 = 0  # sums of consecutive arrival intervals and of their squares
        self.gaps = 0  # missing sequence numbers between consecutive records
        self.no_seq = 0  # records without a sequence number
        self.s_age = self.n_age = 0  # sum and count of the message ages (records that have one)
        self.by_gid: Counter[bytes] = Counter()  # records per publisher gid (those that have one)
        self.age_by_gid: dict[bytes, list[int]] = {}  # gid -> [sum, count] of its records' ages
        self.gap_ns = 0  # the longest interval between records added since `take_gap`
        self.last_stamp: dict[bytes | None, int] = {}  # the newest header stamp per publisher
        self.resets: list[tuple[int, int]] = []  # (received ns, how far back ns) since `take_resets`

    def add(self, recv: int, src: int, size: int, seq: int | None, gid: bytes | None = None,
            age: int | None = None) -> None:
        """Append the newest record."""
        if self.buf:
            last = self.buf[-1]
            d = recv - last[0]
            self.s_d += d
            self.s_d2 += d * d
            # A stall of the monitor stretches receive intervals only; a clock offset between two
            # publishers' hosts, source intervals only: a quiet of the topic stretches both.
            g = src - last[1]
            if d < g:
                g = d
            if g > self.gap_ns:
                self.gap_ns = g
            if seq is not None and last[3] is not None and seq > last[3] + 1:
                self.gaps += seq - last[3] - 1
        if age is not None:  # a publisher's stamps going back: its stream restarted its time
            stamp = recv - age
            prev = self.last_stamp.get(gid)
            if prev is not None and prev - stamp > RESET_NS:
                self.resets.append((recv, prev - stamp))
            self.last_stamp[gid] = stamp
        self.buf.append((recv, src, size, seq, gid, age))
        self.s_recv += recv
        self.s_src += src
        self.s_size += size
        self.no_seq += seq is None
        if age is not None:
            self.s_age += age
            self.n_age += 1
        if gid is not None:
            self.by_gid[gid] += 1
            if age is not None:
                acc = self.age_by_gid.setdefault(gid, [0, 0])
                acc[0] += age
                acc[1] += 1

    def expire(self, before_ns: int) -> None:
        """Drop the records received before ``before_ns``."""
        buf = self.buf
        while buf and buf[0][0] < before_ns:
            recv, src, size, seq, gid, age = buf.popleft()
            self.s_recv -= recv
            self.s_src -= src
            self.s_size -= size
            self.no_seq -= seq is None
            if age is not None:
                self.s_age -= age
                self.n_age -= 1
            if gid is not None:
                left = self.by_gid[gid] - 1
                if left:
                    self.by_gid[gid] = left
                else:
                    del self.by_gid[gid]
                if age is not None:
                    acc = self.age_by_gid[gid]
                    acc[0] -= age
                    acc[1] -= 1
                    if not acc[1]:
                        del self.age_by_gid[gid]
            if buf:
                d = buf[0][0] - recv
                self.s_d -= d
                self.s_d2 -= d * d
                nxt = buf[0][3]
                if seq is not None and nxt is not None and nxt > seq + 1:
                    self.gaps -= nxt - seq - 1

    def metrics(self, now_ns: int, created_ns: int, window_ns: int, n_publishers: int,
                sized: bool = True) -> dict[str, float]:
        """Return `window_metrics` of the records held, from the running sums (O(1) in them)."""
        span_ns = min(window_ns, now_ns - created_ns)
        m: dict[str, float] = {}
        if span_ns < WARMUP_S * 1e9:
            return m
        span = span_ns / 1e9
        n = len(self.buf)
        m["rate_hz"] = n / span
        if n >= 1:
            m["latency_ms"] = (self.s_recv - self.s_src) / n / 1e6
            if self.n_age:
                m["stamp_age_ms"] = self.s_age / self.n_age / 1e6
                m["stamp_age_recent_ms"] = _youngest(self.buf)
            if sized:
                m["bandwidth_kBps"] = self.s_size / span / 1000.0
            if n >= 3:
                k = n - 1  # population variance of the intervals, exact in integers
                m["jitter_ms"] = math.sqrt((k * self.s_d2 - self.s_d * self.s_d) / (k * k)) / 1e6
            # Arrival order is receive-stamp order but for a reordering between transports: the
            # newest stamps are among the last few records.
            tail = sorted(r[0] for r in _tail(self.buf, 2 * (RECENT + 1)))
            m["age_s"] = max(0, now_ns - tail[-1]) / 1e9
            if n >= 4:
                k = min(RECENT, n - 1)
                first = tail[-1 - k]
                if now_ns - first < RECENT_NS:  # a fast topic: every interval of the span counts
                    recv = np.fromiter((r[0] for r in self.buf), dtype=np.int64, count=n)
                    first, k = _recent(recv, now_ns)
                m["rate_recent_hz"] = k / max((now_ns - first) / 1e9, 1e-9)
        if n_publishers == 1 and self.no_seq == 0:
            m["drops_per_s"] = self.gaps / span
        return m

    def take_resets(self) -> list[tuple[int, int]]:
        """Return the stamp resets (received ns, how far back ns) added since the last call: a
        publisher whose ``header.stamp`` went back by more than ``RESET_NS`` (a recording that
        looped, a simulation reset), and start over."""
        out, self.resets = self.resets, []
        return out

    def take_gap(self) -> float:
        """Return the longest interval (s) between consecutive records added since the last call,
        the shorter of its receive and source intervals, and start over (0 without one)."""
        g, self.gap_ns = self.gap_ns, 0
        return g / 1e9

    def publisher_rates(self, now_ns: int, created_ns: int, window_ns: int) -> dict[bytes, float]:
        """Return publisher gid → messages/s over the window (records without a gid left out);
        empty while the subscription is younger than `WARMUP_S`, as the rate."""
        span_ns = min(window_ns, now_ns - created_ns)
        if span_ns < WARMUP_S * 1e9:
            return {}
        return {gid: n * 1e9 / span_ns for gid, n in self.by_gid.items()}

    def newest_stamps(self, k: int) -> list[int]:
        """Return the header stamps (ns) of the newest ``k`` records that have one."""
        out: list[int] = []
        for r in reversed(self.buf):
            if r[5] is not None:
                out.append(r[0] - r[5])
                if len(out) >= k:
                    break
        return out

    def publisher_ages(self) -> dict[bytes, float]:
        """Return publisher gid → mean message age (ms) of its records in the window that have
        one: whose stamps are late when several publish on the topic (``/tf``)."""
        return {gid: total / n / 1e6 for gid, (total, n) in self.age_by_gid.items()}


def _recent(recv: np.ndarray, now_ns: int) -> tuple[int, int]:
    """The intervals behind ``rate_recent_hz``: ``(first, k)``, the (k+1)-th newest arrival and k,
    the last `RECENT` intervals or those of the last `RECENT_NS`, whichever are more (at most n - 1)."""
    n = len(recv)
    k = min(n - 1, max(RECENT, int(np.count_nonzero(recv > now_ns - RECENT_NS))))
    return int(np.partition(recv, n - 1 - k)[n - 1 - k]), k


def _youngest(records: Sequence[tuple]) -> float:
    """The smallest message age (ms) among the newest ``RECENT + 1`` records that have one (at
    least one has): high only when each of the newest messages is late, which one old-stamped
    message never makes it."""
    ages: list[int] = []
    for r in reversed(records):
        if r[5] is not None:
            ages.append(r[5])
            if len(ages) > RECENT:
                break
    return min(ages) / 1e6


def _tail(buf: deque, k: int) -> list:
    return [buf[i] for i in range(max(0, len(buf) - k), len(buf))]


def window_metrics(buf: list[tuple], now_ns: int, created_ns: int, window_ns: int,
                   n_publishers: int, sized: bool = True) -> dict[str, float]:
    """Rate, jitter, latency, bandwidth, drops and message age from `Record` records.

    The definition, computed afresh over the records (numpy); `TopicWindow.metrics` returns the
    same from running sums without walking them, and is tested against this. Pure: ``span`` is
    the window, or less while the subscription is younger than the window; a subscription
    younger than `WARMUP_S` gives no rate (NaN). Drops count sequence-number gaps and
    only with one publisher (interleaved publishers' numbers cannot be told apart).

    Two fast signals beside the window's: ``age_s``, the time since the newest message (a topic
    that stops shows at once, not when the window has emptied), and ``rate_recent_hz``, the rate
    over the last ``RECENT`` intervals, or those of the last ``RECENT_NS`` when more, up to now
    (at least 3; the open interval since the newest message counts, so a slowed topic shows
    before the window has turned over).

    ``stamp_age_ms``: the mean of received − ``header.stamp`` over the records that have one (a
    type beginning with a Header whose stamp is set): the age of the data, beside the transport
    latency (received − source timestamp, i.e. since it was published); ``stamp_age_recent_ms``
    the smallest of them among the newest ``RECENT + 1`` records that have one (stale data shows
    in it at once, a single late message never).
    """
    span_ns = min(window_ns, now_ns - created_ns)
    m: dict[str, float] = {}
    if span_ns < WARMUP_S * 1e9:
        return m
    span = span_ns / 1e9
    n = len(buf)
    m["rate_hz"] = n / span
    if n >= 1:
        recv = np.array([b[0] for b in buf], dtype=np.int64)
        src = np.array([b[1] for b in buf], dtype=np.int64)
        m["latency_ms"] = float(np.mean(recv - src)) / 1e6
        ages = [b[5] for b in buf if b[5] is not None]
        if ages:
            m["stamp_age_ms"] = sum(ages) / len(ages) / 1e6
            m["stamp_age_recent_ms"] = _youngest(buf)
        if sized:
            m["bandwidth_kBps"] = sum(b[2] for b in buf) / span / 1000.0
        if n >= 3:
            m["jitter_ms"] = float(np.std(np.diff(recv))) / 1e6
        newest = int(recv.max())
        m["age_s"] = max(0, now_ns - newest) / 1e9
        if n >= 4:
            first, k = _recent(recv, now_ns)
            m["rate_recent_hz"] = k / max((now_ns - first) / 1e9, 1e-9)
    if n_publishers == 1:
        seqs = [b[3] for b in buf if b[3] is not None]
        if len(seqs) == n:
            gaps = sum(max(0, b - a - 1) for a, b in itertools.pairwise(seqs))
            m["drops_per_s"] = gaps / span
    return m
