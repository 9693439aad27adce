"""A warehouse mobile manipulator in rclpy: ``python -m bench.manipulator.robot PROCESS FAULT_DIR [RUN_FOR]``.

A wheeled base with a 6-DOF arm, a parallel gripper and a wrist F/T sensor picking totes, its stack
laid out as a production team lays out ros2_control, MoveIt and an Open-RMF-style fleet adapter (see
`bench.manipulator.run` for the whole robot, its healthy dynamics and its faults). Everything under
``/mm`` but ``/tf``, ``/tf_static``, ``/diagnostics*``, ``/rosout`` and the infrastructure nodes
(``/fleet_manager``, ``/diagnostic_aggregator``, ``/rosbag2_recorder``, ``/rosbridge_websocket``).

Stock message types only (no control_msgs, trajectory_msgs, tf2_msgs, moveit_msgs,
controller_manager_msgs nor rmf_fleet_msgs here): ``/tf`` and ``/tf_static`` carry
geometry_msgs/TransformStamped, one transform a message; trajectories (the JTC's
``~/joint_trajectory`` topic and servo's output) and the JTC's controller state are
sensor_msgs/JointState; every action is test_msgs/Fibonacci (``order`` the named arm pose's index,
the plan id, the site's index, 0/1 open/close; the feedback's ``sequence`` the progress, the
result's ``sequence[0]`` the error code); the controller manager's and MoveIt's request/response
services are test_msgs/BasicTypes (``string_value`` the request, ``bool_value`` ok, ``int32_value``
the plan id, ``float64_value`` the planning time); fleet and task states, the planning scene and
the URDF are std_msgs/String (JSON / XML); the bumpers std_msgs/UInt8 (bit mask).

The simulated world (the robot's true pose and arm pose, as Gazebo would hold it) is written by the
controller manager's hardware simulation to ``FAULT_DIR/../sim_world.json`` and read by the camera
driver (which marks the frames that show a tote); nothing else crosses outside ROS.

Faults come from files: ``FAULT_DIR/<namespace>.<node>`` (``mm.mcu.sonar``) holding a word the
target node acts on (``hang``, ``degrade``, ``slow``, ``stale``, ``reliable``, ``errlog``,
``flaky``), read by the process's watcher thread every 0.5 s; ``FAULT_DIR/<process>.cpu`` starts a
thread spinning a core in that process, ``<process>.leak`` one leaking 3 MB/s. Crashes are SIGKILLs
from outside. RUN_FOR > 0 ends the process cleanly (exit 0) after that many seconds.
"""

from __future__ import annotations

import array
import json
import math
import os
import random
import signal
import sys
import threading
import time
import zlib
from collections import deque
from pathlib import Path

import numpy as np
import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import (
    Pose,
    PoseArray,
    PoseStamped,
    PoseWithCovarianceStamped,
    TransformStamped,
    Twist,
    TwistStamped,
    WrenchStamped,
)
from nav_msgs.msg import MapMetaData, OccupancyGrid, Odometry
from nav_msgs.msg import Path as PathMsg
from nav_msgs.srv import GetMap
from rcl_interfaces.msg import SetParametersResult
from rcl_interfaces.srv import SetParameters
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.signals import SignalHandlerOptions
from rclpy.task import Future
from sensor_msgs.msg import (
    BatteryState,
    CameraInfo,
    CompressedImage,
    Image,
    JointState,
    LaserScan,
    PointCloud2,
    PointField,
    Range,
)
from std_msgs.msg import Header, Int8, String, UInt8
from std_srvs.srv import SetBool, Trigger
from test_msgs.action import Fibonacci
from test_msgs.srv import BasicTypes

LEAK_MB_S = 3.0
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
MCU_BEST_EFFORT = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.BEST_EFFORT
)  # rclc best-effort publishers

NS = "/mm"
UPDATE_HZ = 250.0  # controller_manager update_rate
JSB_HZ, ODOM_HZ, FT_HZ, JTC_STATE_HZ = 30.0, 25.0, 50.0, 25.0
SCAN_HZ, CAMERA_HZ, DEPTH_HZ = 10.0, 15.0, 5.0
RSP_HZ = 10.0  # robot_state_publisher publish_frequency
ARM_JOINTS = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "elbow_joint",
    "wrist_1_joint",
    "wrist_2_joint",
    "wrist_3_joint",
)
WHEELS = ("left_wheel_joint", "right_wheel_joint")
FINGER = "gripper_finger_joint"
WHEEL_R, WHEEL_SEP = 0.1, 0.52
# SRDF group states (arm): index -> name, joints
POSES = (
    ("stow", (0.0, -2.2, 2.5, -1.85, -1.57, 0.0)),
    ("look", (0.0, -1.4, 1.5, -1.65, -1.57, 0.0)),
    ("pre_pick", (0.0, -1.0, 1.35, -1.9, -1.57, 0.0)),
    ("pick", (0.0, -0.75, 1.2, -2.0, -1.57, 0.0)),
    ("lift", (0.0, -0.95, 1.2, -1.8, -1.57, 0.0)),
    ("pre_place", (3.14, -1.1, 1.4, -1.85, -1.57, 0.0)),
    ("place", (3.14, -0.8, 1.3, -2.05, -1.57, 0.0)),
)
POSE_INDEX = {name: i for i, (name, _) in enumerate(POSES)}
# warehouse sites, map frame (m): name, x, y, yaw
SITES = (
    ("pack_1", 2.0, 0.0, 0.0),
    ("shelf_A03", 8.0, 3.0, 1.57),
    ("shelf_B07", 12.0, -2.5, -1.57),
    ("shelf_C02", 5.5, 6.5, 1.57),
    ("shelf_D11", 14.5, 4.5, 0.0),
)
SITE_INDEX = {s[0]: i for i, s in enumerate(SITES)}
MAP_FROM_ODOM = (2.0, 0.0, 0.0)  # the simulation's truth: the odom origin (the robot's start) in the map
OPEN_M, TOTE_HANDLE_M = 0.08, 0.046


# --- helpers ------------------------------------------------------------------------------------------


def to_stamp(t: float) -> Time:
    sec = int(t)
    return Time(sec=sec, nanosec=int((t - sec) * 1e9))


def secs(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


def clamp(v: float, lo: float, hi: float) -> float:
    return max(lo, min(hi, v))


def wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def yaw_quat(yaw: float):
    return 0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)


def quat_yaw(q) -> float:
    return 2 * math.atan2(q.z, q.w)


def tf_msg(stamp, parent: str, child: str, x=0.0, y=0.0, z=0.0, yaw=0.0, q=None) -> TransformStamped:
    t = TransformStamped()
    t.header.stamp, t.header.frame_id, t.child_frame_id = stamp, parent, child
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = x, y, z
    qx, qy, qz, qw = q if q is not None else yaw_quat(yaw)
    t.transform.rotation.x, t.transform.rotation.y, t.transform.rotation.z, t.transform.rotation.w = (
        qx,
        qy,
        qz,
        qw,
    )
    return t


def map_to_odom(x: float, y: float, yaw: float, base=MAP_FROM_ODOM):
    """A map-frame pose in the odom frame whose origin is ``base`` in the map."""
    bx, by, byaw = base
    dx, dy = x - bx, y - by
    c, s = math.cos(-byaw), math.sin(-byaw)
    return c * dx - s * dy, s * dx + c * dy, wrap(yaw - byaw)


def odom_to_map(x: float, y: float, yaw: float, base=MAP_FROM_ODOM):
    bx, by, byaw = base
    c, s = math.cos(byaw), math.sin(byaw)
    return bx + c * x - s * y, by + s * x + c * y, wrap(yaw + byaw)


STOPPING = threading.Event()


def alive() -> bool:
    return not STOPPING.is_set() and rclpy.ok()


def published(*sends) -> bool:
    """Publish from a driver thread; False once the process is going down."""
    try:
        for pub, msg in sends:
            pub.publish(msg)
    except Exception:
        if alive():
            raise
        return False
    return True


def paced(hz, jitter: float = 0.0, rng: random.Random | None = None):
    """A driver thread's loop: yields at ``hz`` (a number or a callable) while the process is up."""
    rng = rng or random.Random()
    nxt = time.monotonic()
    while alive():
        rate = hz() if callable(hz) else hz
        nxt += 1.0 / rate + (rng.uniform(-jitter, jitter) if jitter else 0.0)
        delay = nxt - time.monotonic()
        if delay > 0:
            if STOPPING.wait(delay):
                return
        elif delay < -0.5:
            nxt = time.monotonic()
        yield


def burn(seconds: float) -> None:
    """CPU work of ``seconds`` (a planner's sampling, a detector's inference)."""
    end = time.thread_time() + seconds
    a = np.random.rand(64, 64)
    while time.thread_time() < end:
        a = np.tanh(a @ a.T * 1e-3)


def wait_future(fut, timeout: float):
    """Wait (not spinning: the executor runs in another thread) for an rclpy future; None on timeout."""
    ev = threading.Event()
    fut.add_done_callback(lambda _f: ev.set())
    if fut.done() or ev.wait(timeout):
        return fut.result()
    return None


class Ticker:
    """A node's timer that wakes the coroutines (async action callbacks) waiting on it: rclpy's way to
    sleep in a callback without holding the executor's thread."""

    def __init__(self, node: Node, period: float) -> None:
        self.waiting: list[Future] = []
        self.timer = node.create_timer(period, self._tick)
        self.timer.cancel()

    def _tick(self) -> None:
        waiting, self.waiting = self.waiting, []
        for f in waiting:
            f.set_result(True)
        if not self.waiting:
            self.timer.cancel()

    def wait(self) -> Future:
        f = Future()
        self.waiting.append(f)
        if self.timer.is_canceled():
            self.timer.reset()
        return f


def node_key(node: Node) -> str:
    return node.get_fully_qualified_name().strip("/").replace("/", ".")


class Faults:
    """The process's fault files, re-read every 0.5 s; the generic CPU burner and leak."""

    def __init__(self, process: str, fault_dir: Path) -> None:
        self.process, self.dir = process, Path(fault_dir)
        self.words: dict[str, str] = {}
        self.started: set[str] = set()
        self.leaked: list[bytes] = []
        threading.Thread(target=self._watch, daemon=True).start()

    def of(self, node: Node | str) -> str:
        return self.words.get(node if isinstance(node, str) else node_key(node), "")

    def _watch(self) -> None:
        while not STOPPING.wait(0.5):
            words = {}
            try:
                for f in os.listdir(self.dir):
                    try:
                        words[f] = (self.dir / f).read_text().strip()
                    except OSError:
                        pass
            except OSError:
                continue
            self.words = words
            for kind, fn in (("cpu", self._spin), ("leak", self._leak)):
                if f"{self.process}.{kind}" in words and kind not in self.started:
                    self.started.add(kind)
                    threading.Thread(target=fn, daemon=True).start()

    def _spin(self) -> None:
        a = np.random.rand(160, 160)
        while alive():
            a = np.tanh(a @ a * 1e-3)  # BLAS releases the GIL: a core spins, the nodes keep running

    def _leak(self) -> None:
        chunk = int(LEAK_MB_S * 1e6 / 10)
        while not STOPPING.wait(0.1):
            self.leaked.append(b"\x5a" * chunk)


class Diagnostics:
    """diagnostic_updater: the node's statuses (``"<node>: <task>"``, a hardware id), /diagnostics at 1 Hz."""

    def __init__(self, node: Node, hardware_id: str, period: float = 1.0) -> None:
        self.node, self.hw = node, hardware_id
        self.tasks: list[tuple[str, object]] = []
        self.pub = node.create_publisher(DiagnosticArray, "/diagnostics", RELIABLE)
        node.create_timer(period, self._update)

    def add(self, task: str, fn) -> None:
        self.tasks.append((task, fn))

    def _update(self) -> None:
        arr = DiagnosticArray()
        arr.header.stamp = to_stamp(time.time())
        for task, fn in self.tasks:
            level, message, values = fn()
            arr.status.append(
                DiagnosticStatus(
                    level=level,
                    name=f"{self.node.get_name()}: {task}",
                    message=message,
                    hardware_id=self.hw,
                    values=[KeyValue(key=k, value=str(v)) for k, v in values.items()],
                )
            )
        self.pub.publish(arr)


class Rate:
    """A topic frequency status (diagnostic_updater's FrequencyStatus) over the last 5 s."""

    def __init__(self, expected: float, tolerance: float = 0.1) -> None:
        self.expected, self.tol, self.ticks = expected, tolerance, deque(maxlen=500)

    def tick(self) -> None:
        self.ticks.append(time.monotonic())

    def status(self):
        now = time.monotonic()
        n = sum(1 for t in self.ticks if t > now - 5.0)
        hz = n / 5.0
        if n == 0:
            return ERROR, "No events recorded.", {"Actual frequency (Hz)": 0.0}
        level = OK if hz >= self.expected * (1 - self.tol) else WARN
        return (
            level,
            "Desired frequency met" if level == OK else "Frequency too low.",
            {
                "Events in window": n,
                "Actual frequency (Hz)": round(hz, 2),
                "Target frequency (Hz)": self.expected,
            },
        )


class World:
    """The simulation's world file (the robot's true pose, its arm's pose, what the gripper holds)."""

    def __init__(self, fault_dir: Path) -> None:
        self.path = Path(fault_dir).parent / "sim_world.json"
        self.mtime, self.state = 0.0, {}

    def write(self, state: dict) -> None:
        tmp = self.path.with_suffix(".tmp")
        tmp.write_text(json.dumps(state))
        os.replace(tmp, self.path)

    def read(self) -> dict:
        try:
            m = self.path.stat().st_mtime
            if m != self.mtime:
                self.mtime, self.state = m, json.loads(self.path.read_text())
        except (OSError, ValueError):
            pass
        return self.state


def at_site(x: float, y: float, tol: float = 0.6) -> str | None:
    for name, sx, sy, _ in SITES:
        if math.hypot(x - sx, y - sy) < tol:
            return name
    return None


def stdout(line: str) -> None:
    print(line, flush=True)


# --- process scaffolding --------------------------------------------------------------------------------


