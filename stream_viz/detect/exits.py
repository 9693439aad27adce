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
