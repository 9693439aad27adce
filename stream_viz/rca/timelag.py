"""Symptom time-lag analysis: a pair's lag against the lag distribution of all alerting pairs.

The lag of a pair ``(a, b)`` is ``onset(b) - onset(a)`` (or an ICP offset the caller passes).
Its strength is the fraction of all alerting pairs whose absolute lag is at least as large: a
pair whose symptoms started closer together than most pairs did is likely causally linked. The
sign gives the direction: cause before effect.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Lag:
    """Time-lag verdict for the pair ``(a, b)``.

    ``lag`` = ``t_b - t_a``; ``direction`` +1 when ``a`` came first (beyond the tolerance), -1
    when ``b`` did, 0 when simultaneous; ``strength`` in [0, 1] (closeness against the
    distribution); ``causal`` is ``strength`` when ``a`` can be the cause of ``b`` (not after it),
    else ``strength`` damped by how much later ``a`` came.
    """

    lag: float
    direction: int
    strength: float
    causal: float


class LagDistribution:
    """Absolute onset lags of all pairs of alerting members, for percentile queries.

    Built once per ranking from the onsets (first alert time per member); a query is
    ``O(n log n)`` without materialising the ``n²`` pairs.
    """

    def __init__(self, onsets: Mapping[str, float] | np.ndarray, tolerance: float = 2.0) -> None:
        values = onsets.values() if isinstance(onsets, Mapping) else onsets
        self.t = np.sort(np.fromiter(values, dtype=float))
        n = len(self.t)
        self.pairs = n * (n - 1) // 2
        self.tolerance = tolerance

    def fraction_at_least(self, lag: float) -> float:
        """Fraction of pairs whose absolute lag is ``>= |lag|`` (1.0 when there are no pairs)."""
        if self.pairs == 0:
            return 1.0
        x = abs(lag)
        # pairs (i < k) with t_k - t_i < x, counted per i with a binary search
        below = np.searchsorted(self.t, self.t + x, side="left") - np.arange(1, len(self.t) + 1)
        closer = int(np.clip(below, 0, None).sum())
        return 1.0 - closer / self.pairs

    def lag(self, t_a: float, t_b: float, lag: float | None = None) -> Lag:
        """Return the verdict for ``a`` (onset ``t_a``) as a cause of ``b`` (onset ``t_b``).

        Parameters
        ----------
        t_a, t_b : float
            Onsets.
        lag : float, optional
            Use this lag (e.g. a co-occurrence offset) instead of ``t_b - t_a``.
        """
        d = (t_b - t_a) if lag is None else lag
        tol = self.tolerance
        direction = 0 if abs(d) <= tol else (1 if d > 0 else -1)
        strength = self.fraction_at_least(d)
        # A cause cannot come after its effect: damp by how far beyond the tolerance it did.
        causal = strength if d >= -tol else strength * float(np.exp(-(-d - tol) / tol))
        return Lag(d, direction, strength, causal)
