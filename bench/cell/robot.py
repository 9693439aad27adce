"""A pick-and-place cell's ROS 2 stack in rclpy: ``python -m bench.cell.robot PROCESS FAULT_DIR [RUN_FOR]``.

Written the way a production cell with ros2_control, MoveIt and a behaviour tree is laid out (see
`bench.cell.run` for the whole robot, its healthy dynamics and its faults): ``/arm`` (the
controller manager's process: hardware loop, joint state broadcaster, joint trajectory controller,
gripper controller; the robot state publisher; move_group), ``/perception`` (the depth camera,
a container of detector, pose estimator and cloud preprocessor), ``/conveyor`` and ``/safety`` (the
PLC bridges), ``/cell`` (the behaviour-tree orchestrator, the lifecycle inspection station, the
diagnostics aggregator, the hand-eye calibration, the operator HMI that comes and goes), a rosbag
recorder, a rosbridge with rosapi, and the HIL bench's cell simulator (``/sim``: the belt and its
parts, which the drivers sample as they would sample their hardware).

Stock message types only (no trajectory_msgs, control_msgs nor tf2_msgs in this environment):
``/tf`` and ``/tf_static`` carry geometry_msgs/TransformStamped, one transform a message; a joint
trajectory is a sensor_msgs/JointState whose ``position`` holds the waypoints one after the other
(6 joints each), ``effort`` their time from start and ``header.frame_id`` the trajectory's id;
actions are test_msgs/Fibonacci goals (``order`` the trajectory id, the gripper's target width in
mm, or the motion's index; the feedback's ``sequence`` the percent done); planning answers
nav_msgs/GetPlan (the goal pose in, the tool path out); the pose estimation is a std_srvs/Trigger
answering JSON; the light curtain a sensor_msgs/Range (inf when clear).

Faults come from files: ``FAULT_DIR/<namespace>.<node>`` (``arm.move_group``) holding a word the
target node acts on (``hang``, ``degrade``, ``slow``, ``stale``, ``reliable``, ``errlog``,
``flaky``), read by the process's watcher thread every 0.5 s; ``FAULT_DIR/<process>.cpu`` starts a
thread burning a core in that process, ``<process>.leak`` one leaking 2.5 MB/s. Crashes are SIGKILLs
from outside. RUN_FOR > 0 ends the process cleanly (exit 0) after that many seconds.
"""

from __future__ import annotations

import json
import math
import random
import signal
import sys
import threading
import time
from collections import deque
from pathlib import Path
from typing import ClassVar

import numpy as np
import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Pose, PoseArray, PoseStamped, TransformStamped
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState
from nav_msgs.msg import Path as PathMsg
from nav_msgs.srv import GetPlan
from rcl_interfaces.msg import Log, SetParametersResult
from rcl_interfaces.srv import SetParameters
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor
from rclpy.experimental import EventsExecutor
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import CameraInfo, Image, JointState, PointCloud2, PointField, Range
from std_msgs.msg import Bool, Float32, Header, Int32, String
from std_srvs.srv import SetBool, Trigger
from test_msgs.action import Fibonacci

from stream_viz.demo.child import burn, leak

LEAK_MB_S = 2.5  # rosbridge's send queue to a stalled browser tab, never drained

OK, WARN, ERROR, STALE = (
    DiagnosticStatus.OK,
    DiagnosticStatus.WARN,
    DiagnosticStatus.ERROR,
    DiagnosticStatus.STALE,
)
SENSOR = qos_profile_sensor_data  # best effort, keep last 5
RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
COMMAND = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)
STATIC_TF = QoSProfile(
    depth=100, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)

HW_HZ, JSB_HZ, JTC_STATE_HZ, CAMERA_HZ, CURTAIN_HZ, ENCODER_HZ = 250.0, 100.0, 50.0, 15.0, 50.0, 20.0
JOINTS = tuple(f"joint_{i}" for i in range(1, 7))
FINGER = "gripper_finger_joint"
HOME_Q = np.array([0.0, -1.2, 1.6, -1.97, -1.57, 0.0])
PICK_X = 1.0  # the photo eye (m along the belt): the part stops under it, in the camera's view
BELT_Y = 0.55  # the belt's centre line in the robot's base frame (m)
PLACE = (-0.1, -0.5, 0.15)  # the inspection nest
PART_H = 0.04  # the parts' height (m)


# --- helpers ------------------------------------------------------------------------------------------


def to_stamp(t: float) -> Time:
    sec = int(t)
    return Time(sec=sec, nanosec=int((t - sec) * 1e9))


def secs(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


def clamp(v: float, lo: float, hi: float) -> float:
    return max(lo, min(hi, v))


def ik(x: float, y: float, z: float) -> np.ndarray:
    """A closed-form stand-in for the arm's IK: joint angles putting the tool above (x, y, z)."""
    base = math.atan2(y, x)
    reach = clamp(math.hypot(x, y), 0.2, 0.85)
    shoulder = -1.6 + 1.1 * reach - 0.6 * z
    elbow = 2.2 - 1.4 * reach + 0.4 * z
    return np.array([base, shoulder, elbow, -math.pi / 2 - shoulder - elbow, -1.57, base])


def fk(q) -> tuple[float, float, float]:
    """The tool's position from the joints (the inverse of `ik` on its domain)."""
    base, shoulder, elbow = q[0], q[1], q[2]
    # solve the two linear equations of `ik` for reach and z
    a = np.array([[1.1, -0.6], [-1.4, 0.4]])
    reach, z = np.linalg.solve(a, np.array([shoulder + 1.6, elbow - 2.2]))
    return reach * math.cos(base), reach * math.sin(base), z


STOPPING = threading.Event()  # Ctrl-C / SIGTERM: the driver threads stop first, then the executor


def alive() -> bool:
    return rclpy.ok() and not STOPPING.is_set()


def published(*sends: tuple) -> bool:
    """Publish from a driver thread; False once the context is going down (the thread then ends)."""
    try:
        for pub, msg in sends:
            pub.publish(msg)
    except Exception:
        if alive():
            raise
        return False
    return True


def paced(hz, jitter: float = 0.0, rng: random.Random | None = None):
    """A driver thread's loop: yields at ``hz`` (a number or a callable) while rclpy is up; ``jitter``
    s of random lateness on each wake (the scheduler of a non-RT kernel)."""
    nxt = time.monotonic()
    rng = rng or random.Random()
    while alive():
        nxt += 1.0 / (hz() if callable(hz) else hz)
        delay = nxt - time.monotonic() + (rng.expovariate(1.0 / jitter) if jitter else 0.0)
        if delay > 0:
            time.sleep(delay)
        elif delay < -0.5:
            nxt = time.monotonic()
        yield


class Outcome:
    """A result handed from the control loop to a blocking action callback (threading, not asyncio)."""

    def __init__(self) -> None:
        self.event = threading.Event()
        self.value = None

    def done(self) -> bool:
        return self.event.is_set()

    def set_result(self, value) -> None:
        self.value = value
        self.event.set()

    def wait(self):
        """The result, or None if the process is going down first."""
        while alive() and not self.event.wait(0.1):
            pass
        return self.value


def wait_for(future, timeout: float):
    """Block an executor thread (of a MultiThreadedExecutor) on an rclpy future: its result or None."""
    end = time.monotonic() + timeout
    while alive() and not future.done() and time.monotonic() < end:
        time.sleep(0.02)
    return future.result() if future.done() else None


POINT_FIELDS = [
    PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1)
    for i, n in enumerate(("x", "y", "z", "rgb"))
]


def cloud(header, pts: np.ndarray) -> PointCloud2:
    pts = np.ascontiguousarray(pts, dtype=np.float32)
    m = PointCloud2(height=1, width=len(pts), fields=POINT_FIELDS, is_bigendian=False, point_step=16,
                    row_step=16 * len(pts), is_dense=True)
    m.header = header
    m.data = pts.tobytes()
    return m


def points(msg: PointCloud2) -> np.ndarray:
    return np.frombuffer(msg.data, dtype=np.float32).reshape(-1, 4)


def transform(parent: str, child: str, xyz, stamp, yaw: float = 0.0) -> TransformStamped:
    t = TransformStamped()
    t.header.frame_id, t.child_frame_id, t.header.stamp = parent, child, stamp
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = map(float, xyz)
    t.transform.rotation.z, t.transform.rotation.w = math.sin(yaw / 2), math.cos(yaw / 2)
    return t


# --- fault hooks and the nodes' common parts ----------------------------------------------------------


def hook(node: Node, fault_dir: Path) -> None:
    """The bench's fault hooks: ``fault`` (the word in ``FAULT_DIR/<namespace>.<name>``, set by the
    watcher thread) and ``on_fault(word)``, run in the executor by `apply_faults` once it changed."""
    parts = [p for p in node.get_namespace().split("/") if p] + [node.get_name()]
    node.fault_file = fault_dir / ".".join(parts)
    node.fault = None
    node.fault_applied = None


def apply_faults(nodes: list) -> None:
    """The process's 1 Hz timer: each node's ``on_fault`` for a changed fault word."""
    for n in nodes:
        if n.fault != n.fault_applied:
            n.fault_applied = n.fault
            n.on_fault(n.fault)


class Diagnosed:
    """diagnostic_updater-style statuses (``node: task``, a hardware id) on /diagnostics, throttling."""

    def on_fault(self, fault: str | None) -> None:
        pass

    def status(self, task: str, hardware_id: str, level: bytes = OK, message: str = "OK", **values):
        kvs = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
        return DiagnosticStatus(level=level, name=f"{self.get_name()}: {task}", hardware_id=hardware_id,
                                message=message, values=kvs)

    def publish_diagnostics(self, *statuses: DiagnosticStatus) -> None:
        if getattr(self, "_diag_pub", None) is None:
            self._diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", RELIABLE)
        arr = DiagnosticArray(status=list(statuses))
        arr.header.stamp = self.get_clock().now().to_msg()
        self._diag_pub.publish(arr)

    def throttle(self, key: str, period: float) -> bool:
        """True at most once per ``period`` s for ``key`` (RCLCPP_WARN_THROTTLE)."""
        if not hasattr(self, "_throttled"):
            self._throttled = {}
        now = time.monotonic()
        if now - self._throttled.get(key, -1e9) < period:
            return False
        self._throttled[key] = now
        return True


