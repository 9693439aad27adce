"""Nodes whose process exited with code 0 while DDS still lists them (no goodbye was sent).

Where the collector reads exit codes (``exit_code`` in an exit event, docs/collector.md), such a
node lingers in the graph until its lease ends as a crashed one does, but nothing crashed.
Plugins keep them in their state as node → (pid, when), one entry per node.
"""

from __future__ import annotations

import signal

from stream_viz.detect.api import PluginContext
from stream_viz.records import Event

CleanExits = dict[str, tuple[int | None, float]]


# Signals another process sends (a person, a supervisor, the OOM killer): what the robot's data
# do to a node shows as an exception, an abort or a segfault, never as one of these.
KILL_SIGNALS = frozenset({-signal.SIGKILL, -signal.SIGTERM, -signal.SIGINT, -signal.SIGHUP})


def killed(e: Event) -> bool:
    """True when ``e`` is an exit event of a process killed by a signal sent to it (`KILL_SIGNALS`)."""
    return e.kind == "exit" and e.data.get("exit_code") in KILL_SIGNALS


def exited_0(e: Event) -> bool:
    """True when ``e`` is an exit event of a process that exited with code 0."""
    return e.kind == "exit" and e.data.get("exit_code") == 0


def note_clean_exits(ctx: PluginContext, clean: CleanExits) -> None:
    """Add the still-listed nodes of this sample's exits with code 0 to ``clean``; drop those of
    an exit with any other code."""
    for e in ctx.events:
        for m in e.data.get("still_listed", ()) if e.kind == "exit" else ():
            if exited_0(e):
                clean[m] = (e.data.get("pid"), ctx.t)
            else:
                clean.pop(m, None)


def forget_clean_exits(ctx: PluginContext, clean: CleanExits) -> None:
    """Drop from ``clean`` the nodes gone from the graph or running in another process now."""
    for m in [m for m, (pid, _) in clean.items() if m not in ctx.graph or ctx.attr(m, "pid") != pid]:
        del clean[m]


# Processes that end this close together were stopped together (a launch file or a supervisor
# stopping them all): a stop, whatever their codes.
STOP_TOGETHER_S = 2.0


def error_exits(events: list[Event], t: float, state: dict,
                together_s: float = STOP_TOGETHER_S) -> list[tuple[Event, list[str]]]:
    """Return the exits decided at ``t`` of processes that ended with an error after their nodes
    left the graph, alone: ``(the process's exit event, its nodes that had left)``.

    A Python node's uncaught exception ends its process this way: rclpy destroys its nodes on
    the way out (DDS gets the goodbye) and the interpreter exits with code 1. So may SIGTERM
    (rclpy's ``ExternalShutdownException`` uncaught, or its shutdown racing the executor; Ctrl-C
    ends with -2 or 0), but a stop usually comes to several processes together. An exit counts
    when its code is known and neither 0 nor a stop signal (`KILL_SIGNALS`; still-listed nodes
    are a crash the caller sees anyway), once ``together_s`` has passed without another process
    with nodes ending within ``together_s`` of it. ``events``: this sample's; ``state``: the
    caller's, kept between calls.
    """
    pending = state.setdefault("pending", {})  # process -> (t, its exit event, the nodes that left)
    recent = state.setdefault("recent", {})  # process -> when it was seen to end (one with nodes)
    for e in events:
        data = e.data
        if e.kind != "exit" or e.member != data.get("process") or not data.get("nodes"):
            continue
        recent[e.member] = t
        code, left = data.get("exit_code"), sorted(set(data["nodes"]) - set(data.get("still_listed", ())))
        if code is not None and code != 0 and code not in KILL_SIGNALS and left:
            pending[e.member] = (t, e, left)
    out = []
    for proc, (t0, e, left) in sorted(pending.items(), key=lambda kv: kv[1][0]):
        if t - t0 < together_s:
            continue
        del pending[proc]
        if not any(p != proc and abs(t1 - t0) <= together_s for p, t1 in recent.items()):
            out.append((e, left))
    for proc in [p for p, t1 in recent.items() if t - t1 > 3 * together_s]:
        del recent[proc]
    return out