class Process:
    """One OS process: its rclpy context, nodes, executor, the fault watcher."""

    def __init__(self, name: str, fault_dir: Path, run_for: float) -> None:
        self.name, self.fault_dir, self.run_for = name, Path(fault_dir), run_for
        self.faults = Faults(name, fault_dir)
        self.nodes: list[Node] = []
        self.rng = random.Random(hash((name, os.getpid())))

    def node(self, name: str, namespace: str = NS, **kw) -> Node:
        n = Node(name, namespace=namespace, **kw)
        self.nodes.append(n)
        return n

    def spin(self, executor, spun: list[Node] | None = None) -> int:
        for n in self.nodes if spun is None else spun:
            executor.add_node(n)
        self.executor = executor
        threading.Thread(target=self._spin, args=(executor,), daemon=True).start()
        t_end = time.monotonic() + self.run_for if self.run_for > 0 else None
        while not STOPPING.is_set():
            if t_end is not None and time.monotonic() >= t_end:
                break
            STOPPING.wait(0.2)
        STOPPING.set()
        time.sleep(0.15)
        try:
            executor.shutdown(timeout_sec=1.0)
            for n in self.nodes:
                n.destroy_node()
            rclpy.try_shutdown()
        except Exception:
            pass
        sys.stdout.flush()
        os._exit(0)

    @staticmethod
    def _spin(executor) -> None:
        try:
            executor.spin()
        except Exception as e:  # the context going down
            if alive():
                stdout(f"executor stopped: {e!r}")


def add_node(proc: Process, node: Node) -> None:
    """A node created while the executor spins (a controller loaded at run time)."""
    proc.nodes.append(node)
    proc.executor.add_node(node)
    proc.executor.wake()


# ================================================================================================
# ros2_control: controller_manager and its controllers (process "controller_manager")
# ================================================================================================

URDF = """<?xml version="1.0"?>
<robot name="mm_picker">
  <link name="base_footprint"/><link name="base_link"/><link name="laser"/>
  <link name="left_wheel_link"/><link name="right_wheel_link"/><link name="arm_base_link"/>
  <link name="shoulder_link"/><link name="upper_arm_link"/><link name="forearm_link"/>
  <link name="wrist_1_link"/><link name="wrist_2_link"/><link name="wrist_3_link"/>
  <link name="wrist_ft_link"/><link name="tool0"/><link name="gripper_finger_link"/>
  <link name="camera_link"/><link name="camera_color_optical_frame"/><link name="camera_depth_optical_frame"/>
  <link name="sonar_front"/><link name="sonar_rear"/><link name="imu_link"/>
{}
  <ros2_control name="mm_base" type="system">
    <hardware><plugin>mm_hardware/DiffBaseSystem</plugin><param name="can_interface">can0</param></hardware>
    <joint name="left_wheel_joint"><command_interface name="velocity"/>
      <state_interface name="position"/><state_interface name="velocity"/></joint>
    <joint name="right_wheel_joint"><command_interface name="velocity"/>
      <state_interface name="position"/><state_interface name="velocity"/></joint>
  </ros2_control>
  <ros2_control name="mm_arm" type="system">
    <hardware><plugin>mm_hardware/ArmRtdeSystem</plugin><param name="robot_ip">192.168.56.2</param></hardware>
{}
  </ros2_control>
  <ros2_control name="mm_gripper" type="actuator">
    <hardware><plugin>mm_hardware/ModbusGripper</plugin><param name="port">/dev/ttyGRIPPER</param></hardware>
    <joint name="gripper_finger_joint"><command_interface name="position"/>
      <state_interface name="position"/><state_interface name="effort"/></joint>
  </ros2_control>
  <ros2_control name="wrist_ft" type="sensor">
    <hardware><plugin>mm_hardware/NetFtSensor</plugin><param name="address">192.168.56.3</param></hardware>
    <sensor name="wrist_ft"><state_interface name="force.x"/><state_interface name="force.y"/>
      <state_interface name="force.z"/><state_interface name="torque.x"/>
      <state_interface name="torque.y"/><state_interface name="torque.z"/></sensor>
  </ros2_control>
</robot>
""".format(
    "\n".join(
        f'  <joint name="{j}" type="revolute"><parent link="p"/><child link="c"/>'
        f'<limit lower="-6.28" upper="6.28" effort="150" velocity="3.14"/></joint>'
        for j in ARM_JOINTS
    ),
    "\n".join(
        f'    <joint name="{j}"><command_interface name="position"/><state_interface name="position"/>'
        f'<state_interface name="velocity"/></joint>'
        for j in ARM_JOINTS
    ),
)

CONTROLLER_TYPES = {
    "joint_state_broadcaster": "joint_state_broadcaster/JointStateBroadcaster",
    "diff_drive_controller": "diff_drive_controller/DiffDriveController",
    "arm_controller": "joint_trajectory_controller/JointTrajectoryController",
    "gripper_controller": "parallel_gripper_action_controller/GripperActionController",
    "ft_sensor_broadcaster": "force_torque_sensor_broadcaster/ForceTorqueSensorBroadcaster",
}


class Hardware:
    """The simulated hardware the controller manager reads and writes every cycle."""

    def __init__(self) -> None:
        self.x = self.y = self.yaw = 0.0  # odom (the world's truth in the odom frame)
        self.v = self.w = 0.0
        self.cmd_v = self.cmd_w = 0.0
        self.wheel_pos = [0.0, 0.0]
        self.q = list(POSES[0][1])
        self.dq = [0.0] * 6
        self.finger, self.finger_cmd, self.finger_effort = OPEN_M, OPEN_M, 0.0
        self.holding = False
        self.rng = random.Random(7)

    def step(self, dt: float) -> None:
        acc_v, acc_w = 0.8 * dt, 2.0 * dt
        self.v += clamp(self.cmd_v - self.v, -acc_v, acc_v)
        self.w += clamp(self.cmd_w - self.w, -acc_w, acc_w)
        self.yaw = wrap(self.yaw + self.w * dt)
        self.x += self.v * math.cos(self.yaw) * dt
        self.y += self.v * math.sin(self.yaw) * dt
        vl = (self.v - self.w * WHEEL_SEP / 2) / WHEEL_R
        vr = (self.v + self.w * WHEEL_SEP / 2) / WHEEL_R
        self.wheel_pos[0] += vl * dt
        self.wheel_pos[1] += vr * dt
        # the gripper: 0.1 m/s; closing on a tote's handle stalls at its width
        target = self.finger_cmd
        if self.holding and target < TOTE_HANDLE_M:
            target = TOTE_HANDLE_M
        self.finger += clamp(target - self.finger, -0.1 * dt, 0.1 * dt)
        self.finger_effort = 35.0 if (self.holding and abs(self.finger - TOTE_HANDLE_M) < 1e-3) else 0.0


class Controller:
    """A ros2_control controller: its own node, loaded/configured/activated through the manager."""

    update_hz = UPDATE_HZ

    def __init__(self, cm: ControllerManager, name: str) -> None:
        self.cm, self.name, self.state = cm, name, "unconfigured"
        self.node = Node(name, namespace=NS)
        self.node.declare_parameter("type", CONTROLLER_TYPES[name])
        self.node.declare_parameter("update_rate", int(self.update_hz))
        self.log = self.node.get_logger()
        self.next_t = 0.0

    def configure(self) -> bool:
        self.state = "inactive"
        return True

    def activate(self) -> None:
        self.state = "active"

    def deactivate(self) -> None:
        self.state = "inactive"

    def due(self, now: float) -> bool:
        if now >= self.next_t:
            self.next_t = max(self.next_t + 1.0 / self.update_hz, now - 0.5 / self.update_hz)
            return True
        return False

    def update(self, now: float, hw: Hardware) -> None:
        pass


class JointStateBroadcaster(Controller):
    update_hz = JSB_HZ

    def configure(self) -> bool:
        self.pub = self.node.create_publisher(JointState, f"{NS}/joint_states", RELIABLE)
        self.msg = JointState(name=[*ARM_JOINTS, *WHEELS, FINGER])
        return super().configure()

    def update(self, now: float, hw: Hardware) -> None:
        m = self.msg
        m.header.stamp = to_stamp(now)
        m.position = [*hw.q, *hw.wheel_pos, hw.finger]
        m.velocity = [
            *hw.dq,
            (hw.v - hw.w * WHEEL_SEP / 2) / WHEEL_R,
            (hw.v + hw.w * WHEEL_SEP / 2) / WHEEL_R,
            0.0,
        ]
        m.effort = [0.0] * 8 + [hw.finger_effort]
        published((self.pub, m))


class DiffDriveController(Controller):
    """diff_drive_controller: ~/cmd_vel (TwistStamped) with a 0.5 s timeout, ~/odom and odom -> base_link."""

    def configure(self) -> bool:
        n = self.node
        n.declare_parameter("publish_rate", ODOM_HZ)
        n.declare_parameter("cmd_vel_timeout", 0.5)
        n.declare_parameter("wheel_separation", WHEEL_SEP)
        n.declare_parameter("wheel_radius", WHEEL_R)
        self.cmd, self.cmd_t, self.warned_stamp = (0.0, 0.0), 0.0, False
        n.create_subscription(TwistStamped, "~/cmd_vel", self._cmd, RELIABLE)
        self.odom_pub = n.create_publisher(Odometry, "~/odom", RELIABLE)
        self.tf_pub = n.create_publisher(TransformStamped, "/tf", RELIABLE)
        self.next_pub = 0.0
        return super().configure()

    def _cmd(self, msg: TwistStamped) -> None:
        if msg.header.stamp.sec == 0 and not self.warned_stamp:
            self.warned_stamp = True
            self.log.warning(
                "Received TwistStamped with zero timestamp, setting it to current time, "
                "this message will only be shown once"
            )
        self.cmd, self.cmd_t = (msg.twist.linear.x, msg.twist.angular.z), time.time()

    def update(self, now: float, hw: Hardware) -> None:
        if now - self.cmd_t > 0.5:
            hw.cmd_v = hw.cmd_w = 0.0
        else:
            hw.cmd_v, hw.cmd_w = self.cmd
        if now < self.next_pub:
            return
        self.next_pub = max(self.next_pub + 1.0 / ODOM_HZ, now - 0.02)
        stamp = to_stamp(now)
        o = Odometry()
        o.header.stamp, o.header.frame_id, o.child_frame_id = stamp, "odom", "base_link"
        o.pose.pose.position.x, o.pose.pose.position.y = hw.x, hw.y
        _, _, o.pose.pose.orientation.z, o.pose.pose.orientation.w = yaw_quat(hw.yaw)
        o.twist.twist.linear.x, o.twist.twist.angular.z = hw.v, hw.w
        published(
            (self.odom_pub, o), (self.tf_pub, tf_msg(stamp, "odom", "base_link", hw.x, hw.y, 0.0, hw.yaw))
        )


class ArmController(Controller):
    """joint_trajectory_controller: ~/follow_joint_trajectory (a named pose's index), ~/joint_trajectory
    (streamed points), ~/controller_state at 25 Hz whatever the arm does."""

    update_hz = 100.0

    def configure(self) -> bool:
        n = self.node
        n.declare_parameter("joints", list(ARM_JOINTS))
        n.declare_parameter("state_publish_rate", JTC_STATE_HZ)
        n.declare_parameter("constraints.goal_time", 0.6)
        self.traj = None  # (q0, q1, t0, duration)
        self.done = threading.Event()
        self.result = 0
        self.state_pub = n.create_publisher(JointState, "~/controller_state", RELIABLE)
        self.next_state = 0.0
        self.ticker = Ticker(n, 0.2)
        group = ReentrantCallbackGroup()
        n.create_subscription(JointState, "~/joint_trajectory", self._topic, RELIABLE)
        ActionServer(
            n,
            Fibonacci,
            "~/follow_joint_trajectory",
            self._execute,
            goal_callback=self._goal,
            cancel_callback=lambda _g: CancelResponse.ACCEPT,
            callback_group=group,
        )
        return super().configure()

    def _goal(self, goal) -> GoalResponse:
        if self.state != "active" or not 0 <= goal.order < len(POSES):
            self.log.error(
                "Can't accept new action goals. Controller is not running."
                if self.state != "active"
                else f"Invalid trajectory goal {goal.order}"
            )
            return GoalResponse.REJECT
        self.log.info("Received new action goal")
        return GoalResponse.ACCEPT

    def _topic(self, msg: JointState) -> None:
        if self.state != "active" or len(msg.position) != 6:
            return
        if self.traj is not None and not self.done.is_set() and self.traj[4]:
            self.result = -1
            self.done.set()
            self.log.warning(
                "Canceling active action goal because a new trajectory was received on the topic"
            )
        hw = self.cm.hw
        self.traj = (list(hw.q), list(msg.position), time.time(), 0.08, False)

    async def _execute(self, goal_handle):
        hw = self.cm.hw
        _name, q1 = POSES[goal_handle.request.order]
        q0 = list(hw.q)
        duration = max(abs(a - b) for a, b in zip(q0, q1, strict=False)) / 0.8 + 0.8
        self.done.clear()
        self.result = 0
        t_goal = time.time()
        self.traj = (q0, list(q1), t_goal, duration, True)
        fb = Fibonacci.Feedback()
        while not self.done.is_set():
            await self.ticker.wait()
            if self.done.is_set():
                break
            if goal_handle.is_cancel_requested:
                self.traj = None
                goal_handle.canceled()
                self.log.info("Canceled trajectory")
                return Fibonacci.Result(sequence=[-1])
            if not alive():
                break
            fb.sequence = [int(100 * min(1.0, (time.time() - t_goal) / duration))]
            goal_handle.publish_feedback(fb)
        if self.result == 0:
            goal_handle.succeed()
            self.log.info("Goal reached, success!")
        else:
            goal_handle.abort()
        return Fibonacci.Result(sequence=[self.result])

    def update(self, now: float, hw: Hardware) -> None:
        tr = self.traj
        if tr is not None:
            q0, q1, t0, dur, action = tr
            s = clamp((now - t0) / dur, 0.0, 1.0)
            s5 = s * s * s * (10 - 15 * s + 6 * s * s)  # quintic
            q = [a + (b - a) * s5 for a, b in zip(q0, q1, strict=False)]
            hw.dq = [(b - a) * 30 * s * s * (1 - s) ** 2 / dur for a, b in zip(q0, q1, strict=False)]
            hw.q = q
            if s >= 1.0:
                hw.dq = [0.0] * 6
                self.traj = None
                if action:
                    self.done.set()
        if now >= self.next_state:
            self.next_state = max(self.next_state + 1.0 / JTC_STATE_HZ, now - 0.02)
            m = JointState(name=list(ARM_JOINTS))
            m.header.stamp = to_stamp(now)
            m.position, m.velocity = list(hw.q), list(hw.dq)
            m.effort = [0.0] * 6  # the tracking error
            published((self.state_pub, m))


