"""A pick station, hand-written in plain rclpy: ``python -m bench.station.robot PROCESS FAULT_DIR``.

Written without the demo's `Topology` machinery, as a user's robot would be, with structures the
two demo robots do not have: an arm's drivers composed in one single-threaded container at
100-200 Hz, a camera whose frame rate a task executive lowers while the station idles (a
parameter change), a detector that publishes only when asked through a service, a motion
planner whose command topic runs only while an action goal executes, a slow 0.2 Hz health topic,
a gripper commanded through a service, a diagnostic aggregator, and an HMI an operator opens and
closes (a clean exit, started again by its launcher).

Faults come from files: ``FAULT_DIR/<node name>`` holding ``hang``, ``degrade``, ``delay``,
``errlog`` or ``slow_service`` makes that node misbehave from then on (checked every 0.2 s);
``FAULT_DIR/<process>.cpu`` starts a thread burning a core in that process. Crashes are SIGKILLs
from outside.
"""

from __future__ import annotations

import sys
import threading
import time
from pathlib import Path

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Pose, PoseArray, WrenchStamped
from rcl_interfaces.msg import SetParametersResult
from rclpy.action import ActionClient, ActionServer
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import Image, JointState
from std_msgs.msg import String
from std_srvs.srv import SetBool, Trigger
from test_msgs.action import Fibonacci

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
JOINTS = [f"joint_{i}" for i in range(1, 7)]


class Station(Node):
    """A node with the station's fault hooks: ``gate()`` before each callback, ``send()`` to publish."""

    def __init__(self, name: str, fault_dir: Path, namespace: str = "/station") -> None:
        super().__init__(name, namespace=namespace)
        self.fault_file = fault_dir / name
        self.fault: str | None = None
        self.count = 0
        self.create_timer(0.2, self._check_fault, callback_group=MutuallyExclusiveCallbackGroup())

    def _check_fault(self) -> None:
        if self.fault is None and self.fault_file.exists():
            self.fault = self.fault_file.read_text().strip() or None  # empty: still being written
            self.get_logger().info(f"fault {self.fault}")
        if self.fault == "errlog":
            self.get_logger().error("lost connection to device: read timeout")

    def gate(self) -> None:
        if self.fault == "hang":
            threading.Event().wait()
        if self.fault == "delay":
            time.sleep(0.3)

    def send(self, pub, msg) -> None:
        self.count += 1
        if self.fault == "degrade" and self.count % 4:
            return
        pub.publish(msg)

    def stamp(self):
        return self.get_clock().now().to_msg()

    def diag(self, pub, task: str, hardware_id: str, values: dict[str, str]) -> None:
        status = DiagnosticStatus(level=DiagnosticStatus.OK, name=f"{self.get_name()}: {task}",
                                  hardware_id=hardware_id, message="OK",
                                  values=[KeyValue(key=k, value=v) for k, v in values.items()])
        pub.publish(DiagnosticArray(header=self._header(), status=[status]))

    def _header(self):
        from std_msgs.msg import Header

        return Header(stamp=self.stamp())


def joint_states(fd: Path) -> Station:
    n = Station("joint_state_broadcaster", fd, "/arm")
    pub = n.create_publisher(JointState, "/arm/joint_states", 10)

    def tick() -> None:
        n.gate()
        t = time.time()
        n.send(pub, JointState(header=n._header(), name=JOINTS, position=[0.1 * t % 1.0] * 6))
    n.create_timer(0.01, tick)
    return n


def gripper(fd: Path) -> Station:
    n = Station("gripper_driver", fd, "/arm")
    state = n.create_publisher(JointState, "/arm/gripper/state", 10)
    diag = n.create_publisher(DiagnosticArray, "/diagnostics", 10)
    closed = [False]

    def command(req, res):
        n.gate()
        closed[0] = req.data
        res.success, res.message = True, "closed" if req.data else "open"
        return res
    n.create_service(SetBool, "/arm/gripper/command", command)

    def tick() -> None:
        n.gate()
        n.send(state, JointState(header=n._header(), name=["finger"], position=[0.8 if closed[0] else 0.0]))
    n.create_timer(0.05, tick)
    n.create_timer(1.0, lambda: n.diag(diag, "motor", "robotiq-2f85-0042", {"closed": str(closed[0])}))
    return n


