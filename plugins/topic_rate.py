"""Topic rate drop or silence, against the topic's own rhythm and rate and the configured rate."""

from __future__ import annotations

import math
import re
from collections import deque
from collections.abc import Iterator
from typing import Any, ClassVar

import numpy as np

from stream_viz.detect.api import Plugin, PluginContext
from stream_viz.detect.baseline import (
    BASELINE_SETTINGS,
    cached_baseline,
    excursions,
    forget_baseline,
    forget_run,
    held,
    held_since,
    robust,
    streak,
)
from stream_viz.detect.endpoints import named_topics, receives
from stream_viz.detect.lifecycle import transitions as lifecycle_transitions
from stream_viz.detect.process import SETTINGS as PROCESS_SETTINGS
from stream_viz.detect.process import publishers_busy
from stream_viz.detect.rhythm import SAME_MESSAGE_S, Rhythm, follow, newest_message, quiet_limit, restarted
from stream_viz.model.ids import name_of
from stream_viz.model.qos import qos_policy
from stream_viz.records import SEVERITY_RANK as RANK
from stream_viz.records import Alert

Baseline = tuple[float, float, int] | None
TRANSITIONS_KEPT = 8  # per node: enough for the changes around one quiet
# A WARN line again within this of the node's last: it goes on (a single one is routine: a
# receiver's dropped sentence in a quiet its status vouches for; `services`' warn_repeat_s alike).
WARN_REPEAT_S = 30.0
COMPLAINTS_KEPT_S = 30.0  # a node's complaints kept this long: a transition is seen samples after
COMPLAINTS_KEPT = 1024  # ... and at most this many
_NUMBER = re.compile(r"[-+]?\d[\d.,:]*")  # a reading in a status's message, not its mode
STATE_GAP_S = 10.0  # a latched topic's message this long after its last is a state published on change
EXECUTOR_CPU = "executor_cpu_percent"
INERT_AFTER = 2  # changes of a parameter in a row that moved no rate: one can be missed (timing)
PROMPT_INTERVALS = 6  # a reconfigured rate shows in the collector's recent rate within this many intervals
FORGET_S = 600.0  # as long as the monitor keeps a vanished member by default (forget_gone_s)
SINGLE_RUN_S = 0.5  # a run of messages this short is one answer (a few messages at most)
STOP_CONFIRM = 2  # samples in a row a withholding node's executor must work less
ANSWERS_HZ = 1.0  # a server's topic at most this fast while publishing can be its answers
UPSTREAM_HOPS = 2  # a rate follows what stopped this many inputs up (commands -> base -> odometry)
CLOCK = "topic:/clock"  # simulated time (`stream_viz.collect.simclock`)
PAUSED = 0.05  # the simulation's pace under this share of its usual: paused
STEADY_SAMPLES = 15  # a publisher that sent in this many samples in a row sends continuously
STOPPING_PERIODS = 3.0  # a quiet this many usual periods long: the topic is stopping, not slower
FEED_SLACK_S = 0.25  # a feeding node's change of state reaches a publisher within a period and this
THREADS_STEADY = 8  # samples before a quiet with one thread count: the process's threads are steady
THREAD_END_S = 1.0  # a thread that stops publishing on an error ends within this (or a period) after
LINES_KEPT = 4  # per node: its newest log lines' times (`_announced`)
BEAT_SHARE = 0.02  # a line this close to the interval of the two before it comes at their beat (a timer)
# On simulated time a sensor's messages come in bursts, one per /clock tick: its intervals spread
# however steady its rate per simulated second is (σ within this share of it): then it is regular.
STEADY_PER_SIM = 0.1
# A drop's run not looked at for this long (a silence judged meanwhile) ended unseen: not learned.
RUN_LAPSE_S = 5.0


class TopicRate(Plugin):
    """Alerts when a watched topic's rate drops or it goes silent, as a departure from its own
    rhythm (`stream_viz.detect.rhythm`): a bursty topic's gaps are normal, a continuous topic's
    gap is not.

    * silence (error): quiet (no message, from the age of the newest one, ``age_s``; without one,
      a zero rate means none for the collector's ``rate_window_s``, 3 s) for longer than
      ``max(silence_periods / rate, silence_min_s)`` (the rate while publishing, not counting a
      bursty topic's quiets: `stream_viz.detect.rhythm`; ``complained_min_s`` for the floor when a
      publisher complained as it went quiet, `_complained`: its word confirms what the floor
      guards against, the monitor's own sampling), or ``gap_margin`` × the longest healthy gap
      or quiet the topic has shown (in this run, or in the healthy run it started from,
      ``--healthy``: `Rhythm.carried`), or, for a topic whose arrivals are irregular, the longest
      quiet random arrivals at its rate show in ``irregular_horizon_s`` (`_by_chance`). Judged
      only once the topic's rhythm is settled: it published for ``warmup_s`` (and
      ``settle_messages`` of its periods) without such a quiet, or showed ``min_gaps`` healthy
      gaps; a topic that left the graph, or had no
      publisher, after its last message from the sample its publishers were back (an
      operator's joystick, its node gone with the operator, is back a second before it
      publishes). Never while it has
      no publisher (graph_anomalies' orphans), while all its publishers are transient-local (a
      latched topic publishes when its data changes; ``judge_latched``), or when a publisher
      changed state within ``transition_grace_s`` of the last message — a lifecycle transition
      (a message on its ``transition_event`` topic: a deactivated publisher is silent) or a goal
      of an action it serves ending (a controller stops when its goal is reached);
      such a quiet is healthy, and not learned (its length is the state's, not the rhythm's).
      Neither that nor what its publishers do or say (`_withheld`, `_announced`, `_on_request`,
      `_vouched`) excuses a quiet a node that reads the topic complained of after its last
      message (`_contested`): the system did not mean it.
      Nor when every publisher has an input that went quiet up to ``input_grace_s`` before the
      topic did: the quiet is the input's (`_inherited`), not learned either; nor while every
      publisher's process is busy beyond its own CPU baseline (`publishers_busy`: its executor held by its
      own work; the CPU is ``process_resources``' symptom); nor while every publisher says OK of
      itself on /diagnostics after the topic's next message was due, and nothing worse since its
      last (`_vouched`: a driver reporting its device fine while its output stops means it;
      ``self_reports`` false for drivers that report OK whatever happens).
      A quiet a publisher complained of (`_complained`: a WARN or worse, a status of its own
      worse than OK) is never learned as the topic's rhythm, however short (a sensor dropping out
      for 1.2 s with a WARN, learned, would make its 2 s dropouts healthy).
      A silence again within ``flap_window_s`` of the last alert is the same episode
      (``episode_hold_s``), counted (``flaps``);
    * drop (warn): ``rate < drop_ratio × baseline`` and ``≥ drop_k`` σ below it for ``confirm``
      samples, the baseline being the median of the topic's own rate after ``warmup_s`` (frozen
      while alerting); only on a continuous topic (settled, no healthy gap, here or carried: a bursty
      topic's rate baseline says nothing), lasting longer than its longest healthy quiet, and for an
      irregular topic (see silence) ``irregular_drop_s``: its rate follows what reaches its
      publisher (a lossy stream halves for seconds as the host's load changes); the rate compared
      is the recent one (``rate_recent_hz``, the last few intervals) where measured, so a slowed
      topic shows before the collector's window has turned over; not while within one of the
      topic's own modes (`in_mode`): a lower rate it showed and left by itself before, its
      publishers the same processes (a downlink throttled while the link is poor), no deeper
      than half that and no longer than ``gap_margin`` × its longest — the first time, a drop;
      nor when every publisher has an input that went quiet (by its base limit) up to
      ``input_grace_s`` before the drop began, or one such input of an input's publisher
      (`_input_stopped`: a gait state slows as the robot's velocity commands stop, a localiser as
      the odometry, fed by those commands, shows the robot standing; the input's quiet is judged
      on the input), and for ``input_grace_s`` after the input resumed (the recent rate still
      counts the slow intervals);
    * below expectation (warn): ``rate < (1 - expected_tolerance) × expected_rate_hz`` from the
      config, for ``confirm`` samples;
    * a slowed simulation (warn, on ``/clock``): its pace (``sim_pace``, its real-time factor)
      under ``sim_slow_ratio`` × its usual (and not paused) for ``sim_slow_s``: the simulator's
      fault (a heavy scene, a pathological mesh). What runs on simulated time slows with it on our
      clock, which is no drop or silence of those topics: their rates and quiets are judged at the
      simulation's pace against its usual one (frozen while it is slowed).
    """

    name = "topic_rate"
    kinds = ("topic",)
    uses = (cached_baseline,)
    settings: ClassVar[dict[str, Any]] = {
        **BASELINE_SETTINGS,
        "drop_ratio": 0.5,
        "drop_k": 3.0,
        "slow_ratio": 0.8,
        "slow_k": 10.0,
        "slow_drop_s": 10.0,
        "min_baseline_hz": 0.5,
        "confirm": 2,
        "silence_periods": 3.0,
        "silence_min_s": 1.5,
        "complained_min_s": 0.5,
        "expected_tolerance": 0.3,
        "rate_window_s": 3.0,
        "gap_margin": 2.0,
        "min_gaps": 3,
        "settle_messages": 10,
        "flap_window_s": 30.0,
        "transition_grace_s": 2.0,
        "input_grace_s": 5.0,
        "withheld_cpu_ratio": 0.25,
        "withheld_cpu_min": 0.2,
        "stalled_cpu_ratio": 0.05,
        "reconfigure_s": 10.0,
        "judge_latched": False,
        "irregular_cv": 0.3,
        "irregular_horizon_s": 600.0,
        "irregular_drop_s": 15.0,
        "sim_slow_ratio": 0.4,
        "sim_slow_s": 3.0,
        "self_reports": True,
    }

    def check(self, ctx: PluginContext) -> Iterator[Alert]:
        alerting = ctx.state.setdefault("alerting", set())
        ctx.state["interval"] = ctx.since_last_call()  # what this sample's process metrics cover
        rhythms: dict[str, Rhythm] = ctx.state.setdefault("rhythms", {})
        _self_reports(ctx)
        _note_lines(ctx)
        _readers_complaints(ctx)
        for topic, r in rhythms.items():  # before any is followed: a quiet complained of is not learned
            if r.newest is not None and not r.doubted and _complained(ctx, topic, r):
                r.doubted = True  # a sensor's dropout, each with a WARN, is no rhythm of its topic
        for e in ctx.events:  # after: a loop's end is learned, whatever its player said
            if e.kind == "stamp_reset" and e.member in rhythms:
                restarted(rhythms[e.member])
        watched = list(ctx.watched())
        # Every topic's rhythm is followed, so one the RCA starts watching later is judged at once.
        topics = ctx.structural(lambda: set(ctx.members("topic")), key="topics")
        back = ctx.state.setdefault("back", {})  # topic -> the last sample it was new or had no publisher
        ctx.state["prev_t"], ctx.state["now_t"] = ctx.state.get("now_t"), ctx.t
        for topic in topics.difference(watched):
            _note_back(ctx, back, topic)
            rate = ctx.value(topic, "rate_hz")
            if not math.isnan(rate):
                _follow(ctx, _rhythm(ctx, rhythms, topic), topic, rate, None)
        if ctx.diff.removed_members:
            _forget(ctx, rhythms)
        slowed = _simulation_slowed(ctx) if CLOCK in ctx.graph else None
        if slowed is not None:
            yield slowed
        transitions = _transitions(ctx)
        relearn = ctx.state.setdefault("relearn", {})  # topic -> learned anew from (a reconfiguration)
        followed = []  # every rhythm is followed before any is judged: a quiet is judged with its inputs'
        for topic in watched:
            _note_back(ctx, back, topic)
            rate = ctx.value(topic, "rate_hz")
            if math.isnan(rate):
                continue  # not measured
            base = cached_baseline(ctx, topic, "rate_hz", frozen=topic in alerting, since=relearn.get(topic))
            r = _rhythm(ctx, rhythms, topic)
            followed.append((topic, r, rate, base, _follow(ctx, r, topic, rate, base)))
        followed = _reconfigured(ctx, followed, rhythms)
        for topic, r, rate, base, quiet in followed:
            alert = (_silence(ctx, topic, r, quiet, base, transitions, rhythms)
                     or _drop(ctx, topic, r, quiet, rate, base, transitions, rhythms))
            expected = _below_expected(ctx, topic, rate)  # its streak counts every sample
            stopped = _publisher_stopped(ctx, topic, transitions)  # its run counts every sample
            alert = alert or expected or stopped  # one alert per topic and sample
            if alert is not None:
                alerting.add(topic)
                yield alert
            else:
                alerting.discard(topic)


