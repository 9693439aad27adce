"""Built-in plugins on small literal models over time: a healthy run stays quiet, a sick one alerts."""

from __future__ import annotations

import math

import numpy as np
import pytest

from stream_viz.detect.api import record_history
from stream_viz.detect.plugin_set import PluginSet
from stream_viz.model.diff import diff
from stream_viz.model.graph import add_flow_edge, add_member, add_tree_edge, new_graph
from stream_viz.model.history import History
from stream_viz.model.theta import make_theta
from stream_viz.records import Event

RNG = np.random.default_rng(7)


def model(rate=10.0, latency=2.0, jitter=1.0, drops=0.0, cpu=5.0, rss=80.0, alive=True, recent=None,
          age=None, subscribers=1, executor=None, dispatch=None):
    """camera (pid 100) -> /img -> detector (pid 200); ``recent``/``age``: the fast rate signals;
    ``executor``: the camera process's executor thread's CPU; ``dispatch``: its main thread's, one
    that dispatches a multi-threaded executor."""
    G = new_graph()
    ex = {} if executor is None else {"executor_cpu_percent": executor}
    ex |= {} if dispatch is None else {"main_cpu_percent": dispatch, "dispatching": 1.0}
    add_member(G, "process:100", pid=100, alive=alive,
               theta=make_theta("process", {"cpu_percent": cpu, "rss_mb": rss, "threads": 4, **ex}))
    add_member(G, "process:200", pid=200, alive=True,
               theta=make_theta("process", {"cpu_percent": 3.0, "rss_mb": 60.0, "threads": 4}))
    add_member(G, "node:/camera", pid=100, alive=alive)
    add_member(G, "node:/detector", pid=200, alive=True)
    add_member(G, "topic:/img", theta=make_theta("topic", {
        "rate_hz": rate, "latency_ms": latency, "jitter_ms": jitter, "drops_per_s": drops,
        "publishers": 1, "subscribers": subscribers,
        **({} if recent is None else {"rate_recent_hz": recent}), **({} if age is None else {"age_s": age})}))
    add_flow_edge(G, "node:/camera", "topic:/img", "pub")
    add_flow_edge(G, "topic:/img", "node:/detector", "sub")
    add_tree_edge(G, "process:100", "node:/camera")
    add_tree_edge(G, "process:200", "node:/detector")
    return G


def drive(plugin, frames, *, settings=None, expected=None, watch=None, full=False, learned=None):
    """Run one built-in plugin over ``frames`` = [(t, G, events)]; return alerts as (t, member, severity)
    (``full``: the alerts themselves). ``learned``: a run's ``PluginSet.learned()`` to start from,
    replaced by this run's at the end."""
    ps = PluginSet.load(enable=[plugin], cwd_plugins=False, settings={plugin: settings or {}}, isolate=False)
    if learned is not None:
        ps.prime(learned)
    hist = History()
    prev = new_graph()
    out = []
    for t, G, events in frames:
        record_history(hist, G, t)
        alerts, problems = ps.run(t, G, watch if watch is not None else G.nodes, hist, events, diff(prev, G),
                                  expected)
        assert problems == [], problems
        out += alerts if full else [(a.t, a.member, a.severity) for a in alerts]
        prev = G
    if learned is not None:
        learned.clear()
        learned.update(ps.learned()[0])
    return out


def noisy(x, rel=0.05):
    return float(x * (1 + RNG.normal(0, rel)))


# --------------------------------------------------------------------------- topic_rate

def test_topic_rate_quiet_when_healthy():
    frames = [(float(t), model(rate=noisy(10.0)), []) for t in range(60)]
    assert drive("topic_rate", frames) == []


def test_topic_rate_drop():
    frames = [(float(t), model(rate=noisy(10.0) if t < 30 else 3.0), []) for t in range(34)]
    assert drive("topic_rate", frames) == [(t, "topic:/img", "warn") for t in (31.0, 32.0, 33.0)]


def _on_sim_time(G, pace, subscribes=True):
    """``G`` with a simulator publishing /clock at ``pace``; the camera on simulated time when
    it ``subscribes`` to /clock (as ``use_sim_time`` makes a node do)."""
    add_member(G, "node:/sim", alive=True)
    add_member(G, "topic:/clock", theta=make_theta("topic", {"rate_hz": 100.0, "sim_pace": pace,
                                                              "publishers": 1, "subscribers": 1}))
    add_flow_edge(G, "node:/sim", "topic:/clock", "pub")
    if subscribes:
        add_flow_edge(G, "topic:/clock", "node:/camera", "sub")
    return G