def ft_sensor(fd: Path) -> Station:
    n = Station("ft_sensor", fd, "/arm")
    pub = n.create_publisher(WrenchStamped, "/arm/wrench", qos_profile_sensor_data)

    def tick() -> None:
        n.gate()
        n.send(pub, WrenchStamped(header=n._header()))
    n.create_timer(0.005, tick)
    return n


def camera(fd: Path) -> Station:
    n = Station("camera", fd)
    n.declare_parameter("fps", 15.0)
    n.declare_parameter("exposure_us", 8000)
    pub = n.create_publisher(Image, "/station/camera/image", qos_profile_sensor_data)
    diag = n.create_publisher(DiagnosticArray, "/diagnostics", 10)
    frame = bytes(640 * 480)
    cg = MutuallyExclusiveCallbackGroup()

    def tick() -> None:
        n.gate()
        n.send(pub, Image(header=n._header(), height=480, width=640, encoding="mono8", step=640, data=frame))
    timer = [n.create_timer(1 / 15.0, tick, callback_group=cg)]

    def on_set(params):
        for p in params:
            if p.name == "fps" and p.value > 0:
                timer[0].cancel()
                n.destroy_timer(timer[0])
                timer[0] = n.create_timer(1.0 / p.value, tick, callback_group=cg)
        return SetParametersResult(successful=True)
    n.add_on_set_parameters_callback(on_set)
    def report() -> None:
        n.diag(diag, "stream", "basler-a2a-40221", {"fps": str(n.get_parameter("fps").value)})
    n.create_timer(1.0, report, callback_group=cg)
    return n


def detector(fd: Path) -> Station:
    n = Station("detector", fd)
    pub = n.create_publisher(PoseArray, "/station/detections", 10)
    cg = MutuallyExclusiveCallbackGroup()
    latest = [0.0]
    n.create_subscription(Image, "/station/camera/image", lambda m: latest.__setitem__(0, time.time()),
                          qos_profile_sensor_data, callback_group=cg)

    def detect(req, res):
        n.gate()
        if n.fault == "slow_service":
            time.sleep(6.0)
        time.sleep(0.15)  # inference
        n.send(pub, PoseArray(header=n._header(), poses=[Pose()]))
        res.success, res.message = time.time() - latest[0] < 1.0, "1 part"
        return res
    n.create_service(Trigger, "/station/detect", detect, callback_group=cg)
    return n


def planner(fd: Path) -> Station:
    n = Station("motion_planner", fd, "/arm")
    cmd = n.create_publisher(JointState, "/arm/trajectory_command", 10)
    group = ReentrantCallbackGroup()

    def execute(goal):
        end = time.monotonic() + 2.0 + goal.request.order / 4.0
        while time.monotonic() < end:
            n.gate()
            n.send(cmd, JointState(header=n._header(), name=JOINTS, velocity=[0.2] * 6))
            time.sleep(0.02)
        goal.succeed()
        return Fibonacci.Result(sequence=[goal.request.order])
    ActionServer(n, Fibonacci, "/arm/execute_trajectory", execute, callback_group=group)
    return n