def _reconfigured(ctx: PluginContext, followed: list[tuple], rhythms: dict[str, Rhythm]) -> list[tuple]:
    """Topics whose publisher was reconfigured, or latched a new state of its own (a command gate
    switched to its operator: `_transitions`), follow a new normal (parameters changed at run time:
    a camera's frame rate, a controller's frequency); return ``followed`` with their rhythms and
    baselines learned anew.

    A *cause* is a ``param`` event of a publisher or a state it latched anew, or an input of a
    publisher that follows one
    (data computed from a reconfigured input changes with it), up to ``reconfigure_s`` ago. After
    a cause, a topic whose recent rate departs from its baseline (below ``slow_ratio`` × it, or
    above it / ``slow_ratio``) in messages sent after it, promptly (within ``PROMPT_INTERVALS``
    of its new intervals, or ``transition_grace_s``), has its rhythm and rate baseline learned
    anew from the cause: no drop, no silence against its old rate; not while it is quiet for
    ``STOPPING_PERIODS`` of its periods and a publisher complained (`_complained`: a flaky encoder
    dropping out, each time with a WARN, just as its PLC bridge latched a new state; a sprayer
    slowing its commands with a WARN of its low tank keeps a new steady rate). A quiet whose last message
    came within ``transition_grace_s`` of the cause is not judged (nor learned) until
    ``reconfigure_s`` after it: a slower rate shows its next message by then and is learned; a
    topic still quiet then (a hang that came with the change, a publisher switched off) is judged
    against its old rhythm. A departure that begins later, or a drop under way before the
    change, is no reconfiguration's. A parameter whose change moved no rate (an exposure set every
    cycle) is no cause when it changes again (`_note_changes`).
    """
    s = ctx.settings
    # Any departure that could alert, down to a slow drop's: a rate halved or doubled is measured
    # a hair short of drop_ratio (a camera set from 10 to 5 fps and back shows 5.0 and 9.9).
    window, ratio = s["reconfigure_s"], s["slow_ratio"]
    changed: dict[str, float] = ctx.state.setdefault("reconfigured", {})  # node -> its newest param event
    relearn: dict[str, float] = ctx.state["relearn"]
    _note_changes(ctx, changed, relearn, window)
    for node, at in ctx.state.pop("state_changes", {}).items():  # its mode latched anew: a new normal
        changed[node] = max(at, changed.get(node, at))
    causes: dict[str, float] = ctx.state.setdefault("reconfig_causes", {})  # topic -> the cause it follows
    # topic -> (judged again at, the last message before its quiet)
    deferred: dict[str, tuple[float, float]] = ctx.state.setdefault("reconfig_deferred", {})
    for table, keep in ((changed, window), (causes, window), (relearn, FORGET_S)):
        for k in [k for k, x in table.items() if ctx.t - x > keep]:
            del table[k]
    if not changed and not deferred:
        return followed

    def cause(topic: str) -> float | None:
        pubs = ctx.publishers(topic)
        times = [changed[p] for p in pubs if p in changed]
        times += [causes[i] for p in pubs for i in ctx.subscribed_topics(p) if i != topic and i in causes]
        recent = [x for x in times if 0.0 <= ctx.t - x <= window]
        return max(recent) if recent else None

    out = list(followed)
    for _ in range(len(out)):  # until no input's change is left to pass downstream
        moved = False
        for k, (topic, r, rate, base, quiet) in enumerate(out):
            # A continuous topic, or one re-learned after an earlier change (its new rate may have
            # gaps): a bursty topic's rate and quiets come and go with its rhythm, not a change.
            at = cause(topic) if (r.settled and not r.gaps) or topic in relearn else None
            until, since = deferred.get(topic, (math.inf, r.newest))
            if at is None or ctx.t >= until or r.newest != since:
                if deferred.pop(topic, None) and r.newest == since:  # still quiet when the change
                    r.explained = False  # had time to show: judge it
            if at is None:
                continue
            limit = quiet_limit(r, _base_limit(s, _ref_hz(r, base)), s["gap_margin"])
            grace = s["transition_grace_s"]
            if quiet is not None and quiet >= limit and r.newest is not None \
                    and abs(r.newest - at) <= grace and not (r.departed or r.explained) \
                    and not _complained(ctx, topic, r):
                if topic not in deferred and ctx.t < at + window:
                    deferred[topic], r.explained = (at + window, r.newest), True
                    moved |= causes.get(topic) != at
                    causes[topic] = at
                continue
            recent = ctx.value(topic, "rate_recent_hz")
            now = recent if recent == recent else rate
            if base is None or relearn.get(topic, -math.inf) >= at or not now > 0 \
                    or not (r.newest or -math.inf) > at:  # a new rate shows in messages after the change
                continue
            if quiet is not None and quiet * base[0] >= STOPPING_PERIODS and _complained(ctx, topic, r):
                continue  # quiet now, its publisher saying something went wrong: no new rate
            began = held_since(ctx.state, (topic, "drop"))
            if began is not None and began < at - grace:
                continue  # a drop under way before the change is not the change's
            # A new rate shows within a few of its intervals (the window's rate: once the window
            # turned over), and is seen at the sample after; a change that comes later is not this one.
            step = ctx.state.get("interval", 0.0)
            step = step if step < s["rate_window_s"] else 0.0  # the first call's is unknown
            prompt = max(grace, PROMPT_INTERVALS / now) + step \
                + (0.0 if recent == recent else s["rate_window_s"])
            if ctx.t - at <= prompt and (now < ratio * base[0] or now > base[0] / ratio):
                fresh = Rhythm()
                rhythms[topic], relearn[topic], causes[topic] = fresh, at, at
                deferred.pop(topic, None)
                forget_baseline(ctx, topic, "rate_hz")
                forget_run(ctx.state, (topic, "drop"))
                out[k] = (topic, fresh, rate, None, _follow(ctx, fresh, topic, rate, None))
                moved = True
        if not moved:
            break
    return out


def _note_back(ctx: PluginContext, back: dict[str, float], topic: str) -> None:
    """Note now in ``back`` when ``topic`` was not followed at the previous call (gone from the
    graph, or not yet listed as a topic) or has no publisher: its publishers are judged from
    then on (`_silence`)."""
    followed = ctx.state.setdefault("followed_at", {})
    if followed.get(topic) != ctx.state.get("prev_t") or ctx.value(topic, "publishers") == 0:
        back[topic] = ctx.t
    followed[topic] = ctx.t


