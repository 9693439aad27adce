"""Topic latency or jitter rising above the topic's own baseline; messages dropped."""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import Any, ClassVar

from stream_viz.detect.api import Plugin, PluginContext
from stream_viz.detect.baseline import BASELINE_SETTINGS, rise, streak
from stream_viz.records import Alert


class TopicLatency(Plugin):
    """Alerts on latency / jitter rises and on message drops of watched topics.

    A rise counts when ``value - median ≥ max(k·σ, min_rise_ms)`` (σ = 1.4826·MAD of the topic's
    own past after ``warmup_s``; for jitter also ≥ ``jitter_period_ratio`` × the period) for
    ``confirm`` samples in a row; drops when
    ``drops_per_s ≥ max(drops_min_per_s, drops_ratio × rate)`` for ``confirm`` samples. Only
    samples with a message newer than the previous sample count (``age_s``): a topic slower than
    the sampling keeps one late message in its window for several samples, which is one
    observation, not ``confirm``.
    """

    name = "topic_latency"
    kinds = ("topic",)
    settings: ClassVar[dict[str, Any]] = {
        **BASELINE_SETTINGS,
        "k": 6.0,
        "latency_min_rise_ms": 20.0,
        "jitter_min_rise_ms": 20.0,
        "jitter_period_ratio": 0.5,
        "confirm": 3,
        "drops_min_per_s": 1.0,
        "drops_ratio": 0.05,
    }

    def check(self, ctx: PluginContext) -> Iterator[Alert]:
        s = ctx.settings
        alerting = ctx.state.setdefault("alerting", set())
        since = ctx.t - ctx.state.get("t_prev", -math.inf)
        ctx.state["t_prev"] = ctx.t
        for topic in ctx.watched("topic"):
            age = ctx.value(topic, "age_s")
            fresh = age != age or age < since  # a message since the last sample (age unknown: yes)
            floors = (("latency_ms", s["latency_min_rise_ms"]), ("jitter_ms", s["jitter_min_rise_ms"]))
            for attr, floor in floors:
                if attr == "jitter_ms":
                    # Scheduling noise on a busy host scales with the period: a 20 Hz topic's
                    # jitter must rise by half its 50 ms period before it counts.
                    rate = ctx.value(topic, "rate_hz")
                    if rate > 0:
                        floor = max(floor, s["jitter_period_ratio"] * 1000.0 / rate)
                risen = rise(ctx, topic, attr, floor, alerting, fresh)
                if risen is not None:
                    value, med = risen
                    what = attr.removesuffix("_ms")
                    yield ctx.alert(topic, "warn", f"{what} {value:.1f} ms, normally {med:.1f} ms",
                                    symptom=f"{what}_rise", value_ms=value, baseline_ms=med)
            drops = ctx.value(topic, "drops_per_s")
            if not math.isnan(drops):
                rate = ctx.value(topic, "rate_hz")
                limit = max(s["drops_min_per_s"], s["drops_ratio"] * (0.0 if math.isnan(rate) else rate))
                if streak(ctx.state, (topic, "drops"), drops >= limit, fresh) >= s["confirm"]:
                    yield ctx.alert(topic, "warn", f"{drops:.3g} messages/s dropped",
                                    symptom="drops", drops_per_s=drops)
