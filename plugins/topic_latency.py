"""Topic latency or jitter rising above the topic's own baseline; messages dropped."""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping
from typing import Any, ClassVar

import numpy as np

from stream_viz.detect.api import Plugin, PluginContext
from stream_viz.detect.baseline import BASELINE_SETTINGS, confirm, excess, held, held_since
from stream_viz.detect.process import publishers_busy
from stream_viz.model.qos import qos_policy
from stream_viz.records import Alert


class TopicLatency(Plugin):
    """Alerts on latency / jitter rises and on message drops of watched topics.

    A rise counts when ``value - median ≥ max(k·σ, min_rise_ms)`` (σ = 1.4826·MAD of the topic's
    own past after ``warmup_s``; also ≥ ``jitter_period_ratio`` × the period for jitter,
    ``latency_period_ratio`` × the period for latency) and the value is also that floor above
    what the topic often shows (the ``usual_quantile`` of the same past: the jitter of a topic
    that publishes in bursts includes its gaps in some windows and not in others, a two-valued
    past whose median says nothing) for ``confirm`` samples in a row; drops likewise, risen by
    ``max(drops_min_per_s, drops_ratio × rate)`` above the topic's own (`_drops`). Only
    samples with a message newer than the previous sample count (``age_s``): a topic slower than
    the sampling keeps one late message in its window for several samples, which is one
    observation, not ``confirm``. A rise must also have held for ``latency_hold_s`` /
    ``jitter_hold_s``, longer than the collector's 3 s window: its latency is the mean and its
    jitter the spread over the window, so one late message (a publisher or the network busy for
    a moment while a participant joins) or one gap (a mux switching sources, a process stalled)
    holds the value up for the whole window, on a slow topic at several times its baseline;
    only a rise that outlasts the window is a change of the topic. Jitter is not judged while
    several publishers send on the topic (`_interleaved`), nor while an input of its publisher
    started or stopped within the last ``switch_samples`` (`_inputs_switched`: a mux handing over
    to a joystick, a relay of an on-demand topic forwards what comes, when it comes), nor while
    the topic's endpoints changed in number within them (`_endpoints_changed`: a recorder
    joining). Neither latency nor jitter is judged while every publisher's process is busy in the
    main thread that dispatches its multi-threaded executor (`publishers_busy`, ``dispatched``: callbacks
    wait for a worker while it spins, rclpy#1452; no node is at fault).

    Carried from a healthy run (``--healthy``): a rise like one it showed, that ended by itself,
    is its normal (`_shown_before`) while no more than ``carried_margin`` × as high and as long.

    Common mode: when at least ``common_mode_min`` topics and ``common_mode_ratio`` of the topics
    measured in a sample rise at once, the sample is a stall of the host or of the monitor (the
    receive stamps are ours), not a fault of those topics' publishers: it neither counts nor
    breaks a streak, raises no alert (a rise held up through it alerts at the next sample that
    counts, if it still holds), and the stall is counted in the plugin state (``common_mode``). So is one
    where that holds of one attribute among the topics that could show it, and the risen topics
    come from more than one process: a stall of 40 ms cannot show on a 1 Hz topic.
    """

    name = "topic_latency"
    kinds = ("topic",)
    uses = (excess, confirm)
    settings: ClassVar[dict[str, Any]] = {
        **BASELINE_SETTINGS,
        "k": 6.0,
        "latency_min_rise_ms": 20.0,
        "jitter_min_rise_ms": 20.0,
        "jitter_period_ratio": 0.5,
        "latency_period_ratio": 0.1,
        "confirm": 3,
        "drops_min_per_s": 1.0,
        "drops_ratio": 0.05,
        "drops_hold_s": 4.0,
        "common_mode_min": 4,
        "common_mode_ratio": 0.5,
        "usual_quantile": 0.9,
        "latency_hold_s": 4.0,
        "jitter_hold_s": 4.0,
        "switch_samples": 8,
        "carried_margin": 2.0,
    }

    def check(self, ctx: PluginContext) -> Iterator[Alert]:
        s = ctx.settings
        alerting = ctx.state.setdefault("alerting", set())
        since = ctx.since_last_call()
        seen = []  # (topic, attr, excess, fresh)
        floors = {}  # (topic, attr) -> the least rise that counts
        drops = []
        for topic in ctx.watched():
            age = ctx.value(topic, "age_s")
            fresh = age != age or age < since  # a message since the last sample (age unknown: yes)
            rate = ctx.value(topic, "rate_hz")
            for attr in ("latency_ms", "jitter_ms"):
                if attr == "jitter_ms" and _interleaved(ctx, topic):
                    continue
                floor = _least_rise(s, attr, rate)
                ex = excess(ctx, topic, attr, floor, alerting)
                ex = _above_usual(ctx, topic, attr, floor, ex, alerting)
                if attr == "jitter_ms" and ex is not None and ex[2] and (
                        _inputs_switched(ctx, topic, s["switch_samples"])
                        or _endpoints_changed(ctx, topic, s["switch_samples"])):
                    continue
                if ex is not None and ex[2] and publishers_busy(ctx, topic, dispatched=True):
                    continue
                seen.append((topic, attr, ex, fresh))
                floors[topic, attr] = floor
            drops += _drops(ctx, topic, rate, fresh, alerting)
        stall = common_mode(seen, s["common_mode_min"], s["common_mode_ratio"], floors,
                            lambda t: set(filter(None, map(ctx.process_of, ctx.publishers(t)))))
        if stall:
            ctx.state["common_mode"] = ctx.state.get("common_mode", 0) + 1
        for topic, attr, ex, fresh in seen:
            counts = fresh and not stall
            risen = confirm(ctx, topic, attr, ex, alerting, counts)
            up = ex is not None and ex[2]
            began = held_since(ctx.state, (topic, attr))  # before held() may end the rise
            lasted = held(ctx.state, (topic, attr), up, ctx.t, counts)
            if counts:
                _keep_rise(ctx, topic, attr, ex[0] if up else None, began)
            what = attr.removesuffix("_ms")
            # A stall of the host holds a rise up but says nothing of the topic: no alert from it.
            if risen is not None and not stall and lasted >= s[f"{what}_hold_s"] \
                    and not _shown_before(ctx, topic, attr, risen[0], lasted):
                value, med = risen
                yield ctx.alert(topic, "warn", f"{what} {value:.1f} ms, normally {med:.1f} ms",
                                symptom=f"{what}_rise", value_ms=value, baseline_ms=med)
        yield from drops