def _forget(ctx: PluginContext, rhythms: dict[str, Rhythm]) -> None:
    """Drop the rhythms of topics gone from the graph with no message for ``FORGET_S`` (a topic
    back sooner keeps what it showed: its quiet while gone is a gap like any other, judged from
    its return)."""
    for topic in [m for m, r in rhythms.items() if m not in ctx.graph
                  and (r.newest is None or ctx.t - r.newest > FORGET_S)]:
        del rhythms[topic]


def _ref_hz(r: Rhythm, base: Baseline) -> float:
    """The topic's usual rate while publishing (`Rhythm.rate`), else its baseline."""
    return r.rate if r.rate > 0 else base[0] if base and base[0] > 0 else 0.0


def _base_limit(s: dict[str, Any], ref_hz: float, complained: bool = False) -> float:
    """The shortest quiet that can be a silence: ``max(silence_periods / rate, silence_min_s)``
    (``complained_min_s`` for the floor when a publisher ``complained`` as it went quiet)."""
    floor = s["complained_min_s"] if complained else s["silence_min_s"]
    return max(s["silence_periods"] / ref_hz, floor) if ref_hz > 0 else s["silence_min_s"]


def _rhythm(ctx: PluginContext, rhythms: dict[str, Rhythm], topic: str) -> Rhythm:
    """The topic's rhythm; a new one carries the longest quiet that ended in the healthy run this
    one started from (``ctx.primed["gaps"]``)."""
    r = rhythms.get(topic)
    if r is None:
        r = rhythms[topic] = Rhythm(carried=ctx.primed.get("gaps", {}).get(topic, 0.0))
    return r


def _follow(ctx: PluginContext, r: Rhythm, topic: str, rate: float, base: Baseline) -> float | None:
    """Account this sample in the topic's rhythm; return its quiet (s), None before any message.
    A notable quiet that ends is kept as the topic's longest for a later run (``ctx.learned``,
    `Rhythm.ended`)."""
    s = ctx.settings
    limit = _base_limit(s, _ref_hz(r, base))
    newest = newest_message(ctx.t, rate, ctx.value(topic, "age_s"))
    gap = ctx.value(topic, "gap_s")
    ended = r.ended
    quiet = follow(r, ctx.t, newest, rate, window_s=s["rate_window_s"], notable=limit,
                   settle_s=_settle_s(s, _ref_hz(r, base), limit), margin=s["gap_margin"],
                   min_gaps=s["min_gaps"],
                   gap=0.0 if math.isnan(gap) else gap)
    if r.ended > ended:
        known = ctx.learned.setdefault("gaps", {})
        known[topic] = max(r.ended, known.get(topic, 0.0))
    return quiet


def _settle_s(s: dict[str, Any], ref_hz: float, limit: float) -> float:
    """How long a topic publishes without a notable quiet before it counts as continuous:
    ``warmup_s``, its base limit, and ``settle_messages`` of its periods (a topic at 0.3 Hz has
    sent three messages in 10 s, too few to say it never pauses)."""
    return max(s["warmup_s"], limit, s["settle_messages"] / ref_hz if ref_hz > 0 else 0.0)


def _silence(ctx: PluginContext, topic: str, r: Rhythm, quiet: float | None, base: Baseline,
             transitions: dict[str, list[float]], rhythms: dict[str, Rhythm]) -> Alert | None:
    """Quiet for longer than the topic's own rhythm allows (see `TopicRate`)."""
    s = ctx.settings
    ref = _ref_hz(r, base)
    contested = _contested(ctx, topic, r)
    if quiet is None or not r.settled or (r.explained and not contested):
        return None
    pace = _pace(ctx, topic)  # on simulated time a quiet lasts 1/pace as long on our clock
    judged = quiet * pace if 0 < pace < 1 else quiet
    back = ctx.state["back"].get(topic, -math.inf)
    if r.newest is not None and back > r.newest:  # gone, or without a publisher, since its last
        judged = min(judged, ctx.t - back)  # message: its publishers are judged from their return
    # A quiet its publisher complained of (a driver's "no data-ready interrupt") is a silence
    # from ``complained_min_s``: the floor guards against our own sampling, which it confirms.
    complained = r.doubted
    limit = quiet_limit(r, _base_limit(s, ref, complained), s["gap_margin"])
    if judged >= limit:  # its arrivals may be irregular: then longer quiets come by chance
        limit = max(limit, _by_chance(ctx, topic, ref))
    stalled = False
    if judged < limit:  # within its rhythm, unless its executor stopped under its inputs (then for good)
        base_limit = _base_limit(s, ref)
        if not r.departed and (judged < base_limit or _healthy_quiet(ctx, topic, r, transitions)
                               or not _stalled(ctx, topic, r, rhythms)):
            return None
        stalled, limit = True, base_limit
    if not r.departed and not stalled and _healthy_quiet(ctx, topic, r, transitions):
        r.explained = True
        return None
    if not r.departed and (_inherited(ctx, topic, r, rhythms, transitions) or publishers_busy(ctx, topic)):
        # For good once this sample's process metrics cover only the quiet: a span that began
        # before it (a late sample) may still show a stopped executor's last work.
        r.explained = ctx.t - ctx.state.get("interval", math.inf) >= r.newest
        return None
    # What its publishers do or say explains a quiet none of its readers complains of.
    if not r.departed and not contested and _withheld(ctx, topic, r, rhythms):
        return None  # the topic's own rhythm: learned when it ends, judged again every sample
    if not r.departed and not contested and _announced(ctx, topic, r):
        return None  # it said what it did as it stopped: its state, learned when it ends
    if not r.departed and not contested and _on_request(ctx, topic, r):
        return None  # its quiet is its clients' (learned when it ends)
    if not r.departed and not contested and s["self_reports"] and _vouched(ctx, topic, r, ref):
        return None  # its publishers say they are fine with it quiet: their state, judged every sample
    if not r.departed:  # a new silence: count it for flapping
        r.departed = True
        flaps = ctx.state.setdefault("flaps", {}).setdefault(topic, [])
        flaps[:] = [f for f in flaps if ctx.t - f <= s["flap_window_s"]] + [ctx.t]
    flaps = len(ctx.state["flaps"][topic])
    usual = f"was {ref:.3g} Hz" if not r.gaps else f"its longest healthy gap {max(r.gaps):.1f} s"
    if r.carried:
        usual += f"; {r.carried:.1f} s in the healthy run it started from"
    again = f"; silent {flaps} times in {s['flap_window_s']:.0f} s" if flaps > 1 else ""
    # Its executor stopped: every node it runs stops with it (the RCA ties them, `siblings.stalls`).
    stalled = stalled or _stalled(ctx, topic, r, rhythms)
    if stalled:
        again += "; its executor stopped while its input arrives"
    if complained and quiet < _base_limit(s, ref):
        again += "; its publisher complained as it went quiet"
    if contested:
        reader, line = contested
        again += f"; {name_of(reader)}, which reads it, complains: {line[:120]}"
    if ended := _this_quiet(ctx, topic, r).get("ended"):
        again += f"; {ended} lost a thread as it stopped"
    idle = stalled or _idle(ctx, topic, r)
    if idle and not stalled:
        again += "; its executor's thread idle"
    # When it began: after its last message, by the next one due (the RCA orders causes by it); a
    # topic with gaps has no next message due: anywhere in its quiet.
    bursty = bool(r.gaps or r.carried) and not stalled
    within = quiet if bursty or not ref > 0 else 1.0 / ref
    began = {} if r.newest is None else {"since": r.newest, "since_within": within}
    # When its publisher last logged, any level: on a stopped executor, the one that ran last.
    pubs = ctx.publishers(topic)
    said = ctx.attr(pubs[0], "logged_at") if len(pubs) == 1 else None
    if isinstance(said, int | float):
        began["logged_at"] = float(said)
    return ctx.alert(topic, "error", f"silent for {quiet:.1f} s ({usual}){again}", symptom="silence",
                     silent_s=quiet, baseline_hz=ref, limit_s=limit, flaps=flaps,
                     episode_hold_s=s["flap_window_s"], executor_stopped=stalled, executor_idle=idle,
                     **began)


def _by_chance(ctx: PluginContext, topic: str, ref_hz: float) -> float:
    """The longest quiet an irregular topic shows by chance: ``ln(rate × irregular_horizon_s) /
    rate``, the longest gap of random arrivals at its rate in that time, when its intervals' usual
    spread is ``irregular_cv`` of their mean or more (a reader of a lossy best-effort stream, a
    detector publishing per object found); 0 for a regular topic. The longest quiet seen in the
    first seconds (what `quiet_limit` knows) says little of the next ten minutes of such a topic."""
    if not _irregular(ctx, topic, ref_hz):
        return 0.0
    return math.log(max(2.0, ref_hz * ctx.settings["irregular_horizon_s"])) / ref_hz


def _irregular(ctx: PluginContext, topic: str, ref_hz: float) -> bool:
    """True when the topic's intervals usually spread ``irregular_cv`` of their mean or more
    (its median jitter × its rate): its arrivals follow what reaches its publisher."""
    if ref_hz <= 0:
        return False
    _, jitter = ctx.past(topic, "jitter_ms", last=ctx.settings["window"])
    jitter = jitter[np.isfinite(jitter)]
    return bool(len(jitter)) and float(np.median(jitter)) / 1000.0 * ref_hz >= ctx.settings["irregular_cv"]


