"""Symptom co-occurrence (1-D ICP) and time-lag analysis."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from stream_viz.rca.cooccurrence import cooccurrence, icp_offset
from stream_viz.rca.timelag import LagDistribution


def test_icp_recovers_a_known_offset():
    rng = np.random.default_rng(1)
    a = np.sort(rng.uniform(0, 300, 30))
    b = a + 7.5 + rng.normal(0, 0.1, len(a))
    offset, iters = icp_offset(a, b, start=0.0)
    assert offset == pytest.approx(7.5, abs=0.15) and iters >= 1
    co = cooccurrence(a, b, tolerance=1.0, max_offset=10.0)
    assert co.offset == pytest.approx(7.5, abs=0.15)
    assert co.matched == 1.0
    assert co.strength == pytest.approx(np.exp(-co.offset / 10.0))


def test_icp_with_outliers_median_vs_mean():
    a = np.arange(0.0, 100.0, 10.0)
    b = np.concatenate([a + 2.0, [1000.0]])  # one alert far away
    assert icp_offset(a, b, estimator="median")[0] == pytest.approx(2.0)
    assert icp_offset(a, b, estimator="mean")[0] != pytest.approx(2.0)


def test_identical_series_match_fully():
    a = [1.0, 2.0, 5.0, 5.0, 9.0]
    co = cooccurrence(a, a)
    assert (co.offset, co.matched, co.strength) == (0.0, 1.0, 1.0)


def test_unrelated_series_score_low():
    rng = np.random.default_rng(7)
    scores = []
    for _ in range(20):
        a = rng.uniform(0, 1000, 15)
        b = rng.uniform(0, 1000, 15)
        scores.append(cooccurrence(a, b, tolerance=1.0, max_offset=10.0).strength)
    related = cooccurrence(a, a + 1.0, tolerance=1.0, max_offset=10.0).strength
    assert max(scores) < 0.4 and np.mean(scores) < 0.2
    assert related > 0.85


def test_empty_series_have_no_cooccurrence():
    assert cooccurrence([], [1.0]).strength == 0.0
    with pytest.raises(ValueError):
        icp_offset([], [1.0])


def test_lag_distribution_matches_brute_force():
    rng = np.random.default_rng(3)
    onsets = {f"m{i}": float(x) for i, x in enumerate(rng.uniform(0, 50, 12).round(1))}
    dist = LagDistribution(onsets)
    lags = [abs(x - y) for x, y in itertools.combinations(onsets.values(), 2)]
    for q in (0.0, 0.5, 3.0, 10.0, 25.0, 60.0):
        want = sum(1 for lag in lags if lag >= q) / len(lags)
        assert dist.fraction_at_least(q) == pytest.approx(want)
        assert dist.fraction_at_least(-q) == pytest.approx(want)


def test_lag_strength_and_direction():
    # onsets 0, 1, 2, 30: lags 1,2,30,1,29,28
    dist = LagDistribution({"a": 0.0, "b": 1.0, "c": 2.0, "z": 30.0}, tolerance=0.5)
    close = dist.lag(0.0, 1.0)
    assert (close.lag, close.direction) == (1.0, 1)
    assert close.strength == pytest.approx(1.0) and close.causal == close.strength
    far = dist.lag(0.0, 30.0)
    assert far.strength == pytest.approx(1 / 6)  # only the pair (a, z) is that far apart
    backwards = dist.lag(1.0, 0.0)  # the "cause" came after its effect
    assert backwards.direction == -1 and backwards.causal < backwards.strength
    same = dist.lag(5.0, 5.2)
    assert same.direction == 0 and same.causal == same.strength


def test_single_member_has_no_pairs():
    assert LagDistribution({"a": 1.0}).fraction_at_least(3.0) == 1.0