def _keep_rise(ctx: PluginContext, topic: str, attr: str, value: float | None,
               began: float | None) -> None:
    """Follow the peak of ``topic``'s ``attr``'s rise under way (``value`` this sample, None: not
    risen; ``began``: when the rise began, as `held` kept it); one that ends widens the topic's
    envelope for a later run (``ctx.learned["rises"]``: its highest value and its longest rise
    that ended by itself, ms and s)."""
    peaks = ctx.state.setdefault("peaks", {})  # (topic, attr) -> its rise's highest value
    if value is not None:
        peaks[topic, attr] = max(peaks.get((topic, attr), value), value)
    elif (topic, attr) in peaks:
        peak = peaks.pop((topic, attr))
        known = ctx.learned.setdefault("rises", {})
        was = known.get(f"{topic} {attr}", [0.0, 0.0])
        known[f"{topic} {attr}"] = [max(was[0], peak), max(was[1], 0.0 if began is None else ctx.t - began)]


def _shown_before(ctx: PluginContext, topic: str, attr: str, value: float, lasted: float) -> bool:
    """True when the healthy run this one started from showed a rise of ``topic``'s ``attr`` that
    ended by itself, ``carried_margin`` × as high and as long as this one so far: its normal
    (a host's hiccup on a fast sensor, a controller's commands while it plans)."""
    carried = ctx.primed.get("rises", {}).get(f"{topic} {attr}")
    margin = ctx.settings["carried_margin"]
    return carried is not None and value <= margin * carried[0] and lasted <= margin * carried[1]