def _healthy_quiet(ctx: PluginContext, topic: str, r: Rhythm, transitions: dict[str, list[float]]) -> bool:
    """True when a quiet has a healthy cause: no publisher (an orphan is graph_anomalies' case),
    only transient-local publishers, or a change of state (a lifecycle transition, a goal of its
    action ending) of a publisher or of a node feeding one, within ``transition_grace_s`` of the
    last message."""
    if ctx.value(topic, "publishers") == 0:
        return True
    if _pace(ctx, topic) < PAUSED:  # the simulation paused: its time, and what runs on it, stands
        return True
    if not ctx.settings["judge_latched"] and latched(ctx.attr(topic, "qos")):
        return True
    last = r.newest or ctx.t
    period = 1.0 / r.rate if r.rate > 0 else None
    if r.gaps:  # its next message may be due only after its longest healthy gap
        period = max(period or 0.0, max(r.gaps))
    pubs = ctx.publishers(topic)
    if not _changed_state(ctx, pubs, last, last, transitions, topic, period):
        return False
    if _contested(ctx, topic, r):
        return False  # a change of state its readers did not expect
    if not _complained(ctx, topic, r):
        return True
    # A lifecycle node put in another state says so after it ("Standby", a WARN of a driver not
    # streaming): the state, not trouble. One that complained before its transition changed state
    # because of it (a localiser deactivating itself on an ERROR): that transition excuses nothing.
    return _own_change(ctx, pubs, last, last, ctx.state.get("clean_lifecycle", {}), period)


def _readers_complaints(ctx: PluginContext) -> None:
    """Keep, per topic, the newest complaint of a node that reads it: a WARN or worse on /rosout
    naming the topic (`named_topics`) or a publisher of it (the collector's ``nodes``), from a
    node that receives it (`receives`) and does not publish it."""
    said: dict[str, tuple[float, str, str]] = ctx.state.setdefault("readers_said", {})
    for e in ctx.events:
        if e.kind != "log" or RANK.get(e.level, -1) < RANK["warn"]:
            continue
        read = [t for t in ctx.subscribed_topics(e.member) if e.member not in ctx.publishers(t)]
        if not read:
            continue
        names = set(e.data.get("nodes", ()))
        ns = e.member.removeprefix("node:").rsplit("/", 1)[0]
        hit = {"topic:" + t for t in named_topics(e.text, [t.removeprefix("topic:") for t in read], ns)}
        hit |= {t for t in read if names.intersection(ctx.publishers(t))}
        for topic in hit:  # QoS last: the costliest test, asked only of the topics the line names
            if e.t > said.get(topic, (-math.inf,))[0] and receives(ctx, e.member, topic):
                said[topic] = (e.t, e.member, e.text)


def _contested(ctx: PluginContext, topic: str, r: Rhythm) -> tuple[str, str] | None:
    """(reader, its line) when a node that reads ``topic`` complained of it after its last message
    (`_readers_complaints`): the quiet is not what the system meant, whatever its publishers'
    change of state or word says (a lidar deactivated by hand mid-row, its row follower warning
    "No scan on …/scan for 8.9 s")."""
    said = ctx.state.get("readers_said", {}).get(topic)
    if said is None or r.newest is None or said[0] <= r.newest:
        return None
    return said[1], said[2]


def _inherited(ctx: PluginContext, topic: str, r: Rhythm, rhythms: dict[str, Rhythm],
               transitions: dict[str, list[float]], seen: set[str] | None = None) -> bool:
    """True when every publisher of ``topic`` has an input that went quiet just before it did.

    An input counts when its last message came at most ``input_grace_s`` before the topic's last
    one (data computed from it, or forwarded until a mux's timeout), or before its next was due
    (one of its periods after its last: a node passing on every other image), and it is quiet by
    its own base limit now; while its quiet is shorter than that, the topic waits for it (its own
    last message came first, so its limit comes first too). The topic's quiet is then the
    input's: judged on the input, as a symptom or as healthy (a burst ending, a lifecycle
    transition), never twice. Not an input published in
    the node's own process when that process's single-threaded executor has stopped
    (`_starved_together`), unless the input's quiet has a cause of its own outside that stall.
    """
    pubs = ctx.publishers(topic)
    if not pubs or r.newest is None:
        return False
    s, grace = ctx.settings, ctx.settings["input_grace_s"]
    seen = set() if seen is None else seen  # each topic asked once: the walk stays linear
    seen.add(topic)
    # a node that passes on every n-th input (an image decimated to half its rate) stops with its
    # input, whose last messages may come up to one of its own periods after its last one
    due = r.newest + (1.0 / r.rate if r.rate > 0 else 0.0)

    def stopped(node: str) -> bool:
        for name in ctx.subscribed_topics(node):
            i = rhythms.get(name)
            if name in seen or i is None or i.newest is None:
                continue
            if not r.newest - grace <= i.newest <= due:
                continue
            if ctx.t - i.newest < _base_limit(s, _ref_hz(i, None)):
                # quiet with it, not judged yet (the output's last message came first): after it
                if not _starved_together(ctx, topic, r, node, name):
                    return True
                continue
            if not _starved_together(ctx, topic, r, node, name) \
                    or _healthy_quiet(ctx, name, i, transitions) \
                    or _inherited(ctx, name, i, rhythms, transitions, seen):
                return True
        return False

    return all(stopped(p) for p in pubs)


def _starved_together(ctx: PluginContext, topic: str, r: Rhythm, node: str, name: str) -> bool:
    """True when every publisher of input ``name`` runs in ``node``'s process and that process's
    single-threaded executor has stopped (`_executor_ratio` under ``stalled_cpu_ratio``).

    One blocked callback stops every node on that thread at once, so the order in which their
    outputs went quiet says nothing of which caused which: a hung merger silences the drivers
    that feed it. Its quiet is then no input's, and the RCA ties the stalled nodes (`stalls`)."""
    proc = ctx.process_of(node)
    if proc is None or any(ctx.process_of(p) != proc for p in ctx.publishers(name)):
        return False
    return _executor_stopped(ctx, node, _this_quiet(ctx, topic, r))


def _withheld(ctx: PluginContext, topic: str, r: Rhythm, rhythms: dict[str, Rhythm]) -> bool:
    """True when every publisher of ``topic`` keeps receiving its input and keeps working, and
    publishes nothing on ``topic``: it withholds it (a detector with nothing in view, a filter
    that passes nothing). A hung node stops working; a node waiting on a server it calls is
    a client's stall (the server's symptom), never taken for this.

    Working is seen in another topic only it publishes having published since ``topic`` stopped
    (and not quiet by its own base limit), or, in a process whose executor is single-threaded,
    in that thread's CPU going on at ``withheld_cpu_ratio`` of its usual (`_executor_ratio`),
    scaled by the share of the sample its inputs were arriving. Once seen withheld, the quiet
    stays so while no input arrives (their quiet, judged on them). A multi-threaded process's busy
    threads say nothing of one node: there only another output of the node does.
    """
    pubs = ctx.publishers(topic)
    if not pubs or r.newest is None:
        return False
    q = _this_quiet(ctx, topic, r)
    dip = False
    for node in pubs:
        if ctx.called_servers(node) or _thread_ended(ctx, node, q, r):
            return False
        fed = _fed(ctx, topic, node, r.newest, rhythms)
        ratio = _executor_ratio(ctx, node, q) if fed > 0 else math.nan
        if fed > 0 and (_other_output(ctx, topic, node, r.newest, rhythms)
                        or ratio >= ctx.settings["withheld_cpu_ratio"] * fed):
            continue
        if ratio >= ctx.settings["stalled_cpu_ratio"]:
            dip = True  # working less, not stopped: one sample can dip (a core shared), twice is real
        elif not (fed == 0 and q["withheld"]):  # stopped, or never seen withheld this quiet
            return False
    q["dips"] = q.get("dips", 0) + 1 if dip else 0
    if dip:
        return q["dips"] < STOP_CONFIRM
    q["withheld"] = True
    return True


def _thread_ended(ctx: PluginContext, node: str, q: dict[str, Any], r: Rhythm) -> bool:
    """True when the process of ``node`` ran a steady number of threads (the same in its last
    ``THREADS_STEADY`` samples) before the quiet, and fewer in every sample from ``THREAD_END_S``
    or one period of the topic after its last message (the thread's last loop) on: the thread
    that published, or fed what did, has ended (a driver's reader thread died on an exception)
    while the executor goes on. A node withholding its output keeps its threads. Decided once a
    quiet (kept in ``q``), when the quiet is first judged: a thread ending later is not this
    quiet's."""
    proc = ctx.process_of(node)
    if proc is None:
        return False
    ended = q.setdefault("threads_ended", {})
    if proc not in ended:
        times, past = ctx.past(proc, "threads", last=PROCESS_SETTINGS["window"])
        ok = np.isfinite(past)
        before = past[ok & (times < q["since"])][-THREADS_STEADY:]
        after = q["since"] + max(THREAD_END_S, 1.0 / r.rate if r.rate > 0 else 0.0)
        since = np.append(past[ok & (times >= after)], ctx.value(proc, "threads"))
        steady = len(before) == THREADS_STEADY and before.min() == before.max()
        ended[proc] = bool(steady and np.all(since < before[-1]))  # NaN now compares False
        if ended[proc]:
            q["ended"] = proc
    return ended[proc]