class GripperController(Controller):
    """parallel_gripper_action_controller: ~/gripper_cmd (0 open, 1 close); stalls on a tote's handle."""

    update_hz = 100.0

    def configure(self) -> bool:
        n = self.node
        n.declare_parameter("joint", FINGER)
        n.declare_parameter("max_effort", 40.0)
        n.declare_parameter("stall_timeout", 0.5)
        self.ticker = Ticker(n, 0.05)
        ActionServer(
            n,
            Fibonacci,
            "~/gripper_cmd",
            self._execute,
            goal_callback=lambda _g: GoalResponse.ACCEPT if self.state == "active" else GoalResponse.REJECT,
            callback_group=ReentrantCallbackGroup(),
        )
        return super().configure()

    async def _execute(self, goal_handle):
        hw, close = self.cm.hw, goal_handle.request.order == 1
        world = self.cm.world_state
        if close and world.get("arm") == "pick" and at_site(*odom_to_map(hw.x, hw.y, hw.yaw)[:2]):
            hw.holding = True
        if not close:
            hw.holding = False
        hw.finger_cmd = 0.0 if close else OPEN_M
        t0 = time.time()
        while alive() and time.time() - t0 < 3.0:
            if close and hw.holding and hw.finger_effort > 0:
                goal_handle.succeed()
                return Fibonacci.Result(sequence=[0, int(hw.finger * 1000)])  # stalled on the object
            if abs(hw.finger - hw.finger_cmd) < 1e-3:
                goal_handle.succeed()
                return Fibonacci.Result(sequence=[0, int(hw.finger * 1000)])
            await self.ticker.wait()
        self.log.error("Gripper action timed out before reaching the goal")
        goal_handle.abort()
        return Fibonacci.Result(sequence=[-1])


class FtSensorBroadcaster(Controller):
    """force_torque_sensor_broadcaster: ~/wrench at 50 Hz from the wrist_ft sensor's state interfaces."""

    update_hz = FT_HZ

    def configure(self) -> bool:
        self.node.declare_parameter("sensor_name", "wrist_ft")
        self.node.declare_parameter("frame_id", "wrist_ft_link")
        self.pub = self.node.create_publisher(WrenchStamped, "~/wrench", SENSOR)
        self.rng = random.Random(11)
        self.next_err = 0.0
        self.last = (0.0, 0.0, -5.9)
        return super().configure()

    def update(self, now: float, hw: Hardware) -> None:
        r = self.rng
        fz = -9.81 * (0.6 + (3.4 if hw.holding else 0.0)) + r.gauss(0, 0.25)
        moving = any(abs(d) > 1e-3 for d in hw.dq)
        fx, fy = r.gauss(0, 0.3 + (1.5 if moving else 0.0)), r.gauss(0, 0.3 + (1.5 if moving else 0.0))
        if self.cm.faults.of(self.node) == "errlog":
            # the sensor's status word reports saturation on Fz: the value is discarded, the last one kept
            fx, fy, fz = self.last
            if now >= self.next_err:
                self.next_err = now + r.uniform(1.0, 2.0)
                self.log.error(
                    "Sensor 'wrist_ft': status word 0x20000000 (gauge saturation on force.z), "
                    "reading discarded; publishing the last valid wrench"
                )
        else:
            self.last = (fx, fy, fz)
        m = WrenchStamped()
        m.header.stamp, m.header.frame_id = to_stamp(now), "wrist_ft_link"
        m.wrench.force.x, m.wrench.force.y, m.wrench.force.z = fx, fy, fz
        m.wrench.torque.x, m.wrench.torque.y, m.wrench.torque.z = (
            r.gauss(0, 0.02),
            r.gauss(0, 0.02),
            r.gauss(0, 0.01),
        )
        published((self.pub, m))


CONTROLLER_CLASSES = {
    "joint_state_broadcaster": JointStateBroadcaster,
    "diff_drive_controller": DiffDriveController,
    "arm_controller": ArmController,
    "gripper_controller": GripperController,
    "ft_sensor_broadcaster": FtSensorBroadcaster,
}


class ControllerManager:
    """/mm/controller_manager: the hardware, the 250 Hz update loop in its own thread, the services."""

    def __init__(self, proc: Process) -> None:
        self.proc, self.faults = proc, proc.faults
        self.node = n = proc.node("controller_manager")
        self.log = n.get_logger()
        n.declare_parameter("update_rate", int(UPDATE_HZ))
        for c, t in CONTROLLER_TYPES.items():
            n.declare_parameter(f"{c}.type", t)
        self.hw = Hardware()
        self.world = World(proc.fault_dir)
        self.world_state: dict = {}
        self.controllers: dict[str, Controller] = {}
        self.lock = threading.Lock()
        self.ready = False
        self.cycles = self.overruns = 0
        self.periods: deque = deque(maxlen=1250)
        self.last_overrun_log = 0.0
        group = MutuallyExclusiveCallbackGroup()
        self.log.warning(
            "Could not enable FIFO RT scheduling policy: with error number <1>(Operation not "
            "permitted). See [https://control.ros.org/jazzy/doc/ros2_control/controller_manager/"
            "doc/userdoc.html] for details on how to enable realtime scheduling."
        )
        self.log.info("Waiting for data on 'robot_description' topic to finish initialization")
        n.create_subscription(String, f"{NS}/robot_description", self._description, LATCHED)
        for srv, fn in (
            ("load_controller", self._load),
            ("configure_controller", self._configure),
            ("switch_controller", self._switch),
            ("unload_controller", self._unload),
        ):
            n.create_service(BasicTypes, f"~/{srv}", fn, callback_group=group)
        n.create_service(Trigger, "~/list_controllers", self._list, callback_group=group)
        n.create_service(Trigger, "~/list_hardware_components", self._list_hw, callback_group=group)
        n.create_service(Trigger, "~/list_hardware_interfaces", self._list_hw, callback_group=group)
        diag = Diagnostics(n, "mm_picker")
        diag.add("Controllers Activity", self._diag_controllers)
        diag.add(
            "Hardware Components Activity",
            lambda: (
                (
                    OK,
                    "All hardware components are active",
                    {h: "active" for h in ("mm_base", "mm_arm", "mm_gripper", "wrist_ft")},
                )
                if self.ready
                else (WARN, "Hardware not initialized", {})
            ),
        )
        diag.add("Controller Manager Activity", self._diag_loop)
        threading.Thread(target=self._world_writer, daemon=True).start()

    def _description(self, msg: String) -> None:
        if self.ready:
            return
        self.log.info("Received robot description from topic.")
        for hw, _kind in (
            ("mm_base", "system"),
            ("mm_arm", "system"),
            ("mm_gripper", "actuator"),
            ("wrist_ft", "sensor"),
        ):
            self.log.info(f"Loading hardware '{hw}' ")
            self.log.info(f"Initialize hardware '{hw}' ")
            self.log.info(f"Successful initialization of hardware '{hw}'")
        self.log.info(
            "Resource Manager has been successfully initialized. Starting Controller Manager services..."
        )
        for hw in ("mm_base", "mm_arm", "mm_gripper", "wrist_ft"):
            self.log.info(f"'configure' hardware '{hw}' ")
            self.log.info(f"Successful 'configure' of hardware '{hw}'")
            self.log.info(f"'activate' hardware '{hw}' ")
            self.log.info(f"Successful 'activate' of hardware '{hw}'")
        self.ready = True
        threading.Thread(target=self._loop, daemon=True, name="cm_update").start()

    # the services (the spawners call them)
    def _load(self, req, res):
        name = req.string_value
        if name in self.controllers:
            res.bool_value, res.string_value = False, f"Controller '{name}' already loaded"
            self.log.error(f"Controller already loaded, skipping load_controller ({name})")
            return res
        if name not in CONTROLLER_CLASSES or not self.ready:
            res.bool_value = False
            self.log.error(f"Loader for controller '{name}' (type '') not found.")
            return res
        self.log.info(f"Loading controller : '{name}' of type '{CONTROLLER_TYPES[name]}'")
        self.log.info(f"Loading controller '{name}'")
        c = CONTROLLER_CLASSES[name](self, name)
        add_node(self.proc, c.node)
        with self.lock:
            self.controllers[name] = c
        res.bool_value = True
        return res

    def _configure(self, req, res):
        c = self.controllers.get(req.string_value)
        if c is None:
            self.log.error(f"Controller '{req.string_value}' is not loaded")
            res.bool_value = False
            return res
        self.log.info(f"Configuring controller: '{c.name}'")
        res.bool_value = c.configure()
        return res

    def _switch(self, req, res):
        spec = json.loads(req.string_value)
        names = spec.get("activate", [])
        self.log.info(f"Activating controllers: [ {' '.join(names)} ]")
        with self.lock:
            for name in names:
                c = self.controllers.get(name)
                if c is None or c.state != "inactive":
                    self.log.error(f"Could not activate controller '{name}': not configured")
                    res.bool_value = False
                    return res
                c.activate()
        res.bool_value = True
        return res

    def _unload(self, req, res):
        res.bool_value = False
        return res

    def _list(self, req, res):
        res.success = True
        res.message = json.dumps(
            [
                {"name": c.name, "type": CONTROLLER_TYPES[c.name], "state": c.state}
                for c in self.controllers.values()
            ]
        )
        return res

    def _list_hw(self, req, res):
        res.success, res.message = (
            True,
            json.dumps(
                {"mm_base": "active", "mm_arm": "active", "mm_gripper": "active", "wrist_ft": "active"}
            ),
        )
        return res

    def _diag_controllers(self):
        states = {c.name: c.state for c in self.controllers.values()}
        if states and all(s == "active" for s in states.values()):
            return OK, "All controllers are active", states
        return WARN, "Not all controllers are active", states

    def _diag_loop(self):
        p = list(self.periods)
        if not p:
            return WARN, "Controller manager update loop not running", {}
        rate = 1.0 / (sum(p) / len(p))
        level = OK if rate > 0.95 * UPDATE_HZ else WARN
        return (
            level,
            "Controller Manager is running" if level == OK else "Controller Manager is below its rate",
            {
                "update_rate": int(UPDATE_HZ),
                "mean_rate": round(rate, 1),
                "cycles": self.cycles,
                "overruns": self.overruns,
                "max_period_ms": round(max(p) * 1000, 2),
            },
        )

    def _world_writer(self) -> None:
        for _ in paced(10.0):
            hw = self.hw
            arm = "moving"
            for name, q in POSES:
                if max(abs(a - b) for a, b in zip(hw.q, q, strict=False)) < 0.02:
                    arm = name
            self.world_state = {
                "x": hw.x,
                "y": hw.y,
                "yaw": hw.yaw,
                "arm": arm,
                "holding": hw.holding,
                "t": time.time(),
            }
            try:
                self.world.write(self.world_state)
            except OSError:
                pass

    def _loop(self) -> None:
        """read() -> update() of every active controller at its rate -> write(), at 250 Hz."""
        period = 1.0 / UPDATE_HZ
        nxt = time.monotonic()
        last = nxt
        while alive():
            t_start = time.monotonic()
            self.periods.append(t_start - last)
            last = t_start
            now = time.time()
            self.hw.step(period)
            with self.lock:
                active = [c for c in self.controllers.values() if c.state == "active"]
            for c in active:
                if c.due(now):
                    c.update(now, self.hw)
            self.cycles += 1
            nxt += period
            delay = nxt - time.monotonic()
            if delay < -3 * period:  # a late wake-up of more than 3 cycles (the machine is busy)
                missed = int(-delay / period)
                self.overruns += 1
                took = (time.monotonic() - t_start) * 1000 + missed * period * 1000
                if time.monotonic() - self.last_overrun_log > 5.0:
                    self.last_overrun_log = time.monotonic()
                    self.log.warning(
                        f"Overrun detected! The controller manager missed its desired rate of "
                        f"{int(UPDATE_HZ)} Hz. The loop took {took:.6f} ms (missed cycles : {missed})."
                    )
                nxt = time.monotonic()
            elif delay > 0:
                time.sleep(delay)


def run_controller_manager(proc: Process) -> int:
    ControllerManager(proc)
    return proc.spin(SingleThreadedExecutor())


def run_spawner(proc: Process, controllers: tuple[str, ...]) -> int:
    """ros2_control's spawner: wait for the manager, load, configure and activate, log, exit 0."""
    n = proc.node(f"spawner_{controllers[0]}")
    log = n.get_logger()
    ex = SingleThreadedExecutor()
    ex.add_node(n)
    clients = {
        s: n.create_client(BasicTypes, f"{NS}/controller_manager/{s}")
        for s in ("load_controller", "configure_controller", "switch_controller")
    }
    lister = n.create_client(Trigger, f"{NS}/controller_manager/list_controllers")
    t0 = time.monotonic()
    while not lister.wait_for_service(timeout_sec=2.0):
        log.info(f"waiting for service {NS}/controller_manager/list_controllers to become available...")
        if time.monotonic() - t0 > 60 or STOPPING.is_set():
            log.error(f"Controller manager not available: {NS}/controller_manager/list_controllers")
            return _exit(proc, 1)
    for cl in clients.values():
        cl.wait_for_service(timeout_sec=10.0)

    def call(srv: str, value: str):
        for _attempt in range(20):
            fut = clients[srv].call_async(BasicTypes.Request(string_value=value))
            ex.spin_until_future_complete(fut, timeout_sec=10.0)
            r = fut.result()
            if r is not None and r.bool_value:
                return True
            time.sleep(0.5)  # the hardware not initialised yet: retry
        return False

    for c in controllers:
        if not call("load_controller", c):
            log.error(f"Failed loading controller {c}")
            return _exit(proc, 1)
        log.info(f"Loaded {c}")
        if not call("configure_controller", c):
            log.error(f"Failed to configure controller {c}")
            return _exit(proc, 1)
    if not call("switch_controller", json.dumps({"activate": list(controllers)})):
        log.error(f"Failed to activate controllers: {', '.join(controllers)}")
        return _exit(proc, 1)
    log.info(f"Configured and activated {', '.join(controllers)}")
    time.sleep(0.5)
    return _exit(proc, 0)


def _exit(proc: Process, code: int) -> int:
    for n in proc.nodes:
        n.destroy_node()
    rclpy.try_shutdown()
    sys.stdout.flush()
    os._exit(code)


# ================================================================================================
# robot_state_publisher
# ================================================================================================

