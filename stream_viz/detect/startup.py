"""A node's bring-up: the first seconds of its process, when complaints are usually about peers
that are not up yet ("service not available, retrying", a transform not yet published); and a
member's standing condition: what it shows from its first look on is its normal."""

from __future__ import annotations

from stream_viz.detect.api import PluginContext

STARTUP_S = 10.0  # a node's bring-up, from its process's start


def starting(ctx: PluginContext, node: str, t: float, within: float = STARTUP_S) -> bool:
    """Return True when ``node``'s process had started less than ``within`` s before ``t``.

    Parameters
    ----------
    ctx : PluginContext
        The plugin's context (the node's process and its ``create_time``).
    node : str
        A node member id.
    t : float
        The time asked about (an event's time), s since the epoch.
    within : float
        The length of the bring-up, s.

    Returns
    -------
    bool
        False when the node's process or its start is unknown (a computer without an agent).
    """
    proc = ctx.process_of(node)
    created = ctx.attr(proc, "create_time") if proc is not None else None
    return isinstance(created, (int, float)) and 0.0 <= t - created < within


def bring_up_note(ctx: PluginContext, node: str) -> str:
    """Return ``"; N during its bring-up"`` for the lines held back for ``node`` (`hold_back`),
    once, and forget them; ``""`` when none were."""
    held = ctx.state.setdefault("bring_up", {}).pop(node, 0)
    return f"; {held} during its bring-up" if held else ""


def hold_back(ctx: PluginContext, node: str) -> None:
    """Count a line of ``node`` logged during its bring-up: not a symptom by itself."""
    held = ctx.state.setdefault("bring_up", {})
    held[node] = held.get(node, 0) + 1


def standing(state: dict, key: object, t: float, kind: str | None, learn_s: float) -> bool:
    """Return True when ``kind`` (None: nothing now) is ``key``'s standing condition: the first
    kind it showed within ``learn_s`` of when it was first seen (a status that warns from the
    start, a device whose stamps run ahead of our clock). Robots run with such conditions.

    Parameters
    ----------
    state : dict
        The plugin's state (``ctx.state``); the first sight and the normal are kept in it.
    key : hashable
        What is judged (a status name, a topic).
    t : float
        Now, or the observation's time.
    kind : str or None
        The condition it shows now.
    learn_s : float
        How long after the first sight a condition counts as its normal.
    """
    first = state.setdefault("_first_seen", {}).setdefault(key, t)
    normal = state.setdefault("_standing", {})
    if kind is not None and t - first < learn_s:
        normal.setdefault(key, kind)
    return kind is not None and normal.get(key) == kind
