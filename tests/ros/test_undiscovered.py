"""A process on our domain that the observer never discovers is named, with why (real rclpy)."""

from __future__ import annotations

import sys

import pytest

from stream_viz.collect.collector import Collector
from stream_viz.collect.undiscovered import UndiscoveredWatch
from stream_viz.testing import TALKER, ros_env, wait_for

pytestmark = pytest.mark.ros


def test_a_participant_with_discovery_off_is_named_and_a_discovered_one_is_not(ros_domain, children):
    seen = children.python(TALKER, name="seen")
    # Done with ROS and still running (a launcher, a tool): Fast DDS loaded, no participant left.
    done = children.python("import rclpy, time; rclpy.init(); rclpy.create_node('brief'); rclpy.shutdown(); "
                           "time.sleep(60)", name="done")
    hidden_env = {**ros_env(ros_domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "OFF"}
    hidden = children.run([sys.executable, "-c", TALKER.replace('"talker"', '"hidden_talker"')
                           .replace('"listener"', '"hidden_listener"')], name="hidden", env=hidden_env)
    with Collector(ros_domain) as col:
        col.undiscovered = UndiscoveredWatch(ros_domain, every_s=1.0, grace_s=3.0)

        def named():
            col.sample()
            return {k for k in col.limits() if k.startswith("discovery of process")}

        wait_for(lambda: "node:/talker" in col.sample().graph, timeout=20)
        found = wait_for(named, timeout=20)
        assert found == {f"discovery of process {hidden.pid}"}
        text = col.limits()[f"discovery of process {hidden.pid}"]
        assert "ROS_AUTOMATIC_DISCOVERY_RANGE=OFF (monitor: LOCALHOST)" in text
        assert "node:/hidden_talker" not in col.sample().graph
        assert seen.poll() is None and hidden.poll() is None and done.poll() is None