class CellNode(Diagnosed, Node):
    def __init__(self, name: str, namespace: str, fault_dir: Path, **kw) -> None:
        Node.__init__(self, name, namespace=namespace, **kw)
        hook(self, fault_dir)
        self.rng = random.Random()


def watch(nodes: list, fault_dir: Path, process: str) -> None:
    """The process's fault watcher: node fault files, ``<process>.cpu`` and ``<process>.leak``."""
    started: set[str] = set()
    while True:
        time.sleep(0.5)
        for n in nodes:
            try:
                word = n.fault_file.read_text().strip() or None
            except OSError:
                word = None
            n.fault = word
        for how, target, arg in (("cpu", burn, 1.0), ("leak", leak, LEAK_MB_S)):
            if how not in started and (fault_dir / f"{process}.{how}").exists():
                started.add(how)  # the demo's own burner and leak, until the process ends
                threading.Thread(target=target, args=(threading.Event(), arg), daemon=True, name=how).start()


class Belt:
    """A driver's view of the HIL bench: the simulator's belt travel and the parts on it (x along
    the belt from its infeed, m), from /sim/ground_truth."""

    def __init__(self, node: Node) -> None:
        self.travel = 0.0
        self.speed = 0.0
        self.parts: list[float] = []
        node.create_subscription(PoseArray, "/sim/ground_truth", self.on_truth, SENSOR)

    def on_truth(self, m: PoseArray) -> None:
        self.travel, self.speed = m.poses[0].position.x, m.poses[0].position.y
        self.parts = [p.position.x for p in m.poses[1:]]

    def at_pick(self) -> bool:
        return any(abs(x - PICK_X) < 0.03 for x in self.parts)


# --- the HIL bench ------------------------------------------------------------------------------------


