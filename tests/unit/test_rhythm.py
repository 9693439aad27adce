"""A topic's learned rhythm (`stream_viz.detect.rhythm`) on tiny literal series."""

from __future__ import annotations

import math

import pytest

from stream_viz.detect.rhythm import GAP_MEMORY, Rhythm, follow, newest_message, quiet_limit

NAN = math.nan
KW = {"window_s": 3.0, "notable": 1.5, "settle_s": 10.0, "margin": 2.0, "min_gaps": 3}


def run(samples, r=None):
    """Follow ``samples`` = [(t, newest or None, rate)]; return the rhythm and the quiets."""
    r = r or Rhythm()
    return r, [follow(r, t, newest, rate, **KW) for t, newest, rate in samples]


def test_newest_message_from_the_age_or_the_rate():
    assert newest_message(10.0, 5.0, 0.25) == 9.75
    assert newest_message(10.0, 5.0, NAN) == 10.0  # messages in the window, no age: now
    assert newest_message(10.0, 0.0, NAN) is None  # none in the window


def test_a_continuous_topic_settles_after_settle_s_and_learns_no_gap():
    samples = [(float(t), t - 0.05, 10.0) for t in range(12)]
    r, quiets = run(samples)
    assert [round(q, 2) for q in quiets] == [0.05] * 12
    assert r.gaps == [] and r.run_start == -0.05
    # settled once it has published for 10 s: at t = 10 (newest 9.95 - (-0.05) = 10)
    r2, _ = run(samples[:10])
    assert not r2.settled and r.settled


def test_a_bursty_topic_learns_its_gaps_and_settles_after_three():
    # 10 Hz for 2 s of every 8 s: the newest message stays at 1.9 (age 1.1, 2.1), then the 3 s
    # window is empty (rate 0) until the next burst at 8.
    def cycle(k):
        o = 8.0 * k
        return [(o, o, 3.3), (o + 1, o + 0.95, 6.7), (o + 2, o + 1.9, 6.3), (o + 3, o + 1.9, 3.3),
                (o + 4, o + 1.9, 0.3), (o + 5, None, 0.0), (o + 6, None, 0.0), (o + 7, None, 0.0)]

    r, quiets = run(cycle(0))
    assert [round(q, 2) for q in quiets] == [0.0, 0.05, 0.1, 1.1, 2.1, 3.1, 4.1, 5.1]
    assert r.gaps == [] and not r.settled  # a 2 s run is no continuity
    # Its rate is the burst's, from the samples less than half a window (1.5 s) after a message:
    # not the 0.3 Hz of the burst's tail in the window (3 periods of that: a 10 s quiet).
    assert r.rates == [3.3, 6.7, 6.3, 3.3] and r.rate == 4.8
    r, _ = run(cycle(1) + cycle(2), r)
    assert [round(g, 2) for g in r.gaps] == [6.1, 6.1] and [round(x, 2) for x in r.runs] == [1.9, 1.9]
    assert not r.settled
    r, _ = run(cycle(3)[:1], r)
    assert len(r.gaps) == 3 and r.settled
    assert round(quiet_limit(r, 1.5, 2.0), 2) == 12.2  # twice its longest gap


def test_a_symptom_quiet_is_not_learned_and_a_settled_topic_stays_judged():
    r, _ = run([(float(t), t - 0.05, 10.0) for t in range(12)])
    assert r.settled
    r, _ = run([(12.0, 10.95, 10.0), (13.0, 10.95, 6.0)], r)  # quiet 2.05 s
    r.departed = True  # the plugin alerted on it
    r, _ = run([(14.0, 13.95, 3.0), (15.0, 13.95, 6.0), (16.0, 15.95, 3.0)], r)  # flapping
    assert r.gaps == [] and r.settled and round(r.peak, 2) == 0.05
    # A quiet with a cause outside the rhythm (its publisher changed state) is not learned
    # either; the same quiet without alert or cause is.
    r.explained = True
    r, _ = run([(17.0, 15.95, 3.0), (18.0, 15.95, 3.0), (19.0, 18.95, 3.0)], r)
    assert r.gaps == [] and r.run_start == 18.95 and not r.explained
    r, _ = run([(20.0, 19.95, 6.0), (21.0, 19.95, 3.0), (22.0, 19.95, 3.0), (23.0, 22.95, 3.0)], r)
    assert r.gaps == [3.0] and r.runs == [1.0]
    assert quiet_limit(r, 1.5, 2.0) == 6.0


def test_a_quiet_that_ended_is_kept_for_a_later_run_alerted_or_not_and_a_carried_one_counts():
    r, _ = run([(float(t), t - 0.05, 10.0) for t in range(12)])
    r, _ = run([(12.0, 11.95, 10.0), (13.0, 11.95, 6.0), (14.0, 11.95, 3.0)], r)  # quiet 2.05 s
    r.departed = True  # the plugin alerted on it
    r, _ = run([(15.0, 14.95, 3.0)], r)
    assert r.gaps == [] and r.ended == pytest.approx(3.0)  # not learned, kept for a later run
    r.explained = True  # a change of state: its quiet neither learned nor kept
    r, _ = run([(16.0, 14.95, 3.0), (17.0, 14.95, 3.0), (18.0, 14.95, 0.0), (19.0, 18.95, 3.0)], r)
    assert r.gaps == [] and r.ended == pytest.approx(3.0)
    # Carried from an earlier run: twice it is the limit, when above the base.
    assert quiet_limit(Rhythm(carried=10.0), 1.5, 2.0) == 20.0
    assert quiet_limit(Rhythm(carried=0.5), 1.5, 2.0) == 1.5


