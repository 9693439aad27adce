"""Process CPU and memory anomalies against the process's own baseline, and memory growth."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any, ClassVar

from stream_viz.detect.api import Plugin, PluginContext
from stream_viz.detect.process import SETTINGS, rise_began, symptoms
from stream_viz.detect.warned import began_warning, note_warnings
from stream_viz.records import Alert


class ProcessResources(Plugin):
    """Alerts on a process using much more CPU or memory than it used to, or leaking memory.

    The rule and its settings are `stream_viz.detect.process` (shared with the process evidence
    the monitor gives the RCA, so these settings tune both): a CPU / memory rise above the
    process's own baseline for ``confirm`` samples, or a steady memory growth.

    Alerts go to the nodes the process hosts (``alert_on = "nodes"``; the process itself when
    it hosts none), to the process (``"process"``) or both (``"both"``). A process is checked
    when it or one of its nodes is watched.
    """

    name = "process_resources"
    kinds = ("process", "node")
    uses = (symptoms,)
    settings: ClassVar[dict[str, Any]] = {**SETTINGS, "alert_on": "nodes",
                                          "warned_quiet_s": 60.0, "warned_lead_s": 10.0}

    def check(self, ctx: PluginContext) -> Iterator[Alert]:
        s = ctx.settings
        warnings = ctx.state.setdefault("warnings", {})
        note_warnings(warnings, ctx.events, s["warned_quiet_s"])
        procs = {m if ctx.kind(m) == "process" else ctx.process_of(m) for m in ctx.watched()}
        for proc, found in symptoms(ctx, sorted(procs - {None})):
            nodes = ctx.nodes_of(proc, by_pid=True)
            message = "; ".join(text for _, text, _ in found)
            data = {"process": proc, "symptoms": [what for what, _, _ in found]}
            data |= {f"{what}_{k}": v for what, _, values in found for k, v in values.items()}
            warned = began_warning(warnings, nodes, _began(ctx, proc, found) - s["warned_lead_s"]) \
                if len(nodes) > 1 else []
            if warned:
                data["names"] = [n for n, _ in warned]
                message += "; " + "; ".join(f"{n.removeprefix('node:')} began to warn: {text}"
                                            for n, text in warned)
            for m in _targets(nodes, proc, s["alert_on"]):
                yield ctx.alert(m, "warn", f"{proc}: {message}", **data)


def _began(ctx: PluginContext, proc: str, found: list) -> float:
    """When the process's symptom began: its CPU rise's first sample, else (memory) the recent
    half of the trend window in which it rose or grew."""
    began = rise_began(ctx, proc) if any(what == "cpu" for what, _, _ in found) else None
    return ctx.t - ctx.settings["trend_s"] / 2 if began is None else began


def _targets(nodes: list[str], proc: str, alert_on: str) -> list[str]:
    """The members a process's alert goes to: its nodes, itself, or both (itself when it has no node)."""
    if alert_on == "process" or not nodes:
        return [proc]
    return [*nodes, proc] if alert_on == "both" else nodes
