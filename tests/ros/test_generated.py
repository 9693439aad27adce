"""A generated 20-node system runs as real rclpy processes, shows up in the graph and ends clean."""

from __future__ import annotations

import os

import psutil
import pytest

from stream_viz.demo.generated import generate
from stream_viz.demo.robot import FaultSpec, Robot
from stream_viz.testing import wait_for

pytestmark = pytest.mark.ros


@pytest.fixture
def graph_node(ros_domain):
    import rclpy
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    ctx = Context()
    rclpy.init(context=ctx, domain_id=ros_domain, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("gen_observer", context=ctx)
    yield node
    node.destroy_node()
    ctx.try_shutdown()


def _names(node) -> set[str]:
    return {f"{ns.rstrip('/')}/{n}" for n, ns in node.get_node_names_and_namespaces()}


def test_generated_20_nodes_run_and_end_clean(graph_node):
    topo = generate(20, seed=1, nodes_per_process=6)
    robot = Robot(env=dict(os.environ), topology=topo)
    with robot:
        robot.wait_ready(60)
        expected = set(topo.node_names())
        wait_for(lambda: expected <= _names(graph_node), timeout=20)
        topics = lambda: {t for t, _ in graph_node.get_topic_names_and_types()}  # noqa: E731
        wait_for(lambda: set(topo.topics()) <= topics(), timeout=10)
        served = lambda: {s for s, _ in graph_node.get_service_names_and_types()}  # noqa: E731
        wait_for(lambda: set(topo.services()) <= served(), timeout=10)
        assert set(robot.node_pids()) == expected
        # the same fault machinery works here: the first group's process kills itself
        robot.inject(FaultSpec("crash", topo.node_names()[0], 0.0))
        wait_for(robot.injected, timeout=15)
        first = topo.groups[0].name
        wait_for(lambda: not robot.alive()[first], timeout=5)
        assert sum(robot.alive().values()) == len(topo.groups) - 1
        pids = list(robot.pids().values())
    assert not [p for p in pids if psutil.pid_exists(p) and psutil.Process(p).status() != "zombie"]
