"""A process on our domain that the observer never discovers is named, with why (real rclpy)."""

from __future__ import annotations

import json
import sys
import threading

import pytest

from stream_viz.collect.collector import Collector
from stream_viz.collect.undiscovered import UndiscoveredWatch, _in_dds
from stream_viz.testing import TALKER, claim_domain, ros_env, wait_for

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


def test_the_monitor_says_it_and_keeps_it_in_its_database_and_report(ros_domain, children, tmp_path):
    from stream_viz.config import load_config
    from stream_viz.detect.store import AlertStore
    from stream_viz.monitor import Monitor
    from stream_viz.progress import Progress

    said = []
    go = tmp_path / "go"

    class Said(Progress):
        def say(self, text: str) -> None:
            said.append(text)
            if text.startswith(f"collector: no discovery of process {late.pid}: "):
                go.touch()  # named: now let it join our domain

    env = {**ros_env(ros_domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "OFF"}
    code = TALKER.replace('"talker"', '"off_talker"').replace('"listener"', '"off_listener"')
    hidden = children.run([sys.executable, "-c", code], name="off", env=env)
    children.python(TALKER, name="seen")
    # In DDS from the start but not on our domain at first (its first context elsewhere): named at
    # the watch's look at 10 s; it joins our domain only once named, is discovered by the next look
    # and taken back then. Fast DDS loaded by rclpy.init with no node yet is no participant: not named.
    late = children.python(
        "import os, pathlib, rclpy, sys, time\nfrom rclpy.context import Context\n"
        f"rclpy.init(domain_id={claim_domain()}); kept = rclpy.create_node('elsewhere')\n"
        "while not pathlib.Path(sys.argv[1]).exists(): time.sleep(0.1)\n"
        "ctx = Context(); rclpy.init(context=ctx, domain_id=int(os.environ['ROS_DOMAIN_ID']))\n"
        "rclpy.spin(rclpy.create_node('late_node', context=ctx))", str(go), name="late")
    loading = children.python("import rclpy, time; rclpy.init(); time.sleep(60)", name="loading")
    # Both in DDS before the watch's first look, so its looks at 10 and 20 s name and take back.
    wait_for(lambda: _in_dds(hidden.pid) and _in_dds(late.pid), timeout=20)
    mon = Monitor(load_config(None), db=tmp_path / "a.sqlite", report=tmp_path / "r.json", viewer="none",
                  domain_id=ros_domain, progress=Said())
    try:
        mon.run(23.0, threading.Event())  # the watch looks every 10 s at processes 10 s old
    finally:
        report = mon.close()
    key = f"discovery of process {hidden.pid}"
    assert [t for t in said if t.startswith(f"collector: no {key}: ")] != []
    assert key in report["collector_limits"]
    assert key in json.loads((tmp_path / "r.json").read_text())["collector_limits"]
    late_key = f"discovery of process {late.pid}"
    assert [t for t in said if t.startswith(f"collector: no {late_key}: ")] != []
    assert [t for t in said if t.startswith(f"collector: {late_key} after all: ")] != []
    assert late_key not in report["collector_limits"]
    assert [t for t in said if f"process {loading.pid}" in t] == []
    store = AlertStore(tmp_path / "a.sqlite", readonly=True)
    try:
        assert key in store.get_meta("collector_limits")
        assert late_key not in store.get_meta("collector_limits")
    finally:
        store.close()