def executive(fd: Path) -> Station:
    """Pick cycles: detect, move, grip, move back; idle between parts with the camera slowed."""
    n = Station("task_executive", fd)
    state = n.create_publisher(String, "/station/task_state", LATCHED)
    cg = ReentrantCallbackGroup()
    detect = n.create_client(Trigger, "/station/detect", callback_group=cg)
    grip = n.create_client(SetBool, "/arm/gripper/command", callback_group=cg)
    move = ActionClient(n, Fibonacci, "/arm/execute_trajectory", callback_group=cg)
    cam = AsyncParameterClient(n, "/station/camera")

    def say(what: str) -> None:
        n.send(state, String(data=what))

    def call(client, req, timeout: float):
        if not client.wait_for_service(timeout_sec=timeout):
            n.get_logger().error(f"service {client.srv_name} not available")
            return None
        fut = client.call_async(req)
        end = time.monotonic() + timeout
        while not fut.done() and time.monotonic() < end:
            time.sleep(0.02)
        if not fut.done():
            n.get_logger().error(f"service {client.srv_name} timed out after {timeout:.0f} s")
            return None
        return fut.result()

    def cycle() -> None:
        k = 0
        while rclpy.ok():
            k += 1
            say("detecting")
            if call(detect, Trigger.Request(), 3.0) is None:
                time.sleep(1.0)
                continue
            for closing in (True, False):
                say("moving")
                if move.wait_for_server(timeout_sec=3.0):
                    gh = move.send_goal_async(Fibonacci.Goal(order=4 + k % 5))
                    while not gh.done():
                        time.sleep(0.02)
                    res = gh.result().get_result_async()
                    while not res.done():
                        time.sleep(0.02)
                call(grip, SetBool.Request(data=closing), 3.0)
            say("idle")
            if k % 4 == 0 and cam.services_are_ready():  # a long idle: the camera slowed to save power
                cam.set_parameters([Parameter("fps", value=5.0)])
                time.sleep(25.0)
                cam.set_parameters([Parameter("fps", value=15.0)])
            elif cam.services_are_ready():
                cam.set_parameters([Parameter("exposure_us", value=6000 + 1000 * (k % 4))])
            time.sleep(3.0 + k % 3)
    threading.Thread(target=cycle, daemon=True).start()
    return n


def aggregator(fd: Path) -> Station:
    n = Station("diagnostic_aggregator", fd)
    agg = n.create_publisher(DiagnosticArray, "/diagnostics_agg", 10)
    health = n.create_publisher(String, "/station/health", 10)
    seen: dict[str, DiagnosticStatus] = {}

    def on_diag(msg) -> None:
        for s in msg.status:
            seen[s.name] = s

    def publish() -> None:
        n.gate()
        out = []
        for name, s in sorted(seen.items()):
            out.append(DiagnosticStatus(level=s.level, name=f"/Station/{name.replace('/', ' ')}",
                                        message=s.message, hardware_id=s.hardware_id, values=s.values))
        n.send(agg, DiagnosticArray(header=n._header(), status=out))
    n.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 10)
    n.create_timer(1.0, publish)
    n.create_timer(5.0, lambda: (n.gate(), n.send(health, String(data=f"{len(seen)} devices OK"))))
    return n


def hmi(fd: Path) -> Station:
    n = Station("hmi", fd)
    for topic, typ, qos in (("/station/task_state", String, LATCHED),
                            ("/diagnostics_agg", DiagnosticArray, 10),
                            ("/station/detections", PoseArray, 10), ("/station/health", String, 10)):
        n.create_subscription(typ, topic, lambda m: None, qos)
    return n


# process -> (executor kind, node factories)
PROCESSES = {
    "arm_drivers": ("single", (joint_states, gripper, ft_sensor)),
    "perception": ("multi", (camera, detector)),
    "planning": ("multi", (planner,)),
    "executive": ("multi", (executive,)),
    "monitoring": ("single", (aggregator,)),
    "hmi": ("single", (hmi,)),
}


def _burn(fd: Path, process: str) -> None:
    flag = fd / f"{process}.cpu"
    while not flag.exists():
        time.sleep(0.2)
    while True:
        pass


def main(argv: list[str]) -> int:
    process, fd = argv[0], Path(argv[1])
    run_for = float(argv[2]) if len(argv) > 2 else 0.0
    kind, factories = PROCESSES[process]
    rclpy.init()
    nodes = [f(fd) for f in factories]
    ex = MultiThreadedExecutor(num_threads=4) if kind == "multi" else SingleThreadedExecutor()
    for node in nodes:
        ex.add_node(node)
    threading.Thread(target=_burn, args=(fd, process), daemon=True).start()
    print("ready", flush=True)
    end = time.monotonic() + run_for if run_for else float("inf")
    try:
        while rclpy.ok() and time.monotonic() < end:
            ex.spin_once(timeout_sec=0.1)
    except KeyboardInterrupt:
        pass
    for node in nodes:
        node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
