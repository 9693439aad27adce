"""Bounded per-member history of θ: what plugins compare the present against."""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field

import numpy as np


class _Ring:
    """One member's last samples in two numpy arrays used as a ring.

    ~8 bytes per number instead of a Python tuple and array per sample (bench/bench_history.py,
    figures in docs/plugins.md), and reading the last n samples is one slice, not n objects stacked. Capacity
    doubles from 16 up to ``maxlen``, so a member that lives a few samples costs little.
    """

    __slots__ = ("end", "maxlen", "n", "t", "v")

    def __init__(self, maxlen: int, dim: int) -> None:
        self.maxlen = maxlen = max(1, maxlen)
        cap = min(16, maxlen)
        self.t = np.empty(cap)
        self.v = np.empty((cap, dim))
        self.n = 0  # samples held
        self.end = 0  # index after the newest sample

    def add(self, t: float, theta: np.ndarray) -> None:
        cap = len(self.t)
        if self.n == cap and cap < self.maxlen:  # full but may grow: unroll into a bigger array
            new = min(2 * cap, self.maxlen)
            order = self._order(cap)
            self.t = np.concatenate([self.t[order], np.empty(new - cap)])
            self.v = np.concatenate([self.v[order], np.empty((new - cap, self.v.shape[1]))])
            self.end, cap = cap, new
        self.t[self.end] = t
        self.v[self.end] = theta
        self.end = (self.end + 1) % cap
        self.n = min(self.n + 1, cap)

    def _order(self, last: int) -> np.ndarray:
        """Indices of the newest ``last`` samples, oldest first."""
        return np.arange(self.end - last, self.end) % len(self.t)

    def last(self, last: int | None) -> tuple[np.ndarray, np.ndarray]:
        k = self.n if last is None else max(0, min(last, self.n))
        idx = self._order(k)
        return self.t[idx], self.v[idx]  # fancy indexing: copies, safe from later writes


@dataclass
class History:
    """Last ``maxlen`` samples ``(t, θ)`` per member; memory bounded by construction."""

    maxlen: int = 600
    _series: dict[str, _Ring] = field(default_factory=dict)

    def add(self, member: str, t: float, theta: np.ndarray) -> None:
        """Append one sample of ``member``."""
        theta = np.asarray(theta, dtype=float).ravel()
        ring = self._series.get(member)
        if ring is None or ring.v.shape[1] != len(theta):  # new member (or a new θ layout)
            ring = self._series[member] = _Ring(self.maxlen, len(theta))
        ring.add(t, theta)

    def add_all(self, t: float, thetas: Iterable[tuple[str, np.ndarray]]) -> None:
        """Append one sample ``(member, θ)`` of each member at ``t``: `add` for each, in order.

        The record step's call (every member, every sample): a θ that is already a flat float
        array of its ring's width goes to the ring without `add`'s conversion.
        """
        series = self._series
        for m, theta in thetas:
            ring = series.get(m)
            if (ring is not None and type(theta) is np.ndarray and theta.dtype == np.float64
                    and theta.ndim == 1 and ring.v.shape[1] == len(theta)):
                ring.add(t, theta)
            else:
                self.add(m, t, theta)  # new member, another layout, or not a float array

    def times(self, member: str, last: int | None = None) -> np.ndarray:
        """Sample times of ``member`` (oldest first; only the ``last`` ones when given)."""
        ring = self._series.get(member)
        return np.zeros(0) if ring is None else ring.last(last)[0]

    def values(self, member: str, last: int | None = None) -> np.ndarray:
        """Samples of ``member`` as a (n, dim) array (the ``last`` ones when given); (0, 0) if never seen."""
        ring = self._series.get(member)
        return np.zeros((0, 0)) if ring is None else ring.last(last)[1]

    def series(self, member: str, last: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """`times` and `values` of ``member`` at once (one ring read instead of two)."""
        ring = self._series.get(member)
        return (np.zeros(0), np.zeros((0, 0))) if ring is None else ring.last(last)

    def forget(self, keep: set[str]) -> None:
        """Drop members not in ``keep`` (bounds memory when the graph churns)."""
        for m in list(self._series):
            if m not in keep:
                del self._series[m]

    def __contains__(self, member: str) -> bool:
        return member in self._series

    def __iter__(self) -> Iterator[str]:
        """The members with a history."""
        return iter(self._series)
