"""The process-anomaly rule: a process using much more CPU or memory than it used to, or leaking.

One rule, one settings table (`SETTINGS`, the defaults of ``[plugins.process_resources]``), two
callers; tuning the table tunes both.

The rule, on a process's θ against its own past:

* **rise**: ``cpu_percent`` or ``rss_mb`` − median ≥ max(``k``·σ, floor) (σ = 1.4826·MAD; the
  absolute floors ``cpu_min_rise`` percentage points and ``rss_min_rise_mb`` keep idle noise
  quiet), `stream_viz.detect.baseline.exceeds`; memory only while it rose lately (at least half
  its floor above the lowest RSS of the last ``trend_s``/2): a process whose memory rose to a new
  level and stays there (a map loaded, a buffer grown to its size) has a new normal;
* **growth**: the least-squares slope of RSS over a recent span of the last ``trend_s`` is at
  least ``growth_mb_per_s``, RSS having grown at least ``growth_min_mb`` in it — unless the
  process grew from when it was first seen (half ``growth_min_mb`` in its first ``warmup_s``)
  and was seen for less than ``startup_s``: that is its start-up (a costmap or a model
  allocated), and a process still growing after ``startup_s`` is judged as any other.

The callers:

* the ``process_resources`` plugin (`symptoms`): confirmed alerts. The baseline is learnt over
  ``warmup_s`` seconds and ``min_samples`` samples, cached and frozen while the process alerts;
  a rise must hold ``confirm`` samples in a row, and a CPU rise must have held ``cpu_hold_s`` and
  outlast ``burst_margin`` × the longest of the process's earlier CPU rises in its history that
  ended by themselves (its bursts: the first is a rise, those like it are its rhythm, `excursions`;
  and the longest a process with the same nodes showed in the healthy run this one started from,
  ``--healthy``); growth is checked over the last
  ``trend_s``/12, /6, /2 and ``trend_s`` (a fast leak shows in the short span, a slow one in the
  long) and must be steady: at least ``growth_steady`` of the steps rising, over at least
  ``growth_min_samples`` samples, so one big allocation is no leak.
* the evidence (`anomalous_processes`; with their nodes, `process_anomalies`): every sample, for
  the watchlist (the processes and their nodes) and the RCA's ranking (the processes; a hint,
  not an alert). It holds no state (it reads the history) and does not confirm, so it
  speaks a sample or more before the plugin. From the same keys (`evidence_rule`): the same
  ``k``, floors, ``growth_mb_per_s``, ``growth_min_mb``, ``burst_margin`` and ``window`` (a CPU
  rise within the process's bursts, `excursions`, is no evidence either); the baseline is the
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
from stream_viz.detect.baseline import BASELINE_SETTINGS, confirm, exceeds, excess, excursions, robust, slope
from stream_viz.detect.reconfigure import RECONFIGURE_SETTINGS, learnt_since, param_changes, reconfigured
from stream_viz.model.history import History
from stream_viz.model.queries import nodes_of_process
from stream_viz.model.theta import SCHEMAS

SETTINGS: dict[str, Any] = {
    **BASELINE_SETTINGS,
    **RECONFIGURE_SETTINGS,
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
    "startup_s": 120.0,
    "cpu_hold_s": 3.0,
    "reconfigure_cpu_s": 4.0,
    "burst_margin": 2.0,
}

# The attributes a rise is looked for in: (θ attribute, the setting of its floor, symptom, unit).
RESOURCES = (("cpu_percent", "cpu_min_rise", "cpu", "%"), ("rss_mb", "rss_min_rise_mb", "memory", " MB"))
_CPU = SCHEMAS["process"].index("cpu_percent")
EXECUTOR = "executor_cpu_percent"
MAIN = "main_cpu_percent"
_MAIN = SCHEMAS["process"].index(MAIN)
_DISPATCHING = SCHEMAS["process"].index("dispatching")
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
    rising = ctx.state.setdefault("cpu_rising", {})
    for gone in ctx.diff.removed_members:  # bound the state when processes come and go
        windows.pop(gone, None)
        rising.pop(gone, None)  # a process that ended in a rise: no burst of its rhythm
    changes = param_changes(ctx)
    for proc in procs:
        found = _symptoms(ctx, proc, alerting, bool(changes))
        if found:
            yield proc, found


def _symptoms(ctx: PluginContext, proc: str, alerting: set, changes: bool) -> list[Symptom]:
    found = []
    rate = _leak(ctx, proc)  # first: it keeps the RSS window the memory rise reads
    nodes = ctx.nodes_of(proc, by_pid=True) if changes else ()
    for attr, floor, what, unit in RESOURCES:
        seen = excess(ctx, proc, attr, ctx.settings[floor], alerting, since=learnt_since(ctx, proc, attr))
        # a parameter takes effect at the node's next callback: the CPU it costs shows within two
        # samples, and on the executor's thread; memory may grow for a while (a finer map filled in)
        within = ctx.settings["reconfigure_cpu_s"] if what == "cpu" else None
        if what == "cpu" and _beside_executor(ctx, proc, seen):
            nodes = ()
        if reconfigured(ctx, proc, attr, nodes, seen, within):
            seen = None  # a parameter change brought it: learnt anew from the change
        if what == "cpu" and seen is not None and seen[2] and _dispatching(ctx, proc, seen):
            seen = None  # its executor's dispatcher spinning while callbacks wait: no work of a node's
        if what == "cpu":
            seen = _beyond_bursts(ctx, proc, seen)
        risen = confirm(ctx, proc, attr, seen, alerting)
        if risen is not None and (what != "memory" or _rose_lately(ctx, proc, risen[0])):
            value, med = risen
            found.append((what, f"{what} {value:.0f}{unit}, normally {med:.0f}{unit}",
                          {"value": value, "baseline": med}))
    if rate is not None:
        found.append(("memory_growth", f"memory growing {rate:.1f} MB/s", {"mb_per_s": rate}))
    return found


def _beside_executor(ctx: PluginContext, proc: str, seen: tuple[float, float, bool] | None) -> bool:
    """True when a CPU rise of the process is known to be beside its executor: the one thread
    that runs its callbacks (``executor_cpu_percent``, read for a single-threaded executor) rose
    by less than half as much, over the same window. A parameter change works through the
    node's callbacks, so such a rise (a runaway worker thread) is not the change's."""
    if seen is None or not seen[2]:
        return False
    now = ctx.value(proc, EXECUTOR)
    _, before = ctx.past(proc, EXECUTOR, last=int(ctx.settings["window"]))
    before = before[np.isfinite(before)]
    if now != now or len(before) == 0:  # not read (a multi-threaded executor): not known
        return False
    return now - float(np.median(before)) < 0.5 * (seen[0] - seen[1])


def _dispatching(ctx: PluginContext, proc: str, seen: tuple[float, float, bool]) -> bool:
    """True when the process's CPU rise ``seen`` is its executor's dispatching main thread's
    (`dispatcher_rise`)."""
    return dispatcher_rise(seen[0], seen[1], ctx.value(proc, MAIN), ctx.value(proc, "dispatching"))


def dispatcher_rise(cpu: float, baseline: float, main: float, dispatching: float) -> bool:
    """True when a process's CPU rise from ``baseline`` to ``cpu`` is carried by the main thread
    that dispatches its multi-threaded executor (``dispatching`` 1, `collect.processes`): that
    thread's CPU ``main`` is at least half the rise above the process's baseline (its own share
    of the baseline being no more than all of it, it carries half the rise or more).

    rclpy's MultiThreadedExecutor spins its dispatch loop while the callbacks it handed to its
    workers wait for one (ros2/rclpy#1452): a core for seconds to a minute, now and then, on a
    healthy robot; so does a flood of small callbacks. No node's callback works then; a node's
    heavy callback or a runaway thread rises on a worker or a thread of its own. Unknown (NaN: not
    read) is False.
    """
    return bool(_carried_by_dispatcher(cpu, baseline, main, dispatching))


def undispatched(cpu: np.ndarray, main: np.ndarray, dispatching: np.ndarray, baseline: float) -> np.ndarray:
    """Return ``cpu`` with each sample whose rise above ``baseline`` the dispatching main thread
    carries (`dispatcher_rise`, sample by sample) set to ``baseline``: an executor's dispatcher
    spinning is no burst of the process's own, which would hide a hog for twice as long."""
    return np.where(_carried_by_dispatcher(cpu, baseline, main, dispatching), baseline, cpu)


def _carried_by_dispatcher(cpu, baseline, main, dispatching):  # scalars or arrays; NaN is False
    rise = np.asarray(cpu) - baseline
    return (np.asarray(dispatching) == 1.0) & (np.asarray(main) - baseline >= 0.5 * rise)


def _beyond_bursts(ctx: PluginContext, proc: str,
                   seen: tuple[float, float, bool] | None) -> tuple[float, float, bool] | None:
    """`excess` of the process's CPU, risen only once the rise has held ``cpu_hold_s`` and
    outlasts ``burst_margin`` × the longest of the rises it showed and left by itself in its
    history (`excursions`: a planner's plans, a map re-inflated, an executor busy now and then),
    or in the healthy run this one started from (`_primed_burst`), so bursts it has shown are
    its rhythm; a hog lasts longer. ``cpu_hold_s`` covers the first burst, of which nothing is
    known yet: a few seconds of work at a goal or a map update is how robots run. Each rise that
    ends is kept for a later run (`_keep_burst`)."""
    rising = ctx.state["cpu_rising"]
    if seen is None or not seen[2]:
        began = rising.pop(proc, None)
        if began is not None:
            _keep_burst(ctx, proc, ctx.t - began)
        return seen
    rising.setdefault(proc, ctx.t)
    times, cpu = ctx.past(proc, "cpu_percent")
    cpu = undispatched(cpu, ctx.past(proc, MAIN)[1], ctx.past(proc, "dispatching")[1], seen[1])
    s = ctx.settings
    level = seen[1] + s["cpu_min_rise"]
    since = times[0] + s["warmup_s"] if len(times) else ctx.t
    lasted, longest = excursions(np.append(times, ctx.t), np.append(cpu, seen[0]), level, since)
    longest = max(longest, _primed_burst(ctx, proc))
    if lasted < s["cpu_hold_s"] or lasted <= s["burst_margin"] * longest:  # longest 0: none known
        return seen[0], seen[1], False
    return seen


def rise_began(ctx: PluginContext, proc: str) -> float | None:
    """When ``proc``'s ongoing CPU rise was first seen (`symptoms` keeps it), or None."""
    return ctx.state.get("cpu_rising", {}).get(proc)


def burst_key(nodes: Iterable[str]) -> str:
    """A process's name across runs, for its carried bursts: the nodes it hosts (its PID is not
    the same in the next run); empty for a process with none (not carried)."""
    return " ".join(sorted(nodes))


def _primed_burst(ctx: PluginContext, proc: str) -> float:
    """The longest CPU burst a process with ``proc``'s nodes showed in the healthy run this one
    started from (``ctx.primed["bursts"]``; 0 if none)."""
    return _carried(ctx.graph, proc, ctx.primed.get("bursts", {}))


def _keep_burst(ctx: PluginContext, proc: str, seconds: float) -> None:
    """Keep a CPU rise of ``seconds`` that ended by itself as the process's longest burst for a
    later run (``ctx.learned``), by `burst_key`; a process with no node is not carried."""
    key = burst_key(ctx.nodes_of(proc, by_pid=True))
    if key:
        known = ctx.learned.setdefault("bursts", {})
        known[key] = max(seconds, known.get(key, 0.0))


def publishers_busy(ctx: PluginContext, topic: str, dispatched: bool = False) -> bool:
    """True when the process of every publisher of ``topic`` is busy beyond its own baseline now
    (CPU risen as ``process_resources`` judges a rise, with its default ``k`` and floor, bursts
    or not): a node whose executor is held by its own work (a plan computed in a callback, an
    executor spinning) pauses its topics and delays its data. The CPU is that process's symptom
    (``process_resources``, which learns its bursts), not one more per topic. ``dispatched``:
    busy in the main thread that dispatches its multi-threaded executor (`dispatcher_rise`), so
    callbacks wait for a worker while it spins and the topic's messages come late and unevenly
    with no node at fault (and no CPU symptom either)."""
    pubs = ctx.publishers(topic)
    procs = {ctx.process_of(p) for p in pubs}
    if not pubs or None in procs:
        return False
    return all(_cpu_risen(ctx, proc, dispatched) for proc in procs)


def _cpu_risen(ctx: PluginContext, proc: str, dispatched: bool = False) -> bool:
    """True when ``proc``'s CPU is risen above its window's median (and, ``dispatched``, the rise
    is its dispatcher's)."""
    now = ctx.value(proc, "cpu_percent")
    _, past = ctx.past(proc, "cpu_percent", last=SETTINGS["window"])
    past = past[np.isfinite(past)]
    if now != now or len(past) < SETTINGS["min_samples"]:
        return False
    med, sigma, _ = robust(past)
    if not exceeds(now, med, sigma, SETTINGS["k"], SETTINGS["cpu_min_rise"]):
        return False
    return not dispatched or dispatcher_rise(now, med, ctx.value(proc, MAIN), ctx.value(proc, "dispatching"))


def _rose_lately(ctx: PluginContext, proc: str, value: float) -> bool:
    """True when ``value`` is at least half the memory floor above the process's lowest RSS of the
    last ``trend_s``/2: memory that rose to a new level and stays there (a map loaded, a buffer
    grown to its size) is the process's new normal, not a symptom for ever."""
    w, since = ctx.state["rss"][proc], ctx.t - ctx.settings["trend_s"] / 2
    low = min((v for t, v in w.q if t >= since and v == v), default=value)
    return value - low >= ctx.settings["rss_min_rise_mb"] / 2


def _leak(ctx: PluginContext, proc: str) -> float | None:
    """Return the RSS growth rate (MB/s) of ``proc`` when its memory grows steadily, else None."""
    s = ctx.settings
    w = _rss_window(ctx, proc)
    now = ctx.value(proc, "rss_mb")
    w.add(ctx.t, now, s["warmup_s"])
    q = w.q
    while q and q[0][0] < ctx.t - s["trend_s"]:
        q.popleft()
    if ctx.t - w.first < s["warmup_s"] or len(q) < s["growth_min_samples"]:
        return None
    if w.high - w.low >= s["growth_min_mb"] / 2 and ctx.t - w.first < s["startup_s"]:
        return None  # growing since it was first seen: its start-up, judged after startup_s
    rss = [v for _, v in q if v == v]
    if not rss or rss[-1] - min(rss) < s["growth_min_mb"]:
        return None  # the common, healthy case: no numpy needed
    return steady_growth(np.array([t for t, _ in q]), np.array([v for _, v in q]), ctx.t, s)


@dataclass
class _RssWindow:
    """A process's recent RSS (an own bounded window, cheaper than reading the history each
    sample) and its range over its first ``warmup_s`` seen (``low``, ``high``)."""

    first: float
    q: deque
    low: float = np.inf
    high: float = -np.inf

    def add(self, t: float, rss: float, warmup_s: float) -> None:
        self.q.append((t, rss))
        if t - self.first <= warmup_s and rss == rss:
            self.low, self.high = min(self.low, rss), max(self.high, rss)


def _rss_window(ctx: PluginContext, proc: str) -> _RssWindow:
    """The process's `_RssWindow`, started from its history when first asked for."""
    windows = ctx.state["rss"]
    if proc not in windows:
        times, values = ctx.past(proc, "rss_mb")
        w = windows[proc] = _RssWindow(times[0] if len(times) else ctx.t, deque())
        for t, v in zip(times.tolist(), values.tolist(), strict=True):
            w.add(t, v, ctx.settings["warmup_s"])
    return windows[proc]


def steady_growth(times: np.ndarray, rss: np.ndarray, now: float,
                  settings: Mapping[str, Any]) -> float | None:
    """Return the RSS growth rate (MB/s) when memory grows steadily in one of the spans, else None.

    Checked over the last ``trend_s``/12, /6, /2 and ``trend_s`` of ``times`` up to ``now``: the
    slope is at least ``growth_mb_per_s``, RSS grew at least ``growth_min_mb`` (the last value
    above the span's minimum) and rose in at least ``growth_steady`` of the steps, over at least
    ``growth_min_samples`` finite samples, no one step being half the growth (an allocation).
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
        steps = np.diff(v)
        steady = np.mean(steps > 0.01)
        grown = v[-1] - v.min()
        # one step of half the growth or more is an allocation, whatever the noise around it does
        if (np.isfinite(rate) and rate >= s["growth_mb_per_s"] and grown >= s["growth_min_mb"]
                and steady >= s["growth_steady"] and steps.max() < grown / 2):
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
    startup_s : float
        Growth since a process was first seen is its start-up until it was seen this long.
    burst_margin : float
        A CPU rise is evidence once it outlasts this × the process's longest earlier burst.
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
    startup_s: float
    burst_margin: float


def evidence_rule(settings: Mapping[str, Any] | None = None) -> EvidenceRule:
    """Return the evidence's parameters from the ``process_resources`` settings (`SETTINGS` for
    what ``settings`` does not give); see the module docstring for the derivation."""
    s = {**SETTINGS, **(settings or {})}
    return EvidenceRule(
        k=s["k"], cpu_min_rise=s["cpu_min_rise"], rss_min_rise_mb=s["rss_min_rise_mb"],
        growth_mb_per_s=s["growth_mb_per_s"], growth_min_mb=s["growth_min_mb"],
        trend_s=s["trend_s"] / 2, growth_samples=s["growth_min_samples"] + 1,
        warmup=round(s["warmup_s"]), window=s["window"], startup_s=s["startup_s"],
        burst_margin=s["burst_margin"],
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
    recent = times >= now - rule.trend_s
    span = values[recent, _RSS]
    out = []
    for col, floor, what in ((_CPU, rule.cpu_min_rise, "cpu"), (_RSS, rule.rss_min_rise_mb, "memory")):
        # The median is at least the minimum: a value not `floor` above the minimum cannot be
        # `floor` above the median, so the healthy case needs no median (called every sample).
        # fmin/fmax skip NaN (an unread sample) as nanmin/nanmax do, in one ufunc call each.
        if not np.isfinite(cur[col]) or not cur[col] - np.fmin.reduce(past[:, col], initial=np.inf) >= floor:
            continue
        if what == "memory" and cur[col] - np.fmin.reduce(span, initial=np.inf) < floor / 2:
            continue  # risen long ago and level since: its new normal (`_rose_lately`)
        med, sigma, _ = robust(past[:, col])
        dispatched = what == "cpu" and dispatcher_rise(cur[col], med, cur[_MAIN], cur[_DISPATCHING])
        if np.isfinite(med) and exceeds(cur[col], med, sigma, rule.k, floor) and not dispatched:
            out.append(what)
    grew = np.fmax.reduce(span, initial=-np.inf) - np.fmin.reduce(span, initial=np.inf)
    growing = recent.sum() >= rule.growth_samples and grew >= rule.growth_min_mb
    if growing and not _starting(times, values, rule):
        s = slope(times[recent], span)
        if np.isfinite(s) and s >= rule.growth_mb_per_s:
            out.append("memory_growth")
    return out


def _starting(times: np.ndarray, values: np.ndarray, rule: EvidenceRule) -> bool:
    """True when the samples are the process's first (fewer than ``window``), seen for less than
    ``startup_s``, and its RSS grew by half ``growth_min_mb`` in its first ``warmup`` samples:
    memory growing since it started is its start-up."""
    if len(times) >= rule.window or times[-1] - times[0] >= rule.startup_s:
        return False
    early = values[: rule.warmup + 1, _RSS]
    return bool(np.fmax.reduce(early, initial=-np.inf) - np.fmin.reduce(early, initial=np.inf)
                >= rule.growth_min_mb / 2)


def anomalous_processes(G: nx.MultiDiGraph, history: History,
                        settings: Mapping[str, Any] | None = None,
                        bursts: Mapping[str, float] | None = None) -> set[str]:
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
    bursts : mapping, optional
        `burst_key` to the longest CPU burst (s) a process with those nodes showed in the
        healthy run this one started from (the plugin's ``learned["bursts"]``).
    """
    rule = evidence_rule(settings)
    out: set[str] = set()
    for m, attrs in G._node.items():  # the attribute dicts, not a data view: every member, every sample
        if attrs.get("kind") != "process" or m not in history:
            continue
        times, values = history.series(m, rule.window)
        found = process_anomaly(times, values, times[-1], rule)
        if found == ["cpu"] and _within_bursts(*history.series(m), rule, _carried(G, m, bursts)):
            continue  # rare: a rise found reads the whole history for the process's bursts
        if found:
            out.add(m)
    return out


