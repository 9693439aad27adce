"""A robot on a Fast DDS discovery server (``ROS_DISCOVERY_SERVER``, as TurtleBot 4 ships it):
the monitor observes as a super client, and sees the whole graph."""

from __future__ import annotations

import socket
import sys

import pytest

from stream_viz.collect.collector import Collector
from stream_viz.testing import wait_for

pytestmark = pytest.mark.ros

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


def _free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def on_a_discovery_server(children, tmp_path, monkeypatch):
    """Start a discovery server and a talker/listener pair that are its clients; point this
    process's environment at the server (the collector runs here)."""
    port = _free_udp_port()
    xml = tmp_path / "server.xml"
    xml.write_text(SERVER_XML.format(port=port))
    server = {k: v for k, v in children.env.items() if k != "ROS_AUTOMATIC_DISCOVERY_RANGE"}
    server["FASTRTPS_DEFAULT_PROFILES_FILE"] = str(xml)
    children.run(_python(children, IDLE, "server"), env=server, name="server")
    client = {**children.env, "ROS_DISCOVERY_SERVER": f"127.0.0.1:{port}"}
    children.run(_python(children, PAIR, "pair"), env=client, name="pair")
    monkeypatch.setenv("ROS_DISCOVERY_SERVER", f"127.0.0.1:{port}")
    monkeypatch.delenv("ROS_SUPER_CLIENT", raising=False)
    return port


def _python(children, code: str, name: str) -> list[str]:
    script = children.workdir / f"{name}.py"
    script.write_text(code)
    return [sys.executable, str(script)]


def _has_the_pair(G) -> bool:
    return {"node:/ds_talker", "node:/ds_listener", "topic:/ds/chatter"} <= set(G)


def test_the_monitor_sees_the_whole_graph_through_a_discovery_server(on_a_discovery_server, ros_domain):
    with Collector(ros_domain) as col:
        G = wait_for(lambda: _has_the_pair(g := col.sample().graph) and g, timeout=20, period=0.5)
        assert ("node:/ds_talker", "topic:/ds/chatter") in G.edges
        assert ("topic:/ds/chatter", "node:/ds_listener") in G.edges
        assert col.limits() == {}


def test_a_plain_client_chosen_by_the_user_is_said(on_a_discovery_server, ros_domain, monkeypatch):
    """ROS_SUPER_CLIENT=False set by the user is kept: the topics this observer does not subscribe
    stay unseen, and the collector says why."""
    monkeypatch.setenv("ROS_SUPER_CLIENT", "False")
    with Collector(ros_domain) as col:
        wait_for(lambda: "node:/ds_talker" in col.sample().graph, timeout=20, period=0.5)
        for _ in range(6):
            G = col.sample().graph
        assert "topic:/ds/chatter" not in G
        assert "whole graph" in col.limits()
