"""Symptom co-occurrence: a 1-D Iterative Closest Points between two members' alert time series.

ICP in one dimension: match every point of ``b`` (shifted by the current offset) to its nearest
point of ``a``, move the offset by the median residual, repeat until it stops moving. The
strength is the fraction of points of both series that have a partner within ``tolerance`` after
the shift, times ``exp(-|offset| / max_offset)`` so that series which only match after a large
shift count less.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Cooccurrence:
    """Result of aligning ``b`` onto ``a``: ``b - offset ≈ a``.

    ``offset`` > 0 means ``b``'s alerts come after ``a``'s; ``matched`` is the fraction of points
    with a partner within the tolerance; ``strength`` in [0, 1]; ``iterations`` the ICP steps.
    """

    offset: float
    matched: float
    strength: float
    iterations: int


def _series(x: np.ndarray | list[float]) -> np.ndarray:
    """``x`` sorted, duplicates (same tick) merged."""
    x = np.asarray(x, dtype=float)
    # The RCA's series are sorted and unique already: checking is cheaper than sorting again
    # (NaN or ±0 fail the check and take the general path).
    if x.ndim == 1 and (len(x) < 2 or bool(np.all(x[1:] > x[:-1]))):
        return x
    return np.unique(x)


def _nearest(ref: np.ndarray, q: np.ndarray) -> np.ndarray:
    """For each value of ``q``, the nearest value of the sorted array ``ref``."""
    i = np.searchsorted(ref, q)
    lo = ref[np.clip(i - 1, 0, len(ref) - 1)]
    hi = ref[np.clip(i, 0, len(ref) - 1)]
    return np.where(np.abs(q - lo) <= np.abs(hi - q), lo, hi)


def _matched(a: np.ndarray, b: np.ndarray, tolerance: float) -> float:
    ma = np.count_nonzero(np.abs(_nearest(b, a) - a) <= tolerance)
    mb = np.count_nonzero(np.abs(_nearest(a, b) - b) <= tolerance)
    return float(ma + mb) / float(len(a) + len(b))


def icp_offset(
    a: np.ndarray | list[float],
    b: np.ndarray | list[float],
    start: float = 0.0,
    max_iter: int = 20,
    estimator: str = "median",
) -> tuple[float, int]:
    """Return ``(offset, iterations)`` minimising the distance of ``b - offset`` to ``a``.

    Parameters
    ----------
    a, b : array-like of float
        Alert times (any order, duplicates allowed); both non-empty.
    start : float
        Initial offset.
    max_iter : int
        Iteration limit.
    estimator : {"median", "mean"}
        How the residuals move the offset (the median ignores outliers).
    """
    a, b = _series(a), _series(b)
    if len(a) == 0 or len(b) == 0:
        raise ValueError("icp_offset needs two non-empty series")
    est = np.median if estimator == "median" else np.mean
    offset = float(start)
    for it in range(1, max_iter + 1):
        shifted = b - offset
        step = float(est(shifted - _nearest(a, shifted)))
        offset += step
        if abs(step) < 1e-9:
            return offset, it
    return offset, max_iter


def cooccurrence(
    a: np.ndarray | list[float],
    b: np.ndarray | list[float],
    tolerance: float = 2.0,
    max_offset: float = 10.0,
    max_iter: int = 20,
) -> Cooccurrence:
    """Return how strongly the alert series ``a`` and ``b`` co-occur (see the module docstring).

    ICP starts twice, at offset 0 and at the onset difference ``b[0] - a[0]``; the better
    alignment wins. Empty series give strength 0.
    """
    a, b = _series(a), _series(b)
    if len(a) == 0 or len(b) == 0:
        return Cooccurrence(0.0, 0.0, 0.0, 0)
    # Each RCA update aligns mostly the same series again: the result is kept per pair of series.
    return _aligned(a.tobytes(), b.tobytes(), float(tolerance), float(max_offset), int(max_iter))


@functools.lru_cache(maxsize=4096)
def _aligned(a_bytes: bytes, b_bytes: bytes, tolerance: float, max_offset: float,
             max_iter: int) -> Cooccurrence:
    """`cooccurrence` of two non-empty `_series`, given as their float64 bytes."""
    a, b = np.frombuffer(a_bytes), np.frombuffer(b_bytes)
    best: Cooccurrence | None = None
    for start in dict.fromkeys((0.0, float(b[0] - a[0]))):
        offset, iters = icp_offset(a, b, start, max_iter)
        matched = _matched(a, b - offset, tolerance)
        strength = matched * float(np.exp(-abs(offset) / max_offset))
        cand = Cooccurrence(offset, matched, strength, iters)
        if best is None or (cand.strength, -abs(cand.offset)) > (best.strength, -abs(best.offset)):
            best = cand
    assert best is not None
    return best
