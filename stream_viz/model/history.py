"""Bounded per-member history of θ: what plugins compare the present against."""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field
from itertools import islice

import numpy as np


@dataclass
class History:
    """Last ``maxlen`` samples ``(t, θ)`` per member; memory bounded by construction."""

    maxlen: int = 600
    _series: dict[str, deque[tuple[float, np.ndarray]]] = field(default_factory=dict)

    def add(self, member: str, t: float, theta: np.ndarray) -> None:
        """Append one sample of ``member``."""
        q = self._series.get(member)
        if q is None:
            q = self._series[member] = deque(maxlen=self.maxlen)
        q.append((t, theta))

    def _last(self, member: str, last: int | None) -> list[tuple[float, np.ndarray]]:
        q = self._series.get(member, ())
        if last is None or last >= len(q):
            return list(q)
        # from the right end: cost grows with ``last``, not with the whole history
        return list(islice(reversed(q), last))[::-1]

    def times(self, member: str, last: int | None = None) -> np.ndarray:
        """Sample times of ``member`` (oldest first; only the ``last`` ones when given)."""
        return np.array([t for t, _ in self._last(member, last)], dtype=float)

    def values(self, member: str, last: int | None = None) -> np.ndarray:
        """Samples of ``member`` as a (n, dim) array (the ``last`` ones when given); (0, 0) if never seen."""
        q = self._last(member, last)
        if not q:
            return np.zeros((0, 0))
        return np.vstack([v for _, v in q])

    def forget(self, keep: set[str]) -> None:
        """Drop members not in ``keep`` (bounds memory when the graph churns)."""
        for m in list(self._series):
            if m not in keep:
                del self._series[m]

    def __contains__(self, member: str) -> bool:
        return member in self._series
