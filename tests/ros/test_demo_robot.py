"""The demo robot against the real thing: its graph matches topology.py, every fault really happens."""

from __future__ import annotations

import importlib
import itertools
import json
import os
import signal
import statistics
import threading
import time

import psutil
import pytest

from stream_viz.collect.rosgraph import read_structure
from stream_viz.demo.robot import FaultSpec, Robot
from stream_viz.demo.topology import DEMO
from stream_viz.errors import DemoError
from stream_viz.testing import wait_for

pytestmark = pytest.mark.ros
AT = 10.0  # fault injected this many seconds after start (start-up is slow on a loaded machine)


class Observer:
    """A plain rclpy node in its own context, spun in a thread, recording arrival times."""

    def __init__(self, domain: int) -> None:
        import rclpy
        from rclpy.context import Context
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.signals import SignalHandlerOptions

        self.ctx = Context()
        rclpy.init(context=self.ctx, domain_id=domain, signal_handler_options=SignalHandlerOptions.NO)
        self.node = rclpy.create_node("demo_observer", context=self.ctx)
        self.ex = SingleThreadedExecutor(context=self.ctx)
        self.ex.add_node(self.node)
        self.arrivals: dict[str, list[tuple[float, object]]] = {}
        threading.Thread(target=self._spin, daemon=True).start()

    def _spin(self) -> None:
        try:
            self.ex.spin()
        except Exception:
            pass

    def watch(self, topic: str, type_name: str) -> list[tuple[float, object]]:
        pkg, kind, cls = type_name.split("/")
        msg_type = getattr(importlib.import_module(f"{pkg}.{kind}"), cls)
        got = self.arrivals.setdefault(topic, [])
        self.node.create_subscription(msg_type, topic, lambda m: got.append((time.time(), m)), 50)
        return got

    def close(self) -> None:
        self.ex.shutdown(1.0)
        self.node.destroy_node()
        self.ctx.try_shutdown()

    def node_names(self) -> set[str]:
        return {f"{ns.rstrip('/')}/{n}" for n, ns in self.node.get_node_names_and_namespaces()}

    def rosout_pids(self) -> dict[str, int]:
        """Node fqn → low 16 bits of its pid, from the Fast DDS GUID of its /rosout publisher."""
        out = {}
        for info in self.node.get_publishers_info_by_topic("/rosout"):
            gid = bytes(info.endpoint_gid)
            out[f"{info.node_namespace.rstrip('/')}/{info.node_name}"] = int.from_bytes(gid[4:6], "little")
        return out


@pytest.fixture
def observer(ros_domain):
    obs = Observer(ros_domain)
    yield obs
    obs.close()


def _window(arrivals, t0: float, t1: float) -> list[float]:
    return [t for t, _ in list(arrivals) if t0 <= t < t1]


def _iqr(xs: list[float]) -> float:
    """The spread of the middle half: a loaded machine's few long gaps inflate a standard
    deviation (32 ms on CI before a fault), not this."""
    q1, _, q3 = statistics.quantiles(xs, n=4)
    return q3 - q1


