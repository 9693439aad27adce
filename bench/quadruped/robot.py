"""A legged inspection robot in rclpy: ``python -m bench.quadruped.robot PROCESS FAULT_DIR [RUN_FOR]``.

Written the way a team building an ANYmal/Spot-class quadruped for autonomous inspection rounds lays
out its stack (see `bench.quadruped.run` for the whole robot, its healthy dynamics and its faults),
everything under ``/quad`` but ``/tf``, ``/tf_static``, ``/diagnostics*``, ``/rosout``, the bag
recorder and the foxglove bridge: locomotion (the 400 Hz whole-body controller and its joint state
broadcaster), the IMU driver, the state estimator beside the robot state publisher, the lidar driver,
elevation mapping, a nav2-style navigation container (planner, controller and behaviour servers and
the BT navigator, all lifecycle nodes, brought up and watched over bonds by a lifecycle manager, on
one multi-threaded executor), a twist mux, the docking server, the mission executive, the
inspection payload's container (PTZ camera, thermal camera, gas sensor, acoustic leak detector on one
single-threaded executor), the battery manager, the diagnostic aggregator, a site map loader that
exits once its map is latched, and the remote operator's station (its UI and its joystick) that comes
and goes.

Stock message types only (no tf2_msgs, nav2_msgs, trajectory_msgs nor control_msgs here): ``/tf`` and
``/tf_static`` carry geometry_msgs/TransformStamped, one transform a message; the actions
(navigate_to_pose, follow_path, backup, undock_robot, move_to_preset) are test_msgs/Fibonacci goals
(``order`` the waypoint's index, the plan's id, the preset's number; the feedback's ``sequence``
their progress); the gait/contact state a sensor_msgs/JointState (``name`` the feet, ``position``
the contact flags, ``velocity`` the legs' body velocity vx, vy, wz, ``header.frame_id`` the gait);
the bonds' heartbeats std_msgs/Header (``frame_id`` the managed node); the thermal capture a
std_srvs/Trigger answering JSON; the gas reading a std_msgs/Float32 (CH4, % LEL).

Faults come from files: ``FAULT_DIR/<namespace>.<node>`` (``quad.inspection.gas_sensor``) holding a
word the target node acts on (``hang``, ``degrade``, ``slow``, ``stale``, ``reliable``, ``flaky``,
``errlog``), read by the process's watcher thread every 0.5 s; ``FAULT_DIR/<process>.cpu`` starts a
thread spinning a core in that process, ``<process>.leak`` one leaking 3 MB/s. Crashes are SIGKILLs
from outside. RUN_FOR > 0 ends the process cleanly (exit 0) after that many seconds.
"""

from __future__ import annotations

import array
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
from geometry_msgs.msg import PoseStamped, TransformStamped, Twist
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState
from nav_msgs.msg import OccupancyGrid, Odometry
from nav_msgs.msg import Path as PathMsg
from nav_msgs.srv import GetPlan
from rcl_interfaces.msg import Log, SetParametersResult
from rcl_interfaces.srv import SetParameters
from rclpy.action import ActionClient, ActionServer, CancelResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.experimental import EventsExecutor
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import BatteryState, CompressedImage, Imu, JointState, Joy, PointCloud2, PointField
from std_msgs.msg import Float32, Header, String
from std_srvs.srv import Trigger
from test_msgs.action import Fibonacci

LEAK_MB_S = 3.0  # the foxglove bridge's send buffer to a stalled client, never drained

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
ROSOUT = QoSProfile(
    depth=100, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)

CONTROL_HZ, JSB_HZ, IMU_HZ, ODOM_HZ, LIDAR_HZ = 400.0, 100.0, 200.0, 50.0, 10.0
LEGS = ("LF", "RF", "LH", "RH")
JOINTS = tuple(f"{leg}_{j}" for leg in LEGS for j in ("HAA", "HFE", "KFE"))
STAND_Q = (0.0, 0.6, -1.2)
# the site's inspection points (odom frame of the dock, m): name, x, y, the asset inspected
WAYPOINTS = (
    ("wp1_pump_P101", 4.0, 0.0),
    ("wp2_manifold_V20", 6.0, 4.0),
    ("wp3_compressor_C3", 2.0, 7.0),
    ("wp4_gauge_PG7", -2.0, 3.0),
)
BOND_PERIOD, BOND_TIMEOUT = 1.0, 4.0


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
    """A driver thread's loop: yields at ``hz`` (a number or a callable) while rclpy is up."""
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


def wait_for(future, timeout: float, tick=None):
    """Block an executor thread (of a MultiThreadedExecutor) on an rclpy future: its result or None;
    ``tick()`` every 0.2 s while waiting (an action's feedback)."""
    end = time.monotonic() + timeout
    last = time.monotonic()
    while alive() and not future.done() and time.monotonic() < end:
        time.sleep(0.02)
        if tick is not None and time.monotonic() - last >= 0.2:
            last = time.monotonic()
            tick()
    return future.result() if future.done() else None


def transform(parent: str, child: str, xyz, stamp, yaw: float = 0.0) -> TransformStamped:
    t = TransformStamped()
    t.header.frame_id, t.child_frame_id, t.header.stamp = parent, child, stamp
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = map(float, xyz)
    t.transform.rotation.z, t.transform.rotation.w = math.sin(yaw / 2), math.cos(yaw / 2)
    return t


POINT_FIELDS = [
    PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1)
    for i, n in enumerate(("x", "y", "z", "intensity"))
]


def grid_msg(
    frame: str, res: float, w: int, h: int, cells: np.ndarray, ox: float, oy: float
) -> OccupancyGrid:
    m = OccupancyGrid()
    m.header.frame_id = frame
    m.info.resolution, m.info.width, m.info.height = res, w, h
    m.info.origin.position.x, m.info.origin.position.y = ox, oy
    m.info.origin.orientation.w = 1.0
    m.data = array.array("b", np.ascontiguousarray(cells, dtype=np.int8).tobytes())
    return m


# --- fault hooks and the nodes' common parts ----------------------------------------------------------


def hook(node: Node, fault_dir: Path) -> None:
    """The bench's fault hooks: ``fault`` (the word in ``FAULT_DIR/<namespace>.<name>``, set by the
    watcher thread) and ``on_fault(word)``, run in the executor by `apply_faults` once it changed."""
    parts = [p for p in node.get_namespace().split("/") if p] + [node.get_name()]
    node.fault_file = fault_dir / ".".join(parts)
    node.fault = None
    node.fault_applied = None
    node.rng = random.Random()


def apply_faults(nodes: list) -> None:
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
        return DiagnosticStatus(
            level=level,
            name=f"{self.get_name()}: {task}",
            hardware_id=hardware_id,
            message=message,
            values=kvs,
        )

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


class QuadNode(Diagnosed, Node):
    def __init__(self, name: str, namespace: str, fault_dir: Path, **kw) -> None:
        Node.__init__(self, name, namespace=namespace, **kw)
        hook(self, fault_dir)


def spin_core(stop: threading.Event, _: float) -> None:
    """A thread busy-polling without a sleep (a driver's retry loop gone wrong): a whole core."""
    n = 0
    while not stop.is_set():
        n = (n + 1) % 1000003


def leak_memory(stop: threading.Event, mb_s: float) -> None:
    """A buffer that only grows: ``mb_s`` MB/s, touched, never freed."""
    kept = []
    chunk = int(mb_s * 1e6 / 10)
    while not stop.wait(0.1):
        kept.append(bytes([len(kept) % 251 + 1]) * chunk)


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
        for how, target, arg in (("cpu", spin_core, 1.0), ("leak", leak_memory, LEAK_MB_S)):
            if how not in started and (fault_dir / f"{process}.{how}").exists():
                started.add(how)
                threading.Thread(target=target, args=(threading.Event(), arg), daemon=True, name=how).start()


class Bonded:
    """nav2's bond with the lifecycle manager: a heartbeat on /quad/bond every 1 s while active."""

    def start_bond(self) -> None:
        if getattr(self, "_bond_pub", None) is None:
            self._bond_pub = self.create_publisher(Header, "/quad/bond", RELIABLE)
            self._bond_timer = self.create_timer(BOND_PERIOD, self._heartbeat)
        self.get_logger().info(f"Creating bond ({self.get_name()}) to lifecycle manager.")

    def _heartbeat(self) -> None:
        if getattr(self, "active", False):
            self._bond_pub.publish(
                Header(stamp=self.get_clock().now().to_msg(), frame_id=self.get_fully_qualified_name())
            )


# --- locomotion ---------------------------------------------------------------------------------------