def _interleaved(ctx: PluginContext, topic: str) -> bool:
    """True when several publishers sent on ``topic`` in the window (``publisher_rates``; without
    it, when it has several publishers): its arrival intervals interleave their streams, and one
    joining or pausing (a joystick held beside an autonomy node) changes the jitter with nothing
    late. Its jitter says nothing then."""
    rates = ctx.attr(topic, "publisher_rates")
    if rates:
        return sum(1 for hz in rates.values() if hz > 0) > 1
    return ctx.value(topic, "publishers") > 1


def _inputs_switched(ctx: PluginContext, topic: str, last: int) -> bool:
    """True when a topic that a publisher of ``topic`` subscribes to was silent (rate 0 or
    unknown) and sending (> 0) within its ``last`` samples: the publisher's input mix changed
    (a joystick taking over a mux, a goal starting a controller), and with it what the
    publisher forwards, when."""
    for node in ctx.publishers(topic):
        for source in ctx.subscribed_topics(node):
            if source == topic:
                continue
            _, rates = ctx.past(source, "rate_hz", last=last)
            sending = np.nan_to_num(np.append(rates, ctx.value(source, "rate_hz")), nan=0.0) > 0
            if sending.any() and not sending.all():
                return True
    return False


def _endpoints_changed(ctx: PluginContext, topic: str, last: int) -> bool:
    """True when ``topic``'s publishers or subscribers changed in number within its ``last``
    samples: matching a new endpoint (a recorder or a viewer subscribing to everything, a node
    restarted) takes the publisher's time, and the joiner's start-up the computer's, for a few
    seconds, seen in the graph only after they began. Its jitter says nothing then."""
    for attr in ("publishers", "subscribers"):
        _, counts = ctx.past(topic, attr, last=last)
        counts = np.append(counts, ctx.value(topic, attr))
        if len(np.unique(counts[np.isfinite(counts)])) > 1:
            return True
    return False


def _least_rise(s: dict[str, Any], attr: str, rate: float) -> float:
    """The least rise of ``latency_ms`` / ``jitter_ms`` that counts on a topic of ``rate`` Hz.

    Scheduling noise on a busy host scales with the period: a 20 Hz topic's jitter must rise by
    half its 50 ms period before it counts; latency by a tenth (30 ms more on a 1 Hz topic is
    3 % of the data's age, on 100 Hz 3 periods).
    """
    what = attr.removesuffix("_ms")
    floor = s[f"{what}_min_rise_ms"]
    if rate > 0:
        floor = max(floor, s[f"{what}_period_ratio"] * 1000.0 / rate)
    return floor


def _above_usual(ctx: PluginContext, topic: str, attr: str, floor: float,
                 ex: tuple[float, float, bool] | None, alerting: set) -> tuple[float, float, bool] | None:
    """`excess` ``ex``, exceeded only if the value is also ``floor`` above the ``usual_quantile`` of
    the topic's own past (the same samples as the baseline; kept while alerting)."""
    if ex is None or not ex[2]:
        return ex
    s = ctx.settings
    cache = ctx.state.setdefault("usual", {})
    hit = cache.get((topic, attr))  # (next refresh time, quantile)
    if hit is None or (ctx.t >= hit[0] and (topic, attr) not in alerting):
        _, past = ctx.past(topic, attr, last=s["window"])
        past = past[np.isfinite(past)]
        usual = float(np.quantile(past, s["usual_quantile"])) if len(past) else -math.inf
        hit = cache[(topic, attr)] = (ctx.t + s["refresh_s"], usual)
    value, med, _ = ex
    return value, med, value - hit[1] >= floor