def test_graph_matches_topology_and_stop_leaves_nothing(observer):
    with Robot(env=dict(os.environ)) as robot:
        robot.wait_ready(30)
        expected = set(DEMO.node_names())
        wait_for(lambda: expected <= observer.node_names(), timeout=15)
        assert len(expected) >= 10 and len(set(robot.pids().values())) >= 5
        def missing() -> list[str]:
            """What the graph does not show yet (endpoints arrive after node names)."""
            out = []
            topics = dict(observer.node.get_topic_names_and_types())
            out += [t for t, ty in DEMO.topics().items() if ty not in topics.get(t, [])]
            for spec in DEMO.nodes():
                ns, _, name = spec.name.rpartition("/")
                ns = ns or "/"
                try:
                    pubs = {t for t, _ in observer.node.get_publisher_names_and_types_by_node(name, ns)}
                    subs = {t for t, _ in observer.node.get_subscriber_names_and_types_by_node(name, ns)}
                    srvs = {t for t, _ in observer.node.get_service_names_and_types_by_node(name, ns)}
                    clis = {t for t, _ in observer.node.get_client_names_and_types_by_node(name, ns)}
                except Exception:  # the node is not (yet) known to this participant
                    out.append(spec.name)
                    continue
                want = ({p.topic for p in spec.pubs} - pubs) | ({s.topic for s in spec.subs} - subs)
                want |= ({s.name for s in spec.services} - srvs) | ({c.name for c in spec.clients} - clis)
                out += [f"{spec.name}: {w}" for w in sorted(want)]
            return out

        try:
            wait_for(lambda: not missing(), timeout=20)
        except TimeoutError:
            raise AssertionError(f"not in the graph: {missing()}") from None
        seen: set[str] = set()  # the monitor's structure: what had endpoints (ghosts, below)
        assert expected <= set(read_structure(observer.node, "/demo_observer", had=seen).nodes)
        wait_for(lambda: expected <= set(observer.rosout_pids()), timeout=10)
        low = observer.rosout_pids()
        node_pids = robot.node_pids()
        assert set(node_pids) == expected
        for node, pid in node_pids.items():
            assert low[node] == pid & 0xFFFF, node
        # data flows end to end: sensors → perception → planning → control
        wheel = observer.watch("/wheel_cmd", "std_msgs/msg/Float64MultiArray")
        wait_for(lambda: len(wheel) >= 5, timeout=15)
        pids = list(robot.pids().values())
    assert not [p for p in pids if psutil.pid_exists(p) and psutil.Process(p).status() != "zombie"]
    codes = {g: p.returncode for g, p in robot.procs.items()}
    # Ended by SIGINT, not SIGKILL: cleanly, or by its own watchdog when Fast DDS's teardown hung.
    assert all(c == 0 or g in robot.hung for g, c in codes.items()), codes
    # A clean exit announces the participant's end at once; on a loaded machine that message
    # can be lost, and then DDS drops the participant when its lease runs out (Fast DDS: 20 s,
    # checked by the observer's own timer). A node's name can stay listed for good without any
    # endpoint (a discovery-info sample that came after its participant's removal: a ghost);
    # the monitor's structure leaves such a name out.
    def left() -> set[str]:
        return expected & set(read_structure(observer.node, "/demo_observer", had=seen).nodes)
    try:
        wait_for(lambda: not left(), timeout=45)
    except TimeoutError:
        raise AssertionError(f"still in the graph with endpoints: {left()}") from None


def test_bad_fault_specs_name_the_choices():
    with pytest.raises(DemoError, match="crash"):
        FaultSpec("explode", "/lidar_driver", 1.0)
    with pytest.raises(DemoError, match="/lidar_driver"):
        Robot(fault=FaultSpec("crash", "/nope", 1.0))


def _run_fault(observer, fault: str, target: str, watch: tuple[str, str] | None = None):
    """Start the robot, let ``watch`` flow for 3 s, then inject ``fault`` via Robot.inject."""
    arrivals = observer.watch(*watch) if watch else None
    robot = Robot(env=dict(os.environ))
    robot.start()
    try:
        robot.wait_ready(60)
        if arrivals is not None:
            wait_for(lambda: arrivals, timeout=30)
        time.sleep(3.0)
        at = robot.inject(FaultSpec(fault, target, 0.2))
        info = wait_for(robot.injected, timeout=10)
        assert info["fault"] == fault and info["target"] == f"node:{target}"
        assert at - 0.1 < info["t"] < at + 3
        return robot, info, arrivals
    except BaseException:
        robot.stop()
        raise


def test_crash_at_a_time_given_at_start_kills_the_target_process():
    robot = Robot(env=dict(os.environ), fault=FaultSpec("crash", "/lidar_driver", AT))
    with robot:
        info = wait_for(robot.injected, timeout=AT + 30)
        assert info["fault"] == "crash" and info["target"] == "node:/lidar_driver"
        assert robot.fault_at - 0.5 < info["t"]  # never early; late only if start-up took longer than AT
        proc = robot.procs["lidar"]
        wait_for(lambda: proc.poll() is not None, timeout=5)
        assert proc.returncode == -9
        wait_for(lambda: sum(robot.alive().values()) == len(DEMO.groups) - 1, timeout=10)
        with pytest.raises(DemoError, match="already"):
            robot.inject(FaultSpec("hang", "/imu_driver", 0))


@pytest.mark.parametrize(("fault", "target", "topic", "type_name"), [
    ("hang", "/imu_driver", "/imu", "sensor_msgs/msg/Imu"),
    ("degrade", "/wheel_odometry", "/odom", "nav_msgs/msg/Odometry"),
])
def test_rate_drops(observer, fault, target, topic, type_name):
    robot, info, arrivals = _run_fault(observer, fault, target, (topic, type_name))
    try:
        t = info["t"]
        time.sleep(max(0.0, t + 4.5 - time.time()))
        before = len(_window(arrivals, t - 2.5, t)) / 2.5
        later = len(_window(arrivals, t + 0.5, t + 4.5)) / 4
        assert before > 10, (len(arrivals), arrivals[:1] and arrivals[0][0] - t, robot.log_tail("base"))
        assert later < (0.05 if fault == "hang" else 0.5) * before, (before, later)
        assert all(robot.alive().values())  # the process stays
    finally:
        robot.stop()


