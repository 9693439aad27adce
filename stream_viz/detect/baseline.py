"""Robust baselines of a member's own past: median / MAD, linear trend, cached per plugin state.

Pure functions over numpy arrays, plus `cached_baseline`, which keeps a baseline in a plugin's
private state and refreshes it only every ``refresh_s`` and never while the member is alerting,
so an ongoing fault does not become the new normal and 1,000 members stay cheap.

The helpers that take a plugin's ``ctx`` read their parameters from ``ctx.settings``; each is
marked with the keys it reads (`stream_viz.detect.api.reads_settings`), and a plugin lists the
ones it calls in ``uses``, so a missing key is a load problem, not a run-time KeyError::

    uses = (rise,)
    settings = {**BASELINE_SETTINGS, "k": 5.0, "confirm": 2}
"""

from __future__ import annotations

from typing import Any

import numpy as np

from stream_viz.detect.api import reads_settings

MAD_TO_SIGMA = 1.4826


# The settings `cached_baseline` reads, with defaults a plugin may override: how long to learn,
# how many samples, how often to refresh, over how many.
BASELINE_SETTINGS: dict[str, float | int] = {
    "warmup_s": 10.0, "min_samples": 5, "refresh_s": 10.0, "window": 120,
}


def robust(values: np.ndarray) -> tuple[float, float, int]:
    """Return ``(median, sigma, n)`` of the finite values; sigma = 1.4826·MAD. NaNs when empty."""
    v = np.asarray(values, dtype=float)
    v = v[np.isfinite(v)]
    if len(v) == 0:
        return float("nan"), float("nan"), 0
    med = float(np.median(v))
    return med, float(MAD_TO_SIGMA * np.median(np.abs(v - med))), len(v)


def slope(times: np.ndarray, values: np.ndarray) -> float:
    """Return the least-squares slope of ``values`` over ``times`` (finite pairs); NaN if < 2."""
    t = np.asarray(times, dtype=float)
    v = np.asarray(values, dtype=float)
    ok = np.isfinite(t) & np.isfinite(v)
    t, v = t[ok], v[ok]
    if len(t) < 2 or np.ptp(t) == 0:
        return float("nan")
    t = t - t.mean()
    return float(np.dot(t, v - v.mean()) / np.dot(t, t))


@reads_settings(*BASELINE_SETTINGS)
def cached_baseline(ctx: Any, member: str, attr: str, *, frozen: bool = False,
                    since: float | None = None) -> tuple[float, float, int] | None:
    """Return ``(median, sigma, n)`` of ``member``'s own past ``attr``, or None while warming up.

    Parameters
    ----------
    ctx : PluginContext
        The call's context: its ``state`` holds the cache, its ``settings`` give ``warmup_s``
        and ``min_samples`` (no baseline before the member has been seen this long with this
        many finite samples), ``refresh_s`` (recompute at most this often) and ``window`` (use
        the last this many samples).
    member, attr : str
        The member and θ attribute.
    frozen : bool
        Keep the cached value (the member is alerting: do not learn the fault).
    since : float, optional
        Learn only from samples at or after this time (the member's normal changed then: a
        reconfiguration); warming up again until ``warmup_s`` after it.
    """
    cache = ctx.state.setdefault("_baselines", {})
    key = (member, attr)
    hit = cache.get(key)  # (next refresh time, baseline or None)
    if hit is not None and (ctx.t < hit[0] or (frozen and hit[1] is not None)):
        return hit[1]
    s = ctx.settings
    warmup_s, min_samples, refresh_s, window = s["warmup_s"], s["min_samples"], s["refresh_s"], s["window"]
    times, values = ctx.past(member, attr, last=window)
    if since is not None:
        keep = times >= since
        times, values = times[keep], values[keep]
    if len(times) == 0 or ctx.t - times[0] < warmup_s:
        # Warming up: look again when the warm-up can be over, not on every call.
        ready = times[0] + warmup_s if len(times) else ctx.t
        cache[key] = (min(ready, ctx.t + refresh_s), hit[1] if hit else None)
        return cache[key][1]
    med, sigma, n = robust(values[-window:])
    if n < min_samples:
        cache[key] = (ctx.t + min(refresh_s, 1.0), hit[1] if hit else None)
        return cache[key][1]
    cache[key] = (ctx.t + refresh_s, (med, sigma, n))
    return med, sigma, n


def forget_baseline(ctx: Any, member: str, attr: str) -> None:
    """Drop the cached baseline of ``member``'s ``attr`` (`cached_baseline`): its normal changed
    and is learnt again from ``since``, not read from the cache until its next refresh."""
    ctx.state.get("_baselines", {}).pop((member, attr), None)


def streak(state: dict[str, Any], key: Any, condition: bool, fresh: bool = True) -> int:
    """Count consecutive calls with ``condition`` true for ``key`` (0 once it is false).

    A call that is not ``fresh`` (no new data since the last one) returns the count unchanged.
    """
    counts = state.setdefault("_streaks", {})
    if not fresh:
        return counts.get(key, 0)
    if condition:
        counts[key] = counts.get(key, 0) + 1
        return counts[key]
    counts.pop(key, None)
    return 0