def _note_lines(ctx: PluginContext) -> None:
    """Keep, per node, the times of its newest log lines seen (any level; the collector's
    ``logged_at``, one a sample at most), the newest `LINES_KEPT`."""
    lines: dict[str, deque] = ctx.state.setdefault("lines", {})
    for node in ctx.structural(lambda: list(ctx.members("node")), key="nodes"):
        at = ctx.attr(node, "logged_at")
        if isinstance(at, int | float):
            times = lines.setdefault(node, deque(maxlen=LINES_KEPT))
            if not times or at > times[-1]:
                times.append(float(at))


def _announced(ctx: PluginContext, topic: str, r: Rhythm) -> bool:
    """True when every publisher of ``topic`` logged a line as the topic stopped — from
    ``FEED_SLACK_S`` before its last message to one of its periods and that after it, no routine
    line (`_routine`) — and nothing worse than INFO (`_complained`): a tracker's
    "track lost", a collision avoider's "contact clear; resuming": a node that says what it does
    changed its state. Its output published only while something holds is then quiet by design,
    which a multi-threaded container's threads cannot show (`_withheld`). Not when the line was
    the last act of a stopped single-threaded executor or of a thread that ended (a driver's
    "running calibration" before its read blocks), nor for a node that calls a server (a client
    waiting, the server's symptom). A line and then a hang in a multi-threaded process looks the
    same, and is taken for a change of state."""
    pubs = ctx.publishers(topic)
    if not pubs or r.newest is None or _complained(ctx, topic, r):
        return False
    slack = (1.0 / r.rate if r.rate > 0 else 0.0) + FEED_SLACK_S
    lines, q = ctx.state.get("lines", {}), _this_quiet(ctx, topic, r)
    said = q.setdefault("said", {})  # node -> its line at the stop, once no line can still come
    for node in pubs:
        if node not in said:
            times = list(lines.get(node, ()))
            at = [k for k, x in enumerate(times) if -FEED_SLACK_S <= x - r.newest <= slack]
            # the line before it gone from what is kept: the node logged as many since
            lost = bool(at) and at[0] == 0 and len(times) == LINES_KEPT
            ok = bool(at) and not lost and not _routine(times[:at[0] + 1], ctx.settings["transition_grace_s"])
            if not ok and ctx.t - r.newest <= slack + min(ctx.state.get("interval", 1.0), 5.0):
                return False  # its line may come with the next sample
            said[node] = ok  # later lines do not push it out
        if not said[node] or ctx.called_servers(node) or _executor_stopped(ctx, node, q) \
                or _thread_ended(ctx, node, q, r):
            return False
    return True


def _routine(times: list[float], pause_s: float) -> bool:
    """True when the newest of a node's line ``times`` says nothing of its own: it came under
    ``pause_s`` after the one before (a node that logs all the time), or at the beat of the two
    before (within `BEAT_SHARE` of their interval: a status line every few seconds)."""
    if len(times) < 2:
        return False
    pause = times[-1] - times[-2]
    return pause < pause_s or (len(times) >= 3 and abs(pause - (times[-2] - times[-3]))
                               <= BEAT_SHARE * (times[-2] - times[-3]))


def _on_request(ctx: PluginContext, topic: str, r: Rhythm) -> bool:
    """True when ``topic`` is published on request: it comes one message at a time — at most
    ``ANSWERS_HZ`` while publishing, or in runs between its healthy gaps each under
    ``SINGLE_RUN_S`` — from nodes that each serve a service or an action someone calls. A
    detector that publishes what it found when asked, a planner its plan (a navigator replans at
    1 Hz along a leg and asks nothing between legs): its quiet is its clients' not asking, which
    nothing observed without introspection tells from a hang. The server's own failure shows at
    its clients (the ``services`` plugin: their timeouts and errors name it), not in this topic's
    silence."""
    pubs = ctx.publishers(topic)
    answers = 0 < r.rate <= ANSWERS_HZ or bool(r.gaps and r.runs and max(r.runs) <= SINGLE_RUN_S)
    if not pubs or not answers:
        return False
    served = ctx.structural(lambda: {n for kind in ("service", "action") for m in ctx.members(kind)
                                     if ctx.clients(m) for n in ctx.servers(m)}, key="served")
    return all(p in served for p in pubs)


def _stalled(ctx: PluginContext, topic: str, r: Rhythm, rhythms: dict[str, Rhythm]) -> bool:
    """True when a publisher's single-threaded executor has stopped while the node's inputs arrive
    (at least half of the sample): its thread used under ``stalled_cpu_ratio`` of its usual CPU
    (`_executor_ratio`). A callback blocked for good: the topic's quiet is a silence at its base
    limit, without waiting for twice its longest healthy gap."""
    q = _this_quiet(ctx, topic, r)
    return any(_fed(ctx, topic, node, r.newest, rhythms) >= 0.5
               and _executor_stopped(ctx, node, q)
               for node in ctx.publishers(topic))


def _idle(ctx: PluginContext, topic: str, r: Rhythm) -> bool:
    """True when a publisher's single-threaded executor has stopped (`_executor_ratio` under
    ``stalled_cpu_ratio``), inputs or not: a callback of any node it runs may have blocked it
    (the RCA makes its other nodes candidates: `stream_viz.rca.symptoms`)."""
    q = _this_quiet(ctx, topic, r)
    return any(_executor_stopped(ctx, node, q) for node in ctx.publishers(topic))


def _executor_stopped(ctx: PluginContext, node: str, q: dict[str, Any]) -> bool:
    """True when the single-threaded executor running ``node`` uses under ``stalled_cpu_ratio`` of
    its usual CPU (`_executor_ratio`; False when that is not known)."""
    return _executor_ratio(ctx, node, q) < ctx.settings["stalled_cpu_ratio"]


def _this_quiet(ctx: PluginContext, topic: str, r: Rhythm) -> dict[str, Any]:
    """What is kept for the current quiet of ``topic`` (begun after its newest message)."""
    quiets = ctx.state.setdefault("quiets", {})
    if quiets.get(topic, {}).get("since") != r.newest:  # a new quiet
        quiets[topic] = {"since": r.newest, "refs": {}, "withheld": False}
    return quiets[topic]


def _arriving(ctx: PluginContext, name: str, since: float, rhythms: dict[str, Rhythm]) -> Rhythm | None:
    """The rhythm of topic ``name`` when it published after ``since`` and is not quiet by its
    own base limit now; else None."""
    i = rhythms.get(name)
    if i is None or i.newest is None or i.newest <= since:
        return None
    return i if ctx.t - i.newest < _base_limit(ctx.settings, _ref_hz(i, None)) else None


def _fed(ctx: PluginContext, topic: str, node: str, since: float, rhythms: dict[str, Rhythm]) -> float:
    """The share of this sample's interval that inputs of ``node`` were arriving (0: none came in
    it; an input arriving is one that published after ``since``, the topic's last message)."""
    arriving = [i.newest for name in ctx.subscribed_topics(node) if name != topic
                and (i := _arriving(ctx, name, since, rhythms)) is not None]
    if not arriving:
        return 0.0
    interval = min(ctx.state.get("interval", math.inf), ctx.t - since)
    return min(1.0, max(0.0, (max(arriving) - (ctx.t - interval)) / interval))


def _other_output(ctx: PluginContext, topic: str, node: str, since: float,
                  rhythms: dict[str, Rhythm]) -> bool:
    """True when another topic only ``node`` publishes is arriving (`_arriving`)."""
    return any(o != topic and _arriving(ctx, o, since, rhythms) is not None
               and ctx.publishers(o) == [node] for o in ctx.published_topics(node))


def _executor_ratio(ctx: PluginContext, node: str, q: dict[str, Any]) -> float:
    """The CPU of the single-threaded executor running ``node`` now over its median before the
    quiet (kept for the quiet); NaN when the process's executor is not single-threaded (its
    ``running_threads`` is not 1, or its main thread dispatched a multi-threaded executor in the
    window: while that spins, rclpy#1452, its workers' CPU is too little to count, and the
    dispatcher's resting after it is no stop), unmeasured, or used under ``withheld_cpu_min`` %
    of a core before (too little to tell a pause from a stop). A blocked callback stops that
    thread and every node it runs: 0."""
    proc = ctx.process_of(node)
    if proc is None or ctx.value(proc, "running_threads") != 1 or ctx.value(proc, "dispatching") == 1:
        return math.nan
    if proc not in q["refs"]:
        times, past = ctx.past(proc, EXECUTOR_CPU, last=PROCESS_SETTINGS["window"])
        before = past[(times < q["since"]) & np.isfinite(past)]
        enough = len(before) >= PROCESS_SETTINGS["min_samples"]
        _, dispatched = ctx.past(proc, "dispatching", last=PROCESS_SETTINGS["window"])
        single = not np.any(dispatched == 1.0)
        q["refs"][proc] = float(np.median(before)) if enough and single else math.nan
    ref = q["refs"][proc]
    if not ref >= ctx.settings["withheld_cpu_min"]:
        return math.nan
    return ctx.value(proc, EXECUTOR_CPU) / ref


def latched(qos: Any) -> bool:
    """Return True when every publisher endpoint in the topic attribute ``qos`` (and at least one)
    is transient-local: a latched topic."""
    pubs = [q for q in qos or () if isinstance(q, dict) and q.get("role") == "pub"]
    return bool(pubs) and all(qos_policy(q, "durability") == "transient_local" for q in pubs)