def test_delay_raises_jitter(observer):
    robot, info, arrivals = _run_fault(observer, "delay", "/imu_driver", ("/imu", "sensor_msgs/msg/Imu"))
    try:
        t = info["t"]
        time.sleep(max(0.0, t + 5 - time.time()))
        gaps = lambda ts: [b - a for a, b in itertools.pairwise(ts)]  # noqa: E731
        before = _iqr(gaps(_window(arrivals, t - 2.5, t)))
        later = gaps(_window(arrivals, t + 0.5, t + 5))
        assert len(later) >= 5
        assert _iqr(later) > max(3 * before, 0.02), (before, _iqr(later))
    finally:
        robot.stop()


def test_cpu_burns_in_the_target_process(observer):
    robot, _info, _ = _run_fault(observer, "cpu", "/camera_driver")
    try:
        # compared with a process of the same shape (one sensor driver), over the same 3 s
        burner, calm = (psutil.Process(robot.node_pids()[n]) for n in ("/camera_driver", "/lidar_driver"))
        cpu = lambda p: sum(p.cpu_times()[:2])  # noqa: E731
        b0, c0 = cpu(burner), cpu(calm)
        time.sleep(3.0)
        burnt, idle = cpu(burner) - b0, cpu(calm) - c0
        assert burnt > 4 * idle + 0.05, (burnt, idle)  # ~3 s on an idle machine; a fair share under load
    finally:
        robot.stop()


def test_leak_grows_rss(observer):
    robot, _info, _ = _run_fault(observer, "leak", "/map_server")
    try:
        proc = psutil.Process(robot.node_pids()["/map_server"])
        rss0 = proc.memory_info().rss
        time.sleep(3.0)
        assert proc.memory_info().rss - rss0 > 30 * 2**20
    finally:
        robot.stop()


def test_errlog_reaches_rosout(observer):
    logs = observer.watch("/rosout", "rcl_interfaces/msg/Log")
    robot, _info, _ = _run_fault(observer, "errlog", "/obstacle_detector")
    try:
        errors = lambda: [m for _, m in list(logs) if m.level == 40 and m.name == "obstacle_detector"]  # noqa: E731
        assert len(wait_for(lambda: len(errors()) >= 2 and errors(), timeout=5)) >= 2
    finally:
        robot.stop()
    others = [m for _, m in logs if m.level >= 40 and m.name != "obstacle_detector"]
    assert not others


def test_diag_reports_error_for_the_target(observer):
    robot, info, diags = _run_fault(observer, "diag", "/localization",
                                    ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray"))
    try:
        def levels():
            out = {}
            for t, arr in list(diags):
                for st in arr.status:
                    level = st.level if isinstance(st.level, int) else ord(st.level)
                    out.setdefault((st.name, t >= info["t"]), set()).add(level)
            return out
        wait_for(lambda: 2 in levels().get(("/localization", True), set()), timeout=5)
        lv = levels()
        assert lv[("/localization", False)] == {0}  # OK before the injection
        assert lv[("/lidar_driver", True)] == {0}  # others stay OK
    finally:
        robot.stop()


def test_children_end_when_the_parent_is_terminated(children, tmp_path):
    out = tmp_path / "pids.txt"
    parent = children.python(f"""
        import json, time
        from stream_viz.demo.robot import Robot
        robot = Robot()
        robot.start()
        robot.wait_ready(30)
        open({str(out)!r}, "w").write(json.dumps(list(robot.pids().values())))
        time.sleep(60)
    """, name="robot_parent")
    pids = json.loads(wait_for(lambda: out.exists() and out.read_text(), timeout=40))
    assert all(psutil.pid_exists(p) for p in pids)
    os.kill(parent.pid, signal.SIGTERM)  # default action: no atexit, no stop()
    parent.wait(5)

    def gone():
        return not [p for p in pids if psutil.pid_exists(p) and psutil.Process(p).status() != "zombie"]
    wait_for(gone, timeout=15)  # each polls its parent every 0.5 s; its watchdogs end it by 6 s