def held(state: dict[str, Any], key: Any, condition: bool, t: float, fresh: bool = True) -> float:
    """Return how long (s) ``condition`` has held for ``key`` at time ``t`` (0 once it is false).

    A call that is not ``fresh`` neither starts nor breaks the run, as in `streak`.
    """
    since = state.setdefault("_held", {})
    if fresh and condition:
        since.setdefault(key, t)
    elif fresh:
        since.pop(key, None)
    return t - since[key] if key in since else 0.0


def held_since(state: dict[str, Any], key: Any) -> float | None:
    """Return when the run `held` follows for ``key`` began (None: not holding). Read before
    the `held` call that may end it, this is the start of a run that just ended."""
    return state.get("_held", {}).get(key)


def forget_run(state: dict[str, Any], key: Any) -> None:
    """End the `streak` and the `held` run of ``key`` (its normal changed: counted anew)."""
    for table in ("_streaks", "_held"):
        state.get(table, {}).pop(key, None)


@reads_settings("k", *BASELINE_SETTINGS)
def excess(ctx: Any, member: str, attr: str, floor: float, alerting: set,
           since: float | None = None) -> tuple[float, float, bool] | None:
    """Return ``(value, median, exceeded)`` of ``member``'s ``attr`` against its own baseline.

    ``exceeded`` means ``value - median ≥ max(k·σ, floor)`` (``k`` from ``ctx.settings``). The
    baseline (`cached_baseline`, from ``ctx.settings``' ``warmup_s``, ``min_samples``,
    ``refresh_s``, ``window``) is frozen while ``(member, attr)`` is in ``alerting`` and learnt
    only from ``since`` on when given (`cached_baseline`). None while warming up or when the value
    is missing (NaN).
    """
    value = ctx.value(member, attr)
    if value != value:  # NaN: not measured this sample
        return None
    base = cached_baseline(ctx, member, attr, frozen=(member, attr) in alerting, since=since)
    if base is None:
        return None
    med, sigma, _ = base
    return value, med, exceeds(value, med, sigma, ctx.settings["k"], floor)


def exceeds(value: float, median: float, sigma: float, k: float, floor: float) -> bool:
    """Return True if ``value`` is risen above a baseline: ``value - median ≥ max(k·σ, floor)``."""
    return value - median >= max(k * sigma, floor)


@reads_settings("confirm")
def confirm(ctx: Any, member: str, attr: str, seen: tuple[float, float, bool] | None, alerting: set,
            fresh: bool = True) -> tuple[float, float] | None:
    """Return ``(value, median)`` while `excess` ``seen`` is exceeded and has been for ``confirm``
    fresh samples in a row, keeping ``alerting`` up to date; a sample that is not ``fresh`` (the
    same data as the one before, e.g. a slow topic's window holding the same message) neither
    counts nor breaks the streak, and is risen only if its own value is. None otherwise."""
    if seen is None:
        return None
    value, med, exceeded = seen
    key = (member, attr)
    # A value that no longer exceeds is no rise, even where it does not break the streak (a topic
    # that stopped: its window's value moves as old messages leave it, without a new one).
    if streak(ctx.state, key, exceeded, fresh) >= ctx.settings["confirm"] and exceeded:
        alerting.add(key)
        return value, med
    alerting.discard(key)
    return None


@reads_settings("k", "confirm", *BASELINE_SETTINGS)
def rise(ctx: Any, member: str, attr: str, floor: float, alerting: set,
         fresh: bool = True) -> tuple[float, float] | None:
    """Return ``(value, median)`` while ``member``'s ``attr`` stays risen above its own baseline:
    `excess` for ``confirm`` fresh samples in a row (`confirm`)."""
    return confirm(ctx, member, attr, excess(ctx, member, attr, floor, alerting), alerting, fresh)


def excursions(times: np.ndarray, values: np.ndarray, level: float,
               since: float = -np.inf) -> tuple[float, float]:
    """Return how long the current excursion has lasted and the longest earlier one that ended.

    An excursion is a run of samples at or above ``level`` (a CPU burst; a rate's low spell, as
    ``-rate`` above ``-level``); one sample below it between two above (a dip) does not end it,
    and unread (NaN) samples are left out.

    Parameters
    ----------
    times, values : (n,) array
        A series, the last sample being the present.
    level : float
        The value an excursion reaches.
    since : float, optional
        Earlier excursions that began before this (a start-up) are not counted, and the current
        one is counted from it.

    Returns
    -------
    lasted : float
        From the first sample of the excursion the present is in (or ``since``) to the present; 0
        when not in one.
    longest : float
        The longest earlier excursion, from its first sample to the first sample after it; 0 if none.
    """
    ok = np.isfinite(values)
    t, high = times[ok], values[ok] >= level
    if len(t) == 0 or not high[-1]:
        return 0.0, 0.0
    dip = ~high & np.r_[False, high[:-1]] & np.r_[high[1:], False]  # one low sample between highs
    high = high | dip
    edges = np.flatnonzero(np.diff(np.r_[False, high, False].astype(np.int8)))
    starts, ends = edges[::2], edges[1::2]  # ends: the index after each run
    lasted = float(t[-1] - max(t[starts[-1]], since))
    done = [float(t[e] - t[b]) for b, e in zip(starts[:-1], ends[:-1], strict=True) if t[b] >= since]
    return lasted, max(done, default=0.0)
