"""Which nodes began to warn as a symptom began (`stream_viz.detect.warned`), on literal events."""

from __future__ import annotations

from stream_viz.detect.warned import began_warning, is_warning, note_warnings
from stream_viz.records import Event


def log(t, node, level="warn", text="w"):
    return Event(t, "log", f"node:{node}", level, text, {})


def test_warnings_are_a_nodes_warn_or_worse_lines_and_statuses_not_a_stale_one():
    assert is_warning(log(0, "/a")) and is_warning(log(0, "/a", "error"))
    assert not is_warning(log(0, "/a", "info"))
    assert is_warning(Event(0, "diag", "node:/a", "warn", "a: WARN slow", {"level": 1}))
    assert not is_warning(Event(0, "diag", "node:/a", "warn", "a: STALE", {"level": 3}))
    assert not is_warning(Event(0, "diag", "topic:/diagnostics", "warn", "x: WARN", {"level": 1}))


def test_a_run_of_warnings_began_when_the_node_had_been_quiet_for_quiet_s():
    runs: dict = {}
    # /a warns every 20 s from 0 (one run); /b at 0, then again from 100 (two runs, the second
    # out of order within its sample); /c at 95 once.
    note_warnings(runs, [log(t, "/a") for t in range(0, 200, 20)], quiet_s=60.0)
    b = [log(0, "/b", text="first"), log(101, "/b", text="later"), log(100, "/b", text="new")]
    note_warnings(runs, b, quiet_s=60.0)
    note_warnings(runs, [log(95, "/c", "error", "boom"), log(95, "/c", "info")], quiet_s=60.0)
    assert runs == {"node:/a": [[0, 180, "w"]], "node:/b": [[0, 0, "first"], [100, 101, "new"]],
                    "node:/c": [[95, 95, "boom"]]}
    assert began_warning(runs, ["node:/a", "node:/b", "node:/c", "node:/d"], since=90.0) == [
        ("node:/b", "new"), ("node:/c", "boom")]
    assert began_warning(runs, ["node:/a", "node:/b"], since=100.5) == []