def test_a_run_much_longer_than_any_before_settles_a_topic_with_few_gaps():
    # One early gap (a publisher that waited for something at start-up), then continuous.
    r, _ = run([(0.0, 0.0, 1.0), (1.0, 0.0, 1.0), (2.0, 0.0, 0.3), (3.0, 3.0, 0.7)])
    assert r.gaps == [3.0] and r.runs == [0.0] and not r.settled
    r, _ = run([(float(t), t - 0.05, 10.0) for t in range(4, 14)], r)
    assert not r.settled  # a run of 9.95 s < settle_s
    r, _ = run([(14.0, 13.95, 10.0)], r)
    assert r.settled and quiet_limit(r, 1.5, 2.0) == 6.0


def test_one_latched_message_never_settles_and_memory_is_bounded():
    once = [(0.0, 0.0, 0.3), (1.0, 0.0, 0.3), (2.0, 0.0, 0.3)]
    r, quiets = run(once + [(float(t), None, 0.0) for t in range(3, 60)])
    assert quiets[-1] == 59.0 and not r.settled and r.gaps == []
    r = Rhythm(gaps=[1.0] * GAP_MEMORY, runs=[1.0] * GAP_MEMORY, newest=0.0, run_start=0.0, peak=5.0)
    run([(10.0, 10.0, 1.0)], r)
    assert len(r.gaps) == GAP_MEMORY and r.gaps[-1] == 10.0


def test_the_same_message_seen_a_little_later_ends_no_quiet():
    # t - age of one message moves by how long the collector took to its metrics: 0.2 ms here.
    samples = [(0.0, 0.0, 3.0), (1.0, 0.95, 6.0), (2.0, 0.95, 6.0), (3.0, 0.9502, 6.0),
               (4.0, 0.9504, 3.0), (5.0, 4.9, 0.3)]
    r, quiets = run(samples)
    assert [round(q, 2) for q in quiets] == [0.0, 0.05, 1.05, 2.05, 3.05, 0.1]
    assert [round(g, 2) for g in r.gaps] == [3.95]  # one quiet, ended by the message at 4.9
    # More messages in the window than before: a new one, however close.
    r, _ = run([(0.0, 0.0, 1.0), (1.0, 0.1, 2.0)])
    assert r.newest == 0.1 and r.peak == 0.9


def test_a_quiet_between_two_samples_is_learned_from_the_collectors_longest_gap():
    # Bursts of 1 s with 2.5 s gaps, sampled while the monitor was too busy to look in between:
    # every sample sees a fresh message. Without the longest interval (gap_s) the topic reads as
    # continuous and settles; with it, each quiet is learned.
    samples = [(3.5 * k + 1.0, 3.5 * k + 0.95, 5.0) for k in range(4)]
    blind = Rhythm()
    for t, newest, rate in samples:
        follow(blind, t, newest, rate, **KW)
    r = Rhythm()
    for i, (t, newest, rate) in enumerate(samples):
        follow(r, t, newest, rate, **KW, gap=2.5 if i else 0.0)
    assert blind.gaps == [] and blind.settled  # as continuous: its next gap would be a "silence"
    assert [round(g, 6) for g in r.gaps] == [3.5, 3.5, 3.5]  # newest to newest: an upper bound
    assert r.settled and round(quiet_limit(r, 1.5, 2.0), 2) == 7.0  # from three gaps
    r2 = Rhythm()
    for t, newest, rate in samples:
        follow(r2, t, newest, rate, **KW, gap=0.3)  # short intervals: no quiet
    assert r2.gaps == []


def test_a_settled_continuous_topic_s_dropout_between_two_samples_is_not_learned():
    # 20 Hz for 20 s (settled, continuous), then a 1.6 s dropout that began and ended between two
    # samples: a silence no sample saw, not its rhythm. Learned, its limit would double to 3.2 s
    # and a 2.5 s dropout after it would pass.
    samples = [(float(t), t - 0.05, 20.0) for t in range(21)]
    r, _ = run(samples)
    assert r.settled and r.gaps == []
    follow(r, 21.0, 20.95, 20.0, **KW, gap=1.6)
    assert r.gaps == [] and quiet_limit(r, 1.5, 2.0) == 1.5
    # The same dropout before the topic settled is learned: its rhythm is still being found.
    early, _ = run(samples[:5])
    follow(early, 5.0, 4.95, 20.0, **KW, gap=1.6)
    assert early.gaps == [1.0] and not early.settled  # newest to newest: 3.95 -> 4.95


def test_a_settled_continuous_topic_s_hiccup_just_under_the_floor_is_not_learned():
    # The manipulator's flaky bumpers (20 Hz, settled): a first dropout of 1.44 s, under the 1.5 s
    # floor. Learned, its limit would be 2.88 s and the 1.7 s quiets after it healthy.
    samples = [(float(t), t - 0.05, 20.0) for t in range(21)]
    r, _ = run(samples)
    follow(r, 21.0, 20.95, 20.0, **KW, gap=1.44)
    assert quiet_limit(r, 1.5, 2.0) == 1.5 and r.longest < 0.1
    # A hiccup within margin × its longest is learned as before: it lifts nothing at once.
    follow(r, 22.0, 21.95, 20.0, **KW, gap=0.09)
    assert r.longest == 0.09
    # Before the topic settled, the same dropout is learned: its rhythm is still being found.
    early, _ = run(samples[:5])
    follow(early, 5.0, 4.95, 20.0, **KW, gap=1.44)
    assert early.longest == 1.44 and quiet_limit(early, 1.5, 2.0) == 2.88
