"""The warehouse forklift's processes: ``python -m bench.forklift.robot PROCESS FAULT_DIR [RUN_FOR]``.

Every process builds its nodes (`PROCESSES`), reads its nodes' fault files (``FAULT_DIR/<node>``)
and spins as `bench.robot_process.spin` says. The work cycle is shared through the wall clock from
``FL_T0`` (`leg`, `nominal_cmd`, `fields`, `link_up`); see `bench.forklift.run` for the robot.
"""

from __future__ import annotations

import array
import json
import math
import os
import random
import struct
import sys
import tempfile
import threading
import time
import traceback
import zlib
from pathlib import Path

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import (
    Point,
    Pose,
    PoseArray,
    PoseStamped,
    PoseWithCovarianceStamped,
    Quaternion,
    TransformStamped,
    Twist,
)
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from nav_msgs.srv import GetPlan
from rclpy.action import ActionClient, ActionServer
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.node import Node
from rclpy.qos import (
    DurabilityPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
)
from sensor_msgs.msg import BatteryState, Imu, JointState, LaserScan, PointCloud2, PointField, Range
from std_msgs.msg import Bool, String, UInt8MultiArray
from test_msgs.action import Fibonacci
from test_msgs.srv import BasicTypes, Empty

from bench.robot_process import (
    RELIABLE,
    Diagnostics,
    header,
    on_shutdown_quiet,
    single_threaded,
    spin,
    status,
    to_s,
    wait_future,
)

OK, WARN, ERROR, STALE = (DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR,
                          DiagnosticStatus.STALE)
NS = "/fl"
SENSOR = qos_profile_sensor_data  # best effort, keep last 5
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
COMMAND = QoSProfile(depth=1)

# ---------------------------------------------------------------------------------------------
# The work cycle, shared by every process through the wall clock.

T0 = float(os.environ.get("FL_T0", repr(time.time())))
BRINGUP_S = 10.0
CYCLE_S = 64.0
LEGS = (  # name, start, end (s into a pallet move)
    ("drive_to_pallet", 0.0, 25.0),
    ("approach", 25.0, 33.0),
    ("lift", 33.0, 39.0),
    ("drive_to_dock", 39.0, 54.0),
    ("lower", 54.0, 59.0),
    ("idle", 59.0, CYCLE_S),
)
LIFT_CM = 145  # the rack beam height of the pick
WARN_PCT = 30.0


def elapsed(t: float | None = None) -> float:
    return (time.time() if t is None else t) - T0


