"""A member's normal changed by a parameter change: a rise that the change brought is learnt anew.

Roboticists tune a running robot (``ros2 param set``, rqt_reconfigure): a camera set to a higher
resolution takes more CPU from then on, and that is its new normal, not a fault. A departure
that begins promptly after a parameter change of one of the member's nodes (the collector's
``param`` events), within ``reconfigure_s``, is the change's: the member's baseline of that
attribute is learnt again from the change (warming up again for ``warmup_s``). A departure
under way before the change, or one that begins later, is judged as any other. `topic_rate` has
its own, finer rule for rates and rhythms (docs/plugins.md).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from stream_viz.detect.api import reads_settings
from stream_viz.detect.baseline import forget_baseline

RECONFIGURE_SETTINGS: dict[str, float] = {"reconfigure_s": 10.0}
FORGET_S = 3600.0  # a baseline window (samples) is far shorter: the change is out of it by then


@reads_settings(*RECONFIGURE_SETTINGS)
def param_changes(ctx: Any) -> dict[str, float]:
    """Return node → the time of its newest parameter change within ``reconfigure_s`` of ``ctx.t``,
    from this call's ``param`` events and the plugin state's earlier ones (older ones forgotten)."""
    changed: dict[str, float] = ctx.state.setdefault("_param_changes", {})
    for e in ctx.events:
        if e.kind == "param":
            changed[e.member] = max(e.t, changed.get(e.member, e.t))
    for node in [n for n, t in changed.items() if ctx.t - t > ctx.settings["reconfigure_s"]]:
        del changed[node]
    relearn = ctx.state.get("_relearn", {})
    for key in [k for k, t in relearn.items() if ctx.t - t > FORGET_S]:  # long in the past window
        del relearn[key]
    return changed


def learnt_since(ctx: Any, member: str, attr: str) -> float | None:
    """Return the time ``member``'s ``attr`` is learnt anew from (its last reconfiguration, or
    another change of its normal: `relearn_from`), or None."""
    return ctx.state.get("_relearn", {}).get((member, attr))


def relearn_from(ctx: Any, member: str, attr: str, at: float) -> None:
    """Learn ``member``'s ``attr`` anew from ``at`` (its normal changed then): `learnt_since`
    answers ``at``, the cached baseline is dropped (`excess` takes ``since``)."""
    ctx.state.setdefault("_relearn", {})[(member, attr)] = at
    forget_baseline(ctx, member, attr)


@reads_settings(*RECONFIGURE_SETTINGS)
def reconfigured(ctx: Any, member: str, attr: str, nodes: Iterable[str],
                 seen: tuple[float, float, bool] | None, within: float | None = None) -> bool:
    """Return True when `excess` ``seen`` of ``member``'s ``attr`` is a rise a parameter change of
    one of ``nodes`` brought: its baseline is then learnt anew from the change.

    The rise must begin (its first exceeding sample) after the change and within ``within`` s of
    it (default ``reconfigure_s``); each change counts once. Call every sample, with
    `param_changes` called first in the same check; ``excess`` takes `learnt_since` as its
    ``since``.
    """
    key = (member, attr)
    began = ctx.state.setdefault("_rise_began", {})
    if seen is None or not seen[2]:
        began.pop(key, None)
        return False
    start = began.setdefault(key, ctx.t)
    changes = ctx.state.get("_param_changes", {})
    at = max((changes[n] for n in nodes if n in changes), default=None)
    relearn = ctx.state.setdefault("_relearn", {})
    window = ctx.settings["reconfigure_s"] if within is None else within
    prompt = at is not None and at <= start <= at + window
    if not prompt or relearn.get(key, -float("inf")) >= at:
        return False
    relearn_from(ctx, member, attr, at)
    began.pop(key, None)
    return True
