"""Topic rate drop or silence, against the topic's own healthy rate and the configured rate."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any, ClassVar

from stream_viz.detect.api import Plugin, PluginContext
from stream_viz.detect.baseline import BASELINE_SETTINGS, cached_baseline, streak
from stream_viz.records import Alert

Baseline = tuple[float, float, int] | None


class TopicRate(Plugin):
    """Alerts when a watched topic's rate drops or it goes silent.

    * silence (error): no message for ``max(silence_periods / rate, silence_min_s)`` after
      having had messages, from the age of the newest message (``age_s``); without one, a zero
      rate means none for the collector's ``rate_window_s``, 3 s;
    * drop (warn): ``rate < drop_ratio × baseline`` for ``confirm`` samples, the baseline being
      the median of the topic's own rate after ``warmup_s`` (frozen while alerting); the rate
      compared is the recent one (``rate_recent_hz``, the last few intervals) where measured, so
      a slowed topic shows before the collector's window has turned over;
    * below expectation (warn): ``rate < (1 - expected_tolerance) × expected_rate_hz`` from the
      config, for ``confirm`` samples.
    """

    name = "topic_rate"
    kinds = ("topic",)
    uses = (cached_baseline,)
    settings: ClassVar[dict[str, Any]] = {
        **BASELINE_SETTINGS,
        "drop_ratio": 0.5,
        "min_baseline_hz": 0.5,
        "confirm": 2,
        "silence_periods": 3.0,
        "silence_min_s": 1.5,
        "expected_tolerance": 0.3,
        "rate_window_s": 3.0,
    }

    def check(self, ctx: PluginContext) -> Iterator[Alert]:
        alerting = ctx.state.setdefault("alerting", set())
        for topic in ctx.watched():
            rate = ctx.value(topic, "rate_hz")
            if math.isnan(rate):
                continue  # not measured
            base = cached_baseline(ctx, topic, "rate_hz", frozen=topic in alerting)
            alert = _silence(ctx, topic, rate, base) or _drop(ctx, topic, rate, base)
            expected = _below_expected(ctx, topic, rate)  # its streak counts every sample
            alert = alert or expected  # one alert per topic and sample
            if alert is not None:
                alerting.add(topic)
                yield alert
            else:
                alerting.discard(topic)


def _silence(ctx: PluginContext, topic: str, rate: float, base: Baseline) -> Alert | None:
    """Silent for ``max(silence_periods / rate, silence_min_s)`` after having had messages."""
    s = ctx.settings
    last_msg = ctx.state.setdefault("last_msg", {})  # topic: (t, rate) when it last had messages
    if rate > 0:
        last_msg[topic] = (ctx.t, rate)
    if topic not in last_msg:
        return None
    t_last, rate_last = last_msg[topic]
    ref = base[0] if base and base[0] > 0 else rate_last
    age = ctx.value(topic, "age_s")
    if age == age:  # measured: seconds since the newest message in the window
        quiet = age
    else:  # none in the window: a zero rate means none for the whole rate window
        quiet = max(ctx.t - t_last, s["rate_window_s"]) if rate == 0 else 0.0
    if quiet < max(s["silence_periods"] / ref, s["silence_min_s"]):
        return None
    return ctx.alert(topic, "error", f"silent for {quiet:.1f} s (was {ref:.3g} Hz)",
                     symptom="silence", silent_s=quiet, baseline_hz=ref)


def _drop(ctx: PluginContext, topic: str, rate: float, base: Baseline) -> Alert | None:
    """The recent rate below ``drop_ratio`` × the baseline for ``confirm`` samples."""
    s = ctx.settings
    if base is None or base[0] < s["min_baseline_hz"]:
        return None
    recent = ctx.value(topic, "rate_recent_hz")
    now_rate = recent if recent == recent else rate
    if streak(ctx.state, (topic, "drop"), now_rate < s["drop_ratio"] * base[0]) < s["confirm"]:
        return None
    return ctx.alert(topic, "warn", f"rate {now_rate:.3g} Hz, down from {base[0]:.3g} Hz",
                     symptom="rate_drop", rate_hz=now_rate, baseline_hz=base[0])


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
