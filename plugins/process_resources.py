"""Process CPU and memory anomalies against the process's own baseline, and memory growth."""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator
from typing import Any, ClassVar

import numpy as np

from stream_viz.detect.api import Plugin, PluginContext
from stream_viz.detect.baseline import BASELINE_SETTINGS, rise, slope
from stream_viz.model.queries import nodes_of_process, process_of_node
from stream_viz.records import Alert


class ProcessResources(Plugin):
    """Alerts on a process using much more CPU or memory than it used to, or leaking memory.

    * CPU / memory: ``value - median ≥ max(k·σ, min_rise)`` (σ = 1.4826·MAD of the process's own
      past after ``warmup_s``, frozen while alerting) for ``confirm`` samples; the absolute
      floors (``cpu_min_rise`` percentage points, ``rss_min_rise_mb``) keep idle noise quiet.
    * growth: the least-squares slope of RSS over a recent window (``trend_s``/12, /6, /2, whole) is
      at least ``growth_mb_per_s``, RSS grew at least ``growth_min_mb`` in it and rose in at
      least ``growth_steady`` of the steps (a leak, not one big allocation), over at least
      ``growth_min_samples`` samples.

    Alerts go to the nodes the process hosts (``alert_on = "nodes"``; the process itself when
    it hosts none), to the process (``"process"``) or both (``"both"``). A process is checked
    when it or one of its nodes is watched.
    """

    name = "process_resources"
    kinds = ("process", "node")
    uses = (rise,)
    settings: ClassVar[dict[str, Any]] = {
        **BASELINE_SETTINGS,
        "min_samples": 8,
        "k": 5.0,
        "cpu_min_rise": 25.0,
        "rss_min_rise_mb": 100.0,
        "growth_mb_per_s": 1.0,
        "growth_min_mb": 20.0,
        "trend_s": 60.0,
        "growth_steady": 0.7,
        "growth_min_samples": 4,
        "confirm": 2,
        "alert_on": "nodes",
    }

    def check(self, ctx: PluginContext) -> Iterator[Alert]:
        s = ctx.settings
        G = ctx.graph
        procs = set(ctx.watched("process"))
        for node in ctx.watched("node"):
            proc = process_of_node(G, node)
            if proc is not None:
                procs.add(proc)
        alerting = ctx.state.setdefault("alerting", set())
        for gone in ctx.diff.removed_members:  # bound the state when processes come and go
            ctx.state.get("rss", {}).pop(gone, None)
        for proc in sorted(procs):
            found = []
            for attr, floor, what in (("cpu_percent", s["cpu_min_rise"], "cpu"),
                                      ("rss_mb", s["rss_min_rise_mb"], "memory")):
                risen = rise(ctx, proc, attr, floor, alerting)
                if risen is not None:
                    value, med = risen
                    unit = "%" if what == "cpu" else " MB"
                    found.append((what, f"{what} {value:.0f}{unit}, normally {med:.0f}{unit}",
                                  {"value": value, "baseline": med}))
            growth = self._growth(ctx, proc)
            if growth is not None:
                found.append(("memory_growth", f"memory growing {growth:.1f} MB/s", {"mb_per_s": growth}))
            if not found:
                continue
            nodes = nodes_of_process(G, proc, by_pid=True)
            mode = s["alert_on"]
            targets = [proc] if mode == "process" or not nodes else []
            targets += nodes if mode != "process" else []
            if mode == "both" and nodes:
                targets.append(proc)
            message = "; ".join(f[1] for f in found)
            data = {"process": proc, "symptoms": [f[0] for f in found]} | {
                f"{f[0]}_{k}": v for f in found for k, v in f[2].items()}
            for m in targets:
                yield ctx.alert(m, "warn", f"{proc}: {message}", **data)

    @staticmethod
    def _growth(ctx: PluginContext, proc: str) -> float | None:
        """Return the RSS growth rate (MB/s) when memory grows steadily, else None.

        Checked over the last ``trend_s``/12, /6, /2 and whole (a fast leak shows in the short window,
        a slow one in the long); steady means at least ``growth_steady`` of the increments are
        positive, so one big allocation (a step) does not count as a leak.
        """
        s = ctx.settings
        # Own bounded (t, rss) window per process: cheaper than reading the whole history.
        windows = ctx.state.setdefault("rss", {})
        q = windows.get(proc)
        if q is None:
            times, values = ctx.past(proc, "rss_mb")
            q = windows[proc] = deque(zip(times.tolist(), values.tolist(), strict=True))
            ctx.state.setdefault("first", {})[proc] = times[0] if len(times) else ctx.t
        q.append((ctx.t, ctx.value(proc, "rss_mb")))
        while q and q[0][0] < ctx.t - s["trend_s"]:
            q.popleft()
        if ctx.t - ctx.state["first"][proc] < s["warmup_s"] or len(q) < s["growth_min_samples"]:
            return None
        rss = [v for _, v in q if v == v]
        if not rss or rss[-1] - min(rss) < s["growth_min_mb"]:
            return None  # the common, healthy case: no numpy needed
        t_all = np.array([t for t, _ in q])
        v_all = np.array([v for _, v in q])
        for span in (s["trend_s"] / 12, s["trend_s"] / 6, s["trend_s"] / 2, s["trend_s"]):
            recent = t_all >= ctx.t - span
            t, v = t_all[recent], v_all[recent]
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
