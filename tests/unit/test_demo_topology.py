"""The demo's ground truth as plain data: topology, fault specs, generated systems."""

from __future__ import annotations

import pytest

from stream_viz.demo.faults import FAULTS, FaultSpec
from stream_viz.demo.generated import generate
from stream_viz.demo.topology import DEMO, Topology
from stream_viz.errors import DemoError


def test_demo_is_a_mobile_robot_in_several_processes():
    assert len(DEMO.nodes()) >= 10 and len(DEMO.groups) >= 5
    assert DEMO.group_of("/obstacle_detector") == DEMO.group_of("/localization") == "navigation"
    assert DEMO.topics()["/scan"] == "sensor_msgs/msg/LaserScan"
    assert DEMO.services() == {"/map_server/get_map": "nav_msgs/srv/GetMap"}
    assert DEMO.diag_monitor() == "/system_monitor"


def test_demo_edges_follow_the_data_flow():
    e = DEMO.edges()
    assert ("node:/lidar_driver", "topic:/scan", "pub") in e
    assert ("topic:/scan", "node:/obstacle_detector", "sub") in e
    assert ("node:/global_planner", "node:/map_server", "send") in e
    assert ("node:/system_monitor", "topic:/diagnostics", "pub") in e
    # every subscribed topic has a publisher in the robot
    published = {d for s, d, k in e if k == "pub"}
    assert {s for s, d, k in e if k == "sub"} <= published


def test_topology_round_trips_through_json(tmp_path):
    back = Topology.load(DEMO.save(tmp_path / "t.json"))
    assert back == DEMO
    gen = generate(30, seed=3)
    assert Topology.from_data(gen.to_data()) == gen


def test_unknown_names_are_errors_naming_the_choices(tmp_path):
    with pytest.raises(DemoError, match="lidar"):
        DEMO.group("nope")
    with pytest.raises(DemoError, match="/lidar_driver"):
        DEMO.group_of("/nope")
    (tmp_path / "bad.json").write_text("{\"groups\": [{\"nodes\": []}]}")
    with pytest.raises(DemoError, match="malformed"):
        Topology.load(tmp_path / "bad.json")


def test_fault_spec_validates():
    assert FaultSpec("hang", "node:/imu_driver", 2).target == "/imu_driver"
    assert FaultSpec("hang", "imu_driver", 2).target == "/imu_driver"
    for bad in ("explode", ""):
        with pytest.raises(DemoError, match=", ".join(FAULTS)):
            FaultSpec(bad, "/imu_driver", 1)
    with pytest.raises(DemoError, match=">= 0"):
        FaultSpec("crash", "/imu_driver", -1)
    with pytest.raises(DemoError, match=r"valid targets: .*/controller"):
        FaultSpec("crash", "/nobody", 1).check(DEMO.node_names())


@pytest.mark.parametrize("n", [20, 100, 500])
def test_generated_systems_are_seeded_layered_and_sized(n):
    topo = generate(n, seed=7, nodes_per_process=8)
    assert topo == generate(n, seed=7, nodes_per_process=8)
    assert topo != generate(n, seed=8, nodes_per_process=8)
    names = topo.node_names()
    assert len(names) == n + 1 and len(set(names)) == n + 1  # + /system_monitor
    assert all(len(g.nodes) <= 9 for g in topo.groups)
    e = topo.edges()
    published = {d for s, d, k in e if k == "pub"}
    assert {s for s, d, k in e if k == "sub"} <= published
    # data flows only from a lower layer to a higher one: no cycles
    layer = {nm: int(nm.rpartition("_l")[2]) for nm in names if "_l" in nm}
    for spec in topo.nodes():
        for sub in spec.subs:
            assert layer[sub.topic.removeprefix("/t")] < layer[spec.name]
    servers = topo.services()
    assert servers and all(c.name in servers for s in topo.nodes() for c in s.clients)
    assert any(k == "send" for _, _, k in e)


def test_generate_rejects_bad_sizes():
    with pytest.raises(DemoError, match="at least 3"):
        generate(2)
    with pytest.raises(DemoError, match="nodes_per_process"):
        generate(10, nodes_per_process=0)
