"""The samples file on a real system: every sample the live collector returns comes back from the
file exactly (graph, attributes, θ, events, unreadable members, diff)."""

from __future__ import annotations

import signal
import time

import pytest

from stream_viz.collect.collector import Collector
from stream_viz.collect.samples_file import SamplesWriter, read_samples
from stream_viz.testing import wait_for
from tests.ros.test_collect import HAVE_ACTIONS, MANY, VICTIM
from tests.unit.test_samples_file import _same

pytestmark = pytest.mark.ros


def test_the_collectors_samples_come_back_exactly(children, ros_domain, tmp_path):
    children.python(MANY.replace("{have_actions}", str(HAVE_ACTIONS)), name="many")
    victim = children.python(VICTIM, name="victim")
    path = tmp_path / "s.jsonl.gz"
    live = []
    with Collector(ros_domain) as col:
        writer = SamplesWriter(path, {"started_at": time.time()})

        def take():
            s = col.sample()
            live.append(s)
            writer.write(s)
            return s

        wait_for(lambda: "node:/victim" in take().graph and "topic:/chatter" in live[-1].graph,
                 timeout=30, period=0.5)
        for _ in range(4):
            time.sleep(0.5)
            take()
        victim.send_signal(signal.SIGKILL)  # an exit event, a node that stays listed, not alive
        wait_for(lambda: any(e.kind == "exit" for e in take().events), timeout=20, period=0.5)
        for _ in range(3):
            time.sleep(0.5)
            take()
        writer.close()
    _, replayed, _ = read_samples(path)
    assert len(replayed) == len(live) >= 8
    assert any(s.events for s in live) and any(s.diff for s in live[1:])
    for a, b in zip(live, replayed, strict=True):
        _same(a, b)