def move_of(t: float | None = None) -> tuple[int, float]:
    """The pallet move (-1: bring-up) and the seconds into it."""
    e = elapsed(t) - BRINGUP_S
    if e < 0:
        return -1, e
    k = int(e // CYCLE_S)
    return k, e - k * CYCLE_S


def leg(t: float | None = None) -> tuple[int, str, float]:
    """The move, the leg's name and the seconds into the leg."""
    k, s = move_of(t)
    if k < 0:
        return k, "bringup", s
    for name, a, b in LEGS:
        if a <= s < b:
            return k, name, s - a
    return k, "idle", s


def move_start(k: int) -> float:
    """Wall time of pallet move ``k``'s start."""
    return T0 + BRINGUP_S + k * CYCLE_S


def _trapezoid(s: float, dur: float, vmax: float, ramp: float = 2.0) -> float:
    return vmax * max(0.0, min(1.0, s / ramp, (dur - s) / ramp))


def nominal_cmd(t: float | None = None) -> tuple[float, float] | None:
    """The path's twist (v m/s, w rad/s) at ``t``, None while the truck does not drive."""
    k, name, s = leg(t)
    if name == "drive_to_pallet":
        return _trapezoid(s, 25.0, 1.4), 0.22 * math.sin(2 * math.pi * s / 25.0 + k)
    if name == "approach":
        return _trapezoid(s, 8.0, 0.25, 1.0), 0.0
    if name == "drive_to_dock":
        return -_trapezoid(s, 15.0, 1.6), -0.25 * math.sin(2 * math.pi * s / 15.0 + k)
    return None


def fields(t: float | None = None) -> tuple[bool, bool, bool, bool]:
    """Safety fields violated: front protective, front warning, rear protective, rear warning."""
    _k, s = move_of(t)
    front_warn = 22.0 <= s < 33.0  # the rack and the pallet in front of the forks
    rear_warn = 51.0 <= s < 54.0  # the dock's wall behind the truck
    return False, front_warn, False, rear_warn


def orders() -> list[tuple[int, int]]:
    """VDA5050 orders: (first move, number of moves), one or two pallets an order (seeded)."""
    rng = random.Random(5050)
    out, k = [], 0
    while k < 200:
        n = rng.choice((1, 2, 2))
        out.append((k, n))
        k += n
    return out


ORDERS = orders()


def link_up(t: float | None = None) -> bool:
    """The MQTT link to the fleet server: down 3-8 s once in every 200 s window (seeded)."""
    e = elapsed(t)
    w = int(e // 200)
    rng = random.Random(1000 + w)
    start = w * 200 + rng.uniform(30, 180)
    return not (start <= e < start + rng.uniform(3, 8))


def quat(yaw: float) -> Quaternion:
    return Quaternion(z=math.sin(yaw / 2), w=math.cos(yaw / 2))


def yaw_of(q: Quaternion) -> float:
    return 2 * math.atan2(q.z, q.w)


class FaultFile:
    """A node's fault file ``FAULT_DIR/fl.<node>`` (`bench.handwritten.NamespacedRobot.fault_file`):
    its word, read at start and every 0.5 s."""

    def __init__(self, fault_dir: Path, node: str) -> None:
        self.path = fault_dir / f"{NS.strip('/')}.{node}"
        self.word = self._read()
        threading.Thread(target=self._poll, daemon=True).start()

    def _read(self) -> str:
        try:
            return self.path.read_text().strip()
        except OSError:
            return ""

    def _poll(self) -> None:
        while True:
            time.sleep(0.5)
            self.word = self._read()


# ---------------------------------------------------------------------------------------------
# plc_bridge


class SafetyPlcBridge(Node):
    """Pilz PNOZmulti over Modbus/TCP: the scanners' field states at 20 Hz, the e-stop latched."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("safety_plc_bridge", namespace=NS)
        self.fault = FaultFile(fault_dir, "safety_plc_bridge")
        self.pub = self.create_publisher(UInt8MultiArray, "safety/fields", RELIABLE)
        self.estop = self.create_publisher(Bool, "safety/estop", LATCHED)
        self.started = time.time()
        self.crash_after = random.uniform(1.5, 2.5)
        self.polls = 0
        self.log = self.get_logger()
        self.log.info("Connected to safety PLC 192.168.10.20:502 (unit 1), polling registers 40001-40016 "
                      "at 20 Hz")
        self.estop.publish(Bool(data=False))
        self.log.info("E-stop released (channels A/B closed)")
        self.create_timer(0.05, self.poll)
        Diagnostics(self, self.diag)

    def poll(self) -> None:
        if self.fault.word == "crashloop" and time.time() - self.started > self.crash_after:
            self.log.error("Modbus exception 0x04 (slave device failure) reading holding registers "
                           "40001-40016")
            regs = {}  # the exception reply carries no register block
            _ = regs[40001]  # the bridge has no branch for it: KeyError, the process ends
        self.polls += 1
        self.pub.publish(UInt8MultiArray(data=[int(b) for b in fields()] + [1]))

    def diag(self):
        return [status(OK, "safety_plc_bridge: Modbus link", "OK", "PNOZ-m-B1-192.168.10.20",
                       polls=self.polls, field_set=1)]


# ---------------------------------------------------------------------------------------------
# sensor_container: both scanners and the pallet camera, ONE single-threaded executor


def _scan_patterns(seed: int, n: int = 541) -> list[tuple[array.array, array.array]]:
    rng = random.Random(seed)
    out = []
    for _ in range(8):
        base = [3.0 + 2.0 * abs(math.sin(i / 40.0 + seed)) for i in range(n)]
        ranges = array.array("f", (b + rng.gauss(0, 0.01) for b in base))
        inten = array.array("f", (float(rng.randint(800, 1200)) for _ in range(n)))
        out.append((ranges, inten))
    return out


class SafetyScanner(Node):
    """SICK microScan3: LaserScan 541 beams (270°, 0.5°) at 12.5 Hz, stamped at the scan's start."""

    def __init__(self, name: str, fault_dir: Path, seed: int) -> None:
        super().__init__(name, namespace=NS)
        self.fault = FaultFile(fault_dir, name)
        self.frame = name.replace("scanner", "laser")
        self.pub = self.create_publisher(LaserScan, f"{name}/scan", SENSOR)
        self.patterns = _scan_patterns(seed)
        self.n = 0
        self.log = self.get_logger()
        self.log.info(f"microScan3 {name.split('_')[0]}: UDP data output on 192.168.10.{21 + seed}:6060, "
                      "541 beams, 12.5 Hz")
        self.create_timer(0.08, self.scan)
        Diagnostics(self, self.diag)

    def scan(self) -> None:
        if self.fault.word == "hang":
            self.log.warn("No UDP datagram for 200 ms (sequence gap 41877 -> 41880); re-syncing to the "
                          "scanner's data output")
            threading.Event().wait()  # the blocking recv() with no timeout: the container stalls
        ranges, inten = self.patterns[self.n % 8]
        self.n += 1
        msg = LaserScan(header=header(self.frame, time.time() - 0.03), angle_min=-2.356, angle_max=2.356,
                        angle_increment=0.008727, time_increment=0.0000308, scan_time=0.08,
                        range_min=0.1, range_max=40.0)
        msg.ranges = ranges
        msg.intensities = inten
        self.pub.publish(msg)

    def diag(self):
        return [status(OK, f"{self.get_name()}: scanner", "Scanning", f"microScan3-{self.get_name()}",
                       scans=self.n, contamination="0 %")]


class PalletCamera(Node):
    """ifm O3R ToF camera at the fork tips: a PointCloud2 (3400 points, 40 KB) at 5 Hz, streaming
    only while the forks approach a pallet."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("pallet_camera", namespace=NS)
        self.fault = FaultFile(fault_dir, "pallet_camera")
        self.pub = self.create_publisher(PointCloud2, "pallet_camera/points", SENSOR)
        rng = random.Random(7)
        self.clouds = []
        for _ in range(4):
            pts = b"".join(struct.pack("<fff", 1.5 + rng.gauss(0, 0.02), rng.uniform(-0.6, 0.6),
                                       rng.uniform(-0.1, 0.3)) for _ in range(3400))
            self.clouds.append(array.array("B", pts))
        self.fields = [PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1)
                       for i, n in enumerate("xyz")]
        self.streaming = False
        self.n = 0
        self.log = self.get_logger()
        self.create_timer(0.2, self.frame)
        Diagnostics(self, self.diag)

    def frame(self) -> None:
        _k, name, _s = leg()
        on = name == "approach"
        if on != self.streaming:
            self.streaming = on
            self.log.info("Streaming started (pallet approach): 224x172 ToF, 5 Hz, downsampled to 3400 "
                          "points" if on else "Streaming stopped (standby)")
        if not on:
            return
        self.n += 1
        msg = PointCloud2(header=header("pallet_camera_optical", time.time() - 0.045), height=1, width=3400,
                          fields=self.fields, is_bigendian=False, point_step=12, row_step=40800,
                          is_dense=True)
        msg.data = self.clouds[self.n % 4]
        self.pub.publish(msg)

    def diag(self):
        return [status(OK, "pallet_camera: camera", "Streaming" if self.streaming else "Standby",
                       "O3R-ToF-fork", frames=self.n)]


# ---------------------------------------------------------------------------------------------
# scan_tools: the laser merger, the dashboard throttle and the odometry relay (one container)


class LaserMerger(Node):
    """ira_laser_tools-like: front + rear paired by stamp (approximate time, slop 40 ms) ->
    ``/fl/scan_merged`` stamped with the newer of the pair."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("laser_merger", namespace=NS)
        self.fault = FaultFile(fault_dir, "laser_merger")
        self.pub = self.create_publisher(LaserScan, "scan_merged", SENSOR)
        self.queues: dict[str, list[LaserScan]] = {"front": [], "rear": []}
        for side in self.queues:
            self.create_subscription(LaserScan, f"{side}_scanner/scan",
                                     lambda m, s=side: self.on_scan(s, m), SENSOR)
        self.merged = 0
        self.lagging = False

    def on_scan(self, side: str, msg: LaserScan) -> None:
        q = self.queues[side]
        q.append(msg)
        del q[:-5]
        other = self.queues["rear" if side == "front" else "front"]
        t = to_s(msg.header.stamp)
        best = min(other, key=lambda m: abs(to_s(m.header.stamp) - t), default=None)
        if best is None or abs(to_s(best.header.stamp) - t) > 0.04:
            return
        # approximate time: the pair and anything older than it leave the queues
        t_best = to_s(best.header.stamp)
        other[:] = [m for m in other if to_s(m.header.stamp) > t_best]
        q.clear()
        front, rear = (msg, best) if side == "front" else (best, msg)
        newer = msg if to_s(msg.header.stamp) >= to_s(best.header.stamp) else best
        out = LaserScan(header=newer.header, angle_min=-math.pi, angle_max=math.pi,
                        angle_increment=2 * math.pi / 1082, time_increment=0.0, scan_time=0.08,
                        range_min=0.1, range_max=40.0)
        out.header.frame_id = "base_link"
        out.ranges = front.ranges + rear.ranges
        self.merged += 1
        if self.fault.word == "lag":
            if not self.lagging:
                self.lagging = True  # the new filter chain (shadows + footprint box) costs 150 ms a pair
            threading.Timer(0.15, self.pub.publish, (out,)).start()
            return
        self.pub.publish(out)


class ScanThrottle(Node):
    """topic_tools throttle messages: the front scan at 2 Hz for the fleet dashboard."""

    def __init__(self) -> None:
        super().__init__("scan_throttle", namespace=NS)
        self.pub = self.create_publisher(LaserScan, "front_scanner/scan_throttle", SENSOR)
        self.create_subscription(LaserScan, "front_scanner/scan", self.on_scan, SENSOR)
        self.last = 0.0

    def on_scan(self, msg: LaserScan) -> None:
        now = time.monotonic()
        if now - self.last >= 0.5:
            self.last = now
            self.pub.publish(msg)


class OdomRelay(Node):
    """topic_tools relay: ``/fl/odometry/filtered`` -> ``/fl/fleet/odom``."""

    def __init__(self) -> None:
        super().__init__("odom_relay", namespace=NS)
        self.pub = self.create_publisher(Odometry, "fleet/odom", RELIABLE)
        self.create_subscription(Odometry, "odometry/filtered", self.pub.publish, RELIABLE)


# ---------------------------------------------------------------------------------------------
# base_driver: the traction drive on CAN, the IMU and the BMS


class DriveState:
    """What the drive controller and the IMU share in the base driver process."""

    def __init__(self) -> None:
        self.v = self.w = 0.0
        self.cmd_t = 0.0


class DriveController(Node):
    """Curtis traction controller over CANopen: ``/fl/cmd_vel`` -> ``/fl/odometry/wheel`` 50 Hz."""

    def __init__(self, shared: DriveState) -> None:
        super().__init__("drive_controller", namespace=NS)
        self.s = shared
        self.x = self.y = self.yaw = 0.0
        self.last = time.time()
        self.timed_out = True
        self.pub = self.create_publisher(Odometry, "odometry/wheel", RELIABLE)
        self.create_subscription(Twist, "cmd_vel", self.on_cmd, COMMAND)
        self.create_timer(0.02, self.tick)
        self.log = self.get_logger()
        self.log.info("CANopen node 0x21 operational (Curtis 1232E), steering node 0x22 operational")
        Diagnostics(self, self.diag)

    def on_cmd(self, msg: Twist) -> None:
        self.s.v, self.s.w, self.s.cmd_t = msg.linear.x, msg.angular.z, time.time()
        if self.timed_out:
            self.timed_out = False

    def tick(self) -> None:
        now = time.time()
        if now - self.s.cmd_t > 0.5 and not self.timed_out:
            self.timed_out = True
            self.s.v = self.s.w = 0.0
        dt, self.last = now - self.last, now
        self.yaw += self.s.w * dt
        self.x += self.s.v * math.cos(self.yaw) * dt
        self.y += self.s.v * math.sin(self.yaw) * dt
        msg = Odometry(header=header("odom", now - 0.004), child_frame_id="base_link")
        msg.pose.pose.position.x, msg.pose.pose.position.y = self.x, self.y
        msg.pose.pose.orientation = quat(self.yaw)
        msg.twist.twist.linear.x = self.s.v + random.gauss(0, 0.005)
        msg.twist.twist.angular.z = self.s.w
        self.pub.publish(msg)

    def diag(self):
        return [status(OK, "drive_controller: traction", "Operational", "curtis-1232E-0x21",
                       motor_temp_c=41 + int(elapsed() / 60), speed=round(self.s.v, 2))]


class ImuDriver(Node):
    """Bosch BMI088 on the drive's CAN: ``/fl/imu/data`` 100 Hz, stamped 3 ms back."""

    def __init__(self, fault_dir: Path, shared: DriveState) -> None:
        super().__init__("imu_driver", namespace=NS)
        self.fault = FaultFile(fault_dir, "imu_driver")
        self.s = shared
        self.pub = self.create_publisher(Imu, "imu/data", SENSOR)
        self.timer = self.create_timer(0.01, self.sample)
        self.slow = False
        self.get_logger().info("BMI088 configured: ODR 100 Hz, gyro range 500 dps")

    def sample(self) -> None:
        if self.fault.word == "rate" and not self.slow:
            self.slow = True
            self.get_logger().warn("CAN bus-off recovery on can1 (TEC 256): IMU node re-initialized in "
                                   "safe mode, output data rate limited to 60 Hz")
            self.timer.cancel()
            self.timer = self.create_timer(1 / 60, self.sample)
        msg = Imu(header=header("imu_link", time.time() - 0.003))
        msg.orientation.w = 1.0
        msg.angular_velocity.z = self.s.w + random.gauss(0, 0.002)
        msg.linear_acceleration.x = random.gauss(0, 0.05)
        msg.linear_acceleration.z = 9.81 + random.gauss(0, 0.05)
        self.pub.publish(msg)


class BatteryManager(Node):
    """The 48 V lithium pack's BMS: ``/fl/battery_state`` 1 Hz; WARN below 30 %."""

    def __init__(self) -> None:
        super().__init__("battery_manager", namespace=NS)
        self.pub = self.create_publisher(BatteryState, "battery_state", RELIABLE)
        self.warned = 0.0
        self.create_timer(1.0, self.tick)
        Diagnostics(self, self.diag, 2.0)

    def pct(self) -> float:
        return 36.0 - 0.9 * elapsed() / 60.0  # ~0.9 %/min under a work cycle

    def tick(self) -> None:
        p = self.pct()
        self.pub.publish(BatteryState(header=header("battery"), voltage=48.0 + p / 20, current=-38.0,
                                      percentage=p / 100, present=True,
                                      power_supply_status=BatteryState.POWER_SUPPLY_STATUS_DISCHARGING))
        if p < WARN_PCT and time.time() - self.warned > 60:
            self.warned = time.time()
            self.get_logger().warn(f"Battery low: {p:.1f} % (threshold {WARN_PCT:.0f} %); charging "
                                   "will be requested below 20 %")

    def diag(self):
        p = self.pct()
        return [status(WARN if p < WARN_PCT else OK, "battery_manager: pack",
                       "Low" if p < WARN_PCT else "OK", "bms-48V-LFP", soc=round(p, 1))]


# ---------------------------------------------------------------------------------------------
# localization: AMCL and the EKF, a MultiThreadedExecutor with callback groups


class Ekf(Node):
    """robot_localization-like EKF: wheel odometry (50 Hz) + IMU (100 Hz) -> ``/fl/odometry/filtered``
    and odom->base_link on ``/tf`` at 30 Hz."""

    def __init__(self) -> None:
        super().__init__("ekf_filter_node", namespace=NS)
        g_in, g_out = ReentrantCallbackGroup(), MutuallyExclusiveCallbackGroup()  # the inputs take a lock
        self.pub = self.create_publisher(Odometry, "odometry/filtered", RELIABLE)
        self.tf = self.create_publisher(TransformStamped, "/tf", RELIABLE)
        self.create_subscription(Odometry, "odometry/wheel", self.on_wheel, RELIABLE, callback_group=g_in)
        self.create_subscription(Imu, "imu/data", self.on_imu, SENSOR, callback_group=g_in)
        self.lock = threading.Lock()
        self.v = self.w = 0.0
        self.x = self.y = self.yaw = 0.0
        self.last = time.time()
        self.n_imu = self.n_wheel = 0
        self.win_t = time.time()
        self.rates = (0.0, 0.0)
        self.create_timer(1 / 30, self.update, callback_group=g_out)
        Diagnostics(self, self.diag, group=g_out)

    def on_wheel(self, msg: Odometry) -> None:
        with self.lock:
            self.v = msg.twist.twist.linear.x
            self.n_wheel += 1

    def on_imu(self, msg: Imu) -> None:
        with self.lock:
            self.w = msg.angular_velocity.z
            self.n_imu += 1

    def update(self) -> None:
        now = time.time()
        with self.lock:
            v, w = self.v, self.w
        dt, self.last = now - self.last, now
        self.yaw += w * dt
        self.x += v * math.cos(self.yaw) * dt
        self.y += v * math.sin(self.yaw) * dt
        h = header("odom", now)
        msg = Odometry(header=h, child_frame_id="base_link")
        msg.pose.pose.position.x, msg.pose.pose.position.y = self.x, self.y
        msg.pose.pose.orientation = quat(self.yaw)
        msg.twist.twist.linear.x, msg.twist.twist.angular.z = v, w
        self.pub.publish(msg)
        tf = TransformStamped(header=h, child_frame_id="base_link")
        tf.transform.translation.x, tf.transform.translation.y = self.x, self.y
        tf.transform.rotation = quat(self.yaw)
        self.tf.publish(tf)

    def diag(self):
        now = time.time()
        span = max(now - self.win_t, 1e-3)
        with self.lock:
            imu_hz, wheel_hz = self.n_imu / span, self.n_wheel / span
            self.n_imu = self.n_wheel = 0
        self.win_t = now
        imu = status(OK if 90 <= imu_hz <= 110 else WARN, "ekf_filter_node: imu topic status",
                     "Desired frequency met" if 90 <= imu_hz <= 110 else "Frequency too low.",
                     "none", frequency=round(imu_hz, 1), expected="90-110")
        odom = status(OK if 45 <= wheel_hz <= 55 else WARN, "ekf_filter_node: odometry topic status",
                      "Desired frequency met" if 45 <= wheel_hz <= 55 else "Frequency too low.", "none",
                      frequency=round(wheel_hz, 1), expected="45-55")
        return [imu, odom]


class Amcl(Node):
    """nav2 AMCL-like: merged scan + filtered odometry -> ``/fl/amcl_pose`` and map->odom, only
    when the truck moved more than 0.1 m or turned more than 0.2 rad."""

    def __init__(self) -> None:
        super().__init__("amcl", namespace=NS)
        g = MutuallyExclusiveCallbackGroup()
        self.pub = self.create_publisher(PoseWithCovarianceStamped, "amcl_pose", LATCHED)
        self.tf = self.create_publisher(TransformStamped, "/tf", RELIABLE)
        self.create_subscription(LaserScan, "scan_merged", self.on_scan, SENSOR, callback_group=g)
        self.create_subscription(Odometry, "odometry/filtered", self.on_odom, RELIABLE, callback_group=g)
        self.odom: Odometry | None = None
        self.at: tuple[float, float, float] | None = None
        self.warned = 0.0
        self.get_logger().info("Setting pose (initial): 2.150 14.300 1.571 (dock D-03)")

    def on_odom(self, msg: Odometry) -> None:
        self.odom = msg

    def on_scan(self, scan: LaserScan) -> None:
        if self.odom is None:
            return
        age = time.time() - to_s(scan.header.stamp)
        if age > 0.12 and time.time() - self.warned > 5:
            self.warned = time.time()
            self.get_logger().warn(
                f"Message Filter dropping message: frame 'base_link' at time {to_s(scan.header.stamp):.3f} "
                f"for reason 'the timestamp on the message is earlier than all the data in the transform "
                f"cache' (scan {age * 1000:.0f} ms old)")
        p = self.odom.pose.pose
        here = (p.position.x, p.position.y, yaw_of(p.orientation))
        if self.at is not None and math.hypot(here[0] - self.at[0], here[1] - self.at[1]) < 0.1 \
                and abs(here[2] - self.at[2]) < 0.2:
            return
        self.at = here
        msg = PoseWithCovarianceStamped(header=header("map", to_s(scan.header.stamp)))
        msg.pose.pose = Pose(position=Point(x=2.15 + here[0], y=14.3 + here[1]),
                             orientation=quat(here[2] + 1.571))
        msg.pose.covariance[0] = msg.pose.covariance[7] = 0.02
        self.pub.publish(msg)
        tf = TransformStamped(header=header("map", to_s(scan.header.stamp) + 0.2), child_frame_id="odom")
        tf.transform.translation.x, tf.transform.translation.y = 2.15, 14.3
        tf.transform.rotation = quat(1.571)
        self.tf.publish(tf)


# ---------------------------------------------------------------------------------------------
# navigation: bt_navigator, planner, controller, velocity smoother, collision monitor (one
# MultiThreadedExecutor, a group per node)

LEG_IDS = {"drive_to_pallet": 0, "approach": 1, "drive_to_dock": 2}
LEG_NAMES = {v: k for k, v in LEG_IDS.items()}


class PlannerServer(Node):
    """nav2 planner_server (Smac 2D): ``/fl/compute_path`` (GetPlan) and ``/fl/plan``."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("planner_server", namespace=NS)
        self.fault = FaultFile(fault_dir, "planner_server")
        g = MutuallyExclusiveCallbackGroup()
        self.create_service(GetPlan, "compute_path", self.plan, callback_group=g)
        self.pub = self.create_publisher(PathMsg, "plan", RELIABLE)
        self.slow_logged = False
        self.log = self.get_logger()

    def plan(self, req: GetPlan.Request, resp: GetPlan.Response) -> GetPlan.Response:
        t = time.time()
        if self.fault.word == "slow":
            if not self.slow_logged:
                self.slow_logged = True
                self.log.warn("global_costmap: obstacle_layer clearing disabled by the new costmap "
                              "parameters (clearing: false); 1.2e6 marked cells, inflation recomputed "
                              "every plan")
            time.sleep(3.0)
        else:
            time.sleep(random.uniform(0.05, 0.15))
        a, b = req.start.pose.position, req.goal.pose.position
        n = 120
        path = PathMsg(header=header("map"))
        path.poses = [PoseStamped(header=path.header, pose=Pose(position=Point(
            x=a.x + (b.x - a.x) * i / n, y=a.y + (b.y - a.y) * i / n + 0.8 * math.sin(math.pi * i / n))))
            for i in range(n + 1)]
        resp.plan = path
        self.pub.publish(path)
        dt = time.time() - t
        (self.log.warn if dt > 1.0 else self.log.debug)(f"Planning took {dt:.2f} s ({n + 1} poses)")
        return resp


class ControllerServer(Node):
    """nav2 controller_server (RPP): the ``/fl/follow_path`` action -> ``/fl/cmd_vel_nav`` 20 Hz while
    following (Fibonacci: ``order`` = the leg)."""

    def __init__(self) -> None:
        super().__init__("controller_server", namespace=NS)
        self.pub = self.create_publisher(Twist, "cmd_vel_nav", COMMAND)
        self.active = ""
        ActionServer(self, Fibonacci, "follow_path", self.follow, callback_group=ReentrantCallbackGroup())
        Diagnostics(self, self.diag, group=MutuallyExclusiveCallbackGroup())

    def follow(self, goal) -> Fibonacci.Result:
        name = LEG_NAMES.get(goal.request.order, "?")
        self.active = name
        self.get_logger().info(f"Received a goal, begin computing control effort ({name})")
        n = 0
        while rclpy.ok():
            _k, now_leg, _s = leg()
            if now_leg != name:
                break
            cmd = nominal_cmd() or (0.0, 0.0)
            tw = Twist()
            tw.linear.x, tw.angular.z = cmd
            self.pub.publish(tw)
            n += 1
            if n % 20 == 0:
                goal.publish_feedback(Fibonacci.Feedback(sequence=[n // 20]))
            time.sleep(0.05)
        self.pub.publish(Twist())
        self.active = ""
        self.get_logger().info("Reached the goal!")
        goal.succeed()
        return Fibonacci.Result(sequence=[goal.request.order, n])

    def diag(self):
        return [status(OK, "controller_server: FollowPath", self.active or "Idle", "none")]


class VelocitySmoother(Node):
    """nav2 velocity_smoother: ``/fl/cmd_vel_nav`` -> ``/fl/cmd_vel_smoothed`` 20 Hz while commands
    come (one zero after a 1 s timeout)."""

    def __init__(self) -> None:
        super().__init__("velocity_smoother", namespace=NS)
        g = MutuallyExclusiveCallbackGroup()
        self.pub = self.create_publisher(Twist, "cmd_vel_smoothed", COMMAND)
        self.create_subscription(Twist, "cmd_vel_nav", self.on_cmd, COMMAND, callback_group=g)
        self.target, self.t_cmd = Twist(), 0.0
        self.v = self.w = 0.0
        self.stopped = True
        self.create_timer(0.05, self.tick, callback_group=g)

    def on_cmd(self, msg: Twist) -> None:
        self.target, self.t_cmd = msg, time.time()

    def tick(self) -> None:
        if time.time() - self.t_cmd > 1.0:
            if self.stopped:
                return
            self.target, self.stopped = Twist(), True
        else:
            self.stopped = False
        dv = max(-0.05, min(0.05, self.target.linear.x - self.v))  # 1.0 m/s² at 20 Hz
        self.v += dv
        self.w = self.target.angular.z
        out = Twist()
        out.linear.x, out.angular.z = self.v, self.w
        self.pub.publish(out)


class CollisionMonitor(Node):
    """nav2 collision_monitor fed by the safety PLC's fields: slows to 30 % while a warning field is
    violated, stops on a protective one or when the fields are stale (> 0.3 s)."""

    def __init__(self) -> None:
        super().__init__("collision_monitor", namespace=NS)
        g = MutuallyExclusiveCallbackGroup()
        self.pub = self.create_publisher(Twist, "cmd_vel", COMMAND)
        self.create_subscription(Twist, "cmd_vel_smoothed", self.on_cmd, COMMAND, callback_group=g)
        self.create_subscription(UInt8MultiArray, "safety/fields", self.on_fields, RELIABLE, callback_group=g)
        self.fields = (0, 0, 0, 0)
        self.t_fields = 0.0
        self.action = "none"

    def on_fields(self, msg: UInt8MultiArray) -> None:
        self.fields, self.t_fields = tuple(msg.data[:4]), time.time()

    def on_cmd(self, msg: Twist) -> None:
        fp, fw, rp, rw = self.fields
        moving = abs(msg.linear.x) > 1e-3
        if time.time() - self.t_fields > 0.3:
            action, scale = "stop_stale", 0.0
        elif (fp and msg.linear.x > 0) or (rp and msg.linear.x < 0):
            action, scale = "stop", 0.0
        elif (fw and msg.linear.x > 0) or (rw and msg.linear.x < 0):
            action, scale = "slowdown", 0.3
        else:
            action, scale = "none", 1.0
        if action != self.action and moving:
            self.action = action
            if action == "stop_stale":
                self.get_logger().error("Safety field states from /fl/safety/fields are stale "
                                        f"({time.time() - self.t_fields:.1f} s): robot stopped")
            elif action == "slowdown":
                self.get_logger().info("Robot to slowdown for warning field")
            elif action == "none":
                self.get_logger().info("Robot to continue normal operation")
        out = Twist()
        out.linear.x, out.angular.z = msg.linear.x * scale, msg.angular.z * scale
        self.pub.publish(out)


class BtNavigator(Node):
    """nav2 bt_navigator: the ``/fl/navigate_to_pose`` action (``order`` = the leg) from the mission
    manager: plans with ``/fl/compute_path`` (2 s timeout, 3 tries), identifies the pallet with
    ``/fl/pallet_detector/detect`` at the approach, follows with ``/fl/follow_path``."""

    def __init__(self) -> None:
        super().__init__("bt_navigator", namespace=NS)
        g = ReentrantCallbackGroup()
        self.planner = self.create_client(GetPlan, "compute_path", callback_group=g)
        self.detect = self.create_client(BasicTypes, "pallet_detector/detect", callback_group=g)
        self.follow = ActionClient(self, Fibonacci, "follow_path", callback_group=g)
        ActionServer(self, Fibonacci, "navigate_to_pose", self.navigate, callback_group=g)
        self.log = self.get_logger()

    def _plan(self, name: str) -> bool:
        req = GetPlan.Request()
        req.goal.pose.position.x = 24.0 if name == "drive_to_pallet" else 0.0
        for attempt in range(1, 4):
            if not self.planner.wait_for_service(timeout_sec=1.0):
                self.log.error("compute_path service not available")
                continue
            resp = wait_future(self.planner.call_async(req), 2.0)
            if resp is not None:
                return True
            self.log.error(f"Failed to compute path for {name}: /fl/compute_path did not answer within "
                           f"2.0 s (attempt {attempt}/3)")
        return False

    def navigate(self, goal) -> Fibonacci.Result:
        name = LEG_NAMES.get(goal.request.order, "?")
        self.log.info(f"Begin navigating: {name}")
        if name != "approach" and not self._plan(name):
            self.log.error(f"Goal failed: {name}: ComputePathToPose failed after 3 attempts")
            goal.abort()
            return Fibonacci.Result(sequence=[-1])
        if not self.follow.wait_for_server(timeout_sec=1.0):
            self.log.error("follow_path action server not available")
            goal.abort()
            return Fibonacci.Result(sequence=[-2])
        gh = wait_future(self.follow.send_goal_async(Fibonacci.Goal(order=goal.request.order)), 2.0)
        if gh is None or not gh.accepted:
            goal.abort()
            return Fibonacci.Result(sequence=[-2])
        result = gh.get_result_async()
        if name == "approach":
            time.sleep(2.0)  # the camera streams by then
            if self.detect.wait_for_service(timeout_sec=0.5):
                r = wait_future(self.detect.call_async(BasicTypes.Request(bool_value=True)), 1.0)
            else:
                r = None
            if r is None or not r.bool_value:
                why = r.string_value if r else "no answer"
                self.log.warn(f"Pallet not identified at the approach ({why}); continuing on the order's "
                              "nominal pose")
            else:
                self.log.info(f"Pallet identified: lateral offset {r.float64_value:+.3f} m")
        wait_future(result, 30.0)
        self.log.info(f"Goal succeeded: {name}")
        goal.succeed()
        return Fibonacci.Result(sequence=[goal.request.order])


# ---------------------------------------------------------------------------------------------
# pallet_detection: the lifecycle-managed pallet detector


class PalletDetector(LifecycleNode):
    """Pallet pocket detector on the ToF cloud: configured/activated by the lifecycle manager at the
    approach, deactivated after the pick; ``~/detect`` (BasicTypes) and ``~/pallets`` while active."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("pallet_detector", namespace=NS)
        self.fault = FaultFile(fault_dir, "pallet_detector")
        self.reliable = self.fault.word == "reliable"
        self.sub = None
        self.pub = None
        self.last: float = 0.0
        self.clouds = 0
        self.create_service(BasicTypes, "~/detect", self.on_detect)
        depth = 5
        self.qos = QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE if self.reliable
                              else ReliabilityPolicy.BEST_EFFORT)
        self.get_logger().info(
            f"Loaded pallet_detector.yaml (points qos: {'reliable' if self.reliable else 'best_effort'}, "
            f"depth {depth}; model EUR-1200x800)")

    def on_configure(self, state) -> TransitionCallbackReturn:
        self.pub = self.create_lifecycle_publisher(PoseArray, "~/pallets", RELIABLE)
        self.get_logger().info("Configuring: pocket template EUR 1200x800 loaded")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        self.sub = self.create_subscription(PointCloud2, "pallet_camera/points", self.on_cloud, self.qos)
        self.get_logger().info("Activating: subscribed to /fl/pallet_camera/points")
        return super().on_activate(state)

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        if self.sub is not None:
            self.destroy_subscription(self.sub)
            self.sub = None
        self.get_logger().info(f"Deactivating ({self.clouds} clouds processed)")
        return super().on_deactivate(state)

    def on_cleanup(self, state) -> TransitionCallbackReturn:
        return TransitionCallbackReturn.SUCCESS

    def on_cloud(self, msg: PointCloud2) -> None:
        self.last = time.time()
        self.clouds += 1
        pa = PoseArray(header=msg.header)
        pa.poses = [Pose(position=Point(x=1.5, y=random.gauss(0, 0.01)), orientation=quat(0.0))]
        if self.pub is not None:
            self.pub.publish(pa)

    def on_detect(self, req: BasicTypes.Request, resp: BasicTypes.Response) -> BasicTypes.Response:
        if self.sub is None:
            resp.bool_value, resp.string_value = False, "detector not active"
        elif time.time() - self.last > 1.0:
            resp.bool_value, resp.string_value = False, "no point cloud in the last 1.0 s"
            self.get_logger().warn(f"Detect request: no point cloud on /fl/pallet_camera/points for "
                                   f"{time.time() - self.last:.1f} s" if self.last else
                                   "Detect request: no point cloud received since activation")
        else:
            resp.bool_value, resp.float64_value = True, random.gauss(0, 0.012)
            resp.string_value = "EUR pallet, pockets at 0.31/0.89 m"
        return resp


# ---------------------------------------------------------------------------------------------
# mission: the mission manager, the lifecycle manager, the charger dock


class MissionManager(Node):
    """Runs each pallet move: navigate (``/fl/navigate_to_pose``), lift and lower
    (``/fl/lift_controller/lift``); ``~/state`` latched on change."""

    def __init__(self) -> None:
        super().__init__("mission_manager", namespace=NS)
        self.nav = ActionClient(self, Fibonacci, "navigate_to_pose")
        self.lift = ActionClient(self, Fibonacci, "lift_controller/lift")
        self.state = self.create_publisher(String, "~/state", LATCHED)
        self.create_subscription(String, "vda5050/order", self.on_order, RELIABLE)
        self.log = self.get_logger()
        self.order = ""
        self._set("bringup")
        threading.Thread(target=on_shutdown_quiet(self.run), daemon=True).start()

    def on_order(self, msg: String) -> None:
        o = json.loads(msg.data)
        self.order = o["orderId"]
        self.log.info(f"Order {o['orderId']} accepted: {len(o['nodes'])} pallet moves")

    def _set(self, state: str) -> None:
        self.state.publish(String(data=json.dumps({"state": state, "order": self.order})))

    def _goal(self, client: ActionClient, what: str, order: int, timeout: float) -> bool:
        if not client.wait_for_server(timeout_sec=2.0):
            server = "/fl/navigate_to_pose" if client is self.nav else "/fl/lift_controller/lift"
            self.log.error(f"{what}: action server {server} not available after 2.0 s")
            return False
        gh = wait_future(client.send_goal_async(Fibonacci.Goal(order=order)), 2.0)
        if gh is None or not gh.accepted:
            self.log.error(f"{what}: goal {'not answered within 2.0 s' if gh is None else 'rejected'}")
            return False
        res = wait_future(gh.get_result_async(), timeout)
        if res is None or res.status != 4:  # SUCCEEDED
            why = "timeout" if res is None else f"status {res.status}"
            self.log.error(f"{what}: did not succeed ({why})")
            return False
        return True

    def run(self) -> None:
        k, _ = move_of()
        k = max(k + 1, 0)
        while rclpy.ok():
            for name, a, _b in LEGS:
                wait = move_start(k) + a - time.time()
                if wait > 0:
                    time.sleep(wait)
                if not rclpy.ok():
                    return
                self._set(name)
                if name in LEG_IDS:
                    self.log.info(f"Move {k}: {name}")
                    threading.Thread(target=on_shutdown_quiet(self._goal),
                                     args=(self.nav, f"Move {k} {name}", LEG_IDS[name], 30.0),
                                     daemon=True).start()
                elif name in ("lift", "lower"):
                    target = LIFT_CM if name == "lift" else 10
                    self.log.info(f"Move {k}: {name} forks to {target} cm")
                    threading.Thread(target=on_shutdown_quiet(self._goal),
                                     args=(self.lift, f"Move {k} {name}", target, 8.0), daemon=True).start()
                elif name == "idle":
                    self.log.info(f"Move {k}: pallet delivered to dock D-03")
            k += 1


class LifecycleManager(Node):
    """nav2 lifecycle_manager for the pallet detector: configure + activate at the approach,
    deactivate after the pick."""

    def __init__(self) -> None:
        super().__init__("lifecycle_manager", namespace=NS)
        self.change = self.create_client(ChangeState, "pallet_detector/change_state")
        self.get = self.create_client(GetState, "pallet_detector/get_state")
        self.log = self.get_logger()
        threading.Thread(target=on_shutdown_quiet(self.run), daemon=True).start()

    def _transition(self, tid: int, label: str) -> bool:
        if not self.change.wait_for_service(timeout_sec=1.0):
            self.log.error(f"Failed to change state for node: pallet_detector ({label}): service not "
                           "available")
            return False
        r = wait_future(self.change.call_async(ChangeState.Request(transition=Transition(id=tid))), 2.0)
        if r is None or not r.success:
            self.log.error(f"Failed to change state for node: pallet_detector ({label})")
            return False
        return True

    def _state(self) -> str:
        if not self.get.wait_for_service(timeout_sec=1.0):
            return "unknown"
        r = wait_future(self.get.call_async(GetState.Request()), 2.0)
        return r.current_state.label if r else "unknown"

    def run(self) -> None:
        k, _ = move_of()
        k = max(k + 1, 0)
        while rclpy.ok():
            for at, act in ((24.0, "up"), (39.5, "down")):
                wait = move_start(k) + at - time.time()
                if wait > 0:
                    time.sleep(wait)
                if not rclpy.ok():
                    return
                state = self._state()
                if act == "up":
                    self.log.info("Activating managed nodes: pallet_detector")
                    if state == "unconfigured":
                        self._transition(Transition.TRANSITION_CONFIGURE, "configure")
                        state = "inactive"
                    if state == "inactive" and self._transition(Transition.TRANSITION_ACTIVATE, "activate"):
                        self.log.info("Managed nodes are active")
                elif state == "active":
                    self.log.info("Deactivating managed nodes: pallet_detector")
                    self._transition(Transition.TRANSITION_DEACTIVATE, "deactivate")
            k += 1


class ChargerDock(Node):
    """The dock's charger contactor: ``~/start_charging`` (Empty), used below 20 % only."""

    def __init__(self) -> None:
        super().__init__("charger_dock", namespace=NS)
        self.create_service(Empty, "~/start_charging", self.start)
        Diagnostics(self, lambda: [status(OK, "charger_dock: contactor", "Open (not docked)",
                                          "charger-D03")], 5.0)

    def start(self, req, resp):
        self.get_logger().info("Charging requested: closing contactor at dock D-03")
        return resp


# ---------------------------------------------------------------------------------------------
# fork_control: ros2_control-like controller manager with a 100 Hz update thread


class Hydraulics:
    """The mast's state, shared by the controllers and the update thread."""

    def __init__(self) -> None:
        self.height = 0.10  # m
        self.target = 0.10
        self.lock = threading.Lock()


class ControllerManager(Node):
    """ros2_control controller_manager: the 100 Hz read/update/write thread."""

    def __init__(self, hyd: Hydraulics, lift: LiftController) -> None:
        super().__init__("controller_manager", namespace=NS)
        self.h, self.lift = hyd, lift
        self.overruns = 0
        self.log = self.get_logger()
        self.log.info("Loaded hardware 'forklift_mast' (HydraulicMastSystem), 3 state interfaces")
        self.log.info("Configured and activated joint_state_broadcaster, lift_controller")
        Diagnostics(self, self.diag)
        threading.Thread(target=on_shutdown_quiet(self.loop), daemon=True).start()

    def loop(self) -> None:
        period = 0.01
        nxt = time.monotonic()
        while rclpy.ok():
            try:
                self.lift.update(period)
            except Exception:
                traceback.print_exc()
                print("terminate called after throwing an instance of 'std::runtime_error'\n"
                      "  what():  lift_controller update failed", file=sys.stderr, flush=True)
                os._exit(134)
            nxt += period
            d = nxt - time.monotonic()
            if d > 0:
                time.sleep(d)
            else:
                self.overruns += 1
                nxt = time.monotonic()

    def diag(self):
        return [status(OK, "controller_manager: update loop", "OK", "forklift_mast", rate_hz=100,
                       overruns=self.overruns)]


class LiftController(Node):
    """The hydraulic lift controller: ``~/lift`` action (``order`` = fork height in cm; feedback the
    height 10 Hz), a PI loop on the proportional valve in the update thread."""

    def __init__(self, fault_dir: Path, hyd: Hydraulics) -> None:
        super().__init__("lift_controller", namespace=NS)
        self.fault = FaultFile(fault_dir, "lift_controller")
        self.h = hyd
        self.ki = 0.4
        self.integral = 0.0
        self.reloaded = False
        ActionServer(self, Fibonacci, "lift_controller/lift", self.execute,
                     callback_group=ReentrantCallbackGroup())

    def update(self, dt: float) -> None:
        if self.fault.word == "crash" and not self.reloaded:
            self.reloaded = True
            self.ki = float("nan")
            self.get_logger().info("Reloaded gains from /opt/fl/config/lift_controller.yaml "
                                   "(p: 2.0, i: .nan, valve_deadband: 0.05)")
        with self.h.lock:
            err = self.h.target - self.h.height
            self.integral = max(-0.5, min(0.5, self.integral + err * dt))
            u = 2.0 * err + self.ki * self.integral
            if math.isnan(u):
                raise RuntimeError(f"Valve command is NaN (err={err:.3f}, integral={self.integral:.3f}): "
                                   "refusing to write proportional valve PV-1")
            self.h.height += max(-0.3, min(0.3, u)) * dt  # the valve's max flow: 0.3 m/s

    def execute(self, goal) -> Fibonacci.Result:
        target = goal.request.order / 100.0
        self.get_logger().info(f"Lift goal: forks to {target:.2f} m")
        with self.h.lock:
            self.h.target = target
        t0 = time.time()
        while time.time() - t0 < 7.0:
            with self.h.lock:
                h = self.h.height
            goal.publish_feedback(Fibonacci.Feedback(sequence=[int(h * 100)]))
            if abs(h - target) < 0.01:
                goal.succeed()
                self.get_logger().info(f"Lift goal reached: {h:.2f} m in {time.time() - t0:.1f} s")
                return Fibonacci.Result(sequence=[int(h * 100)])
            time.sleep(0.1)
        self.get_logger().warn(f"Lift goal aborted: {h:.2f} m after 7 s (target {target:.2f} m)")
        goal.abort()
        return Fibonacci.Result(sequence=[int(h * 100)])


class JointStateBroadcaster(Node):
    """``/fl/joint_states`` at 50 Hz: the mast lift, the tilt and the side shift."""

    def __init__(self, hyd: Hydraulics) -> None:
        super().__init__("joint_state_broadcaster", namespace=NS)
        self.h = hyd
        self.pub = self.create_publisher(JointState, "joint_states", RELIABLE)
        self.names = ["mast_lift_joint", "fork_tilt_joint", "fork_sideshift_joint"]
        self.create_timer(0.02, self.tick)

    def tick(self) -> None:
        with self.h.lock:
            h = self.h.height
        self.pub.publish(JointState(header=header("base_link"), name=self.names, position=[h, 0.02, 0.0],
                                    velocity=[0.0, 0.0, 0.0], effort=[0.0, 0.0, 0.0]))


class MastHeightSensor(Node):
    """Draw-wire encoder on the mast: ``/fl/mast/height`` Range 20 Hz, stamped 5 ms back."""

    def __init__(self, hyd: Hydraulics) -> None:
        super().__init__("mast_height_sensor", namespace=NS)
        self.h = hyd
        self.pub = self.create_publisher(Range, "mast/height", SENSOR)
        self.create_timer(0.05, self.tick)

    def tick(self) -> None:
        with self.h.lock:
            h = self.h.height
        self.pub.publish(Range(header=header("mast_encoder", time.time() - 0.005),
                               radiation_type=Range.INFRARED, field_of_view=0.0, min_range=0.0, max_range=4.5,
                               range=h + random.gauss(0, 0.001)))


# ---------------------------------------------------------------------------------------------
# fleet_bridge: VDA5050 over MQTT


class Vda5050Bridge(Node):
    """The fleet manager link (MQTT, VDA5050 2.0): orders -> ``/fl/vda5050/order``; mission states ->
    ``/fl/vda5050/state`` on change (buffered while the link is down); ``/fl/vda5050/visualization``
    1 Hz."""

    def __init__(self) -> None:
        super().__init__("vda5050_bridge", namespace=NS)
        self.order_pub = self.create_publisher(String, "vda5050/order", RELIABLE)
        self.state_pub = self.create_publisher(String, "vda5050/state", LATCHED)
        self.viz = self.create_publisher(String, "vda5050/visualization", RELIABLE)
        self.create_subscription(String, "mission_manager/state", self.on_state, LATCHED)
        self.create_subscription(PoseWithCovarianceStamped, "amcl_pose", self.on_pose, LATCHED)
        self.pose = (0.0, 0.0, 0.0)
        self.buffer: list[str] = []
        self.up = True
        self.down_t = 0.0
        self.header_id = 0
        k, _ = move_of()
        self.next_order = k + 1  # orders for moves already begun went to the last run of the bridge
        self.log = self.get_logger()
        self.log.info("Connected to mqtt://fleet.dc-rotterdam.local:1883 as uagv/v2/Acme/FL-07")
        self.create_timer(1.0, self.tick)
        Diagnostics(self, self.diag)

    def on_pose(self, msg: PoseWithCovarianceStamped) -> None:
        p = msg.pose.pose
        self.pose = (p.position.x, p.position.y, yaw_of(p.orientation))

    def on_state(self, msg: String) -> None:
        self.header_id += 1
        s = json.loads(msg.data)
        out = json.dumps({"headerId": self.header_id, "orderId": s.get("order", ""),
                          "actionStates": [{"actionType": s["state"], "actionStatus": "RUNNING"}],
                          "agvPosition": {"x": round(self.pose[0], 3), "y": round(self.pose[1], 3),
                                          "theta": round(self.pose[2], 3), "mapId": "dc-rtm-hall2"}})
        self.state_pub.publish(String(data=out))
        if not self.up:
            self.buffer.append(out)

    def tick(self) -> None:
        up = link_up()
        if up != self.up:
            self.up = up
            if up:
                self.log.info(f"MQTT reconnected to fleet.dc-rotterdam.local:1883 after "
                              f"{time.time() - self.down_t:.1f} s; flushing {len(self.buffer)} buffered "
                              "state messages")
                self.buffer.clear()
            else:
                self.down_t = time.time()
                self.log.warn("MQTT connection to fleet.dc-rotterdam.local:1883 lost (keepalive timeout, "
                              "rc=7); buffering state messages")
        nxt = next((o for o in ORDERS if o[0] >= self.next_order), None)
        now = time.time()
        if up and nxt is not None and now >= move_start(nxt[0]) - 3.0:
            first, n = nxt
            self.next_order = first + n
            if now < move_start(first) + 20.0:
                oid = f"ORD-{48211 + first}"
                self.order_pub.publish(String(data=json.dumps({
                    "orderId": oid, "orderUpdateId": 0,
                    "nodes": [{"nodeId": f"PAL-{first + i:03d}", "sequenceId": 2 * i} for i in range(n)]})))
                self.log.info(f"Order {oid} received ({n} pallets)")
        x, y, th = self.pose
        self.viz.publish(String(data=json.dumps({"headerId": self.header_id, "agvPosition": {
            "x": round(x, 3), "y": round(y, 3), "theta": round(th, 3), "positionInitialized": True},
            "velocity": {"vx": 0.0}})))

    def diag(self):
        return [status(OK if self.up else WARN, "vda5050_bridge: MQTT link", "Connected" if self.up
                       else "Disconnected, buffering", "mqtt-fleet", buffered=len(self.buffer))]


# ---------------------------------------------------------------------------------------------
# recorder, web_bridge, diagnostics, operator


RECORDED = (
    ("/fl/safety/fields", UInt8MultiArray, SENSOR), ("/fl/safety/estop", Bool, LATCHED),
    ("/fl/scan_merged", LaserScan, SENSOR), ("/fl/odometry/filtered", Odometry, SENSOR),
    ("/fl/mast/height", Range, SENSOR), ("/fl/vda5050/order", String, SENSOR),
    ("/fl/amcl_pose", PoseWithCovarianceStamped, LATCHED), ("/fl/cmd_vel", Twist, SENSOR),
    ("/fl/joint_states", JointState, SENSOR), ("/fl/battery_state", BatteryState, SENSOR),
    ("/fl/vda5050/state", String, LATCHED), ("/fl/plan", PathMsg, SENSOR),
    ("/fl/mission_manager/state", String, LATCHED), ("/diagnostics", DiagnosticArray, SENSOR),
    ("/tf", TransformStamped, SENSOR),
)


class Recorder(Node):
    """rosbag2 record-like: 15 topics serialized into a 10 s chunk, compressed and written to a
    temp bag file at each flush (split at 64 MB)."""

    def __init__(self, where: Path) -> None:
        super().__init__("recorder", namespace=NS)
        self.chunk: list[bytes] = []
        self.n = 0
        self.dir = Path(tempfile.mkdtemp(prefix="fl_bag_", dir=where))
        self.file = open(self.dir / "fl_0.mcap", "wb")
        self.split = 0
        for topic, typ, qos in RECORDED:
            self.create_subscription(typ, topic, lambda b, t=topic: self.chunk.append(b), qos, raw=True)
        self.get_logger().info(f"Recording {len(RECORDED)} topics to {self.dir} (zlib chunks, 10 s)")
        self.create_timer(10.0, self.flush)

    def flush(self) -> None:
        data, self.chunk = b"".join(self.chunk), []
        comp = zlib.compress(data, 9)
        self.file.write(comp)
        self.file.flush()
        self.n += 1
        if self.file.tell() > 64 << 20:
            self.file.close()
            os.unlink(self.file.name)
            self.split += 1
            self.file = open(self.dir / f"fl_{self.split}.mcap", "wb")
            self.get_logger().info(f"Bag split: fl_{self.split}.mcap")


WEB_TOPICS = (("/fl/scan_merged", LaserScan, SENSOR), ("/fl/odometry/filtered", Odometry, SENSOR),
              ("/tf", TransformStamped, SENSOR), ("/fl/plan", PathMsg, SENSOR),
              ("/fl/vda5050/visualization", String, SENSOR), ("/diagnostics_agg", DiagnosticArray, SENSOR),
              ("/fl/front_scanner/scan_throttle", LaserScan, SENSOR))


class FoxgloveBridge(Node):
    """foxglove_bridge-like: a dashboard client connects 40 s every 90 s and subscribes 7 topics."""

    def __init__(self) -> None:
        super().__init__("foxglove_bridge", namespace=NS)
        self.subs = []
        self.get_logger().info("Server listening on port 8765")
        self.create_timer(1.0, self.tick)

    def tick(self) -> None:
        e = elapsed() % 90.0
        want = 20.0 <= e < 60.0
        if want and not self.subs:
            self.get_logger().info("Client 10.20.4.117:53012 connected via Foxglove Studio")
            self.subs = [self.create_subscription(t, n, lambda _b: None, q, raw=True)
                         for n, t, q in WEB_TOPICS]
        elif not want and self.subs:
            for s in self.subs:
                self.destroy_subscription(s)
            self.subs = []
            self.get_logger().info("Client 10.20.4.117:53012 disconnected")


GROUPS = (("safety_plc", "Safety"), ("scanner", "Sensors"), ("camera", "Sensors"),
          ("ekf", "Localization"), ("drive", "Drive"), ("battery", "Power"), ("charger", "Power"),
          ("controller_server", "Navigation"), ("controller_manager", "Forks"), ("vda5050", "Fleet"))


class DiagnosticAggregator(Node):
    """diagnostic_aggregator: ``/diagnostics`` -> ``/diagnostics_agg`` 1 Hz, STALE after 5 s."""

    def __init__(self) -> None:
        super().__init__("diagnostic_aggregator")
        self.last: dict[str, tuple[float, DiagnosticStatus]] = {}
        self.create_subscription(DiagnosticArray, "/diagnostics", self.on_diag, RELIABLE)
        self.pub = self.create_publisher(DiagnosticArray, "/diagnostics_agg", RELIABLE)
        self.create_timer(1.0, self.tick)

    def on_diag(self, msg: DiagnosticArray) -> None:
        now = time.time()
        for s in msg.status:
            self.last[s.name] = (now, s)

    def tick(self) -> None:
        now = time.time()
        out = []
        for name, (t, s) in sorted(self.last.items()):
            group = next((g for key, g in GROUPS if key in name), "Other")
            out.append(DiagnosticStatus(level=STALE if now - t > 5 else s.level,
                                        name=f"/Forklift/{group}/{name}", message=s.message,
                                        hardware_id=s.hardware_id, values=s.values))
        self.pub.publish(DiagnosticArray(header=header(""), status=out))


class OperatorConsole(Node):
    """A shift lead's ``ros2 topic echo`` of the mission state and the battery."""

    def __init__(self) -> None:
        super().__init__("operator_console", namespace=NS)
        self.create_subscription(String, "mission_manager/state", lambda m: print(m.data, flush=True),
                                 LATCHED)
        self.create_subscription(BatteryState, "battery_state",
                                 lambda m: print(f"battery {m.percentage * 100:.1f} %", flush=True), RELIABLE)


# ---------------------------------------------------------------------------------------------


def build(process: str, fault_dir: Path):
    """The process's executor, its nodes added."""
    if process == "plc_bridge":
        return single_threaded(SafetyPlcBridge(fault_dir))
    if process == "sensor_container":
        return single_threaded(SafetyScanner("front_scanner", fault_dir, 0),
                               SafetyScanner("rear_scanner", fault_dir, 1), PalletCamera(fault_dir))
    if process == "scan_tools":
        return single_threaded(LaserMerger(fault_dir), ScanThrottle(), OdomRelay())
    if process == "localization":
        return single_threaded(Ekf(), Amcl())
    if process == "base_driver":
        shared = DriveState()
        return single_threaded(DriveController(shared), ImuDriver(fault_dir, shared), BatteryManager())
    if process == "navigation":
        ex = MultiThreadedExecutor(num_threads=6)
        for n in (BtNavigator(), PlannerServer(fault_dir), ControllerServer(), VelocitySmoother(),
                  CollisionMonitor()):
            ex.add_node(n)
        return ex
    if process == "pallet_detection":
        return single_threaded(PalletDetector(fault_dir))
    if process == "mission":
        return single_threaded(MissionManager(), LifecycleManager(), ChargerDock())
    if process == "fork_control":
        hyd = Hydraulics()
        lift = LiftController(fault_dir, hyd)
        ex = MultiThreadedExecutor(num_threads=2)
        for n in (ControllerManager(hyd, lift), JointStateBroadcaster(hyd), lift, MastHeightSensor(hyd)):
            ex.add_node(n)
        return ex
    if process == "fleet_bridge":
        return single_threaded(Vda5050Bridge())
    if process == "recorder":
        return single_threaded(Recorder(fault_dir.parent))
    if process == "web_bridge":
        return single_threaded(FoxgloveBridge())
    if process == "diagnostics":
        return single_threaded(DiagnosticAggregator())
    if process == "operator":
        return single_threaded(OperatorConsole())
    raise SystemExit(f"unknown process {process!r}")


def main(argv: list[str]) -> None:
    process, fault_dir = argv[0], Path(argv[1])
    run_for = float(argv[2]) if len(argv) > 2 else 0.0
    rclpy.init()
    ex = build(process, fault_dir)
    hooks = {}
    if process == "recorder":
        hooks["cpu"] = lambda: ex.get_nodes()[0].get_logger().warn(
            "Compression level changed to 19 (storage_preset_profile: resilient): chunk compression "
            "falling behind, 3 chunks queued")
    spin(ex, fault_dir, process, run_for, hooks)


if __name__ == "__main__":
    main(sys.argv[1:])