def _transitions(ctx: PluginContext) -> dict[str, list[float]]:
    """Node → times of its recent changes of state (the newest `TRANSITIONS_KEPT`), kept across
    samples: a message on a ``…/transition_event`` topic it publishes (a lifecycle transition),
    a goal of an action it serves ending (a ``goal`` event: `stream_viz.collect.goals`), a
    message on a latched topic it publishes `STATE_GAP_S` or more after the last one (a state
    published on change: a route set, a mission arrived, a mode; not a map republished every
    second)."""
    last: dict[str, list[float]] = ctx.state.setdefault("transitions", {})

    def note(node: str, at: float) -> None:
        times = last.setdefault(node, [])
        if all(abs(x - at) > SAME_MESSAGE_S for x in times):  # the same message seen again
            times[:] = sorted([*times, at])[-TRANSITIONS_KEPT:]

    states = ctx.structural(lambda: [m for m in ctx.members("topic") if latched(ctx.attr(m, "qos"))],
                            key="states", token=ctx.graph.graph.get("qos_version"))
    complaints, clean = ctx.state.setdefault("complaints", {}), ctx.state.setdefault("clean_lifecycle", {})
    grace = ctx.settings["transition_grace_s"]
    for node, at in lifecycle_transitions(ctx):
        note(node, at)
        times = clean.setdefault(node, [])
        # Why it changed state: a line it logs with the transition (stamped by its clock as the
        # transition is sent: the same moment, not a recurring WARN a second before), or a status
        # of its own worse than OK before it; a status it publishes after is the state it is in.
        said = complaints.get(node, ())
        if all(abs(x - at) > SAME_MESSAGE_S for x in times) and not any(
                abs(x - at) < SAME_MESSAGE_S if logged else at - grace <= x < at for x, logged in said):
            times[:] = sorted([*times, at])[-TRANSITIONS_KEPT:]
    newest: dict[str, float] = ctx.state.setdefault("state_newest", {})
    for topic in states:
        age = ctx.value(topic, "age_s")
        if age != age:
            continue
        at, before = ctx.t - age, newest.get(topic)
        if before is None or at - before > SAME_MESSAGE_S:  # a message not seen before
            newest[topic] = at
            if before is None or at - before >= STATE_GAP_S:
                for node in ctx.publishers(topic):
                    note(node, at)
                    ctx.state.setdefault("state_changes", {})[node] = at  # a new mode: `_reconfigured`
    said = ctx.state.setdefault("modes_said", {})
    for e in ctx.events:
        if e.kind == "goal":
            note(e.member, e.t)
        elif e.kind == "diag" and e.member.startswith("node:") and e.member == e.data.get("publisher"):
            mode = announced_mode(e)
            before = said.get((e.member, e.data.get("name")))
            said[(e.member, e.data.get("name"))] = mode
            if mode is not None and before is not None and mode != before:
                note(e.member, e.t)
    return last


def _self_reports(ctx: PluginContext) -> None:
    """Keep, per node, when it last said OK of itself on /diagnostics and when it last said worse:
    a status of its own worse than OK (published by the node it is mapped to, not an aggregator's
    copy), or a WARN or worse on /rosout; and when it last said worse *again* (`_vouched`): such
    a status, an ERROR or worse, or a WARN within `WARN_REPEAT_S` of its last WARN."""
    # node -> [ok at, worse at, worse again at, its last WARN line at]
    said: dict[str, list[float]] = ctx.state.setdefault("self_reports", {})
    complaints = ctx.state.setdefault("complaints", {})  # node -> (when, logged: a line, not a status)
    for e in ctx.events:
        if e.kind == "diag" and e.member.startswith("node:") and e.member == e.data.get("publisher"):
            k = 0 if e.data.get("level") == 0 else 1
        elif e.kind == "log" and RANK.get(e.level, -1) >= RANK["warn"]:
            k = 1
        else:
            continue
        last = said.setdefault(e.member, [-math.inf] * 4)
        last[k] = max(last[k], e.t)
        if k and e.kind == "log" and RANK.get(e.level, -1) == RANK["warn"]:
            if e.t - last[3] <= WARN_REPEAT_S:
                last[2] = max(last[2], e.t)
            last[3] = max(last[3], e.t)
        elif k:
            last[2] = max(last[2], e.t)
        if k:  # when, as well as the last time: a lifecycle transition asks what came before it
            recent = complaints.setdefault(e.member, deque(maxlen=COMPLAINTS_KEPT))
            recent.append((e.t, e.kind == "log"))
            while e.t - recent[0][0] > COMPLAINTS_KEPT_S:  # O(1) a line, a node WARNing at 100 Hz too
                recent.popleft()


def _complained(ctx: PluginContext, topic: str, r: Rhythm) -> bool:
    """True when a publisher of ``topic`` said something was wrong as it went quiet: a WARN or
    worse on /rosout, or a status of its own worse than OK, from ``transition_grace_s`` before
    its last message on (`_self_reports`). A node that complains as its output stops did not
    stop it for a change of state it made: the change does not excuse the quiet nor make its rate
    a new normal (a PLC bridge latching a new state each cycle, its flaky encoder's dropouts each
    with a WARN). Its complaint says nothing of a quiet it withholds while it works, though (an
    acoustic modem's lost packet, a WARN each: a lossy input)."""
    since = (r.newest if r.newest is not None else ctx.t) - ctx.settings["transition_grace_s"]
    said = ctx.state.get("self_reports", {})
    return any(said[n][1] >= since for n in ctx.publishers(topic) if n in said)


def _vouched(ctx: PluginContext, topic: str, r: Rhythm, ref_hz: float) -> bool:
    """True when every publisher of ``topic`` said OK of itself after the topic's next message was
    due, and nothing worse since its last message — a status worse than OK, an ERROR, a WARN again
    within `WARN_REPEAT_S` of its last (one WARN is routine: the blind USV's AIS receiver dropped
    a sentence 39 s into a quiet with no ship in range) —: a driver that keeps reporting its device fine
    while its output stops means it (a USBL receiver with the vehicle on the surface), where a
    driver's frequency check, a crash or a stalled executor says otherwise or stops its reports.
    Not when a publisher's process lost a thread as the topic stopped (`_thread_ended`): a reader
    thread that died beside a self-check that does not watch it."""
    pubs = ctx.publishers(topic)
    if not pubs or r.newest is None:
        return False
    period = max(1.0 / ref_hz if ref_hz > 0 else 0.0, max(r.gaps) if r.gaps else 0.0)
    said = ctx.state.get("self_reports", {})
    if not all(n in said and said[n][0] > r.newest + period and said[n][2] < r.newest for n in pubs):
        return False
    q = _this_quiet(ctx, topic, r)
    return not any(_thread_ended(ctx, n, q, r) for n in pubs)


def announced_mode(e: Any) -> str | None:
    """The mode a node's own OK status says it is in (``camera_status: OK idle``; numbers left
    out, so a reading that changes is no new mode), or None for a status not OK."""
    name = str(e.data.get("name", ""))
    if e.data.get("level") != 0:
        return None
    text = e.text.removeprefix(f"{name}:").strip().removeprefix("OK").strip()
    return _NUMBER.sub("#", text)


