"""The process-anomaly rule: a process using much more CPU or memory than it used to, or leaking.

One rule, one settings table (`SETTINGS`, the defaults of ``[plugins.process_resources]``), two
callers; tuning the table tunes both.

The rule, on a process's θ against its own past:

* **rise**: ``cpu_percent`` or ``rss_mb`` − median ≥ max(``k``·σ, floor) (σ = 1.4826·MAD; the
  absolute floors ``cpu_min_rise`` percentage points and ``rss_min_rise_mb`` keep idle noise
  quiet), `stream_viz.detect.baseline.exceeds`;
* **growth**: the least-squares slope of RSS over a recent span of the last ``trend_s`` is at
  least ``growth_mb_per_s``, RSS having grown at least ``growth_min_mb`` in it.

The callers:

* the ``process_resources`` plugin (`symptoms`): confirmed alerts. The baseline is learnt over
  ``warmup_s`` seconds and ``min_samples`` samples, cached and frozen while the process alerts;
  a rise must hold ``confirm`` samples in a row; growth is checked over the last
  ``trend_s``/12, /6, /2 and ``trend_s`` (a fast leak shows in the short span, a slow one in the
  long) and must be steady: at least ``growth_steady`` of the steps rising, over at least
  ``growth_min_samples`` samples, so one big allocation is no leak.
* the evidence (`anomalous_processes`; with their nodes, `process_anomalies`): every sample, for
  the watchlist (the processes and their nodes) and the RCA's ranking (the processes; a hint,
  not an alert). It holds no state (it reads the history) and does not confirm, so it
  speaks a sample or more before the plugin. From the same keys (`evidence_rule`): the same
  ``k``, floors, ``growth_mb_per_s``, ``growth_min_mb`` and ``window``; the baseline is the
  median of the window's earlier samples; growth is checked over one span, the trend window's
  last half (``trend_s``/2), with no steadiness test, so it asks one sample more
  (``growth_min_samples`` + 1, read or not); the warm-up ``warmup_s`` is counted in samples, one
  a second (the monitor's default period), as the history holds samples, not a clock.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any

import networkx as nx
import numpy as np

from stream_viz.detect.api import PluginContext, reads_settings
from stream_viz.detect.baseline import BASELINE_SETTINGS, exceeds, rise, robust, slope
from stream_viz.model.history import History
from stream_viz.model.queries import nodes_of_process
from stream_viz.model.theta import SCHEMAS

SETTINGS: dict[str, Any] = {
    **BASELINE_SETTINGS,
    "min_samples": 8,
    "k": 5.0,
    "confirm": 2,
    "cpu_min_rise": 25.0,
    "rss_min_rise_mb": 100.0,
    "growth_mb_per_s": 1.0,
    "growth_min_mb": 20.0,
    "trend_s": 60.0,
    "growth_steady": 0.7,
    "growth_min_samples": 4,
}

# The attributes a rise is looked for in: (θ attribute, the setting of its floor, symptom, unit).
RESOURCES = (("cpu_percent", "cpu_min_rise", "cpu", "%"), ("rss_mb", "rss_min_rise_mb", "memory", " MB"))
_CPU = SCHEMAS["process"].index("cpu_percent")
_RSS = SCHEMAS["process"].index("rss_mb")


# --------------------------------------------------------------------------- the plugin's side

Symptom = tuple[str, str, dict[str, float]]


@reads_settings(*SETTINGS)
def symptoms(ctx: PluginContext, procs: Iterable[str]) -> Iterator[tuple[str, list[Symptom]]]:
    """Yield ``(process, its symptoms)`` for each of ``procs`` with confirmed symptoms at ``ctx.t``.

    Parameters
    ----------
    ctx : PluginContext
        The plugin's context: ``settings`` as `SETTINGS`; ``state`` keeps the baselines, streaks
        and RSS windows, and forgets the windows of processes that left the graph.
    procs : iterable of str
        The processes to check, in the order to report them.

    Yields
    ------
    proc : str
        A process.
    symptoms : list of (symptom, text, data)
        ``cpu``, ``memory`` (data ``value``, ``baseline``) and ``memory_growth`` (``mb_per_s``).
    """
    alerting = ctx.state.setdefault("alerting", set())  # (process, attribute): baseline frozen
    windows = ctx.state.setdefault("rss", {})
    for gone in ctx.diff.removed_members:  # bound the state when processes come and go
        windows.pop(gone, None)
    for proc in procs:
        found = _symptoms(ctx, proc, alerting)
        if found:
            yield proc, found


def _symptoms(ctx: PluginContext, proc: str, alerting: set) -> list[Symptom]:
    found = []
    for attr, floor, what, unit in RESOURCES:
        risen = rise(ctx, proc, attr, ctx.settings[floor], alerting)
        if risen is not None:
            value, med = risen
            found.append((what, f"{what} {value:.0f}{unit}, normally {med:.0f}{unit}",
                          {"value": value, "baseline": med}))
    rate = _leak(ctx, proc)
    if rate is not None:
        found.append(("memory_growth", f"memory growing {rate:.1f} MB/s", {"mb_per_s": rate}))
    return found


def _leak(ctx: PluginContext, proc: str) -> float | None:
    """Return the RSS growth rate (MB/s) of ``proc`` when its memory grows steadily, else None."""
    s = ctx.settings
    first, q = _rss_window(ctx, proc)
    q.append((ctx.t, ctx.value(proc, "rss_mb")))
    while q and q[0][0] < ctx.t - s["trend_s"]:
        q.popleft()
    if ctx.t - first < s["warmup_s"] or len(q) < s["growth_min_samples"]:
        return None
    rss = [v for _, v in q if v == v]
    if not rss or rss[-1] - min(rss) < s["growth_min_mb"]:
        return None  # the common, healthy case: no numpy needed
    return steady_growth(np.array([t for t, _ in q]), np.array([v for _, v in q]), ctx.t, s)


def _rss_window(ctx: PluginContext, proc: str) -> tuple[float, deque]:
    """``(first seen, deque of (t, rss))`` of ``proc``: an own bounded window per process, cheaper
    than reading the whole history each sample."""
    windows = ctx.state["rss"]
    if proc not in windows:
        times, values = ctx.past(proc, "rss_mb")
        windows[proc] = (times[0] if len(times) else ctx.t,
                         deque(zip(times.tolist(), values.tolist(), strict=True)))
    return windows[proc]


def steady_growth(times: np.ndarray, rss: np.ndarray, now: float,
                  settings: Mapping[str, Any]) -> float | None:
    """Return the RSS growth rate (MB/s) when memory grows steadily in one of the spans, else None.

    Checked over the last ``trend_s``/12, /6, /2 and ``trend_s`` of ``times`` up to ``now``: the
    slope is at least ``growth_mb_per_s``, RSS grew at least ``growth_min_mb`` (the last value
    above the span's minimum) and rose in at least ``growth_steady`` of the steps, over at least
    ``growth_min_samples`` finite samples.
    """
    s = settings
    for span in (s["trend_s"] / 12, s["trend_s"] / 6, s["trend_s"] / 2, s["trend_s"]):
        recent = times >= now - span
        t, v = times[recent], rss[recent]
        ok = np.isfinite(v)
        t, v = t[ok], v[ok]
        if len(v) < s["growth_min_samples"]:
            continue
        rate = slope(t, v)
        steady = np.mean(np.diff(v) > 0.01)
        if (np.isfinite(rate) and rate >= s["growth_mb_per_s"] and v[-1] - v.min() >= s["growth_min_mb"]
                and steady >= s["growth_steady"]):
            return rate
    return None


# --------------------------------------------------------------------------- the evidence

@dataclass(frozen=True)
class EvidenceRule:
    """The evidence's parameters, derived from the settings by `evidence_rule`.

    Attributes
    ----------
    k, cpu_min_rise, rss_min_rise_mb : float
        The rise test.
    growth_mb_per_s, growth_min_mb : float
        The growth test.
    trend_s : float
        Growth is checked over the last this many seconds.
    growth_samples : int
        ... in at least this many samples (read or not).
    warmup : int
        Earlier samples needed before judging.
    window : int
        Samples compared (the present and its past).
    """

    k: float
    cpu_min_rise: float
    rss_min_rise_mb: float
    growth_mb_per_s: float
    growth_min_mb: float
    trend_s: float
    growth_samples: int
    warmup: int
    window: int


def evidence_rule(settings: Mapping[str, Any] | None = None) -> EvidenceRule:
    """Return the evidence's parameters from the ``process_resources`` settings (`SETTINGS` for
    what ``settings`` does not give); see the module docstring for the derivation."""
    s = {**SETTINGS, **(settings or {})}
    return EvidenceRule(
        k=s["k"], cpu_min_rise=s["cpu_min_rise"], rss_min_rise_mb=s["rss_min_rise_mb"],
        growth_mb_per_s=s["growth_mb_per_s"], growth_min_mb=s["growth_min_mb"],
        trend_s=s["trend_s"] / 2, growth_samples=s["growth_min_samples"] + 1,
        warmup=round(s["warmup_s"]), window=s["window"],
    )


DEFAULT_EVIDENCE = evidence_rule()


def process_anomaly(times: np.ndarray, values: np.ndarray, now: float,
                    rule: EvidenceRule = DEFAULT_EVIDENCE) -> list[str]:
    """Return what is anomalous in a process's last sample vs its own earlier samples.

    Parameters
    ----------
    times : (n,) array
        Sample times, the last one being the present.
    values : (n, dim) array
        θ of the process (schema ``SCHEMAS["process"]``).
    now : float
        The present (samples after it are ignored).
    rule : EvidenceRule
        The parameters (`evidence_rule`).

    Returns
    -------
    list of str
        Subset of ``["cpu", "memory", "memory_growth"]``.
    """
    if len(times) and times[-1] > now:  # samples after `now` (a replay): left out
        keep = times <= now
        times, values = times[keep], values[keep]
    if len(times) < rule.warmup + 1:
        return []
    past, cur = values[:-1], values[-1]
    out = []
    for col, floor, what in ((_CPU, rule.cpu_min_rise, "cpu"), (_RSS, rule.rss_min_rise_mb, "memory")):
        # The median is at least the minimum: a value not `floor` above the minimum cannot be
        # `floor` above the median, so the healthy case needs no median (called every sample).
        # fmin/fmax skip NaN (an unread sample) as nanmin/nanmax do, in one ufunc call each.
        if not np.isfinite(cur[col]) or not cur[col] - np.fmin.reduce(past[:, col], initial=np.inf) >= floor:
            continue
        med, sigma, _ = robust(past[:, col])
        if np.isfinite(med) and exceeds(cur[col], med, sigma, rule.k, floor):
            out.append(what)
    recent = times >= now - rule.trend_s
    span = values[recent, _RSS]
    grew = np.fmax.reduce(span, initial=-np.inf) - np.fmin.reduce(span, initial=np.inf)
    if recent.sum() >= rule.growth_samples and grew >= rule.growth_min_mb:
        s = slope(times[recent], span)
        if np.isfinite(s) and s >= rule.growth_mb_per_s:
            out.append("memory_growth")
    return out


def anomalous_processes(G: nx.MultiDiGraph, history: History,
                        settings: Mapping[str, Any] | None = None) -> set[str]:
    """Return the processes whose metrics are anomalous vs their own past.

    Parameters
    ----------
    G : MultiDiGraph
        The model.
    history : History
        θ history; the last sample of each process is the present.
    settings : mapping, optional
        The ``process_resources`` settings (`SETTINGS` by default), read by `evidence_rule`;
        ``window`` bounds the samples compared per process, whatever the history length.
    """
    rule = evidence_rule(settings)
    out: set[str] = set()
    for m, kind in G.nodes(data="kind"):
        if kind != "process" or m not in history:
            continue
        times, values = history.series(m, rule.window)
        if process_anomaly(times, values, times[-1], rule):
            out.add(m)
    return out


def with_nodes(G: nx.MultiDiGraph, processes: set[str]) -> set[str]:
    """Return ``processes`` and the nodes they host (what process monitoring adds to the watchlist)."""
    return processes.union(*(nodes_of_process(G, p) for p in processes))


def process_anomalies(G: nx.MultiDiGraph, history: History,
                      settings: Mapping[str, Any] | None = None) -> set[str]:
    """Return `anomalous_processes` and the nodes they host."""
    return with_nodes(G, anomalous_processes(G, history, settings))