class LocomotionController(QuadNode):
    """The whole-body locomotion controller: its 400 Hz control loop in its own thread tracks
    ``/quad/cmd_vel`` (stands when no command came for 0.5 s, or while the state estimate is
    degraded), trots at 1.8 Hz when walking; ``/quad/gait_state`` (contacts and the legs' body
    velocity) at 50 Hz walking, 10 Hz standing; the joint state broadcaster publishes from the loop."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("locomotion_controller", "quad", fault_dir)
        self.declare_parameter("control_rate", int(CONTROL_HZ))
        self.declare_parameter("max_lin_vel", 0.8)
        self.declare_parameter("trot_frequency", 1.8)
        self.gait_pub = self.create_publisher(JointState, "/quad/gait_state", SENSOR)
        self.create_subscription(Twist, "/quad/cmd_vel", self.on_cmd, COMMAND)
        self.create_subscription(String, "/quad/state_estimator/health", self.on_health, LATCHED)
        self.cmd = (0.0, 0.0, 0.0)
        self.cmd_at = -1e9
        self.v = [0.0, 0.0, 0.0]
        self.phase = 0.0
        self.walking = False
        self.health = None
        self.broadcaster = None
        self.next_gait = 0.0
        self.cycles = self.overruns = 0
        self.max_jitter = 0.0
        self.wbc = np.eye(12) * 0.9 + 0.01
        self.tau = np.zeros(12)
        self.q = np.tile(STAND_Q, 4).astype(float)
        self.create_timer(1.0, self.on_second)
        self.get_logger().info("Actuators ready: 12 drives on EtherCAT, whole-body controller at 400 Hz")

    def on_cmd(self, msg: Twist) -> None:
        self.cmd = (msg.linear.x, msg.linear.y, msg.angular.z)
        self.cmd_at = time.monotonic()

    def on_health(self, msg: String) -> None:
        degraded = msg.data.startswith("DEGRADED")
        if degraded and (self.health is None or not self.health.startswith("DEGRADED")):
            self.get_logger().warn(
                f"State estimate degraded ({msg.data}): holding the stand, cmd_vel ignored"
            )
        elif not degraded and self.health is not None and self.health.startswith("DEGRADED"):
            self.get_logger().info("State estimate nominal: locomotion enabled")
        self.health = msg.data

    def start(self) -> None:
        threading.Thread(target=self.loop, daemon=True, name="wbc").start()

    def loop(self) -> None:
        period = 1.0 / CONTROL_HZ
        last = time.monotonic()
        accel = (1.0, 1.0, 2.0)
        for _ in paced(CONTROL_HZ, jitter=0.0002, rng=self.rng):
            now = time.monotonic()
            dt = now - last
            last = now
            ok = self.health is not None and self.health.startswith("OK")
            target = self.cmd if ok and now - self.cmd_at < 0.5 else (0.0, 0.0, 0.0)
            v = self.v
            for k in range(3):
                v[k] += clamp(target[k] - v[k], -accel[k] * dt, accel[k] * dt)
            walking = max(map(abs, target)) > 0.01 or max(map(abs, v)) > 0.02
            if walking != self.walking:
                self.walking = walking
                self.get_logger().info("Gait: stand -> trot" if walking else "Gait: trot -> stand")
            if walking:
                self.phase = (self.phase + 2 * math.pi * 1.8 * dt) % (2 * math.pi)
            try:
                if self.broadcaster is not None:
                    self.broadcaster.update(now, self)
                if now >= self.next_gait:
                    self.next_gait = now + (1 / 50.0 if walking else 1 / 10.0)
                    self.publish_gait(walking)
            except Exception:
                if alive():
                    raise
                return
            self.cycles += 1
            jitter = abs(dt - period) * 1e3
            if jitter > self.max_jitter:
                self.max_jitter = jitter
            if dt > 2 * period:
                self.overruns += 1

    def joints(self) -> tuple[list[float], list[float]]:
        """The legs' joint positions now and the whole-body controller's torques for them."""
        for i in range(4):
            ph = self.phase + (0.0 if i in (0, 3) else math.pi)
            swing = max(0.0, math.sin(ph)) if self.walking else 0.0
            self.q[3 * i + 1] = STAND_Q[1] + 0.25 * math.sin(ph) * self.walking
            self.q[3 * i + 2] = STAND_Q[2] - 0.5 * swing
        self.tau = self.wbc @ (self.q - np.tile(STAND_Q, 4)) * 40.0
        return self.q.tolist(), self.tau.tolist()

    def publish_gait(self, walking: bool) -> None:
        m = JointState(name=list(LEGS))
        m.header.stamp = self.get_clock().now().to_msg()
        m.header.frame_id = "trot" if walking else "stand"
        contacts = [
            float(not walking or math.sin(self.phase + (0.0 if i in (0, 3) else math.pi)) <= 0)
            for i in range(4)
        ]
        m.position = contacts
        m.velocity = [float(self.v[0]), float(self.v[1]), float(self.v[2]), 0.0]
        m.effort = [c * 120.0 for c in contacts]
        self.gait_pub.publish(m)

    def on_second(self) -> None:
        if self.walking and self.rng.random() < 1 / 45:
            leg = self.rng.choice(LEGS)
            self.get_logger().warn(
                f"Foot slip detected on {leg} ({self.rng.uniform(0.03, 0.08):.2f} m): re-planning footholds"
            )
        self.publish_diagnostics(
            self.status(
                "whole_body_control",
                "anymal-actuators-ecat0",
                OK,
                "trot" if self.walking else "stand",
                cycles=self.cycles,
                overruns=self.overruns,
                max_jitter_ms=f"{self.max_jitter:.2f}",
            )
        )
        self.cycles = self.overruns = 0
        self.max_jitter = 0.0


class JointStateBroadcaster(QuadNode):
    """/quad/joint_states (12 joints) at 100 Hz from the control loop, through a realtime publisher
    (it skips a cycle when the publisher's lock is held)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("joint_state_broadcaster", "quad", fault_dir)
        self.declare_parameter("publish_rate", JSB_HZ)
        self.pub = self.create_publisher(JointState, "/quad/joint_states", RELIABLE)
        self.msg = JointState(name=list(JOINTS))
        self.next = 0.0

    def update(self, now: float, lc: LocomotionController) -> None:
        if now < self.next:
            return
        # a realtime publisher whose non-RT thread is starved gets its lock on fewer than half the cycles
        rate = 45.0 if self.fault == "degrade" else self.get_parameter("publish_rate").value
        self.next = max(self.next + 1.0 / rate, now)
        m = self.msg
        m.header.stamp = lc.get_clock().now().to_msg()
        m.position, m.effort = lc.joints()
        m.velocity = [0.0] * 12
        self.pub.publish(m)


# --- state estimation ---------------------------------------------------------------------------------


class ImuDriver(QuadNode):
    """The body IMU (an ADIS16495 on SPI): /quad/imu/data at 200 Hz from its data-ready thread,
    stamped at the sample (PTP-synchronised clock), sensor QoS."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("imu_driver", "quad", fault_dir)
        self.declare_parameter("rate", int(IMU_HZ))
        self.declare_parameter("frame_id", "imu_link")
        self.pub = self.create_publisher(Imu, "/quad/imu/data", SENSOR)
        self.n = 0
        self.out_until = 0.0
        self.next_out = 0.0
        self.lost = False
        self.get_logger().info("ADIS16495-2 on /dev/spidev0.0: 200 Hz, PTP-synchronised")
        self.create_timer(1.0, self.on_second)
        threading.Thread(target=self.stream, daemon=True, name="spi").start()

    def stream(self) -> None:
        m = Imu()
        m.header.frame_id = "imu_link"
        m.orientation.w = 1.0
        m.orientation_covariance[0] = m.orientation_covariance[4] = m.orientation_covariance[8] = 1e-4
        t = 0.0
        for _ in paced(IMU_HZ, jitter=0.0003, rng=self.rng):
            now = time.monotonic()
            if self.fault == "flaky":  # the IMU's harness chafes at the hip: the data-ready line drops out
                if now > self.next_out:
                    self.out_until = now + self.rng.uniform(1.0, 3.0)
                    self.next_out = self.out_until + self.rng.uniform(4.0, 9.0)
            lost = now < self.out_until
            if lost != self.lost:
                self.lost = lost
                if lost:
                    self.get_logger().warn(
                        "IMU timeout: no data-ready interrupt from the ADIS16495 for 0.1 s"
                    )
                else:
                    self.get_logger().info("IMU data back")
            if lost:
                continue
            t += 1.0 / IMU_HZ
            stamp = time.time() - 0.0008  # the sample's time (the SPI read takes 0.8 ms)
            if self.fault == "stale":  # PTP lost: the IMU's own oscillator, drifted 1.5 s behind
                stamp -= 1.5
            m.header.stamp = to_stamp(stamp)
            m.angular_velocity.x = self.rng.gauss(0.0, 0.02)
            m.angular_velocity.y = self.rng.gauss(0.0, 0.02)
            m.angular_velocity.z = self.rng.gauss(0.0, 0.01)
            m.linear_acceleration.x = 0.3 * math.sin(2 * math.pi * 3.6 * t) + self.rng.gauss(0, 0.05)
            m.linear_acceleration.z = 9.81 + self.rng.gauss(0, 0.08)
            self.n += 1
            if not published((self.pub, m)):
                return

    def on_second(self) -> None:
        level = WARN if self.lost else OK
        self.publish_diagnostics(
            self.status("imu", "adis16495-spi0", level, "timeout" if self.lost else "OK", rate=self.n)
        )
        self.n = 0


class StateEstimator(QuadNode):
    """The state estimator (an EKF over the IMU and the legs' kinematics): every IMU sample updated
    (rejected when its stamp is more than 0.25 s off the filter's time), the legs' velocity from the
    gait state (the legs' kinematics); /quad/odom and odom -> base_link on /tf at 50 Hz;
    /quad/state_estimator/health latched (OK, or DEGRADED without a valid IMU sample for 0.5 s:
    leg odometry only, the locomotion controller stands)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("state_estimator", "quad", fault_dir)
        self.declare_parameter("imu_max_delay", 0.25)
        self.declare_parameter("publish_rate", ODOM_HZ)
        self.odom_pub = self.create_publisher(Odometry, "/quad/odom", RELIABLE)
        self.tf_pub = self.create_publisher(TransformStamped, "/tf", 100)
        self.health_pub = self.create_publisher(String, "/quad/state_estimator/health", LATCHED)
        self.imu_sub = self.create_subscription(Imu, "/quad/imu/data", self.on_imu, SENSOR)
        self.create_subscription(JointState, "/quad/gait_state", self.on_gait, SENSOR)
        self.x = self.y = self.yaw = 0.0
        self.v = (0.0, 0.0, 0.0)
        self.gyro_bias = 0.0
        self.imu_ok_at = None  # no IMU sample yet: initializing
        self.imu_n = self.rejected = self.joints_n = 0
        self.health = None
        self.last = time.monotonic()
        self.odom = Odometry()
        self.odom.header.frame_id, self.odom.child_frame_id = "odom", "base_link"
        self.set_health("INITIALIZING: waiting for the IMU")
        self.create_timer(1.0 / ODOM_HZ, self.update)
        self.create_timer(1.0, self.on_second)

    def on_fault(self, fault: str | None) -> None:
        if fault == "reliable":  # a redeployed state_estimator.yaml asks for a reliable IMU stream
            self.get_logger().info(
                "Parameters reloaded from state_estimator.yaml: re-creating the IMU "
                "subscription (reliability: reliable)"
            )
            self.destroy_subscription(self.imu_sub)
            self.imu_sub = self.create_subscription(
                Imu,
                "/quad/imu/data",
                self.on_imu,
                QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE),
            )

    def set_health(self, h: str) -> None:
        self.health = h
        self.health_pub.publish(String(data=h))

    def on_imu(self, msg: Imu) -> None:
        age = time.time() - secs(msg.header.stamp)
        if abs(age) > 0.25:
            self.rejected += 1
            if self.throttle("stale", 2.0):
                self.get_logger().error(
                    f"IMU measurement {age:.2f} s behind the filter time: rejected "
                    f"({self.rejected} so far); check the time synchronisation"
                )
            return
        self.imu_ok_at = time.monotonic()
        self.imu_n += 1
        self.gyro_bias = 0.999 * self.gyro_bias + 0.001 * msg.angular_velocity.z

    def on_gait(self, msg: JointState) -> None:
        self.joints_n += 1
        if len(msg.velocity) >= 3:
            self.v = (msg.velocity[0], msg.velocity[1], msg.velocity[2])

    def update(self) -> None:
        now = time.monotonic()
        dt, self.last = now - self.last, now
        gap = now - self.imu_ok_at if self.imu_ok_at is not None else 0.0
        if self.imu_ok_at is not None and self.health.startswith("INITIALIZING"):
            self.get_logger().info("First IMU measurement: filter initialized")
            self.set_health("OK")
        elif gap > 0.5 and self.health.startswith("OK"):
            why = (
                f"{self.rejected} IMU samples rejected" if self.rejected else f"no IMU sample for {gap:.1f} s"
            )
            self.get_logger().error(
                f"Filter degraded: no valid IMU measurement for 0.5 s ({why}): leg odometry only"
            )
            self.set_health(f"DEGRADED: {why}")
        elif gap < 0.1 and self.health.startswith("DEGRADED"):
            self.get_logger().info("IMU measurements valid again: filter nominal")
            self.set_health("OK")
            self.rejected = 0
        vx, vy, wz = self.v
        self.yaw = wrap(self.yaw + wz * dt)
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        self.x += (c * vx - s * vy) * dt
        self.y += (s * vx + c * vy) * dt
        stamp = self.get_clock().now().to_msg()
        o = self.odom
        o.header.stamp = stamp
        o.pose.pose.position.x, o.pose.pose.position.y = self.x, self.y
        o.pose.pose.orientation.z, o.pose.pose.orientation.w = math.sin(self.yaw / 2), math.cos(self.yaw / 2)
        o.twist.twist.linear.x, o.twist.twist.linear.y, o.twist.twist.angular.z = vx, vy, wz
        var = 0.002 if self.health.startswith("OK") else 0.05
        o.pose.covariance[0] = o.pose.covariance[7] = o.pose.covariance[35] = var
        self.odom_pub.publish(o)
        self.tf_pub.publish(transform("odom", "base_link", (self.x, self.y, 0.48), stamp, self.yaw))

    def on_second(self) -> None:
        level = ERROR if self.health.startswith("DEGRADED") else OK
        self.publish_diagnostics(
            self.status(
                "ekf",
                "state-estimator",
                level,
                self.health,
                imu_rate=self.imu_n,
                leg_odom_rate=self.joints_n,
                rejected=self.rejected,
            )
        )
        self.imu_n = self.joints_n = 0


class RobotStatePublisher(QuadNode):
    """The robot description latched on /quad/robot_description, the sensor mounts on /tf_static once
    (latched), base_link -> each foot on /tf at 10 Hz from the newest joint state."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("robot_state_publisher", "quad", fault_dir)
        urdf = "<robot name='quad_inspector'>" + "<link/>" * 30 + "</robot>"
        self.declare_parameter("robot_description", urdf)
        self.declare_parameter("publish_frequency", 10.0)
        desc = self.create_publisher(String, "/quad/robot_description", LATCHED)
        desc.publish(String(data=urdf))
        self.static = self.create_publisher(TransformStamped, "/tf_static", STATIC_TF)
        now = self.get_clock().now().to_msg()
        for child, xyz in (
            ("lidar_link", (0.25, 0.0, 0.18)),
            ("imu_link", (0.0, 0.0, 0.05)),
            ("ptz_base", (0.3, 0.0, 0.12)),
            ("thermal_link", (0.32, 0.0, 0.08)),
            ("gas_sensor_link", (-0.2, 0.0, 0.1)),
            ("mic_link", (0.0, 0.1, 0.1)),
        ):
            self.static.publish(transform("base_link", child, xyz, now))
        self.tf_pub = self.create_publisher(TransformStamped, "/tf", 100)
        self.q = None
        self.create_subscription(JointState, "/quad/joint_states", self.on_joints, RELIABLE)
        self.create_timer(1 / 10.0, self.publish_feet)
        self.get_logger().info("Robot initialized: 17 links, 12 movable joints")

    def on_joints(self, msg: JointState) -> None:
        self.q = msg.position

    def publish_feet(self) -> None:
        if self.q is None or len(self.q) < 12:
            return
        stamp = self.get_clock().now().to_msg()
        for i, leg in enumerate(LEGS):
            hfe, kfe = self.q[3 * i + 1], self.q[3 * i + 2]
            x = (0.3 if i < 2 else -0.3) + 0.25 * math.sin(hfe) + 0.25 * math.sin(hfe + kfe)
            z = -0.25 * math.cos(hfe) - 0.25 * math.cos(hfe + kfe)
            self.tf_pub.publish(
                transform("base_link", f"{leg}_foot", (x, 0.2 if i % 2 == 0 else -0.2, z), stamp)
            )


# --- lidar and mapping --------------------------------------------------------------------------------


class LidarDriver(QuadNode):
    """The 3D lidar (a 32-beam spinning unit on Ethernet): /quad/lidar/points (PointCloud2, ~16k
    points, ~262 KB) at 10 Hz from its packet thread, stamped at the scan (PTP), sensor QoS."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("lidar_driver", "quad/lidar", fault_dir)
        self.declare_parameter("device_ip", "10.0.2.20")
        self.declare_parameter("rpm", 600)
        self.pub = self.create_publisher(PointCloud2, "/quad/lidar/points", SENSOR)
        self.scans = [self.make_cloud(k) for k in range(4)]
        self.n = 0
        self.lost_packets = 0
        self.get_logger().info("Lidar at 10.0.2.20: 32 beams, 600 rpm, PTP master locked")
        self.create_timer(1.0, self.on_second)
        threading.Thread(target=self.stream, daemon=True, name="packets").start()

    def make_cloud(self, k: int) -> PointCloud2:
        rng = np.random.default_rng(k)
        az = np.linspace(-math.pi, math.pi, 512, endpoint=False)
        el = np.linspace(-0.4, 0.3, 32)
        a, e = np.meshgrid(az, el)
        r = 3.0 + 6.0 * rng.random(a.shape) ** 2
        pts = np.column_stack(
            [
                (r * np.cos(e) * np.cos(a)).ravel(),
                (r * np.cos(e) * np.sin(a)).ravel(),
                (r * np.sin(e)).ravel() + 0.6,
                rng.random(a.size) * 100,
            ]
        )
        pts = np.ascontiguousarray(pts, dtype=np.float32)
        m = PointCloud2(
            height=32,
            width=512,
            fields=POINT_FIELDS,
            is_bigendian=False,
            point_step=16,
            row_step=16 * 512,
            is_dense=True,
        )
        m.header.frame_id = "lidar_link"
        m.data = pts.tobytes()
        return m

    def stream(self) -> None:
        k = 0
        for _ in paced(LIDAR_HZ, jitter=0.001, rng=self.rng):
            k += 1
            m = self.scans[k % 4]
            stamp = time.time() - 0.05  # the scan's mid-time
            if self.fault == "stale":  # the lidar lost its PTP master: its free-running clock is 2 s behind
                stamp -= 2.0
            m.header.stamp = to_stamp(stamp)
            self.n += 1
            if not published((self.pub, m)):
                return

    def on_second(self) -> None:
        if self.rng.random() < 1 / 35:
            lost = self.rng.randint(1, 4)
            self.lost_packets += lost
            self.get_logger().warn(f"Dropped {lost} UDP packets in the last scan (socket buffer full)")
        self.publish_diagnostics(
            self.status("scan", "lidar-10.0.2.20", OK, "OK", rate=self.n, lost_packets=self.lost_packets)
        )
        self.n = 0


class ElevationMapping(QuadNode):
    """Robot-centric elevation mapping: each lidar scan fused into the 6 x 6 m map (clouds whose
    stamp can't be transformed, more than 0.5 s old, dropped with an ERROR), every 5th scan the
    heavy update (variance propagation, smoothing and inpainting: ~40 ms of CPU) and
    /quad/elevation_mapping/elevation_map (OccupancyGrid, traversability) published, 2 Hz."""

    SIZE, RES = 120, 0.05

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("elevation_mapping", "quad", fault_dir)
        self.declare_parameter("length_in_x", 6.0)
        self.declare_parameter("resolution", self.RES)
        self.declare_parameter("fusion_every_n_scans", 5)
        self.map_pub = self.create_publisher(OccupancyGrid, "~/elevation_map", RELIABLE)
        self.create_subscription(PointCloud2, "/quad/lidar/points", self.on_cloud, SENSOR)
        self.height = np.zeros((self.SIZE, self.SIZE), dtype=np.float32)
        self.var = np.ones((self.SIZE, self.SIZE), dtype=np.float32)
        self.scans = 0
        self.dropped = 0
        self.updated_at = time.monotonic()
        self.create_timer(1.0, self.on_second)

    def on_cloud(self, msg: PointCloud2) -> None:
        now = time.time()
        stamp = secs(msg.header.stamp)
        if now - stamp > 0.5:
            self.dropped += 1
            if self.throttle("extrapolation", 1.0):
                self.get_logger().error(
                    f"Lookup would require extrapolation into the past. Requested time {stamp:.6f} but the "
                    f"earliest data is at time {now - 0.5:.6f}, when looking up transform from frame "
                    f"[lidar_link] to frame [odom]: point cloud dropped"
                )
            return
        pts = np.frombuffer(msg.data, dtype=np.float32).reshape(-1, 4)[::16]
        ix = np.clip(((pts[:, 0] + 3.0) / self.RES).astype(np.int32), 0, self.SIZE - 1)
        iy = np.clip(((pts[:, 1] + 3.0) / self.RES).astype(np.int32), 0, self.SIZE - 1)
        self.height[iy, ix] = 0.8 * self.height[iy, ix] + 0.2 * pts[:, 2]
        self.var[iy, ix] *= 0.9
        self.scans += 1
        self.updated_at = time.monotonic()
        if self.scans % self.get_parameter("fusion_every_n_scans").value == 0:
            self.fuse(msg.header.stamp)

    def fuse(self, stamp) -> None:
        h = self.height
        for _ in range(12):  # smoothing and inpainting of the holes
            h = (h + np.roll(h, 1, 0) + np.roll(h, -1, 0) + np.roll(h, 1, 1) + np.roll(h, -1, 1)) / 5.0
            self.var = np.minimum(self.var * 1.001 + 1e-4, 1.0)
        big = np.kron(h, np.ones((2, 2), dtype=np.float32))
        slope = np.hypot(*np.gradient(big))
        rough = np.abs(big - np.median(big.reshape(-1, 64), axis=1).repeat(64).reshape(big.shape))
        trav = np.clip((slope * 400 + rough * 100), 0, 100)[::2, ::2]
        self.height = h
        m = grid_msg("odom", self.RES, self.SIZE, self.SIZE, trav, -3.0, -3.0)
        m.header.stamp = stamp
        self.map_pub.publish(m)

    def on_second(self) -> None:
        age = time.monotonic() - self.updated_at
        level = OK if age < 2.0 else WARN
        if age > 2.0 and self.throttle("old", 5.0):
            self.get_logger().warn(f"Elevation map not updated for {age:.1f} s (no usable point cloud)")
        self.publish_diagnostics(
            self.status(
                "map_update",
                "elevation-mapping",
                level,
                "OK" if level == OK else "map not updated",
                scans=self.scans,
                dropped=self.dropped,
            )
        )


class SiteMapLoader(QuadNode):
    """The site map loader at boot: loads the surveyed site's 2D map, latches it on /quad/map
    (transient local) for the planner and exits 0 after ~6 s (the latched map goes with it)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("site_map_loader", "quad", fault_dir)
        self.declare_parameter("yaml_filename", "/opt/quad/maps/plant_b_level0.yaml")
        self.pub = self.create_publisher(OccupancyGrid, "/quad/map", LATCHED)
        cells = np.zeros((300, 300), dtype=np.int8)
        cells[:4, :] = cells[-4:, :] = cells[:, :4] = cells[:, -4:] = 100  # the hall's walls
        cells[100:130, 140:170] = 100  # a pump skid
        m = grid_msg("map", 0.05, 300, 300, cells, -5.0, -3.0)
        m.header.stamp = self.get_clock().now().to_msg()
        self.pub.publish(m)
        self.get_logger().info("Loading yaml file: /opt/quad/maps/plant_b_level0.yaml: 300 x 300 @ 0.05 m")
        self.t0 = time.monotonic()
        self.create_timer(1.0, self.check)

    def check(self) -> None:
        if time.monotonic() - self.t0 > 6.0 and not STOPPING.is_set():
            self.get_logger().info("Map latched on /quad/map: loader done")
            STOPPING.set()


# --- navigation (nav2-style, one component_container_mt) ----------------------------------------------


class NavLifecycle(Diagnosed, Bonded, LifecycleNode):
    """A nav2 server: a lifecycle node, configured and activated by the lifecycle manager, bonded."""

    def __init__(self, name: str, fault_dir: Path) -> None:
        LifecycleNode.__init__(self, name, namespace="quad")
        hook(self, fault_dir)
        self.active = False
        self.actions_group = ReentrantCallbackGroup()

    def on_configure(self, state) -> TransitionCallbackReturn:
        self.get_logger().info("Configuring")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        self.get_logger().info("Activating")
        self.active = True
        self.start_bond()
        return super().on_activate(state)

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        self.get_logger().info("Deactivating")
        self.active = False
        return super().on_deactivate(state)


class PlannerServer(NavLifecycle):
    """``/quad/planner_server/compute_path`` (GetPlan): a grid search over the site map's costmap
    (50-120 ms); each plan also published on /quad/plan (Path, reliable), its id in ``frame_id``."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("planner_server", fault_dir)
        self.declare_parameter("planner_plugin", "GridBased")
        self.declare_parameter("expected_planner_frequency", 1.0)
        self.costmap = None
        self.plan_id = 0
        self.plan_pub = self.create_publisher(PathMsg, "/quad/plan", RELIABLE)
        self.create_subscription(OccupancyGrid, "/quad/map", self.on_map, LATCHED)
        self.create_service(
            GetPlan, "~/compute_path", self.on_plan, callback_group=MutuallyExclusiveCallbackGroup()
        )

    def on_map(self, msg: OccupancyGrid) -> None:
        self.costmap = (
            np.frombuffer(bytes(array.array("b", msg.data)), dtype=np.int8)
            .reshape(msg.info.height, msg.info.width)
            .astype(np.float32)
        )
        self.get_logger().info(
            f"Received a {msg.info.width} X {msg.info.height} map @ {msg.info.resolution:.2f} m/pix"
        )

    def on_plan(self, request, response):
        t0 = time.monotonic()
        if not self.active:
            self.get_logger().warn("Planner server inactive: request rejected")
            return response
        cm = self.costmap if self.costmap is not None else np.zeros((300, 300), dtype=np.float32)
        inflated = cm.copy()
        for _ in range(self.rng.randint(6, 14)):  # inflation and the wavefront's expansions
            inflated = np.maximum(
                inflated, 0.9 * np.maximum(np.roll(inflated, 1, 0), np.roll(inflated, 1, 1))
            )
            inflated = np.maximum(
                inflated, 0.9 * np.maximum(np.roll(inflated, -1, 0), np.roll(inflated, -1, 1))
            )
        if self.fault == "slow":  # the global costmap rebuilt at 1 cm for every request (a bad params file)
            time.sleep(8.0)
        s, g = request.start.pose.position, request.goal.pose.position
        n = max(2, int(math.hypot(g.x - s.x, g.y - s.y) / 0.1))
        bend = self.rng.uniform(-0.3, 0.3)
        self.plan_id += 1
        path = PathMsg()
        path.header.frame_id = f"plan:{self.plan_id}"
        path.header.stamp = self.get_clock().now().to_msg()
        for k in range(n + 1):
            u = k / n
            ps = PoseStamped()
            ps.header.frame_id = "odom"
            ps.pose.position.x = s.x + (g.x - s.x) * u - (g.y - s.y) * bend * math.sin(math.pi * u) * 0.2
            ps.pose.position.y = s.y + (g.y - s.y) * u + (g.x - s.x) * bend * math.sin(math.pi * u) * 0.2
            path.poses.append(ps)
        response.plan = path
        self.plan_pub.publish(path)
        took = time.monotonic() - t0
        if took > 1.0:
            self.get_logger().warn(
                f"Planner loop missed its desired rate of 1.0 Hz: computing the path took {took:.2f} s"
            )
        return response


class ControllerServer(NavLifecycle):
    """The path follower: ``/quad/follow_path`` (order = the plan's id, from /quad/plan) runs the
    control loop at 20 Hz in its execute callback (regulated pure pursuit on /quad/odom), checks the
    local costmap (the elevation map, older than 2.5 s: aborted) and its progress (0.25 m in 10 s),
    publishes /quad/cmd_vel_nav; ``max_vel_x`` a runtime parameter."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("controller_server", fault_dir)
        self.declare_parameter("controller_frequency", 20.0)
        self.declare_parameter("max_vel_x", 0.5)
        self.declare_parameter("xy_goal_tolerance", 0.25)
        self.add_on_set_parameters_callback(self.on_params)
        self.cmd_pub = self.create_publisher(Twist, "/quad/cmd_vel_nav", COMMAND)
        self.create_subscription(PathMsg, "/quad/plan", self.on_plan, RELIABLE)
        self.plans: dict[str, list[tuple[float, float]]] = {}
        self.costmap: LocalCostmap | None = None  # its costmap node, spun in its own thread
        ActionServer(
            self,
            Fibonacci,
            "/quad/follow_path",
            execute_callback=self.execute,
            callback_group=self.actions_group,
            cancel_callback=lambda g: CancelResponse.ACCEPT,
        )

    def on_params(self, params) -> SetParametersResult:
        for p in params:
            if p.name == "max_vel_x":
                if not 0.1 <= p.value <= 1.0:
                    return SetParametersResult(successful=False, reason="max_vel_x out of 0.1-1.0 m/s")
                self.get_logger().info(f"max_vel_x set to {p.value:.2f} m/s")
        return SetParametersResult(successful=True)

    def on_plan(self, msg: PathMsg) -> None:
        self.plans[msg.header.frame_id] = [(p.pose.position.x, p.pose.position.y) for p in msg.poses]
        while len(self.plans) > 10:
            self.plans.pop(next(iter(self.plans)))

    def stop(self) -> None:
        self.cmd_pub.publish(Twist())

    def execute(self, goal):
        key = f"plan:{goal.request.order}"
        end = time.monotonic() + 1.0
        while key not in self.plans and time.monotonic() < end:
            time.sleep(0.02)
        if key not in self.plans or not self.active:
            self.get_logger().error(f"Received a goal for unknown {key}: aborting")
            goal.abort()
            return Fibonacci.Result()
        path = self.plans[key]
        self.get_logger().info(f"Received a goal, begin computing control effort ({len(path)} poses)")
        gx, gy = path[-1]
        period = 1.0 / self.get_parameter("controller_frequency").value
        progress_at, progress_pose = time.monotonic(), self.costmap.pose
        blocked_at = time.monotonic() + self.rng.uniform(2.0, 12.0) if self.rng.random() < 0.06 else None
        fb = Fibonacci.Feedback()
        k = ahead = 0
        nxt = time.monotonic()
        while alive():
            nxt += period
            time.sleep(max(0.0, nxt - time.monotonic()))
            now = time.monotonic()
            x, y, yaw = self.costmap.pose
            dist = math.hypot(gx - x, gy - y)
            if dist < self.get_parameter("xy_goal_tolerance").value:
                self.stop()
                self.get_logger().info("Reached the goal!")
                goal.succeed()
                return Fibonacci.Result(sequence=[int(dist * 100)])
            age = None if self.costmap.map_stamp is None else time.time() - self.costmap.map_stamp
            if age is None or age > 2.5:
                self.stop()
                self.get_logger().error(
                    f"Elevation map is {'missing' if age is None else f'{age:.1f} s old'}: "
                    "the local costmap is not current; aborting FollowPath"
                )
                goal.abort()
                return Fibonacci.Result()
            if blocked_at is not None and now > blocked_at:
                self.stop()
                self.get_logger().warn(
                    "Collision ahead in the local costmap (a pallet jack across the "
                    "path): aborting FollowPath"
                )
                goal.abort()
                return Fibonacci.Result()
            if math.hypot(x - progress_pose[0], y - progress_pose[1]) > 0.25:
                progress_at, progress_pose = now, (x, y)
            elif now - progress_at > 10.0:
                self.stop()
                self.get_logger().error("Failed to make progress: the robot moved less than 0.25 m in 10 s")
                goal.abort()
                return Fibonacci.Result()
            # regulated pure pursuit: the path point 0.6 m ahead of the robot's progress along it
            while ahead < len(path) - 1 and math.hypot(path[ahead][0] - x, path[ahead][1] - y) < 0.6:
                ahead += 1
            look = path[ahead]
            err = wrap(math.atan2(look[1] - y, look[0] - x) - yaw)
            vmax = self.get_parameter("max_vel_x").value
            t = Twist()
            t.angular.z = clamp(1.5 * err, -0.8, 0.8)
            t.linear.x = (
                vmax * max(0.0, math.cos(err)) * min(1.0, dist / 0.6 + 0.2) if abs(err) < 0.9 else 0.0
            )
            self.cmd_pub.publish(t)
            k += 1
            if k % 4 == 0:
                fb.sequence = [int(dist * 100)]
                goal.publish_feedback(fb)
        return Fibonacci.Result()  # shutting down


class LocalCostmap(Diagnosed, Node):
    """The controller's local costmap (``/quad/local_costmap/local_costmap``, as nav2 makes one), spun
    by its own executor thread: the robot's pose from /quad/odom, the elevation map as its obstacle
    layer; ``~/costmap`` (OccupancyGrid) at 1 Hz."""

    private_executor = True

    def __init__(self, fault_dir: Path) -> None:
        Node.__init__(self, "local_costmap", namespace="quad/local_costmap")
        hook(self, fault_dir)
        self.declare_parameter("update_frequency", 5.0)
        self.declare_parameter("publish_frequency", 1.0)
        self.pose = (0.0, 0.0, 0.0)
        self.map_stamp = None
        self.grid = None
        self.pub = self.create_publisher(OccupancyGrid, "~/costmap", RELIABLE)
        self.create_subscription(Odometry, "/quad/odom", self.on_odom, RELIABLE)
        self.create_subscription(
            OccupancyGrid, "/quad/elevation_mapping/elevation_map", self.on_map, RELIABLE
        )
        self.create_timer(1.0, self.publish_costmap)

    def on_odom(self, msg: Odometry) -> None:
        q = msg.pose.pose.orientation
        self.pose = (msg.pose.pose.position.x, msg.pose.pose.position.y, 2 * math.atan2(q.z, q.w))

    def on_map(self, msg: OccupancyGrid) -> None:
        self.map_stamp = secs(msg.header.stamp)
        self.grid = msg

    def publish_costmap(self) -> None:
        if self.grid is not None:
            self.grid.header.stamp = self.get_clock().now().to_msg()
            self.grid.info.origin.position.x, self.grid.info.origin.position.y = (
                self.pose[0] - 3.0,
                self.pose[1] - 3.0,
            )
            self.pub.publish(self.grid)


class BehaviorServer(NavLifecycle):
    """nav2's behaviours: ``/quad/backup`` (order = cm to back up at 0.1 m/s on /quad/cmd_vel_nav)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("behavior_server", fault_dir)
        self.declare_parameter("behavior_plugins", ["spin", "backup", "wait"])
        self.cmd_pub = self.create_publisher(Twist, "/quad/cmd_vel_nav", COMMAND)
        ActionServer(
            self,
            Fibonacci,
            "/quad/backup",
            execute_callback=self.execute,
            callback_group=self.actions_group,
            cancel_callback=lambda g: CancelResponse.ACCEPT,
        )

    def execute(self, goal):
        dist = goal.request.order / 100.0
        self.get_logger().info(f"Running backup ({dist:.2f} m)")
        t = Twist()
        t.linear.x = -0.1
        end = time.monotonic() + dist / 0.1
        while alive() and time.monotonic() < end:
            self.cmd_pub.publish(t)
            time.sleep(0.05)
        self.cmd_pub.publish(Twist())
        self.get_logger().info("backup completed successfully")
        goal.succeed()
        return Fibonacci.Result(sequence=[goal.request.order])


class BtNavigator(NavLifecycle):
    """``/quad/navigate_to_pose`` (order = the waypoint's index): compute the path (4 s timeout),
    follow it, on a failure back up 0.2 m and try again (3 attempts); feedback at 5 Hz while
    navigating (distance remaining in cm, recoveries, s elapsed)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("bt_navigator", fault_dir)
        self.declare_parameter(
            "default_nav_to_pose_bt_xml", "/opt/quad/bt/navigate_w_replanning_and_recovery.xml"
        )
        self.declare_parameter("planner_timeout", 4.0)
        self.clients_group = ReentrantCallbackGroup()
        self.planner = self.create_client(
            GetPlan, "/quad/planner_server/compute_path", callback_group=self.clients_group
        )
        self.follow = ActionClient(self, Fibonacci, "/quad/follow_path", callback_group=self.clients_group)
        self.backup = ActionClient(self, Fibonacci, "/quad/backup", callback_group=self.clients_group)
        self.costmap: LocalCostmap | None = None  # the robot's pose, as nav2 looks it up in its tf buffer
        ActionServer(
            self,
            Fibonacci,
            "/quad/navigate_to_pose",
            execute_callback=self.execute,
            callback_group=self.actions_group,
            cancel_callback=lambda g: CancelResponse.ACCEPT,
        )

    @property
    def pose(self) -> tuple[float, float]:
        return self.costmap.pose[:2]

    def execute(self, goal):
        name, gx, gy = WAYPOINTS[goal.request.order % len(WAYPOINTS)]
        self.get_logger().info(
            f"Begin navigating from ({self.pose[0]:.2f}, {self.pose[1]:.2f}) to {name} ({gx:.2f}, {gy:.2f})"
        )
        t0 = time.monotonic()
        recoveries = 0
        fb = Fibonacci.Feedback()

        def feedback() -> None:
            fb.sequence = [
                int(math.hypot(gx - self.pose[0], gy - self.pose[1]) * 100),
                recoveries,
                int(time.monotonic() - t0),
            ]
            goal.publish_feedback(fb)

        for _attempt in range(3):
            if not alive():
                return Fibonacci.Result()  # shutting down
            req = GetPlan.Request()
            req.start.pose.position.x, req.start.pose.position.y = self.pose
            req.goal.pose.position.x, req.goal.pose.position.y = gx, gy
            timeout = self.get_parameter("planner_timeout").value
            fut = self.planner.call_async(req)
            res = wait_for(fut, timeout, feedback)
            if res is None:
                self.planner.remove_pending_request(fut)
                self.get_logger().error(
                    f"Timed out waiting for /quad/planner_server/compute_path ({timeout:.0f} s): "
                    "ComputePathToPose failed"
                )
            elif not res.plan.poses:
                self.get_logger().warn("ComputePathToPose returned no path")
            else:
                pid = int(res.plan.header.frame_id.split(":")[1])
                gh = wait_for(self.follow.send_goal_async(Fibonacci.Goal(order=pid)), 2.0)
                if gh is not None and gh.accepted:
                    r = wait_for(gh.get_result_async(), 120.0, feedback)
                    if r is not None and r.status == 4:
                        self.get_logger().info(
                            f"Goal succeeded: {name} reached in {time.monotonic() - t0:.1f} s"
                        )
                        goal.succeed()
                        return Fibonacci.Result(sequence=[goal.request.order])
                if not alive():
                    return Fibonacci.Result()  # shutting down
                self.get_logger().warn("FollowPath failed: running the recovery (backup 0.2 m)")
            recoveries += 1
            if self.backup.server_is_ready():
                gh = wait_for(self.backup.send_goal_async(Fibonacci.Goal(order=20)), 2.0)
                if gh is not None and gh.accepted:
                    wait_for(gh.get_result_async(), 5.0, feedback)
            time.sleep(1.0)
        if not alive():
            return Fibonacci.Result()  # shutting down
        self.get_logger().error(f"Goal failed: navigation to {name} aborted after {recoveries} recoveries")
        goal.abort()
        return Fibonacci.Result()


class LifecycleManager(QuadNode):
    """nav2's lifecycle manager for navigation: configures then activates the planner, controller,
    behaviour servers and the BT navigator at start-up (their ``change_state``), then watches their
    bonds (a heartbeat on /quad/bond, 4 s timeout); ``~/is_active`` (Trigger)."""

    MANAGED = ("planner_server", "controller_server", "behavior_server", "bt_navigator")

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("lifecycle_manager_navigation", "quad", fault_dir)
        self.declare_parameter("node_names", list(self.MANAGED))
        self.declare_parameter("autostart", True)
        self.declare_parameter("bond_timeout", BOND_TIMEOUT)
        self.cli = {n: self.create_client(ChangeState, f"/quad/{n}/change_state") for n in self.MANAGED}
        self.steps = [(n, Transition.TRANSITION_CONFIGURE) for n in self.MANAGED] + [
            (n, Transition.TRANSITION_ACTIVATE) for n in self.MANAGED
        ]
        self.pending = None
        self.active = False
        self.beats: dict[str, float] = {}
        self.broken: set[str] = set()
        self.create_subscription(Header, "/quad/bond", self.on_bond, RELIABLE)
        self.create_service(Trigger, "~/is_active", self.on_is_active)
        self.bringup_timer = self.create_timer(0.2, self.bringup)
        self.create_timer(1.0, self.check_bonds)
        self.get_logger().info("Starting managed nodes bringup...")

    def on_bond(self, msg: Header) -> None:
        self.beats[msg.frame_id.rsplit("/", 1)[-1]] = time.monotonic()

    def on_is_active(self, request, response):
        response.success = self.active and not self.broken
        response.message = "active" if response.success else "inactive"
        return response

    def bringup(self) -> None:
        if not self.steps:
            return
        node, tid = self.steps[0]
        if self.pending is not None:
            sent, fut = self.pending
            if fut.done():
                self.pending = None
                if fut.result() is not None and fut.result().success:
                    self.steps.pop(0)
                    if not self.steps:
                        self.active = True
                        self.bringup_timer.cancel()
                        self.get_logger().info("Managed nodes are active")
                else:
                    self.get_logger().error(f"Failed to change state for node: {node}")
            elif time.monotonic() - sent > 5.0:
                self.cli[node].remove_pending_request(fut)
                self.pending = None
                self.get_logger().warn(f"Timed out changing the state of {node}: retrying")
            return
        if not self.cli[node].service_is_ready():
            return
        self.get_logger().info(
            f"{'Configuring' if tid == Transition.TRANSITION_CONFIGURE else 'Activating'} {node}"
        )
        self.pending = (
            time.monotonic(),
            self.cli[node].call_async(ChangeState.Request(transition=Transition(id=tid))),
        )

    def check_bonds(self) -> None:
        if not self.active:
            return
        now = time.monotonic()
        for n in self.MANAGED:
            late = now - self.beats.get(n, now)
            if late > BOND_TIMEOUT and n not in self.broken:
                self.broken.add(n)
                self.get_logger().error(f"Have not received a heartbeat from {n}: bond broken")
            elif late < 1.0 and n in self.broken:
                self.broken.discard(n)
                self.get_logger().info(f"Bond with {n} restored")
        self.publish_diagnostics(
            self.status(
                "lifecycle",
                "nav2",
                ERROR if self.broken else OK,
                "broken: " + ",".join(sorted(self.broken)) if self.broken else "active",
            )
        )


class TwistMux(QuadNode):
    """twist_mux: /quad/cmd_vel_nav (priority 10), /quad/cmd_vel_dock (20) and /quad/cmd_vel_teleop
    (100, the operator's remote) into /quad/cmd_vel (reliable, keep last 1), each input timing out
    after 0.5 s; the active input latched on /quad/twist_mux/active."""

    INPUTS: ClassVar[dict[str, tuple[str, int]]] = {
        "navigation": ("/quad/cmd_vel_nav", 10),
        "docking": ("/quad/cmd_vel_dock", 20),
        "joystick": ("/quad/cmd_vel_teleop", 100),
    }

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("twist_mux", "quad", fault_dir)
        self.pub = self.create_publisher(Twist, "/quad/cmd_vel", COMMAND)
        self.active_pub = self.create_publisher(String, "~/active", LATCHED)
        self.last: dict[str, float] = {}
        self.active = None
        self.n = 0
        for name, (topic, prio) in self.INPUTS.items():
            self.declare_parameter(f"topics.{name}.priority", prio)
            self.create_subscription(Twist, topic, lambda m, n=name: self.on_twist(n, m), COMMAND)
        self.set_active("idle")
        self.create_timer(1.0, self.on_second)

    def set_active(self, name: str) -> None:
        self.active = name
        self.active_pub.publish(String(data=name))

    def on_twist(self, name: str, msg: Twist) -> None:
        now = time.monotonic()
        self.last[name] = now
        live = [n for n, t in self.last.items() if now - t < 0.5]
        top = max(live, key=lambda n: self.INPUTS[n][1])
        if top != name:
            return
        if self.active != name:
            self.set_active(name)
        self.pub.publish(msg)
        self.n += 1

    def on_second(self) -> None:
        now = time.monotonic()
        if self.active != "idle" and now - self.last.get(self.active, 0.0) > 0.5:
            self.set_active("idle")
        self.publish_diagnostics(self.status("mux", "twist_mux", OK, self.active, rate=self.n))
        self.n = 0


class DockingServer(QuadNode):
    """The docking server: ``~/undock_robot`` (backs off the charger at 0.15 m/s for 4 s on
    /quad/cmd_vel_dock) and ``~/dock_robot``; ``~/state`` latched (DOCKED / UNDOCKED)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("docking_server", "quad", fault_dir)
        self.declare_parameter("dock_id", "dock_main")
        self.cmd_pub = self.create_publisher(Twist, "/quad/cmd_vel_dock", COMMAND)
        self.state_pub = self.create_publisher(String, "~/state", LATCHED)
        self.state_pub.publish(String(data="DOCKED"))
        self.docked = True
        group = ReentrantCallbackGroup()
        ActionServer(
            self,
            Fibonacci,
            "~/undock_robot",
            execute_callback=self.undock,
            callback_group=group,
            cancel_callback=lambda g: CancelResponse.ACCEPT,
        )
        ActionServer(
            self,
            Fibonacci,
            "~/dock_robot",
            execute_callback=self.dock,
            callback_group=group,
            cancel_callback=lambda g: CancelResponse.ACCEPT,
        )
        self.get_logger().info("Docking server: robot on charger 'dock_main'")

    def drive(self, goal, v: float, seconds: float) -> None:
        t = Twist()
        t.linear.x = v
        fb = Fibonacci.Feedback()
        t0 = time.monotonic()
        while alive() and time.monotonic() - t0 < seconds:
            self.cmd_pub.publish(t)
            fb.sequence = [int(100 * (time.monotonic() - t0) / seconds)]
            goal.publish_feedback(fb)
            time.sleep(0.05)
        self.cmd_pub.publish(Twist())

    def undock(self, goal):
        self.get_logger().info("Undocking from charger 'dock_main'")
        self.drive(goal, -0.15, 4.0)
        self.docked = False
        self.state_pub.publish(String(data="UNDOCKED"))
        self.get_logger().info("Undocked: robot clear of the charger")
        goal.succeed()
        return Fibonacci.Result(sequence=[1])

    def dock(self, goal):
        self.get_logger().info("Docking on charger 'dock_main'")
        self.drive(goal, 0.1, 5.0)
        self.docked = True
        self.state_pub.publish(String(data="DOCKED"))
        goal.succeed()
        return Fibonacci.Result(sequence=[1])


# --- mission ------------------------------------------------------------------------------------------


class MissionExecutive(QuadNode):
    """The inspection mission's behaviour tree, ticked at 10 Hz: WaitForNavigation -> Undock, then for
    each waypoint: NavigateToWaypoint (the navigate_to_pose action) -> PtzOn (the PTZ camera
    activated) -> PtzPreset (move_to_preset) -> ThermalCapture (3 s timeout, one retry) -> GasCheck
    (a reading younger than 3 s) -> Listen (3 s for acoustic leak events) -> PtzOff -> the next;
    /quad/mission/status latched, /quad/mission/report per waypoint, ``~/get_status`` (Trigger)."""

    TIMEOUTS: ClassVar[dict[str, float]] = {
        "navigate": 150.0,
        "undock": 15.0,
        "preset": 5.0,
        "thermal": 3.0,
        "ptz_state": 2.0,
        "nav_active": 2.0,
    }

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("mission_executive", "quad", fault_dir)
        self.declare_parameter("mission_file", "/opt/quad/missions/plant_b_daily_round.yaml")
        self.declare_parameter("listen_s", 3.0)
        self.status_pub = self.create_publisher(String, "/quad/mission/status", LATCHED)
        self.report_pub = self.create_publisher(String, "/quad/mission/report", RELIABLE)
        self.create_subscription(Float32, "/quad/inspection/gas/reading", self.on_gas, RELIABLE)
        self.create_subscription(String, "/quad/inspection/acoustic/leak", self.on_leak, RELIABLE)
        self.srv = {
            "thermal": self.create_client(Trigger, "/quad/inspection/thermal_camera/capture"),
            "ptz_state": self.create_client(ChangeState, "/quad/inspection/ptz_camera/change_state"),
            "nav_active": self.create_client(Trigger, "/quad/lifecycle_manager_navigation/is_active"),
        }
        self.act = {
            "navigate": ActionClient(self, Fibonacci, "/quad/navigate_to_pose"),
            "undock": ActionClient(self, Fibonacci, "/quad/docking_server/undock_robot"),
            "preset": ActionClient(self, Fibonacci, "/quad/inspection/ptz_camera/move_to_preset"),
        }
        self.create_service(Trigger, "~/get_status", self.on_get_status)
        self.gas = None
        self.gas_at = -1e9
        self.leaks: list[str] = []
        self.wp = 0
        self.round = 1
        self.report: dict = {}
        self.state = None
        self.since = 0.0
        self.pending = None
        self.wait_until = 0.0
        self.tries = 0
        self.done_wps = 0
        self.set_state("WaitForNavigation")
        self.create_timer(0.1, self.tick)
        self.create_timer(1.0, self.on_second)

    def on_gas(self, msg: Float32) -> None:
        self.gas, self.gas_at = msg.data, time.monotonic()

    def on_leak(self, msg: String) -> None:
        self.leaks.append(msg.data)

    def on_get_status(self, request, response):
        response.success = True
        response.message = json.dumps(
            {
                "state": self.state,
                "waypoint": WAYPOINTS[self.wp][0],
                "round": self.round,
                "inspected": self.done_wps,
            }
        )
        return response

    def set_state(self, s: str) -> None:
        self.state, self.since = s, time.monotonic()
        self.status_pub.publish(
            String(data=f"{s} {WAYPOINTS[self.wp][0]}" if s not in ("WaitForNavigation", "Undock") else s)
        )

    def advance(self, s: str) -> None:
        self.tries = 0
        self.set_state(s)

    def call(self, kind: str, request) -> None:
        self.pending = (kind, time.monotonic(), self.srv[kind].call_async(request), "call")

    def goal(self, kind: str, order: int) -> None:
        self.pending = (
            kind,
            time.monotonic(),
            self.act[kind].send_goal_async(Fibonacci.Goal(order=order)),
            "goal",
        )

    def ready(self, kind: str) -> bool:
        return self.srv[kind].service_is_ready() if kind in self.srv else self.act[kind].server_is_ready()

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
                cli = self.srv[kind]
                cli.remove_pending_request(fut)
                self.get_logger().error(
                    f"Timed out waiting for {cli.srv_name} ({self.TIMEOUTS[kind]:.0f} s) "
                    f"in {self.state} at {WAYPOINTS[self.wp][0]}"
                )
            else:
                self.get_logger().error(
                    f"{self.state}: action {self.act[kind]._action_name} gave no result in "
                    f"{self.TIMEOUTS[kind]:.0f} s"
                )
            self.done(kind, None)

    def retry(self, why: str, wait: float) -> None:
        self.tries += 1
        if self.tries >= 3:
            self.get_logger().error(f"{self.state} failed {self.tries} times in a row ({why})")
        else:
            self.get_logger().warn(f"{self.state} failed ({why}): retrying ({self.tries})")
        self.wait_until = time.monotonic() + wait
        self.set_state(self.state)

    def skip(self, why: str) -> None:
        """An inspection step failed for good: the waypoint is reported incomplete, the round goes on."""
        self.get_logger().error(f"Inspection at {WAYPOINTS[self.wp][0]} incomplete: {why}")
        self.report["incomplete"] = why
        self.advance("PtzOff")

    def tick(self) -> None:
        now = time.monotonic()
        if self.pending is not None:
            self.poll(now)
            return
        if now < self.wait_until:
            return
        s = self.state
        if s == "WaitForNavigation":
            if self.ready("nav_active"):
                self.call("nav_active", Trigger.Request())
        elif s == "Undock" and self.ready("undock"):
            self.goal("undock", 0)
        elif s == "Navigate" and self.ready("navigate"):
            name = WAYPOINTS[self.wp][0]
            self.get_logger().info(f"Round {self.round}: walking to {name}")
            self.report = {"waypoint": name, "round": self.round}
            self.goal("navigate", self.wp)
        elif s == "PtzOn" and self.ready("ptz_state"):
            self.call(
                "ptz_state", ChangeState.Request(transition=Transition(id=Transition.TRANSITION_ACTIVATE))
            )
        elif s == "PtzPreset" and self.ready("preset"):
            self.goal("preset", self.wp + 1)
        elif s == "Thermal" and self.ready("thermal"):
            self.call("thermal", Trigger.Request())
        elif s == "GasCheck":
            if now - self.gas_at < 3.0:
                self.report["ch4_lel"] = round(self.gas, 2)
                self.get_logger().info(f"Gas at {WAYPOINTS[self.wp][0]}: CH4 {self.gas:.2f} % LEL")
            else:
                self.get_logger().warn(f"No gas reading in the last 3 s at {WAYPOINTS[self.wp][0]}")
            self.leaks.clear()
            self.advance("Listen")
        elif s == "Listen":
            if now - self.since > self.get_parameter("listen_s").value:
                self.report["acoustic_events"] = len(self.leaks)
                if self.leaks:
                    self.get_logger().warn(
                        f"Acoustic leak candidate at {WAYPOINTS[self.wp][0]}: {self.leaks[-1]}"
                    )
                self.advance("PtzOff")
        elif s == "PtzOff" and self.ready("ptz_state"):
            self.call(
                "ptz_state", ChangeState.Request(transition=Transition(id=Transition.TRANSITION_DEACTIVATE))
            )

    def done(self, kind: str, result) -> None:
        s = self.state
        if s == "WaitForNavigation":
            if result is not None and result.success:
                self.get_logger().info(
                    "Navigation active: starting the mission 'plant_b_daily_round' (4 waypoints)"
                )
                self.advance("Undock")
            else:
                self.wait_until = time.monotonic() + 1.0
        elif s == "Undock":
            if result is not None and result.status == 4:
                self.advance("Navigate")
            else:
                self.retry("undocking failed", 2.0)
        elif s == "Navigate":
            if result is not None and result.status == 4:
                self.get_logger().info(f"Arrived at {WAYPOINTS[self.wp][0]}: inspecting")
                self.advance("PtzOn")
            else:
                self.retry(f"navigation to {WAYPOINTS[self.wp][0]} aborted", 3.0)
        elif s == "PtzOn":
            if result is None:
                self.skip("PTZ camera did not activate")
            else:
                self.advance("PtzPreset")
        elif s == "PtzPreset":
            if result is not None and result.status == 4:
                self.advance("Thermal")
            else:
                self.skip("PTZ preset not reached")
        elif s == "Thermal":
            if result is not None and result.success:
                t = json.loads(result.message)
                self.report["thermal_max_c"] = t["max_c"]
                if t["max_c"] > 75.0:
                    self.get_logger().warn(
                        f"Hot spot {t['max_c']:.1f} C at {WAYPOINTS[self.wp][0]}: flagged for review"
                    )
                self.advance("GasCheck")
            elif self.tries < 1:
                self.retry(f"thermal capture: {'no answer' if result is None else result.message}", 0.5)
            else:
                self.get_logger().error(f"Thermal capture failed at {WAYPOINTS[self.wp][0]}: skipped")
                self.report["thermal_max_c"] = None
                self.advance("GasCheck")
        elif s == "PtzOff":
            self.report_pub.publish(String(data=json.dumps(self.report)))
            self.done_wps += 1
            self.wp = (self.wp + 1) % len(WAYPOINTS)
            if self.wp == 0:
                self.get_logger().info(f"Round {self.round} complete")
                self.round += 1
            self.advance("Navigate")

    def on_second(self) -> None:
        stuck = time.monotonic() - self.since
        level = OK if stuck < 60.0 else WARN
        self.publish_diagnostics(
            self.status(
                "mission",
                "mission-executive",
                level,
                self.state,
                waypoint=WAYPOINTS[self.wp][0],
                round=self.round,
            )
        )


# --- inspection payload (one component container, one single-threaded executor) ----------------------


class PtzCamera(Diagnosed, LifecycleNode):
    """The pan-tilt-zoom camera, a lifecycle node: configured at start-up, activated by the mission at
    each waypoint, deactivated after; active it streams /quad/inspection/ptz/image/compressed (JPEG,
    ~45 KB, 10 Hz, sensor QoS); ``~/move_to_preset`` (order = the preset) drives the pan-tilt head
    over VISCA (a blocking ~0.8 s serial exchange)."""

    def __init__(self, fault_dir: Path) -> None:
        LifecycleNode.__init__(self, "ptz_camera", namespace="quad/inspection")
        hook(self, fault_dir)
        self.declare_parameter("device", "/dev/ttyUSB1")
        self.declare_parameter("jpeg_quality", 80)
        self.active = False
        self.img_pub = None
        self.frames = 0
        self.jpegs = [
            bytes(np.random.default_rng(k).integers(0, 256, 45000 + 900 * k, dtype=np.uint8))
            for k in range(3)
        ]
        self.preset = 0
        ActionServer(self, Fibonacci, "~/move_to_preset", execute_callback=self.move)
        self.create_timer(0.1, self.on_frame)
        self.create_timer(1.0, self.on_second)
        self.trigger_configure()

    def on_configure(self, state) -> TransitionCallbackReturn:
        self.img_pub = self.create_lifecycle_publisher(
            CompressedImage, "/quad/inspection/ptz/image/compressed", SENSOR
        )
        self.get_logger().info("Configured: PTZ head on /dev/ttyUSB1, 1920x1080 MJPEG")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        self.active, self.frames = True, 0
        self.get_logger().info("Activated: streaming")
        return super().on_activate(state)

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        self.active = False
        self.get_logger().info(f"Deactivated after {self.frames} frames")
        return super().on_deactivate(state)

    def move(self, goal):
        self.preset = goal.request.order
        time.sleep(self.rng.uniform(0.6, 1.0))  # VISCA: recall the preset and wait for the head to settle
        goal.succeed()
        return Fibonacci.Result(sequence=[self.preset])

    def on_frame(self) -> None:
        if not self.active:
            return
        m = CompressedImage(format="jpeg")
        m.header.stamp, m.header.frame_id = self.get_clock().now().to_msg(), "ptz_optical"
        m.data = self.jpegs[self.frames % 3]
        self.img_pub.publish(m)
        self.frames += 1

    def on_second(self) -> None:
        self.publish_diagnostics(
            self.status(
                "ptz", "ptz-visca-ttyUSB1", OK, "streaming" if self.active else "idle", preset=self.preset
            )
        )


class ThermalCamera(QuadNode):
    """The radiometric thermal camera, on demand: ``~/capture`` (Trigger, JSON: max and mean
    temperature of the frame) grabs a 640x512 frame and converts it (0.3-0.6 s in the callback);
    ~4 % of the captures fail during the camera's flat-field correction."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("thermal_camera", "quad/inspection", fault_dir)
        self.declare_parameter("device", "/dev/video4")
        self.declare_parameter("emissivity", 0.95)
        self.create_service(Trigger, "~/capture", self.on_capture)
        self.captures = 0
        self.create_timer(1.0, self.on_second)

    def on_capture(self, request, response):
        t0 = time.monotonic()
        if self.rng.random() < 0.04:
            time.sleep(0.1)
            response.success, response.message = False, "flat-field correction in progress"
            self.get_logger().warn("Capture refused: flat-field correction in progress")
            return response
        raw = np.random.default_rng().normal(7400, 60, (512, 640))
        temp = (raw - 7000) * 0.04 + 20.0 + self.rng.uniform(0, 32)
        time.sleep(max(0.0, self.rng.uniform(0.3, 0.6) - (time.monotonic() - t0)))
        self.captures += 1
        response.success = True
        response.message = json.dumps(
            {"max_c": round(float(temp.max()), 1), "mean_c": round(float(temp.mean()), 1)}
        )
        return response

    def on_second(self) -> None:
        self.publish_diagnostics(self.status("thermal", "flir-a70-video4", OK, "OK", captures=self.captures))


class GasSensor(QuadNode):
    """The gas sensor on a serial line: the 1 Hz timer reads its frame (20 ms) and publishes CH4 in %
    LEL on /quad/inspection/gas/reading."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("gas_sensor", "quad/inspection", fault_dir)
        self.declare_parameter("port", "/dev/ttyS3")
        self.declare_parameter("baud", 9600)
        self.pub = self.create_publisher(Float32, "/quad/inspection/gas/reading", RELIABLE)
        self.level = 0.5
        self.reads = 0
        self.create_timer(1.0, self.on_read)

    def on_read(self) -> None:
        while self.fault == "hang":  # the serial read() without a timeout: the sensor stopped answering
            time.sleep(0.05)
        time.sleep(0.02)
        self.level = clamp(self.level + self.rng.gauss(0, 0.08), 0.0, 3.0)
        self.pub.publish(Float32(data=float(self.level)))
        self.reads += 1
        if self.reads % 2 == 0:
            self.publish_diagnostics(
                self.status("gas", "draeger-x-zone-ttyS3", OK, "OK", ch4_lel=f"{self.level:.2f}")
            )


class AcousticDetector(QuadNode):
    """The acoustic leak detector: 200 ms audio frames from its ultrasound microphone analysed in a 5 Hz
    timer (an FFT); /quad/inspection/acoustic/leak (JSON) only when it hears a leak signature."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("acoustic_detector", "quad/inspection", fault_dir)
        self.declare_parameter("device", "hw:2,0")
        self.declare_parameter("threshold_db", 38.0)
        self.pub = self.create_publisher(String, "/quad/inspection/acoustic/leak", RELIABLE)
        self.frames = self.events = self.xruns = 0
        self.create_timer(0.2, self.on_frame)
        self.create_timer(1.0, self.on_second)

    def on_frame(self) -> None:
        if (
            self.fault == "errlog" and self.frames % 2 == 0
        ):  # the USB sound card's isochronous transfers glitch
            self.xruns += 1
            self.get_logger().error(
                f"ALSA: capture overrun (xrun) on hw:2,0, recovering the stream ({self.xruns} since start)"
            )
        samples = np.random.default_rng().normal(0, 1, 3200).astype(np.float32)
        spec = np.abs(np.fft.rfft(samples))
        self.frames += 1
        if self.rng.random() < 1 / 75:  # a leak's ultrasound (or a hiss mistaken for one)
            self.events += 1
            db = self.rng.uniform(38, 52)
            self.pub.publish(
                String(
                    data=json.dumps(
                        {
                            "db": round(db, 1),
                            "peak_khz": round(self.rng.uniform(30, 42), 1),
                            "band_energy": round(float(spec[600:840].mean()), 2),
                        }
                    )
                )
            )

    def on_second(self) -> None:
        self.publish_diagnostics(
            self.status("acoustic", "usb-mic-hw2", OK, "OK", frames=self.frames, events=self.events)
        )


# --- platform: battery, diagnostics, recording, bridge, operator --------------------------------------


class BatteryManager(QuadNode):
    """The battery management system over SMBus: /quad/battery/state (BatteryState) at 1 Hz,
    /quad/battery/status latched on change (CHARGING on the dock, DISCHARGING after)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("battery_manager", "quad", fault_dir)
        self.declare_parameter("smbus", "/dev/i2c-1")
        self.declare_parameter("low_threshold", 0.2)
        self.pub = self.create_publisher(BatteryState, "/quad/battery/state", RELIABLE)
        self.status_pub = self.create_publisher(String, "/quad/battery/status", LATCHED)
        self.create_subscription(String, "/quad/docking_server/state", self.on_dock, LATCHED)
        self.soc = 0.82
        self.docked = True
        self.supply = None
        self.create_timer(1.0, self.on_second)

    def on_dock(self, msg: String) -> None:
        self.docked = msg.data == "DOCKED"

    def on_second(self) -> None:
        self.soc = clamp(self.soc + (0.0002 if self.docked else -0.00012), 0.0, 1.0)
        status = "CHARGING" if self.docked else "DISCHARGING"
        if status != self.supply:
            self.supply = status
            self.status_pub.publish(String(data=status))
            self.get_logger().info(f"Battery {status.lower()} at {self.soc * 100:.1f} %")
        m = BatteryState(
            voltage=46.0 + 4.0 * self.soc,
            current=8.0 if self.docked else -9.5 + self.rng.gauss(0, 0.8),
            percentage=self.soc,
            temperature=31.0 + self.rng.gauss(0, 0.2),
            present=True,
            power_supply_status=BatteryState.POWER_SUPPLY_STATUS_CHARGING
            if self.docked
            else BatteryState.POWER_SUPPLY_STATUS_DISCHARGING,
            power_supply_technology=BatteryState.POWER_SUPPLY_TECHNOLOGY_LION,
        )
        m.header.stamp = self.get_clock().now().to_msg()
        m.cell_voltage = [3.6 + 0.5 * self.soc + self.rng.gauss(0, 0.005) for _ in range(12)]
        self.pub.publish(m)
        self.publish_diagnostics(
            self.status("battery", "bms-smbus-0x0b", OK, status, soc=f"{self.soc * 100:.1f}")
        )


class DiagnosticAggregator(QuadNode):
    """/diagnostics grouped by analyzer into /diagnostics_agg at 1 Hz (STALE after 5 s) and
    /diagnostics_toplevel_state."""

    GROUPS: ClassVar[dict[str, str]] = {
        "locomotion_controller": "/quad/locomotion",
        "imu_driver": "/quad/state_estimation",
        "state_estimator": "/quad/state_estimation",
        "lidar_driver": "/quad/perception",
        "elevation_mapping": "/quad/perception",
        "lifecycle_manager_navigation": "/quad/navigation",
        "twist_mux": "/quad/navigation",
        "mission_executive": "/quad/mission",
        "ptz_camera": "/quad/payload",
        "thermal_camera": "/quad/payload",
        "gas_sensor": "/quad/payload",
        "acoustic_detector": "/quad/payload",
        "battery_manager": "/quad/power",
        "foxglove_bridge": "/quad/comms",
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
            group = self.GROUPS.get(name.split(":")[0], "/quad/other")
            level = STALE if now - t > 5.0 else st.level
            lv = level[0] if isinstance(level, bytes) else level
            out.append(
                DiagnosticStatus(
                    level=level,
                    name=f"{group}/{name}",
                    hardware_id=st.hardware_id,
                    message="Stale" if lv == STALE[0] else st.message,
                    values=st.values,
                )
            )
            groups[group] = max(groups.get(group, 0), lv)
        names = {0: "OK", 1: "Warning", 2: "Error", 3: "Stale"}
        for group, lv in sorted(groups.items()):
            out.insert(0, DiagnosticStatus(level=bytes([lv]), name=group, message=names[lv]))
        arr = DiagnosticArray(status=out)
        arr.header.stamp = self.get_clock().now().to_msg()
        self.agg_pub.publish(arr)
        top = max(groups.values(), default=0)
        self.top_pub.publish(DiagnosticStatus(level=bytes([top]), name="toplevel_state", message=names[top]))


class BagRecorder(Node):
    """``ros2 bag record`` of the mission's topics (serialized, as it does): it subscribes to each topic
    of its list once a publisher shows up and splits the bag every 60 s."""

    TOPICS: ClassVar[dict[str, tuple[type, QoSProfile]]] = {
        "/quad/odom": (Odometry, RELIABLE),
        "/quad/cmd_vel": (Twist, COMMAND),
        "/quad/plan": (PathMsg, RELIABLE),
        "/quad/elevation_mapping/elevation_map": (OccupancyGrid, RELIABLE),
        "/quad/mission/status": (String, LATCHED),
        "/quad/mission/report": (String, RELIABLE),
        "/quad/inspection/ptz/image/compressed": (CompressedImage, SENSOR),
        "/quad/inspection/gas/reading": (Float32, RELIABLE),
        "/quad/inspection/acoustic/leak": (String, RELIABLE),
        "/quad/battery/state": (BatteryState, RELIABLE),
        "/quad/state_estimator/health": (String, LATCHED),
        "/diagnostics_agg": (DiagnosticArray, RELIABLE),
        "/tf_static": (TransformStamped, STATIC_TF),
        "/rosout": (Log, ROSOUT),
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
                    typ, topic, lambda data, t=topic: self.write(t, data), qos, raw=True
                )
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
        self.get_logger().info(
            f"Split the bag: {self.messages} messages so far, new file '{self.dir.name}_{self.split}.mcap'"
        )


class FoxgloveBridge(QuadNode):
    """foxglove_bridge for the site's web dashboard (one client): it subscribes to the topics the
    client asked for, throttles them to the client's rates and queues the frames for the websocket,
    drained 10 times a second."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("foxglove_bridge", "", fault_dir)
        self.declare_parameter("port", 8765)
        self.declare_parameter("send_buffer_limit", 10000000)
        self.queue: deque = deque()
        self.sent_at: dict[str, float] = {}
        self.bytes = 0
        self.subs = {
            "/quad/local_costmap/local_costmap/costmap": (OccupancyGrid, RELIABLE, 0.0),
            "/tf_static": (TransformStamped, STATIC_TF, 0.0),
            "/quad/robot_description": (String, LATCHED, 0.0),
            "/quad/plan": (PathMsg, RELIABLE, 0.0),
            "/quad/elevation_mapping/elevation_map": (OccupancyGrid, RELIABLE, 1.0),
            "/quad/mission/status": (String, LATCHED, 0.0),
            "/quad/battery/state": (BatteryState, RELIABLE, 0.0),
            "/quad/inspection/ptz/image/compressed": (CompressedImage, SENSOR, 0.2),
            "/diagnostics_agg": (DiagnosticArray, RELIABLE, 0.0),
            "/rosout": (Log, ROSOUT, 0.0),
        }
        for topic, (typ, qos, _throttle) in self.subs.items():
            self.create_subscription(typ, topic, lambda m, t=topic: self.on_msg(t, m), qos)
        self.get_logger().info("Server listening on port 8765")
        self.get_logger().info("Client 10.0.9.14:52344 connected via Websocket")
        self.create_timer(0.1, self.drain)
        self.create_timer(1.0, self.on_second)

    def on_msg(self, topic: str, msg) -> None:
        now = time.monotonic()
        if now - self.sent_at.get(topic, 0.0) < self.subs[topic][2]:
            return
        self.sent_at[topic] = now
        self.queue.append((topic, msg))

    def drain(self) -> None:
        while self.queue:
            _topic, msg = self.queue.popleft()
            data = getattr(msg, "data", None)
            self.bytes += len(data) if isinstance(data, bytes | array.array) else 200

    def on_second(self) -> None:
        self.publish_diagnostics(
            self.status("websocket", "foxglove-8765", OK, "1 client", bytes_per_s=self.bytes)
        )
        self.bytes = 0


class OperatorUi(QuadNode):
    """The remote operator's station UI (a rugged tablet on the site's Wi-Fi): watches the mission,
    the battery, the PTZ stream and the aggregated diagnostics; 5 s after it opens it sets the
    controller's ``max_vel_x`` (0.45-0.6 m/s) through ``/quad/controller_server/set_parameters``;
    asks the mission's ``get_status`` every 10 s."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("operator_ui", "quad", fault_dir)
        self.params = self.create_client(SetParameters, "/quad/controller_server/set_parameters")
        self.status_cli = self.create_client(Trigger, "/quad/mission_executive/get_status")
        self.create_subscription(String, "/quad/mission/status", self.on_status, LATCHED)
        self.create_subscription(BatteryState, "/quad/battery/state", lambda m: None, RELIABLE)
        self.create_subscription(
            CompressedImage, "/quad/inspection/ptz/image/compressed", lambda m: None, SENSOR
        )
        self.create_subscription(DiagnosticArray, "/diagnostics_agg", self.on_diag, RELIABLE)
        self.speed_at = time.monotonic() + 5.0
        self.status_at = time.monotonic() + 2.0
        self.pending = None
        self.level = 0
        self.get_logger().info("Operator station connected")
        self.create_timer(0.2, self.tick)

    def on_status(self, msg: String) -> None:
        pass

    def on_diag(self, msg: DiagnosticArray) -> None:
        level = max((s.level[0] if isinstance(s.level, bytes) else s.level for s in msg.status), default=0)
        if level >= 2 and self.level < 2:
            self.get_logger().warn("The robot reports an ERROR in its diagnostics")
        self.level = level

    def tick(self) -> None:
        now = time.monotonic()
        if self.speed_at is not None and now >= self.speed_at and self.params.service_is_ready():
            self.speed_at = None
            v = random.choice((0.45, 0.5, 0.55, 0.6))
            self.get_logger().info(f"Setting the walking speed to {v:.2f} m/s")
            self.params.call_async(
                SetParameters.Request(parameters=[Parameter("max_vel_x", value=v).to_parameter_msg()])
            )
        if self.pending is not None:
            sent, fut = self.pending
            if fut.done():
                self.pending = None
                self.get_logger().info(f"Mission status: {fut.result().message}")
            elif now - sent > 5.0:
                self.status_cli.remove_pending_request(fut)
                self.pending = None
                self.get_logger().warn("No answer to the mission status request in 5 s")
        elif now >= self.status_at and self.status_cli.service_is_ready():
            self.status_at = now + 10.0
            self.pending = (now, self.status_cli.call_async(Trigger.Request()))


class TeleopJoy(QuadNode):
    """The operator's remote (joy_node and teleop_twist_joy in one): /quad/joy (the sticks and
    buttons, 20 Hz, sensor QoS) while connected; /quad/cmd_vel_teleop only while the dead-man
    button is held (not during an autonomous round)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("teleop_joy", "quad", fault_dir)
        self.declare_parameter("enable_button", 4)
        self.joy_pub = self.create_publisher(Joy, "/quad/joy", SENSOR)
        self.cmd_pub = self.create_publisher(Twist, "/quad/cmd_vel_teleop", COMMAND)
        self.create_timer(0.05, self.on_joy)

    def on_joy(self) -> None:
        m = Joy(axes=[self.rng.gauss(0, 0.01) for _ in range(6)], buttons=[0] * 12)
        m.header.stamp = self.get_clock().now().to_msg()
        self.joy_pub.publish(m)
        if m.buttons[4]:
            self.cmd_pub.publish(Twist())


# --- processes ----------------------------------------------------------------------------------------


def locomotion(d: Path) -> list:
    lc = LocomotionController(d)
    lc.broadcaster = JointStateBroadcaster(d)
    lc.start()
    return [lc, lc.broadcaster]


def navigation(d: Path) -> list:
    ctrl, bt = ControllerServer(d), BtNavigator(d)
    ctrl.costmap = bt.costmap = LocalCostmap(d)
    return [PlannerServer(d), ctrl, ctrl.costmap, BehaviorServer(d), bt, LifecycleManager(d)]


PROCESSES = {  # process -> its nodes
    "site_map_loader": lambda d: [SiteMapLoader(d)],
    "locomotion": locomotion,
    "imu": lambda d: [ImuDriver(d)],
    "state_estimation": lambda d: [StateEstimator(d), RobotStatePublisher(d)],
    "lidar": lambda d: [LidarDriver(d)],
    "elevation_mapping": lambda d: [ElevationMapping(d)],
    "navigation": navigation,
    "twist_mux": lambda d: [TwistMux(d)],
    "docking": lambda d: [DockingServer(d)],
    "mission": lambda d: [MissionExecutive(d)],
    "inspection": lambda d: [PtzCamera(d), ThermalCamera(d), GasSensor(d), AcousticDetector(d)],
    "battery": lambda d: [BatteryManager(d)],
    "diagnostics": lambda d: [DiagnosticAggregator(d)],
    "recorder": lambda d: [BagRecorder(d)],
    "foxglove_bridge": lambda d: [FoxgloveBridge(d)],
    "operator": lambda d: [OperatorUi(d), TeleopJoy(d)],
}
EXECUTORS = {  # process -> its executor (the rest: one EventsExecutor)
    "navigation": lambda: MultiThreadedExecutor(num_threads=5),  # component_container_mt
    "docking": lambda: MultiThreadedExecutor(num_threads=2),
    "inspection": SingleThreadedExecutor,  # component_container: one thread for the payload's four nodes
}


def spin_private(ex) -> None:
    """A private node's own executor thread (nav2's costmap node)."""
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
        ex = EXECUTORS.get(process, EventsExecutor)()
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
            nodes[0].get_logger().info("Operator station disconnected")
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