def test_topic_rate_on_simulated_time_follows_the_simulations_pace():
    # the simulator slows from 0.9 to 0.3 of real time at 30 s: a camera on simulated time
    # publishes at a third of its rate on our clock (no drop); one on our clock that drops so does.
    def frames(subscribes, pace_after=0.3):
        return [(float(t), _on_sim_time(model(rate=noisy(10.0) if t < 30 else 3.0),
                                        0.9 if t < 30 else pace_after, subscribes), [])
                for t in range(36)]

    # the slowed simulation is the simulator's symptom (on /clock, once held 3 s), not the camera's
    slowed = [(float(t), "topic:/clock", "warn") for t in range(33, 36)]
    assert drive("topic_rate", frames(True), watch=["topic:/img"]) == slowed
    dropped = [(float(t), "topic:/img", "warn") for t in range(31, 36)]
    assert sorted(drive("topic_rate", frames(False), watch=["topic:/img"])) == sorted(dropped + slowed)
    assert drive("topic_rate", frames(True, pace_after=0.9), watch=["topic:/img"]) == dropped
    # a pace that wanders above half its usual (0.6-1.0 of real time) is no slowed simulation
    wander = [(float(t), _on_sim_time(model(rate=noisy(10.0)), 0.6 + 0.4 * (t // 10 % 2)), [])
              for t in range(60)]
    assert drive("topic_rate", wander, watch=["topic:/img"]) == []


def test_topic_rate_a_slowed_simulation_s_quiets_count_at_its_pace():
    # a 1 Hz heartbeat on simulated time: at a quarter of the usual pace its 1 s becomes 5 s of
    # ours, no silence; the same quiet on our clock is one
    def frames(subscribes):
        out = []
        for t in range(60):
            pace = 0.8 if t < 30 else 0.2
            sent = t < 30 or t % 5 == 0  # every 5 s of ours after the slowdown
            out.append((float(t), _on_sim_time(model(rate=1.0 if t < 30 else 0.2, age=0.1 if sent else
                                                     (t % 5) + 0.1), pace, subscribes), []))
        return out

    judged = [a for a in drive("topic_rate", frames(True), watch=["topic:/img"]) if a[1] == "topic:/img"]
    assert judged == []
    assert [a for a in drive("topic_rate", frames(False), watch=["topic:/img"]) if a[1] == "topic:/img"]


def test_topic_rate_a_paused_simulation_silences_no_topic_on_its_time():
    def frames(subscribes):
        return [(float(t), _on_sim_time(model(rate=noisy(10.0) if t < 30 else 0.0,
                                              age=0.05 if t < 30 else t - 29.9), 0.9 if t < 30 else 0.0,
                                        subscribes), []) for t in range(40)]

    assert drive("topic_rate", frames(True), watch=["topic:/img"]) == []
    assert drive("topic_rate", frames(False), watch=["topic:/img"]) != []


def _two_publishers(a_hz, b_hz):
    """/camera and /lidar both publish /img (a /tf-like topic); their rates by publisher."""
    G = model(rate=a_hz + b_hz)
    add_member(G, "node:/lidar", alive=True)
    add_flow_edge(G, "node:/lidar", "topic:/img", "pub")
    G.nodes["topic:/img"]["publisher_rates"] = {"node:/camera": a_hz, "node:/lidar": b_hz}
    return G


def test_topic_rate_one_of_two_publishers_stopping_is_its_symptom():
    # /lidar stops at 30 s, /camera goes on: the topic's rate halves (no drop at 0.5), the stop
    # is /lidar's. A publisher that never sent steadily (/camera's first 20 s at 0) is no stop.
    frames = [(float(t), _two_publishers(10.0, 10.0 if t < 30 else 0.0), []) for t in range(34)]
    alerts = drive("topic_rate", frames, full=True)
    assert [(a.t, a.member) for a in alerts] == [(float(t), "topic:/img") for t in range(30, 34)]
    assert alerts[0].data["publishers"] == ["node:/lidar"]
    assert "/lidar stopped publishing" in alerts[0].message
    late = [(float(t), _two_publishers(0.0 if t < 20 else 10.0, 10.0), []) for t in range(34)]
    assert drive("topic_rate", late) == []


def test_topic_rate_a_publisher_restarted_by_hand_is_no_stop():
    # /lidar's process is Ctrl-C'd at 30 s (it leaves the topic's publishers) and relaunched:
    # back at 36 s, its first sample sends nothing yet, then it sends again. A new publisher.
    def frames(back_hz):
        out = []
        for t in range(45):
            G = _two_publishers(10.0, 10.0)
            rates = G.nodes["topic:/img"]["publisher_rates"]
            if 30 <= t < 36:
                del rates["node:/lidar"]
            elif t >= 36:
                rates["node:/lidar"] = 0.0 if t == 36 else back_hz
            out.append((float(t), G, []))
        return out

    assert drive("topic_rate", frames(10.0)) == []
    # One that comes back and never sends has not sent steadily yet: no stop of it either.
    assert drive("topic_rate", frames(0.0)) == []


def test_topic_rate_a_publisher_in_bursts_is_no_stop():
    # a joystick held 6 s every 40 s beside an autonomy node at 10 Hz: its runs never reach 15
    # samples in a row (they do not add up), and once it has resumed by itself it publishes in
    # bursts: even a long hold (100-120 s) ending is no stop
    def held(t):
        return 20.0 if 10 <= (t % 40) < 16 or 100 <= t < 120 else 0.0
    frames = [(float(t), _two_publishers(10.0, held(t)), []) for t in range(130)]
    assert drive("topic_rate", frames) == []
    # the same long run ending with no burst before it: a stop
    frames = [(float(t), _two_publishers(10.0, 20.0 if t < 30 else 0.0), []) for t in range(34)]
    assert drive("topic_rate", frames) != []


def test_topic_rate_a_publisher_stopping_as_its_goal_ends_is_healthy():
    goal = [Event(29.0, "goal", "node:/lidar", "info", "goal 1 of /scan_area succeeded", {})]
    frames = [(float(t), _two_publishers(10.0, 10.0 if t < 30 else 0.0), goal if t == 29 else [])
              for t in range(34)]
    assert drive("topic_rate", frames) == []


def test_topic_rate_messages_sent_and_lost_on_the_way_are_no_drop():
    # 10 Hz published; the monitor receives 3/s and the sequence numbers skip 7/s: the publisher
    # sent them (lost at a loaded monitor, on a busy link). 1 gap/s of 7 missing is a drop.
    for drops, want in ((7.0, []), (1.0, [31.0, 32.0, 33.0])):
        frames = [(float(t), model(rate=noisy(10.0) if t < 30 else 3.0, drops=0.0 if t < 30 else drops), [])
                  for t in range(34)]
        assert [a[0] for a in drive("topic_rate", frames)] == want, drops


def test_topic_rate_silence_and_recovery():
    rates = [10.0] * 20 + [0.0] * 3 + [10.0] * 3
    frames = [(float(t), model(rate=r), []) for t, r in enumerate(rates)]
    assert drive("topic_rate", frames) == [(t, "topic:/img", "error") for t in (20.0, 21.0, 22.0)]


def test_topic_rate_silence_from_the_age_of_the_newest_message():
    # 10 Hz, then no message: the window's rate stays up for 3 s, the age says it at once.
    ages = [0.05] * 20 + [0.6, 1.6, 2.6]
    frames = [(float(t), model(rate=10.0, age=a), []) for t, a in enumerate(ages)]
    assert drive("topic_rate", frames) == [(t, "topic:/img", "error") for t in (21.0, 22.0)]
    # When it began: after its last message (20 − 0.6 s), by the next one due (0.1 s later).
    got = drive("topic_rate", frames, full=True)
    assert [(a.data["since"], a.data["since_within"]) for a in got] == [(pytest.approx(19.4), 0.1)] * 2
    # A healthy topic whose newest message is always a little old never counts as silent.
    frames = [(float(t), model(rate=noisy(10.0), age=RNG.uniform(0, 0.3)), []) for t in range(60)]
    assert drive("topic_rate", frames) == []


def test_topic_rate_an_irregular_topic_s_chance_quiet_is_no_silence():
    # 2.5 Hz whose intervals spread 0.6 of their mean (a reader of a lossy stream): a 2.4 s quiet
    # after 30 s comes by chance (random arrivals at 2.5 Hz show ~2.9 s in 10 minutes); the same
    # quiet of a regular topic (spread 0.02) is a silence, and the irregular one stopping for good
    # is one past ln(2.5 × 600) / 2.5 = 2.9 s.
    def frames(cv, quiet_ages):
        jitter = cv / 2.5 * 1000.0
        out = [(float(t), model(rate=2.5, jitter=jitter, age=0.2), []) for t in range(30)]
        return out + [(30.0 + i, model(rate=2.5, jitter=jitter, age=a), []) for i, a in enumerate(quiet_ages)]

    chance = [0.4, 1.4, 2.4, 0.1, 0.2, 0.3]
    assert drive("topic_rate", frames(0.6, chance)) == []
    assert [a[0] for a in drive("topic_rate", frames(0.02, chance))] == [32.0]
    stopped = [0.4 + i for i in range(6)]
    assert [a[0] for a in drive("topic_rate", frames(0.6, stopped))] == [33.0, 34.0, 35.0]


def test_topic_rate_a_steady_topic_slowed_by_a_third_for_long_is_a_drop_a_noisy_one_is_not():
    # 50 Hz at 30 s falls to 33 Hz for good. Steady (0.5 % noise): far outside its spread, a drop
    # once it held slow_drop_s (10 s). Noisy (10 %): within ten of its σ, nothing; nor 8 s of it.
    def frames(rel, low_until=80):
        return [(float(t), model(rate=(r := noisy(50.0, rel) if t < 30 or t >= low_until else 33.0),
                                 recent=r), []) for t in range(80)]

    times = [t for t, _, _ in drive("topic_rate", frames(0.005))]
    assert times and times[0] == 40.0 and times == [float(t) for t in range(40, 80)]
    assert drive("topic_rate", frames(0.10)) == []
    assert drive("topic_rate", frames(0.005, low_until=38)) == []


def test_topic_rate_drop_from_the_recent_rate():
    # Slowed to a quarter: the recent rate shows it while the window's rate is still above half.
    frames = [(float(t), model(rate=noisy(10.0), recent=noisy(10.0)), []) for t in range(30)]
    frames += [(30.0, model(rate=8.0, recent=3.0), []), (31.0, model(rate=5.5, recent=2.5), [])]
    assert drive("topic_rate", frames) == [(31.0, "topic:/img", "warn")]


def test_topic_rate_an_irregular_topic_s_drop_must_outlast_irregular_drop_s():
    # 3.6 Hz with intervals spreading 0.45 of their mean (the field robot's row detector reading
    # 1 MiB best-effort clouds): halved for 10 s as the host's load changed is no drop; halved for
    # good it is one 15 s on (irregular_drop_s). A regular topic halved alerts after 2 samples.
    def frames(cv, low_s, total_s=20):
        jitter = cv / 3.6 * 1000.0
        out = [(float(t), model(rate=3.6, recent=3.6, jitter=jitter, age=0.1), []) for t in range(30)]
        return out + [(30.0 + i, model(rate=1.7 if i < low_s else 3.6, recent=1.7 if i < low_s else 3.6,
                                       jitter=jitter, age=0.1), []) for i in range(total_s)]

    assert drive("topic_rate", frames(0.45, 10)) == []
    assert drive("topic_rate", frames(0.45, 20))[0] == (45.0, "topic:/img", "warn")
    assert drive("topic_rate", frames(0.02, 10))[0] == (31.0, "topic:/img", "warn")


def test_topic_rate_a_lower_rate_the_topic_showed_and_left_by_itself_is_its_own_mode():
    # 10 Hz, throttled to 1 Hz for 15 s at 30 s (a telemetry link at low quality): a drop, the
    # first time; back at 10 Hz by itself. The same throttle at 90 s is the topic's own mode. At
    # 150 s it stays at 1 Hz: a drop again once it outlasts twice the longest throttle (30 s).
    def rate(t):
        return 1.0 if 30 <= t < 45 or 90 <= t < 105 or t >= 150 else noisy(10.0)

    frames = [(float(t), model(rate=rate(t), recent=rate(t), age=0.05), []) for t in range(200)]
    times = [t for t, _, _ in drive("topic_rate", frames)]
    assert times[0] == 31.0 and max(t for t in times if t < 90) == 44.0  # the first throttle
    assert not [t for t in times if 45 <= t < 181]  # the mode, and a drop no longer than it
    assert times[-1] == 199.0 and min(t for t in times if t >= 150) == 181.0
    # a deeper drop than the mode (0.3 Hz: under half its lowest) is judged at once
    deep = [(float(t), model(rate=r, recent=r, age=0.05), [])
            for t, r in ((t, 0.3 if 90 <= t < 105 else rate(t)) for t in range(110))]
    assert next(t for t, _, _ in drive("topic_rate", deep) if t >= 90) == 91.0


def test_topic_rate_a_mode_shown_before_the_rate_was_learned_is_its_own_mode_too():
    # A localiser at 1 Hz while the robot stands, 10 Hz while it drives: standing for its first
    # 60 s, then driving long enough for 10 Hz to be its learned rate, then standing again at
    # 150 s. 1 Hz is a rate it held and left by itself: no drop while it lasts up to twice that
    # spell (57 s: from when the collector's window filled), by when 1 Hz is its learned rate
    # again. Driving from the start, the same stop is a drop.
    def frames(standing_first):
        def rate(t):
            return 1.0 if (t < 60 and standing_first) or t >= 150 else noisy(10.0)

        return [(float(t), model(rate=rate(t), recent=rate(t), age=0.05), []) for t in range(280)]

    assert drive("topic_rate", frames(True)) == []
    assert min(t for t, _, _ in drive("topic_rate", frames(False))) == 151.0


def test_topic_rate_modes_are_lower_rates_shown_and_left():
    from plugins.topic_rate import in_mode, learn_mode

    modes = learn_mode([], 0.1, 15.0)
    assert modes == [(0.1, 15.0)]
    assert in_mode(modes, 0.1, 29.0, 2.0) and in_mode(modes, 0.5, 10.0, 2.0)  # as low or less so
    assert not in_mode(modes, 0.1, 31.0, 2.0)  # longer than twice the longest
    assert not in_mode(modes, 0.04, 5.0, 2.0)  # deeper than half its lowest
    assert not in_mode([], 0.1, 1.0, 2.0)
    many = [(0.1, float(i)) for i in range(10)]
    assert learn_mode(many, 0.2, 3.0, keep=8) == [*many[3:], (0.2, 3.0)]


def test_topic_rate_slow_topic_needs_three_periods():
    # A 0.2 Hz topic: silence only after 3 periods (15 s) without a message.
    rates = [0.2] * 60 + [0.0] * 20
    frames = [(float(t), model(rate=r), []) for t, r in enumerate(rates)]
    assert drive("topic_rate", frames)[0] == (74.0, "topic:/img", "error")


def test_topic_rate_a_slow_topic_is_continuous_once_it_sent_settle_messages():
    # A gap detector's findings every 3 s while the robot drives an aisle (20 s), none for 20 s
    # while it turns or docks, and again: seven messages in its first run are too few to say it
    # never pauses (it settled as continuous after 10 s, and its first pause was a silence).
    drives = [float(t) for start in range(0, 120, 40) for t in range(start, start + 20, 3)]
    assert drive("topic_rate", sampled(drives, HALF)) == []
    # Ten messages or more without a pause: continuous, and a stop is a silence at 3 periods.
    steady = [float(t) for t in range(0, 45, 3)]
    assert drive("topic_rate", sampled(steady, HALF))[:1] == [(51.5, "topic:/img", "error")]


def test_topic_rate_expected_rate_from_config_and_unmeasured():
    frames = [(float(t), model(rate=6.0), []) for t in range(3)]
    assert drive("topic_rate", frames, expected={"topic:/img": 10.0}) == [(1.0, "topic:/img", "warn"),
                                                                         (2.0, "topic:/img", "warn")]
    frames = [(float(t), model(rate=float("nan")), []) for t in range(3)]
    assert drive("topic_rate", frames, expected={"topic:/img": 10.0}) == []


def test_topic_rate_only_watched():
    frames = [(float(t), model(rate=0.0 if t > 2 else 10.0), []) for t in range(6)]
    assert drive("topic_rate", frames, watch={"node:/camera"}) == []


# ------------------------------------------------- topic_rate: the topic's own rhythm

def seen(msgs, t, span=3.0):
    """θ the collector shows at ``t`` for messages received at ``msgs`` (its 3 s window): rate,
    age of the newest, recent rate over the last 5 intervals up to now."""
    inside = [m for m in msgs if t - span < m <= t]
    out = {"rate": len(inside) / span}
    if inside:
        out["age"] = t - inside[-1]
    if len(inside) >= 4:
        k = min(5, len(inside) - 1)
        out["recent"] = k / (t - inside[-1 - k])
    return out


def sampled(msgs, times, graph=model):
    """One frame per sample time of a topic whose messages arrive at ``msgs``."""
    return [(t, graph(**seen(msgs, t)), []) for t in times]


def bursts(starts, on=2.0, hz=10):
    """Messages at ``hz`` for ``on`` s from each start."""
    return [round(s + i / hz, 3) for s in starts for i in range(int(on * hz))]


HALF = [k + 0.5 for k in range(120)]  # samples at 0.5, 1.5, ... (between message times)


def test_topic_rate_a_topic_back_in_the_graph_is_judged_from_its_return():
    # An operator's joystick at 20 Hz until 30 s; its node leaves with the operator (the topic
    # gone from the graph 31-42 s) and is back at 43.5, publishing from 45: no silence (its quiet
    # while gone was no publisher's). Back at 43.5 and never publishing: silent from its return.
    def frames(msgs):
        out = []
        for t in HALF[:55]:
            if 31 <= t <= 43:
                G = model()
                G.remove_node("topic:/img")
            elif t == 43.5:  # back, not measured yet
                G = model()
                G.nodes["topic:/img"]["theta"] = make_theta("topic", {"publishers": 1})
            else:
                G = model(**seen(msgs, t))
            out.append((t, G, []))
        return out

    joy = [i / 20 for i in range(600)] + [45 + i / 20 for i in range(300)]
    assert drive("topic_rate", frames(joy)) == []
    assert drive("topic_rate", frames(joy[:600]))[:1] == [(45.5, "topic:/img", "error")]


def test_topic_rate_bursty_topic_is_quiet_when_healthy_and_silent_when_hung_past_its_own_gaps():
    healthy = bursts(range(0, 120, 8))  # 10 Hz for 2 s, then 6 s without a message, repeated
    assert drive("topic_rate", sampled(healthy, HALF)) == []
    # Hung after the burst at 48 (last message 49.9): learned gaps are 6.6 s (8.5 - 1.9), so the
    # limit is twice that, 13.2 s: silent at the first sample with a quiet of at least 13.2 s.
    hung = bursts(range(0, 49, 8))
    alerts = drive("topic_rate", sampled(hung, HALF), full=True)
    assert [(a.t, a.severity, a.data["symptom"]) for a in alerts][:1] == [(63.5, "error", "silence")]
    assert round(alerts[0].data["limit_s"], 2) == 13.2 and "longest healthy gap 6.6 s" in alerts[0].message
    # No next message was due: it went silent anywhere after its last one, up to now.
    assert alerts[0].data["since"] == pytest.approx(49.9)
    assert alerts[0].data["since_within"] == pytest.approx(alerts[0].data["silent_s"])


def test_topic_rate_gaps_a_healthy_run_showed_are_its_rhythm_in_the_next():
    # A healthy run whose first gap is 18 s (before its rhythm settled: learned), then 6 s ones.
    healthy = bursts([0, 20, *range(28, 120, 8)])
    learned = {}
    assert drive("topic_rate", sampled(healthy, HALF), learned=learned) == []
    # From its last message before (1.9) to the newest at the sample after (an upper bound).
    assert learned["topic_rate"]["gaps"] == {"topic:/img": pytest.approx(18.6)}
    # A run with 6 s gaps, then a pause of 20 s: past twice its own gaps (13.2 s) a silence on
    # its own; started from the healthy run, within twice its 18.6 s.
    paused = bursts([*range(0, 49, 8), 70, 78, 86])
    judged = {}
    alone = drive("topic_rate", sampled(paused, HALF[:95]), full=True, learned=judged)
    assert [(a.t, a.data["symptom"]) for a in alone][:1] == [(63.5, "silence")]
    assert drive("topic_rate", sampled(paused, HALF[:95]), learned=dict(learned)) == []
    # A run the user judged healthy, its alert included, teaches that pause as well.
    assert judged["topic_rate"]["gaps"] == {"topic:/img": pytest.approx(20.6)}  # 49.9 -> 70.5
    assert drive("topic_rate", sampled(paused, HALF[:95]), learned=judged) == []
    # Hung past twice the carried gap: silent, said so; and never judged by its rate.
    alerts = drive("topic_rate", sampled(bursts(range(0, 49, 8)), HALF), learned=dict(learned), full=True)
    assert [(a.t, a.data["symptom"]) for a in alerts][:1] == [(87.5, "silence")]  # 49.9 + 37.2
    assert alerts[0].data["limit_s"] == pytest.approx(37.2)
    assert "18.6 s in the healthy run it started from" in alerts[0].message


def test_topic_rate_a_loops_pause_ended_by_its_stamps_going_back_is_learned():
    # a recording played in loops: 10 Hz for 28 s, a 2 s pause, again (its stamps go back each time)
    msgs = bursts(range(0, 120, 30), on=28.0)
    frames = sampled(msgs, HALF)
    restarts = {30.5, 60.5, 90.5}  # the first sample after each pause

    def reset(t):
        return [Event(t - 0.5, "stamp_reset", "topic:/img", "info", "header stamps went back 30.0 s",
                      {"back_s": 30.0})] if t in restarts else []
    looped = [(t, G, reset(t)) for t, G, _ in frames]
    alerts = drive("topic_rate", looped)
    assert alerts and max(t for t, _, _ in alerts) < 30.5  # its first pause only: a departure
    # the same when the player warns of each loop as it pauses: the stamps say it was a loop
    said = [(t, G, reset(t) + ([Event(t - 1.5, "log", "node:/camera", "warn", "end of bag: looping", {})]
                               if t + 1.0 in restarts else [])) for t, G, _ in frames]
    alerts = drive("topic_rate", said)
    assert alerts and max(t for t, _, _ in alerts) < 30.5
    # without the stamps going back, every pause of the continuous topic is a silence
    assert max(t for t, _, _ in drive("topic_rate", frames)) > 90.0


def test_topic_rate_short_bursts_are_judged_by_their_rate_while_publishing():
    # 5 messages at 10 Hz every 6 s: the 3 s window's rate is at most 1.7 Hz and mostly lower
    # (0.3 Hz as a burst leaves it); its 5.6 s quiets are its rhythm, learned as gaps. (The grid of
    # rhythms in test_topic_rhythms.py holds the cases the window's rate got wrong.)
    healthy = bursts(range(0, 120, 6), on=0.5)
    assert drive("topic_rate", sampled(healthy, HALF)) == []
    hung = bursts(range(0, 49, 6), on=0.5)  # hung after the burst at 48 (last message 48.4)
    alerts = drive("topic_rate", sampled(hung, HALF), full=True)
    assert [(a.t, a.data["symptom"]) for a in alerts][:1] == [(60.5, "silence")]
    assert alerts[0].data["limit_s"] == pytest.approx(12.0)  # twice its learned gaps (6.4 - 0.4)


def test_topic_rate_a_continuous_topic_that_starts_to_flap_is_one_flapping_symptom():
    on = [i / 10 for i in range(200)]  # continuous at 10 Hz for 20 s, then silent 2 s, back 3 s, ...
    on += bursts([22.0, 27.0, 32.0], on=3.0)
    alerts = drive("topic_rate", sampled(on, HALF[:36]), full=True)
    assert [(a.t, a.severity) for a in alerts] == [(21.5, "error"), (26.5, "error"), (31.5, "error")]
    assert [a.data["flaps"] for a in alerts] == [1, 2, 3]  # counted, never learned as its rhythm:
    assert [a.data["limit_s"] for a in alerts] == [1.5, 1.5, 1.5]
    assert all(a.data["episode_hold_s"] == 30.0 for a in alerts)  # one episode in the store
    assert "silent 3 times in 30 s" in alerts[-1].message


def test_topic_rate_a_topic_that_published_once_or_a_few_times_is_not_silent():
    once = sampled([1.0], HALF[:60])  # a latched topic seen once: no run, no rhythm, no silence
    assert drive("topic_rate", once) == []
    few = sampled([1.0, 1.2, 5.0, 9.3], HALF[:60])  # on request, now and then
    assert drive("topic_rate", few) == []


def latched_model(**kw):
    G = model(**kw)
    G.nodes["topic:/img"]["qos"] = [_qos("/camera", "pub", dur="transient_local"),
                                    _qos("/detector", "sub", dur="transient_local")]
    return G


def test_topic_rate_a_latched_topic_that_stops_is_not_silent_unless_asked():
    msgs = [float(t) for t in range(20)]  # 1 Hz for 20 s, transient-local, then no more changes
    frames = sampled(msgs, HALF[:40], graph=latched_model)
    assert drive("topic_rate", frames) == []
    judged = drive("topic_rate", frames, settings={"judge_latched": True})
    assert judged[:1] == [(22.5, "topic:/img", "error")]  # 3 periods of 1 Hz after 19.0
    # The same stream without transient-local publishers is a continuous topic: silent.
    assert drive("topic_rate", sampled(msgs, HALF[:40]))[:1] == [(22.5, "topic:/img", "error")]


def lifecycle_model(transitions, t, **kw):
    """`model` whose publisher /camera is a lifecycle node with a transition at each of ``transitions``."""
    G = model(**kw)
    lc = seen(transitions, t)
    add_member(G, "topic:/camera/transition_event", theta=make_theta("topic", {
        "rate_hz": lc["rate"], "publishers": 1, **({"age_s": lc["age"]} if "age" in lc else {})}))
    add_flow_edge(G, "node:/camera", "topic:/camera/transition_event", "pub")
    return G


def test_topic_rate_a_deactivated_lifecycle_publisher_is_not_silent():
    # Active 0-20 s, deactivated at 20.0 (last message 19.9), active again at 40; hung at 60.
    msgs = [i / 10 for i in range(200)] + [40 + i / 10 for i in range(200)]
    transitions = [20.0, 40.0]
    frames = [(t, lifecycle_model(transitions, t, **seen(msgs, t)), []) for t in HALF[:110]]
    alerts = drive("topic_rate", frames, full=True)
    # The 20 s deactivation is healthy, and its length is the state's, not the topic's rhythm (not
    # learned): the hang after 59.9 is a silence at the base limit, as on any continuous topic.
    assert [(a.t, a.member) for a in alerts][:1] == [(61.5, "topic:/img")]
    assert alerts[0].data["limit_s"] == 1.5


def test_topic_rate_a_lifecycle_node_saying_standby_after_its_transition_is_not_silent():
    # Deactivated at 20.0 (last message 19.9), active again at 40. Its own status, each second at
    # .2, is OK while active and WARN "Standby" while not: the state it was put in, not trouble.
    msgs = [i / 10 for i in range(200)] + [40 + i / 10 for i in range(200)]

    def status(t, before=False, line_at=None):  # its status of 0.3 s before the sample
        u = t - 0.3
        bad = (before and 19.0 <= u < 20.0) or 20.0 <= u < 40.0
        text = f"lidar: {'WARN Standby' if bad else 'OK Streaming'}"
        ev = [Event(u, "diag", "node:/camera", "info", text,
                    {"name": "lidar", "level": 1 if bad else 0, "publisher": "node:/camera"})]
        if line_at is not None and t == 20.5:  # it said something was wrong as it changed state
            ev.append(Event(line_at, "log", "node:/camera", "error", "Scan matching diverged", {}))
        if t == 19.5:  # a WARN it repeats now and then, 1.4 s before the transition: not why
            ev.append(Event(18.6, "log", "node:/camera", "warn", "Window blockage detected", {}))
        return ev

    def frames(**kw):
        return [(t, lifecycle_model([20.0, 40.0], t, **seen(msgs, t)), status(t, **kw)) for t in HALF[:80]]

    assert drive("topic_rate", frames()) == []
    # A node whose own status was worse before its transition changed state because of it, as one
    # that logs why with it (its clock's stamp a moment before or after the transition arrived:
    # the blind courier's costmap, "rolling window lost the robot pose; deactivating"): a silence.
    for kw in ({"before": True}, {"line_at": 19.8}, {"line_at": 20.2}):
        assert drive("topic_rate", frames(**kw))[:1] == [(20.5, "topic:/img", "error")], kw


def test_topic_rate_a_goal_ending_by_the_last_message_explains_the_quiet():
    # /camera serves an action; its goal ends at 20.0, its output's last message is at 19.9.
    msgs = [i / 10 for i in range(200)]
    ended = Event(20.0, "goal", "node:/camera", "info", "goal 1a2b3c4d of /dock succeeded",
                  {"action": "/dock", "goal": "1a2b3c4d", "status": "succeeded"})
    frames = [(t, model(**seen(msgs, t)), [ended] if t == 20.5 else []) for t in HALF[:40]]
    assert drive("topic_rate", frames) == []
    # A goal that ends well after the output stopped (cancelled because it hung: 2.5 s after the
    # last message, > transition_grace_s) explains nothing, though it comes before the limit (5 s).
    late = Event(19.4, "goal", "node:/camera", "info", "goal 1a2b3c4d of /dock canceled",
                 {"action": "/dock", "goal": "1a2b3c4d", "status": "canceled"})
    hung = [(t, model(**seen(msgs[:170], t)), [late] if t == 19.5 else []) for t in HALF[:40]]
    silences = [a for a in drive("topic_rate", hung, settings={"silence_min_s": 5.0}) if a[2] == "error"]
    assert silences[:1] == [(22.5, "topic:/img", "error")]


def test_topic_rate_a_mode_the_node_announces_in_its_own_status_explains_the_quiet():
    # /camera captures only while low over the seabed; its own status says "capturing", then, at
    # 20.3 (its 1 Hz updater), "idle": its output stopped at 19.9 for a new mode, no silence.
    msgs = [i / 10 for i in range(200)]

    def said(t, words, level=0, by="node:/camera"):  # its status of 0.2 s before each sample
        text = f"camera_status: {'OK' if level == 0 else 'ERROR'} {words(t - 0.2)}"
        return [Event(t - 0.2, "diag", "node:/camera", "info", text,
                      {"name": "camera_status", "level": level, "publisher": by})]

    idle = [(t, model(**seen(msgs, t)), said(t, lambda u: "capturing" if u < 20 else "idle"))
            for t in HALF[:60]]
    assert drive("topic_rate", idle) == []
    # A reading that changes ("12.0 fps" -> "0.0 fps") is no new mode; nor is a status another
    # node publishes about it (an aggregator's copy), nor one no longer OK: a silence each time
    # (the node's own OK statuses after the quiet began not taken at their word: `self_reports`),
    # from 1.5 s, or 0.5 s once the node's own status is no longer OK (it complained).
    fps = (lambda u: f"{4.0 if u < 20 else 0.0:.1f} fps", {})
    for words, kw in (fps, (lambda u: "capturing" if u < 20 else "idle", {"by": "node:/agg"}),
                      (lambda u: "capturing" if u < 20 else "no frames", {"level": 2})):
        frames = [(t, model(**seen(msgs, t)), said(t, words, **kw)) for t in HALF[:60]]
        alerts = drive("topic_rate", frames, settings={"self_reports": False})
        assert alerts[:1] == [(20.5 if kw.get("level") else 21.5, "topic:/img", "error")], kw
        # Taken at their word, the node's own OK says its quiet is its state; the others do not.
        assert (drive("topic_rate", frames) == []) == (kw == {}), kw


def test_topic_rate_a_publisher_that_keeps_saying_ok_of_itself_vouches_for_its_quiet():
    # /img's fixes every 4 s stop after 36 (the vehicle surfaced); its own status says OK each second.
    msgs = [t for t in np.arange(0.0, 40.0, 4.0)]

    def status(t, level=0, by="node:/camera", until=math.inf):
        text = f"usbl_link: {'OK' if level == 0 else 'ERROR'}"
        return [Event(t - 0.2, "diag", "node:/camera", "info", text,
                      {"name": "usbl_link", "level": level, "publisher": by})] if t - 0.2 < until else []

    def frames(**kw):
        return [(t, model(**seen(msgs, t)), status(t, **kw)) for t in np.arange(1.0, 90.0, 1.0)]

    assert drive("topic_rate", frames()) == []
    # It stopped saying anything (a crash, a stalled executor) before its next fix was due (40),
    # it says ERROR, or only an aggregator's copy says OK: a silence.
    for kw in ({"until": 39.5}, {"level": 2}, {"by": "node:/agg"}):
        assert [a[2] for a in drive("topic_rate", frames(**kw))][:1] == ["error"], kw


def test_topic_rate_one_warn_in_a_vouched_quiet_is_routine_a_second_within_30_s_is_not():
    # The same receiver: one WARN line at 60 (a dropped sentence) leaves the quiet vouched for;
    # a second at 70 (within WARN_REPEAT_S of the first) is a complaint that goes on: a silence.
    msgs = [t for t in np.arange(0.0, 40.0, 4.0)]

    def events(t, warns):
        out = [Event(t - 0.2, "diag", "node:/camera", "info", "usbl_link: OK",
                     {"name": "usbl_link", "level": 0, "publisher": "node:/camera"})]
        return out + [Event(w, "log", "node:/camera", "warn", "checksum mismatch, dropped sentence", {})
                      for w in warns if t - 1.0 < w <= t]

    def frames(warns):
        return [(t, model(**seen(msgs, t)), events(t, warns)) for t in np.arange(1.0, 90.0, 1.0)]

    assert drive("topic_rate", frames([60.3])) == []
    assert [a[:3] for a in drive("topic_rate", frames([60.3, 70.3]))][:1] == [(71.0, "topic:/img", "error")]


def test_topic_rate_a_feeding_node_s_goal_ending_after_the_quiet_began_explains_nothing():
    # /detector computes /det from /camera's /img and stops at 19.95 while /img goes on; /camera
    # serves an action. Its goal ending first (19.8) is why /det stopped: healthy. Ending 0.75 s
    # after /det's last message (> a period + 0.25 s), it is /det's consequence (a mission
    # aborted because its setpoints stopped): /det is silent.
    img, det = [i / 10 for i in range(400)], [i / 10 + 0.05 for i in range(200)]

    def ended(at):
        return Event(at, "goal", "node:/camera", "info", "goal 1a2b3c4d of /dock aborted",
                     {"action": "/dock", "goal": "1a2b3c4d", "status": "aborted"})
    first = [(t, chain_model(img, det, t), [ended(19.8)] if t == 19.5 + 1 else []) for t in HALF[:40]]
    assert drive("topic_rate", first) == []
    after = [(t, chain_model(img, det, t), [ended(20.7)] if t == 20.5 + 1 else []) for t in HALF[:40]]
    assert drive("topic_rate", after)[:1] == [(21.5, "topic:/det", "error")]


def test_topic_rate_a_new_state_latched_by_a_feeding_node_explains_a_quiet():
    # /detector publishes /det while /mission's latched /state says so; /mission latches a new state
    # (ARRIVED) 70 ms after /det's last message, 18 s after its last one: /det stopping is healthy.
    # Later than a period + 0.25 s after it, or a latched topic republished every second, says
    # nothing of why /det stopped: silent.
    img, det = [i / 10 for i in range(400)], [i / 10 + 0.05 for i in range(200)]

    def frames(states):
        out = []
        for t in HALF[:40]:
            G = chain_model(img, det, t)
            st = seen(states, t)
            add_member(G, "node:/mission")
            add_member(G, "topic:/state", qos=[_qos("/mission", "pub", dur="transient_local"),
                                               _qos("/detector", "sub", dur="transient_local")],
                       theta=make_theta("topic", {"rate_hz": st["rate"], "publishers": 1,
                                                  **({"age_s": st["age"]} if "age" in st else {})}))
            add_flow_edge(G, "node:/mission", "topic:/state", "pub")
            add_flow_edge(G, "topic:/state", "node:/detector", "sub")
            out.append((t, G, []))
        return out

    assert drive("topic_rate", frames([2.0, 20.02])) == []
    assert drive("topic_rate", frames([2.0, 21.0]))[:1] == [(21.5, "topic:/det", "error")]
    every_second = [float(i) for i in range(40)]
    assert drive("topic_rate", frames(every_second))[:1] == [(21.5, "topic:/det", "error")]


def test_topic_rate_its_publisher_s_new_state_before_its_next_message_was_due_explains_a_quiet():
    # Bursts every 8 s (learned gaps 6.6 s), the last ending at 49.9. /camera latches a new state
    # (its route arrived) at 54, before its next burst was due (49.9 + 6.6 s): healthy. At 59, after
    # it was due, the state explains nothing: silent at 63.5, as without it.
    hung = bursts(range(0, 49, 8))

    def frames(states):
        out = []
        for t, G, ev in sampled(hung, HALF[:70]):
            st = seen(states, t)
            add_member(G, "topic:/state", qos=[_qos("/camera", "pub", dur="transient_local")],
                       theta=make_theta("topic", {"rate_hz": st["rate"], "publishers": 1,
                                                  **({"age_s": st["age"]} if "age" in st else {})}))
            add_flow_edge(G, "node:/camera", "topic:/state", "pub")
            out.append((t, G, ev))
        return out

    assert drive("topic_rate", frames([1.0, 54.0])) == []
    assert drive("topic_rate", frames([1.0, 59.0]))[:1] == [(63.5, "topic:/img", "error")]


def test_topic_rate_a_pause_while_its_process_is_busy_is_the_processs():
    # /camera's process computes for 4 s from 20 s (its executor held: no message 19.9-24.0).
    msgs = [i / 10 for i in range(200)] + [24.0 + i / 10 for i in range(100)]
    busy = [(t, model(cpu=95.0 if 20 <= t < 24 else noisy(5.0, 0.2), **seen(msgs, t)), []) for t in HALF[:34]]
    assert drive("topic_rate", busy) == []  # the CPU is process_resources' symptom
    idle = [(t, model(cpu=noisy(5.0, 0.2), **seen(msgs, t)), []) for t in HALF[:34]]
    assert drive("topic_rate", idle)[:1] == [(21.5, "topic:/img", "error")]


def chain_model(img, det, t, latched_img=False):
    """`model` plus /detector -> /det: messages of /img at ``img``, of /det at ``det``."""
    G = latched_model(**seen(img, t)) if latched_img else model(**seen(img, t))
    d = seen(det, t)
    add_member(G, "topic:/det", theta=make_theta("topic", {
        "rate_hz": d["rate"], "publishers": 1, **({"age_s": d["age"]} if "age" in d else {})}))
    add_flow_edge(G, "node:/detector", "topic:/det", "pub")
    return G


def test_topic_rate_a_quiet_that_follows_its_inputs_is_the_inputs():
    # /det is computed from /img (50 ms later). Healthy: /img comes from a latched publisher that
    # stops at 20 s (its quiet is healthy, so is the detections' that follows it): no alert.
    img = [i / 10 for i in range(200)]
    det = [m + 0.05 for m in img]
    frames = [(t, chain_model(img, det, t, latched_img=True), []) for t in HALF[:40]]
    assert drive("topic_rate", frames) == []
    # /img's publisher hangs at 20 s: the silence is /img's, not again on /det.
    frames = [(t, chain_model(img, det, t), []) for t in HALF[:40]]
    assert {m for _, m, _ in drive("topic_rate", frames)} == {"topic:/img"}
    # The detector hangs while /img goes on: /det is silent.
    img_on = [i / 10 for i in range(400)]
    frames = [(t, chain_model(img_on, det, t), []) for t in HALF[:40]]
    assert drive("topic_rate", frames)[:1] == [(21.5, "topic:/det", "error")]
    # An input that stopped long before /det did (> input_grace_s) does not explain it.
    frames = [(t, chain_model(img[:120], det, t, latched_img=True), []) for t in HALF[:40]]
    assert drive("topic_rate", frames)[:1] == [(21.5, "topic:/det", "error")]
    # /det is every other /img (5 Hz of 10): /img's last message, 19.9, came after /det's, 19.85,
    # and before /det's next was due: /det stops with it, its silence is /img's.
    halved = [m + 0.05 for m in img[::2]]
    frames = [(t, chain_model(img, halved, t), []) for t in HALF[:40]]
    assert {m for _, m, _ in drive("topic_rate", frames)} == {"topic:/img"}
    # Every fifth (2 Hz): /det's last, 19.55, is 0.35 s before /img's, so /det passes its limit
    # first (at 21.25 /img is quiet 1.35 s of its 1.5): it waits for its input to be judged.
    fifth = [m + 0.05 for m in img[::5]]
    frames = [(t + 0.25, chain_model(img, fifth, t + 0.25), []) for t in range(40)]
    assert {m for _, m, _ in drive("topic_rate", frames)} == {"topic:/img"}


def one_thread_model(img, det, t, main, running=1, latched_img=False, dispatching=lambda t: 0.0):
    """`chain_model` with the camera and the detector in one process (pid 100) whose executor
    (one thread running, or ``running``) uses ``main(t)`` % of a core; its main thread dispatching
    a multi-threaded executor when ``dispatching(t)`` is 1."""
    G = chain_model(img, det, t, latched_img=latched_img)
    G.remove_edge("process:200", "node:/detector")
    G.remove_node("process:200")
    G.nodes["node:/detector"]["pid"] = 100
    add_tree_edge(G, "process:100", "node:/detector")
    G.nodes["process:100"]["theta"] = make_theta("process", {
        "cpu_percent": 5.0, "rss_mb": 80.0, "threads": 4, "executor_cpu_percent": main(t),
        "running_threads": running, "dispatching": dispatching(t)})
    return G


def test_topic_rate_a_stalled_executor_silences_its_nodes_together_not_one_after_the_other():
    # The camera and the detector share one thread; both stop at 20 s (the detector's callback
    # blocks it, or the camera's: the order of their quiets cannot tell).
    img = [i / 10 for i in range(200)]
    det = [m + 0.05 for m in img]
    stopped = lambda t: noisy(3.0, 0.3) if t < 20 else 0.0  # noqa: E731
    frames = [(t, one_thread_model(img, det, t, stopped), []) for t in HALF[:40]]
    assert {(m, s) for _, m, s in drive("topic_rate", frames)} == {("topic:/img", "error"),
                                                                   ("topic:/det", "error")}
    # The camera's timer has no input: its silence says the thread went idle (a callback of any
    # node it runs may have blocked it; the RCA makes them candidates).
    got = [a for a in drive("topic_rate", frames, full=True) if a.member == "topic:/img"]
    assert got[0].data["executor_idle"] is True and "its executor's thread idle" in got[0].message
    # A late sample (20.5 missed) measures the thread over 19.5-21.5, half of it still working:
    # not yet a stop, and not the input's quiet for good either; the next sample shows the stop.
    late = lambda t: noisy(3.0, 0.3) if t < 20 else 1.5 if t < 22 else 0.0  # noqa: E731
    frames = [(t, one_thread_model(img, det, t, late), []) for t in HALF[:40] if t != 20.5]
    assert {(m, s) for _, m, s in drive("topic_rate", frames)} == {("topic:/img", "error"),
                                                                   ("topic:/det", "error")}
    # The thread goes on (other callbacks run: the camera lost its device): /det's quiet is /img's.
    going = lambda t: noisy(3.0, 0.3)  # noqa: E731
    frames = [(t, one_thread_model(img, det, t, going), []) for t in HALF[:40]]
    assert {m for _, m, _ in drive("topic_rate", frames)} == {"topic:/img"}
    assert all(a.data["executor_idle"] is False for a in drive("topic_rate", frames, full=True))
    # Threads of a multi-threaded process say nothing of one executor: as in two processes.
    frames = [(t, one_thread_model(img, det, t, stopped, running=3), []) for t in HALF[:40]]
    assert {m for _, m, _ in drive("topic_rate", frames)} == {"topic:/img"}
    # So do they when one probe saw only the dispatching main thread run (rclpy's multi-threaded
    # executor spinning, its workers too little to count) and it rests after: no stopped thread.
    spun = lambda t: 1.0 if t < 20 else 0.0  # noqa: E731
    frames = [(t, one_thread_model(img, det, t, stopped, dispatching=spun), []) for t in HALF[:40]]
    got = drive("topic_rate", frames, full=True)
    assert {a.member for a in got} == {"topic:/img"} and not any(a.data["executor_idle"] for a in got)
    # The input's quiet is healthy (its latched publisher stopped): the thread idles, no alert.
    frames = [(t, one_thread_model(img, det, t, stopped, latched_img=True), []) for t in HALF[:40]]
    assert drive("topic_rate", frames) == []


def withholding_model(det, t, main=None, img_until=40.0, status=None, client=False, running=1, sibling=False,
                      threads=lambda t: 4):
    """`chain_model` with /img at 10 Hz until ``img_until``; the detector's process's executor (one
    thread running, or ``running``) at ``main(t)`` % (None: not measured), its own /det_status at
    ``status``, a call to a server (``client``); ``sibling``: another node in its process; the
    process's thread count ``threads(t)``."""
    img = [i / 10 for i in range(int(img_until * 10))]
    G = chain_model(img, det, t)
    if main is not None:
        G.nodes["process:200"]["theta"] = make_theta("process", {
            "cpu_percent": 3.0, "rss_mb": 60.0, "threads": threads(t), "executor_cpu_percent": main(t),
            "running_threads": running})
    if sibling:
        add_member(G, "node:/tracker", pid=200, alive=True)
        add_tree_edge(G, "process:200", "node:/tracker")
    if status is not None:
        st = seen(status, t)
        add_member(G, "topic:/det_status", theta=make_theta("topic", {
            "rate_hz": st["rate"], "publishers": 1, **({"age_s": st["age"]} if "age" in st else {})}))
        add_flow_edge(G, "node:/detector", "topic:/det_status", "pub")
    if client:
        add_flow_edge(G, "node:/detector", "node:/camera", "send")
    return G


def test_topic_rate_an_output_withheld_by_a_working_node_is_its_rhythm():
    # The detector finds something in 0-20 s and 30-40 s, nothing in 20-30 s, while /img goes on.
    det = [m + 0.05 for m in [i / 10 for i in range(200)] + [30 + i / 10 for i in range(100)]]
    going = lambda t: noisy(3.0, 0.3)  # noqa: E731  its executor processes every image
    hung = lambda t: noisy(3.0, 0.3) if t < 20 else 0.0  # noqa: E731  blocked from 20 s
    frames = [(t, withholding_model(det, t, main=going), []) for t in HALF[:40]]
    assert drive("topic_rate", frames) == []
    # Its executor stopped (a hang): /det is silent, as without the main thread measured; the alert
    # says so (the RCA then ties the nodes that executor runs).
    frames = [(t, withholding_model(det[:200], t, main=hung), []) for t in HALF[:40]]
    got = drive("topic_rate", frames, full=True)
    assert [(a.t, a.member, a.severity) for a in got][:1] == [(21.5, "topic:/det", "error")]
    assert got[0].data["executor_stopped"] is True
    assert "its executor stopped while its input arrives" in got[0].message
    assert drive("topic_rate", [(t, withholding_model(det, t), []) for t in HALF[:40]])[:1] \
        == [(21.5, "topic:/det", "error")]
    # A single-threaded executor vouches for every node it runs; busy threads of a multi-threaded
    # process say nothing of one node.
    frames = [(t, withholding_model(det, t, main=going, sibling=True), []) for t in HALF[:40]]
    assert drive("topic_rate", frames) == []
    frames = [(t, withholding_model(det, t, main=going, running=3), []) for t in HALF[:40]]
    got = drive("topic_rate", frames, full=True)
    assert [(a.t, a.member) for a in got][:1] == [(21.5, "topic:/det")]
    assert got[0].data["executor_stopped"] is False
    # Its own other output going on shows it working (no main thread needed) ...
    status = [float(k) for k in range(40)]
    assert drive("topic_rate", [(t, withholding_model(det, t, status=status), []) for t in HALF[:40]]) == []
    # ... unless that stopped with it.
    frames = [(t, withholding_model(det, t, status=status[:20]), []) for t in HALF[:40]]
    assert ("topic:/det", "error") in {(m, s) for _, m, s in drive("topic_rate", frames)}
    # A node that calls a server may be waiting on it: its stall is a symptom, never withheld.
    frames = [(t, withholding_model(det, t, main=going, client=True), []) for t in HALF[:40]]
    assert drive("topic_rate", frames)[:1] == [(21.5, "topic:/det", "error")]
    # Withheld, then its input stops too (at 24.9 s; the executor idles): still no silence of /det
    # (the quiet is /img's).
    idles = lambda t: noisy(3.0, 0.3) if t < 25 else 1.2 if t < 26 else 0.0  # noqa: E731
    frames = [(t, withholding_model(det, t, main=idles, img_until=25), []) for t in HALF[:40]]
    assert {m for _, m, _ in drive("topic_rate", frames)} == {"topic:/img"}


def test_topic_rate_an_output_its_node_said_it_stopped_is_its_state():
    # /det stops at 20 s (its last message 19.95) in a multi-threaded process, whose busy threads
    # say nothing of one node: a silence, unless the detector logged a line as it stopped ("track
    # lost"), after a pause in its logging.
    det = [m + 0.05 for m in [i / 10 for i in range(200)]]
    going = lambda t: noisy(3.0, 0.3)  # noqa: E731

    def run(lines, main=going, running=3, events=lambda t: []):
        frames = []
        for t in HALF[:40]:
            G = withholding_model(det, t, main=main, running=running)
            said = [x for x in lines if x <= t]
            if said:
                G.nodes["node:/detector"]["logged_at"] = said[-1]
            frames.append((t, G, events(t)))
        return [(t, m) for t, m, _ in drive("topic_rate", frames)]

    assert run([])[:1] == [(21.5, "topic:/det")]
    assert run([20.0]) == []
    assert run([4.0, 20.0]) == []
    # A line seconds before the stop, or one of a node that logs every half second, says nothing.
    assert run([17.0])[:1] == [(21.5, "topic:/det")]
    assert run([k / 2 for k in range(1, 80)])[:1] == [(21.5, "topic:/det")]
    # Nor does a status line every 5 s that happened to come with the stop.
    assert run([5.0, 10.0, 15.0, 20.0])[:1] == [(21.5, "topic:/det")]
    assert run([5.0, 10.0, 20.0]) == []
    # Its single-threaded executor stopped with the line (a driver's "calibrating" before its read
    # blocked): the line was its last act.
    hung = lambda t: noisy(3.0, 0.3) if t < 20 else 0.0  # noqa: E731
    assert run([20.0], main=hung, running=1)[:1] == [(21.5, "topic:/det")]
    # A WARN with it is a complaint, no change of state.
    lost = Event(20.0, "log", "node:/detector", "warn", "lost the target", {})
    warn = lambda t: [lost] if t == 20.5 else []  # noqa: E731
    assert run([20.0], events=warn)[:1] == [(20.5, "topic:/det")]


def test_topic_rate_an_output_whose_thread_ended_is_silent_while_its_node_works():
    # /det stops at 20 s while the executor goes on: withheld, unless the process lost a thread
    # as it stopped (its publishing thread died on an exception).
    det = [m + 0.05 for m in [i / 10 for i in range(200)]]
    going = lambda t: noisy(3.0, 0.3)  # noqa: E731
    died = lambda t: 5 if t < 20 else 4  # noqa: E731
    alerts = drive("topic_rate", [(t, withholding_model(det, t, main=going, threads=died), [])
                                  for t in HALF[:40]], full=True)
    assert [(a.t, a.member) for a in alerts][:1] == [(21.5, "topic:/det")]
    assert "process:200 lost a thread as it stopped" in alerts[0].message
    # A thread count that moves by itself says nothing: withheld.
    churn = lambda t: 5 + int(t) % 2 if t < 20 else 4  # noqa: E731
    assert drive("topic_rate", [(t, withholding_model(det, t, main=going, threads=churn), [])
                                for t in HALF[:40]]) == []
    # A thread ending well after the quiet began is not this quiet's.
    late = lambda t: 5 if t < 30 else 4  # noqa: E731
    assert drive("topic_rate", [(t, withholding_model(det, t, main=going, threads=late), [])
                                for t in HALF[:40]]) == []
    # Back to its count (a thread restarted) before the quiet was judged: withheld.
    blip = lambda t: 4 if 20 <= t < 21 else 5  # noqa: E731
    assert drive("topic_rate", [(t, withholding_model(det, t, main=going, threads=blip), [])
                                for t in HALF[:40]]) == []


def test_topic_rate_learns_a_withheld_quiet_as_a_healthy_gap():
    det = [m + 0.05 for m in [i / 10 for i in range(200)] + [30 + i / 10 for i in range(100)]]
    ps = PluginSet.load(enable=["topic_rate"], cwd_plugins=False, settings={}, isolate=False)
    hist, prev = History(), new_graph()
    for t in HALF[:40]:
        G = withholding_model(det, t, main=lambda t: 3.0)
        record_history(hist, G, t)
        ps.run(t, G, G.nodes, hist, [], diff(prev, G), None)
        prev = G
    (plugin,) = ps.plugins
    r = plugin.state["rhythms"]["topic:/det"]
    assert r.settled and [round(g, 2) for g in r.gaps] == [10.5]  # 19.95 -> 30.45 (the newest at the sample)


def test_topic_rate_a_stopped_executor_under_arriving_inputs_is_a_silence_within_the_rhythm():
    # The detector's gap of 20-30 s is learned (limit 21 s); in view again from 30 s, it deadlocks
    # at 45 s while /img goes on: its executor stops, a silence at the base limit (1.5 s).
    in_view = [i / 10 for i in range(200)] + [30 + i / 10 for i in range(150)]
    det = [m + 0.05 for m in in_view]
    hung = lambda t: noisy(3.0, 0.3) if t < 45.5 else 0.0  # noqa: E731
    frames = [(t, withholding_model(det, t, main=hung, img_until=60), []) for t in HALF[:60]]
    alerts = drive("topic_rate", frames, full=True)
    assert [(a.t, a.member) for a in alerts][:1] == [(46.5, "topic:/det")]
    assert "executor stopped" in alerts[0].message and alerts[0].data["limit_s"] == 1.5
    assert {(a.member, a.data["limit_s"]) for a in alerts} == {("topic:/det", 1.5)}
    assert alerts[-1].t == 59.5  # for as long as it lasts
    # Its executor going on (nothing in view from 45 s): no alert; unmeasured: at its rhythm's limit.
    going = lambda t: noisy(3.0, 0.3)  # noqa: E731
    frames = [(t, withholding_model(det, t, main=going, img_until=60), []) for t in HALF[:60]]
    assert drive("topic_rate", frames) == []
    frames = [(t, withholding_model(det, t, img_until=60), []) for t in HALF[:60]]
    assert drive("topic_rate", frames)[:1] == [(21.5, "topic:/det", "error")]  # its first quiet, unlearned


def test_topic_rate_a_topic_whose_publisher_left_is_not_silent():
    def gone(**kw):
        G = model(**kw)
        G.remove_edge("node:/camera", "topic:/img", 0)
        theta = G.nodes["topic:/img"]["theta"]
        theta[5] = 0.0  # publishers
        return G

    msgs = [i / 10 for i in range(200)]
    frames = sampled(msgs, HALF[:20]) + sampled(msgs, HALF[20:40], graph=gone)
    assert drive("topic_rate", frames) == []  # an orphan: graph_anomalies' case


def test_topic_rate_forgets_the_rhythm_of_a_topic_gone_for_long():
    from plugins.topic_rate import FORGET_S, _forget
    from stream_viz.detect.api import PluginContext
    from stream_viz.detect.rhythm import Rhythm

    rhythms = {"topic:/img": Rhythm(newest=0.0), "topic:/old": Rhythm(newest=0.0),
               "topic:/recent": Rhythm(newest=FORGET_S - 1.0), "topic:/never": Rhythm()}
    _forget(PluginContext(FORGET_S + 1.0, model(), frozenset(), History()), rhythms)
    assert sorted(rhythms) == ["topic:/img", "topic:/recent"]  # in the graph, or gone lately


def param(t, node="node:/camera", **changed):
    return Event(t, "param", node, "info", "parameters changed", {"changed": changed, "deleted": []})


def test_topic_rate_a_reconfigured_rate_is_the_new_normal_a_drop_without_a_change_is_not():
    # 10 Hz, then 4 Hz from 30.0 (/camera's rate_hz set at 30.0): learned anew, no drop, no silence.
    msgs = [i / 10 for i in range(300)] + [30 + i / 4 for i in range(240)]
    set_rate = param(30.2, rate_hz="4.0")
    frames = [(t, model(**seen(msgs, t)), [set_rate] if t == 30.5 else []) for t in HALF[:90]]
    assert drive("topic_rate", frames) == []
    # The same drop without a parameter change is a rate drop (no new normal), and so is one whose
    # change came longer than reconfigure_s before it, or at another node.
    for events in ([], [param(19.0, rate_hz="4.0")], [param(30.2, node="node:/detector", k="1")]):
        frames = [(t, model(**seen(msgs, t)), events if t == 30.5 else []) for t in HALF[:90]]
        assert drive("topic_rate", frames)[:1] == [(32.5, "topic:/img", "warn")], events
    # A parameter set 4 s before a drop (an exposure tuned, then the camera degrades): not the
    # change's doing; a rate drop as without it.
    earlier = param(26.0, exposure="0.02")
    frames = [(t, model(**seen(msgs, t)), [earlier] if t == 26.5 else []) for t in HALF[:90]]
    assert drive("topic_rate", frames)[:1] == [(32.5, "topic:/img", "warn")]
    # The camera degrades at 30.0 (low from 31.5) and its rate is set at 34.0 (an executive slowing
    # it while idle): the drop was under way before the change, so it is not the change's.
    late = param(34.0, rate_hz="5.0")
    frames = [(t, model(**seen(msgs, t)), [late] if t == 34.5 else []) for t in HALF[:90]]
    assert drive("topic_rate", frames, settings={"confirm": 5})[:1] == [(35.5, "topic:/img", "warn")]
    # After the new normal is learned, a drop from it alerts: 4 Hz -> 1 Hz at 60 s.
    slowed = msgs[:300 + 120] + [60 + i for i in range(30)]
    frames = [(t, model(**seen(slowed, t)), [set_rate] if t == 30.5 else []) for t in HALF[:90]]
    assert drive("topic_rate", frames)[:1] == [(63.5, "topic:/img", "warn")]


def test_topic_rate_a_new_state_its_publisher_latched_is_a_new_normal_as_a_reconfiguration():
    # A command gate: 10 Hz, 4 Hz from 30.0 as it latches its new mode (an operator took over) at
    # 30.1, its last mode latched at 1.0: learned anew. The same drop with no new state: a drop.
    msgs = [i / 10 for i in range(300)] + [30 + i / 4 for i in range(240)]

    def frames(states):
        out = []
        for t in HALF[:90]:
            G, st = model(**seen(msgs, t)), seen(states, t)
            add_member(G, "topic:/mode", qos=[_qos("/camera", "pub", dur="transient_local")],
                       theta=make_theta("topic", {"rate_hz": st["rate"], "publishers": 1,
                                                  **({"age_s": st["age"]} if "age" in st else {})}))
            add_flow_edge(G, "node:/camera", "topic:/mode", "pub")
            out.append((t, G, []))
        return out

    assert drive("topic_rate", frames([1.0, 30.1])) == []
    assert drive("topic_rate", frames([1.0]))[:1] == [(32.5, "topic:/img", "warn")]


def test_topic_rate_a_publisher_that_complains_as_its_topic_stops_did_not_choose_the_quiet():
    # /img 10 Hz, out from 29.9 to 32.5 (a cable dropping out) as /camera latches a new state at
    # 30.1 (a PLC bridge's part present, every cycle): by itself the state explains the quiet.
    # The same with /camera's WARN at 30.3 ("signal lost"): a silence, from 0.5 s
    # (`complained_min_s`: the publisher's word confirms the quiet).
    msgs = [i / 10 for i in range(300)] + [32.5 + i / 10 for i in range(200)]

    def frames(said):
        out = []
        for t in HALF[:45]:
            G, st = model(**seen(msgs, t)), seen([1.0, 30.1], t)
            add_member(G, "topic:/mode", qos=[_qos("/camera", "pub", dur="transient_local")],
                       theta=make_theta("topic", {"rate_hz": st["rate"], "publishers": 1,
                                                  **({"age_s": st["age"]} if "age" in st else {})}))
            add_flow_edge(G, "node:/camera", "topic:/mode", "pub")
            out.append((t, G, said if t == 30.5 else []))
        return out

    assert [a for a in drive("topic_rate", frames([])) if a[2] == "error"] == []
    lost = Event(30.3, "log", "node:/camera", "warn", "signal lost: no counts", {})
    assert [a for a in drive("topic_rate", frames([lost])) if a[2] == "error"][:1] == [
        (30.5, "topic:/img", "error")]


def test_topic_rate_a_parameter_that_moved_no_rate_is_no_cause_when_it_changes_again():
    # 10 Hz, then 4 Hz from 30.0; /camera's exposure set at 30.2 (as at 30.2 it is the drop's cause:
    # a new normal, above). Set twice before, at 5.2 and 17.2, with the rate as it was, it is
    # known to move no rate: the drop at 30.0 is a fault (an executive setting the exposure
    # every cycle would otherwise hide any drop that came within seconds of one).
    msgs = [i / 10 for i in range(300)] + [30 + i / 4 for i in range(240)]
    exposures = {5.5: [param(5.2, exposure="0.01")], 17.5: [param(17.2, exposure="0.02")],
                 30.5: [param(30.2, exposure="0.03")]}
    frames = [(t, model(**seen(msgs, t)), exposures.get(t, [])) for t in HALF[:90]]
    assert drive("topic_rate", frames)[:1] == [(32.5, "topic:/img", "warn")]
    # Its rate_hz set at 30.2 instead, after the same exposures: still a change of its rate.
    exposures[30.5] = [param(30.2, rate_hz="4.0")]
    frames = [(t, model(**seen(msgs, t)), exposures.get(t, [])) for t in HALF[:90]]
    assert drive("topic_rate", frames) == []
    # Only the exposure at 30.2 (no history): taken for the change's new normal, as before.
    frames = [(t, model(**seen(msgs, t)), [param(30.2, exposure="0.03")] if t == 30.5 else [])
              for t in HALF[:90]]
    assert drive("topic_rate", frames) == []


def slowed_while_idle(slows, lag, end):
    """15 Hz, 5 Hz for 25 s from each of ``slows`` (an executive slowing a camera while the station
    idles); the ``fps`` events stamped ``lag`` s from each change (or from the k-th, ``lag[k]``)."""
    lags = lag if isinstance(lag, list) else [lag] * len(slows)
    bounds = sorted([(x, 5.0) for x in slows] + [(x + 25, 15.0) for x in slows])
    msgs, t, rate = [], 0.0, 15.0
    while t < end:
        while bounds and bounds[0][0] <= t:
            rate = bounds.pop(0)[1]
        msgs.append(t)
        t += 1.0 / rate
    events = {}
    for x, lag in zip(slows, lags, strict=True):
        for at, fps in ((x + lag, "5.0"), (x + 25 + lag, "15.0")):
            events.setdefault(math.floor(at) + 0.5, []).append(param(at, fps=fps))
    return [(t, model(**seen(msgs, t)), events.get(t, [])) for t in (k + 0.5 for k in range(end))]


def test_topic_rate_a_slower_rate_seen_a_sample_late_is_still_the_changes():
    # The event stamped 0.6 s before the camera slows: the recent rate is under half the baseline
    # only at the second sample after it (2.1 s), one sample later than a new rate's few intervals.
    assert drive("topic_rate", slowed_while_idle([55.0, 135.0], -0.6, 170)) == []
    # One change stamped 3.5 s early is a rate drop (too late to be the change's); it does not make
    # `fps` a parameter that moves no rate, so the next slowdowns are changes again.
    late = drive("topic_rate", slowed_while_idle([55.0, 135.0, 215.0, 295.0], [-0.6, -3.5, -0.6, -0.6], 330))
    assert late and {int(t) // 80 for t, _, _ in late} == {1}, late


def test_topic_rate_a_rate_doubled_by_a_parameter_is_its_new_normal():
    # A camera at 5 fps set to 10 at 28 s. Its recent rate, over its last intervals and the open
    # one, reads 0.84 of the fps, as the blind tunnel crawler's camera did (8.4 Hz at 10 fps): short
    # of twice the rate before. The rise is the change's all the same, learned anew: `fps` moved a
    # rate (two changes that move none make it a parameter that moves nothing, and the next fall a
    # drop: the crawler's executive sets its camera from 5 to 10 fps and back at every segment).
    frames = []
    for t in HALF[:50]:
        fps, rate = (10.0, min(10.0, 5.0 + 5.0 * (t - 28.0) / 3.0)) if t >= 28.0 else (5.0, 5.0)
        events = [param(27.9, fps="10.0")] if t == 28.5 else []
        frames.append((t, model(rate=rate, recent=0.84 * fps, age=0.095), events))
    ps = PluginSet.load(enable=["topic_rate"], cwd_plugins=False, settings={}, isolate=False)
    hist, prev, alerts = History(), new_graph(), []
    for t, G, events in frames:
        record_history(hist, G, t)
        alerts += ps.run(t, G, G.nodes, hist, events, diff(prev, G), None)[0]
        prev = G
    (plugin,) = ps.plugins
    assert alerts == [] and plugin.state["relearn"] == {"topic:/img": 27.9}
    assert plugin.state["param_misses"] == {("node:/camera", "fps"): 0}


def test_topic_rate_a_parameter_set_once_to_its_value_still_moves_the_rate_later():
    # An executive sets the camera's fps to the 15 it has at 10 s (no rate moves), then to 5 at 55:
    # one change that moved nothing does not make `fps` a parameter that moves no rate.
    frames = slowed_while_idle([55.0], -0.3, 90)
    frames[10] = (frames[10][0], frames[10][1], [param(10.2, fps="15.0")])
    assert drive("topic_rate", frames) == []


def test_topic_rate_a_bursty_topic_keeps_its_rhythm_through_parameter_changes():
    # 10 Hz for 2 s every 8 s; its node's threshold set every 4 s: its gaps are learned as ever,
    # and its hang (nothing after 98 s) is a silence at twice its longest gap.
    healthy = bursts(range(0, 100, 8))
    tuned = {t: [param(t - 0.3, threshold="0.6")] for t in HALF if int(t) % 4 == 0}
    frames = [(t, model(**seen(healthy, t)), tuned.get(t, [])) for t in HALF[:120]]
    alerts = drive("topic_rate", frames, full=True)
    assert [(a.t, a.member) for a in alerts][:1] == [(111.5, "topic:/img")]
    assert 12.0 <= alerts[0].data["limit_s"] <= 14.0, alerts[0].data


def test_topic_rate_a_quiet_after_a_reconfiguration_waits_for_its_new_rhythm():
    # 10 Hz, then 0.5 Hz from 32.0 (set at 30.0): no silence while the next messages come slower.
    msgs = [i / 10 for i in range(300)] + [32 + 2 * i for i in range(30)]
    set_rate = param(30.0, rate_hz="0.5")
    frames = [(t, model(**seen(msgs, t)), [set_rate] if t == 30.5 else []) for t in HALF[:90]]
    assert drive("topic_rate", frames) == []
    # A topic that stops 5 s after a parameter change is no slower rate: silent at its base limit.
    stops = [i / 10 for i in range(350)]
    frames = [(t, model(**seen(stops, t)), [set_rate] if t == 30.5 else []) for t in HALF[:60]]
    assert drive("topic_rate", frames)[:1] == [(36.5, "topic:/img", "error")]
    # Nothing after 29.9 (a hang that came with the change): judged reconfigure_s after the change.
    hung = msgs[:300]
    frames = [(t, model(**seen(hung, t)), [set_rate] if t == 30.5 else []) for t in HALF[:60]]
    assert drive("topic_rate", frames)[:1] == [(40.5, "topic:/img", "error")]


def test_topic_rate_a_reconfigured_input_passes_its_new_normal_downstream():
    # /det follows every /img message; /camera's rate_hz set from 10 to 4 Hz at 30.0.
    img = [i / 10 for i in range(300)] + [30 + i / 4 for i in range(240)]
    det = [m + 0.05 for m in img]
    set_rate = param(30.0, rate_hz="4.0")
    frames = [(t, chain_model(img, det, t), [set_rate] if t == 30.5 else []) for t in HALF[:90]]
    assert drive("topic_rate", frames) == []
    frames = [(t, chain_model(img, det, t), []) for t in HALF[:90]]
    assert {m for _, m, _ in drive("topic_rate", frames)} == {"topic:/img", "topic:/det"}


def served_model(served=True, called=True, **kw):
    """`model` whose /camera serves /detect (called by /planner when ``called``)."""
    G = model(**kw)
    if served:
        add_member(G, "node:/planner")
        add_member(G, "service:/detect", servers=["/camera"], clients=["/planner"] if called else [],
                   theta=make_theta("service", {"servers": 1, "clients": int(called)}))
    return G


def test_topic_rate_a_topic_published_on_request_is_not_silent_when_nobody_asks():
    # One message per request, every 10-12 s, then nobody asks for 40 s, then again.
    msgs = [5.0 + 11.0 * k + (k % 3) * 0.5 for k in range(6)] + [101.0 + 11.0 * k for k in range(3)]
    frames = [(t, served_model(**seen(msgs, t)), []) for t in HALF[:125]]
    assert drive("topic_rate", frames) == []
    # The same single messages from a node that serves nobody (or nobody calls): a silence.
    for served, called in ((False, False), (True, False)):
        frames = [(t, served_model(served, called, **seen(msgs, t)), []) for t in HALF[:125]]
        silences = [a for a in drive("topic_rate", frames) if a[2] == "error"]
        assert silences[:1] == [(84.5, "topic:/img", "error")], (served, called)
    # Asked every 3-4 s (no notable gap: it settles as continuous at ~0.3 Hz), then not for 30 s.
    often = [5.0 + 3.5 * k for k in range(12)] + [73.5 + 3.5 * k for k in range(8)]
    frames = [(t, served_model(**seen(often, t)), []) for t in HALF[:100]]
    assert drive("topic_rate", frames) == []
    frames = [(t, served_model(False, False, **seen(often, t)), []) for t in HALF[:100]]
    assert [a for a in drive("topic_rate", frames) if a[2] == "error"][:1] == [(52.5, "topic:/img", "error")]
    # Answers at 1 Hz while a client asks (a navigator replanning along a leg, 6-9 s), none
    # between legs (4-8 s, then 30 s at a lift): its clients' rhythm, not a hang.
    legs = [(5.0, 8), (17.0, 6), (27.0, 9), (40.0, 7), (79.0, 8), (93.0, 6)]
    replans = [s + k * 1.02 for s, n in legs for k in range(n)]
    frames = [(t, served_model(**seen(replans, t, span=3.0)), []) for t in HALF[:110]]
    assert drive("topic_rate", frames) == []
    frames = [(t, served_model(False, False, **seen(replans, t)), []) for t in HALF[:110]]
    assert [a for a in drive("topic_rate", frames) if a[2] == "error"][:1] != []
    # A burst topic of a server (10 Hz for 2 s) is not on request: its hang is a silence.
    burst = bursts(range(0, 50, 8))
    frames = [(t, served_model(**seen(burst, t)), []) for t in HALF[:90]]
    assert [a for a in drive("topic_rate", frames) if a[2] == "error"][:1] != []


def test_topic_rate_no_drop_on_a_bursty_topic_but_on_a_continuous_one():
    # Bursts of 20 Hz for 4 s every 6 s: the window's rate swings 0..20 Hz, the recent rate falls
    # at each burst's end; a rate baseline of such a topic is no basis for a drop.
    healthy = bursts(range(0, 120, 6), on=4.0, hz=20)
    assert drive("topic_rate", sampled(healthy, HALF)) == []
    steady = [i / 20 for i in range(600)] + [30 + i / 5 for i in range(50)]  # 20 Hz, then 5 Hz
    alerts = drive("topic_rate", sampled(steady, HALF[:36]), full=True)
    assert alerts and alerts[0].data["symptom"] == "rate_drop" and 30.5 <= alerts[0].t <= 32.5


# --------------------------------------------------------------------------- topic_latency

def test_topic_latency_quiet_then_rise_and_drops():
    healthy = [(float(t), model(latency=noisy(2.0, 0.3), jitter=noisy(1.0, 0.3)), []) for t in range(40)]
    assert drive("topic_latency", healthy) == []
    # Confirmed after 3 samples, counted once it has outlasted the 3 s window (latency_hold_s 4 s).
    sick = healthy[:30] + [(float(t), model(latency=150.0, jitter=1.0), []) for t in range(30, 36)]
    assert drive("topic_latency", sick) == [(34.0, "topic:/img", "warn"), (35.0, "topic:/img", "warn")]
    # Jitter must rise by half the period (50 ms at 10 Hz), not just by 20 ms.
    busy = healthy[:30] + [(float(t), model(jitter=40.0), []) for t in range(30, 34)]
    assert drive("topic_latency", busy) == []
    # A jitter rise counts once it has outlasted the collector's 3 s window (jitter_hold_s 4 s).
    bursty = healthy[:30] + [(float(t), model(jitter=90.0), []) for t in range(30, 36)]
    assert drive("topic_latency", bursty) == [(34.0, "topic:/img", "warn"), (35.0, "topic:/img", "warn")]
    # Drops risen above the topic's own, confirmed over 3 samples, counted once they outlast the
    # collector's 3 s window (drops_hold_s 4 s).
    drops = [(float(t), model(drops=noisy(0.2, 0.1) if t < 30 else 4.0), []) for t in range(36)]
    assert drive("topic_latency", drops) == [(34.0, "topic:/img", "warn"), (35.0, "topic:/img", "warn")]
    # One burst of losses, held up by the window for 3 samples: not the topic's.
    burst = [(float(t), model(drops=4.0 if 30 <= t < 33 else noisy(0.2, 0.1)), []) for t in range(36)]
    assert drive("topic_latency", burst) == []
    # Large messages reach the monitor's best-effort reader with fragments missing from the first
    # look on: ~2 a second is the topic's normal, a rise to 3 is not news, to 12 is.
    for late, want in ((3.0, []), (12.0, [34.0, 35.0])):
        lossy = [(float(t), model(drops=noisy(2.0, 0.5) if t < 30 else late), []) for t in range(36)]
        assert [a.t for a in drive("topic_latency", lossy, full=True)] == want, late
    # The same losses of a best-effort publisher's messages (a camera's frames): by design.
    for reliability, want in (("best_effort", []), ("reliable", [34.0, 35.0])):
        frames = []
        for t, G, ev in drops:
            G.nodes["topic:/img"]["qos"] = [{"role": "pub", "node": "/camera", "reliability": reliability}]
            frames.append((t, G, ev))
        assert [a[0] for a in drive("topic_latency", frames)] == want, reliability


def test_topic_latency_jitter_a_bursty_topic_often_shows_is_no_rise():
    # A topic in bursts: its 3 s window holds a gap in some samples (jitter ~400 ms) and not in
    # others (0). The median is 0; three windows with a gap in a row are its rhythm, not a rise.
    usual = [0.0, 0.0, 0.0, 420.0, 0.0] * 8 + [410.0, 430.0, 440.0, 0.0, 0.0]
    frames = [(float(t), model(jitter=j), []) for t, j in enumerate(usual)]
    assert drive("topic_latency", frames) == []
    # Past what it often shows (its 90th percentile, 420 ms) by the floor (50 ms at 10 Hz): a rise.
    sick = [*usual[:40], 480.0, 490.0, 500.0, 510.0, 520.0]
    frames = [(float(t), model(jitter=j), []) for t, j in enumerate(sick)]
    assert drive("topic_latency", frames) == [(44.0, "topic:/img", "warn")]


def test_topic_latency_one_gap_held_by_the_window_is_no_jitter_rise():
    # One gap (a mux switching sources, a container stalled for a moment) stays in the 3 s window
    # for 3-4 samples: the jitter is up for that long, fresh messages in every sample. No alert.
    healthy = [(float(t), model(jitter=noisy(1.0, 0.3)), []) for t in range(30)]
    twice = healthy + [(float(t), model(jitter=90.0 if t % 10 < 4 else noisy(1.0, 0.3)), [])
                       for t in range(30, 50)]  # gaps at 30-33 and 40-43
    assert drive("topic_latency", twice) == []
    # Held past the window, it is a change of the topic's rhythm.
    longer = [(float(t), model(jitter=90.0), []) for t in range(30, 35)]
    assert drive("topic_latency", healthy + longer) == [(34.0, "topic:/img", "warn")]
    # Latency, the window's mean, is held up by one late message alike: 3 samples are no rise.
    late = [(float(t), model(latency=150.0), []) for t in range(30, 33)]
    assert drive("topic_latency", healthy + late) == []


# --------------------------------------------------------------------------- process_resources

def test_process_resources_quiet_with_idle_noise():
    cpus = [noisy(5.0, 0.5) for _ in range(60)]
    cpus[30] = 22.0  # a blip below the absolute floor
    frames = [(float(t), model(cpu=c, rss=noisy(80.0, 0.01)), []) for t, c in enumerate(cpus)]
    assert drive("process_resources", frames) == []


def test_process_resources_cpu_hog_alerts_on_the_hosted_node():
    # A rise counts once it has held cpu_hold_s (3 s: a burst of work is no hog), then confirm (2).
    frames = [(float(t), model(cpu=noisy(5.0, 0.2) if t < 30 else 95.0), []) for t in range(36)]
    assert drive("process_resources", frames) == [(34.0, "node:/camera", "warn"),
                                                  (35.0, "node:/camera", "warn")]
    both = drive("process_resources", frames, settings={"alert_on": "both"})
    assert both[:2] == [(34.0, "node:/camera", "warn"), (34.0, "process:100", "warn")]
    # A first burst of 4 s (a plan, a map loaded) is over before it counts.
    burst = [(float(t), model(cpu=95.0 if 30 <= t < 34 else noisy(5.0, 0.2)), []) for t in range(40)]
    assert drive("process_resources", burst) == []


def test_process_resources_a_rise_a_parameter_change_brought_is_the_new_normal():
    from stream_viz.records import Event

    # /camera (pid 100) set to a higher resolution at 29.5 s: its CPU 5 -> 60 % from then on.
    change = Event(29.5, "param", "node:/camera", "info", "parameter of /camera: resolution = 1080")
    cpu = [noisy(5.0, 0.2) if t < 30 else noisy(60.0, 0.05) for t in range(60)]
    tuned = [(float(t), model(cpu=c), [change] if t == 30 else []) for t, c in enumerate(cpu)]
    assert drive("process_resources", tuned) == []
    # From the new normal, a hog (95 %) with no change is a rise again (once the new baseline is
    # learnt: warmup_s after the change).
    hog = tuned + [(float(t), model(cpu=95.0), []) for t in range(60, 66)]
    assert drive("process_resources", hog) == [(64.0, "node:/camera", "warn"), (65.0, "node:/camera", "warn")]
    # The same rise without a change, or with one of another node, or a rise that began before
    # the change, or one that began more than reconfigure_s (10 s) after it, is a rise.
    for events in ({}, {30: Event(29.5, "param", "node:/detector", "info", "x")},
                   {33: Event(32.5, "param", "node:/camera", "info", "x")},
                   {18: Event(17.5, "param", "node:/camera", "info", "x")}):
        frames = [(float(t), model(cpu=c), [events[t]] if t in events else [])
                  for t, c in enumerate(cpu[:36])]
        assert drive("process_resources", frames)[:1] == [(34.0, "node:/camera", "warn")], events
    # A CPU rise shows within two samples of the change that brings it (reconfigure_cpu_s, 4 s):
    # one 5.5 s later is a hog's, though a memory step as late is still the change's (a finer map
    # filled in takes a while).
    late = {25: Event(24.5, "param", "node:/camera", "info", "x")}
    frames = [(float(t), model(cpu=c), [late[t]] if t in late else []) for t, c in enumerate(cpu[:36])]
    assert drive("process_resources", frames)[:1] == [(34.0, "node:/camera", "warn")]
    rss = [80.0 + RNG.normal(0, 0.2) for _ in range(30)] + [200.0 + RNG.normal(0, 0.2) for _ in range(6)]
    frames = [(float(t), model(rss=r), [late[t]] if t in late else []) for t, r in enumerate(rss)]
    assert drive("process_resources", frames) == []
    # With its single executor's thread read: a rise on that thread is the change's; the same rise
    # beside it (a runaway worker thread, the executor at its usual 4 %) is not.
    inside = [(float(t), model(cpu=c, executor=c - 1.0), [change] if t == 30 else [])
              for t, c in enumerate(cpu)]
    assert drive("process_resources", inside) == []
    beside = [(float(t), model(cpu=c, executor=noisy(4.0, 0.2)), [change] if t == 30 else [])
              for t, c in enumerate(cpu[:36])]
    assert drive("process_resources", beside)[:1] == [(34.0, "node:/camera", "warn")]


def test_process_resources_a_rise_of_the_executors_dispatching_thread_is_no_symptom():
    # A multi-threaded executor at 10 %, its dispatching main thread 8 % of it; at 15 s the process
    # goes to 90 % for 45 s, longer than its time at 10 %. Carried by that thread (rclpy's dispatch
    # loop spinning while callbacks wait for a worker): no alert, nor jitter on its topic. Carried
    # by another thread (a worker's callback, a runaway thread; the dispatcher at its 8 %): the
    # rise it always was.
    def frames(dispatched, n=60):
        return [(float(t), model(cpu=noisy(10.0) if t < 15 else noisy(90.0),
                                 jitter=1.0 if t < 15 else 60.0,
                                 dispatch=noisy(8.0) if t < 15 or not dispatched else noisy(87.0)), [])
                for t in range(n)]
    assert drive("process_resources", frames(True)) == []
    assert drive("topic_latency", frames(True)) == []
    hog = drive("process_resources", frames(False))
    assert hog[:1] == [(19.0, "node:/camera", "warn")] and hog[-1] == (59.0, "node:/camera", "warn")
    assert drive("topic_latency", frames(False))[:1] == [(19.0, "topic:/img", "warn")]
    # Nor is it evidence for the RCA.
    from stream_viz.detect.process import process_anomalies
    for dispatched, found in ((True, set()), (False, {"process:100", "node:/camera"})):
        hist = History()
        for t, G, _ in frames(dispatched, 26):
            record_history(hist, G, t)
        assert process_anomalies(G, hist) == found


def test_a_process_rise_names_the_sibling_that_began_to_warn_with_it():
    # The camera's process hosts a reader too; at 20 s the process goes from 10 % to 95 %. The
    # reader logs a WARN as it rises and its status turns WARN; the camera has warned every 5 s
    # since the start (its normal). The alert names the reader, whose warning began with the rise.
    def frame(t):
        G = model(cpu=noisy(95.0) if t >= 20 else noisy(10.0))
        add_member(G, "node:/reader", pid=100, alive=True)
        add_tree_edge(G, "process:100", "node:/reader")
        return G

    def events(t, reader_from):
        out = [Event(t, "log", "node:/camera", "warn", "exposure clipped", {})] if t % 5 == 0 else []
        if t >= reader_from and t % 5 == 0:
            out += [Event(t, "log", "node:/reader", "warn", "falling back to CPU inference", {}),
                    Event(t, "diag", "node:/reader", "warn", "reader: WARN CPU fallback", {"level": 1})]
        return out

    alerts = drive("process_resources", [(float(t), frame(t), events(t, 20)) for t in range(30)], full=True)
    assert alerts and {a.member for a in alerts} == {"node:/camera", "node:/reader"}
    assert all(a.data["names"] == ["node:/reader"] for a in alerts), alerts[0].data
    assert "/reader began to warn: falling back to CPU inference" in alerts[0].message
    # A reader that has warned all along began nothing with the rise: the alert names nobody.
    alerts = drive("process_resources", [(float(t), frame(t), events(t, 0)) for t in range(30)], full=True)
    assert alerts and all("names" not in a.data for a in alerts), alerts[0].data


def test_a_dispatchers_spin_is_no_burst_that_would_hide_a_hog():
    # 15 s of the dispatcher spinning (20-35 s), then a runaway thread from 60 s (the main thread at
    # its 8 %): a rise after cpu_hold_s, not after twice the spin.
    def frame(t):
        if 20 <= t < 35:
            return model(cpu=noisy(90.0), dispatch=noisy(87.0))
        return model(cpu=noisy(100.0) if t >= 60 else noisy(10.0), dispatch=noisy(8.0))
    frames = [(float(t), frame(t), []) for t in range(70)]
    assert drive("process_resources", frames)[:1] == [(64.0, "node:/camera", "warn")]
    from stream_viz.detect.process import process_anomalies
    hist = History()
    for t, G, _ in frames[:66]:
        record_history(hist, G, t)
    assert process_anomalies(G, hist) == {"process:100", "node:/camera"}


def test_dispatcher_rise_is_half_the_process_rise_or_more():
    from stream_viz.detect.process import dispatcher_rise

    # The process 10 -> 90 %: its dispatching main thread at 50 % carries at least 40 points of it.
    assert dispatcher_rise(90.0, 10.0, 50.0, 1.0)
    assert not dispatcher_rise(90.0, 10.0, 49.0, 1.0)
    assert not dispatcher_rise(90.0, 10.0, 80.0, 0.0)  # not a dispatching main thread
    assert not dispatcher_rise(90.0, 10.0, 80.0, float("nan"))
    assert not dispatcher_rise(90.0, 10.0, float("nan"), 1.0)
    from stream_viz.detect.process import undispatched
    assert undispatched(np.array([10.0, 90.0, 90.0, 90.0]), np.array([8.0, 85.0, 20.0, 85.0]),
                        np.array([1.0, 1.0, 1.0, np.nan]), 10.0).tolist() == [10.0, 10.0, 90.0, 90.0]


def test_process_resources_memory_growth():
    rss = [80.0 + RNG.normal(0, 0.2) for _ in range(30)] + [80.0 + 5.0 * i for i in range(1, 11)]
    frames = [(float(t), model(rss=r), []) for t, r in enumerate(rss)]
    alerts = drive("process_resources", frames)
    assert alerts and alerts[0][1] == "node:/camera"
    assert 32.0 <= alerts[0][0] <= 35.0  # within a few samples of the leak starting at t=30


def test_process_resources_one_big_allocation_is_not_a_leak():
    rss = [80.0 + RNG.normal(0, 0.2) for _ in range(30)] + [200.0 + RNG.normal(0, 0.2) for _ in range(3)]
    frames = [(float(t), model(rss=r), []) for t, r in enumerate(rss)]
    # A +120 MB step is a memory anomaly vs the baseline (confirmed after 2 samples) but no growth.
    assert drive("process_resources", frames) == [(31.0, "node:/camera", "warn"),
                                                  (32.0, "node:/camera", "warn")]
    # Whatever the noise around the step (half of its steps rising or more looked "steady").
    for seed in range(40):
        rng = np.random.default_rng(seed)
        rss = [80.0 + rng.normal(0, 0.2) for _ in range(30)] + [200.0 + rng.normal(0, 0.2) for _ in range(3)]
        frames = [(float(t), model(rss=r), []) for t, r in enumerate(rss)]
        alerts = drive("process_resources", frames, full=True)
        assert [(a.t, a.data["symptoms"]) for a in alerts] == [(31.0, ["memory"]), (32.0, ["memory"])], seed


def test_process_resources_memory_at_a_new_level_is_its_new_normal():
    # +120 MB in one step at 30 s, level after: a symptom while it is recent (the trend's last
    # half, 30 s), then the process's new normal (a map loaded, a buffer grown to its size).
    rss = [80.0 + RNG.normal(0, 0.2) for _ in range(30)] + [200.0 + RNG.normal(0, 0.2) for _ in range(60)]
    frames = [(float(t), model(rss=r), []) for t, r in enumerate(rss)]
    times = [t for t, _, _ in drive("process_resources", frames)]
    assert times[0] <= 31.0 and set(range(31, 60)) <= set(times) and max(times) == 59.0


def test_process_resources_growth_from_the_start_is_start_up_until_startup_s():
    # 150 MB over the first 40 s, then level: its start-up, no alert; the same growth after 30 s
    # of a level RSS is a leak (the previous test's).
    rss = [80.0 + min(t, 40) * 3.75 + RNG.normal(0, 0.2) for t in range(90)]
    assert drive("process_resources", [(float(t), model(rss=r), []) for t, r in enumerate(rss)]) == []
    # Still growing after startup_s (120 s): a leak after all.
    rss = [80.0 + t * 1.5 + RNG.normal(0, 0.2) for t in range(130)]
    alerts = drive("process_resources", [(float(t), model(rss=r), []) for t, r in enumerate(rss)])
    assert alerts and alerts[0][0] == 120.0


def test_process_resources_cpu_bursts_it_has_shown_are_its_rhythm_a_hog_outlasts_them():
    # A planner busy for 2 s every 20 s: the first burst is over before it counts (cpu_hold_s),
    # the next ones are its rhythm; then a hog from 100 s on is a rise once it outlasts 2 × 2 s.
    cpu = [90.0 if t >= 20 and t % 20 < 2 else noisy(5.0, 0.2) for t in range(100)] + [95.0] * 10
    alerts = drive("process_resources", [(float(t), model(cpu=c), []) for t, c in enumerate(cpu)])
    assert [t for t, _, _ in alerts] == [106.0, 107.0, 108.0, 109.0]  # risen at 105 (5 s > 4 s), confirmed
    # Bursts of 6 s, longer than the hold: the first is a rise, the next ones its rhythm.
    cpu = [90.0 if t >= 20 and t % 20 < 6 else noisy(5.0, 0.2) for t in range(100)]
    alerts = drive("process_resources", [(float(t), model(cpu=c), []) for t, c in enumerate(cpu)])
    assert [t for t, _, _ in alerts] == [24.0, 25.0]


def test_process_resources_bursts_a_healthy_run_showed_are_its_rhythm_in_the_next():
    # Bursts of 6 s every 20 s: in a run of its own the first is a rise; in a run started from
    # that one (by the nodes of the process, not its PID) none is, and a hog outlasting 2 × 6 s is.
    cpu = [90.0 if t >= 20 and t % 20 < 6 else noisy(5.0, 0.2) for t in range(100)]
    frames = [(float(t), model(cpu=c), []) for t, c in enumerate(cpu)]
    learned = {}
    assert [t for t, _, _ in drive("process_resources", frames, learned=learned)] == [24.0, 25.0]
    assert learned == {"process_resources": {"bursts": {"node:/camera": 6.0}}}
    assert drive("process_resources", frames, learned=dict(learned)) == []
    hog = [noisy(5.0, 0.2) for _ in range(40)] + [95.0] * 20
    hog_frames = [(float(t), model(cpu=c), []) for t, c in enumerate(hog)]
    alerts = drive("process_resources", hog_frames, learned=learned)
    assert [t for t, _, _ in alerts][:1] == [54.0]  # risen at 53 (13 s > 2 × 6 s), confirmed


def test_topic_rate_a_mode_a_healthy_run_showed_is_no_drop_in_the_next():
    # 10 Hz stepping to 4 Hz for 10 s and back, twice: in a run of its own the first step is a
    # drop; in a run started from that one, neither is, and a drop to 1 Hz (deeper than half the
    # mode's 0.4) is.
    rates = [noisy(10.0, 0.02) if t < 30 or 40 <= t < 60 or t >= 70 else 4.0 for t in range(90)]
    frames = [(float(t), model(rate=r, recent=r), []) for t, r in enumerate(rates)]
    learned = {}
    first = drive("topic_rate", frames, learned=learned)
    assert first and {t for t, _, _ in first} < set(range(30, 40)), first
    assert [seconds for _, seconds in learned["topic_rate"]["modes"]["topic:/img"]] == [10.0, 10.0]
    assert drive("topic_rate", frames, learned=dict(learned)) == []
    deeper = [noisy(10.0, 0.02) if t < 30 else 1.0 for t in range(40)]
    alerts = drive("topic_rate", [(float(t), model(rate=r, recent=r), []) for t, r in enumerate(deeper)],
                   learned=learned)
    assert alerts and alerts[0][0] <= 33.0, alerts


def test_process_resources_slow_leak():
    rss = [80.0 + RNG.normal(0, 0.2) for _ in range(30)] + [80.0 + 1.5 * i for i in range(1, 41)]
    frames = [(float(t), model(rss=r), []) for t, r in enumerate(rss)]
    alerts = drive("process_resources", frames)
    assert alerts and 44.0 <= alerts[0][0] <= 55.0


def test_process_resources_watched_through_the_node():
    frames = [(float(t), model(cpu=5.0 if t < 30 else 95.0), []) for t in range(35)]
    assert drive("process_resources", frames, watch={"node:/camera"}) == [(34.0, "node:/camera", "warn")]
    assert drive("process_resources", frames, watch={"node:/detector"}) == []


# --------------------------------------------------------------------------- member_gone

def test_member_gone_exit_restart_left_and_not_alive():
    G = model()
    data = {"pid": 100, "process": "process:100", "nodes": ["node:/camera"], "still_listed": ["node:/camera"]}
    exit_events = [Event(5.0, "exit", "node:/camera", "error", "process 100 exited", data),
                   Event(5.0, "exit", "process:100", "error", "process 100 exited", data)]
    G_dead = model(alive=False)
    G_gone = model()
    G_gone.remove_nodes_from(["node:/camera", "process:100"])
    frames = [(4.0, G, []), (5.0, G_dead, exit_events), (6.0, G_dead, []), (7.0, G_gone, [])]
    # exit: once on the node (not also on its process); alive=False: error while it lasts, but not
    # twice in the sample of the exit; removal after an exit: no new alert.
    assert drive("member_gone", frames) == [(5.0, "node:/camera", "error"), (6.0, "node:/camera", "error")]
    restart = [Event(3.0, "restart", "node:/camera", "warn", "node /camera now runs in process 300",
                     {"old_pid": 100, "pid": 300})]
    G_left = model()
    G_left.remove_node("node:/detector")
    # A node that leaves the graph while its process runs on was destroyed on purpose: no alert
    # (it was a warn before issue 16); one whose process cannot be seen (no pid) still warns.
    assert drive("member_gone", [(2.0, G, []), (3.0, G, restart), (4.0, G_left, [])]) == [
        (3.0, "node:/camera", "warn")]
    G_remote = model()
    G_remote.nodes["node:/detector"]["pid"] = None
    assert drive("member_gone", [(2.0, G_remote, []), (3.0, G_left, [])]) == [(3.0, "node:/detector", "warn")]
    assert drive("member_gone", [(float(t), G, []) for t in range(5)]) == []


def test_member_gone_a_process_never_read_is_not_alive_only_once_that_lasted():
    # A one-shot job's process ended (exit 0) before the sampler read it; under load DDS listed its
    # node one sample more: no alert. A node listed 3 s with its process gone is not alive.
    G, G_dead, G_gone = model(), model(alive=False), model()
    G_gone.remove_nodes_from(["node:/camera", "process:100"])
    lag = [(1.0, G, []), (2.0, G_dead, []), (3.0, G_gone, [])]
    assert drive("member_gone", lag) == []
    stays = [(1.0, G, [])] + [(float(t), G_dead, []) for t in range(2, 7)]
    assert drive("member_gone", stays) == [(t, "node:/camera", "error") for t in (5.0, 6.0)]
    assert drive("member_gone", stays, settings={"not_alive_s": 0.0}) == [
        (float(t), "node:/camera", "error") for t in range(2, 7)]


def test_member_gone_a_node_listed_briefly_without_a_process_deregistered():
    # A spawner (no pid found: it ended before its process was) joins at 5 s and leaves at 8 s:
    # a crashed node stays listed until its DDS lease ends, so it deregistered. Listed from 5 s
    # to 20 s, its departure cannot be told from a lease running out: it warns.
    G = model()
    G_with = model()
    add_member(G_with, "node:/spawner", pid=None)

    def run(leave_at):
        frames = [(float(t), G_with if 5 <= t < leave_at else G, []) for t in range(leave_at + 2)]
        return drive("member_gone", frames)

    assert run(8) == []
    assert run(20) == [(20.0, "node:/spawner", "warn")]


def exit_of(t, pid, nodes, still_listed):
    """The collector's exit events of process ``pid`` (one per node, one for the process)."""
    data = {"pid": pid, "process": f"process:{pid}", "nodes": nodes, "still_listed": still_listed}
    return [Event(t, "exit", m, "error" if still_listed else "warn", f"process {pid} exited", data)
            for m in [*nodes, f"process:{pid}"]]


def camera_in(pid, alive=True, instances=1):
    """`model` with /camera in process ``pid`` (None: not running, the node gone from the graph)."""
    G = model()
    G.remove_nodes_from(["node:/camera", "process:100"])
    if pid is not None:
        add_member(G, f"process:{pid}", pid=pid, alive=alive)
        add_member(G, "node:/camera", pid=pid, alive=alive, instances=instances)
        add_flow_edge(G, "node:/camera", "topic:/img", "pub")
        add_tree_edge(G, f"process:{pid}", "node:/camera")
    return G


def test_member_gone_a_clean_exit_and_a_process_without_nodes_raise_nothing():
    # /camera deregisters (t=3), then its process ends (t=4, not listed any more): exit code 0 or
    # not, a clean exit. A process that hosted no node ends: nothing either.
    frames = [(2.0, camera_in(100), []), (3.0, camera_in(None), []),
              (4.0, camera_in(None), exit_of(4.0, 100, [], [])),
              (5.0, camera_in(None), exit_of(5.0, 777, [], []))]
    assert drive("member_gone", frames) == []
    # Both in one sample: the node had left the DDS graph when its process ended.
    frames = [(2.0, camera_in(100), []), (3.0, camera_in(None), exit_of(3.0, 100, ["node:/camera"], []))]
    assert drive("member_gone", frames) == []


def coded_exit(t, pid, nodes, code, still_listed=()):
    """`exit_of` with the exit code the kernel reported."""
    events = exit_of(t, pid, nodes, list(still_listed))
    for e in events:
        e.data["exit_code"] = code
    return events


def test_member_gone_an_error_exit_after_the_goodbye_alone_is_a_crash():
    # /camera's process ends with code 1 in the sample its node left the graph (rclpy destroyed it
    # on the way out of an uncaught exception); said once 2 s have passed without another exit.
    def run(code, others=()):
        ended = coded_exit(3.0, 100, ["node:/camera"], code)
        frames = [(2.0, camera_in(100), []), (3.0, camera_in(None), ended)]
        frames += [(t, camera_in(None), list(others) if t == 4.0 else []) for t in (4.0, 5.0, 6.0)]
        return drive("member_gone", frames, full=True)

    [alert] = run(1)
    assert (alert.t, alert.member, alert.severity) == (5.0, "node:/camera", "error")
    assert alert.data["after_goodbye"] is True and alert.data["process"] == "process:100"
    assert "an uncaught exception" in alert.message
    assert run(0) == [] and run(-2) == [] and run(-15) == []  # exit 0, a stop signal: a stop
    assert run(None) == []  # no code known: a clean goodbye, as before
    # Another process with nodes ending within 2 s: a launch file shut down, whatever the codes.
    assert run(1, coded_exit(4.0, 200, ["node:/detector"], 0)) == []
    assert run(1, coded_exit(4.0, 300, [], 1)) != []  # a process without nodes is no stop of the robot


def test_error_exits_decides_after_the_window_and_groups_stops():
    from stream_viz.detect.exits import error_exits

    state: dict = {}
    a, b = coded_exit(10.0, 1, ["node:/a"], 1), coded_exit(11.5, 2, ["node:/b"], 1)
    assert error_exits(a, 10.0, state) == [] and error_exits([], 11.0, state) == []
    assert error_exits(b, 11.5, state) == []
    assert error_exits([], 12.0, state) == []  # /a's window passed: /b ended 1.5 s after it
    assert error_exits([], 14.0, state) == []  # nor /b: /a ended 1.5 s before it
    assert state["pending"] == {}
    c = coded_exit(20.0, 3, ["node:/c", "node:/d"], 134, still_listed=["node:/d"])
    assert error_exits(c, 20.0, state) == []
    assert [(e.member, left) for e, left in error_exits([], 22.0, state)] == [("process:3", ["node:/c"])]


def test_member_gone_a_restart_loop_is_one_escalating_symptom_of_the_node():
    # /camera crashes (still listed when its process ends) and is started again, 7 times in 35 s.
    frames, pid = [(0.0, camera_in(100), [])], 100
    for k in range(1, 8):
        t = 5.0 * k
        frames.append((t, camera_in(None), exit_of(t, pid, ["node:/camera"], ["node:/camera"])))
        pid += 1
        frames.append((t + 1.0, camera_in(pid), []))
    alerts = drive("member_gone", frames, full=True)
    assert {a.member for a in alerts} == {"node:/camera"}  # never a process:<pid> member
    restarts = [(a.t, a.severity, a.data["restarts"]) for a in alerts if a.data["symptom"] == "restart"]
    assert restarts == [(6.0, "warn", 1), (11.0, "warn", 2), (16.0, "error", 3), (21.0, "error", 4),
                        (26.0, "error", 5), (31.0, "fatal", 6), (36.0, "fatal", 7)]
    assert [a.t for a in alerts if a.data["symptom"] == "exit"] == [5.0, 10.0, 15.0, 20.0, 25.0, 30.0, 35.0]
    assert "restarted 7 times in 30 s" in alerts[-1].message
    assert all(a.data["episode_hold_s"] == 60.0 for a in alerts)


def test_member_gone_a_restart_loop_behind_ghosts_of_crashed_processes():
    # As the collector shows a crash loop: a killed process's node stays listed (alive=False) until
    # its DDS lease ends, so the next process of the name shows first as one more instance (its
    # pid still the dead one's), then takes the name's pid (a `restart` event).
    moved = [Event(10.0, "restart", "node:/camera", "warn", "now in process 200", {"pid": 200})]
    frames = [(1.0, camera_in(100), []), (2.0, camera_in(100), []),
              (4.0, camera_in(100, alive=False), exit_of(4.0, 100, ["node:/camera"], ["node:/camera"])),
              (9.0, camera_in(100, alive=False, instances=2), []),
              (10.0, camera_in(200, instances=2), moved),
              (12.0, camera_in(200, alive=False, instances=2),
               exit_of(12.0, 200, ["node:/camera"], ["node:/camera"])),
              (13.0, camera_in(200, alive=False, instances=3), [])]
    alerts = drive("member_gone", frames, full=True)
    assert [(a.t, a.data["symptom"], a.severity) for a in alerts] == [
        (4.0, "exit", "error"), (9.0, "restart", "warn"), (9.0, "not_alive", "error"),
        (12.0, "exit", "error"), (13.0, "restart", "warn"), (13.0, "not_alive", "error")]
    assert [a.data["restarts"] for a in alerts if a.data["symptom"] == "restart"] == [1, 2]


def test_member_gone_a_node_that_comes_back_cleanly_now_and_then_is_healthy():
    # A job that runs, exits cleanly, and is started again a minute later, three times.
    frames, pid = [], 100
    for k in range(3):
        t = 70.0 * k
        frames += [(t, camera_in(pid), []), (t + 10.0, camera_in(None), exit_of(t + 10.0, pid, [], []))]
        pid += 1
    assert drive("member_gone", frames) == []
    def lives(every: float) -> list:
        """Four lives of 46 s (sampled every 5 s), each ended cleanly, the next ``every`` s on."""
        return [f for k in range(4) for f in
                [(every * k + dt, camera_in(100 + k), []) for dt in range(0, 46, 5)]
                + [(every * k + 46.0, camera_in(None), exit_of(every * k + 46.0, 100 + k, [], []))]]

    # An operator's tool: open 45 s, closed cleanly, opened again 10 s later: each life ran its course.
    assert drive("member_gone", lives(55.0)) == []
    # The same lives ended by a respawn at once (a node dying of an exception says goodbye to DDS
    # too): a restart each time, a loop from the second within loop_window_s.
    assert [a[2] for a in drive("member_gone", lives(47.0))] == ["warn", "warn"]
    # Restarted cleanly but often (every 10 s): a loop all the same.
    frames, pid = [], 100
    for k in range(4):
        t = 10.0 * k
        frames += [(t, camera_in(pid), []), (t + 5.0, camera_in(None), exit_of(t + 5.0, pid, [], []))]
        pid += 1
    assert drive("member_gone", frames) == [(20.0, "node:/camera", "warn"), (30.0, "node:/camera", "error")]


def test_member_gone_a_process_that_exits_0_without_its_goodbye_is_no_crash():
    # An operator UI: each session lives 46 s, then its process calls exit(0) without shutting ROS
    # down, so DDS lists its node 20 s more (alive=False), until the next session starts.
    def sessions(code):
        frames = []
        for k in range(3):
            t0, pid = 66.0 * k, 100 + k
            data = {"pid": pid, "process": f"process:{pid}", "nodes": ["node:/camera"],
                    "still_listed": ["node:/camera"], **({} if code is None else {"exit_code": code})}
            ended = [Event(t0 + 46.0, "exit", m, "error", f"process {pid} exited", data)
                     for m in ("node:/camera", f"process:{pid}")]
            # the collector sees the name in a new process from one sample to the next
            moved = [Event(t0, "restart", "node:/camera", "warn", f"now in process {pid}",
                           {"old_pid": pid - 1, "pid": pid})] if k else []
            frames += [(t0, camera_in(pid), moved)]
            frames += [(t0 + dt, camera_in(pid), []) for dt in range(5, 46, 5)]
            frames += [(t0 + 46.0, camera_in(pid, alive=False), ended)]
            frames += [(t0 + dt, camera_in(pid, alive=False), []) for dt in range(47, 66)]
        return frames

    assert drive("member_gone", sessions(0)) == []
    # The kernel said nothing (no exit code readable): each end looks like a crash.
    got = drive("member_gone", sessions(None))
    assert [a for a in got if a[0] == 46.0] == [(46.0, "node:/camera", "error")] and len(got) > 3
    # Killed: a crash, with or without the code.
    assert (46.0, "node:/camera", "error") in drive("member_gone", sessions(-9))


def test_graph_anomalies_a_publisher_that_exited_0_without_its_goodbye_did_not_die():
    # /camera's process exits 0 at t=2 without the goodbye: DDS lists it (alive=False) until its
    # lease ends at t=6; then /img has no publisher, as after a clean departure: no fault.
    data = {"pid": 100, "process": "process:100", "nodes": ["node:/camera"],
            "still_listed": ["node:/camera"], "exit_code": 0}
    ended = [Event(2.0, "exit", "node:/camera", "info", "process 100 exited with code 0", data)]
    frames = [(0.0, model(), []), (1.0, model(), []), (2.0, model(alive=False), ended)]
    frames += [(float(t), model(alive=False), []) for t in range(3, 6)]
    frames += [(float(t), without_camera(), []) for t in range(6, 13)]
    assert drive("graph_anomalies", frames) == []


# --------------------------------------------------------------------------- diagnostics, rosout

def test_diagnostics_levels():
    G = model()
    ev = [Event(1.0, "diag", "node:/camera", "info", "cam: OK", {"name": "cam", "level": 0}),
          Event(1.0, "diag", "node:/camera", "warn", "temp: WARN hot", {"name": "temp", "level": 1}),
          Event(1.0, "diag", "node:/camera", "error", "lens: ERROR broken", {"name": "lens", "level": 2}),
          Event(1.0, "diag", "node:/detector", "warn", "x: STALE", {"name": "x", "level": 3})]
    at_once = {"error_confirm_s": 0.0}  # an ERROR alerts without waiting for its next message
    assert drive("diagnostics", [(1.0, G, ev)], settings=at_once) == [(1.0, "node:/camera", "error"),
                                                                      (1.0, "node:/detector", "warn")]
    assert drive("diagnostics", [(1.0, G, ev[:1])], settings=at_once) == []


def test_diagnostics_an_error_counts_once_its_next_message_says_it_too():
    G = model()

    def frame(t, level, name="detector"):
        return (float(t), G, [Event(float(t), "diag", "node:/camera", "info", f"{name}: {level}",
                                    {"name": name, "level": level})] if level is not None else [])

    # A frequency check enabled at 10: ERROR ("no events") for one message, then WARN, then OK.
    assert drive("diagnostics", [frame(t, lvl) for t, lvl in enumerate([0] * 10 + [2, 1, 1, 0, 0])]) == []
    # A real ERROR says so again a period later: it alerts then, and says when it began.
    got = drive("diagnostics", [frame(t, lvl) for t, lvl in enumerate([0] * 10 + [2, 2, 2])], full=True)
    assert [(a.t, a.severity, a.data["since"]) for a in got] == [(11.0, "error", 10.0), (12.0, "error", 10.0)]
    # A status published once, on change, that says nothing more: it counts after error_confirm_s.
    once = [frame(t, lvl) for t, lvl in enumerate([0] * 10 + [2] + [None] * 5)]
    assert drive("diagnostics", once) == [(13.0, "node:/camera", "error")]
    # Two messages of it in one sample (a 2 Hz updater) confirm each other at once.
    two = [(float(t), G, [Event(t - 0.5, "diag", "node:/camera", "info", "d: 2", {"name": "d", "level": 2}),
                          Event(float(t), "diag", "node:/camera", "info", "d: 2", {"name": "d", "level": 2})])
           for t in (10, 11)]
    assert drive("diagnostics", two) == [(10.0, "node:/camera", "error"), (11.0, "node:/camera", "error")]


def test_diagnostics_a_standing_warning_is_the_status_normal_a_new_one_is_news():
    G = model()

    def diag(t, name, level, node="node:/camera"):
        return Event(t, "diag", node, "info", f"{name}: {level}", {"name": name, "level": level})

    # "gps" warns from its first report (no fix indoors) and keeps warning; "temp" is OK for 20 s,
    # then warns; "lens" warns from the start, then errors; "late" appears at 30 s already warning.
    frames = []
    for t in range(0, 40):
        ev = [diag(t, "gps", 1), diag(t, "temp", 0 if t < 20 else 1), diag(t, "lens", 1 if t < 25 else 2)]
        ev += [diag(t, "late", 1, "node:/detector")] if t >= 30 else []
        frames.append((float(t), G, ev))
    alerts = drive("diagnostics", frames, settings={"warn_hold_s": 0.0})  # a WARN counts at once
    warned = [t for t, m, sev in alerts if m == "node:/camera" and sev == "warn"]
    assert warned == [float(t) for t in range(20, 26)]  # at 25 the lens's first ERROR waits for its next
    assert [t for t, m, sev in alerts if sev == "error"] == [float(t) for t in range(26, 40)]  # confirmed
    assert [a for a in alerts if a[1] == "node:/detector"] == []  # warned as it appeared: its normal
    # learn_s 0: every WARN alerts, as robots without standing warnings may want
    assert len(drive("diagnostics", frames, settings={"learn_s": 0.0, "warn_hold_s": 0.0})) == 40 + 10


def test_diagnostics_a_new_warning_counts_once_it_has_held():
    G = model()

    def frames(levels):
        return [(float(t), G, [Event(float(t), "diag", "node:/sprayer", "info", f"tank: {lvl}",
                                     {"name": "tank", "level": lvl})]) for t, lvl in enumerate(levels)]

    # A tank running low for 20 s, refilled, a battery low for 34 s: no alert (warn_hold_s 60 s);
    # the same WARN staying alerts once it has held 60 s; one that turns ERROR alerts at once.
    assert drive("diagnostics", frames([0] * 20 + [1] * 20 + [0] * 20)) == []
    assert drive("diagnostics", frames([0] * 20 + [1] * 34 + [0] * 20)) == []
    staying = drive("diagnostics", frames([0] * 20 + [1] * 70))
    assert [t for t, _, _ in staying] == [float(t) for t in range(80, 90)]
    assert drive("diagnostics", frames([0] * 20 + [1] * 5 + [2] * 3)) == [(26.0, "node:/sprayer", "error"),
                                                                           (27.0, "node:/sprayer", "error")]


def test_diagnostics_a_warning_that_came_and_went_by_itself_is_shown_once():
    G = model()

    def frame(t, level):
        return (float(t), G, [Event(float(t), "diag", "node:/camera", "info", f"battery: {level}",
                                    {"name": "battery", "level": level})])

    levels = [0] * 20 + [1] * 10 + [0] * 20 + [1] * 10 + [2] * 5
    alerts = drive("diagnostics", [frame(t, lvl) for t, lvl in enumerate(levels)],
                   settings={"warn_hold_s": 0.0})
    assert [t for t, _, sev in alerts if sev == "warn"] == [float(t) for t in range(20, 30)]
    assert [t for t, _, sev in alerts if sev == "error"] == [float(t) for t in range(61, 65)]


def test_diagnostics_in_a_node_s_bring_up_are_not_news():
    # The filter's process started at 0: "ERROR waiting for GPS" at 7 s is its bring-up, as a line
    # logged then; still ERROR at 11 s, it alerts.
    G = model()
    G.nodes["process:100"]["create_time"] = 0.0
    frames = [(float(t), G, [Event(float(t), "diag", "node:/camera", "error", "nav: ERROR WAITING_FOR_GPS",
                                   {"name": "nav", "level": 2})]) for t in range(5, 13)]
    assert drive("diagnostics", frames) == [(10.0, "node:/camera", "error"), (11.0, "node:/camera", "error"),
                                            (12.0, "node:/camera", "error")]
    # A status of a node not discovered yet (mapped to nothing) in the monitor's own first 10 s:
    # the robot starting with it; later, such a status alerts on the topic as before.
    def lost(t):
        return [Event(t, "diag", "topic:/diagnostics", "error", "nav: ERROR lost",
                      {"name": "nav", "level": 2, "mapped_by": "none"})] if t in (3.0, 12.0) else []
    unknown = [(float(t), model(), lost(float(t))) for t in range(0, 13)]
    assert drive("diagnostics", unknown) == [(12.0, "topic:/diagnostics", "error")]


def test_diagnostics_an_aggregator_s_stale_after_its_node_was_deactivated_is_the_transition_s():
    # /camera's own status (1 Hz) until 19.5; deactivated at 20.0; the aggregator (/agg) says its
    # copy is STALE from 25 s. With the transition: no alert; without one, or with one long before
    # its statuses stopped: STALE alerts (warn).
    def frames(transitions):
        out = []
        for t in range(10, 30):
            ev = [Event(t - 0.5, "diag", "node:/camera", "info", "cam: OK", {"name": "cam", "level": 0,
                                                                              "publisher": "node:/camera"})]
            ev = ev if t < 20 else []
            ev += [Event(float(t), "diag", "node:/camera", "warn", "/robot/cam: STALE",
                         {"name": "/robot/cam", "level": 3 if t >= 25 else 0, "publisher": "node:/agg"})]
            out.append((float(t), lifecycle_model(transitions, float(t)), ev))
        return out

    assert drive("diagnostics", frames([20.0])) == []
    stale = [(float(t), "node:/camera", "warn") for t in range(25, 30)]
    assert drive("diagnostics", frames([])) == stale
    assert drive("diagnostics", frames([5.0])) == stale


def test_rosout_levels():
    G = model()
    ev = [Event(1.0, "log", "node:/camera", "warn", "meh"),
          Event(1.0, "log", "node:/camera", "error", "bad"),
          Event(1.0, "log", "node:/detector", "fatal", "worse"),
          Event(1.0, "log", "node:/detector", "error", "bad too")]
    assert drive("rosout", [(1.0, G, ev)]) == [(1.0, "node:/camera", "error"),
                                               (1.0, "node:/detector", "fatal")]
    assert drive("rosout", [(1.0, G, ev[:1])]) == []
    # Since the first line's stamp, unless it is far from the calls' times (another clock).
    late = [Event(t, "log", "node:/camera", "error", "bad") for t in (4.5, 4.2)]
    far = [Event(99.0, "log", "node:/camera", "error", "ahead")]
    got = drive("rosout", [(1.0, G, []), (5.0, G, late), (6.0, G, far)], full=True)
    assert [a.data.get("since") for a in got] == [4.2, None]
    assert drive("rosout", [(1.0, G, ev[:1])], settings={"min_level": "warn"}) == [
        (1.0, "node:/camera", "warn")]


def test_rosout_lines_of_a_nodes_bring_up_are_counted_not_alerted():
    # the camera's process started at t=100: its ERRORs at 101-105 s are its bring-up (a peer not
    # up yet); one at 115 s alerts and counts them; the detector's process is of unknown start.
    def frame(t, member="node:/camera"):
        G = model()
        G.nodes["process:100"]["create_time"] = 100.0
        return (t, G, [Event(t, "log", member, "error", "service /plan not available")])

    frames = [frame(float(t)) for t in range(101, 106)] + [frame(115.0), frame(101.0, "node:/detector")]
    alerts = drive("rosout", frames, full=True)
    assert [(a.t, a.member) for a in alerts] == [(115.0, "node:/camera"), (101.0, "node:/detector")]
    assert alerts[0].message.endswith("; 5 during its bring-up")
    assert drive("rosout", frames[:5], settings={"startup_s": 0.0}) == [
        (float(t), "node:/camera", "error") for t in range(101, 106)]


def test_rosout_a_line_before_its_node_is_discovered_waits_for_it():
    # The camera logs at 2 s, before it is discovered; at 3 s it is in the model, its process
    # started at 1.5 s: its bring-up. Its process started long before: the line alerts when the
    # camera is in the model; waiting more than 5 s, it is judged as it is.
    def camera(created=1.5):
        G = model()
        G.nodes["process:100"]["create_time"] = created
        return G

    line = [Event(2.0, "log", "node:/camera", "error", "Failed to open /dev/video4: busy")]
    assert drive("rosout", [(2.0, new_graph(), line), (3.0, camera(), []), (20.0, camera(), [])]) == []
    assert drive("rosout", [(2.0, new_graph(), line), (4.0, camera(-100.0), [])]) == [
        (4.0, "node:/camera", "error")]
    late = [(2.0, new_graph(), line), (4.0, new_graph(), []), (7.0, camera(6.5), [])]
    assert drive("rosout", late) == [(7.0, "node:/camera", "error")]


def test_rosout_a_line_naming_a_node_it_reads_from_names_it():
    # The detector reads /img from the camera: its ERROR naming the camera points at it (data
    # ``names``: the RCA charges it); /planner, named too, is nothing the detector depends on.
    G = model()
    add_member(G, "node:/planner")
    text = "no image from camera for 2 s (planner waits)"
    line = [Event(1.0, "log", "node:/detector", "error", text, {"nodes": ["node:/camera", "node:/planner"]})]
    got = drive("rosout", [(1.0, G, line)], full=True)
    assert [(a.member, a.data.get("names")) for a in got] == [("node:/detector", ["node:/camera"])]
    alone = [Event(1.0, "log", "node:/detector", "error", text, {"nodes": ["node:/planner"]})]
    assert "names" not in drive("rosout", [(1.0, G, alone)], full=True)[0].data


# --------------------------------------------------------------------------- graph_anomalies

def _qos(node, role, rel="reliable", dur="volatile"):
    return {"node": node, "role": role, "reliability": rel, "durability": dur, "history": "unknown"}


def test_graph_anomalies_healthy_graph_is_quiet():
    G = model()
    G.nodes["topic:/img"]["qos"] = [_qos("/camera", "pub"), _qos("/detector", "sub")]
    assert drive("graph_anomalies", [(float(t), G, []) for t in range(10)]) == []


def test_graph_anomalies_subscriber_without_publisher_after_grace():
    G = model()
    G.remove_edge("node:/camera", "topic:/img", 0)
    frames = [(float(t), G, []) for t in range(8)]
    # By default a topic that never had a publisher is how the robot is built (/initialpose, /joy).
    assert drive("graph_anomalies", frames) == []
    never = {"never_published": True}  # asked for: nobody provides what it waits for
    assert drive("graph_anomalies", frames, settings=never) == [
        (t, "node:/detector", "warn") for t in (5.0, 6.0, 7.0)]
    assert drive("graph_anomalies", frames, settings={**never, "ignore_topics": ["/img"]}) == []


def without_camera(alive=True):
    """`model` after /camera left the graph (its process with it), /detector still subscribed."""
    G = model(alive=alive)
    G.remove_nodes_from(["node:/camera", "process:100"])
    return G


def test_graph_anomalies_a_publisher_whose_process_ended_alone_with_an_error_died():
    # /camera deregisters and its process exits 1 at t=3 (an uncaught exception): /detector's
    # input lost its publisher, a fault after the grace; with another process ending at once it
    # is a stop of the robot: nothing.
    def run(others=()):
        frames = [(float(t), model(), []) for t in range(3)]
        frames += [(3.0, without_camera(), coded_exit(3.0, 100, ["node:/camera"], 1) + list(others))]
        frames += [(float(t), without_camera(), []) for t in range(4, 12)]
        return drive("graph_anomalies", frames, full=True)

    alerts = run()
    assert {(a.member, a.data["symptom"]) for a in alerts} == {("node:/detector", "no_publisher")}
    assert min(a.t for a in alerts) == 8.0 and "since its publisher /camera died" in alerts[0].message
    assert run(coded_exit(3.0, 400, ["node:/ui"], 1)) == []


def test_graph_anomalies_a_publisher_that_left_cleanly_leaves_no_orphan_fault():
    # /camera deregisters at t=3 (a job done, a node destroyed on purpose): healthy, for good.
    frames = [(float(t), model() if t < 3 else without_camera(), []) for t in range(20)]
    assert drive("graph_anomalies", frames) == []
    # A publisher that comes and goes (on for 3 s, off for 7 s): healthy too.
    frames = [(float(t), model() if t % 10 < 3 else without_camera(), []) for t in range(40)]
    assert drive("graph_anomalies", frames) == []


def test_graph_anomalies_a_publisher_that_died_leaves_an_orphan_fault():
    # /camera's process is killed at t=2: DDS lists the dead node (alive=False) until its lease
    # ends at t=6, then the topic has no publisher: its subscriber is alerted after the grace.
    data = {"pid": 100, "process": "process:100", "nodes": ["node:/camera"], "still_listed": ["node:/camera"]}
    killed = [Event(2.0, "exit", "node:/camera", "error", "process 100 exited", data)]
    frames = [(0.0, model(), []), (1.0, model(), []), (2.0, model(alive=False), killed)]
    frames += [(float(t), model(alive=False), []) for t in range(3, 6)]
    frames += [(float(t), without_camera(), []) for t in range(6, 13)]
    alerts = drive("graph_anomalies", frames, full=True)
    assert [(a.t, a.member) for a in alerts] == [(11.0, "node:/detector"), (12.0, "node:/detector")]
    assert "since its publisher /camera died" in alerts[0].message
    # Started again under the same name and gone cleanly later: forgiven.
    frames += [(float(t), model(), []) for t in range(13, 16)]
    frames += [(float(t), without_camera(), []) for t in range(16, 25)]
    assert [a.t for a in drive("graph_anomalies", frames, full=True)] == [11.0, 12.0]


def test_graph_anomalies_duplicate_names():
    # Twice for longer than a DDS lease: two launches of one node. For 15 s: a restarted node's
    # old instance lingering until its lease ends.
    G, twice = model(), model()
    twice.nodes["node:/camera"]["instances"] = 2
    lasting = [(float(t), twice, []) for t in range(30)]
    assert drive("graph_anomalies", lasting) == [(float(t), "node:/camera", "error") for t in range(25, 30)]
    restarted = [(float(t), twice if 5 <= t < 20 else G, []) for t in range(40)]
    assert drive("graph_anomalies", restarted) == []


def test_topic_latency_jitter_of_two_publishers_interleaving_is_not_judged():
    # a joystick held beside an autonomy node: while both send, the arrival intervals interleave
    def both(jitter, joystick):
        G = model(jitter=jitter)
        G.nodes["topic:/img"]["publisher_rates"] = {"node:/camera": 10.0, "node:/joystick": joystick}
        return G
    healthy = [(float(t), both(noisy(1.0, 0.3), 0.0), []) for t in range(30)]
    held = [(float(t), both(90.0, 20.0), []) for t in range(30, 40)]
    assert drive("topic_latency", healthy + held) == []
    # the same rise with one publisher sending is the topic's own
    alone = [(float(t), both(90.0, 0.0), []) for t in range(30, 40)]
    assert drive("topic_latency", healthy + alone) != []


def test_topic_latency_jitter_while_an_input_of_its_publisher_switches_is_not_judged():
    # a mux (the camera here) forwarding a joystick's bursts over its autonomy input: while the
    # joystick starts or stops, what it forwards comes when its inputs send, not on its own clock
    def mux(jitter, joystick):
        G = model(jitter=jitter)
        add_member(G, "topic:/joy", theta=make_theta("topic", {"rate_hz": joystick, "publishers": 1}))
        add_flow_edge(G, "topic:/joy", "node:/camera", "sub")
        return G
    healthy = [(float(t), mux(noisy(1.0, 0.3), 0.0), []) for t in range(30)]
    burst = [(float(t), mux(90.0, 10.0 if t < 35 else 0.0), []) for t in range(30, 40)]
    assert drive("topic_latency", healthy + burst) == []
    # the same rise while the input sends steadily (or stays silent) is the topic's own
    steady = [(float(t), mux(noisy(1.0, 0.3), 10.0), []) for t in range(30)]
    held = [(float(t), mux(90.0, 10.0), []) for t in range(30, 40)]
    assert drive("topic_latency", steady + held) != []
    silent = [(float(t), mux(90.0, 0.0), []) for t in range(30, 40)]
    assert drive("topic_latency", healthy + silent) != []


def test_topic_latency_jitter_while_the_topic_s_endpoints_change_is_not_judged():
    # a recorder subscribing to every topic: matching it takes the publishers' time, and its
    # start-up the computer's, for seconds that begin before the graph shows it
    def joined(jitter, subscribers):
        return model(jitter=jitter, subscribers=subscribers)
    healthy = [(float(t), joined(noisy(1.0, 0.3), 1.0), []) for t in range(120)]
    joining = [(float(t), joined(90.0 if t < 126 else noisy(1.0, 0.3), 1.0 if t < 122 else 2.0), [])
               for t in range(120, 135)]
    assert drive("topic_latency", healthy + joining) == []
    # the same rise with no endpoint changing, or outlasting the change, is the topic's own
    steady = [(float(t), joined(90.0 if t < 126 else noisy(1.0, 0.3), 1.0), []) for t in range(120, 135)]
    assert drive("topic_latency", healthy + steady) != []
    lasting = [(float(t), joined(90.0, 1.0 if t < 122 else 2.0), []) for t in range(120, 135)]
    assert [t for t, _, _ in drive("topic_latency", healthy + lasting)][:1] == [130.0]  # 8 samples on


def test_topic_latency_counts_one_late_message_once():
    # A topic slower than the sampling: one late message stays in the 3 s window for 3 samples
    # (ages 0.2, 1.2, 2.2 s). That is one observation, not three: no alert. Three late
    # messages (each newer than the sample before) are.
    frames = [(float(t), model(latency=noisy(2.0), age=0.1), []) for t in range(30)]
    stale = [(0.2, 200.0), (1.2, 200.0), (2.2, 200.0)]
    frames += [(30.0 + i, model(latency=lat, age=age), []) for i, (age, lat) in enumerate(stale)]
    assert drive("topic_latency", frames) == []
    more = [(0.3, 210.0), (1.3, 210.0), (0.2, 190.0)]
    frames += [(33.0 + i, model(latency=lat, age=age), []) for i, (age, lat) in enumerate(more)]
    assert drive("topic_latency", frames) == [(35.0, "topic:/img", "warn")]


def test_common_mode_counts_topics_measured_afresh():
    from plugins.topic_latency import common_mode

    up, flat = (90.0, 2.0, True), (2.0, 2.0, False)
    seen = [("a", "latency_ms", up, True), ("a", "jitter_ms", up, True), ("b", "jitter_ms", up, True),
            ("c", "latency_ms", up, True), ("d", "latency_ms", flat, True), ("e", "latency_ms", None, True),
            ("f", "latency_ms", up, False)]
    # Measured afresh with a baseline: a, b, c, d (e warming up, f stale); risen: a, b, c.
    assert common_mode(seen, 3, 0.5) is True
    assert common_mode(seen, 4, 0.5) is False  # too few topics
    assert common_mode(seen, 3, 0.8) is False  # 3 of 4 < 80 %
    assert common_mode([], 1, 0.5) is False


def test_common_mode_of_one_attribute_among_the_topics_that_could_show_it():
    from plugins.topic_latency import common_mode

    # Four fast topics' jitter up by 40-60 ms in one sample; six 1 Hz topics measured, whose
    # jitter floor (500 ms) no 40 ms stall reaches; their latency flat.
    up = [(f"/fast{i}", "jitter_ms", (1.0 + 40 + 5 * i, 1.0, True), True) for i in range(4)]
    slow = [(f"/slow{i}", a, (3.0, 3.0, False), True) for i in range(6) for a in ("jitter_ms", "latency_ms")]
    fast_lat = [(f"/fast{i}", "latency_ms", (2.0, 2.0, False), True) for i in range(4)]
    seen = up + slow + fast_lat
    floors = {(t, a): (500.0 if t.startswith("/slow") and a == "jitter_ms" else 20.0) for t, a, _, _ in seen}
    apart = {f"/fast{i}": {f"process:{i}"} for i in range(4)}
    assert common_mode(seen, 4, 0.5) is False  # 4 of 10 topics
    assert common_mode(seen, 4, 0.5, floors, lambda t: apart.get(t, set())) is True  # 4 of the 4 able
    # All four from one process: its own trouble (a container starved), not the computer's.
    assert common_mode(seen, 4, 0.5, floors, lambda t: {"process:0"}) is False
    # A fifth fast topic whose jitter stayed flat, and three more: 4 of 8 able is still half.
    more = [(f"/fast{i}", "jitter_ms", (1.0, 1.0, False), True) for i in range(4, 8)]
    floors.update({(t, "jitter_ms"): 20.0 for t, *_ in more})
    assert common_mode(seen + more, 4, 0.5, floors, lambda t: apart.get(t, set())) is True
    more.append(("/fast8", "jitter_ms", (1.0, 1.0, False), True))
    floors["/fast8", "jitter_ms"] = 20.0
    assert common_mode(seen + more, 4, 0.5, floors, lambda t: apart.get(t, set())) is False  # 4 of 9


def topics_model(n, risen=(), jitter=1.0):
    """``n`` topics /t0…, each from its own node and process; the ``risen`` ones with 150 ms latency."""
    G = new_graph()
    for i in range(n):
        add_member(G, f"process:{100 + i}", pid=100 + i, alive=True)
        add_member(G, f"node:/n{i}", pid=100 + i, alive=True)
        add_member(G, f"topic:/t{i}", theta=make_theta("topic", {
            "rate_hz": 10.0, "latency_ms": 150.0 if i in risen else noisy(2.0, 0.3),
            "jitter_ms": noisy(jitter, 0.3), "publishers": 1, "subscribers": 0}))
        add_flow_edge(G, f"node:/n{i}", f"topic:/t{i}", "pub")
        add_tree_edge(G, f"process:{100 + i}", f"node:/n{i}")
    return G


def test_topic_latency_a_stall_of_most_topics_at_once_is_not_a_fault_of_each():
    healthy = [(float(t), topics_model(6), []) for t in range(30)]
    # A stall: 5 of 6 topics rise together for 6 samples, then all recover. No alert.
    stall = healthy + [(float(t), topics_model(6, risen={0, 1, 2, 3, 4}), []) for t in range(30, 36)]
    stall += [(float(t), topics_model(6), []) for t in range(36, 40)]
    assert drive("topic_latency", stall) == []
    # One topic of six rising is that topic's fault, as before.
    one = healthy + [(float(t), topics_model(6, risen={2}), []) for t in range(30, 36)]
    assert drive("topic_latency", one) == [(34.0, "topic:/t2", "warn"), (35.0, "topic:/t2", "warn")]
    # A fault reaching 3 of 10 topics (below the ratio) still alerts on each.
    ten = [(float(t), topics_model(10), []) for t in range(30)]
    ten += [(float(t), topics_model(10, risen={1, 2, 3}), []) for t in range(30, 35)]
    assert sorted(m for _, m, _ in drive("topic_latency", ten)) == ["topic:/t1", "topic:/t2", "topic:/t3"]
    # The ratio and the minimum are settings: off (ratio > 1) gives the per-topic alerts back.
    off = drive("topic_latency", stall[:36], settings={"common_mode_ratio": 2.0})
    assert sorted({m for _, m, _ in off}) == [f"topic:/t{i}" for i in range(5)]


def test_graph_anomalies_grace_starts_again_while_the_system_is_being_discovered():
    from plugins.graph_anomalies import discovery_burst

    def grown(n):
        """The orphan subscriber of `model` plus ``n`` more nodes discovered so far."""
        G = model()
        G.remove_edge("node:/camera", "topic:/img", 0)
        for i in range(n):
            add_member(G, f"node:/extra{i}")
        return G

    G = grown(0)
    assert discovery_burst(G, {"node:/camera", "node:/detector", "topic:/img"}, 2, 0.5)
    assert not discovery_burst(G, {"node:/camera", "topic:/img"}, 2, 0.5)  # one node only
    assert not discovery_burst(grown(100), {f"node:/extra{i}" for i in range(5)}, 5, 0.05)  # 5 of 102
    # 10 nodes more per sample for 6 s (bring-up): the orphan's grace counts from the last burst.
    never = {"never_published": True}
    frames = [(float(t), grown(10 * min(t, 6)), []) for t in range(14)]
    assert drive("graph_anomalies", frames, settings=never) == [
        (t, "node:/detector", "warn") for t in (11.0, 12.0, 13.0)]
    # A steady trickle (1 node per sample) is churn, not discovery: the grace runs from the start.
    frames = [(float(t), grown(100 + t), []) for t in range(8)]
    assert drive("graph_anomalies", frames, settings=never) == [
        (t, "node:/detector", "warn") for t in (5.0, 6.0, 7.0)]


def test_topic_latency_a_stall_raises_no_alert_of_a_rise_it_holds_up():
    # /t0 rises alone for 3 samples (30-32), then the host stalls (33-35: 5 of 6 topics): held up
    # for 4 s by then, but by stall samples only. Back at 36, no alert; risen still at 36, one.
    healthy = [(float(t), topics_model(6), []) for t in range(30)]
    rise = [(float(t), topics_model(6, risen={0}), []) for t in range(30, 33)]
    stall = [(float(t), topics_model(6, risen={0, 1, 2, 3, 4}), []) for t in range(33, 36)]
    assert drive("topic_latency", healthy + rise + stall + [(36.0, topics_model(6), [])]) == []
    on = [(36.0, topics_model(6, risen={0}), [])]
    assert drive("topic_latency", healthy + rise + stall + on) == [(36.0, "topic:/t0", "warn")]


def test_topic_latency_rises_a_healthy_run_showed_are_its_normal_in_the_next():
    # Jitter up to 90 ms for 5 s, twice, ending by itself: alone, the first is a rise once it held
    # 4 s (the second is within what the topic often shows by then, `usual_quantile`); started
    # from that run, neither is, and one more than twice as high, or as long, is a rise.
    def frames(level, seconds, n=60):
        up = lambda t: (30 <= t < 30 + seconds) or (45 <= t < 45 + seconds)  # noqa: E731
        return [(float(t), model(jitter=level if up(t) else noisy(1.0, 0.3)), []) for t in range(n)]

    learned = {}
    assert [t for t, _, _ in drive("topic_latency", frames(90.0, 5), learned=learned)] == [34.0]
    assert learned["topic_latency"]["rises"] == {"topic:/img jitter_ms": [90.0, 5.0]}
    assert drive("topic_latency", frames(90.0, 5), learned=dict(learned)) == []
    assert [t for t, _, _ in drive("topic_latency", frames(200.0, 5), learned=dict(learned))][:1] == [34.0]
    longer = drive("topic_latency", frames(90.0, 14), learned=dict(learned))
    assert [t for t, _, _ in longer][:1] == [41.0]  # risen at 30: 11 s > 2 × 5 s


def test_topic_latency_rise_of_a_slow_topic_must_be_a_tenth_of_its_period():
    # 1 Hz topic: +40 ms (3 → 43 ms, a loaded host) is 4 % of its period: no alert; +150 ms is.
    base = [(float(t), model(rate=1.0, latency=noisy(3.0, 0.2), age=0.1), []) for t in range(30)]
    small = base + [(float(t), model(rate=1.0, latency=43.0, age=0.1), []) for t in range(30, 34)]
    assert drive("topic_latency", small) == []
    big = base + [(float(t), model(rate=1.0, latency=153.0, age=0.1), []) for t in range(30, 36)]
    assert drive("topic_latency", big) == [(34.0, "topic:/img", "warn"), (35.0, "topic:/img", "warn")]
    # At 10 Hz the 20 ms floor rules (a tenth of the period is 10 ms): +40 ms alerts.
    fast = [(float(t), model(rate=10.0, latency=noisy(3.0, 0.2)), []) for t in range(30)]
    fast += [(float(t), model(rate=10.0, latency=43.0), []) for t in range(30, 36)]
    assert drive("topic_latency", fast) == [(34.0, "topic:/img", "warn"), (35.0, "topic:/img", "warn")]


def test_topic_latency_a_rise_that_ended_as_its_topic_stopped_is_no_alert_later():
    # An action's command topic: its jitter risen for 3 fresh samples as a goal began, then the
    # goal ended: no new message (not fresh), the window's jitter back to 1 ms. The streak is
    # neither counted nor broken, but a value that no longer exceeds is no rise, however long.
    base = [(float(t), model(jitter=noisy(1.0, 0.3), age=0.05), []) for t in range(30)]
    rise = [(float(t), model(jitter=90.0, age=0.05), []) for t in range(30, 33)]
    quiet = [(float(t), model(jitter=1.2, age=float(t - 32)), []) for t in range(33, 45)]
    assert drive("topic_latency", base + rise + quiet) == []


def test_topic_latency_one_late_message_held_in_the_window_is_no_rise():
    # A 2 Hz topic (~0.3 ms): one message 360 ms late, while a participant joins, lifts the 3 s
    # window's mean to ~60 ms for the 3 samples it stays in the window, each with a new message.
    base = [(float(t), model(rate=2.0, latency=noisy(0.3, 0.2), age=0.2), []) for t in range(30)]
    late = base + [(float(t), model(rate=2.0, latency=61.0 if t < 33 else 0.3, age=0.2), [])
                   for t in range(30, 40)]
    assert drive("topic_latency", late) == []
    # The same rise kept up is a change of the topic: counted once it outlasts the window.
    kept = base + [(float(t), model(rate=2.0, latency=61.0, age=0.2), []) for t in range(30, 36)]
    assert [a[0] for a in drive("topic_latency", kept)] == [34.0, 35.0]


# --------------------------------------------------------------------------- services: goals

def _goal_frames(goals, stall_at=None):
    """/nav serves the action /nav/follow, /bt sends goals; ``goals`` (start, end) s; feedback every
    0.5 s while one executes, none from ``stall_at`` on (the server stuck mid-goal)."""
    frames, fed = [], None
    for t in range(70):
        G = model()
        add_member(G, "node:/nav", pid=100, alive=True)
        add_member(G, "node:/bt", pid=200, alive=True)
        running = next((a for a, b in goals if a <= t < b), None)
        if running is not None and (stall_at is None or t < stall_at):
            fed = t - 0.25  # the newest feedback, a quarter of a second old
        add_member(G, "action:/nav/follow", servers=["/nav"], clients=["/bt"],
                   executing_since=None if running is None else float(running), feedback_at=fed)
        frames.append((float(t), G, []))
    return frames


def test_services_a_goal_executing_without_feedback_is_a_stall_of_its_action():
    goals = [(5, 15), (25, 40), (50, 60)]
    assert drive("services", _goal_frames(goals)) == []  # feedback all through every goal
    # Stuck in the second goal at 30 s: its feedback quiet past 3 s (goal_quiet_s) alerts on the
    # action (its server's progress) until the goal is cancelled at 40 s, and in the next goal.
    alerts = drive("services", _goal_frames(goals, stall_at=30), full=True)
    assert [a.t for a in alerts] == [float(t) for t in (*range(33, 40), *range(54, 60))]
    assert {a.member for a in alerts} == {"action:/nav/follow"}
    assert alerts[0].data["symptom"] == "goal_stalled" and alerts[0].data["server"] == "node:/nav"
    # Stuck in the first goal: nothing is known of its feedback yet (a server may give none).
    assert drive("services", _goal_frames(goals, stall_at=8)) == []
    # A server giving no feedback at all: never a stall.
    quiet = _goal_frames(goals, stall_at=0)
    assert drive("services", quiet) == []


def test_topic_rate_a_dropout_its_publisher_complained_of_is_not_learned_however_short():
    # /img 10 Hz; out from 29.2 to 30.6 (seen 1.3 s quiet at 30.5: under the 1.5 s base limit)
    # and from 49.9 to 52.2 (seen 1.6 s at 51.5). Learned, the first dropout would make the limit
    # 2 x 1.3 s and the second no silence; with /camera's WARN at each, neither is learned, and
    # without it neither is the first: a settled continuous topic's hiccup that would lift its
    # limit at once is no rhythm (`rhythm._message`).
    msgs = [i / 10 for i in range(293)] + [30.6 + i / 10 for i in range(194)] + \
        [52.2 + i / 10 for i in range(100)]

    def frames(said):
        return [(t, model(**seen(msgs, t)), said.get(t, [])) for t in HALF[:60]]

    assert drive("topic_rate", frames({}))[:1] == [(51.5, "topic:/img", "error")]
    lost = {29.5: [Event(29.4, "log", "node:/camera", "warn", "signal lost", {})],
            50.5: [Event(50.1, "log", "node:/camera", "warn", "signal lost", {})]}
    # With the complained-of floor as high as the base one (below, the first dropout alerts).
    floor = {"complained_min_s": 1.5}
    assert drive("topic_rate", frames(lost), settings=floor)[:1] == [(51.5, "topic:/img", "error")]


def test_topic_rate_a_quiet_its_publisher_complained_of_is_a_silence_from_half_a_second():
    # /img 10 Hz, out from 29.2 to 30.6: 1.3 s quiet at 30.5, under the 1.5 s floor. With
    # /camera's WARN as it went out (an IMU's "no data-ready interrupt"), a silence there: its
    # subscriber's ERROR 0.5 s in must not be the first symptom. Without the WARN, nothing.
    msgs = [i / 10 for i in range(293)] + [30.6 + i / 10 for i in range(294)]

    def frames(said):
        return [(t, model(**seen(msgs, t)), said.get(t, [])) for t in HALF[:50]]

    assert drive("topic_rate", frames({})) == []
    lost = {29.5: [Event(29.4, "log", "node:/camera", "warn", "no data-ready interrupt", {})]}
    alerts = drive("topic_rate", frames(lost), full=True)
    assert [(a.t, a.member, a.severity) for a in alerts] == [(30.5, "topic:/img", "error")]
    assert alerts[0].message.endswith("its publisher complained as it went quiet")
    assert alerts[0].data["since"] == pytest.approx(29.2)
    # A quiet under half a second is not, complaint or not (29.2 to 29.6: 0.3 s at 29.5).
    short = [i / 10 for i in range(293)] + [29.6 + i / 10 for i in range(304)]
    quick = [(t, model(**seen(short, t)), lost.get(t, [])) for t in HALF[:50]]
    assert drive("topic_rate", quick) == []


def test_topic_rate_a_rate_that_falls_as_its_publishers_input_stops_follows_the_input():
    # /camera publishes /img at 10 Hz while /cmd (20 Hz, from /teleop) comes, 2 Hz after it
    # stops at 29.6 (a gait state slowing as the robot stands): no drop. The same fall while
    # /cmd goes on is a drop.
    msgs = [i / 10 for i in range(300)] + [30 + i / 2 for i in range(60)]
    stops = [i / 20 for i in range(593)]  # last at 29.6

    def img(cmd):
        return [a for a in drive("topic_rate", commanded(msgs, cmd, HALF[:45])) if a[1] == "topic:/img"]

    assert img(stops) == []
    assert img([i / 20 for i in range(900)])[:1] == [(32.5, "topic:/img", "warn")]  # /cmd goes on


def commanded(msgs, cmd, times):
    """Frames of `model` (/img at ``msgs``) whose /camera also reads /cmd (at ``cmd``, from /teleop)."""
    out = []
    for t in times:
        G, st = model(**seen(msgs, t)), seen(cmd, t)
        add_member(G, "node:/teleop")
        add_member(G, "topic:/cmd", theta=make_theta("topic", {
            "rate_hz": st["rate"], "publishers": 1, "subscribers": 1,
            **({"age_s": st["age"]} if "age" in st else {})}))
        add_flow_edge(G, "node:/teleop", "topic:/cmd", "pub")
        add_flow_edge(G, "topic:/cmd", "node:/camera", "sub")
        out.append((t, G, []))
    return out


def test_topic_rate_a_drop_that_followed_its_input_stays_its_inputs_as_the_input_resumes():
    # /img 10 Hz, 2 Hz while /cmd stops (29.6 to 33.45), 10 Hz again from 33.47: at 33.5 the
    # recent rate still counts the slow intervals, while /cmd publishes again; the drop was the
    # input's, and stays so. The same drop held after /cmd resumed (for more than
    # input_grace_s, 5 s) is one.
    def frames(msgs, cmd):
        return commanded(msgs, cmd, HALF[:50])

    cmd = [i / 20 for i in range(593)] + [33.45 + i / 20 for i in range(400)]
    slow = [30 + i / 2 for i in range(7)]
    back = [i / 10 for i in range(300)] + slow + [33.47 + i / 10 for i in range(200)]
    assert [a for a in drive("topic_rate", frames(back, cmd)) if a[1] == "topic:/img"] == []
    low = [i / 10 for i in range(300)] + [30 + i / 2 for i in range(60)]
    assert [a for a in drive("topic_rate", frames(low, cmd)) if a[1] == "topic:/img"][:1] == [
        (38.5, "topic:/img", "warn")]


def test_topic_rate_a_rate_that_falls_as_a_command_upstream_stops_follows_it():
    # AMCL-like: /camera publishes /img at 10 Hz while the robot moves, 2 Hz still. It reads
    # /odom (20 Hz always, from /base), and /base follows /cmd (20 Hz from /teleop while it
    # drives, last at 29.6): the robot stopping is seen two hops up, in /cmd. No drop then; the
    # same fall while /cmd goes on is a drop. Three hops up is too far to say.
    msgs = [i / 10 for i in range(300)] + [30 + i / 2 for i in range(60)]
    odom = [i / 20 for i in range(900)]

    def topic(G, name, pub, sub, times, t):
        st = seen(times, t)
        add_member(G, f"node:{pub}")
        add_member(G, f"topic:{name}", theta=make_theta("topic", {
            "rate_hz": st["rate"], "publishers": 1, "subscribers": 1,
            **({"age_s": st["age"]} if "age" in st else {})}))
        add_flow_edge(G, f"node:{pub}", f"topic:{name}", "pub")
        add_flow_edge(G, f"topic:{name}", f"node:{sub}", "sub")

    def frames(cmd, hops=2):
        out = []
        for t in HALF[:45]:
            G = model(**seen(msgs, t))
            topic(G, "/odom", "/base", "/camera", odom, t)
            if hops == 2:
                topic(G, "/cmd", "/teleop", "/base", cmd, t)
            else:
                topic(G, "/cmd_in", "/mux", "/base", odom, t)
                topic(G, "/cmd", "/teleop", "/mux", cmd, t)
            out.append((t, G, []))
        return out

    stops = [i / 20 for i in range(593)]  # last at 29.6
    assert [a for a in drive("topic_rate", frames(stops)) if a[1] == "topic:/img"] == []
    goes_on = [i / 20 for i in range(900)]
    assert [a for a in drive("topic_rate", frames(goes_on)) if a[1] == "topic:/img"][:1] == [
        (32.5, "topic:/img", "warn")]
    assert [a for a in drive("topic_rate", frames(stops, hops=3)) if a[1] == "topic:/img"][:1] == [
        (32.5, "topic:/img", "warn")]