STATIC = (  # parent, child, x, y, z, yaw
    ("base_footprint", "base_link", 0.0, 0.0, 0.12, 0.0),
    ("base_link", "laser", 0.32, 0.0, 0.25, 0.0),
    ("base_link", "imu_link", 0.0, 0.0, 0.1, 0.0),
    ("base_link", "sonar_front", 0.36, 0.0, 0.15, 0.0),
    ("base_link", "sonar_rear", -0.36, 0.0, 0.15, math.pi),
    ("base_link", "arm_base_link", 0.1, 0.0, 0.42, 0.0),
    ("wrist_3_link", "wrist_ft_link", 0.0, 0.0, 0.03, 0.0),
    ("wrist_ft_link", "tool0", 0.0, 0.0, 0.05, 0.0),
    ("tool0", "camera_link", 0.06, 0.0, 0.0, 0.0),
    ("camera_link", "camera_color_optical_frame", 0.0, 0.015, 0.0, -math.pi / 2),
    ("camera_link", "camera_depth_optical_frame", 0.0, 0.0, 0.0, -math.pi / 2),
)
CHAIN = (
    ("arm_base_link", "shoulder_link"),
    ("shoulder_link", "upper_arm_link"),
    ("upper_arm_link", "forearm_link"),
    ("forearm_link", "wrist_1_link"),
    ("wrist_1_link", "wrist_2_link"),
    ("wrist_2_link", "wrist_3_link"),
    ("base_link", "left_wheel_link"),
    ("base_link", "right_wheel_link"),
    ("tool0", "gripper_finger_link"),
)


def run_robot_state_publisher(proc: Process) -> int:
    n = proc.node("robot_state_publisher")
    log = n.get_logger()
    n.declare_parameter("robot_description", URDF)
    n.declare_parameter("publish_frequency", RSP_HZ)
    n.create_publisher(String, "~/robot_description", LATCHED)  # rsp's own name for it, in its namespace
    desc = n.create_publisher(String, f"{NS}/robot_description", LATCHED)
    static = n.create_publisher(TransformStamped, "/tf_static", STATIC_TF)
    tf = n.create_publisher(TransformStamped, "/tf", RELIABLE)
    for _, child in CHAIN:
        log.info(f"got segment {child}")
    for _, child, *_ in STATIC:
        log.info(f"got segment {child}")
    desc.publish(String(data=URDF))
    stamp = to_stamp(time.time())
    for p, c, x, y, z, yaw in STATIC:
        static.publish(tf_msg(stamp, p, c, x, y, z, yaw))
    last = [0.0]

    def joints(msg: JointState) -> None:
        t = time.monotonic()
        if t - last[0] < 1.0 / RSP_HZ - 0.005:
            return
        last[0] = t
        pos = dict(zip(msg.name, msg.position, strict=False))
        for (parent, child), j in zip(CHAIN, (*ARM_JOINTS, *WHEELS, FINGER), strict=False):
            a = pos.get(j, 0.0)
            if j == FINGER:
                tf.publish(tf_msg(msg.header.stamp, parent, child, 0.0, a / 2, 0.08))
            else:
                tf.publish(
                    tf_msg(
                        msg.header.stamp,
                        parent,
                        child,
                        0.0,
                        0.0,
                        0.1,
                        q=(0.0, math.sin(a / 2), 0.0, math.cos(a / 2)),
                    )
                )

    n.create_subscription(JointState, f"{NS}/joint_states", joints, RELIABLE)
    return proc.spin(SingleThreadedExecutor())


# ================================================================================================
# micro-ROS agent: the MCU's nodes (battery, bumpers, sonar) over a serial link
# ================================================================================================


def agent_log(level: str, src: str, fn: str, what: str, detail: str) -> None:
    stdout(f"[{time.time():.6f}] {level:<8} | {src:<22} | {fn:<24} | {what:<22} | {detail}")


def run_micro_ros_agent(proc: Process) -> int:
    """micro_ros_agent serial --dev /dev/ttyMCU -b 921600: the MCU's rclc nodes appear through it."""
    agent_log("info", "TermiosAgentLinux.cpp", "init", "running...", "fd: 3")
    agent_log("info", "Root.cpp", "set_verbose_level", "logger setup", "verbose_level: 4")
    time.sleep(1.2)  # the MCU boots and opens its session
    key = "0x5C1E9A27"
    agent_log("info", "Root.cpp", "create_client", "create", f"client_key: {key}, session_id: 0x81")
    agent_log(
        "info",
        "SessionManager.hpp",
        "establish_session",
        "session established",
        f"client_key: {key}, address: 0",
    )
    battery, bumpers, sonar = (
        proc.node("battery", NS + "/mcu"),
        proc.node("bumpers", NS + "/mcu"),
        proc.node("sonar", NS + "/mcu"),
    )
    for i, _nd in enumerate((battery, bumpers, sonar)):
        agent_log(
            "info",
            "ProxyClient.cpp",
            "create_participant",
            "participant created",
            f"client_key: {key}, participant_id: 0x000({i + 1})",
        )
    p_batt = battery.create_publisher(BatteryState, "~/state", RELIABLE)
    p_bump = bumpers.create_publisher(UInt8, f"{NS}/mcu/bumpers", MCU_BEST_EFFORT)
    p_front = sonar.create_publisher(Range, "~/front", MCU_BEST_EFFORT)
    p_rear = sonar.create_publisher(Range, "~/rear", MCU_BEST_EFFORT)
    for i, _t in enumerate(
        ("mm/mcu/battery/state", "mm/mcu/bumpers", "mm/mcu/sonar/front", "mm/mcu/sonar/rear")
    ):
        agent_log(
            "info",
            "ProxyClient.cpp",
            "create_topic",
            "topic created",
            f"client_key: {key}, topic_id: 0x00{i}(2), participant_id: 0x000(1)",
        )
        agent_log(
            "info",
            "ProxyClient.cpp",
            "create_publisher",
            "publisher created",
            f"client_key: {key}, publisher_id: 0x00{i}(3), participant_id: 0x000(1)",
        )
        agent_log(
            "info",
            "ProxyClient.cpp",
            "create_datawriter",
            "datawriter created",
            f"client_key: {key}, datawriter_id: 0x00{i}(5), publisher_id: 0x00{i}(3)",
        )
    serial: deque = deque()  # frames on the wire: (publisher, message)
    link = {"down_until": 0.0}
    faults, rng = proc.faults, proc.rng

    def mcu() -> None:
        """The MCU's rclc executor: one thread, timers for the three nodes (a 20 Hz tick)."""
        soc, tick = 0.87, 0
        person_until, next_person = 0.0, time.time() + rng.uniform(60, 180)
        flaky_next, flaky_until = 0.0, 0.0
        for _ in paced(20.0):
            tick += 1
            now = time.time()
            stamp = to_stamp(now - 0.002)  # rmw_uros_epoch_synchronized time
            if tick % 2 == 0:  # sonar timer, 10 Hz
                while faults.of("mm.mcu.sonar") == "hang" and alive():
                    time.sleep(0.1)  # pulseIn() on the echo pin without a timeout: the executor never returns
                if now > next_person:
                    person_until, next_person = now + rng.uniform(0.8, 2.0), now + rng.uniform(90, 240)
                for pub, frame, base in ((p_front, "sonar_front", 2.4), (p_rear, "sonar_rear", 3.1)):
                    r = Range(
                        radiation_type=Range.ULTRASOUND, field_of_view=0.52, min_range=0.03, max_range=4.0
                    )
                    r.header.stamp, r.header.frame_id = stamp, frame
                    r.range = (
                        0.22 if (frame == "sonar_front" and now < person_until) else base + rng.gauss(0, 0.03)
                    )
                    serial.append((pub, r))
            # bumpers timer, 20 Hz
            if faults.of("mm.mcu.bumpers") == "flaky" and now > flaky_next:
                flaky_until, flaky_next = now + rng.uniform(1.0, 3.0), now + rng.uniform(5.0, 12.0)
            if now >= flaky_until:  # else the I/O expander NAKs on I2C: the callback returns without a frame
                serial.append((p_bump, UInt8(data=0)))
            if tick % 20 == 0:  # battery timer, 1 Hz
                soc = max(0.2, soc - 0.00004)
                b = BatteryState(
                    voltage=46.2 + 4.0 * soc + rng.gauss(0, 0.02),
                    current=-6.5 + rng.gauss(0, 0.4),
                    percentage=soc,
                    power_supply_status=BatteryState.POWER_SUPPLY_STATUS_DISCHARGING,
                    power_supply_technology=BatteryState.POWER_SUPPLY_TECHNOLOGY_LIFE,
                    present=True,
                )
                b.header.stamp, b.header.frame_id = stamp, "battery"
                b.temperature = 31.0 + rng.gauss(0, 0.1)
                serial.append((p_batt, b))

    def agent() -> None:
        """The agent's serial reader: frames -> DDS writes; now and then a framing error (a short gap)."""
        next_hiccup = time.time() + rng.uniform(40, 120)
        for _ in paced(50.0):
            now = time.time()
            if now > next_hiccup:
                next_hiccup = now + rng.uniform(40, 120)
                link["down_until"] = now + rng.uniform(0.1, 0.4)
                agent_log(
                    "error",
                    "SerialAgentLinux.cpp",
                    "recv_message",
                    "serial framing error",
                    f"client_key: {key}, bytes discarded: {rng.randint(12, 180)}",
                )
            if now < link["down_until"]:
                serial.clear()
                continue
            while serial:
                pub, msg = serial.popleft()
                if not published((pub, msg)):
                    return

    threading.Thread(target=mcu, daemon=True, name="mcu").start()
    threading.Thread(target=agent, daemon=True, name="serial").start()
    return proc.spin(SingleThreadedExecutor())


# ================================================================================================
# lidar driver
# ================================================================================================


def run_lidar(proc: Process) -> int:
    n = proc.node("lidar_driver", NS + "/lidar")
    log = n.get_logger()
    for k, v in (("frame_id", "laser"), ("hostname", "192.168.56.10"), ("port", 2112), ("range_max", 25.0)):
        n.declare_parameter(k, v)
    pub = n.create_publisher(LaserScan, f"{NS}/scan", SENSOR)
    rate = Rate(SCAN_HZ)
    diag = Diagnostics(n, "LMS1xx-1917")
    diag.add(f"{NS}/scan topic status", rate.status)
    log.info("Connecting to laser at 192.168.56.10:2112")
    log.info("Connected to laser. Setting scan config: 720 points, 270 deg, 10 Hz")
    beams = 720
    base = (
        3.0
        + 2.0 * np.abs(np.sin(np.linspace(0, 6 * math.pi, beams)))
        + 0.8 * np.cos(np.linspace(0, 3, beams))
    )
    rng, nprng = proc.rng, np.random.default_rng(3)

    def loop() -> None:
        next_bad = time.time() + rng.uniform(60, 150)
        k = 0
        for _ in paced(lambda: 4.0 if proc.faults.of(n) == "degrade" else SCAN_HZ):
            now = time.time()
            if now > next_bad:
                next_bad = now + rng.uniform(60, 150)
                log.warning(
                    f"Received incomplete scan packet ({rng.randint(900, 1400)} of 1472 bytes): frame skipped"
                )
                continue
            stale = proc.faults.of(n) == "stale"
            m = LaserScan(
                angle_min=-2.356,
                angle_max=2.356,
                angle_increment=4.712 / beams,
                time_increment=1.0 / 7200,
                scan_time=0.1,
                range_min=0.05,
                range_max=25.0,
            )
            # stamped at the scan's first beam by the PTP-synchronised clock; "stale": its free-running one
            m.header.stamp, m.header.frame_id = to_stamp(now - 0.1 - (2.5 if stale else 0.0)), "laser"
            k += 1
            r = (base + nprng.normal(0, 0.02, beams) + 0.3 * math.sin(k * 0.01)).astype(np.float32)
            m.ranges = array.array("f", r.tobytes())
            m.intensities = array.array("f")
            if not published((pub, m)):
                return
            rate.tick()

    threading.Thread(target=loop, daemon=True).start()
    return proc.spin(SingleThreadedExecutor())


# ================================================================================================
# perception container: camera driver, compressed republisher, tote detector
# ================================================================================================

IMG_W, IMG_H = 424, 240
CLOUD_W, CLOUD_H = 80, 60