def _drop(ctx: PluginContext, topic: str, r: Rhythm, quiet: float | None, rate: float,
          base: Baseline, transitions: dict[str, list[float]], rhythms: dict[str, Rhythm]) -> Alert | None:
    """The recent rate below ``drop_ratio`` × the baseline (and ``drop_k`` σ) for ``confirm``
    samples, on a continuous topic that is not quiet (a quiet is a silence or not: `_silence`),
    nor stopping for a healthy cause (its recent rate falls as it stops: a goal ended), nor
    following an input that went quiet as it fell (`_input_stopped`)."""
    s = ctx.settings
    # A topic with healthy gaps, in this run or the healthy one it started from, is bursty.
    if base is None or base[0] < s["min_baseline_hz"] or not r.settled or r.gaps or r.carried:
        return None
    stopping = quiet is not None and quiet >= STOPPING_PERIODS / base[0]
    if stopping and _healthy_quiet(ctx, topic, r, transitions):
        streak(ctx.state, (topic, "drop"), False)
        return None
    if r.longest >= _base_limit(s, _ref_hz(r, base)):  # quiets no continuous topic shows: sparse bursts
        return None
    recent = ctx.value(topic, "rate_recent_hz")
    now_rate = recent if recent == recent else rate
    med, sigma, _ = base
    quieting = quiet is not None and quiet >= _base_limit(s, med)
    pace = _pace(ctx, topic)
    expect = med * pace  # on simulated time, the rate follows the simulation's pace
    per_sim = _per_simulated_second(ctx, topic) if pace != 1.0 else None
    if per_sim is not None:  # sample by sample: a baseline over a wandering pace blurs the median
        now_pace = ctx.value(CLOCK, "sim_pace")
        expect, sigma = per_sim[0] * now_pace, per_sim[1] * now_pace
    # An empty window is a quiet (judged by `_silence`), not a lower rate.
    deep = 0 < now_rate < s["drop_ratio"] * expect and expect - now_rate >= s["drop_k"] * sigma
    # A steady topic slowed by a fifth or more, far outside its own spread, for long: a sensor
    # dropping one message in three (a link that lost its requested interval) is no load hiccup.
    # One publisher's own stream: several interleave, and one joining or pausing moves the sum.
    slow = (0 < now_rate < s["slow_ratio"] * expect and expect - now_rate >= s["slow_k"] * sigma
            and len(ctx.publishers(topic)) == 1)
    lost = (deep or slow) and _lost_on_the_way(ctx, topic, rate, med)
    deep, slow = not quieting and deep and not lost, not quieting and slow and not lost
    # A drop lasts longer than any healthy pause of the topic (its recent rate counts a pause).
    # The slow tier keeps its own streak: a pause's edges (a window half full) must not lengthen
    # a deep drop's.
    samples, lasted = streak(ctx.state, (topic, "drop"), deep), held(ctx.state, (topic, "drop"), deep, ctx.t)
    slower = deep or slow
    slow_n = streak(ctx.state, (topic, "slow"), slower)
    slow_s = held(ctx.state, (topic, "slow"), slower, ctx.t)
    if not deep and slow:
        samples, lasted = slow_n, slow_s
    # Modes hold in later runs of the robot (`learned`): a link steps down again as it did then.
    known = ctx.learned.setdefault("modes", {})
    modes = known.get(topic, [])
    ratio = now_rate / expect if expect > 0 else 1.0
    run = _drop_run(ctx, topic, deep, ratio, quieting)  # deep runs only: modes as they were learned
    if run is not None:  # a drop that ended by itself, the topic back at its rate: one of its modes
        modes = known[topic] = learn_mode(modes, *run)
    # A slow drop holds for slow_drop_s and as many samples in a row (at the default 1 s period):
    # a topic gone from the graph between two slow samples is not judged between them.
    if (samples < s["confirm"] or lasted < r.longest
            or (not deep and (lasted < s["slow_drop_s"] or samples < s["slow_drop_s"]))):
        return None
    # Its rate follows what reaches it (a gait published slower as its commands stop); once so,
    # this drop stays the input's for input_grace_s after the input resumed: the recent rate
    # still counts the slow intervals when the input's first messages are back.
    follows = ctx.state.setdefault("drop_follows", {})  # topic -> (its drop's start, last explained)
    start = held_since(ctx.state, (topic, "drop" if deep else "slow"))
    start = ctx.t - lasted if start is None else start
    if _input_stopped(ctx, topic, start, rhythms):
        follows[topic] = (start, ctx.t)
        return None
    if follows.get(topic, (None, -math.inf))[0] == start and ctx.t - follows[topic][1] <= s["input_grace_s"]:
        return None
    level = s["drop_ratio"] if deep else s["slow_ratio"]
    if in_mode(modes, ratio, lasted, s["gap_margin"]) or _low_before(ctx, topic, now_rate, expect, lasted,
                                                                     level):
        return None  # a lower rate it has shown and left by itself (a link throttled, a mode)
    steady = per_sim is not None and per_sim[1] <= STEADY_PER_SIM * per_sim[0]
    if lasted < s["irregular_drop_s"] and not steady and _irregular(ctx, topic, med):
        return None  # its rate follows a lossy or event-driven input: it halves for seconds by chance
    sim = f" (the simulation at {pace:.2g}× its usual pace)" if abs(pace - 1.0) > 0.1 else ""
    usual = expect if per_sim is not None else med
    return ctx.alert(topic, "warn", f"rate {now_rate:.3g} Hz, down from {usual:.3g} Hz{sim}",
                     symptom="rate_drop", rate_hz=now_rate, baseline_hz=usual, sim_pace_ratio=pace)


def _low_before(ctx: PluginContext, topic: str, now_rate: float, expect: float, lasted: float,
                ratio: float) -> bool:
    """True when the topic's rate was below ``ratio`` (the drop's tier) × ``expect``, and at most twice
    ``now_rate``, for a spell earlier in its history that ended by itself (after the
    collector's ``rate_window_s`` first filled, and since the rate was last learned anew), for
    ``confirm`` s at least, and
    this drop has lasted no longer than ``gap_margin`` × the longest such spell (`excursions`):
    a mode it showed before its rate was learned at the higher one, which `learn_mode` cannot
    know (a localiser at 1 Hz while the robot stands and at 10 Hz while it drives, its first
    minutes spent driving)."""
    s = ctx.settings
    times, rates = ctx.past(topic, "rate_hz")
    # Not while the collector's window first filled, nor before the rate was learned anew (a
    # reconfiguration's rate is no spell of the old one).
    since = max(times[0] + s["rate_window_s"] if len(times) else math.inf,
                ctx.state["relearn"].get(topic, -math.inf))
    keep = times >= since
    if not keep.any():
        return False
    level = min(ratio * expect, 2.0 * now_rate)  # as low as now, or half as low at most
    _, longest = excursions(np.append(times[keep], ctx.t), -np.append(rates[keep], now_rate), -level)
    return longest >= s["confirm"] and lasted <= s["gap_margin"] * longest


def _input_stopped(ctx: PluginContext, topic: str, since: float, rhythms: dict[str, Rhythm]) -> bool:
    """True when every publisher of ``topic`` has an input, or an input of an input's publisher
    (``UPSTREAM_HOPS``), whose last message came at most ``input_grace_s`` before its drop began
    (``since``) and no later, and that is quiet by its own base limit now: the publisher runs
    slower as what it follows stops, as `_inherited` makes a quiet the input's. A legged robot's
    gait state, 50 Hz walking and 10 Hz standing, slows as its velocity commands stop; a
    localiser that updates on motion slows as the base's odometry, which goes on, shows it
    standing, its commands having stopped one hop further up. The input's quiet is judged on the
    input."""
    pubs = ctx.publishers(topic)
    if not pubs:
        return False
    s = ctx.settings

    def stopped(node: str, hops: int, seen: set[str]) -> bool:
        for name in ctx.subscribed_topics(node):
            i = rhythms.get(name)
            if name in seen or i is None or i.newest is None:
                continue
            seen.add(name)
            if since - s["input_grace_s"] <= i.newest <= since \
                    and ctx.t - i.newest >= _base_limit(s, _ref_hz(i, None)):
                return True
            if hops > 1 and any(stopped(p, hops - 1, seen) for p in ctx.publishers(name)):
                return True
        return False

    return all(stopped(p, UPSTREAM_HOPS, {topic}) for p in pubs)


def _drop_run(ctx: PluginContext, topic: str, low: bool, ratio: float,
              quieting: bool) -> tuple[float, float] | None:
    """Follow the topic's current run of low samples; return ``(lowest ratio, seconds)`` of one
    that just ended by itself: the topic back above ``drop_ratio`` of its rate, not gone quiet,
    its publishers the same processes (a node restarted by hand ends its drop by the restart)."""
    runs = ctx.state.setdefault("drop_runs", {})
    run = runs.get(topic)
    if run is None and not low:  # most topics, most samples: nothing to follow
        return None
    pids = tuple(sorted(str(ctx.attr(n, "pid")) for n in ctx.publishers(topic)))
    if run is not None and ctx.t - run["last"] > RUN_LAPSE_S:  # not followed a while: unknown end
        del runs[topic]
        run = None
    if low:
        if run is None:
            runs[topic] = {"start": ctx.t, "lowest": ratio, "pids": pids, "samples": 1, "last": ctx.t}
        else:
            run["lowest"], run["samples"] = min(run["lowest"], ratio), run["samples"] + 1
            run["last"] = ctx.t
        return None
    if run is None:  # lapsed
        return None
    del runs[topic]
    back = not quieting and ratio >= ctx.settings["drop_ratio"] and pids == run["pids"]
    if back and run["samples"] >= ctx.settings["confirm"]:
        return run["lowest"], ctx.t - run["start"]
    return None


def learn_mode(modes: list[tuple[float, float]], lowest: float, seconds: float,
               keep: int = 8) -> list[tuple[float, float]]:
    """Return ``modes`` (``(lowest ratio to the usual rate, seconds)`` of the drops a topic showed
    and left by itself) with one more, the newest ``keep``.

    A topic that throttles itself for a while (a telemetry link at low quality, a camera in a
    power-saving mode) shows the same lower rate again; a degraded one does not leave it.
    """
    return [*modes, (lowest, seconds)][-keep:]


def in_mode(modes: list[tuple[float, float]], ratio: float, lasted: float, margin: float) -> bool:
    """True when a drop to ``ratio`` of the usual rate, ``lasted`` s so far, is within one of the
    topic's own ``modes`` (`learn_mode`): no deeper than half its lowest ratio, and no longer than
    ``margin`` × the longest it lasted. A drop that outlasts it is judged as any drop is."""
    return any(ratio >= 0.5 * lowest and lasted <= margin * seconds for lowest, seconds in modes)


def _pace(ctx: PluginContext, topic: str) -> float:
    """The simulation's pace now over its usual pace (``/clock``'s ``sim_pace``) when every
    publisher of ``topic`` runs on simulated time (it subscribes ``/clock``: ``use_sim_time``);
    1 otherwise. Their timers tick on simulated time, so on our clock their rates follow the
    simulation's real-time factor: a simulator slowed by a heavy scene is no drop."""
    if topic == CLOCK or CLOCK not in ctx.graph:  # no simulation: no graph walk per topic
        return 1.0
    pubs = ctx.publishers(topic)
    if not pubs or not all(CLOCK in ctx.subscribed_topics(p) for p in pubs):
        return 1.0
    now = ctx.value(CLOCK, "sim_pace")
    base = cached_baseline(ctx, CLOCK, "sim_pace", frozen=ctx.state.get("sim_slow", False))
    if not now >= 0 or base is None or not base[0] > 0:
        return 1.0
    return now / base[0]


