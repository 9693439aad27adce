"""`discover`: how long `stream-viz snapshot` waits for discovery, on a literal timeline."""

from stream_viz.collect.snapshot import discover


class Timeline:
    """A fake clock whose node names change at given times (pure timing, no ROS)."""

    def __init__(self, changes: dict[float, set[str]]) -> None:
        self.t, self.changes = 0.0, sorted(changes.items())

    def clock(self) -> float:
        return self.t

    def sleep(self, s: float) -> None:
        self.t = round(self.t + s, 6)

    def names(self) -> frozenset[str]:
        seen: set[str] = set()
        for at, names in self.changes:
            if at <= self.t:
                seen = names
        return frozenset(seen)


def run(changes: dict[float, set[str]], min_s: float, **kw) -> tuple[frozenset[str], float]:
    tl = Timeline(changes)
    names = discover(tl.names, min_s, clock=tl.clock, sleep=tl.sleep, **kw)
    return names, tl.t


def test_a_system_seen_at_once_ends_discovery_at_the_settle_time():
    assert run({0.0: {"/a", "/b"}}, 1.0) == (frozenset({"/a", "/b"}), 1.0)


def test_a_late_participant_is_waited_for_past_the_settle_time():
    # Its first announcements were lost; the next one comes 3 s later.
    names, t = run({3.0: {"/talker", "/listener"}}, 1.5)
    assert names == {"/talker", "/listener"} and t == 4.0


def test_discovery_goes_on_while_the_node_set_still_grows():
    names, t = run({0.0: {"/a"}, 0.6: {"/a", "/b"}}, 1.0)
    assert names == {"/a", "/b"} and t == 1.6


def test_an_empty_domain_ends_at_the_ceiling():
    assert run({}, 1.0) == (frozenset(), 5.0)
    assert run({}, 1.0, max_s=2.0) == (frozenset(), 2.0)
