"""Simulated time: a robot in simulation stamps its data with the time on ``/clock``.

Nodes with ``use_sim_time`` stamp headers with the simulator's time (which starts near zero and
may run slower or faster than ours, or pause), while others in the same system keep the wall
clock. A message's age is only meaningful on the clock it was stamped with, so the ``/clock``
ticks are kept with their receive times, the simulated time at a message's receive time is read
between them (or on from the newest at the simulation's recent pace), and each stamped message is
aged on whichever of the two clocks its stamp is nearer to. The simulation's pace (its real-time
factor) is ``/clock``'s θ ``sim_pace``: what runs on simulated time slows with it on our clock.
Without ``/clock`` nothing changes.
From when ``/clock`` is subscribed until its first tick is taken (`expect`), and in the monitor's
first seconds (``/clock`` may be discovered after the topics stamped with its time), a stamp has
no age: the simulated stamps taken first would otherwise be aged on our clock, decades old.
"""

from __future__ import annotations

from bisect import bisect_left, bisect_right
from collections.abc import Callable
from operator import sub

ROS_CLOCK = "/clock"
CLOCK_TYPE = "rosgraph_msgs/msg/Clock"
KEEP = 256  # ticks kept (a simulator publishes /clock at 100–1000 Hz: a fraction of a second or more)


class SimClock:
    """The recent ``/clock`` ticks: our receive time and the simulated time of each (ns)."""

    __slots__ = ("expected_until", "recv", "sim")

    def __init__(self) -> None:
        self.recv: list[int] = []
        self.sim: list[int] = []
        self.expected_until = 0  # our time (ns) until which a first tick is awaited

    def expect(self, until: int) -> None:
        """``/clock`` is subscribed, or may be soon: until our time ``until`` (ns), no age before
        its first tick."""
        self.expected_until = max(self.expected_until, until)

    def tick(self, recv: int, sim: int | None) -> None:
        """A ``/clock`` message with simulated time ``sim`` (ns; None unreadable) received at ``recv``."""
        if sim is None or (self.recv and recv < self.recv[-1]):
            return
        if self.sim and sim < self.sim[-1]:  # the simulation restarted: its time went back
            self.recv, self.sim = [], []
        self.recv.append(recv)
        self.sim.append(sim)
        if len(self.recv) > 2 * KEEP:
            del self.recv[:-KEEP], self.sim[:-KEEP]

    def now(self, recv: int) -> int | None:
        """Return the simulated time (ns) at our time ``recv``; None before any tick."""
        r, s = self.recv, self.sim
        if not r:
            return None
        if len(r) == 1:
            return s[0] + (recv - r[0])
        i = min(max(bisect_right(r, recv), 1), len(r) - 1)  # the ticks around it, or the nearest two
        span = r[i] - r[i - 1]
        pace = (s[i] - s[i - 1]) / span if span > 0 else 1.0
        return s[i - 1] + round(pace * (recv - r[i - 1]))

    def pace(self, now: int, span: int) -> float | None:
        """Return the simulation's pace (simulated s per s of ours) over the ticks of our last
        ``span`` ns before ``now``: 1 in real time, under 1 when it lags, 0 while paused with its
        clock still ticking; None with fewer than two ticks in that span (no clock, or stopped)."""
        r, s = self.recv, self.sim
        i = bisect_left(r, now - span)
        if len(r) - i < 2 or r[-1] <= r[i]:
            return None
        return (s[-1] - s[i]) / (r[-1] - r[i])

    def aging(self, now: int) -> Callable[[int, int], int | None]:
        """Return what ages a stamp at our time ``now`` (ns): `age`; while no ``/clock`` tick was
        seen, plain ``recv - stamp`` (every stamped message goes through it: the common case stays
        a C call), or no age while a first tick is awaited (`expect`)."""
        if self.recv:
            return self.age
        return _unknown if now < self.expected_until else sub

    def age(self, recv: int, stamp: int) -> int:
        """Return the age (ns) at ``recv`` of data stamped ``stamp``, on the clock it was stamped
        with: the simulated one when that makes the age nearer to zero, else ours."""
        age = recv - stamp
        if not self.recv:
            return age
        sim = self.now(recv)
        return sim - stamp if sim is not None and abs(sim - stamp) < abs(age) else age


def _unknown(recv: int, stamp: int) -> None:
    return None