def _drops(ctx: PluginContext, topic: str, rate: float, fresh: bool, alerting: set) -> list[Alert]:
    """Drops risen above the topic's own: ``drops_per_s`` at least ``max(drops_min_per_s,
    drops_ratio × rate)`` above its baseline and its usual (as latency, `excess`), for
    ``confirm`` fresh samples and ``drops_hold_s``, on a topic some publisher sends reliably.

    Sequence gaps are counted where the monitor receives, best effort: a best-effort publisher's
    messages are lost by design on a busy link or reader, and a reliable one's large messages
    (images, point clouds: many fragments each) reach a best-effort reader with some missing all
    the time. What a topic shows from the first look on is its normal; a rise above it is news.
    """
    s = ctx.settings
    if best_effort(ctx.attr(topic, "qos")):
        return []
    floor = max(s["drops_min_per_s"], s["drops_ratio"] * (0.0 if math.isnan(rate) else rate))
    ex = _above_usual(ctx, topic, "drops_per_s", floor,
                      excess(ctx, topic, "drops_per_s", floor, alerting), alerting)
    risen = confirm(ctx, topic, "drops_per_s", ex, alerting, fresh)
    # Counted over the collector's window, one burst of losses (a participant joining a busy link)
    # holds the count up for the whole window: only a rise that outlasts it is the topic's.
    lasted = held(ctx.state, (topic, "drops_per_s"), ex is not None and ex[2], ctx.t, fresh)
    if risen is None or lasted < s["drops_hold_s"]:
        return []
    drops, med = risen
    return [ctx.alert(topic, "warn", f"{drops:.3g} messages/s dropped, normally {med:.3g}", symptom="drops",
                      drops_per_s=drops, baseline_per_s=med)]


def best_effort(qos: Any) -> bool:
    """True when every publisher endpoint in the topic attribute ``qos`` (and at least one) is
    best effort."""
    pubs = [q for q in qos or () if isinstance(q, dict) and q.get("role") == "pub"]
    return bool(pubs) and all(qos_policy(q, "reliability") == "best_effort" for q in pubs)


def common_mode(seen: list[tuple[str, str, tuple[float, float, bool] | None, bool]], least: int,
                ratio: float, floors: Mapping[tuple[str, str], float] | None = None,
                processes: Callable[[str], set[str]] | None = None) -> bool:
    """Return True if at least ``least`` topics and ``ratio`` of the topics measured afresh (with a
    baseline) exceed their baseline in one sample: a stall of all, not a fault of each.

    ``seen`` holds ``(topic, attr, excess, fresh)`` per topic and attribute (`excess` result).
    With ``floors`` (the least rise that counts, per topic and attribute), it is also True when
    that holds of one attribute among the topics that could show the smallest rise of it, and
    the risen ones come from more than one process (``processes``: a topic's publishers'): a
    stall of the computer for 50 ms (a participant joining, each process busy with its discovery)
    raises the jitter of the fast topics only, as a 1 Hz topic's floor is 500 ms.
    """
    live = [(t, a, ex) for t, a, ex, fresh in seen if ex is not None and fresh]
    risen = {t for t, _, ex in live if ex[2]}
    if len(risen) >= least and len(risen) >= ratio * len({t for t, _, _ in live}):
        return True
    if floors is None or processes is None:
        return False
    for attr in {a for _, a, _ in live}:
        ups = [(t, ex) for t, a, ex in live if a == attr and ex[2]]
        if len(ups) < least or len(set().union(*(processes(t) for t, _ in ups))) < 2:
            continue
        smallest = min(value - med for _, (value, med, _) in ups)
        able = [t for t, a, ex in live if a == attr and (ex[2] or floors.get((t, a), math.inf) <= smallest)]
        if len(ups) >= ratio * len(able):
            return True
    return False
