"""Regression tests of the diagnosis on recorded real runs: samples files of the demo robot
(`tests/data/`, recorded on commit b75c65e with ``stream-viz demo --fault crash|errlog --at 8
--duration 22 --samples FILE`` on a shared machine under heavy load: the crash run also has a
false ``topic_rate`` alert on ``/imu``), and of the generated 50-node system with a crash of
``/n000_l0``'s process after 25 s (commit 5d60a55, in-process ``Monitor(samples=…)``), replayed
through the real monitor, no ROS needed."""

from __future__ import annotations

from pathlib import Path

import pytest

from stream_viz.collect.replay import ReplayCollector
from stream_viz.commands.replay import PLUGIN_TIMEOUT_S, replay_config

DATA = Path(__file__).resolve().parents[1] / "data"


def replayed(name: str, tmp_path: Path) -> dict:
    """The report of replaying ``tests/data/<name>`` as `stream-viz replay` does."""
    from stream_viz.monitor import Monitor

    source = ReplayCollector(DATA / name)
    mon = Monitor(replay_config(None, source.header), db=tmp_path / "a.sqlite", collector=source,
                  started_at=source.header["started_at"], plugin_timeout_s=PLUGIN_TIMEOUT_S)
    while not source.done:
        mon.step()
    end = source.notes["end"]
    mon.injected = end["injected"]
    assert not source.truncated
    return mon.close(ended_at=end["ended_at"])


@pytest.mark.parametrize(("name", "plugin", "nodes"), [("demo_crash.jsonl.gz", "member_gone", 12),
                                                       ("demo_errlog.jsonl.gz", "rosout", 12),
                                                       ("generated50_crash.jsonl.gz", "member_gone", 51)])
def test_a_recorded_run_is_diagnosed_as_live(tmp_path, name, plugin, nodes):
    report = replayed(name, tmp_path)
    target = report["injected"]["target"]
    assert report["root_causes"][0]["member"] == target, report["root_causes"][:3]
    alerted = {(a["member"], a["plugin"]) for a in report["alerts"]}
    assert (target, plugin) in alerted, sorted(alerted)
    seen = {m["id"] for m in report["members"] if m["kind"] == "node"}
    assert len(seen) == nodes and target in seen
