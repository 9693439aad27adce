"""The warehouse AMR's ground truth as plain data, fault validation per robot, and the robot registry."""

from __future__ import annotations

import pytest

from stream_viz.demo.amr.topology import (
    AMR,
    BEST_EFFORT,
    DEFAULT_TARGETS,
    LATCHED,
    PROCESSES,
    UPDATERS,
)
from stream_viz.demo.faults import FAULTS, FaultSpec
from stream_viz.demo.messages import load_type
from stream_viz.demo.robots import ROBOTS, default_target, robot_topology
from stream_viz.demo.topology import DEMO, Topology
from stream_viz.errors import DemoError


def test_amr_is_a_namespaced_robot_of_several_multi_node_processes():
    names = AMR.node_names()
    assert 15 <= len(names) <= 30 and 6 <= len(AMR.groups) <= 10
    assert all(nm.startswith("/amr1/") for nm in names)
    assert set(PROCESSES) == {g.name for g in AMR.groups}
    kinds = {PROCESSES[g.name].executor for g in AMR.groups if len(g.nodes) > 1}
    assert kinds == {"single", "multi", "isolated"}
    assert len(AMR.group("sensors").nodes) == len(AMR.group("navigation").nodes) == 4
    assert [g.name for g in AMR.groups if g.respawn] == ["camera", "base"]


def test_amr_edges_service_mux_and_flow():
    e = AMR.edges()
    assert ("node:/amr1/bt_navigator", "node:/amr1/planner_server", "send") in e
    assert ("node:/amr1/lifecycle_manager", "node:/amr1/map_server", "send") in e
    mux_inputs = {s for s, d, k in e if k == "sub" and d == "node:/amr1/velocity_mux"}
    assert mux_inputs == {"topic:/amr1/cmd_vel_nav", "topic:/amr1/cmd_vel_teleop"}
    feeders = {s for s, d, k in e if k == "pub" and d in mux_inputs}
    assert feeders == {"node:/amr1/controller_server", "node:/amr1/teleop_joy"}
    published = {d for s, d, k in e if k == "pub"}
    assert {s for s, d, k in e if k == "sub"} <= published  # every input has a publisher in the robot
    assert {s for s, d, k in e if k == "pub" and d == "topic:/diagnostics"} == {f"node:{n}" for n in UPDATERS}


def test_amr_qos_and_stamped_types():
    topics = AMR.topics()
    assert BEST_EFFORT <= set(topics) and LATCHED <= set(topics)
    def first_field(ty: str) -> tuple[str, str]:
        return next(iter(load_type(ty).get_fields_and_field_types().items()))

    stamped = [t for t, ty in topics.items() if first_field(ty) == ("header", "std_msgs/Header")]
    assert len(stamped) >= 12
    assert "/amr1/cmd_vel" not in stamped and "/amr1/scan" in stamped


def test_amr_faults_and_their_default_targets():
    kinds = dict(AMR.faults)
    assert set(kinds) == set(FAULTS) == set(DEFAULT_TARGETS)
    for fault, target in DEFAULT_TARGETS.items():
        AMR.check_fault(FaultSpec(fault, target))
        assert default_target("amr", fault) == target
    with pytest.raises(DemoError, match="valid targets: /amr1/planner_server"):
        AMR.check_fault(FaultSpec("slow_service", "/amr1/amcl"))
    with pytest.raises(DemoError, match=r"valid targets: .*/amr1/base_driver"):
        AMR.check_fault(FaultSpec("diag", "/amr1/amcl"))
    with pytest.raises(DemoError, match="valid targets: /amr1/camera_driver, /amr1/base_driver"):
        AMR.check_fault(FaultSpec("restart", "/amr1/amcl"))
    with pytest.raises(DemoError, match=r"cannot inject 'qos'; its faults: crash, .*, diag$"):
        DEMO.check_fault(FaultSpec("qos", "/lidar_driver"))


def test_amr_round_trips_through_json(tmp_path):
    back = Topology.load(AMR.save(tmp_path / "amr.json"))
    assert back == AMR
    assert back.entry == "stream_viz.demo.amr.process" and back.group("camera").respawn
    assert Topology.from_data(DEMO.to_data()).faults == DEMO.faults


def test_robots_by_name():
    assert ROBOTS == ("demo", "amr")
    assert robot_topology("demo") is DEMO and robot_topology("amr") is AMR
    assert default_target("demo", "hang") == "/lidar_driver"
    with pytest.raises(DemoError, match="robots: demo, amr"):
        robot_topology("rover")
