"""`topic_rate` over topics of many rhythms, sampled the way a live monitor samples them.

Bursts of 0.2 to 3 s every 4 to 15 s at 2 to 30 Hz, and continuous topics from 0.2 to 30 Hz,
each with jittered message times, burst starts and sample times (seeded): healthy, none raises
an alert; hung, each whose rhythm settled is silent by twice its longest healthy gap (a sample
later at most); a continuous topic slowed to a quarter is a rate drop.
"""

from __future__ import annotations

import numpy as np
import pytest

from tests.unit.test_plugins import drive, sampled

END, HANG = 200.0, 60.0
BURSTY = [(period, on, hz) for period in (4, 5, 7, 10, 15) for on in (0.2, 1.0, 3.0)
          for hz in (2, 5, 10, 30) if on * hz >= 1]
CONTINUOUS = [0.2, 0.5, 1.0, 2.0, 10.0, 30.0]


def messages(rng, period, on, hz, end=END, jitter=0.2):
    """Receive times: ``on`` s at ``hz`` every ``period`` s (±10 %), each message ±``jitter`` of a
    period late or early."""
    out, start = [], 0.0
    while start < end:
        out += [start + (i + rng.uniform(-jitter, jitter)) / hz for i in range(max(1, int(on * hz)))]
        start += period * rng.uniform(0.9, 1.1)
    return sorted(m for m in out if 0 <= m < end)


def samples(rng, n=150):
    """A monitor's sample times: about one a second, each 0.7 to 1.3 s after the last."""
    return list(np.cumsum(rng.uniform(0.7, 1.3, n)))


def rhythms():
    rng = np.random.default_rng(11)
    for period, on, hz in BURSTY:
        yield f"{on:g}s at {hz:g} Hz every {period:g}s", messages(rng, period, on, hz), samples(rng)
    for hz in CONTINUOUS:
        yield f"continuous {hz:g} Hz", messages(rng, END, END, hz), samples(rng)


CASES = list(rhythms())


def test_healthy_topics_of_any_rhythm_raise_no_alert():
    noisy = {name: [(round(a.t, 1), a.message) for a in alerts][:2]
             for name, msgs, times in CASES
             if (alerts := drive("topic_rate", sampled(msgs, times), full=True))}
    assert noisy == {}


def test_a_hung_topic_is_silent_by_twice_its_longest_gap():
    late, missed = {}, []
    for name, msgs, times in CASES:
        hung = [m for m in msgs if m < HANG]
        if len(hung) < 5:  # too few messages for a rhythm: never judged
            continue
        alerts = [a for a in drive("topic_rate", sampled(hung, times), full=True) if a.t > hung[-1]]
        if not alerts:
            missed.append(name)
            continue
        a = alerts[0]
        assert a.data["symptom"] == "silence" and a.severity == "error", (name, a.message)
        if a.t - hung[-1] > a.data["limit_s"] + 1.3:
            late[name] = (round(a.t - hung[-1], 1), a.data["limit_s"])
    assert missed == [] and late == {}


@pytest.mark.parametrize("hz", [5.0, 10.0, 30.0])  # slower: a quarter is a silence
def test_a_continuous_topic_slowed_to_a_quarter_is_a_rate_drop(hz):
    rng = np.random.default_rng(int(hz))
    msgs = [m for m in messages(rng, END, END, hz) if m < HANG] + messages(rng, END, END, hz / 4)
    msgs = sorted(m for m in msgs if m < HANG or m >= HANG + 0.5)
    alerts = drive("topic_rate", sampled(msgs, samples(rng)), full=True)
    assert alerts, "no alert"
    first = alerts[0]
    assert first.data["symptom"] == "rate_drop" and HANG < first.t < HANG + 6.0, (first.t, first.message)


@pytest.mark.parametrize("hz", [10.0, 30.0, 50.0])
def test_a_steady_topic_that_loses_one_message_in_three_is_a_rate_drop_after_slow_drop_s(hz):
    # Two thirds of its rate (a sensor stream that lost its requested interval): above half, so
    # not the deep drop; a slow one once it held `slow_drop_s` (10 s), a sample or two later.
    rng = np.random.default_rng(int(hz))
    msgs = [m for m in messages(rng, END, END, hz, jitter=0.05) if m < HANG]
    msgs += [HANG + (k + rng.uniform(-0.05, 0.05)) / hz for k in range(int((END - HANG) * hz)) if k % 3 != 2]
    alerts = drive("topic_rate", sampled(sorted(msgs), samples(rng)), full=True)
    assert alerts, "no alert"
    first = alerts[0]
    assert first.data["symptom"] == "rate_drop", first.message
    assert HANG + 10.0 < first.t < HANG + 14.0, (first.t, first.message)


def test_a_symptom_quiet_ended_by_a_restarted_stream_is_learned_as_a_gap():
    from stream_viz.detect.rhythm import Rhythm, follow, restarted

    def run(restart: bool) -> list[float]:
        r, kw = Rhythm(), dict(window_s=3.0, notable=1.5, settle_s=10.0, margin=2.0, min_gaps=3)
        for k in range(120):  # 10 Hz for 12 s: continuous
            follow(r, k / 10 + 0.05, k / 10, 10.0, **kw)
        follow(r, 14.0, 11.9, 10.0, **kw)  # 2.1 s quiet: a symptom
        r.departed = True
        if restart:
            restarted(r)
        follow(r, 15.0, 14.5, 10.0, **kw)  # the stream is back
        return r.gaps

    assert run(restart=True) == [pytest.approx(2.6)]
    assert run(restart=False) == []
