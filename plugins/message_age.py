"""The age of a topic's data from its messages' header stamps: stale data, skewed clocks, or
stamps that left the topics they matched.

The collector measures ``stamp_age_ms`` (received − ``header.stamp``, mean over its window) for
types that begin with a ``std_msgs/Header`` whose stamp is set. It is the age of the data (since
the sensor reading or the input it was computed from), beside the transport latency (since it was
published). It compares two clocks, the publisher's and ours: a negative or implausible age is a
clock problem, not a delay, and is said so.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any, ClassVar

from stream_viz.detect.api import Plugin, PluginContext
from stream_viz.detect.baseline import (
    BASELINE_SETTINGS,
    cached_baseline,
    confirm,
    exceeds,
    excess,
    held,
    streak,
)
from stream_viz.detect.process import publishers_busy
from stream_viz.detect.reconfigure import learnt_since, relearn_from
from stream_viz.detect.startup import standing
from stream_viz.model.ids import name_of
from stream_viz.records import Alert

PAUSE_PERIODS = 3.0  # an interval this many periods long (and PAUSE_MIN_S) ends a burst of a topic
PAUSE_MIN_S = 0.2
JUMP_SAID_S = 60.0  # a clock's jump back is said in the stale alerts this long after it


class MessageAge(Plugin):
    """Alerts on watched topics whose messages arrive with old or impossible header stamps.

    * ``stale`` (warn; error once the data are ``error_ms`` older than usual; not while every
      publisher's process is busy beyond its own CPU baseline, `publishers_busy`: the CPU is the
      symptom, ``process_resources``'): the age rises
      above the topic's own baseline by ``max(k·σ, min_rise_ms, rise_ratio × baseline)`` for
      ``confirm`` samples with a new message and for ``hold_s`` (the mean over the window, which
      one late message holds up), or sooner, for ``fast_confirm`` such samples, when the youngest
      of the newest messages is as late (`_all_late`); with ``max_age_ms`` > 0 also any age above it;
    * ``clock_skew`` (warn): the age is below ``-skew_ms`` (the stamps are in our future: the
      publisher's clock runs ahead, another host's or a simulated one) or above ``implausible_s``
      (stamps not from this clock at all: simulated time, an unset or unsynchronised clock), for
      ``confirm`` samples. No stale check on such a topic: its ages say nothing about delay.
    * ``desync`` (warn): its stamps no longer match those of the topics that carried the same
      stamps (cameras on one trigger, a synchronizer's inputs), `_desync`.

    On a topic several nodes publish (``/tf``), the alert names those whose own messages are late
    (``publisher_ages``; data ``publishers``) when the others' are not: the RCA charges them.

    A topic whose stamps went back to about where they began (a ``stamp_reset`` event at least
    ``loop_share`` of the time it has been stamping: a recording that looped, a simulation reset,
    `looped`) learns its age afresh from then on: its data are as old as its new time makes them,
    which is no delay. Stamps that went back less, mid-stream, are a clock that jumped (a
    device's clock reset by a brown-out): judged as any rise of the age, the jump said.

    Its normal age is learnt from ``min_messages`` messages at least (samples holding the same
    message, on a slow or aperiodic topic, say nothing new): the blind AUV's USBL fixes, stamped
    0.2–0.6 s before they arrive every 2–6 s, were judged against their first two.

    A skew the topic shows within ``learn_s`` of its first stamped message, and keeps, is its
    normal (a device that stamps with its own clock, a recording's old stamps): no alert, and a
    plausible standing skew (stamps ahead) is checked for staleness against its own baseline, the
    offset cancelling out. A topic whose stamps were on time and then skew is news. Transforms
    stamped ahead by publishers on this computer are postdated on purpose (`_postdated`), no skew.
    """

    name = "message_age"
    kinds = ("topic",)
    uses = (excess, confirm)
    settings: ClassVar[dict[str, Any]] = {
        **BASELINE_SETTINGS,
        "k": 6.0,
        "confirm": 3,
        "hold_s": 4.0,
        "fast_confirm": 2,
        "min_rise_ms": 100.0,
        "rise_ratio": 0.5,
        "max_age_ms": 0.0,
        "skew_ms": 20.0,
        "implausible_s": 3600.0,
        "learn_s": 10.0,
        "loop_share": 0.3,
        "min_messages": 8,
        "error_ms": 1000.0,
        "partner_share": 0.8,
        "partner_samples": 5,
        "lost_share": 0.1,
    }

    def check(self, ctx: PluginContext) -> Iterator[Alert]:
        s = ctx.settings
        alerting = ctx.state.setdefault("alerting", set())
        since = ctx.since_last_call()
        stamped = ctx.state.setdefault("stamped", {})  # topic -> since when (its last loop)
        jumped = ctx.state.setdefault("jumped", {})  # topic -> how far its clock went back (s)
        for e in ctx.events:
            if e.kind != "stamp_reset":
                continue
            back = float(e.data.get("back_s", 0.0))
            if looped(back, e.t - stamped.get(e.member, e.t), s["loop_share"]):
                relearn_from(ctx, e.member, "stamp_age_ms", e.t)  # the age is learnt anew from then
                ctx.state.setdefault("messages", {}).pop(e.member, None)
                alerting.discard((e.member, "stamp_age_ms"))
                held(ctx.state, e.member, False, ctx.t)
                stamped[e.member] = e.t
                jumped.pop(e.member, None)
            else:
                jumped[e.member] = (back, e.t)
        for topic in ctx.watched():
            age = ctx.value(topic, "stamp_age_ms")
            if math.isnan(age):
                continue
            stamped.setdefault(topic, ctx.t)
            newest = ctx.value(topic, "age_s")
            fresh = math.isnan(newest) or newest < since  # a message since the last sample
            if fresh:
                counted = ctx.state.setdefault("messages", {})
                counted[topic] = counted.get(topic, 0) + 1
            ahead, implausible = age < -s["skew_ms"], age > s["implausible_s"] * 1000.0
            ahead = ahead and not _postdated(ctx, topic, -s["skew_ms"])
            skew = "ahead" if ahead else "implausible" if implausible else None
            if standing(ctx.state, topic, ctx.t, skew, s["learn_s"]):
                if skew == "ahead":
                    yield from self._stale(ctx, topic, age, fresh, alerting)
                continue
            if (moved := _desync(ctx, topic, age, fresh)) is not None:
                yield moved
                continue
            if streak(ctx.state, (topic, "skew"), skew is not None, fresh) >= s["confirm"]:
                yield _skew(ctx, topic, age)
                continue
            if skew is not None:
                continue
            yield from self._stale(ctx, topic, age, fresh, alerting)

    @staticmethod
    def _stale(ctx: PluginContext, topic: str, age: float, fresh: bool, alerting: set) -> Iterator[Alert]:
        s = ctx.settings
        if ctx.state.get("messages", {}).get(topic, 0) < s["min_messages"]:
            return  # a USBL fix every 4 s is in four samples: its normal age is learnt from messages
        since = learnt_since(ctx, topic, "stamp_age_ms")
        seen = excess(ctx, topic, "stamp_age_ms", s["min_rise_ms"], alerting, since=since)
        if seen is not None:
            value, med, risen = seen
            risen = risen and value - med >= s["rise_ratio"] * abs(med)
            # Its publishers' processes busy: their callbacks run late, the CPU's symptom. Asked
            # only of a rise: it reads their CPU history, which most samples need not.
            seen = (value, med, risen and not publishers_busy(ctx, topic))
        risen = confirm(ctx, topic, "stamp_age_ms", seen, alerting, fresh)
        if held(ctx.state, topic, seen is not None and seen[2], ctx.t, fresh) < s["hold_s"]:
            risen = None
        if risen is None and _all_late(ctx, topic, seen, fresh, since):
            alerting.add((topic, "stamp_age_ms"))  # the baseline must not learn the delay
            risen = (seen[0], seen[1])
        over = s["max_age_ms"] > 0 and age > s["max_age_ms"]
        if risen is None and not over:
            return
        usual = f", normally {risen[1]:.0f} ms" if risen is not None else f" (limit {s['max_age_ms']:.0f} ms)"
        floor = max(s["min_rise_ms"], s["rise_ratio"] * abs(seen[1] if seen else 0.0))
        late = _late_publishers(ctx, topic, floor)
        whose = f", from {', '.join(name_of(p) for p in late)} (the others' on time)" if late else ""
        back, when = ctx.state.get("jumped", {}).get(topic, (0.0, -math.inf))
        back = back if ctx.t - when <= JUMP_SAID_S else 0.0
        clock = f"; its stamps went back {back:.1f} s mid-stream (its clock jumped)" if back else ""
        # As old as a topic silent this long is useless to its consumers: an error, as silence is.
        base = risen[1] if risen is not None else 0.0
        level = "error" if s["error_ms"] > 0 and age - base >= s["error_ms"] else "warn"
        yield ctx.alert(topic, level, f"stale data: messages arrive {age:.0f} ms after their header "
                        f"stamp{usual}{whose}{clock}", symptom="stale", value_ms=age,
                        baseline_ms=None if risen is None else risen[1],
                        **({"publishers": late} if late else {}), **({"stamps_back_s": back} if back else {}))


def looped(back_s: float, stamping_s: float, share: float = 0.3) -> bool:
    """True when stamps that went back ``back_s`` after ``stamping_s`` of stamping (since the
    topic's first stamp seen, or its last loop) went back to about where they began — at least
    ``share`` of that time: a recording that looped, a simulation reset. A live clock that went
    back less, mid-stream, jumped (a device's clock reset): its data now arrive older."""
    return back_s >= share * stamping_s


def _postdated(ctx: PluginContext, topic: str, ahead_ms: float) -> bool:
    """True when ``topic`` carries transforms and its stamps ahead of our clock (``publisher_ages``
    below ``ahead_ms``; all its publishers without them) come from publishers on this computer,
    whose clock is ours: a transform is stamped in the future on purpose (AMCL's and Nav2's
    ``transform_tolerance``, robot_localization's ``transform_time_offset``), so that lookups
    at the present time find it. Not a skew, nor a delay."""
    if "transform" not in str(ctx.attr(topic, "type", "")).lower():
        return False
    ages = ctx.attr(topic, "publisher_ages") or {}
    ahead = [p for p, ms in ages.items() if ms < ahead_ms] if ages else ctx.publishers(topic)
    here = {ctx.attr(h, "label") for h in ctx.members("host") if ctx.attr(h, "agent") == "local"}
    return bool(ahead) and all(ctx.attr(p, "host") in here for p in ahead)


def _late_publishers(ctx: PluginContext, topic: str, floor: float) -> list[str]:
    """The publishers of ``topic`` whose own messages are ``floor`` ms older than the youngest
    publisher's (``publisher_ages``), when some are and some are not: on ``/tf`` from three nodes,
    the one whose stamps froze, whose symptom it is. A publisher stamping ahead (a postdated
    transform) counts as on time: beside it, every publisher on time would look late."""
    ages = ctx.attr(topic, "publisher_ages") or {}
    if len(ages) < 2:
        return []
    least = max(0.0, min(ages.values()))
    late = sorted(p for p, ms in ages.items() if ms - least >= floor)
    return late if len(late) < len(ages) else []


def _all_late(ctx: PluginContext, topic: str, seen: tuple[float, float, bool] | None, fresh: bool,
              since: float | None) -> bool:
    """True when the mean age has risen and so has the youngest of the newest messages
    (``stamp_age_recent_ms``), by the same margin, for ``fast_confirm`` fresh samples: every
    recent message is late, which one old-stamped message in the window never makes it; no need
    to wait out the window (``hold_s``)."""
    s = ctx.settings
    young = ctx.value(topic, "stamp_age_recent_ms")
    late = False
    if seen is not None and seen[2] and young == young:
        base = cached_baseline(ctx, topic, "stamp_age_ms", frozen=True, since=since)
        if base is not None:
            med, sigma, _ = base
            late = exceeds(young, med, sigma, s["k"], max(s["min_rise_ms"], s["rise_ratio"] * abs(med)))
    return streak(ctx.state, (topic, "all_late"), late, fresh) >= s["fast_confirm"]


def _desync(ctx: PluginContext, topic: str, age: float, fresh: bool) -> Alert | None:
    """``desync`` (warn): the topic's stamps no longer match those of the topics that carried the
    same stamps (``stamp_partners``: a camera trio on one trigger, a synchronizer's inputs), while
    both publish, for ``confirm`` samples with a new message. A partner is learnt from
    ``partner_samples`` samples sharing ``partner_share`` of the stamps; one is lost under
    ``lost_share``. It began after the last sample in which every stamp matched (data ``since``),
    by the first that saw them part (``since`` + ``since_within``): the newest stamps compared
    span a few samples, so the share falls below ``lost_share`` only later. The topic that moved
    is the one whose partners still match each other; of a pair, the one whose age moved (twice
    the other's shift at least), else both."""
    s = ctx.settings
    now = ctx.attr(topic, "stamp_partners") or {}
    _note_resumed(ctx, topic)
    learned = ctx.state.setdefault("partners", {}).setdefault(topic, {})  # partner -> samples matched
    if fresh:
        for p, share in now.items():
            if share >= s["partner_share"]:
                learned[p] = learned.get(p, 0) + 1
    compared = [p for p, k in learned.items() if k >= s["partner_samples"] and p in now]
    lost = bool(compared) and all(now[p] < s["lost_share"] for p in compared)
    ages = ctx.state.setdefault("matched_age", {})  # topic -> its age while it matched its partners
    matched = ctx.state.setdefault("matched_at", {})  # topic -> the last sample it matched them all
    if not lost:
        if compared and fresh and all(now[p] >= s["partner_share"] for p in compared):
            ages[topic], matched[topic] = age, ctx.t
    elif not any(_matched_elsewhere(ctx, p, topic) for p in compared):  # a pair: whose stamps moved?
        mine = abs(age - ages.get(topic, age))
        theirs = max(abs(ctx.value(p, "stamp_age_ms") - ages.get(p, math.nan)) for p in compared)
        lost = not theirs > 2.0 * mine  # NaN: unknown, both are charged
    began = ctx.state.setdefault("desync_since", {})
    resumed = ctx.state["resumed"]
    for p in compared if lost else ():  # a partner judged after this topic in this sample
        _note_resumed(ctx, p)
    if lost and any(resumed.get(x, -math.inf) > matched.get(topic, -math.inf) for x in (topic, *compared)):
        # A burst began since they matched: its messages may take other ticks of the clock they
        # share (an arm controller's state every other cycle from its trajectory's start).
        for p in compared:
            learned.pop(p, None)
        streak(ctx.state, (topic, "desync"), False, fresh)
        lost = False
    if not lost:
        if fresh:
            began.pop(topic, None)
        return None
    began.setdefault(topic, ctx.t)
    if streak(ctx.state, (topic, "desync"), True, fresh) < s["confirm"]:
        return None
    names = ", ".join(name_of(p) for p in compared)
    shift = age - ages.get(topic, math.nan)
    moved = f"; its stamps moved {shift:+.0f} ms" if shift == shift else ""
    # It moved after the last sample its stamps all matched, by the first that saw them part.
    since = matched.get(topic, began[topic])
    return ctx.alert(topic, "warn", f"header stamps no longer match those of {names}, which they "
                     f"matched{moved}: a trigger or clock of its publisher changed (what synchronizes "
                     "them receives no set)", symptom="desync", partners=compared,
                     **({"shift_ms": shift} if shift == shift else {}), since=since,
                     since_within=began[topic] - since)


def _note_resumed(ctx: PluginContext, topic: str) -> None:
    """Note when ``topic`` resumed after a pause: its longest interval since the last sample
    (``gap_s``) over `PAUSE_PERIODS` of its periods and `PAUSE_MIN_S`."""
    gap, rate = ctx.value(topic, "gap_s"), ctx.value(topic, "rate_hz")
    resumed = ctx.state.setdefault("resumed", {})
    if gap == gap and gap > max(PAUSE_MIN_S, PAUSE_PERIODS / rate if rate > 0 else 0.0):
        resumed[topic] = ctx.t


def _matched_elsewhere(ctx: PluginContext, topic: str, but: str) -> bool:
    """True when ``topic`` still matches a partner other than ``but``."""
    shares = ctx.attr(topic, "stamp_partners") or {}
    return any(u != but and share >= ctx.settings["partner_share"] for u, share in shares.items())


def _skew(ctx: PluginContext, topic: str, age: float) -> Alert:
    if age < 0:
        why = (f"header stamps are {-age:.0f} ms ahead of this host's clock: the publisher's clock "
               "is skewed (another host not synchronised, or simulated time); not a latency")
    else:
        why = (f"header stamps are {age / 1000:.0f} s behind this host's clock: they are not from "
               "the wall clock (simulated time, or an unset clock); not a latency")
    return ctx.alert(topic, "warn", why, symptom="clock_skew", value_ms=age)
