"""A robot on a Fast DDS discovery server (``ROS_DISCOVERY_SERVER``, as TurtleBot 4 ships it):
the monitor observes as a super client, and sees the whole graph."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.ros

ROOT = Path(__file__).resolve().parents[2]

# A participant acting as the discovery server (server id 0: the prefix ROS_DISCOVERY_SERVER's
# first entry names), its every transport on loopback (it cannot start under
# ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST, which is left out of its environment); one idle node.
SERVER_XML = """<?xml version="1.0" encoding="UTF-8" ?>
<dds xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles"><profiles>
  <transport_descriptors><transport_descriptor>
    <transport_id>loopback</transport_id><type>UDPv4</type>
    <interfaceWhiteList><address>127.0.0.1</address></interfaceWhiteList>
  </transport_descriptor></transport_descriptors>
  <participant profile_name="server" is_default_profile="true"><rtps>
    <prefix>44.53.00.5f.45.50.52.4f.53.49.4d.41</prefix>
    <userTransports><transport_id>loopback</transport_id></userTransports>
    <useBuiltinTransports>false</useBuiltinTransports>
    <builtin>
      <discovery_config><discoveryProtocol>SERVER</discoveryProtocol></discovery_config>
      <metatrafficUnicastLocatorList><locator><udpv4>
        <address>127.0.0.1</address><port>{port}</port>
      </udpv4></locator></metatrafficUnicastLocatorList>
    </builtin>
  </rtps></participant>
</profiles></dds>
"""

IDLE = """
import rclpy
rclpy.init()
rclpy.spin(rclpy.create_node('discovery_server'))
"""

PAIR = """
import rclpy
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import String
rclpy.init()
talker, listener = rclpy.create_node('ds_talker'), rclpy.create_node('ds_listener')
pub = talker.create_publisher(String, '/ds/chatter', 10)
listener.create_subscription(String, '/ds/chatter', lambda m: None, 10)
talker.create_timer(0.1, lambda: pub.publish(String(data='x')))
ex = SingleThreadedExecutor(); ex.add_node(talker); ex.add_node(listener)
ex.spin()
"""


# The collector in a process of its own: Fast DDS keeps the discovery settings it read from the
# environment for the rest of a process, which would leave this test's server in the next tests'.
OBSERVER = """
import json, sys, time
from stream_viz.collect.collector import Collector
want = {"node:/ds_talker", "node:/ds_listener", "topic:/ds/chatter"}
with Collector(int(sys.argv[1])) as col:
    deadline = time.monotonic() + 20
    while not (want <= set(G := col.sample().graph)) and time.monotonic() < deadline:
        time.sleep(0.5)
    for _ in range(6):  # a few samples more: what is missing stays missing
        G = col.sample().graph
        time.sleep(0.3)
    print(json.dumps({"members": sorted(G), "edges": [[u, v] for u, v in G.edges()],
                      "limits": col.limits()}))
"""


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def on_a_discovery_server(children, tmp_path):
    """Start a discovery server and a talker/listener pair that are its clients; return the
    environment of a client of it."""
    port = _free_udp_port()
    xml = tmp_path / "server.xml"
    xml.write_text(SERVER_XML.format(port=port))
    server = {k: v for k, v in children.env.items() if k != "ROS_AUTOMATIC_DISCOVERY_RANGE"}
    server["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(xml)
    children.run(_python(children, IDLE, "server"), env=server, name="server")
    client = {**children.env, "ROS_DISCOVERY_SERVER": f"127.0.0.1:{port}"}
    children.run(_python(children, PAIR, "pair"), env=client, name="pair")
    return client


def _python(children, code: str, name: str) -> list[str]:
    script = children.workdir / f"{name}.py"
    script.write_text(code)
    return [sys.executable, str(script)]


def _observe(env: dict[str, str], domain: int, tmp_path) -> dict:
    script = tmp_path / "observer.py"
    script.write_text(OBSERVER)
    out = subprocess.run([sys.executable, str(script), str(domain)], env=env, capture_output=True,
                         text=True, timeout=90, cwd=ROOT)
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_the_monitor_sees_the_whole_graph_through_a_discovery_server(on_a_discovery_server, ros_domain,
                                                                       tmp_path):
    seen = _observe(on_a_discovery_server, ros_domain, tmp_path)
    assert {"node:/ds_talker", "node:/ds_listener", "topic:/ds/chatter"} <= set(seen["members"]), seen
    assert ["node:/ds_talker", "topic:/ds/chatter"] in seen["edges"]
    assert ["topic:/ds/chatter", "node:/ds_listener"] in seen["edges"]
    assert seen["limits"] == {}


def test_a_plain_client_chosen_by_the_user_is_said(on_a_discovery_server, ros_domain, tmp_path):
    """ROS_SUPER_CLIENT=False set by the user is kept: the topics this observer does not subscribe
    stay unseen, and the collector says why."""
    seen = _observe({**on_a_discovery_server, "ROS_SUPER_CLIENT": "False"}, ros_domain, tmp_path)
    assert "node:/ds_talker" in seen["members"], seen
    assert "topic:/ds/chatter" not in seen["members"]
    assert "whole graph" in seen["limits"]