def _per_simulated_second(ctx: PluginContext, topic: str) -> tuple[float, float] | None:
    """The topic's rate per simulated second (its rate over ``/clock``'s pace, sample by sample):
    robust median and σ over the baseline window, recomputed every ``refresh_s`` as the other
    baselines and kept while the topic alerts; None when fewer than ``min_samples`` samples have
    both."""
    s, cache = ctx.settings, ctx.state.setdefault("per_sim", {})
    hit = cache.get(topic)  # (next refresh time, baseline or None)
    if hit is not None and (ctx.t < hit[0] or topic in ctx.state.get("alerting", ())):
        return hit[1]
    t_rate, rate = ctx.past(topic, "rate_hz", last=s["window"])
    t_pace, pace = ctx.past(CLOCK, "sim_pace", last=s["window"])
    _, i, j = np.intersect1d(t_rate, t_pace, return_indices=True)
    ok = np.isfinite(rate[i]) & (pace[j] > 0.01)  # a paused simulation has no rate per second
    per = rate[i][ok] / pace[j][ok]
    found = None if len(per) < s["min_samples"] else robust(per)[:2]
    cache[topic] = (ctx.t + (s["refresh_s"] if found is not None else 1.0), found)
    return found


def _simulation_slowed(ctx: PluginContext) -> Alert | None:
    """The simulation at under ``sim_slow_ratio`` of its usual pace, not paused, for ``sim_slow_s``
    (its usual pace frozen meanwhile, as `_pace` reads it)."""
    s = ctx.settings
    now = ctx.value(CLOCK, "sim_pace")
    base = cached_baseline(ctx, CLOCK, "sim_pace", frozen=ctx.state.get("sim_slow", False))
    usual = base[0] if base is not None else math.nan
    slow = usual > 0 and PAUSED * usual <= now < s["sim_slow_ratio"] * usual
    ctx.state["sim_slow"] = slow
    if held(ctx.state, (CLOCK, "sim_slow"), slow, ctx.t) < s["sim_slow_s"] or not slow:
        return None
    return ctx.alert(CLOCK, "warn", f"the simulation runs at {now:.2g}× real time, usually {usual:.2g}×: "
                     "everything on simulated time slows with it", symptom="sim_slow", sim_pace=now,
                     baseline_pace=usual)


def _note_changes(ctx: PluginContext, changed: dict[str, float], relearn: dict[str, float],
                  window: float) -> None:
    """Note this sample's ``param`` events in ``changed`` (node → its newest change), except those
    that change only parameters known to move no rate: changes after which no topic was learned
    anew within ``window``, `INERT_AFTER` of them in a row, mark their parameters so (per node;
    one can be missed: a new rate that showed a moment too late; a change while a topic of the node
    alerts is not counted: its baseline is frozen, a move cannot show). A node that sets one parameter
    every cycle (an executive tuning a camera's exposure) otherwise keeps its topics in a state
    where any drop is taken for the change's new normal."""
    inert: set[tuple[str, str]] = ctx.state.setdefault("inert_params", set())
    misses: dict[tuple[str, str], int] = ctx.state.setdefault("param_misses", {})
    # (when, node, names, whether a topic of the node was alerting then or since)
    pending: list[tuple[float, str, set[str], bool]] = ctx.state.setdefault("param_pending", [])
    _note_frozen(ctx, pending)
    while pending and ctx.t - pending[0][0] > window:
        at, node, names, frozen = pending.pop(0)
        moved = any(at <= x <= at + window for x in relearn.values())  # something learned anew after it
        if not moved and frozen:
            continue  # its topic's baseline was frozen by an alert: a move could not show
        for key in ((node, n) for n in names):
            misses[key] = 0 if moved else misses.get(key, 0) + 1
            if misses[key] >= INERT_AFTER:
                inert.add(key)
    for e in ctx.events:
        if e.kind != "param":
            continue
        names = {*e.data.get("changed", {}), *e.data.get("deleted", ())}
        if names and all((e.member, n) in inert for n in names):
            continue
        changed[e.member] = max(e.t, changed.get(e.member, e.t))
        pending.append((e.t, e.member, names, False))
    _note_frozen(ctx, pending)


def _note_frozen(ctx: PluginContext, pending: list[tuple[float, str, set[str], bool]]) -> None:
    """Mark the pending changes of nodes with a topic alerting now (its baseline frozen)."""
    alerting = ctx.state.get("alerting", set())
    for k, (at, node, names, frozen) in enumerate(pending):
        if not frozen and alerting & set(ctx.published_topics(node)):
            pending[k] = (at, node, names, True)


def _publisher_stopped(ctx: PluginContext, topic: str, transitions: dict[str, list[float]]) -> Alert | None:
    """One publisher of a topic others go on publishing sent nothing in the collector's window
    after sending in each of its last ``STEADY_SAMPLES`` samples (``publisher_rates``: whose
    messages they were; a node that left the topic's publishers and came back starts afresh),
    and has never before stopped and resumed by itself (a publisher that
    does publishes in bursts: a joystick while held). The topic's rate hides it (``/tf`` from
    four nodes loses a quarter); the others still flowing, the stop is that publisher's. Not
    when the node changed state, or a node feeding it did, around its stop (`_healthy_quiet`),
    nor for a node gone from the graph (``member_gone``'s), nor while the simulation its
    publishers run on is paused."""
    rates = ctx.attr(topic, "publisher_rates") or {}
    # topic -> node -> (samples sending, stopped at); a node no longer publishing it is forgotten:
    # one that comes back (restarted by hand, relaunched) is a new publisher, silent until it sends.
    runs = ctx.state.setdefault("publisher_runs", {}).setdefault(topic, {})
    for node in runs.keys() - rates.keys():
        del runs[node]
    intermittent = ctx.state.setdefault("intermittent", set())  # (topic, node) that stopped and resumed
    stopped = []
    for node, hz in rates.items():
        sending, since = runs.get(node, (0, None))
        if hz > 0:
            if since is not None:  # it resumed by itself: it publishes in bursts (a joystick held)
                intermittent.add((topic, node))
            runs[node] = ((sending if since is None else 0) + 1, None)
            continue
        since = ctx.t if since is None else since
        runs[node] = (sending, since)
        if sending >= STEADY_SAMPLES and (topic, node) not in intermittent and ctx.attr(node, "alive", True):
            stopped.append((node, since))
    others = sum(hz for hz in rates.values() if hz > 0)
    if not stopped or not others or _pace(ctx, topic) < PAUSED:
        return None
    window = ctx.settings["rate_window_s"]  # its last message came within the window before
    stopped = [(n, at) for n, at in stopped
               if not _changed_state(ctx, [n], at - window, at, transitions, topic)]
    if not stopped:
        return None
    names = ", ".join(name_of(n) for n, _ in stopped)
    return ctx.alert(topic, "warn", f"{names} stopped publishing it ({others:.3g} Hz from the others)",
                     symptom="publisher_stopped", publishers=[n for n, _ in stopped])


def _changed_state(ctx: PluginContext, nodes: list[str], since: float, until: float,
                   transitions: dict[str, list[float]], topic: str, period: float | None = None) -> bool:
    """True when one of ``nodes`` (publishers of ``topic``), or a node feeding one through another
    topic, changed state from ``transition_grace_s`` before ``since`` to as long after ``until``
    (a lifecycle transition, a goal ended, a new state latched); a publisher's own change also
    while its next message was not due yet (``until`` plus the topic's ``period`` and
    ``FEED_SLACK_S``: an ETA published every 10 s stops when its route arrives). A node that
    follows another's goal (a controller driving the path of its planner's goal) stops with it;
    so a feeding node's change comes before the stop, by ``until`` plus a period and
    ``FEED_SLACK_S`` at the latest: one later is the stop's consequence (a mission aborted because
    its setpoints stopped)."""
    if _own_change(ctx, nodes, since, until, transitions, period):
        return True
    grace = ctx.settings["transition_grace_s"]
    feeding = {u for p in nodes for i in ctx.subscribed_topics(p) if i != topic for u in ctx.publishers(i)}
    after = grace if period is None else min(grace, period + FEED_SLACK_S)
    upstream = (x for p in feeding.difference(nodes) for x in transitions.get(p, ()))
    return any(since - grace <= x <= until + after for x in upstream)


def _own_change(ctx: PluginContext, nodes: list[str], since: float, until: float,
                transitions: dict[str, list[float]], period: float | None) -> bool:
    """True when one of ``nodes`` changed state (a time in ``transitions``) from
    ``transition_grace_s`` before ``since`` to as long after ``until``, or while its next message
    was not due yet (``until`` plus ``period`` and ``FEED_SLACK_S``): `_changed_state`'s own part."""
    grace = ctx.settings["transition_grace_s"]
    due = until + (period + FEED_SLACK_S if period is not None else 0.0)
    return any(since - grace <= x <= max(until + grace, due) for p in nodes for x in transitions.get(p, ()))


def _lost_on_the_way(ctx: PluginContext, topic: str, rate: float, med: float) -> bool:
    """True when most of what the window lacks against the baseline ``med`` are gaps in the
    publisher's sequence numbers (``drops_per_s``, known with one publisher): it sent them and
    they were lost on the way to the monitor (its own receive on a loaded host, a busy link),
    which the robot's reliable subscribers do not see. Not a lower rate of the publisher."""
    drops = ctx.value(topic, "drops_per_s")
    missing = med - rate
    return drops == drops and missing > 0 and drops >= 0.5 * missing


def _below_expected(ctx: PluginContext, topic: str, rate: float) -> Alert | None:
    """The rate below ``(1 - expected_tolerance)`` × the configured rate for ``confirm`` samples."""
    expected = ctx.expected_rates.get(topic)
    if not expected:
        return None
    low = rate < (1.0 - ctx.settings["expected_tolerance"]) * expected
    if streak(ctx.state, (topic, "expected"), low) < ctx.settings["confirm"]:
        return None
    return ctx.alert(topic, "warn", f"rate {rate:.3g} Hz, expected {expected:.3g} Hz",
                     symptom="below_expected", rate_hz=rate, expected_hz=expected)