def run_perception(proc: Process) -> int:
    """component_container: the camera driver, image_transport's republisher and the tote detector."""
    cam = proc.node("camera_driver", NS + "/camera")
    rep = proc.node("compressed_republisher", NS + "/camera")
    det = proc.node("tote_detector")
    world = World(proc.fault_dir)
    faults, rng = proc.faults, proc.rng

    # --- the camera driver (RealSense D405-like on the wrist)
    clog = cam.get_logger()
    for k, v in (
        ("serial_no", "_218622271489"),
        ("rgb_camera.color_profile", f"{IMG_W},{IMG_H},15"),
        ("depth_module.depth_profile", f"{CLOUD_W * 4},{CLOUD_H * 4},5"),
        ("enable_sync", True),
    ):
        cam.declare_parameter(k, v)
    p_img = cam.create_publisher(Image, f"{NS}/camera/color/image_raw", SENSOR)
    p_info = cam.create_publisher(CameraInfo, f"{NS}/camera/color/camera_info", SENSOR)
    p_cloud = cam.create_publisher(PointCloud2, f"{NS}/camera/depth/color/points", SENSOR)
    img_rate, cloud_rate = Rate(CAMERA_HZ), Rate(DEPTH_HZ)
    diag = Diagnostics(cam, "D405 _218622271489")
    diag.add(f"{NS}/camera/color/image_raw topic status", img_rate.status)
    diag.add(f"{NS}/camera/depth/color/points topic status", cloud_rate.status)
    clog.info("RealSense ROS v4.55.1")
    clog.info("Built with LibRealSense v2.55.1")
    clog.info("Device with serial number 218622271489 was found.")
    clog.info("Device USB type: 3.2")
    clog.warning("Hardware Notification:Right MIPI error,1.71234e+12,Error,Hardware Error")
    clog.info("RealSense Node Is Up!")
    pixels = np.random.default_rng(5).integers(0, 255, IMG_W * IMG_H * 3, dtype=np.uint8).tobytes()
    info = CameraInfo(
        width=IMG_W,
        height=IMG_H,
        distortion_model="plumb_bob",
        d=[0.0] * 5,
        k=[310.0, 0.0, 212.0, 0.0, 310.0, 120.0, 0.0, 0.0, 1.0],
        r=[1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p=[310.0, 0.0, 212.0, 0.0, 0.0, 310.0, 120.0, 0.0, 0.0, 0.0, 1.0, 0.0],
    )
    fields = [
        PointField(name=c, offset=4 * i, datatype=PointField.FLOAT32, count=1) for i, c in enumerate("xyz")
    ]
    fields.append(PointField(name="rgb", offset=12, datatype=PointField.FLOAT32, count=1))
    cloud_bytes = np.random.default_rng(6).random(CLOUD_W * CLOUD_H * 4, dtype=np.float32).tobytes()

    img = Image(height=IMG_H, width=IMG_W, encoding="rgb8", is_bigendian=0, step=IMG_W * 3)
    img.header.frame_id = "camera_color_optical_frame"
    img.data = array.array("B", pixels)
    frame = img.data  # the driver's frame buffer, reused

    def camera() -> None:
        k = 0
        for _ in paced(lambda: 5.0 if faults.of(cam) == "degrade" else CAMERA_HZ, jitter=0.002, rng=rng):
            k += 1
            now = time.time()
            stamp = to_stamp(now - 0.035)  # the frame's exposure (global time domain)
            w = world.read()
            mx, my, _ = odom_to_map(w.get("x", 0.0), w.get("y", 0.0), w.get("yaw", 0.0))
            site = at_site(mx, my)
            tote = (
                site is not None
                and site.startswith("shelf")
                and w.get("arm") == "look"
                and not w.get("holding")
            )
            img.header.stamp = stamp
            frame[:24] = array.array("B", f"TOTE:{site}".encode().ljust(24, b" ") if tote else bytes(24))
            info.header = img.header
            sends = [(p_img, img), (p_info, info)]
            if k % 3 == 0:
                c = PointCloud2(
                    height=CLOUD_H,
                    width=CLOUD_W,
                    fields=fields,
                    is_bigendian=False,
                    point_step=16,
                    row_step=16 * CLOUD_W,
                    is_dense=False,
                )
                c.header.stamp, c.header.frame_id = stamp, "camera_depth_optical_frame"
                c.data = array.array("B", cloud_bytes)
                sends.append((p_cloud, c))
                cloud_rate.tick()
            if not published(*sends):
                return
            img_rate.tick()

    # --- image_transport republisher: raw -> compressed, only while someone subscribes (lazy)
    p_comp = rep.create_publisher(CompressedImage, f"{NS}/camera/color/image_raw/compressed", SENSOR)
    rep.declare_parameter("in_transport", "raw")
    rep.declare_parameter("out_transport", "compressed")
    rep.declare_parameter("jpeg_quality", 80)

    def republish(msg: Image) -> None:
        if p_comp.get_subscription_count() == 0:
            return
        out = CompressedImage(format="rgb8; jpeg compressed bgr8")
        out.header = msg.header
        out.data = array.array("B", zlib.compress(bytes(msg.data[: IMG_W * IMG_H // 2]), 1))
        p_comp.publish(out)

    lazy = {"sub": None}

    def connect() -> None:
        """image_transport's lazy subscription: raw is taken only while compressed has a subscriber."""
        wanted = p_comp.get_subscription_count() > 0
        if wanted and lazy["sub"] is None:
            lazy["sub"] = rep.create_subscription(Image, f"{NS}/camera/color/image_raw", republish, SENSOR)
        elif not wanted and lazy["sub"] is not None:
            rep.destroy_subscription(lazy["sub"])
            lazy["sub"] = None

    rep.create_timer(1.0, connect)

    # --- the tote detector (barcode + pose), every other frame
    dlog = det.get_logger()
    det.declare_parameter("model", "tote_yolo_v8n_int8.onnx")
    det.declare_parameter("frame_skip", 1)
    det.declare_parameter("max_image_age", 0.5)
    p_det = det.create_publisher(PoseArray, "~/detections", RELIABLE)
    dstate = {
        "k": 0,
        "sub": None,
        "qos": None,
        "processed": Rate(CAMERA_HZ / 2, 0.2),
        "seen": 0.0,
        "glare_until": 0.0,
    }
    ddiag = Diagnostics(det, "tote_detector")
    ddiag.add(
        "Detector",
        lambda: (
            (
                dstate["processed"].status()[0],
                "inference running",
                {"model": "tote_yolo_v8n_int8.onnx", **dstate["processed"].status()[2]},
            )
            if dstate["enabled"]
            else (OK, "idle (disabled)", {"model": "tote_yolo_v8n_int8.onnx"})
        ),
    )

    def image(msg: Image) -> None:
        dstate["k"] += 1
        if dstate["k"] % 2:
            return
        age = time.time() - secs(msg.header.stamp)
        if age > 0.5:
            dlog.warning(f"Dropping image: {age:.2f} s old (max_image_age 0.5 s)", throttle_duration_sec=5.0)
            return
        burn(0.002)
        dstate["processed"].tick()
        marker = bytes(msg.data[:24])
        if not marker.startswith(b"TOTE:"):
            return
        now = time.time()
        if now - dstate["seen"] > 3.0 and rng.random() < 0.1:  # a fresh look: glare on the label now and then
            dstate["glare_until"] = now + rng.uniform(0.5, 1.2)
            dlog.warning("Barcode unreadable on tote candidate (glare): retrying")
        dstate["seen"] = now
        if now < dstate["glare_until"]:
            return
        out = PoseArray()
        out.header = msg.header
        p = Pose()
        p.position.x, p.position.y, p.position.z = (
            0.02 + rng.gauss(0, 0.003),
            -0.01 + rng.gauss(0, 0.003),
            0.38,
        )
        p.orientation.w = 1.0
        out.poses = [p]
        p_det.publish(out)

    def qos_watch() -> None:
        """The camera subscription exists while the detector is enabled (the fleet adapter enables it at a
        shelf): created with the QoS of the detector's parameter file."""
        want = ("reliable" if faults.of(det) == "reliable" else "best_effort") if dstate["enabled"] else None
        if want != dstate["qos"]:
            if dstate["sub"] is not None:
                det.destroy_subscription(dstate["sub"])
                dstate["sub"] = None
            if want is not None:
                qos = RELIABLE if want == "reliable" else SENSOR
                dstate["sub"] = det.create_subscription(Image, f"{NS}/camera/color/image_raw", image, qos)
            dstate["qos"] = want

    def enable(req, res):
        dstate["enabled"] = req.data
        qos_watch()
        dlog.info("Detector enabled" if req.data else "Detector disabled")
        res.success = True
        return res

    dstate["enabled"], dstate["qos"] = False, None
    det.create_service(SetBool, "~/enable", enable)
    det.create_subscription(CameraInfo, f"{NS}/camera/color/camera_info", lambda _m: None, SENSOR)
    det.create_timer(0.5, qos_watch)
    dlog.info("Loaded model tote_yolo_v8n_int8.onnx (CPU, 1 thread)")
    threading.Thread(target=camera, daemon=True).start()
    return proc.spin(SingleThreadedExecutor())


# ================================================================================================
# MoveIt: move_group (planning, execution, planning-scene monitor) and servo
# ================================================================================================


class MoveGroup:
    def __init__(self, proc: Process) -> None:
        self.proc = proc
        self.node = n = proc.node("move_group")
        self.log = n.get_logger()
        self.rng = proc.rng
        for k, v in (
            ("planning_pipelines.pipeline_names", ["ompl", "pilz_industrial_motion_planner"]),
            ("ompl.planning_plugins", ["ompl_interface/OMPLPlanner"]),
            ("ompl.longest_valid_segment_fraction", 0.005),
            ("planning_scene_monitor_options.joint_state_topic", f"{NS}/joint_states"),
            ("octomap_resolution", 0.025),
            ("default_planning_pipeline", "ompl"),
        ):
            n.declare_parameter(k, v)
        self.q: list[float] = list(POSES[0][1])
        self.q_t = 0.0
        self.cloud_t = 0.0
        self.plans: dict[int, str] = {}
        self.next_id = 1
        self.scene_dirty = False
        group = ReentrantCallbackGroup()
        n.create_subscription(JointState, f"{NS}/joint_states", self._joints, RELIABLE)
        n.create_subscription(PointCloud2, f"{NS}/camera/depth/color/points", self._cloud, SENSOR)
        self.scene_pub = n.create_publisher(String, "~/monitored_planning_scene", RELIABLE)
        self.path_pub = n.create_publisher(JointState, f"{NS}/display_planned_path", RELIABLE)
        n.create_service(BasicTypes, f"{NS}/plan_kinematic_path", self._plan, callback_group=group)
        n.create_service(BasicTypes, f"{NS}/compute_cartesian_path", self._cartesian, callback_group=group)
        ActionServer(
            n,
            Fibonacci,
            f"{NS}/execute_trajectory",
            self._execute,
            callback_group=group,
            cancel_callback=lambda _g: CancelResponse.ACCEPT,
        )
        self.jtc = ActionClient(
            n, Fibonacci, f"{NS}/arm_controller/follow_joint_trajectory", callback_group=group
        )
        n.create_timer(1.0, self._publish_scene)
        self.log.info("Loading robot model 'mm_picker'...")
        self.log.info("Publishing maintained planning scene on 'monitored_planning_scene'")
        self.log.info("Starting planning scene monitor")
        self.log.info(f"Listening to '{NS}/joint_states' for joint states")
        self.log.info("Stopping existing world geometry and octomap monitor")
        self.log.info(
            f"Listening to '{NS}/camera/depth/color/points' using message filter with target frame 'odom '"
        )
        self.log.info("Using planning interface 'OMPL'")
        self.log.info("MoveGroup context using pipeline 'ompl'")
        self.log.info("You can start planning now!")

    def _joints(self, msg: JointState) -> None:
        self.q, self.q_t = list(msg.position[:6]), time.time()

    def _cloud(self, msg: PointCloud2) -> None:
        age = time.time() - secs(msg.header.stamp)
        if age > 1.0:
            self.log.warning(
                f"Transform error: Lookup would require extrapolation into the past.  Requested time "
                f"{secs(msg.header.stamp):.6f} but the earliest data is at time "
                f"{time.time() - 1.0:.6f}, when looking up transform from frame "
                "[camera_depth_optical_frame] to frame [odom]",
                throttle_duration_sec=5.0,
            )
            return
        burn(0.003)  # the octomap update
        self.cloud_t = time.time()
        self.scene_dirty = True

    def _publish_scene(self) -> None:
        if self.scene_dirty:
            self.scene_dirty = False
            self.scene_pub.publish(
                String(data=json.dumps({"name": "(noname)+", "is_diff": True, "octomap_stamp": self.cloud_t}))
            )

    def _state_ok(self) -> bool:
        age = time.time() - self.q_t
        if age > 1.0:
            self.log.warning(
                f"Didn't receive robot state (joint angles) with recent timestamp within 1.000000 "
                f"seconds. Requested time {time.time():.6f}, but latest received state has time "
                f"{self.q_t:.6f}."
            )
            return False
        return True

    def _plan(self, req, res):
        _kind, _, target = req.string_value.partition(":")
        self.log.info("Planning request received for MoveGroup action. Forwarding to planning pipeline.")
        t0 = time.time()
        if target not in POSE_INDEX or not self._state_ok():
            res.bool_value, res.string_value = (
                False,
                "INVALID_GOAL_CONSTRAINTS" if target not in POSE_INDEX else "FAILURE: no current robot state",
            )
            self.log.error(f"Unable to solve the planning problem ({res.string_value})")
            return res
        work = self.rng.uniform(0.2, 1.0) if self.rng.random() < 0.85 else self.rng.uniform(1.0, 1.5)
        if self.proc.faults.of(self.node) == "slow":
            work += self.rng.uniform(
                6.0, 9.0
            )  # longest_valid_segment_fraction 5e-5: 100x the collision checks
        burn(work)
        dt = time.time() - t0
        self.log.info(
            f"Planner 'RRTConnect' found solution of {self.rng.randint(9, 30)} states; "
            f"simplified in {self.rng.uniform(0.01, 0.05):.3f} s"
        )
        self.log.info(f"Motion plan was computed successfully. Solution found in {dt:.6f} seconds")
        if dt > 5.0:
            self.log.warning(f"Planning took {dt:.2f} s (allowed_planning_time 5.0 s)")
        res.bool_value, res.float64_value = True, dt
        res.int32_value, res.string_value = self._store(target), "SUCCESS"
        return res

    def _cartesian(self, req, res):
        target = req.string_value.partition(":")[2]
        if target not in POSE_INDEX or not self._state_ok():
            res.bool_value = False
            return res
        burn(0.03)
        res.bool_value, res.float64_value = True, 1.0  # fraction achieved
        res.int32_value = self._store(target)
        self.log.info("Computed Cartesian path with 11 points (followed 100.000000% of requested trajectory)")
        return res

    def _store(self, target: str) -> int:
        pid = self.next_id
        self.next_id += 1
        self.plans[pid] = target
        m = JointState(name=list(ARM_JOINTS), position=list(POSES[POSE_INDEX[target]][1]))
        m.header.stamp = to_stamp(time.time())
        self.path_pub.publish(m)
        return pid

    async def _execute(self, goal_handle):
        target = self.plans.pop(goal_handle.request.order, None)
        self.log.info("Execution request received")
        if target is None:
            goal_handle.abort()
            return Fibonacci.Result(sequence=[-2])
        if not self.jtc.server_is_ready():
            self.log.error(
                f"Action client not connected to action server: {NS}/arm_controller/follow_joint_trajectory"
            )
            goal_handle.abort()
            return Fibonacci.Result(sequence=[-4])
        h = await self.jtc.send_goal_async(Fibonacci.Goal(order=POSE_INDEX[target]))
        if h is None or not h.accepted:
            self.log.error("Goal was rejected by the controller")
            goal_handle.abort()
            return Fibonacci.Result(sequence=[-4])
        r = await h.get_result_async()
        if r is None or r.status != 4:
            self.log.error(
                f"Controller '{NS}/arm_controller' failed with error code: "
                f"{'TIMED_OUT' if r is None else 'ABORTED'}"
            )
            self.log.error("Completed trajectory execution with status ABORTED ...")
            goal_handle.abort()
            return Fibonacci.Result(sequence=[-4])
        self.log.info(f"Controller '{NS}/arm_controller' successfully finished")
        self.log.info("Completed trajectory execution with status SUCCEEDED ...")
        goal_handle.succeed()
        return Fibonacci.Result(sequence=[1])


def servo(proc: Process, mg: MoveGroup) -> None:
    """MoveIt Servo, composed with move_group: it shares move_group's planning scene monitor (no joint
    state subscription of its own); paused until asked; while unpaused, 25 Hz joint commands."""
    n = proc.node("servo_node")
    log = n.get_logger()
    n.declare_parameter("moveit_servo.publish_period", 0.04)
    n.declare_parameter("moveit_servo.command_out_topic", f"{NS}/arm_controller/joint_trajectory")
    st = {"paused": True, "q": list(POSES[0][1]), "twist": (0.0, 0.0, 0.0), "twist_t": 0.0, "k": 0}
    out = n.create_publisher(JointState, f"{NS}/arm_controller/joint_trajectory", RELIABLE)
    status = n.create_publisher(Int8, "~/status", RELIABLE)

    def twist(msg: TwistStamped) -> None:
        st["twist"], st["twist_t"] = (
            (msg.twist.angular.z, msg.twist.linear.z, msg.twist.linear.x),
            time.time(),
        )

    def pause(req, res):
        if st["paused"] and not req.data:
            st["q"] = list(mg.q)
            timer.reset()
        elif req.data:
            timer.cancel()
        st["paused"] = req.data
        res.success, res.message = True, ""
        log.info("Servo is paused" if req.data else "Servo is unpaused")
        return res

    def tick() -> None:
        if st["paused"]:
            return
        st["k"] += 1
        fresh = time.time() - st["twist_t"] < 0.2
        wz, vz, vx = st["twist"] if fresh else (0.0, 0.0, 0.0)
        q = st["q"]
        q[0] += wz * 0.04
        q[1] += vz * 0.04
        q[2] -= vz * 0.04
        q[3] += vx * 0.04
        m = JointState(name=list(ARM_JOINTS), position=list(q))
        m.header.stamp = to_stamp(time.time())
        out.publish(m)
        if st["k"] % 4 == 0:
            status.publish(Int8(data=0 if fresh else 5))  # NO_WARNING / idle (no command)
            if fresh and proc.rng.random() < 0.01:
                log.warning("Close to a singularity, decelerating", throttle_duration_sec=5.0)

    n.create_subscription(TwistStamped, "~/delta_twist_cmds", twist, RELIABLE)
    n.create_service(SetBool, "~/pause_servo", pause)
    timer = n.create_timer(0.04, tick)
    timer.cancel()
    log.info("Servo initialized successfully")


def run_move_group(proc: Process) -> int:
    servo(proc, MoveGroup(proc))
    return proc.spin(SingleThreadedExecutor())


# ================================================================================================
# navigation container: map server, AMCL, path follower
# ================================================================================================

MAP_W, MAP_H, MAP_RES = 400, 240, 0.05


def run_navigation(proc: Process) -> int:
    ms, amcl, pf = proc.node("map_server"), proc.node("amcl"), proc.node("path_follower")
    _faults, rng = proc.faults, proc.rng

    # --- map server
    mlog = ms.get_logger()
    ms.declare_parameter("yaml_filename", "/opt/mm/maps/warehouse_b.yaml")
    grid = OccupancyGrid()
    grid.header.frame_id = "map"
    grid.header.stamp = to_stamp(time.time())
    grid.info = MapMetaData(resolution=MAP_RES, width=MAP_W, height=MAP_H)
    grid.info.origin.position.x, grid.info.origin.position.y = -2.0, -6.0
    data = np.zeros((MAP_H, MAP_W), dtype=np.int8)
    data[0, :] = data[-1, :] = data[:, 0] = data[:, -1] = 100
    for r in range(30, 210, 45):
        data[r : r + 8, 60:360] = 100
    grid.data = array.array("b", data.tobytes())
    mlog.info("Loading yaml file: /opt/mm/maps/warehouse_b.yaml")
    mlog.info(f"Read map warehouse_b.pgm: {MAP_W} X {MAP_H} map @ {MAP_RES} m/cell")
    map_pub = ms.create_publisher(OccupancyGrid, f"{NS}/map", LATCHED)
    map_pub.publish(grid)

    def get_map(_req, res):
        res.map = grid
        return res

    ms.create_service(GetMap, "~/map", get_map)

    # --- AMCL
    alog = amcl.get_logger()
    for k, v in (
        ("laser_model_type", "likelihood_field"),
        ("max_particles", 2000),
        ("min_particles", 500),
        ("transform_tolerance", 0.5),
        ("scan_topic", f"{NS}/scan"),
        ("global_frame_id", "map"),
    ):
        amcl.declare_parameter(k, v)
    a = {
        "odom": deque(maxlen=50),
        "offset": MAP_FROM_ODOM,
        "last_scan": time.time(),
        "map": False,
        "scans": 0,
        "last_warn": 0.0,
    }
    pose_pub = amcl.create_publisher(PoseWithCovarianceStamped, f"{NS}/amcl_pose", LATCHED)
    tf_pub = amcl.create_publisher(TransformStamped, "/tf", RELIABLE)
    cloud_pub = amcl.create_publisher(PoseArray, f"{NS}/particle_cloud", SENSOR)

    def on_map(msg: OccupancyGrid) -> None:
        if not a["map"]:
            a["map"] = True
            alog.info(
                f"Received a {msg.info.width} X {msg.info.height} map @ {msg.info.resolution:.3f} m/pix"
            )

    def on_odom(msg: Odometry) -> None:
        p = msg.pose.pose
        a["odom"].append((secs(msg.header.stamp), p.position.x, p.position.y, quat_yaw(p.orientation)))

    def on_scan(msg: LaserScan) -> None:
        t = secs(msg.header.stamp)
        odom = a["odom"]
        if not odom:
            return
        if t < odom[0][0]:
            alog.warning(
                f"Message Filter dropping message: frame 'laser' at time {t:.3f} for reason 'the timestamp "
                "on the message is earlier than all the data in the transform cache'",
                throttle_duration_sec=1.0,
            )
            return
        o = min(odom, key=lambda e: abs(e[0] - t))
        a["last_scan"] = time.time()
        a["scans"] += 1
        bx, by, byaw = MAP_FROM_ODOM  # the filter's estimate: the truth plus a few cm
        a["offset"] = (bx + rng.gauss(0, 0.01), by + rng.gauss(0, 0.01), byaw + rng.gauss(0, 0.003))
        x, y, yaw = odom_to_map(o[1], o[2], o[3], a["offset"])
        m = PoseWithCovarianceStamped()
        m.header.stamp, m.header.frame_id = msg.header.stamp, "map"
        m.pose.pose.position.x, m.pose.pose.position.y = x, y
        _, _, m.pose.pose.orientation.z, m.pose.pose.orientation.w = yaw_quat(yaw)
        cov = [0.0] * 36
        cov[0] = cov[7] = 0.02 + rng.uniform(0, 0.01)
        cov[35] = 0.01
        m.pose.covariance = cov
        pose_pub.publish(m)
        ox, oy, oyaw = a["offset"]
        tf_pub.publish(tf_msg(to_stamp(t + 0.5), "map", "odom", ox, oy, 0.0, oyaw))  # transform_tolerance
        if a["scans"] % 5 == 0:
            pc = PoseArray()
            pc.header.stamp, pc.header.frame_id = msg.header.stamp, "map"
            pc.poses = [Pose() for _ in range(50)]
            cloud_pub.publish(pc)

    def watchdog() -> None:
        if time.time() - a["last_scan"] > 5.0 and time.time() - a["last_warn"] > 5.0:
            a["last_warn"] = time.time()
            alog.warning(
                f"No laser scan received (and thus no pose updates have been published) for "
                f"{time.time() - a['last_scan']:.6f} seconds.  Verify that data is being published on the "
                f"{NS}/scan topic."
            )

    amcl.create_subscription(OccupancyGrid, f"{NS}/map", on_map, LATCHED)
    amcl.create_subscription(Odometry, f"{NS}/diff_drive_controller/odom", on_odom, RELIABLE)
    amcl.create_subscription(LaserScan, f"{NS}/scan", on_scan, SENSOR)
    amcl.create_timer(1.0, watchdog)
    alog.info(f"Setting pose ({time.time():.6f}): 2.000 0.000 0.000")

    # --- the path follower: navigate_to_pose (a site's index), regulated pure pursuit at 20 Hz
    plog = pf.get_logger()
    pf.declare_parameter("max_vel_x", 0.7)
    pf.declare_parameter("xy_goal_tolerance", 0.15)
    pf.declare_parameter("max_pose_age", 1.0)
    pf.declare_parameter("progress_required_movement", 0.2)
    pf.declare_parameter("progress_time_allowance", 10.0)
    p = {"pose": None, "pose_t": 0.0}
    cmd_pub = pf.create_publisher(Twist, f"{NS}/cmd_vel_nav", COMMAND)
    plan_pub = pf.create_publisher(PathMsg, f"{NS}/plan", RELIABLE)

    def on_pose(msg: PoseWithCovarianceStamped) -> None:
        q = msg.pose.pose
        p["pose"], p["pose_t"] = (q.position.x, q.position.y, quat_yaw(q.orientation)), time.time()

    pf.create_subscription(PoseWithCovarianceStamped, f"{NS}/amcl_pose", on_pose, LATCHED)

    ticker = Ticker(pf, 0.05)

    async def execute(goal_handle):
        idx = goal_handle.request.order
        name, gx, gy, _ = SITES[idx]
        plog.info(f"Received a goal, begin computing control effort ({name})")
        if p["pose"] is None or time.time() - p["pose_t"] > 1.0:
            plog.error("Robot pose is not available: can't start the path")
            goal_handle.abort()
            return Fibonacci.Result(sequence=[1])
        sx, sy, _ = p["pose"]
        path = PathMsg()
        path.header.stamp, path.header.frame_id = to_stamp(time.time()), "map"
        for i in range(21):
            ps = PoseStamped()
            ps.header = path.header
            ps.pose.position.x, ps.pose.position.y = sx + (gx - sx) * i / 20, sy + (gy - sy) * i / 20
            path.poses.append(ps)
        plan_pub.publish(path)
        best, best_t = math.hypot(gx - sx, gy - sy), time.time()
        fb = Fibonacci.Feedback()
        k = 0
        while alive():
            await ticker.wait()
            k += 1
            if goal_handle.is_cancel_requested:
                cmd_pub.publish(Twist())
                goal_handle.canceled()
                return Fibonacci.Result(sequence=[2])
            age = time.time() - p["pose_t"]
            if age > 1.0:
                cmd_pub.publish(Twist())
                plog.error(f"Robot pose is {age:.2f} s old (max_pose_age 1.0 s): localization lost, aborting")
                goal_handle.abort()
                return Fibonacci.Result(sequence=[3])
            x, y, yaw = p["pose"]
            dist = math.hypot(gx - x, gy - y)
            if dist < 0.15:
                cmd_pub.publish(Twist())
                plog.info("Reached the goal!")
                goal_handle.succeed()
                return Fibonacci.Result(sequence=[0])
            if dist < best - 0.2:
                best, best_t = dist, time.time()
            elif time.time() - best_t > 10.0:
                cmd_pub.publish(Twist())
                plog.error("Failed to make progress")
                goal_handle.abort()
                return Fibonacci.Result(sequence=[4])
            err = wrap(math.atan2(gy - y, gx - x) - yaw)
            t = Twist()
            vmax = pf.get_parameter("max_vel_x").value
            if abs(err) > 0.6:
                t.angular.z = clamp(1.2 * err, -0.8, 0.8)
            else:
                t.linear.x = clamp(0.6 * dist, 0.08, vmax) * (1 - abs(err) / 1.2)
                t.angular.z = clamp(1.5 * err, -0.8, 0.8)
            cmd_pub.publish(t)
            if k % 4 == 0:
                fb.sequence = [int(dist * 100)]
                goal_handle.publish_feedback(fb)
        goal_handle.abort()
        return Fibonacci.Result(sequence=[5])

    ActionServer(
        pf,
        Fibonacci,
        f"{NS}/navigate_to_pose",
        execute,
        callback_group=ReentrantCallbackGroup(),
        cancel_callback=lambda _g: CancelResponse.ACCEPT,
    )
    return proc.spin(SingleThreadedExecutor())


# ================================================================================================
# safety controller and velocity mux
# ================================================================================================


def run_safety(proc: Process) -> int:
    sc, mux = proc.node("safety_controller"), proc.node("velocity_mux")
    faults = proc.faults
    slog, mlog = sc.get_logger(), mux.get_logger()
    # --- safety: bumpers, sonars, e-stop -> RUN / PROTECTIVE_STOP; a 20 Hz heartbeat
    sc.declare_parameter("sonar_stop_distance", 0.3)
    sc.declare_parameter("input_timeout", 0.5)
    s = {
        "bump_t": time.time() + 5,
        "front_t": time.time() + 5,
        "rear_t": time.time() + 5,
        "front": 4.0,
        "bump": 0,
        "state": "RUN",
        "reason": "",
        "qos": None,
        "subs": [],
    }
    hb = sc.create_publisher(Header, f"{NS}/safety/heartbeat", COMMAND)
    state_pub = sc.create_publisher(String, f"{NS}/safety/state", LATCHED)
    state_pub.publish(String(data="RUN"))

    def bump(msg: UInt8) -> None:
        s["bump"], s["bump_t"] = msg.data, time.time()

    def front(msg: Range) -> None:
        s["front"], s["front_t"] = msg.range, time.time()

    def rear(_msg: Range) -> None:
        s["rear_t"] = time.time()

    def sonar_subs() -> None:
        want = "reliable" if faults.of(sc) == "reliable" else "best_effort"
        if want == s["qos"]:
            return
        for sub in s["subs"]:
            sc.destroy_subscription(sub)
        qos = RELIABLE if want == "reliable" else MCU_BEST_EFFORT
        s["subs"] = [
            sc.create_subscription(Range, f"{NS}/mcu/sonar/front", front, qos),
            sc.create_subscription(Range, f"{NS}/mcu/sonar/rear", rear, qos),
        ]
        s["qos"] = want

    sonar_subs()
    sc.create_subscription(UInt8, f"{NS}/mcu/bumpers", bump, MCU_BEST_EFFORT)

    def check() -> None:
        now = time.time()
        reasons = []
        if now - s["bump_t"] > 0.5:
            reasons.append(f"bumper data stale ({now - s['bump_t']:.2f} s)")
        if now - min(s["front_t"], s["rear_t"]) > 0.5:
            reasons.append(f"sonar data stale ({now - min(s['front_t'], s['rear_t']):.2f} s)")
        if s["bump"] & 0x80:
            reasons.append("e-stop pressed")
        elif s["bump"]:
            reasons.append("bumper contact")
        if s["front"] < 0.3 and now - s["front_t"] < 0.5:
            reasons.append(f"obstacle at {s['front']:.2f} m (front sonar)")
        state = "PROTECTIVE_STOP" if reasons else "RUN"
        if state != s["state"]:
            s["state"], s["reason"] = state, ", ".join(reasons)
            if reasons:
                slog.warning(f"Protective stop: {s['reason']}")
            else:
                slog.info("Protective stop cleared: resuming")
            state_pub.publish(String(data=state))
        h = Header(frame_id=s["state"])
        h.stamp = to_stamp(now)
        hb.publish(h)

    sc.create_timer(0.05, check)
    sc.create_timer(0.5, sonar_subs)
    sdiag = Diagnostics(sc, "mm_safety")
    sdiag.add(
        "Safety state",
        lambda: (OK, "RUN", {}) if s["state"] == "RUN" else (WARN, f"PROTECTIVE_STOP: {s['reason']}", {}),
    )

    # --- velocity mux / limiter: teleop (100) > navigation (10); the safety stop overrides
    mux.declare_parameter("max_linear_vel", 0.7)
    mux.declare_parameter("max_angular_vel", 1.0)
    mux.declare_parameter("max_linear_accel", 0.8)
    m = {
        "nav": None,
        "nav_t": 0.0,
        "tele": None,
        "tele_t": 0.0,
        "hb": "RUN",
        "hb_t": time.time() + 5,
        "active": "idle",
        "v": 0.0,
        "stopped_logged": False,
    }
    out = mux.create_publisher(TwistStamped, f"{NS}/diff_drive_controller/cmd_vel", RELIABLE)
    active_pub = mux.create_publisher(String, "~/active", LATCHED)
    active_pub.publish(String(data="idle"))

    def params(ps: list[Parameter]) -> SetParametersResult:
        for prm in ps:
            mlog.info(f"Parameter '{prm.name}' set to {prm.value}")
        return SetParametersResult(successful=True)

    mux.add_on_set_parameters_callback(params)

    def on_nav(msg: Twist) -> None:
        m["nav"], m["nav_t"] = msg, time.time()
        emit()

    def on_tele(msg: Twist) -> None:
        m["tele"], m["tele_t"] = msg, time.time()
        emit()

    def on_hb(msg: Header) -> None:
        m["hb"], m["hb_t"] = msg.frame_id, time.time()

    def emit() -> None:
        now = time.time()
        src = "teleop" if now - m["tele_t"] < 0.5 else "navigation" if now - m["nav_t"] < 0.5 else "idle"
        if src != m["active"]:
            m["active"] = src
            active_pub.publish(String(data=src))
        if src == "idle":
            return
        cmd = m["tele"] if src == "teleop" else m["nav"]
        safe = m["hb"] == "RUN" and now - m["hb_t"] < 0.3
        if not safe and not m["stopped_logged"]:
            m["stopped_logged"] = True
            mlog.warning(
                "Safety stop active: commanding zero velocity"
                if now - m["hb_t"] < 0.3
                else "Safety heartbeat lost: commanding zero velocity"
            )
        elif safe:
            m["stopped_logged"] = False
        vmax = mux.get_parameter("max_linear_vel").value
        v = clamp(cmd.linear.x, -vmax, vmax) if safe else 0.0
        m["v"] += clamp(v - m["v"], -0.8 * 0.05, 0.8 * 0.05) if safe else v - m["v"]
        t = TwistStamped()
        t.header.stamp, t.header.frame_id = to_stamp(now), "base_link"
        t.twist.linear.x = m["v"]
        t.twist.angular.z = clamp(cmd.angular.z, -1.0, 1.0) if safe else 0.0
        out.publish(t)

    mux.create_subscription(Twist, f"{NS}/cmd_vel_nav", on_nav, COMMAND)
    mux.create_subscription(Twist, f"{NS}/cmd_vel_teleop", on_tele, COMMAND)
    mux.create_subscription(Header, f"{NS}/safety/heartbeat", on_hb, COMMAND)
    mdiag = Diagnostics(mux, "mm_safety")
    mdiag.add("Velocity mux", lambda: (OK, f"active input: {m['active']}", {"safety": m["hb"]}))
    return proc.spin(SingleThreadedExecutor())


# ================================================================================================
# fleet adapter (the task state machine) and the fleet manager
# ================================================================================================


class TaskFailed(Exception):
    pass


class FleetAdapter:
    def __init__(self, proc: Process) -> None:
        self.proc = proc
        self.node = n = proc.node("fleet_adapter")
        self.log = n.get_logger()
        for k, v in (
            ("fleet_name", "picking_fleet"),
            ("robot_name", "mm_01"),
            ("plan_timeout", 5.0),
            ("server_uri", "ws://fleet-manager:8000/_internal"),
        ):
            n.declare_parameter(k, v)
        group = ReentrantCallbackGroup()
        self.nav = ActionClient(n, Fibonacci, f"{NS}/navigate_to_pose", callback_group=group)
        self.exec = ActionClient(n, Fibonacci, f"{NS}/execute_trajectory", callback_group=group)
        self.grip = ActionClient(n, Fibonacci, f"{NS}/gripper_controller/gripper_cmd", callback_group=group)
        self.plan = n.create_client(BasicTypes, f"{NS}/plan_kinematic_path", callback_group=group)
        self.cart = n.create_client(BasicTypes, f"{NS}/compute_cartesian_path", callback_group=group)
        self.enable = n.create_client(SetBool, f"{NS}/tote_detector/enable", callback_group=group)
        self.state_pub = n.create_publisher(String, "~/robot_state", RELIABLE)
        self.task_pub = n.create_publisher(String, "~/task_state", LATCHED)
        self.pose = (2.0, 0.0, 0.0)
        self.battery = 1.0
        self.safety = "RUN"
        self.detection_t = 0.0
        self.mode, self.task, self.phase = "MODE_IDLE", "", ""
        self.orders: deque = deque()
        n.create_subscription(PoseWithCovarianceStamped, f"{NS}/amcl_pose", self._pose, LATCHED)
        n.create_subscription(BatteryState, f"{NS}/mcu/battery/state", self._battery, RELIABLE)
        n.create_subscription(
            String, f"{NS}/safety/state", lambda m: setattr(self, "safety", m.data), LATCHED
        )
        n.create_subscription(PoseArray, f"{NS}/tote_detector/detections", self._detection, RELIABLE)
        n.create_subscription(String, "/fleet_manager/task_orders", self._order, RELIABLE)
        n.create_timer(1.0, self._publish_state)
        diag = Diagnostics(n, "mm_01")
        diag.add(
            "Fleet connection",
            lambda: (OK, "connected to picking_fleet", {"mode": self.mode, "task": self.task}),
        )
        self.log.info("Fleet adapter for robot [mm_01] of fleet [picking_fleet] started")
        self.log.info("Connecting to fleet manager at ws://fleet-manager:8000/_internal")
        threading.Thread(target=self._worker, daemon=True).start()

    def _pose(self, msg) -> None:
        q = msg.pose.pose
        self.pose = (q.position.x, q.position.y, quat_yaw(q.orientation))

    def _battery(self, msg: BatteryState) -> None:
        self.battery = msg.percentage

    def _detection(self, msg: PoseArray) -> None:
        if msg.poses and time.time() - secs(msg.header.stamp) < 1.0:
            self.detection_t = time.time()

    def _order(self, msg: String) -> None:
        order = json.loads(msg.data)
        if order.get("robot") != "mm_01":
            return
        self.log.info(
            f"Received task {order['task_id']}: pick {order['tote']} at {order['pickup']}, "
            f"place at {order['dropoff']}"
        )
        self.orders.append(order)

    def _publish_state(self) -> None:
        x, y, yaw = self.pose
        self.state_pub.publish(
            String(
                data=json.dumps(
                    {
                        "name": "mm_01",
                        "model": "mm_picker",
                        "task_id": self.task,
                        "mode": self.mode,
                        "phase": self.phase,
                        "battery_percent": round(self.battery * 100, 1),
                        "location": {
                            "map": "warehouse_b",
                            "x": round(x, 3),
                            "y": round(y, 3),
                            "yaw": round(yaw, 3),
                        },
                        "seq": int(time.time()),
                    }
                )
            )
        )

    def _task_state(self, status: str, detail: str = "") -> None:
        self.task_pub.publish(
            String(
                data=json.dumps(
                    {
                        "task_id": self.task,
                        "status": status,
                        "phase": self.phase,
                        "detail": detail,
                        "t": time.time(),
                    }
                )
            )
        )

    # the task's steps, each blocking this worker thread (the executor runs in the main one)
    def _action(self, client: ActionClient, goal: int, timeout: float, what: str) -> None:
        if not client.wait_for_server(timeout_sec=2.0):
            raise TaskFailed(f"{what}: action server {client._action_name} not available")
        h = wait_future(client.send_goal_async(Fibonacci.Goal(order=goal)), 5.0)
        if h is None or not h.accepted:
            raise TaskFailed(f"{what}: goal rejected")
        r = wait_future(h.get_result_async(), timeout)
        if r is None:
            h.cancel_goal_async()
            raise TaskFailed(f"{what}: timed out after {timeout:.0f} s")
        if r.status != 4:
            raise TaskFailed(f"{what}: aborted (code {list(r.result.sequence)})")

    def _navigate(self, site: str) -> None:
        self.mode, self.phase = "MODE_MOVING", f"navigate to {site}"
        self._task_state("underway")
        self.log.info(f"[{self.task}] Navigating to {site}")
        self._action(self.nav, SITE_INDEX[site], 90.0, f"navigate to {site}")
        self.log.info(f"[{self.task}] Arrived at {site}")

    def _move_arm(self, target: str, planner: str = "ompl") -> None:
        client = self.plan if planner == "ompl" else self.cart
        timeout = self.node.get_parameter("plan_timeout").value
        if not client.wait_for_service(timeout_sec=2.0):
            raise TaskFailed(f"plan to '{target}': {client.srv_name} not available")
        r = wait_future(client.call_async(BasicTypes.Request(string_value=f"{planner}:{target}")), timeout)
        if r is None:
            raise TaskFailed(f"planning to '{target}' timed out after {timeout:.1f} s")
        if not r.bool_value:
            raise TaskFailed(f"planning to '{target}' failed: {r.string_value}")
        self._action(self.exec, r.int32_value, 20.0, f"execute trajectory to '{target}'")

    def _detector(self, on: bool) -> None:
        if self.enable.wait_for_service(timeout_sec=1.0):
            wait_future(self.enable.call_async(SetBool.Request(data=on)), 2.0)

    def _gripper(self, close: bool) -> None:
        self._action(self.grip, 1 if close else 0, 5.0, "close gripper" if close else "open gripper")

    def _run(self, order: dict) -> None:
        shelf, pack = order["pickup"], order["dropoff"]
        self._navigate(shelf)
        self.mode, self.phase = "MODE_PICKING", "pick"
        self._task_state("underway")
        self.log.info(f"[{self.task}] Picking {order['tote']} at {shelf}")
        self._detector(True)
        self._move_arm("look")
        t0 = time.time()
        while time.time() - t0 < 3.0 and self.detection_t < t0 + 0.1:
            time.sleep(0.1)
        self._detector(False)
        if self.detection_t < t0 + 0.1:
            raise TaskFailed(f"no tote detected at {shelf} within 3.0 s")
        self.log.info(f"[{self.task}] Tote {order['tote']} detected")
        self._move_arm("pre_pick")
        self._move_arm("pick", "cartesian")
        self._gripper(True)
        self._move_arm("lift", "cartesian")
        self._move_arm("stow")
        self._navigate(pack)
        self.mode, self.phase = "MODE_PLACING", "place"
        self._task_state("underway")
        self._move_arm("pre_place")
        self._move_arm("place", "cartesian")
        self._gripper(False)
        self._move_arm("stow")

    def _worker(self) -> None:
        while alive():
            if not self.orders:
                time.sleep(0.2)
                continue
            order = self.orders.popleft()
            self.task = order["task_id"]
            self.phase = "start"
            self._task_state("underway")
            t0 = time.time()
            try:
                self._run(order)
                self.log.info(f"[{self.task}] Task completed in {time.time() - t0:.1f} s")
                self._task_state("completed")
            except TaskFailed as e:
                if not alive():
                    return
                self.log.error(f"[{self.task}] Task failed in phase '{self.phase}': {e}")
                self._task_state("failed", str(e))
                self.mode = "MODE_ERROR"
                try:  # recover: stow the arm
                    self._move_arm("stow")
                except TaskFailed as e2:
                    self.log.warning(f"[{self.task}] Could not stow the arm after the failure: {e2}")
            except Exception:  # shutting down
                if alive():
                    raise
                return
            self.mode, self.task, self.phase = "MODE_IDLE", "", ""


def run_fleet_adapter(proc: Process) -> int:
    FleetAdapter(proc)
    return proc.spin(SingleThreadedExecutor())


def run_fleet_manager(proc: Process) -> int:
    """The fleet manager (Open-RMF's dispatcher, simplified): a task to the robot when it idles."""
    n = proc.node("fleet_manager", "/")
    log = n.get_logger()
    rng = proc.rng
    pub = n.create_publisher(String, "/fleet_manager/task_orders", RELIABLE)
    st = {
        "state_t": 0.0,
        "mode": "",
        "idle_since": None,
        "next_gap": 8.0,
        "n": 0,
        "pending": None,
        "lost": False,
        "retry": None,
        "orders": {},
    }

    def on_state(msg: String) -> None:
        s = json.loads(msg.data)
        if st["lost"]:
            log.info("Robot mm_01 is back online")
            st["lost"] = False
        st["state_t"] = time.time()
        if s["mode"] == "MODE_IDLE":
            if st["idle_since"] is None:
                st["idle_since"] = time.time()
        else:
            st["idle_since"] = None
            st["pending"] = None

    def on_task(msg: String) -> None:
        s = json.loads(msg.data)
        if s["status"] == "failed":
            log.warning(f"Task {s['task_id']} failed on mm_01 ({s['detail']}): re-queued")
            st["retry"] = s["task_id"]
        elif s["status"] == "completed":
            log.info(f"Task {s['task_id']} completed by mm_01")

    def tick() -> None:
        now = time.time()
        if st["state_t"] and now - st["state_t"] > 5.0:
            if not st["lost"]:
                st["lost"] = True
                log.error(f"Robot mm_01: no state for {now - st['state_t']:.1f} s, marking it lost")
            return
        idle = st["idle_since"]
        if idle is None or st["pending"] is not None or now - idle < st["next_gap"]:
            return
        retry = st["orders"].get(st["retry"]) if st["retry"] else None
        st["retry"] = None
        if retry is not None:
            order = retry  # the failed order again, as it was
        else:
            st["n"] += 1
            order = {
                "robot": "mm_01",
                "task_id": f"pick.{st['n']:04d}",
                "type": "pick_place",
                "pickup": rng.choice([s[0] for s in SITES if s[0].startswith("shelf")]),
                "dropoff": "pack_1",
                "tote": f"TOTE-{rng.randint(10000, 99999)}",
            }
            st["orders"][order["task_id"]] = order
        task_id, shelf = order["task_id"], order["pickup"]
        log.info(f"Dispatching {task_id} to mm_01: {shelf} -> pack_1")
        pub.publish(String(data=json.dumps(order)))
        st["pending"] = now
        st["next_gap"] = rng.uniform(4.0, 12.0)

    n.create_subscription(String, f"{NS}/fleet_adapter/robot_state", on_state, RELIABLE)
    n.create_subscription(String, f"{NS}/fleet_adapter/task_state", on_task, LATCHED)
    n.create_timer(0.5, tick)

    def pending_timeout() -> None:
        if st["pending"] is not None and time.time() - st["pending"] > 10.0:
            st["pending"] = None

    n.create_timer(1.0, pending_timeout)
    log.info("Fleet manager up: 1 fleet (picking_fleet), 1 robot (mm_01)")
    return proc.spin(SingleThreadedExecutor())


# ================================================================================================
# diagnostics aggregator, bag recorder, web bridge, operator UI
# ================================================================================================

ANALYZERS = (
    ("Base", ("controller_manager", "velocity_mux", "safety_controller")),
    ("Sensors", ("lidar_driver", "camera_driver")),
    ("Perception", ("tote_detector",)),
    ("Fleet", ("fleet_adapter",)),
)


def run_diagnostics(proc: Process) -> int:
    n = proc.node("diagnostic_aggregator", "/")
    n.declare_parameter("pub_rate", 1.0)
    n.declare_parameter("base_path", "")
    latest: dict[str, tuple[float, DiagnosticStatus]] = {}
    agg = n.create_publisher(DiagnosticArray, "/diagnostics_agg", RELIABLE)
    top = n.create_publisher(DiagnosticStatus, "/diagnostics_toplevel_state", RELIABLE)

    def on_diag(msg: DiagnosticArray) -> None:
        for s in msg.status:
            latest[s.name] = (time.time(), s)

    def publish() -> None:
        now = time.time()
        out = DiagnosticArray()
        out.header.stamp = to_stamp(now)
        worst = OK
        for group, nodes in (*ANALYZERS, ("Other", ())):
            items = []
            for name, (t, s) in latest.items():
                owner = name.split(":")[0]
                if (owner in nodes) or (group == "Other" and not any(owner in ns for _, ns in ANALYZERS)):
                    level = s.level if now - t < 5.0 else STALE
                    items.append(
                        DiagnosticStatus(
                            level=level,
                            name=f"/{group}/{name}",
                            message=s.message if level != STALE else "Stale",
                            hardware_id=s.hardware_id,
                            values=s.values,
                        )
                    )
            glevel = max((i.level for i in items), default=OK)
            worst = max(worst, glevel)
            out.status.append(
                DiagnosticStatus(
                    level=glevel,
                    name=f"/{group}",
                    message="OK"
                    if glevel == OK
                    else "Warning"
                    if glevel == WARN
                    else "Error"
                    if glevel == ERROR
                    else "Stale",
                )
            )
            out.status.extend(items)
        agg.publish(out)
        top.publish(DiagnosticStatus(level=worst, name="toplevel_state", message=""))

    n.create_subscription(DiagnosticArray, "/diagnostics", on_diag, RELIABLE)
    n.create_timer(1.0, publish)
    return proc.spin(SingleThreadedExecutor())


RECORDED = (
    (f"{NS}/joint_states", JointState, RELIABLE),
    (f"{NS}/diff_drive_controller/odom", Odometry, RELIABLE),
    ("/tf", TransformStamped, RELIABLE),
    ("/tf_static", TransformStamped, STATIC_TF),
    (f"{NS}/scan", LaserScan, SENSOR),
    (f"{NS}/amcl_pose", PoseWithCovarianceStamped, LATCHED),
    (f"{NS}/plan", PathMsg, RELIABLE),
    (f"{NS}/cmd_vel_nav", Twist, COMMAND),
    (f"{NS}/diff_drive_controller/cmd_vel", TwistStamped, RELIABLE),
    (f"{NS}/ft_sensor_broadcaster/wrench", WrenchStamped, SENSOR),
    (f"{NS}/arm_controller/controller_state", JointState, RELIABLE),
    (f"{NS}/mcu/battery/state", BatteryState, RELIABLE),
    (f"{NS}/mcu/bumpers", UInt8, MCU_BEST_EFFORT),
    (f"{NS}/safety/state", String, LATCHED),
    (f"{NS}/camera/color/camera_info", CameraInfo, SENSOR),
    (f"{NS}/tote_detector/detections", PoseArray, RELIABLE),
    (f"{NS}/fleet_adapter/robot_state", String, RELIABLE),
    (f"{NS}/fleet_adapter/task_state", String, LATCHED),
    ("/diagnostics", DiagnosticArray, RELIABLE),
    (f"{NS}/robot_description", String, LATCHED),
)


def run_recorder(proc: Process) -> int:
    """rosbag2's recorder: serialized subscriptions made as the publishers appear, a split every 60 s."""
    n = proc.node("rosbag2_recorder", "/")
    log = n.get_logger()
    n.declare_parameter("storage.uri", "/data/bags/mm_01")
    n.declare_parameter("storage.max_bag_duration", 60)
    subs: dict[str, object] = {}
    st = {"bytes": 0, "msgs": 0, "split": time.time(), "n": 0}
    log.info("Press SPACE for pausing/resuming")
    log.info(f"Listening for topics... (uri /data/bags/mm_01/rosbag2_{time.strftime('%Y_%m_%d-%H_%M_%S')})")

    def write(raw: bytes) -> None:
        st["bytes"] += len(raw)
        st["msgs"] += 1

    def writer() -> None:
        """rosbag2's writer thread: takes the serialized messages off every subscription, 10 times a second
        (no executor: the node's topic discovery runs here too, every 2 s)."""
        k = 0
        for _ in paced(10.0):
            k += 1
            if k % 20 == 1:
                discover()
            for sub in list(subs.values()):
                try:
                    with sub.handle:
                        while True:
                            got = sub.handle.take_message(sub.msg_type, True)
                            if got is None:
                                break
                            write(got[0])
                except Exception:
                    if alive():
                        raise
                    return

    def discover() -> None:
        names = dict(n.get_topic_names_and_types())
        for topic, typ, qos in RECORDED:
            if topic in names and topic not in subs and n.count_publishers(topic) > 0:
                deep = QoSProfile(depth=200, reliability=qos.reliability, durability=qos.durability)
                subs[topic] = n.create_subscription(typ, topic, write, deep, raw=True)
                log.info(f"Subscribed to topic '{topic}'")
        if time.time() - st["split"] > 60.0:
            st["split"] = time.time()
            st["n"] += 1
            log.info(
                f"Writing to a new bag file: /data/bags/mm_01/mm_01_{st['n']}.mcap "
                f"({st['msgs']} messages, {st['bytes'] / 1e6:.1f} MB so far)"
            )

    threading.Thread(target=writer, daemon=True).start()
    log.info("Recording...")
    return proc.spin(SingleThreadedExecutor(), spun=[])


def run_rosbridge(proc: Process) -> int:
    """rosbridge_websocket with the warehouse dashboard connected: its subscriptions, throttled sends."""
    n = proc.node("rosbridge_websocket", "/")
    log = n.get_logger()
    n.declare_parameter("port", 9090)
    n.declare_parameter("max_message_size", 10000000)
    queue: deque = deque(maxlen=200)
    last_sent: dict[str, float] = {}
    log.info("Rosbridge WebSocket server started on port 9090")
    log.info("Client connected. 1 clients total.")
    subs = (
        (f"{NS}/fleet_adapter/robot_state", String, RELIABLE, 0.0),
        (f"{NS}/mcu/battery/state", BatteryState, RELIABLE, 1.0),
        ("/diagnostics_agg", DiagnosticArray, RELIABLE, 1.0),
        (f"{NS}/safety/state", String, LATCHED, 0.0),
        (f"{NS}/amcl_pose", PoseWithCovarianceStamped, LATCHED, 0.5),
        (f"{NS}/map", OccupancyGrid, LATCHED, 0.0),
        (f"{NS}/plan", PathMsg, RELIABLE, 0.0),
        (f"{NS}/fleet_adapter/task_state", String, LATCHED, 0.0),
    )

    def make(topic: str, throttle: float):
        def cb(msg) -> None:
            now = time.time()
            if now - last_sent.get(topic, 0.0) >= throttle:
                last_sent[topic] = now
                queue.append((topic, msg))

        return cb

    for topic, typ, qos, throttle in subs:
        n.create_subscription(typ, topic, make(topic, throttle), qos)
        log.info(f"[Client 7b2e] Subscribed to {topic}")

    def send() -> None:
        for _ in paced(10.0):
            while queue:
                topic, msg = queue.popleft()
                if isinstance(msg, OccupancyGrid):
                    size = f"{msg.info.width}x{msg.info.height}"
                    payload = json.dumps({"op": "publish", "topic": topic, "msg": {"info": size}})
                else:
                    payload = json.dumps({"op": "publish", "topic": topic, "msg": str(msg)[:4000]})
                _ = len(payload)

    threading.Thread(target=send, daemon=True).start()
    return proc.spin(SingleThreadedExecutor())


def run_operator(proc: Process) -> int:
    """The operator's UI (a tablet app through a ROS node): watches, sets a limit, jogs the wrist once."""
    n = proc.node("operator_ui")
    log = n.get_logger()
    rng = proc.rng
    st = {"mode": "", "frames": 0, "t0": time.time(), "set": False, "jog": "pending", "jog_t": 0.0}
    n.create_subscription(
        CompressedImage,
        f"{NS}/camera/color/image_raw/compressed",
        lambda _m: st.__setitem__("frames", st["frames"] + 1),
        SENSOR,
    )
    n.create_subscription(
        String,
        f"{NS}/fleet_adapter/robot_state",
        lambda m: st.__setitem__("mode", json.loads(m.data)["mode"]),
        RELIABLE,
    )
    n.create_subscription(DiagnosticArray, "/diagnostics_agg", lambda _m: None, RELIABLE)
    n.create_subscription(String, f"{NS}/safety/state", lambda _m: None, LATCHED)
    n.create_publisher(Twist, f"{NS}/cmd_vel_teleop", COMMAND)  # the joystick's dead-man button not held
    jog_pub = n.create_publisher(TwistStamped, f"{NS}/servo_node/delta_twist_cmds", RELIABLE)
    setp = n.create_client(SetParameters, f"{NS}/velocity_mux/set_parameters")
    pause = n.create_client(SetBool, f"{NS}/servo_node/pause_servo")
    log.info("Operator UI connected (operator: shift B, tablet 3)")

    def jog() -> None:
        if st["jog"] != "active":
            return
        if time.time() - st["jog_t"] > 6.0 or st["mode"] != "MODE_MOVING":
            pause.call_async(SetBool.Request(data=True))
            st["jog"] = "done"
            jog_timer.cancel()
            return
        t = TwistStamped()
        t.header.stamp, t.header.frame_id = to_stamp(time.time()), "tool0"
        t.twist.angular.z = 0.15 * math.sin((time.time() - st["jog_t"]) * 1.2)
        jog_pub.publish(t)

    jog_timer = n.create_timer(0.05, jog)
    jog_timer.cancel()

    def tick() -> None:
        el = time.time() - st["t0"]
        if el > 5.0 and not st["set"]:
            st["set"] = True
            v = round(rng.uniform(0.55, 0.7), 2)
            req = SetParameters.Request(parameters=[Parameter("max_linear_vel", value=v).to_parameter_msg()])
            if setp.service_is_ready():
                setp.call_async(req)
                log.info(f"Set {NS}/velocity_mux max_linear_vel to {v}")
        # a wrist-camera look-around by teleop, once a session, while the robot drives (the arm stowed)
        if st["jog"] == "pending" and el > 20.0 and st["mode"] == "MODE_MOVING" and pause.service_is_ready():
            st["jog"], st["jog_t"] = "active", time.time()
            pause.call_async(SetBool.Request(data=False))
            log.info("Teleop: wrist camera look-around")
            jog_timer.reset()

    n.create_timer(0.5, tick)
    n.create_timer(10.0, lambda: log.info(f"UI: {st['frames']} camera frames, robot {st['mode'] or '?'}"))
    return proc.spin(SingleThreadedExecutor())


# ================================================================================================

PROCESSES = {
    "controller_manager": run_controller_manager,
    "robot_state_publisher": run_robot_state_publisher,
    "spawner_base": lambda p: run_spawner(
        p, ("joint_state_broadcaster", "ft_sensor_broadcaster", "diff_drive_controller")
    ),
    "spawner_arm": lambda p: run_spawner(p, ("arm_controller", "gripper_controller")),
    "micro_ros_agent": run_micro_ros_agent,
    "lidar": run_lidar,
    "perception": run_perception,
    "move_group": run_move_group,
    "navigation": run_navigation,
    "safety": run_safety,
    "fleet_adapter": run_fleet_adapter,
    "fleet_manager": run_fleet_manager,
    "diagnostics": run_diagnostics,
    "recorder": run_recorder,
    "rosbridge": run_rosbridge,
    "operator": run_operator,
}


def main(argv: list[str]) -> int:
    process, fault_dir = argv[0], Path(argv[1])
    run_for = float(argv[2]) if len(argv) > 2 else 0.0
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: STOPPING.set())
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    proc = Process(process, fault_dir, run_for)
    return PROCESSES[process](proc)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
