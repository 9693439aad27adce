"""Simulated time (`stream_viz.collect.simclock`) on literal ticks."""

from __future__ import annotations

from stream_viz.collect.simclock import KEEP, SimClock

S = 1_000_000_000
WALL = 1_800_000_000 * S  # our clock, around 2027


def half_speed(n: int = 11) -> SimClock:
    """Ticks every 0.1 s of ours; simulated time from 1000 s at half our pace."""
    c = SimClock()
    for k in range(n):
        c.tick(WALL + k * S // 10, 1000 * S + k * S // 20)
    return c


def test_without_clock_the_age_is_ours():
    assert SimClock().age(WALL + S, WALL) == S
    assert SimClock().now(WALL) is None
    assert SimClock().aging(WALL)(WALL + S, WALL) == S


def test_aging_follows_the_clock_once_it_ticks():
    c = half_speed()
    assert c.aging(WALL) == c.age and c.aging(WALL)(WALL + S // 2, 1000 * S + S // 4) == 0


def test_no_age_while_the_first_tick_is_awaited():
    # /clock subscribed, nothing taken from it yet: a simulated stamp aged on our clock would be
    # decades old, so no age until the first tick or the end of the wait (then our clock)
    c = SimClock()
    c.expect(WALL + 2 * S)
    assert c.aging(WALL + S)(WALL + S, 1000 * S) is None
    assert c.aging(WALL + 2 * S)(WALL + 2 * S, WALL + S) == S
    c.tick(WALL + S, 1000 * S)
    assert c.aging(WALL + S) == c.age


def test_simulated_time_between_and_after_the_ticks():
    c = half_speed()
    assert c.now(WALL + S // 20) == 1000 * S + S // 40  # between two ticks
    assert c.now(WALL + 2 * S) == 1000 * S + S  # one second on at the recent pace: half of it


def test_a_stamp_is_aged_on_the_clock_it_is_nearer_to():
    c = half_speed()
    recv = WALL + S // 2  # simulated 1000.25 s
    assert c.age(recv, 1000 * S + S // 4 - S // 10) == S // 10  # a sim stamp 0.1 s old
    assert c.age(recv, recv - S // 100) == S // 100  # a wall stamp beside it
    assert c.age(recv, recv + S // 10) == -S // 10  # a wall stamp in our future stays a skew


def test_a_restarted_simulation_starts_its_clock_over_and_memory_is_bounded():
    c = half_speed()
    c.tick(WALL + 2 * S, 5 * S)  # time went back: a new simulation
    assert c.sim == [5 * S] and c.now(WALL + 3 * S) == 6 * S
    c.tick(WALL + S, 7 * S)  # received before the newest tick: ignored
    assert c.sim == [5 * S]
    for k in range(3 * KEEP):
        c.tick(WALL + 3 * S + k, 6 * S + k)
    assert KEEP <= len(c.recv) <= 2 * KEEP and len(c.recv) == len(c.sim)


def test_pace_is_simulated_seconds_per_second_over_the_span():
    c = half_speed()  # 11 ticks over 1 s of ours
    assert c.pace(WALL + S, 2 * S) == 0.5
    assert c.pace(WALL + S, S // 2) == 0.5  # the last 0.5 s: 6 ticks
    assert c.pace(WALL + 5 * S, S) is None  # no tick in the last second: the clock stopped
    assert SimClock().pace(WALL, S) is None
    paused = SimClock()
    for k in range(5):
        paused.tick(WALL + k * S // 10, 1000 * S)
    assert paused.pace(WALL + S // 2, S) == 0.0