class CellSimulator(CellNode):
    """The HIL bench's belt and parts: the belt follows the PLC's drive command (/conveyor/drive,
    m/s), a part is loaded at the infeed every 8-16 s (the upstream machine's output) when there is
    room, parts stop against the stopper under the photo eye, the part there leaves the belt once the
    gripper closes on it; /sim/ground_truth (PoseArray: poses[0] the belt's travel and speed, then
    the parts) at 20 Hz from its physics thread."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("cell_simulator", "sim", fault_dir)
        self.pub = self.create_publisher(PoseArray, "/sim/ground_truth", SENSOR)
        self.create_subscription(Float32, "/conveyor/drive", self.on_drive, COMMAND)
        self.create_subscription(JointState, "/arm/gripper_controller/state", self.on_gripper, SENSOR)
        self.cmd = 0.0
        self.speed = self.travel = 0.0
        self.parts: list[float] = []
        self.holding = False
        self.next_part = time.monotonic() + 2.0
        self.lock = threading.Lock()
        self.get_logger().info("HIL cell model up: belt 1.6 m, infeed at 0, photo eye at 1.0 m")
        threading.Thread(target=self.physics, daemon=True, name="physics").start()

    def on_drive(self, msg: Float32) -> None:
        self.cmd = msg.data

    def on_gripper(self, msg: JointState) -> None:
        holding = bool(msg.effort) and msg.effort[0] > 10.0 and 0.02 < msg.position[0] < 0.045
        if holding and not self.holding:  # the fingers closed on the part at the stopper: it leaves the belt
            with self.lock:
                self.parts = [x for x in self.parts if abs(x - PICK_X) > 0.03]
        self.holding = holding

    def physics(self) -> None:
        dt = 1.0 / 20.0
        m = PoseArray()
        m.header.frame_id = "conveyor_link"
        for _ in paced(20.0):
            self.speed += clamp(self.cmd - self.speed, -0.5 * dt, 0.5 * dt)  # the drive's ramp
            self.travel += self.speed * dt
            now = time.monotonic()
            with self.lock:
                # a part stops against the stopper under the photo eye; the belt slips beneath it
                self.parts = [x if x >= PICK_X else min(PICK_X, x + self.speed * dt) for x in self.parts]
                if now > self.next_part and (not self.parts or min(self.parts) > 0.25):
                    self.parts.append(0.0)
                    self.next_part = now + self.rng.uniform(8.0, 16.0)
                parts = list(self.parts)
            m.header.stamp = self.get_clock().now().to_msg()
            belt = Pose()
            belt.position.x, belt.position.y = self.travel, self.speed
            poses = [belt]
            for x in parts:
                p = Pose()
                p.position.x = x
                poses.append(p)
            m.poses = poses
            if not published((self.pub, m)):
                return


# --- ros2_control -------------------------------------------------------------------------------------


class ControllerManager(CellNode):
    """ros2_control's controller manager: the hardware interface's read/update/write loop at 250 Hz in
    its own thread (the arm's EtherCAT drives and the gripper), calling each active controller's
    update; the drives disabled (a protective stop) while the safety PLC's state is not RUN."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("controller_manager", "arm", fault_dir)
        self.declare_parameter("update_rate", int(HW_HZ))
        self.q = HOME_Q.copy()
        self.qd = np.zeros(6)
        self.finger = 0.085
        self.finger_effort = 0.0
        self.controllers: list = []
        self.safety = None
        self.stopped = False
        self.cycles = self.overruns = 0
        self.max_cycle_ms = 0.0
        self.create_subscription(String, "/safety/state", self.on_safety, LATCHED)
        self.create_timer(1.0, self.on_second)
        self.get_logger().info("Loaded hardware 'ur_arm_ethercat' (6 joints) and 'robotiq_2f85' (1 joint)")

    def add(self, controller) -> None:
        self.controllers.append(controller)
        self.get_logger().info(f"Configured and activated {controller.get_name()}")

    def start(self) -> None:
        threading.Thread(target=self.loop, daemon=True, name="ros2_control").start()

    def on_safety(self, msg: String) -> None:
        self.safety = msg.data

    def safe(self) -> str | None:
        """Why the arm must not move, or None."""
        return None if self.safety == "RUN" else f"safety state {self.safety}"

    def loop(self) -> None:
        period = 1.0 / HW_HZ
        last = time.monotonic()
        for _ in paced(HW_HZ, jitter=0.0004, rng=self.rng):
            t0 = time.monotonic()
            dt = t0 - last
            last = t0
            why = self.safe()
            if self.safety is None:  # bring-up: the drives stay disabled until the safety PLC is seen
                self.stopped = True
            elif why and not self.stopped:
                self.stopped = True
                self.qd[:] = 0.0
                self.get_logger().error(f"Protective stop: {why}")
            elif not why and self.stopped:
                self.stopped = False
                self.get_logger().info("Safety OK: drives enabled")
            for c in self.controllers:  # read() is the state kept here; update(); write()
                try:
                    c.update(t0, dt, self)
                except Exception:
                    if alive():
                        raise
                    return
            self.cycles += 1
            ms = (time.monotonic() - t0) * 1e3
            self.max_cycle_ms = max(self.max_cycle_ms, ms + dt * 1e3 - period * 1e3)
            if dt > 2 * period:
                self.overruns += 1

    def on_second(self) -> None:
        level, msg = (ERROR, "protective stop") if self.stopped else (OK, "running")
        self.publish_diagnostics(self.status("hardware_interface", "ur-ethercat-0", level, msg,
                                             cycles=self.cycles, overruns=self.overruns,
                                             max_jitter_ms=f"{self.max_cycle_ms:.2f}"))
        self.cycles = self.overruns = 0
        self.max_cycle_ms = 0.0


class JointStateBroadcaster(CellNode):
    """/joint_states (7 joints: the arm's 6 and the finger) at 100 Hz from the control loop, through a
    realtime publisher (it skips a cycle when the publisher's lock is held)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("joint_state_broadcaster", "arm", fault_dir)
        self.declare_parameter("publish_rate", JSB_HZ)
        self.pub = self.create_publisher(JointState, "/joint_states", RELIABLE)
        self.msg = JointState(name=[*JOINTS, FINGER])
        self.next = 0.0
        self.n = 0
        self.create_timer(1.0, self.on_second)

    def on_fault(self, fault: str | None) -> None:
        if fault == "degrade":
            pass  # the realtime publisher's trylock now fails on most cycles (see update)

    def update(self, now: float, dt: float, cm: ControllerManager) -> None:
        if now < self.next:
            return
        # a realtime publisher whose non-RT thread is starved gets its lock only every 2.5 cycles
        rate = 40.0 if self.fault == "degrade" else self.get_parameter("publish_rate").value
        self.next = max(self.next + 1.0 / rate, now)
        m = self.msg
        m.header.stamp = cm.get_clock().now().to_msg()
        m.position = [*map(float, cm.q), cm.finger]
        m.velocity = [*map(float, cm.qd), 0.0]
        m.effort = [0.0] * 6 + [cm.finger_effort]
        self.pub.publish(m)
        self.n += 1

    def on_second(self) -> None:
        self.n = 0


class JointTrajectoryController(CellNode):
    """The arm's joint trajectory controller: the action ``/arm/joint_trajectory_controller/
    follow_joint_trajectory`` (order = the id of a trajectory sent on its ``~/joint_trajectory``
    topic); the loop interpolates the waypoints; ``~/controller_state`` at 50 Hz only while a
    trajectory executes; a goal aborts on a protective stop or a 0.1 rad path tolerance."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("joint_trajectory_controller", "arm", fault_dir)
        self.declare_parameter("joints", list(JOINTS))
        self.declare_parameter("constraints.goal_time", 0.5)
        self.state_pub = self.create_publisher(JointState, "~/controller_state", SENSOR)
        self.create_subscription(JointState, "~/joint_trajectory", self.on_traj, RELIABLE)
        self.trajs: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        self.active = None  # [waypoints, times, start, future, progress]
        self.next_state = 0.0
        ActionServer(self, Fibonacci, "~/follow_joint_trajectory", execute_callback=self.execute,
                     callback_group=ReentrantCallbackGroup(),
                     goal_callback=self.on_goal, cancel_callback=lambda g: CancelResponse.ACCEPT)
        self.create_timer(1.0, self.on_second)

    def on_traj(self, msg: JointState) -> None:
        wps = np.array(msg.position).reshape(-1, 6)
        self.trajs[msg.header.frame_id] = (wps, np.array(msg.effort))
        while len(self.trajs) > 8:
            self.trajs.pop(next(iter(self.trajs)))

    def on_goal(self, goal) -> GoalResponse:
        if str(goal.order) not in self.trajs:
            self.get_logger().error(f"Trajectory {goal.order} unknown: goal rejected")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def execute(self, goal):
        wps, times = self.trajs[str(goal.request.order)]
        fut = Outcome()
        self.active = [wps, times, None, fut, 0.0]
        self.get_logger().info(f"Received new trajectory {goal.request.order}: {len(wps)} points, "
                               f"{times[-1]:.2f} s")
        ok = fut.wait()
        self.active = None
        if ok:
            goal.succeed()
            return Fibonacci.Result(sequence=[100])
        goal.abort()
        self.get_logger().error("Aborted the trajectory: protective stop")
        return Fibonacci.Result(sequence=[0])

    def update(self, now: float, dt: float, cm: ControllerManager) -> None:
        a = self.active
        if a is None or a[3].done():
            return
        wps, times, start, fut, _ = a
        if start is None:
            a[2] = start = now
        if cm.stopped:
            fut.set_result(False)
            return
        t = now - start
        i = int(np.searchsorted(times, t))
        if i >= len(times):
            cm.q[:] = wps[-1]
            cm.qd[:] = 0.0
            fut.set_result(True)
            return
        t0, t1 = (times[i - 1], times[i]) if i > 0 else (0.0, times[0])
        q0 = wps[i - 1] if i > 0 else wps[0]
        s = clamp((t - t0) / max(t1 - t0, 1e-3), 0.0, 1.0)
        s = s * s * (3 - 2 * s)
        q = q0 + (wps[i] - q0) * s
        cm.qd[:] = (q - cm.q) / max(dt, 1e-3)
        cm.q[:] = q
        a[4] = t / times[-1]
        if now >= self.next_state:
            self.next_state = now + 1.0 / JTC_STATE_HZ
            m = JointState(name=list(JOINTS), position=list(map(float, q)),
                           velocity=list(map(float, cm.qd)), effort=[0.0] * 6)
            m.header.stamp = cm.get_clock().now().to_msg()
            self.state_pub.publish(m)

    def on_second(self) -> None:
        pass


class GripperController(CellNode):
    """The two-finger gripper: ``/arm/gripper_controller/gripper_cmd`` (order = the target width in
    mm); the fingers move at 0.15 m/s and stall on a part (width ~0.04 m, effort ~20 N: grasped);
    ``~/state`` (JointState: width, effort) at 20 Hz."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("gripper_controller", "arm", fault_dir)
        self.declare_parameter("max_effort", 40.0)
        self.state_pub = self.create_publisher(JointState, "~/state", SENSOR)
        self.belt = Belt(self)
        self.target = 0.085
        self.fut = None
        self.next_state = 0.0
        self.errors = 0
        self.slip = False
        ActionServer(self, Fibonacci, "~/gripper_cmd", execute_callback=self.execute,
                     callback_group=ReentrantCallbackGroup(),
                     cancel_callback=lambda g: CancelResponse.ACCEPT)
        self.create_timer(1.0, self.on_second)

    def execute(self, goal):
        self.target = goal.request.order / 1000.0
        # now and then a part sits crooked against the stopper and the fingers close on nothing
        self.slip = self.target < 0.04 and self.rng.random() < 0.05
        self.fut = Outcome()
        width = self.fut.wait() or 0.0
        goal.succeed()
        return Fibonacci.Result(sequence=[int(width * 1000)])

    def update(self, now: float, dt: float, cm: ControllerManager) -> None:
        step = 0.15 * dt
        if self.target < cm.finger:  # closing
            part = self.belt.at_pick() and not self.slip and fk(cm.q)[2] < 0.12
            if cm.finger_effort > 10.0:
                pass  # holding the part: stalled
            elif part and cm.finger - step <= PART_H:
                cm.finger, cm.finger_effort = PART_H, 20.0
            else:
                cm.finger = max(self.target, cm.finger - step)
        else:
            cm.finger_effort = 0.0
            cm.finger = min(self.target, cm.finger + step)
        done = abs(cm.finger - self.target) < 1e-4 or cm.finger_effort > 10.0
        if self.fut is not None and done and not self.fut.done():
            self.fut.set_result(cm.finger)
        if now >= self.next_state:
            self.next_state = now + 0.05
            m = JointState(name=[FINGER], position=[cm.finger], effort=[cm.finger_effort])
            m.header.stamp = cm.get_clock().now().to_msg()
            self.state_pub.publish(m)

    def on_second(self) -> None:
        if self.fault == "errlog":  # one finger's CAN node fails its CRC: every frame is re-read
            self.errors += 1
            self.get_logger().error(f"CAN bus: CRC error on node 0x09 (finger B), frame re-read "
                                    f"({self.errors} since start)")
        self.publish_diagnostics(self.status("gripper", "robotiq-2f85-can0", OK, "OK",
                                             crc_errors=self.errors))


# --- robot state --------------------------------------------------------------------------------------


class RobotStatePublisher(CellNode):
    """/tf from /joint_states (base_link -> tool0 and the finger, one transform a message, each joint
    state's stamp) and the robot's fixed frames on /tf_static once, latched."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("robot_state_publisher", "", fault_dir)
        self.declare_parameter("robot_description", "<robot name='cell_ur5e'>...</robot>")
        self.declare_parameter("publish_frequency", 100.0)
        self.tf_pub = self.create_publisher(TransformStamped, "/tf", 100)
        static = self.create_publisher(TransformStamped, "/tf_static", STATIC_TF)
        now = self.get_clock().now().to_msg()
        for parent, child, xyz in (("world", "base_link", (0.0, 0.0, 0.8)),
                                   ("world", "conveyor_link", (-0.6, BELT_Y, 0.8)),
                                   ("base_link", "inspection_nest", PLACE),
                                   ("tool0", "gripper_base", (0.0, 0.0, 0.03))):
            static.publish(transform(parent, child, xyz, now))
        self.static = static
        self.create_subscription(JointState, "/joint_states", self.on_joints, RELIABLE)
        self.get_logger().info("Robot initialized: 8 links, 7 movable joints")

    def on_joints(self, msg: JointState) -> None:
        if len(msg.position) < 7:
            return
        x, y, z = fk(msg.position)
        self.tf_pub.publish(transform("base_link", "tool0", (x, y, z), msg.header.stamp, msg.position[0]))
        self.tf_pub.publish(transform("gripper_base", "finger_left", (0.0, msg.position[6] / 2, 0.05),
                                      msg.header.stamp))


# --- MoveIt -------------------------------------------------------------------------------------------


class MoveGroup(CellNode):
    """move_group: ``/arm/move_group/plan`` (GetPlan: the goal's pose; 0.2-2 s of sampling-based
    planning against the octomap, a plan fails now and then), the action ``/arm/move_group/
    execute_trajectory`` (order = the plan's id) driving the trajectory controller's action; the
    current state and the octomap from its private node (`PlanningSceneMonitor`)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("move_group", "arm", fault_dir)
        self.declare_parameter("planning_plugin", "ompl_interface/OMPLPlanner")
        self.declare_parameter("max_velocity_scaling_factor", 0.6)
        self.declare_parameter("octomap_resolution", 0.025)
        self.planning = MutuallyExclusiveCallbackGroup()
        self.exec_group = ReentrantCallbackGroup()
        self.monitors = MutuallyExclusiveCallbackGroup()
        self.create_service(GetPlan, "~/plan", self.on_plan, callback_group=self.planning)
        ActionServer(self, Fibonacci, "~/execute_trajectory", execute_callback=self.execute,
                     callback_group=self.exec_group, cancel_callback=lambda g: CancelResponse.ACCEPT)
        self.jtc = ActionClient(self, Fibonacci, "/arm/joint_trajectory_controller/follow_joint_trajectory",
                                callback_group=self.exec_group)
        self.traj_pub = self.create_publisher(JointState, "/arm/joint_trajectory_controller/joint_trajectory",
                                              RELIABLE)
        self.path_pub = self.create_publisher(PathMsg, "~/display_planned_path", LATCHED)
        self.scene_pub = self.create_publisher(String, "~/monitored_planning_scene", RELIABLE)
        self.monitor: PlanningSceneMonitor | None = None  # its private node, spun in its own thread
        self.plans: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self.plan_id = 0
        self.lock = threading.Lock()
        self.create_timer(1.0, self.on_second, callback_group=self.monitors)
        self.get_logger().info("MoveGroup context using planning plugin ompl_interface/OMPLPlanner")
        self.get_logger().info("You can start planning now!")

    def on_plan(self, request, response):
        g = request.goal.pose.position
        t0 = time.monotonic()
        goal_q = ik(g.x, g.y, g.z)
        start = self.monitor.q.copy()
        # RRTConnect: its sampling and the collision checks against the octomap (real CPU work)
        budget = self.rng.uniform(0.2, 0.8) if self.rng.random() < 0.85 else self.rng.uniform(1.0, 2.0)
        if request.tolerance > 0.5:  # a free-space motion (home): straight to the goal
            budget = 0.1
        octomap = self.monitor.octomap
        obstacles = octomap if len(octomap) else np.zeros((1, 3))
        samples = 0
        while time.monotonic() - t0 < budget:
            qs = start + (goal_q - start) * np.random.rand(64, 1) + np.random.normal(0, 0.2, (64, 6))
            tips = np.column_stack([np.cos(qs[:, 0]), np.sin(qs[:, 0]), qs[:, 1]]) * 0.6
            d = np.linalg.norm(tips[:, None, :] - obstacles[None, :400, :], axis=2)
            samples += int((d.min(axis=1) > 0.02).sum())
        if self.fault == "slow":  # the octomap's collision cache rebuilt at every query (a 0.01 m octree)
            time.sleep(8.0)
        if self.rng.random() < 0.06:
            self.get_logger().warn(f"RRTConnect: unable to find a valid path within {budget:.2f} s: "
                                   "unable to solve the planning problem")
            return response
        n = 8
        scale = self.get_parameter("max_velocity_scaling_factor").value
        dist = float(np.abs(goal_q - start).max())
        dur = max(0.8, dist / (1.2 * scale))
        wps = np.array([start + (goal_q - start) * k / (n - 1) for k in range(n)])
        times = np.linspace(dur / (n - 1), dur, n)
        self.plan_id += 1
        self.plans[self.plan_id] = (wps, times)
        self.plans.pop(self.plan_id - 10, None)
        response.plan.header.frame_id = f"plan:{self.plan_id}"
        response.plan.header.stamp = self.get_clock().now().to_msg()
        for q in wps:
            ps = PoseStamped()
            ps.pose.position.x, ps.pose.position.y, ps.pose.position.z = fk(q)
            response.plan.poses.append(ps)
        self.path_pub.publish(response.plan)
        self.get_logger().info(f"Motion plan was computed successfully: {samples} states, "
                               f"{time.monotonic() - t0:.3f} s, trajectory {dur:.2f} s")
        return response

    def execute(self, goal):
        pid = goal.request.order
        if pid not in self.plans:
            goal.abort()
            return Fibonacci.Result()
        wps, times = self.plans[pid]
        m = JointState(name=list(JOINTS) * len(wps), position=list(map(float, wps.ravel())),
                       effort=list(map(float, times)))
        m.header.stamp = self.get_clock().now().to_msg()
        m.header.frame_id = str(pid)
        self.traj_pub.publish(m)
        self.get_logger().info(f"Execution request received for plan {pid}")
        time.sleep(0.2)  # the trajectory reaches the controller first
        gh = wait_for(self.jtc.send_goal_async(Fibonacci.Goal(order=pid)), 2.0)
        if gh is None or not gh.accepted:
            self.get_logger().error("Controller rejected the trajectory")
            goal.abort()
            return Fibonacci.Result()
        res = wait_for(gh.get_result_async(), 60.0)
        if res is not None and res.status == 4:
            self.get_logger().info("Completed trajectory execution with status SUCCEEDED ...")
            goal.succeed()
            return Fibonacci.Result(sequence=[100])
        self.get_logger().error("Controller failed during execution: ABORTED")
        goal.abort()
        return Fibonacci.Result(sequence=[0])

    def on_second(self) -> None:
        m = self.monitor
        age = None if m.cloud_at is None else time.monotonic() - m.cloud_at
        if age is not None and age > 2.0 and self.throttle("scene", 10.0):
            self.get_logger().warn(f"The planning scene's octomap was not updated for {age:.1f} s")
        self.scene_pub.publish(String(data=json.dumps({"octomap_voxels": len(m.octomap),
                                                       "cloud_age": None if age is None else round(age, 2)})))
        self.publish_diagnostics(self.status("planning_scene", "move_group", OK if age is not None and age < 2
                                             else WARN, "OK", octomap_voxels=len(m.octomap)))


class PlanningSceneMonitor(CellNode):
    """move_group's private node (``/arm/move_group_private``, as MoveIt makes one), spun by its own
    executor thread: the current state monitor on /joint_states and the octomap updater on the
    filtered cloud (a voxel set at ``octomap_resolution``)."""

    private_executor = True

    def __init__(self, fault_dir: Path, resolution: float) -> None:
        super().__init__("move_group_private", "arm", fault_dir)
        self.resolution = resolution
        self.q = HOME_Q.copy()
        self.octomap: np.ndarray = np.zeros((0, 3))
        self.cloud_at = None
        self.create_subscription(JointState, "/joint_states", self.on_joints, RELIABLE)
        self.create_subscription(PointCloud2, "/perception/points_filtered", self.on_cloud, SENSOR)

    def on_joints(self, msg: JointState) -> None:
        self.q = np.array(msg.position[:6])

    def on_cloud(self, msg: PointCloud2) -> None:
        pts = points(msg)[:, :3]
        self.octomap = np.unique(np.round(pts / self.resolution).astype(np.int32), axis=0) * self.resolution
        self.cloud_at = time.monotonic()


# --- perception ---------------------------------------------------------------------------------------


class CameraDriver(CellNode):
    """The depth camera over the belt's pick zone (a structured-light camera on USB 3): a 1200-point
    cloud at 15 Hz of the belt and of the parts in view (x 0.8-1.2 m along the belt), camera info
    beside it, sensor QoS, stamped at the exposure."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("camera_driver", "perception/camera", fault_dir)
        self.declare_parameter("serial_no", "213622251070")
        self.declare_parameter("depth_fps", int(CAMERA_HZ))
        self.belt = Belt(self)
        self.pub = self.create_publisher(PointCloud2, "/perception/camera/depth/points", SENSOR)
        self.info_pub = self.create_publisher(CameraInfo, "/perception/camera/depth/camera_info", SENSOR)
        self.n = 0
        self.get_logger().info("Device 213622251070 (USB 3.2) connected: depth 640x480 @ 15 fps")
        self.create_timer(1.0, self.on_second)
        threading.Thread(target=self.stream, daemon=True, name="usb").start()

    def rate(self) -> float:
        return 5.0 if self.fault == "degrade" else CAMERA_HZ

    def stream(self) -> None:
        gx, gy = np.meshgrid(np.linspace(0.8, 1.2, 40), np.linspace(-0.15, 0.15, 30))
        grid = np.column_stack([gx.ravel(), gy.ravel()])
        info = CameraInfo(width=640, height=480, distortion_model="plumb_bob")
        info.header.frame_id = "camera_depth_optical_frame"
        for _ in paced(self.rate, jitter=0.002, rng=self.rng):
            z = np.random.normal(0.0, 0.002, len(grid))
            for x in self.belt.parts:
                if 0.75 < x < 1.25:
                    on = (np.abs(grid[:, 0] - x) < 0.03) & (np.abs(grid[:, 1]) < 0.03)
                    z[on] += PART_H
            pts = np.column_stack([grid, z, np.full(len(grid), 0.5)])
            h = Header(frame_id="camera_depth_optical_frame", stamp=self.get_clock().now().to_msg())
            info.header.stamp = h.stamp
            self.n += 1
            if not published((self.pub, cloud(h, pts)), (self.info_pub, info)):
                return

    def on_second(self) -> None:
        self.publish_diagnostics(self.status("depth_stream", "d435-213622251070", OK, "streaming",
                                             fps=self.n))
        self.n = 0


class ObjectDetector(CellNode):
    """Segments the cloud above the belt plane into parts: /perception/detections (PoseArray, the
    cloud's stamp, belt frame) only when parts are in view."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("object_detector", "perception", fault_dir)
        self.declare_parameter("min_height", 0.015)
        self.declare_parameter("min_points", 6)
        self.pub = self.create_publisher(PoseArray, "/perception/detections", RELIABLE)
        self.create_subscription(PointCloud2, "/perception/camera/depth/points", self.on_cloud, SENSOR)
        self.seen = 0
        self.create_timer(1.0, self.on_second)

    def on_cloud(self, msg: PointCloud2) -> None:
        while self.fault == "hang":  # the clustering's union-find loops on a cyclic parent array
            time.sleep(0.05)
        pts = points(msg)
        above = pts[pts[:, 2] > self.get_parameter("min_height").value]
        if len(above) < self.get_parameter("min_points").value:
            return
        order = np.sort(above[:, 0])
        splits = np.where(np.diff(order) > 0.03)[0]
        out = PoseArray(header=msg.header)
        for chunk in np.split(order, splits + 1):
            if len(chunk) >= 3:
                p = Pose()
                p.position.x, p.position.z = float(chunk.mean()), PART_H
                p.orientation.w = 1.0
                out.poses.append(p)
        if out.poses:
            out.header.frame_id = "conveyor_link"
            self.pub.publish(out)
            self.seen += 1

    def on_second(self) -> None:
        self.publish_diagnostics(self.status("detector", "perception-gpu0", OK, "OK", detections=self.seen))
        self.seen = 0


class CloudPreprocessor(CellNode):
    """Crop box and voxel grid on the camera cloud for the planning scene: /perception/points_filtered
    (sensor QoS, 15 Hz, the camera's stamp, every other point)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("cloud_preprocessor", "perception", fault_dir)
        self.declare_parameter("voxel_leaf_size", 0.02)
        self.pub = self.create_publisher(PointCloud2, "/perception/points_filtered", SENSOR)
        self.create_subscription(PointCloud2, "/perception/camera/depth/points", self.on_cloud, SENSOR)

    def on_cloud(self, msg: PointCloud2) -> None:
        pts = points(msg)[::2].copy()
        pts[:, 0] -= 0.6  # conveyor_link -> base_link
        pts[:, 1] += BELT_Y
        self.pub.publish(cloud(msg.header, pts))


class PoseEstimator(CellNode):
    """``/perception/pose_estimator/estimate`` (Trigger, JSON): the newest detection refined against
    the newest cloud (an ICP fit, 50-150 ms) into a grasp pose in base_link; fails when it has no
    detection or no cloud younger than 1 s."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("pose_estimator", "perception", fault_dir)
        self.declare_parameter("model", "/opt/cell/models/housing_v3.ply")
        self.declare_parameter("icp_iterations", 30)
        self.create_service(Trigger, "~/estimate", self.on_estimate)
        self.cloud_sub = self.create_subscription(PointCloud2, "/perception/camera/depth/points",
                                                  self.on_cloud, SENSOR)
        self.create_subscription(PoseArray, "/perception/detections", self.on_det, RELIABLE)
        self.cloud = self.det = None
        self.cloud_at = self.det_at = 0.0

    def on_fault(self, fault: str | None) -> None:
        if fault == "reliable":  # a redeployed pose_estimator.yaml asks for a reliable cloud
            self.get_logger().info("Parameters reloaded: re-creating the cloud subscription "
                                   "(reliability: reliable)")
            self.destroy_subscription(self.cloud_sub)
            self.cloud_sub = self.create_subscription(
                PointCloud2, "/perception/camera/depth/points", self.on_cloud,
                QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE))

    def on_cloud(self, msg: PointCloud2) -> None:
        self.cloud, self.cloud_at = msg, time.monotonic()

    def on_det(self, msg: PoseArray) -> None:
        self.det, self.det_at = msg, time.monotonic()

    def on_estimate(self, request, response):
        now = time.monotonic()
        if self.cloud is None or now - self.cloud_at > 1.0:
            response.success, response.message = False, "no point cloud in the last 1.0 s"
            self.get_logger().error("Pose estimation failed: no point cloud in the last 1.0 s")
            return response
        if self.det is None or now - self.det_at > 2.0:
            response.success, response.message = False, "no detection"
            self.get_logger().warn("Pose estimation: no recent detection")
            return response
        pts = points(self.cloud)
        x = min((p.position.x for p in self.det.poses), key=lambda v: abs(v - PICK_X))
        near = pts[(np.abs(pts[:, 0] - x) < 0.05) & (pts[:, 2] > 0.015)]
        for _ in range(self.get_parameter("icp_iterations").value):  # ICP against the part model
            if len(near):
                x = 0.5 * x + 0.5 * float(near[:, 0].mean())
        time.sleep(self.rng.uniform(0.04, 0.12))
        bx, by = x - 0.6, BELT_Y  # conveyor_link -> base_link: the pick point
        response.success = True
        response.message = json.dumps({"frame_id": "base_link", "x": round(bx, 4), "y": round(by, 4),
                                       "z": PART_H, "yaw": round(self.rng.gauss(0, 0.05), 3),
                                       "fitness": round(0.9 + self.rng.random() * 0.08, 3)})
        self.get_logger().info(f"Estimated the part's pose at ({bx:.3f}, {by:.3f}) in base_link")
        return response


# --- PLC bridges --------------------------------------------------------------------------------------


class ConveyorPlcBridge(CellNode):
    """The conveyor PLC over Modbus/TCP: the belt runs at ``speed`` (a runtime parameter, m/s) unless
    stopped (``~/run``, SetBool) and stops itself when the photo eye sees a part; /conveyor/speed
    (10 Hz), /conveyor/encoder (JointState, 20 Hz, sensor QoS), /conveyor/parts_present (latched, on
    change), /conveyor/heartbeat (2 Hz); the drive command to the VFD on /conveyor/drive."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("plc_bridge", "conveyor", fault_dir)
        self.declare_parameter("speed", 0.2)
        self.declare_parameter("plc_ip", "10.10.0.21")
        self.add_on_set_parameters_callback(self.on_params)
        self.belt = Belt(self)
        self.drive_pub = self.create_publisher(Float32, "/conveyor/drive", COMMAND)
        self.speed_pub = self.create_publisher(Float32, "/conveyor/speed", RELIABLE)
        self.enc_pub = self.create_publisher(JointState, "/conveyor/encoder", SENSOR)
        self.present_pub = self.create_publisher(Bool, "/conveyor/parts_present", LATCHED)
        self.hb_pub = self.create_publisher(Header, "/conveyor/heartbeat", RELIABLE)
        self.create_service(SetBool, "~/run", self.on_run)
        self.running = True
        self.present = None
        self.hb = 0
        self.dropout_until = 0.0
        self.next_dropout = 0.0
        self.encoder_ok = True
        self.get_logger().info("Connected to the conveyor PLC at 10.10.0.21:502")
        self.create_timer(0.1, self.on_tick)
        self.create_timer(0.05, self.on_encoder)
        self.create_timer(0.5, self.on_heartbeat)

    def on_params(self, params) -> SetParametersResult:
        for p in params:
            if p.name == "speed":
                if not 0.05 <= p.value <= 0.4:
                    return SetParametersResult(successful=False, reason="speed out of 0.05-0.4 m/s")
                self.get_logger().info(f"Belt speed set to {p.value:.2f} m/s")
        return SetParametersResult(successful=True)

    def on_run(self, request, response):
        self.running = request.data
        self.get_logger().info("Belt started" if request.data else "Belt stopped by the cell")
        response.success, response.message = True, "running" if request.data else "stopped"
        return response

    def on_tick(self) -> None:
        present = self.belt.at_pick()
        if present != self.present:
            self.present = present
            self.present_pub.publish(Bool(data=present))
            if present:
                self.get_logger().info("Part at the photo eye: belt stopped")
                self.running = False
        cmd = self.get_parameter("speed").value if self.running and not present else 0.0
        self.drive_pub.publish(Float32(data=float(cmd)))
        self.speed_pub.publish(Float32(data=float(self.belt.speed)))

    def on_encoder(self) -> None:
        now = time.monotonic()
        if self.fault == "flaky":  # the encoder's cable chafes on the belt frame: its A/B signals drop out
            if now > self.next_dropout:
                self.dropout_until = now + self.rng.uniform(1.0, 3.0)
                self.next_dropout = self.dropout_until + self.rng.uniform(5.0, 10.0)
        ok = now >= self.dropout_until
        if ok != self.encoder_ok:
            self.encoder_ok = ok
            if ok:
                self.get_logger().info("Encoder signal back")
            else:
                self.get_logger().warn("Encoder signal lost: no counts from the belt encoder")
        if not ok:
            return
        m = JointState(name=["belt"], position=[self.belt.travel], velocity=[self.belt.speed])
        m.header.stamp = self.get_clock().now().to_msg()
        m.header.frame_id = "conveyor_link"
        self.enc_pub.publish(m)

    def on_heartbeat(self) -> None:
        self.hb += 1
        self.hb_pub.publish(Header(stamp=self.get_clock().now().to_msg(), frame_id=str(self.hb)))
        if self.hb % 2 == 0:
            level = OK if self.encoder_ok else WARN
            self.publish_diagnostics(self.status("conveyor", "plc-s7-1200-conveyor", level,
                                                 "OK" if self.encoder_ok else "encoder signal lost",
                                                 running=self.running, speed=f"{self.belt.speed:.2f}"))


class SafetyPlcBridge(CellNode):
    """The safety PLC's read-only bridge: /safety/state latched (RUN, on change), the light curtain on
    /safety/light_curtain (Range: inf when clear, the first interrupted beam's height otherwise;
    ``frame_id`` ``muted`` while muted) at 50 Hz from its polling thread; a tote passes through the
    curtain every 40-80 s, muted for ~3 s."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("safety_plc_bridge", "safety", fault_dir)
        self.declare_parameter("plc_ip", "10.10.0.22")
        self.state_pub = self.create_publisher(String, "/safety/state", LATCHED)
        self.curtain_pub = self.create_publisher(Range, "/safety/light_curtain", SENSOR)
        self.state_pub.publish(String(data="RUN"))
        self.mute_at = time.monotonic() + self.rng.uniform(40.0, 80.0)
        self.muted = False
        self.get_logger().info("Safety PLC at 10.10.0.22: RUN, light curtain 24 beams")
        self.create_timer(1.0, self.on_second)
        threading.Thread(target=self.poll, daemon=True, name="plc").start()

    def poll(self) -> None:
        m = Range(radiation_type=Range.INFRARED, field_of_view=0.0, min_range=0.0, max_range=1.2)
        for _ in paced(CURTAIN_HZ, jitter=0.001, rng=self.rng):
            now = time.monotonic()
            muted = self.mute_at <= now < self.mute_at + 3.0
            if now >= self.mute_at + 3.0:
                self.mute_at = now + self.rng.uniform(40.0, 80.0)
            if muted != self.muted:
                self.muted = muted
                self.get_logger().info("Muting active: tote passing" if muted else "Muting ended")
            stamp = time.time()
            if self.fault == "stale":  # the bridge's NTP sync lost: it stamps with the PLC's own clock
                stamp -= 2.0
            m.header.stamp = to_stamp(stamp)
            m.header.frame_id = "muted" if muted else "light_curtain"
            m.range = 0.35 if muted and now - self.mute_at > 0.8 else math.inf
            if not published((self.curtain_pub, m)):
                return

    def on_second(self) -> None:
        self.publish_diagnostics(self.status("safety_plc", "pilz-pnoz-m-b1", OK, "RUN", muted=self.muted))


# --- the cell -----------------------------------------------------------------------------------------


class TaskOrchestrator(CellNode):
    """The cell's behaviour tree, ticked at 10 Hz: WaitForPart -> Detect -> EstimatePose (service, 3 s
    timeout) -> PlanPick (5 s timeout) -> ExecutePick -> Grasp -> RestartBelt -> PlanPlace ->
    ExecutePlace -> Inspect (the inspection station activated) -> Release -> (deactivated) ->
    PlanHome -> ExecuteHome; a missed detection, a failed plan or a missed grasp is retried with a
    WARN; every motion step is guarded by CellSafe (the light curtain, 50 Hz, clear or muted and
    its data younger than 0.5 s). /cell/bt_status latched (the active node); ``~/get_status``
    (Trigger) for the HMI."""

    TIMEOUTS: ClassVar[dict[str, float]] = {"estimate": 3.0, "plan": 5.0, "execute": 20.0, "gripper": 5.0,
                                            "belt": 2.0, "lifecycle": 2.0}

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("task_orchestrator", "cell", fault_dir)
        self.declare_parameter("bt_xml", "/opt/cell/trees/pick_place_inspect.xml")
        self.declare_parameter("tick_rate", 10.0)
        self.status_pub = self.create_publisher(String, "/cell/bt_status", LATCHED)
        self.cycle_pub = self.create_publisher(Float32, "/cell/cycle_time", RELIABLE)
        self.create_subscription(Bool, "/conveyor/parts_present", self.on_present, LATCHED)
        self.create_subscription(PoseArray, "/perception/detections", self.on_det, RELIABLE)
        self.create_subscription(String, "/cell/inspection/result", self.on_inspection, RELIABLE)
        self.create_subscription(Range, "/safety/light_curtain", self.on_curtain, SENSOR)
        self.srv_clients = {
            "estimate": self.create_client(Trigger, "/perception/pose_estimator/estimate"),
            "plan": self.create_client(GetPlan, "/arm/move_group/plan"),
            "belt": self.create_client(SetBool, "/conveyor/plc_bridge/run"),
            "lifecycle": self.create_client(ChangeState, "/cell/inspection_station/change_state"),
        }
        self.actions = {
            "execute": ActionClient(self, Fibonacci, "/arm/move_group/execute_trajectory"),
            "gripper": ActionClient(self, Fibonacci, "/arm/gripper_controller/gripper_cmd"),
        }
        self.create_service(Trigger, "~/get_status", self.on_get_status)
        self.present = False
        self.det = None
        self.det_at = 0.0
        self.inspection = None
        self.curtain_age = None  # s between the newest light curtain sample's stamp and its arrival
        self.curtain_at = None
        self.curtain_clear = True
        self.state = None
        self.pending = None  # (kind, sent, future, stage)
        self.wait_until = 0.0
        self.since = 0.0
        self.tries = 0
        self.pose = None
        self.plan_id = None
        self.cycle = 0
        self.cycle_start = None
        self.passed = self.failed = 0
        self.set_state("Configure")
        self.create_timer(0.1, self.tick)
        self.create_timer(1.0, self.on_second)

    # inputs
    def on_present(self, msg: Bool) -> None:
        self.present = msg.data

    def on_det(self, msg: PoseArray) -> None:
        if any(abs(p.position.x - PICK_X) < 0.05 for p in msg.poses):
            self.det, self.det_at = msg, time.monotonic()

    def on_inspection(self, msg: String) -> None:
        self.inspection = msg.data

    def on_curtain(self, msg: Range) -> None:
        self.curtain_age = time.time() - secs(msg.header.stamp)
        self.curtain_at = time.monotonic()
        self.curtain_clear = math.isinf(msg.range) or msg.header.frame_id == "muted"

    def unsafe(self) -> str | None:
        """The CellSafe condition before each motion: the light curtain clear (or muted) and live."""
        if self.curtain_at is None or time.monotonic() - self.curtain_at > 0.5:
            return "no light curtain data for 0.5 s"
        if self.curtain_age > 0.5:
            return f"light curtain data {self.curtain_age:.1f} s old"
        if not self.curtain_clear:
            return "light curtain interrupted"
        return None

    def on_get_status(self, request, response):
        response.success = True
        response.message = json.dumps({"node": self.state, "cycle": self.cycle, "passed": self.passed,
                                       "failed": self.failed})
        return response

    def set_state(self, state: str) -> None:
        self.state = state
        self.since = time.monotonic()
        self.status_pub.publish(String(data=state))

    # requests
    def call(self, kind: str, request) -> None:
        self.pending = (kind, time.monotonic(), self.srv_clients[kind].call_async(request), "call")

    def goal(self, kind: str, order: int) -> None:
        fut = self.actions[kind].send_goal_async(Fibonacci.Goal(order=order))
        self.pending = (kind, time.monotonic(), fut, "goal")

    def ready(self, kind: str) -> bool:
        c = self.srv_clients.get(kind) or self.actions[kind]
        return c.service_is_ready() if kind in self.srv_clients else c.server_is_ready()

    def poll(self, now: float) -> None:
        kind, sent, fut, stage = self.pending
        if fut.done():
            if stage == "goal":
                gh = fut.result()
                if not gh.accepted:
                    self.pending = None
                    self.done(kind, None)
                else:
                    self.pending = (kind, sent, gh.get_result_async(), "result")
                return
            self.pending = None
            self.done(kind, fut.result())
        elif now - sent > self.TIMEOUTS[kind]:
            self.pending = None
            if stage == "call":
                client = self.srv_clients[kind]
                client.remove_pending_request(fut)
                self.get_logger().error(f"Timed out waiting for {client.srv_name} "
                                        f"({self.TIMEOUTS[kind]:.0f} s) in {self.state}")
            else:
                self.get_logger().error(f"{self.state}: action {self.actions[kind]._action_name} "
                                        f"did not finish in {self.TIMEOUTS[kind]:.0f} s")
            self.retry(f"{kind} timed out", 1.0, warn=False)

    def retry(self, why: str, wait: float, warn: bool = True) -> None:
        self.tries += 1
        if self.tries >= 3:  # the retry decorator's limit: reported, and the tree tries on
            self.get_logger().error(f"{self.state} failed {self.tries} times in a row ({why})")
        elif warn:
            self.get_logger().warn(f"{self.state} failed ({why}): retrying ({self.tries})")
        self.wait_until = time.monotonic() + wait
        back = {"EstimatePose": "Detect", "Grasp": "EstimatePose"}.get(self.state, self.state)
        self.set_state(back)

    def advance(self, state: str) -> None:
        self.tries = 0
        self.set_state(state)

    # the tree
    def tick(self) -> None:
        now = time.monotonic()
        if self.pending is not None:
            self.poll(now)
            return
        if now < self.wait_until:
            return
        s = self.state
        if s.startswith("Execute") or s in ("Grasp", "Release", "RestartBelt"):
            why = self.unsafe()
            if why:
                if self.throttle("unsafe", 5.0):
                    self.get_logger().error(f"CellSafe failed before {s}: {why}; holding")
                return
        if s == "Configure":
            if self.ready("lifecycle"):
                configure = Transition(id=Transition.TRANSITION_CONFIGURE)
                self.call("lifecycle", ChangeState.Request(transition=configure))
        elif s == "WaitForPart":
            if self.present:
                self.cycle += 1
                self.cycle_start = now
                self.get_logger().info(f"Cycle {self.cycle}: part at the pick position")
                self.advance("Detect")
        elif s == "Detect":
            if self.det is not None and self.det_at > self.since:
                if self.rng.random() < 0.05:
                    self.retry("detection score 0.42 below the 0.60 threshold", 0.5)
                else:
                    self.get_logger().info(f"Part detected at the pick position "
                                           f"(score {self.rng.uniform(0.82, 0.97):.2f})")
                    self.set_state("EstimatePose")  # the retries count on until a pose is had
            elif now - self.since > 3.0:
                self.retry("no detection at the pick position for 3 s", 0.5)
        elif s == "EstimatePose" and self.ready("estimate"):
            self.call("estimate", Trigger.Request())
        elif s in ("PlanPick", "PlanPlace", "PlanHome") and self.ready("plan"):
            req = GetPlan.Request()
            x, y, z = {"PlanPick": self.pose, "PlanPlace": PLACE, "PlanHome": fk(HOME_Q)}[s]
            req.goal.header.frame_id = "base_link"
            req.goal.pose.position.x, req.goal.pose.position.y, req.goal.pose.position.z = x, y, z
            req.tolerance = 1.0 if s == "PlanHome" else 0.01
            self.call("plan", req)
        elif s in ("ExecutePick", "ExecutePlace", "ExecuteHome") and self.ready("execute"):
            self.goal("execute", self.plan_id)
        elif s == "Grasp" and self.ready("gripper"):
            self.goal("gripper", 0)
        elif s == "Release" and self.ready("gripper"):
            self.goal("gripper", 85)
        elif s == "RestartBelt" and self.ready("belt"):
            self.call("belt", SetBool.Request(data=True))
        elif s in ("InspectOn", "InspectOff") and self.ready("lifecycle"):
            tid = Transition.TRANSITION_ACTIVATE if s == "InspectOn" else Transition.TRANSITION_DEACTIVATE
            self.inspection = None
            self.call("lifecycle", ChangeState.Request(transition=Transition(id=tid)))
        elif s == "Inspect":
            if self.inspection is not None:
                ok = self.inspection.startswith("PASS")
                self.passed += ok
                self.failed += not ok
                if ok:
                    self.get_logger().info(f"Inspection: {self.inspection}")
                else:
                    self.get_logger().warn(f"Inspection: {self.inspection}: part to the reject chute")
                self.advance("Release")
            elif now - self.since > 4.0:
                self.get_logger().warn("Inspection gave no result in 4 s: releasing the part unchecked")
                self.advance("Release")

    def done(self, kind: str, result) -> None:
        s = self.state
        if s == "Configure":
            if result is not None and result.success:
                self.get_logger().info("Inspection station configured: waiting for parts")
                self.advance("WaitForPart")
            else:
                self.wait_until = time.monotonic() + 2.0
        elif s == "EstimatePose":
            if result.success:
                p = json.loads(result.message)
                self.pose = (p["x"], p["y"], p["z"])
                self.get_logger().info(f"Pick pose ({p['x']:.3f}, {p['y']:.3f}, {p['z']:.3f}) "
                                       f"fitness {p['fitness']}: planning the pick")
                self.advance("PlanPick")
            else:
                self.retry(f"pose estimation: {result.message}", 1.0)
        elif s.startswith("Plan"):
            if result.plan.poses:
                self.plan_id = int(result.plan.header.frame_id.split(":")[1])
                self.advance(s.replace("Plan", "Execute"))
            else:
                self.retry("no motion plan", 0.3)
        elif s.startswith("Execute"):
            if result is not None and result.status == 4:
                nxt = {"ExecutePick": "Grasp", "ExecutePlace": "InspectOn", "ExecuteHome": "WaitForPart"}[s]
                if s == "ExecuteHome":
                    dt = time.monotonic() - (self.cycle_start or time.monotonic())
                    self.cycle_pub.publish(Float32(data=float(dt)))
                    self.get_logger().info(f"Cycle {self.cycle} done in {dt:.1f} s")
                self.advance(nxt)
            else:
                self.get_logger().error(f"{s} failed: the motion was aborted")
                self.retry("execution aborted", 2.0, warn=False)
                self.set_state(s.replace("Execute", "Plan"))
        elif s == "Grasp":
            width = result.result.sequence[0] if result is not None and result.result.sequence else 0
            if width >= 30:
                self.get_logger().info(f"Grasped the part ({width} mm)")
                self.advance("RestartBelt")
            else:
                self.get_logger().warn("Grasp missed: no part between the fingers, reopening and "
                                       "re-estimating its pose")
                self.tries += 1
                self.set_state("Reopen")
                self.goal("gripper", 85)
        elif s == "Reopen":
            self.set_state("EstimatePose")
        elif s == "RestartBelt":
            self.advance("PlanPlace")
        elif s == "InspectOn":
            self.advance("Inspect")
        elif s == "Release":
            self.get_logger().info("Part released in the inspection nest")
            self.advance("InspectOff")
        elif s == "InspectOff":
            self.advance("PlanHome")

    def on_second(self) -> None:
        stuck = time.monotonic() - self.since
        level = OK if stuck < 30.0 or self.state == "WaitForPart" else WARN
        self.publish_diagnostics(self.status("behavior_tree", "cell-bt", level, self.state, cycle=self.cycle,
                                             passed=self.passed, failed=self.failed))


class InspectionStation(Diagnosed, LifecycleNode):
    """The barcode/vision inspection station, a lifecycle node: configured at start-up by the
    orchestrator, activated when a part is placed in its nest, deactivated after. Active, it streams
    /cell/inspection/image (mono 320x240, 10 Hz, sensor QoS) and, after 1 s of frames, the verdict on
    /cell/inspection/result (PASS with the barcode, or FAIL for ~3 % of the parts)."""

    def __init__(self, fault_dir: Path) -> None:
        LifecycleNode.__init__(self, "inspection_station", namespace="cell")
        hook(self, fault_dir)
        self.rng = random.Random()
        self.declare_parameter("camera_ip", "10.10.0.31")
        self.declare_parameter("exposure_us", 1800)
        self.active = False
        self.frames = 0
        self.img_pub = self.res_pub = None
        self.inspected = 0
        self.create_timer(0.1, self.on_frame)
        self.create_timer(1.0, self.on_second)

    def on_configure(self, state) -> TransitionCallbackReturn:
        self.img_pub = self.create_lifecycle_publisher(Image, "/cell/inspection/image", SENSOR)
        self.res_pub = self.create_lifecycle_publisher(String, "/cell/inspection/result", RELIABLE)
        self.get_logger().info("Configured: camera at 10.10.0.31, decoder DataMatrix/Code128")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        self.active, self.frames = True, 0
        self.get_logger().info("Activated: inspecting")
        return super().on_activate(state)

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        self.active = False
        self.get_logger().info("Deactivated")
        return super().on_deactivate(state)

    def on_frame(self) -> None:
        if not self.active:
            return
        img = Image(height=240, width=320, encoding="mono8", step=320)
        img.header.stamp, img.header.frame_id = self.get_clock().now().to_msg(), "inspection_camera"
        img.data = bytes(320 * 240)
        self.img_pub.publish(img)
        self.frames += 1
        if self.frames == 10:
            self.inspected += 1
            if self.rng.random() < 0.03:
                verdict = "FAIL: barcode unreadable"
            else:
                verdict = f"PASS: serial HX3-{self.rng.randrange(10**6):06d}"
            self.res_pub.publish(String(data=verdict))

    def on_second(self) -> None:
        self.publish_diagnostics(self.status("inspection", "cognex-is2800-0031", OK,
                                             "active" if self.active else "idle", inspected=self.inspected))


class DiagnosticAggregator(CellNode):
    """/diagnostics grouped by analyzer into /diagnostics_agg at 1 Hz (STALE after 5 s) and
    /diagnostics_toplevel_state."""

    GROUPS: ClassVar[dict[str, str]] = {
        "controller_manager": "/cell/arm", "gripper_controller": "/cell/arm", "move_group": "/cell/arm",
        "camera_driver": "/cell/perception", "object_detector": "/cell/perception",
        "plc_bridge": "/cell/conveyor", "safety_plc_bridge": "/cell/safety",
        "task_orchestrator": "/cell/task", "inspection_station": "/cell/task",
        "rosbridge_websocket": "/cell/hmi",
    }

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("diagnostic_aggregator", "", fault_dir)
        self.latest: dict[str, tuple[DiagnosticStatus, float]] = {}
        self.create_subscription(DiagnosticArray, "/diagnostics", self.on_diag, QoSProfile(depth=50))
        self.agg_pub = self.create_publisher(DiagnosticArray, "/diagnostics_agg", RELIABLE)
        self.top_pub = self.create_publisher(DiagnosticStatus, "/diagnostics_toplevel_state", RELIABLE)
        self.create_timer(1.0, self.on_second)

    def on_diag(self, msg: DiagnosticArray) -> None:
        for st in msg.status:
            self.latest[st.name] = (st, time.monotonic())

    def on_second(self) -> None:
        now, out, groups = time.monotonic(), [], {}
        for name, (st, t) in sorted(self.latest.items()):
            group = self.GROUPS.get(name.split(":")[0], "/cell/other")
            level = STALE if now - t > 5.0 else st.level
            lv = level[0] if isinstance(level, bytes) else level
            out.append(DiagnosticStatus(level=level, name=f"{group}/{name}", hardware_id=st.hardware_id,
                                        message="Stale" if lv == STALE[0] else st.message, values=st.values))
            groups[group] = max(groups.get(group, 0), lv)
        names = {0: "OK", 1: "Warning", 2: "Error", 3: "Stale"}
        for group, lv in sorted(groups.items()):
            out.insert(0, DiagnosticStatus(level=bytes([lv]), name=group, message=names[lv]))
        arr = DiagnosticArray(status=out)
        arr.header.stamp = self.get_clock().now().to_msg()
        self.agg_pub.publish(arr)
        top = max(groups.values(), default=0)
        self.top_pub.publish(DiagnosticStatus(level=bytes([top]), name="toplevel_state", message=names[top]))


class HandEyeCalibration(CellNode):
    """The once-off hand-eye calibration at boot: loads the stored calibration, checks it against the
    camera's view of the belt's fiducials, publishes base_link -> camera_link on /tf_static (latched)
    and exits 0 after ~5 s (the latched transform goes with it: nodes started later never get it)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("hand_eye_calibration", "cell", fault_dir)
        self.declare_parameter("calibration_file", "/opt/cell/calib/hand_eye_2026-11-02.yaml")
        self.pub = self.create_publisher(TransformStamped, "/tf_static", STATIC_TF)
        self.get_logger().info("Loaded /opt/cell/calib/hand_eye_2026-11-02.yaml")
        self.pub.publish(transform("base_link", "camera_link", (0.4, BELT_Y, 0.75),
                                   self.get_clock().now().to_msg(), math.pi / 2))
        self.t0 = time.monotonic()
        self.create_timer(1.0, self.check)

    def check(self) -> None:
        if time.monotonic() - self.t0 > 4.0 and not STOPPING.is_set():
            self.get_logger().info("Fiducial check: reprojection error 0.41 px (< 1.0): calibration valid")
            STOPPING.set()


# --- recording, dashboard, operator -------------------------------------------------------------------


class BagRecorder(Node):
    """``ros2 bag record`` of the cell's topics (serialized, as it does): it subscribes to each topic of
    its list once a publisher shows up and splits the bag every 60 s."""

    TOPICS: ClassVar[dict[str, tuple[type, QoSProfile]]] = {
        "/joint_states": (JointState, RELIABLE),
        "/arm/joint_trajectory_controller/controller_state": (JointState, SENSOR),
        "/arm/move_group/display_planned_path": (PathMsg, LATCHED),
        "/perception/detections": (PoseArray, RELIABLE),
        "/conveyor/encoder": (JointState, SENSOR),
        "/conveyor/parts_present": (Bool, LATCHED),
        "/safety/state": (String, LATCHED),
        "/safety/light_curtain": (Range, SENSOR),
        "/cell/bt_status": (String, LATCHED),
        "/cell/inspection/result": (String, RELIABLE),
        "/cell/cycle_time": (Float32, RELIABLE),
        "/diagnostics_agg": (DiagnosticArray, RELIABLE),
        "/tf_static": (TransformStamped, STATIC_TF),
        "/rosout": (Log, QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                                    durability=DurabilityPolicy.TRANSIENT_LOCAL)),
    }

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("rosbag2_recorder")
        hook(self, fault_dir)
        stamp = time.strftime("%Y_%m_%d-%H_%M_%S")
        self.dir = fault_dir.parent / f"rosbag2_{stamp}"
        self.dir.mkdir(parents=True, exist_ok=True)
        self.split = 0
        self.file = open(self.dir / f"rosbag2_{stamp}_0.mcap", "wb")
        self.subs = {}
        self.messages = 0
        self.get_logger().info("Listening for topics...")
        self.get_logger().info(f"Recording to '{self.dir}'...")
        self.create_timer(1.0, self.discover)
        self.create_timer(60.0, self.split_bag)

    def on_fault(self, fault: str | None) -> None:
        pass

    def discover(self) -> None:
        have = {name for name, _ in self.get_topic_names_and_types()}
        for topic, (typ, qos) in self.TOPICS.items():
            if topic in have and topic not in self.subs:
                self.subs[topic] = self.create_subscription(
                    typ, topic, lambda data, t=topic: self.write(t, data), qos, raw=True)
                self.get_logger().info(f"Subscribed to topic '{topic}'")

    def write(self, topic: str, data: bytes) -> None:
        self.file.write(f"{topic} {time.time_ns()} {len(data)}\n".encode())
        self.file.write(data)
        self.messages += 1

    def split_bag(self) -> None:
        self.file.close()
        self.split += 1
        old = self.dir / f"{self.dir.name}_{self.split - 2}.mcap"
        if self.split >= 2 and old.exists():
            old.unlink()
        self.file = open(self.dir / f"{self.dir.name}_{self.split}.mcap", "wb")
        self.get_logger().info(f"Split the bag: {self.messages} messages so far, "
                               f"new file '{self.dir.name}_{self.split}.mcap'")


class RosbridgeWebsocket(CellNode):
    """rosbridge_server's websocket for the cell's web dashboard (one browser client): it subscribes to
    the dashboard's topics, throttles them to what the client asked for and queues the JSON for the
    socket, drained 10 times a second; /client_count latched."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("rosbridge_websocket", "", fault_dir)
        self.declare_parameter("port", 9090)
        self.declare_parameter("max_message_size", 10000000)
        self.count_pub = self.create_publisher(Int32, "/client_count", LATCHED)
        self.count_pub.publish(Int32(data=1))
        self.queue: deque = deque()
        self.latest: dict[str, object] = {}
        self.sent_at: dict[str, float] = {}
        self.bytes = 0
        self.subs = {
            "/joint_states": (JointState, RELIABLE, 0.1),
            "/cell/bt_status": (String, LATCHED, 0.0),
            "/cell/cycle_time": (Float32, RELIABLE, 0.0),
            "/cell/inspection/result": (String, RELIABLE, 0.0),
            "/conveyor/speed": (Float32, RELIABLE, 0.5),
            "/conveyor/parts_present": (Bool, LATCHED, 0.0),
            "/conveyor/heartbeat": (Header, RELIABLE, 1.0),
            "/safety/state": (String, LATCHED, 0.0),
            "/perception/detections": (PoseArray, RELIABLE, 0.2),
            "/arm/move_group/display_planned_path": (PathMsg, LATCHED, 0.0),
            "/arm/gripper_controller/state": (JointState, SENSOR, 0.2),
            "/diagnostics_agg": (DiagnosticArray, RELIABLE, 0.0),
            "/diagnostics_toplevel_state": (DiagnosticStatus, RELIABLE, 0.0),
            "/rosout": (Log, QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                                        durability=DurabilityPolicy.TRANSIENT_LOCAL), 0.0),
        }
        for topic, (typ, qos, _) in self.subs.items():
            self.create_subscription(typ, topic, lambda m, t=topic: self.on_msg(t, m), qos)
        self.get_logger().info("Rosbridge WebSocket server started on port 9090")
        self.get_logger().info("Client connected. 1 clients total.")
        self.create_timer(0.1, self.drain)
        self.create_timer(1.0, self.on_second)

    def on_msg(self, topic: str, msg) -> None:
        now = time.monotonic()
        if now - self.sent_at.get(topic, 0.0) < self.subs[topic][2]:
            return  # the client's throttle_rate
        self.sent_at[topic] = now
        self.queue.append((topic, msg))

    def drain(self) -> None:
        while self.queue:
            topic, msg = self.queue.popleft()
            if topic == "/joint_states":
                payload = {"position": [round(v, 4) for v in msg.position]}
            elif hasattr(msg, "data") and not isinstance(msg.data, bytes | list):
                payload = {"data": msg.data}
            else:
                payload = {"type": type(msg).__name__}
            self.bytes += len(json.dumps({"op": "publish", "topic": topic, "msg": payload}))

    def on_second(self) -> None:
        self.publish_diagnostics(self.status("websocket", "rosbridge-9090", OK, "1 client",
                                             bytes_per_s=self.bytes))
        self.bytes = 0


class Rosapi(CellNode):
    """rosapi beside rosbridge: the dashboard's ``/rosapi/topics`` and ``/rosapi/nodes`` (Trigger,
    JSON stand-ins for rosapi's own services), asked every 5 s by the page."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("rosapi", "", fault_dir)
        self.create_service(Trigger, "/rosapi/topics", self.on_topics)
        self.create_service(Trigger, "/rosapi/nodes", self.on_nodes)
        self.topics = self.create_client(Trigger, "/rosapi/topics")
        self.create_timer(5.0, self.poll)

    def on_topics(self, request, response):
        response.success = True
        response.message = json.dumps(sorted(n for n, _ in self.get_topic_names_and_types()))
        return response

    def on_nodes(self, request, response):
        response.success = True
        response.message = json.dumps(sorted(self.get_node_names()))
        return response

    def poll(self) -> None:  # the page's periodic refresh, through rosbridge
        if self.topics.service_is_ready():
            self.topics.call_async(Trigger.Request())


class OperatorHmi(CellNode):
    """The operator's HMI panel (a touch screen beside the cell): watches the BT status, the cycle
    times and the aggregated diagnostics; 5 s after it opens it sets the belt speed (0.15, 0.2 or
    0.25 m/s) through ``/conveyor/plc_bridge/set_parameters``; asks the orchestrator's
    ``get_status`` every 10 s."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("operator_hmi", "cell", fault_dir)
        self.params = self.create_client(SetParameters, "/conveyor/plc_bridge/set_parameters")
        self.status_cli = self.create_client(Trigger, "/cell/task_orchestrator/get_status")
        self.create_subscription(String, "/cell/bt_status", self.on_bt, LATCHED)
        self.create_subscription(Float32, "/cell/cycle_time", self.on_cycle, RELIABLE)
        self.create_subscription(DiagnosticArray, "/diagnostics_agg", self.on_diag, RELIABLE)
        self.speed_at = time.monotonic() + 5.0
        self.status_at = time.monotonic() + 2.0
        self.pending = None
        self.level = 0
        self.bt = None
        self.get_logger().info("HMI opened by the operator")
        self.create_timer(0.2, self.tick)

    def on_bt(self, msg: String) -> None:
        self.bt = msg.data

    def on_cycle(self, msg: Float32) -> None:
        pass

    def on_diag(self, msg: DiagnosticArray) -> None:
        level = max((s.level[0] if isinstance(s.level, bytes) else s.level for s in msg.status), default=0)
        if level >= 2 and self.level < 2:
            self.get_logger().warn("The cell reports an ERROR in its diagnostics")
        self.level = level

    def tick(self) -> None:
        now = time.monotonic()
        if self.speed_at is not None and now >= self.speed_at and self.params.service_is_ready():
            self.speed_at = None
            speed = random.choice((0.15, 0.2, 0.25))
            self.get_logger().info(f"Setting the belt speed to {speed:.2f} m/s")
            self.params.call_async(SetParameters.Request(
                parameters=[Parameter("speed", value=speed).to_parameter_msg()]))
        if self.pending is not None:
            sent, fut = self.pending
            if fut.done():
                self.pending = None
                self.get_logger().info(f"Cell status: {fut.result().message}")
            elif now - sent > 5.0:
                self.status_cli.remove_pending_request(fut)
                self.pending = None
                self.get_logger().warn("No answer to the status request in 5 s")
        elif now >= self.status_at and self.status_cli.service_is_ready():
            self.status_at = now + 10.0
            self.pending = (now, self.status_cli.call_async(Trigger.Request()))


# --- processes ----------------------------------------------------------------------------------------


def controller_manager(d: Path) -> list:
    cm = ControllerManager(d)
    controllers = [JointStateBroadcaster(d), JointTrajectoryController(d), GripperController(d)]
    for c in controllers:
        cm.add(c)
    cm.start()
    return [cm, *controllers]


def move_group(d: Path) -> list:
    mg = MoveGroup(d)
    mg.monitor = PlanningSceneMonitor(d, mg.get_parameter("octomap_resolution").value)
    return [mg, mg.monitor]


PROCESSES = {  # process -> its nodes
    "cell_sim": lambda d: [CellSimulator(d)],
    "calibration": lambda d: [HandEyeCalibration(d)],
    "controller_manager": controller_manager,
    "robot_state_publisher": lambda d: [RobotStatePublisher(d)],
    "move_group": move_group,
    "camera": lambda d: [CameraDriver(d)],
    "perception": lambda d: [ObjectDetector(d), PoseEstimator(d), CloudPreprocessor(d)],
    "conveyor": lambda d: [ConveyorPlcBridge(d)],
    "safety": lambda d: [SafetyPlcBridge(d)],
    "orchestrator": lambda d: [TaskOrchestrator(d)],
    "inspection": lambda d: [InspectionStation(d)],
    "diagnostics": lambda d: [DiagnosticAggregator(d)],
    "recorder": lambda d: [BagRecorder(d)],
    "rosbridge": lambda d: [RosbridgeWebsocket(d), Rosapi(d)],
    "hmi": lambda d: [OperatorHmi(d)],
}
MULTI_THREADED = {  # process -> threads: blocking action callbacks beside the rest
    "move_group": 3,  # planning, execution and the monitors at once
    "controller_manager": 4,  # ros2_control_node's MultiThreadedExecutor: the two controllers' actions
}


def spin_private(ex) -> None:
    """A private node's own executor thread (MoveIt's planning scene monitor)."""
    try:
        while alive():
            ex.spin_once(timeout_sec=0.2)
    except Exception:
        if alive():
            raise


def main(argv: list[str]) -> int:
    process, fault_dir = argv[0], Path(argv[1])
    run_for = float(argv[2]) if len(argv) > 2 else 0.0
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)  # an orderly shutdown of our own
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: STOPPING.set())
    try:
        nodes = PROCESSES[process](fault_dir)
        threading.Thread(target=watch, args=(nodes, fault_dir, process), daemon=True, name="faults").start()
        nodes[0].create_timer(1.0, lambda: apply_faults(nodes))
        if process in MULTI_THREADED:
            ex = MultiThreadedExecutor(num_threads=MULTI_THREADED[process])
        else:
            ex = EventsExecutor()  # the C++ events executor: a fraction of the dispatch CPU of rclpy's own
        for n in nodes:
            if getattr(n, "private_executor", False):
                own = EventsExecutor()
                own.add_node(n)
                threading.Thread(target=spin_private, args=(own,), daemon=True, name="private").start()
            else:
                ex.add_node(n)
        deadline = time.monotonic() + run_for if run_for > 0 else None
        try:
            while alive() and (deadline is None or time.monotonic() < deadline):
                ex.spin_once(timeout_sec=0.2)
        except ExternalShutdownException:
            pass
        if deadline is not None and time.monotonic() >= deadline:
            nodes[0].get_logger().info("Closed by the operator")
        STOPPING.set()
        time.sleep(0.3)  # the driver threads see it and end
        ex.shutdown(timeout_sec=1.0)
        for n in nodes:
            n.destroy_node()
        return 0
    finally:
        if rclpy.ok():
            rclpy.shutdown()


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