def _carried(G: nx.MultiDiGraph, process: str, bursts: Mapping[str, float] | None) -> float:
    """The longest burst a process with ``process``'s nodes showed in the carried ``bursts``."""
    return bursts.get(burst_key(nodes_of_process(G, process, by_pid=True)), 0.0) if bursts else 0.0


def _within_bursts(times: np.ndarray, values: np.ndarray, rule: EvidenceRule, carried: float = 0.0) -> bool:
    """True when the process's CPU rise lasts no longer than ``burst_margin`` × its longest
    earlier burst in ``times``/``values`` (its whole history), measured from the median of its
    last ``window`` samples before the present plus the floor, or the ``carried`` one of a
    healthy run: its rhythm, no evidence."""
    cpu = values[:, _CPU]
    med = float(np.nanmedian(cpu[-rule.window:-1])) if len(cpu) > 1 else np.nan
    if not np.isfinite(med):
        return False
    cpu = undispatched(cpu, values[:, _MAIN], values[:, _DISPATCHING], med)
    lasted, longest = excursions(times, cpu, med + rule.cpu_min_rise, times[0] + rule.warmup)
    longest = max(longest, carried)
    return longest > 0 and lasted <= rule.burst_margin * longest


def with_nodes(G: nx.MultiDiGraph, processes: set[str]) -> set[str]:
    """Return ``processes`` and the nodes they host (what process monitoring adds to the watchlist)."""
    return processes.union(*(nodes_of_process(G, p) for p in processes))


def process_anomalies(G: nx.MultiDiGraph, history: History, settings: Mapping[str, Any] | None = None,
                      bursts: Mapping[str, float] | None = None) -> set[str]:
    """Return `anomalous_processes` and the nodes they host."""
    return with_nodes(G, anomalous_processes(G, history, settings, bursts))
