"""One process of the sidewalk delivery robot "courier" (the design: `bench.courier.run`).

``python -m bench.courier.robot PROCESS FAULT_DIR [RUN_FOR]``

Every process builds its nodes, puts them on its executor (a component container holds several
nodes on one executor), polls ``FAULT_DIR`` about once a second (each node's fault file
``FAULT_DIR/<namespace.name>``, the process's ``FAULT_DIR/<process>.cpu`` and ``.leak``) and ends
cleanly on SIGINT/SIGTERM. ``RUN_FOR`` > 0 ends the process by itself with code 0 (the operator's
console). The world the robot lives in (when it drives, waits at a crossing, meets pedestrians, is
stuck and teleoperated, delivers) is one shared schedule computed from the wall clock, so every
process agrees on it without talking.
"""

from __future__ import annotations

import array
import functools
import json
import math
import os
import random
import signal
import sys
import threading
import time
import traceback
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
import rclpy
from action_msgs.msg import GoalStatus
from builtin_interfaces.msg import Time as TimeMsg
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import (
    Point32,
    PolygonStamped,
    Pose,
    PoseArray,
    PoseStamped,
    TransformStamped,
    Twist,
    TwistStamped,
)
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from nav_msgs.msg import OccupancyGrid, Odometry
from nav_msgs.msg import Path as PathMsg
from nav_msgs.srv import GetPlan
from rcl_interfaces.msg import SetParametersResult
from rcl_interfaces.srv import SetParameters
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import (
    BatteryState,
    CameraInfo,
    CompressedImage,
    Image,
    Imu,
    JointState,
    LaserScan,
    NavSatFix,
    NavSatStatus,
)
from std_msgs.msg import Bool, Float32, Header, String
from std_srvs.srv import Trigger
from test_msgs.action import Fibonacci

# --------------------------------------------------------------------------------------------- QoS
SENSOR = qos_profile_sensor_data  # best effort, keep last 5, volatile
RELIABLE = QoSProfile(depth=10)
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
TF = QoSProfile(depth=100)
TF_STATIC = QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL)

NS = "/dlv"
SHUTDOWN = threading.Event()  # SIGINT / SIGTERM / RUN_FOR reached: every loop and blocked read ends

# ------------------------------------------------------------------------------------------ world
EPOCH_S = 120.0  # one delivery round: hub -> drop-off -> back
SEED = "courier-sidewalk-v1"


@dataclass(frozen=True)
class Plan:
    """One delivery round of the world: its phases and what happens around the robot."""

    epoch: int
    start: float
    segments: tuple[tuple[str, float, float], ...]  # (phase, t0, t1), absolute wall times
    peds: tuple[tuple[float, float, float], ...]  # (t0, t1, closest range in m) pedestrians in view
    canopy: tuple[tuple[float, float], ...]  # under trees: GNSS RTK float
    weak: tuple[tuple[float, float, float], ...]  # (t0, t1, link quality) weak cellular coverage
    order: str


@functools.lru_cache(maxsize=16)
def plan(k: int) -> Plan:
    rng = random.Random(f"{SEED}:{k}")
    start = k * EPOCH_S
    end = start + EPOCH_S
    t = start
    segs: list[tuple[str, float, float]] = []

    def add(phase: str, lo: float, hi: float) -> None:
        nonlocal t
        d = rng.uniform(lo, hi)
        segs.append((phase, t, t + d))
        t += d

    add("idle", 8, 14)
    add("driving", 12, 20)
    add("crossing", 7, 12)
    add("driving", 10, 18)
    if rng.random() < 0.7:
        add("stuck", 8, 14)
        add("driving", 6, 12)
    add("delivering", 8, 12)
    rest = end - t
    if rest > 34:
        add("driving", 10, rest - 24)
        add("crossing", 7, 10)
    segs.append(("driving", t, end))
    peds = []
    for phase, a, b in segs:
        if phase == "driving" and b - a > 10 and rng.random() < 0.65:
            s = rng.uniform(a + 2, b - 6)
            peds.append((s, min(s + rng.uniform(3, 7), b - 0.5), rng.uniform(0.4, 3.0)))
        elif phase == "crossing":
            peds.append((a + 0.5, a + rng.uniform(3, 5), rng.uniform(1.5, 4.0)))
    canopy = []
    for _ in range(rng.choice((1, 2))):
        s = rng.uniform(start, end - 15)
        canopy.append((s, s + rng.uniform(6, 15)))
    weak = []
    for _ in range(rng.choice((1, 1, 2))):
        s = rng.uniform(start, end - 25)
        weak.append((s, s + rng.uniform(8, 25), rng.uniform(0.12, 0.5)))
    return Plan(k, start, tuple(segs), tuple(peds), tuple(canopy), tuple(weak),
                f"D-{(k * 7919) % 100000:05d}")


@dataclass(frozen=True)
class World:
    """The world at one instant."""

    t: float
    plan: Plan
    phase: str
    t0: float
    t1: float
    leg: int  # index of the segment in its round

    @property
    def ped_range(self) -> float | None:
        for a, b, r in self.plan.peds:
            if a <= self.t < b:
                u = (self.t - a) / (b - a)
                return r + (6.0 - r) * abs(2 * u - 1)
        return None

    @property
    def canopy(self) -> bool:
        return any(a <= self.t < b for a, b in self.plan.canopy)

    @property
    def link(self) -> float:
        for a, b, q in self.plan.weak:
            if a <= self.t < b:
                return q
        return 0.78 + 0.12 * math.sin(self.t / 23.0) + 0.05 * math.sin(self.t / 7.3)

    @property
    def light(self) -> str | None:
        if self.phase != "crossing":
            return None
        return "red" if self.t < self.t1 - 3.5 else "green"

    @property
    def crosswalk(self) -> float | None:
        """Distance to a crosswalk in view (m), None when none is."""
        if self.phase == "crossing":
            return 0.5
        segs = self.plan.segments
        if self.phase == "driving" and self.leg + 1 < len(segs) and segs[self.leg + 1][0] == "crossing":
            left = self.t1 - self.t
            if left < 4.0:
                return 0.5 + 1.5 * left
        return None

    @property
    def moving(self) -> bool:
        return self.phase in ("driving", "stuck") or (self.phase == "crossing" and self.light == "green")


def world(t: float | None = None) -> World:
    t = time.time() if t is None else t
    p = plan(int(t // EPOCH_S))
    for i, (phase, a, b) in enumerate(p.segments):
        if a <= t < b:
            return World(t, p, phase, a, b, i)
    phase, a, b = p.segments[-1]
    return World(t, p, phase, a, b, len(p.segments) - 1)


# ----------------------------------------------------------------------------------------- faults
class FaultBoard:
    """The fault files of a process's nodes and its CPU burner / leak files, polled once a second."""

    def __init__(self) -> None:
        self.dir = Path("/nonexistent")
        self.process = ""
        self.words: dict[str, str] = {}
        self.cpu_hooks: list = []
        self._cpu = self._leak = False

    def setup(self, fault_dir: str, process: str) -> None:
        self.dir, self.process = Path(fault_dir), process
        threading.Thread(target=self._poll, name="fault-poll", daemon=True).start()

    def register(self, key: str) -> None:
        self.words[key] = self._read(key)

    def word(self, key: str) -> str:
        return self.words.get(key, "")

    def _read(self, key: str) -> str:
        try:
            return (self.dir / key).read_text().strip()
        except OSError:
            return ""

    def _poll(self) -> None:
        while not SHUTDOWN.wait(1.0):
            for key in list(self.words):
                self.words[key] = self._read(key)
            if not self._cpu and (self.dir / f"{self.process}.cpu").exists():
                self._cpu = True
                for hook in self.cpu_hooks:
                    hook()
                threading.Thread(target=self._burn, name="burner", daemon=True).start()
            if not self._leak and (self.dir / f"{self.process}.leak").exists():
                self._leak = True
                threading.Thread(target=self._hoard, name="hoard", daemon=True).start()

    @staticmethod
    def _burn() -> None:
        while not SHUTDOWN.is_set():
            n = 0
            for i in range(20000):
                n += i * i

    @staticmethod
    def _hoard() -> None:
        kept = []
        while not SHUTDOWN.wait(1.0):
            kept.append(b"\x5a" * (3 << 20))  # touched pages: the RSS grows ~3 MB/s


BOARD = FaultBoard()


def stamp_ns(ns: int) -> TimeMsg:
    return TimeMsg(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def age_of(node: Node, stamp: TimeMsg) -> float:
    return (node.get_clock().now().nanoseconds - (stamp.sec * 1_000_000_000 + stamp.nanosec)) / 1e9


class Part:
    """What every courier node shares: its fault word and header stamps."""

    def _part(self) -> None:
        self._key = self.get_fully_qualified_name().strip("/").replace("/", ".")
        BOARD.register(self._key)

    @property
    def fault(self) -> str:
        return BOARD.word(self._key)

    def stamp(self, age: float = 0.0) -> TimeMsg:
        """A header stamp ``age`` s before now (negative: in the future)."""
        return stamp_ns(self.get_clock().now().nanoseconds - int(age * 1e9))

    @property
    def log(self):
        return self.get_logger()


class CNode(Part, Node):
    def __init__(self, name: str, namespace: str = NS, **kw) -> None:
        Node.__init__(self, name, namespace=namespace, **kw)
        self._part()


class LNode(Part, LifecycleNode):
    def __init__(self, name: str, namespace: str = NS, **kw) -> None:
        LifecycleNode.__init__(self, name, namespace=namespace, **kw)
        self._part()
        self.active = False

    def on_configure(self, state) -> TransitionCallbackReturn:
        self.log.info("Configuring")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        self.log.info("Activating")
        self.active = True
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        self.log.info("Deactivating")
        self.active = False
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state) -> TransitionCallbackReturn:
        return TransitionCallbackReturn.SUCCESS


class Diag:
    """diagnostic_updater's role: one status per task, "node_name: task", 1 Hz on /diagnostics."""

    def __init__(self, node: Node, hardware_id: str, tasks: dict, group=None) -> None:
        self.node, self.hw, self.tasks = node, hardware_id, tasks
        self.pub = node.create_publisher(DiagnosticArray, "/diagnostics", RELIABLE)
        node.create_timer(1.0, self._tick, callback_group=group)

    def _tick(self) -> None:
        msg = DiagnosticArray()
        msg.header.stamp = self.node.get_clock().now().to_msg()
        for task, fn in self.tasks.items():
            level, text, values = fn()
            msg.status.append(DiagnosticStatus(
                level=bytes([level]), name=f"{self.node.get_name()}: {task}", message=text,
                hardware_id=self.hw, values=[KeyValue(key=k, value=str(v)) for k, v in values.items()]))
        self.pub.publish(msg)


OK, WARN, ERROR, STALE = 0, 1, 2, 3


# ---------------------------------------------------------------------------------------- sensors
class GnssDriver(CNode):
    """u-blox F9P RTK receiver: /dlv/gnss/fix 5 Hz, best effort."""

    def __init__(self) -> None:
        super().__init__("gnss_driver")
        self.pub = self.create_publisher(NavSatFix, "gnss/fix", SENSOR)
        self.float_ = False
        self.create_timer(0.2, self.tick)
        Diag(self, "ublox-f9p-SN4471", {"fix": self.status})

    def tick(self) -> None:
        w = world()
        if w.canopy != self.float_:
            self.float_ = w.canopy
            if w.canopy:
                self.log.warn(f"RTK float: {random.randint(4, 8)} satellites lost under canopy "
                              f"(hAcc {random.uniform(0.3, 0.7):.2f} m)")
            else:
                self.log.info("RTK fixed (hAcc 0.02 m)")
        age = 0.08 + random.uniform(0.0, 0.03)  # solution latency of the receiver
        if self.fault == "stale":  # PPS lost: the receiver's clock drifts, stamps seconds old
            age += 4.5 + random.uniform(0.0, 0.3)
        m = NavSatFix()
        m.header.stamp = self.stamp(age)
        m.header.frame_id = "gnss_link"
        m.status.status = NavSatStatus.STATUS_SBAS_FIX if self.float_ else NavSatStatus.STATUS_GBAS_FIX
        m.status.service = NavSatStatus.SERVICE_GPS | NavSatStatus.SERVICE_GALILEO
        m.latitude = 37.7749 + 0.0004 * math.sin(w.t / 90.0)
        m.longitude = -122.4194 + 0.0004 * math.cos(w.t / 90.0)
        m.altitude = 16.0
        var = 0.25 if self.float_ else 0.0004
        m.position_covariance = [var, 0.0, 0.0, 0.0, var, 0.0, 0.0, 0.0, 4 * var]
        m.position_covariance_type = NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN
        self.pub.publish(m)

    def status(self):
        if self.float_:
            return WARN, "RTK float", {"satellites": 14, "hAcc": 0.5}
        return OK, "RTK fixed", {"satellites": 21, "hAcc": 0.02}


class ImuDriver(CNode):
    """Bosch BMI088 over a serial bridge: /dlv/imu/data 25 Hz, best effort."""

    def __init__(self) -> None:
        super().__init__("imu_driver")
        self.pub = self.create_publisher(Imu, "imu/data", SENSOR)
        self.create_timer(1 / 25, self.tick)
        Diag(self, "bmi088-ttyUSB1", {"imu": lambda: (OK, "OK", {"temperature": 41.5})})

    def tick(self) -> None:
        if self.fault == "hang":
            self._read_frame()
        m = Imu()
        m.header.stamp = self.stamp(0.004)
        m.header.frame_id = "imu_link"
        jitter = 0.02 if world().moving else 0.002
        m.orientation.w = 1.0
        m.angular_velocity.z = random.gauss(0.0, jitter)
        m.linear_acceleration.x = random.gauss(0.0, 5 * jitter)
        m.linear_acceleration.z = 9.81 + random.gauss(0.0, 5 * jitter)
        m.orientation_covariance[0] = m.orientation_covariance[4] = m.orientation_covariance[8] = 0.001
        self.pub.publish(m)

    @staticmethod
    def _read_frame() -> None:
        """The serial bridge stops answering: read() on the tty never returns."""
        SHUTDOWN.wait()


class WheelOdometry(CNode):
    """Six-wheel skid-steer odometry from the motor controller's encoders: /dlv/wheel/odom 20 Hz."""

    def __init__(self) -> None:
        super().__init__("wheel_odometry")
        self.create_subscription(JointState, "motor/joint_states", self.on_joints, SENSOR)
        self.pub = self.create_publisher(Odometry, "wheel/odom", SENSOR)
        self.last = None
        self.last_t = time.monotonic() + 5.0  # start-up grace: the motor controller may start later
        self.x = self.y = self.yaw = 0.0
        self.create_timer(1.0, self.watchdog)

    def watchdog(self) -> None:
        gap = time.monotonic() - self.last_t
        if gap > 1.0:
            self.log.warn(f"no wheel encoder data for {gap:.1f} s; odometry is not updated",
                          throttle_duration_sec=5.0)

    def on_joints(self, m: JointState) -> None:
        """diff_drive_controller style: one odometry message per encoder update (20 Hz)."""
        dt = max(0.0, min(0.2, time.monotonic() - self.last_t))
        self.last, self.last_t = m, time.monotonic()
        v = sum(m.velocity) / len(m.velocity) * 0.165 if m.velocity else 0.0  # wheel radius
        self.x += v * dt * math.cos(self.yaw)
        self.y += v * dt * math.sin(self.yaw)
        m = Odometry()
        m.header.stamp = self.last.header.stamp
        m.header.frame_id = "odom"
        m.child_frame_id = "base_link"
        m.pose.pose.position.x, m.pose.pose.position.y = self.x, self.y
        m.pose.pose.orientation.w = 1.0
        m.twist.twist.linear.x = v
        self.pub.publish(m)


class BatteryMonitor(CNode):
    """48 V pack BMS over CAN: /dlv/battery 1 Hz."""

    def __init__(self) -> None:
        super().__init__("battery_monitor")
        self.pub = self.create_publisher(BatteryState, "battery", RELIABLE)
        self.soc = 0.92
        self.create_timer(1.0, self.tick)
        Diag(self, "bms-48v-pack2", {"battery": lambda: (OK if self.soc > 0.2 else WARN,
                                                        f"{self.soc * 100:.0f} %", {"voltage": 49.1})})

    def tick(self) -> None:
        w = world()
        self.soc = max(0.25, self.soc - (0.0004 if w.moving else 0.00005))
        m = BatteryState()
        m.header.stamp = self.stamp(0.02)
        m.header.frame_id = "battery"
        m.voltage = 44.0 + 8.0 * self.soc
        m.current = -18.0 if w.moving else -3.5
        m.percentage = self.soc
        m.power_supply_status = BatteryState.POWER_SUPPLY_STATUS_DISCHARGING
        m.present = True
        self.pub.publish(m)


def _scan_base() -> array.array:
    r = array.array("f")
    for i in range(360):
        a = math.radians(i - 180)
        wall = 2.8 / abs(math.sin(a)) if a > 0.15 else 12.0  # building on the left, street on the right
        r.append(min(wall, 12.0) if math.sin(a) > 0.05 else 12.0)
    return r


class LidarDriver(CNode):
    """Ouster-style 2D scan: /dlv/scan 10 Hz, best effort."""

    def __init__(self) -> None:
        super().__init__("lidar_driver")
        self.pub = self.create_publisher(LaserScan, "scan", SENSOR)
        self.base = _scan_base()
        self.n = 0
        self.create_timer(0.1, self.tick)
        Diag(self, "os0-32-992109", {"scan": self.status})

    def status(self):
        if self.fault == "degraded":
            return WARN, "packet loss", {"packets_per_rev": random.randint(80, 110), "expected": 360}
        return OK, "OK", {"packets_per_rev": 360, "expected": 360}

    def tick(self) -> None:
        self.n += 1
        if self.fault == "degraded":  # a failing eth link: most revolutions arrive incomplete
            if self.n % 6:
                return
            self.log.warn(f"incomplete revolution: received {random.randint(80, 110)}/360 packets",
                          throttle_duration_sec=15.0)
        w = world()
        m = LaserScan()
        m.header.stamp = self.stamp(0.1)  # the revolution started 100 ms ago
        m.header.frame_id = "lidar_link"
        m.angle_min, m.angle_max = -math.pi, math.pi * 179 / 180
        m.angle_increment = math.pi / 180
        m.scan_time, m.time_increment = 0.1, 0.1 / 360
        m.range_min, m.range_max = 0.1, 30.0
        r = array.array("f", self.base)
        ped = w.ped_range
        if ped is not None:
            for i in range(172, 189):
                r[i] = ped + 0.05 * abs(i - 180)
        m.ranges = r
        self.pub.publish(m)


class FrontCamera(CNode):
    """Front RGB camera (downscaled for the bench): /dlv/front_camera/image_raw 10 Hz + camera_info."""

    def __init__(self, group) -> None:
        super().__init__("front_camera")
        self.pub = self.create_publisher(Image, "front_camera/image_raw", SENSOR)
        self.info = self.create_publisher(CameraInfo, "front_camera/camera_info", SENSOR)
        rng = np.random.default_rng(7)
        self.frames = [rng.integers(0, 255, 64 * 48 * 3, dtype=np.uint8).tobytes() for _ in range(4)]
        self.n = 0
        self.create_timer(0.1, self.tick, callback_group=group)
        Diag(self, "imx390-front", {"camera": lambda: (OK, "streaming", {"fps": 10})}, group)

    def tick(self) -> None:
        self.n += 1
        m = Image()
        m.header.stamp = self.stamp(0.035)  # mid-exposure
        m.header.frame_id = "front_camera_optical"
        m.height, m.width, m.encoding, m.step = 48, 64, "rgb8", 64 * 3
        m.data = self.frames[self.n % 4]
        self.pub.publish(m)
        ci = CameraInfo()
        ci.header = m.header
        ci.height, ci.width = 48, 64
        ci.distortion_model = "plumb_bob"
        ci.k = [60.0, 0.0, 32.0, 0.0, 60.0, 24.0, 0.0, 0.0, 1.0]
        self.info.publish(ci)


class ImageCompressor(CNode):
    """image_transport's compressed plugin: compresses only while someone subscribes."""

    def __init__(self, group) -> None:
        super().__init__("image_compressor")
        self.pub = self.create_publisher(CompressedImage, "front_camera/image_raw/compressed", SENSOR)
        self.create_subscription(Image, "front_camera/image_raw", self.on_image, SENSOR, callback_group=group)

    def on_image(self, m: Image) -> None:
        if self.pub.get_subscription_count() == 0:
            return
        c = CompressedImage()
        c.header = m.header
        c.format = "rgb8; jpeg compressed bgr8"
        c.data = zlib.compress(bytes(m.data), 1)
        self.pub.publish(c)


MODES = {"HIGH": (10, 2500, "720p"), "MEDIUM": (5, 1000, "480p"), "LOW": (2, 300, "240p")}


class VideoUplink(CNode):
    """WebRTC uplink to the teleop supervisors: frame rate and bitrate follow the cellular link."""

    def __init__(self) -> None:
        super().__init__("video_uplink")
        self.create_subscription(Image, "front_camera/image_raw", self.on_image, SENSOR)
        self.create_subscription(Float32, "modem/link_quality", self.on_link, RELIABLE)
        self.video = self.create_publisher(CompressedImage, "uplink/video", SENSOR)
        self.stats = self.create_publisher(String, "uplink/stats", RELIABLE)
        self.frame = None
        self.link = 0.8
        self.mode = "HIGH"
        self.low_since = self.good_since = time.monotonic()
        self.sent = 0
        self.n = 0
        self.create_timer(1.0, self.adapt)
        Diag(self, "nvenc0", {"encoder": lambda: (OK, self.mode, {"kbps": MODES[self.mode][1]})})
        self.aborting = None
        self._check_driver()
        self.create_timer(1.0, self._check_driver)  # the running pipeline meets the broken driver too
        self.log.info("uplink pipeline PLAYING: 720p@10fps, 2500 kbps")

    def _check_driver(self) -> None:
        if self.fault == "abort" and self.aborting is None:  # a broken encoder driver: aborts soon after
            self.aborting = self.create_timer(random.uniform(2.0, 3.0), self._abort)

    def _abort(self) -> None:
        self.log.fatal("gst: nvv4l2h264enc0: NvEnc session lost (error -5): pipeline aborted")
        sys.stdout.flush()
        sys.stderr.flush()
        os.abort()

    def on_image(self, m: Image) -> None:
        """The encoder takes every camera frame at HIGH, every 2nd at MEDIUM, every 5th at LOW."""
        self.frame = m
        self.n += 1
        if self.n % (10 // MODES[self.mode][0]) == 0:
            self.send()

    def on_link(self, m: Float32) -> None:
        self.link = m.data

    def adapt(self) -> None:
        now = time.monotonic()
        want = "HIGH" if self.link > 0.6 else "MEDIUM" if self.link > 0.3 else "LOW"
        order = ["LOW", "MEDIUM", "HIGH"]
        if order.index(want) < order.index(self.mode):
            self.good_since = now
            if now - self.low_since >= 2.0:
                self._switch(want, True)
        elif order.index(want) > order.index(self.mode):
            self.low_since = now
            if now - self.good_since >= 5.0:
                self._switch(order[order.index(self.mode) + 1], False)
        else:
            self.low_since = self.good_since = now
        s = String()
        fps, kbps, res = MODES[self.mode]
        s.data = json.dumps({"mode": self.mode, "fps": fps, "kbps": kbps, "res": res, "frames": self.sent,
                             "link": round(self.link, 2)})
        self.stats.publish(s)

    def _switch(self, mode: str, down: bool) -> None:
        fps, kbps, res = MODES[mode]
        text = (f"link quality {self.link:.2f}: switching uplink {self.mode} -> {mode} "
                f"({res}@{fps}fps, {kbps} kbps)")
        if down:
            self.log.warn(text)
        else:
            self.log.info(text)
        self.mode = mode

    def send(self) -> None:
        if self.frame is None:
            return
        c = CompressedImage()
        c.header = self.frame.header
        c.format = "h264"
        c.data = bytes(MODES[self.mode][1] // 8 // MODES[self.mode][0] * 8)[:2000]
        self.video.publish(c)
        self.sent += 1


# ------------------------------------------------------------------------------------- perception
class ObstacleTracker(CNode):
    """Lidar + camera pedestrian tracker: /dlv/obstacles only while something is in view."""

    def __init__(self, group) -> None:
        super().__init__("obstacle_tracker")
        self.create_subscription(LaserScan, "scan", self.on_scan, SENSOR, callback_group=group)
        self.create_subscription(Image, "front_camera/image_raw", self.on_image, SENSOR, callback_group=group)
        self.pub = self.create_publisher(PoseArray, "obstacles", RELIABLE)
        self.img = np.zeros((48, 64, 3), np.float32)
        self.tracking = False

    def on_image(self, m: Image) -> None:
        self.img = np.frombuffer(bytes(m.data), np.uint8).reshape(48, 64, 3).astype(np.float32)

    def on_scan(self, m: LaserScan) -> None:
        r = np.asarray(m.ranges, np.float32)
        front = r[150:210]
        close = front < 5.0
        if not close.any():
            if self.tracking:
                self.log.debug("track lost")
            self.tracking = False
            return
        self.tracking = True
        # the camera branch of the tracker: appearance features of the detection crops
        big = np.kron(self.img.mean(axis=2), np.ones((4, 4), np.float32))
        for _ in range(3):
            np.abs(np.fft.rfft2(big))
        ang = np.radians(np.arange(150, 210)[close] - 180)
        out = PoseArray()
        out.header = m.header
        p = Pose()
        p.position.x = float(np.mean(front[close] * np.cos(ang)))
        p.position.y = float(np.mean(front[close] * np.sin(ang)))
        p.orientation.w = 1.0
        out.poses.append(p)
        self.pub.publish(out)


class CrosswalkDetector(CNode):
    """Segmentation net finding crosswalks: /dlv/crosswalk 5 Hz (empty polygon: none in view)."""

    def __init__(self, group) -> None:
        super().__init__("crosswalk_detector")
        self.create_subscription(Image, "front_camera/image_raw", self.on_image, SENSOR, callback_group=group)
        self.pub = self.create_publisher(PolygonStamped, "crosswalk", RELIABLE)
        self.n = 0

    def on_image(self, m: Image) -> None:
        self.n += 1
        if self.n % 2:  # the net runs on every other frame
            return
        out = PolygonStamped()
        out.header.stamp = m.header.stamp
        out.header.frame_id = "base_link"
        d = world().crosswalk
        if d is not None:
            out.polygon.points = [Point32(x=d, y=-2.0), Point32(x=d, y=2.0),
                                  Point32(x=d + 3.5, y=2.0), Point32(x=d + 3.5, y=-2.0)]
        self.pub.publish(out)


class TrafficLightDetector(CNode):
    """Pedestrian-signal classifier: /dlv/traffic_light while a crosswalk is right ahead."""

    def __init__(self) -> None:
        super().__init__("traffic_light_detector")
        self.create_subscription(PolygonStamped, "crosswalk", self.on_crosswalk, RELIABLE)
        self.pub = self.create_publisher(String, "traffic_light", RELIABLE)
        self.camera = None  # the camera subscription exists only while a crosswalk is right ahead
        self.cpu = False
        BOARD.cpu_hooks.append(self._fallback)

    def _fallback(self) -> None:
        self.cpu = True
        self.log.warn("TensorRT: CUDA error 999 (unknown error) creating execution context; "
                      "falling back to CPUExecutionProvider")

    def on_crosswalk(self, m: PolygonStamped) -> None:
        near = bool(m.polygon.points) and m.polygon.points[0].x < 2.0
        if near and self.camera is None:
            self.camera = self.create_subscription(Image, "front_camera/image_raw", self.on_image, SENSOR)
        elif not near and self.camera is not None:
            self.destroy_subscription(self.camera)
            self.camera = None

    def on_image(self, m: Image) -> None:
        t = time.monotonic()
        img = np.frombuffer(bytes(m.data), np.uint8).reshape(48, 64, 3).mean(axis=2)
        big = np.kron(img, np.ones((4, 4), np.float32))
        for _ in range(120 if self.cpu else 2):
            np.abs(np.fft.rfft2(big))
        took = time.monotonic() - t
        if took > 0.1:
            self.log.warn(f"inference took {took * 1000:.0f} ms (budget 100 ms)", throttle_duration_sec=10.0)
        light = world().light or "unknown"
        out = String()
        out.data = json.dumps({"state": light, "confidence": round(random.uniform(0.86, 0.99), 2),
                               "stamp": time.time() - age_of(self, m.header.stamp)})
        self.pub.publish(out)


# ----------------------------------------------------------------------------------- localization
class EkfFilter(CNode):
    """robot_localization-style EKF: /dlv/odometry/filtered 10 Hz and odom->base_link on /tf."""

    def __init__(self) -> None:
        super().__init__("ekf_filter")
        self.create_subscription(Imu, "imu/data", self.on_imu, SENSOR)
        self.create_subscription(Odometry, "wheel/odom", self.on_odom, SENSOR)
        self.pub = self.create_publisher(Odometry, "odometry/filtered", RELIABLE)
        self.tf = self.create_publisher(TransformStamped, "/tf", TF)
        self.t_imu = self.t_odom = time.monotonic() + 5.0  # start-up grace
        self.odom = Odometry()
        self.create_timer(0.1, self.tick)

    def on_imu(self, m: Imu) -> None:
        self.t_imu = time.monotonic()

    def on_odom(self, m: Odometry) -> None:
        self.t_odom, self.odom = time.monotonic(), m

    def tick(self) -> None:
        now = time.monotonic()
        if now - self.t_imu > 0.5:
            self.log.warn(f"No IMU data received for {now - self.t_imu:.1f} s", throttle_duration_sec=5.0)
        if now - self.t_odom > 0.5:
            self.log.warn(f"No wheel odometry received for {now - self.t_odom:.1f} s",
                          throttle_duration_sec=5.0)
        m = Odometry()
        m.header.stamp = self.stamp(0.0)
        m.header.frame_id, m.child_frame_id = "odom", "base_link"
        m.pose = self.odom.pose
        m.twist = self.odom.twist
        self.pub.publish(m)
        t = TransformStamped()
        t.header = m.header
        t.child_frame_id = "base_link"
        t.transform.translation.x = m.pose.pose.position.x
        t.transform.translation.y = m.pose.pose.position.y
        t.transform.rotation.w = 1.0
        self.tf.publish(t)


class NavsatTransform(CNode):
    """GNSS -> map frame: /dlv/odometry/gps per fix, map->odom on /tf 5 Hz postdated like AMCL."""

    TRANSFORM_TOLERANCE = 0.2  # s the map->odom transform is stamped into the future
    MAX_FIX_AGE = 1.0

    def __init__(self) -> None:
        super().__init__("navsat_transform")
        self.create_subscription(NavSatFix, "gnss/fix", self.on_fix, SENSOR)
        self.create_subscription(Odometry, "odometry/filtered", self.on_odom, RELIABLE)
        self.pub = self.create_publisher(Odometry, "odometry/gps", RELIABLE)
        self.tf = self.create_publisher(TransformStamped, "/tf", TF)
        self.t_fix = time.monotonic() + 5.0  # start-up grace
        self.offset = (0.0, 0.0)
        self.create_timer(0.2, self.tick)

    def on_odom(self, m: Odometry) -> None:
        pass

    def on_fix(self, m: NavSatFix) -> None:
        self.t_fix = time.monotonic()
        age = age_of(self, m.header.stamp)
        if age > self.MAX_FIX_AGE:
            self.log.warn(f"GNSS fix is {age:.2f} s old (limit {self.MAX_FIX_AGE:.2f} s); discarding it",
                          throttle_duration_sec=5.0)
            return
        o = Odometry()
        o.header.stamp = m.header.stamp
        o.header.frame_id, o.child_frame_id = "map", "base_link"
        o.pose.pose.position.x = (m.longitude + 122.4194) * 88000.0
        o.pose.pose.position.y = (m.latitude - 37.7749) * 111000.0
        o.pose.pose.orientation.w = 1.0
        o.pose.covariance[0] = o.pose.covariance[7] = m.position_covariance[0]
        self.pub.publish(o)
        self.offset = (o.pose.pose.position.x * 0.01, o.pose.pose.position.y * 0.01)

    def tick(self) -> None:
        gap = time.monotonic() - self.t_fix
        if gap > 2.0:
            self.log.warn(f"no GNSS fix for {gap:.1f} s; map->odom is dead-reckoned",
                          throttle_duration_sec=10.0)
        t = TransformStamped()
        t.header.stamp = self.stamp(-self.TRANSFORM_TOLERANCE)
        t.header.frame_id, t.child_frame_id = "map", "odom"
        t.transform.translation.x, t.transform.translation.y = self.offset
        t.transform.rotation.w = 1.0
        self.tf.publish(t)


# ------------------------------------------------------------------------------------- navigation
class RoutePlanner(LNode):
    """Sidewalk-graph route planner (lifecycle): service /dlv/plan_route (nav_msgs/GetPlan)."""

    def __init__(self) -> None:
        super().__init__("route_planner")
        self.srv_group = MutuallyExclusiveCallbackGroup()
        self.pub_group = MutuallyExclusiveCallbackGroup()
        self.route_pub = self.create_publisher(PathMsg, "route", LATCHED)
        self.progress = self.create_publisher(Float32, "route_progress", RELIABLE)
        self.create_service(GetPlan, "plan_route", self.on_plan, callback_group=self.srv_group)
        self.create_timer(0.5, self.tick, callback_group=self.pub_group)
        self.route_t = None

    def on_plan(self, req: GetPlan.Request, res: GetPlan.Response) -> GetPlan.Response:
        if not self.active:
            self.log.warn("plan request while inactive; returning an empty route")
            return res
        if self.fault == "hang":  # waits on the tile cache lock a crashed prefetch thread still holds
            SHUTDOWN.wait()
            return res
        # A* over the sidewalk graph
        t = time.monotonic()
        g = np.random.default_rng(int(time.time())).random((120, 120))
        for _ in range(4):
            g = np.minimum(g, np.roll(g, 1, axis=0) + 0.01)
        n = random.randint(14, 30)
        res.plan.header.frame_id = "map"
        res.plan.header.stamp = self.stamp(0.0)
        for i in range(n):
            p = PoseStamped()
            p.header.frame_id = "map"
            p.pose.position.x = req.start.pose.position.x + i * 4.0
            p.pose.position.y = req.start.pose.position.y + 0.5 * math.sin(i / 3.0)
            p.pose.orientation.w = 1.0
            res.plan.poses.append(p)
        self.route_pub.publish(res.plan)
        self.route_t = world()
        self.log.info(f"route planned: {n} waypoints, {n * 4.0:.0f} m "
                      f"({(time.monotonic() - t) * 1000:.0f} ms)")
        return res

    def tick(self) -> None:
        if not self.active:
            return
        w = world()
        m = Float32()
        if self.route_t is not None and self.route_t.t0 == w.t0:
            m.data = min(1.0, (w.t - w.t0) / max(1.0, w.t1 - w.t0))
        self.progress.publish(m)


class LocalCostmap(LNode):
    """Rolling-window local costmap (lifecycle): /dlv/local_costmap/costmap 2 Hz from /dlv/scan."""

    EXPECTED_UPDATE = 0.5  # s: the scan observation buffer's expected_update_rate

    def __init__(self, group) -> None:
        super().__init__("local_costmap")
        self.create_subscription(LaserScan, "scan", self.on_scan, SENSOR, callback_group=group)
        self.pub = self.create_publisher(OccupancyGrid, "local_costmap/costmap", RELIABLE)
        self.create_timer(0.5, self.tick, callback_group=group)
        self.last_scan = time.monotonic()
        self.scan = None
        self.failing = False

    def on_scan(self, m: LaserScan) -> None:
        now = time.monotonic()
        gap = now - self.last_scan
        self.last_scan, self.scan = now, m
        if self.active and gap > self.EXPECTED_UPDATE:
            self.log.warn(f"The /dlv/scan observation buffer has not been updated for {gap:.2f} seconds, "
                          f"and it should be updated every {self.EXPECTED_UPDATE:.2f} seconds.",
                          throttle_duration_sec=5.0)

    def tick(self) -> None:
        if not self.active:
            return
        if self.fault == "deactivate" and not self.failing:
            self.failing = True
            self.log.error("Sensor origin at (412.31, -87.12) is out of map bounds (0.00, 0.00) to "
                           "(8.00, 8.00); the costmap cannot raytrace for it")
            self.log.error("local_costmap: rolling window lost the robot pose; deactivating")
            self.trigger_deactivate()
            return
        gap = time.monotonic() - self.last_scan
        if gap > 1.0:
            self.log.warn(f"no /dlv/scan for {gap:.1f} s; costmap not updated", throttle_duration_sec=5.0)
            return
        g = OccupancyGrid()
        g.header.stamp = self.stamp(0.0)
        g.header.frame_id = "odom"
        g.info.resolution = 0.2
        g.info.width = g.info.height = 40
        g.info.origin.position.x = g.info.origin.position.y = -4.0
        g.info.origin.orientation.w = 1.0
        cells = array.array("b", bytes(1600))
        if self.scan is not None:
            for i in range(0, 360, 4):
                r = self.scan.ranges[i]
                if r < 3.9:
                    a = math.radians(i - 180)
                    cx, cy = int((r * math.cos(a) + 4) / 0.2), int((r * math.sin(a) + 4) / 0.2)
                    if 0 <= cx < 40 and 0 <= cy < 40:
                        cells[cy * 40 + cx] = 100
        g.data = cells
        self.pub.publish(g)


class PathFollower(LNode):
    """Route follower / local controller (lifecycle): action /dlv/follow_route, /dlv/autonomy/cmd_vel."""

    MAX_COSTMAP_AGE = 1.5

    def __init__(self, group) -> None:
        super().__init__("path_follower")
        self.create_subscription(OccupancyGrid, "local_costmap/costmap", self.on_costmap, RELIABLE,
                                 callback_group=group)
        self.create_subscription(PoseArray, "obstacles", self.on_obstacles, RELIABLE, callback_group=group)
        self.create_subscription(Odometry, "odometry/filtered", lambda m: None, RELIABLE,
                                 callback_group=group)
        self.cmd = self.create_publisher(Twist, "autonomy/cmd_vel", RELIABLE)
        self.costmap_t = time.monotonic()
        self.obstacle_t = 0.0
        self.goal_phase: tuple | None = None
        self.server = ActionServer(self, Fibonacci, "follow_route", execute_callback=self.execute,
                                   goal_callback=self.on_goal,
                                   cancel_callback=lambda g: CancelResponse.ACCEPT,
                                   callback_group=ReentrantCallbackGroup())

    def on_costmap(self, m: OccupancyGrid) -> None:
        self.costmap_t = time.monotonic()

    def on_obstacles(self, m: PoseArray) -> None:
        self.obstacle_t = time.monotonic()

    def on_goal(self, goal) -> GoalResponse:
        if not self.active:
            self.log.warn("follow_route goal rejected: controller is not active")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def execute(self, handle):
        w = world()
        key = (w.t0, w.phase)
        self.goal_phase = key
        self.log.info(f"following route: {handle.request.order} waypoints ({w.phase})")
        fb = Fibonacci.Feedback()
        done = 0
        result = Fibonacci.Result()
        try:
            while not SHUTDOWN.wait(0.1):
                w = world()
                if handle.is_cancel_requested:
                    handle.canceled()
                    self.log.info("route canceled")
                    return result
                if not self.active:
                    self.log.error("controller deactivated while following the route; aborting")
                    handle.abort()
                    return result
                age = time.monotonic() - self.costmap_t
                if age > self.MAX_COSTMAP_AGE:
                    self.log.error(f"local costmap is {age:.1f} s old (limit {self.MAX_COSTMAP_AGE} s); "
                                   "aborting route")
                    handle.abort()
                    return result
                if (w.t0, w.phase) != key:
                    result.sequence = list(range(handle.request.order))
                    handle.succeed()
                    self.log.info("route segment complete")
                    return result
                self.command()
                passed = int((w.t - w.t0) / max(1.0, w.t1 - w.t0) * handle.request.order)
                if passed != done:
                    done = passed
                    fb.sequence = list(range(done))
                    handle.publish_feedback(fb)
            handle.abort()
            return result
        finally:
            self.goal_phase = None

    def command(self) -> None:
        """The controller's 10 Hz output while a route is followed."""
        m = Twist()
        slow = time.monotonic() - self.obstacle_t < 1.0
        m.linear.x = 0.5 if slow else 1.4
        m.angular.z = 0.05 * math.sin(time.time() / 3.0)
        self.cmd.publish(m)


# ------------------------------------------------------------------------------------- executive
class LifecycleManager(CNode):
    """nav2-style lifecycle manager: configures and activates the navigation nodes, polls their state."""

    MANAGED = ("route_planner", "local_costmap", "path_follower")

    def __init__(self) -> None:
        super().__init__("lifecycle_manager")
        self.change = {n: self.create_client(ChangeState, f"{NS}/{n}/change_state") for n in self.MANAGED}
        self.get = {n: self.create_client(GetState, f"{NS}/{n}/get_state") for n in self.MANAGED}
        self.create_service(Trigger, "lifecycle_manager/is_active", self.on_is_active)
        self.step = 0  # index into the startup sequence (node, transition)
        self.seq = [(n, tr) for tr in (Transition.TRANSITION_CONFIGURE, Transition.TRANSITION_ACTIVATE)
                    for n in self.MANAGED]
        self.pending = None
        self.states: dict[str, str] = {}
        self.all_active = False
        self.startup_timer = self.create_timer(0.5, self.startup)
        self.create_timer(2.0, self.poll)
        self.log.info("Starting managed nodes bringup...")

    def on_is_active(self, req, res):
        res.success = self.all_active
        res.message = json.dumps(self.states)
        return res

    def startup(self) -> None:
        if self.step >= len(self.seq):
            return
        if self.pending is not None:
            if not self.pending.done():
                return
            r = self.pending.result()
            n, tr = self.seq[self.step]
            self.pending = None
            if r is None or not r.success:
                self.log.error(f"Failed to change state for node: {n}")
                return
            self.step += 1
            if self.step == len(self.seq):
                self.log.info("Managed nodes are active")
                self.startup_timer.cancel()
            return
        n, tr = self.seq[self.step]
        if not self.change[n].service_is_ready():
            self.log.info(f"Waiting for service {NS}/{n}/change_state...", throttle_duration_sec=5.0)
            return
        self.log.info(f"{'Configuring' if tr == Transition.TRANSITION_CONFIGURE else 'Activating'} {n}")
        self.pending = self.change[n].call_async(ChangeState.Request(transition=Transition(id=tr)))

    def poll(self) -> None:
        if self.step < len(self.seq):
            return
        for n in self.MANAGED:
            if self.get[n].service_is_ready():
                self.get[n].call_async(GetState.Request()).add_done_callback(
                    functools.partial(self._got, n))
        bad = [n for n, s in self.states.items() if s != "active"]
        self.all_active = not bad and len(self.states) == len(self.MANAGED)
        for n in bad:
            self.log.error(f"Managed node {NS}/{n} is '{self.states[n]}' (expected active): "
                           "navigation is not available", throttle_duration_sec=10.0)

    def _got(self, n: str, fut) -> None:
        r = fut.result()
        if r is not None:
            self.states[n] = r.current_state.label


class MissionExecutive(CNode):
    """Behaviour tree of a delivery: takes orders from the fleet bridge, plans, drives, crosses,
    asks for remote help when stuck, unlocks the cargo bay at the drop-off."""

    PLAN_TIMEOUT = 5.0
    STOP_LIMIT = 10.0

    def __init__(self) -> None:
        super().__init__("mission_executive")
        self.state_pub = self.create_publisher(String, "mission/state", LATCHED)
        self.assist_pub = self.create_publisher(Bool, "mission/assistance", LATCHED)
        self.create_subscription(String, "fleet/order", self.on_order, LATCHED)
        self.create_subscription(Header, "fleet/heartbeat", self.on_heartbeat, RELIABLE)
        self.create_subscription(String, "traffic_light", self.on_light, RELIABLE)
        self.create_subscription(PolygonStamped, "crosswalk", self.on_crosswalk, RELIABLE)
        self.create_subscription(Bool, "safety/stop", self.on_stop, LATCHED)
        self.create_subscription(String, "velocity_mux/active", self.on_mux, LATCHED)
        self.planner = self.create_client(GetPlan, "plan_route")
        self.unlock = self.create_client(Trigger, "cargo_bay/unlock")
        self.follow = ActionClient(self, Fibonacci, "follow_route")
        self.order: dict | None = None
        self.heartbeat_t = self.crosswalk_t = time.monotonic() + 10.0  # start-up grace
        self.light: dict | None = None
        self.light_t = 0.0
        self.stop = False
        self.stop_since = 0.0
        self.seg = None
        self.state = ""
        self.plan_fut = None
        self.plan_deadline = 0.0
        self.goal_handle = None
        self.crossing = False
        self.failed = False
        self.started = time.monotonic()
        self.mux_source = "idle"
        self.create_timer(0.1, self.tick)
        self.set_state("idle")

    # --- inputs
    def on_order(self, m: String) -> None:
        o = json.loads(m.data)
        if self.order is None or o["id"] != self.order["id"]:
            self.order = o
            self.log.info(f"delivery order {o['id']} accepted: drop-off '{o['dropoff']['name']}'")

    def on_heartbeat(self, m: Header) -> None:
        self.heartbeat_t = time.monotonic()

    def on_light(self, m: String) -> None:
        self.light, self.light_t = json.loads(m.data), time.monotonic()

    def on_crosswalk(self, m: PolygonStamped) -> None:
        self.crosswalk_t = time.monotonic()

    def on_stop(self, m: Bool) -> None:
        if m.data and not self.stop:
            self.stop_since = time.monotonic()
        self.stop = m.data

    def on_mux(self, m: String) -> None:
        if m.data == "teleop" and self.mux_source != "teleop":
            self.log.info("remote supervisor has control")
        self.mux_source = m.data

    def set_state(self, s: str) -> None:
        if s == self.state:
            return
        self.state = s
        out = String()
        oid = self.order["id"] if self.order else None
        out.data = json.dumps({"state": s, "order": oid, "leg": self.seg[2] if self.seg else 0,
                               "t": round(time.time(), 2)})
        self.state_pub.publish(out)

    # --- the tree
    def tick(self) -> None:
        now = time.monotonic()
        w = world()
        hb = now - self.heartbeat_t
        if hb > 5.0:
            self.log.warn(f"fleet bridge heartbeat lost for {hb:.0f} s: no new orders can arrive",
                          throttle_duration_sec=15.0)
        cw = now - self.crosswalk_t
        if cw > 2.0:
            self.log.warn(f"no crosswalk detections for {cw:.1f} s: crossings are blind",
                          throttle_duration_sec=15.0)
        key = (w.t0, w.phase, w.leg)
        if key != self.seg:
            prev = self.seg
            self.seg = key
            self.enter(w, prev)
        self.during(w, now)

    def _has_order(self, w: World) -> bool:
        return self.order is not None and self.order.get("epoch") == w.plan.epoch

    def enter(self, w: World, prev) -> None:
        if prev is not None and prev[1] == "stuck":
            self.assist_pub.publish(Bool(data=False))
            self.log.info(f"remote assistance finished after {prev and (w.t - prev[0]):.0f} s; resuming")
        self.crossing = False
        self.failed = False
        self.plan_fut = None
        if time.monotonic() - self.started < 8.0 and w.phase != "idle":
            self.set_state("starting")
            return
        if w.phase == "idle":
            self.set_state("idle")
            self.log.info("at hub, waiting for the next delivery order")
            return
        if not self._has_order(w):
            self.log.warn(f"no delivery order for round {w.plan.epoch}; staying at the hub",
                          throttle_duration_sec=30.0)
            self.set_state("idle")
            return
        if w.phase == "driving":
            if not self.planner.service_is_ready():
                self.log.error("route planner service not available; leg failed")
                self.fail(w)
                return
            req = GetPlan.Request()
            req.start.header.frame_id = req.goal.header.frame_id = "map"
            req.goal.pose.position.x = float(self.order["dropoff"]["x"])
            req.tolerance = 1.0
            self.plan_fut = self.planner.call_async(req)
            self.plan_deadline = time.monotonic() + self.PLAN_TIMEOUT
            self.set_state("planning")
        elif w.phase == "crossing":
            self.set_state("at_crossing")
            self.log.info("at crosswalk, waiting for the pedestrian signal")
        elif w.phase == "stuck":
            self.set_state("awaiting_teleop")
            self.log.warn(f"no progress for {random.uniform(5, 8):.1f} s (wheels slipping on the curb); "
                          "requesting remote assistance")
            self.assist_pub.publish(Bool(data=True))
        elif w.phase == "delivering":
            self.set_state("delivering")
            self.log.info(f"arrived at drop-off for {self.order['id']}; unlocking cargo bay")
            if self.unlock.service_is_ready():
                self.unlock.call_async(Trigger.Request()).add_done_callback(self._unlocked)
            else:
                self.log.error("cargo bay service not available")

    def _unlocked(self, fut) -> None:
        r = fut.result()
        if r is not None and r.success:
            self.log.info(f"cargo bay unlocked: {r.message}")
        else:
            self.log.error("cargo bay unlock failed")

    def fail(self, w: World) -> None:
        self.failed = True
        self.set_state("failed")
        oid = self.order["id"] if self.order else "?"
        self.log.error(f"delivery {oid}: leg {w.leg} failed")

    def send_goal(self, n: int) -> None:
        if not self.follow.server_is_ready():
            self.log.error("follow_route action server not available")
            self.fail(world())
            return
        fut = self.follow.send_goal_async(Fibonacci.Goal(order=n))
        fut.add_done_callback(self._goal_response)

    def _goal_response(self, fut) -> None:
        h = fut.result()
        if not h.accepted:
            self.log.error("follow_route goal rejected")
            self.fail(world())
            return
        self.goal_handle = h
        h.get_result_async().add_done_callback(self._result)

    def _result(self, fut) -> None:
        r = fut.result()
        self.goal_handle = None
        if r.status == GoalStatus.STATUS_ABORTED:
            self.log.error("follow_route aborted")
            self.fail(world())

    def during(self, w: World, now: float) -> None:
        if self.failed:
            return
        if self.plan_fut is not None:
            if self.plan_fut.done():
                res = self.plan_fut.result()
                self.plan_fut = None
                if res is None or not res.plan.poses:
                    self.log.error("route planner returned no route")
                    self.fail(w)
                    return
                self.set_state("driving")
                self.send_goal(len(res.plan.poses))
            elif now > self.plan_deadline:
                self.plan_fut = None
                self.log.error(f"plan_route did not answer within {self.PLAN_TIMEOUT:.1f} s")
                self.fail(w)
            return
        if self.state in ("driving", "crossing") and self.stop and now - self.stop_since > self.STOP_LIMIT:
            self.log.error(f"safety stop held for {now - self.stop_since:.0f} s; aborting the leg")
            if self.goal_handle is not None:
                self.goal_handle.cancel_goal_async()
            self.fail(w)
            return
        if self.state == "at_crossing":
            fresh = self.light is not None and now - self.light_t < 1.0
            if fresh:
                lag = time.time() - self.light["stamp"]
                if lag > 0.5:
                    self.log.warn(f"traffic light detection is {lag:.2f} s late", throttle_duration_sec=10.0)
                if self.light["state"] == "green" and not self.crossing:
                    self.crossing = True
                    self.log.info("signal is WALK; crossing")
                    self.set_state("crossing")
                    self.send_goal(3)
            elif w.t - w.t0 > 3.0:
                self.log.warn("no traffic light detection at the crosswalk; holding",
                              throttle_duration_sec=5.0)
        if self.state == "delivering" and w.t1 - w.t < 0.2:
            self.log.info(f"parcel for {self.order['id']} collected; cargo bay locked, returning")
            self.set_state("returning")


# ---------------------------------------------------------------------------------------- safety
class SafetyMonitor(CNode):
    """Protective stop: lidar too close or lidar silent -> /dlv/safety/stop (latched)."""

    STOP_RANGE = 0.6
    SCAN_TIMEOUT = 1.0

    def __init__(self) -> None:
        super().__init__("safety_monitor")
        qos = SENSOR
        if self.fault == "qos":  # the redeployed parameter file sets the scan subscription to reliable
            qos = QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(LaserScan, "scan", self.on_scan, qos)
        self.pub = self.create_publisher(Bool, "safety/stop", LATCHED)
        self.scan_t = time.monotonic() + 2.0  # start-up grace
        self.near = 99.0
        self.clear_t = 0.0
        self.stopped = None
        self.reason = ""
        self.create_timer(0.25, self.tick)  # the lidar watchdog

    def on_scan(self, m: LaserScan) -> None:
        self.scan_t = time.monotonic()
        self.near = min(m.ranges[165:196])
        self.tick()

    def tick(self) -> None:
        now = time.monotonic()
        silent = now - self.scan_t
        stop = self.stopped or False
        if silent > self.SCAN_TIMEOUT:
            if not stop or self.reason != "scan":
                self.log.error(f"no /dlv/scan for {silent:.1f} s: protective stop asserted")
            elif silent > self.SCAN_TIMEOUT + 5.0:
                self.log.error(f"protective stop held: no /dlv/scan for {silent:.0f} s",
                               throttle_duration_sec=10.0)
            stop, self.reason = True, "scan"
        elif self.near < self.STOP_RANGE:
            if not stop:
                self.log.info(f"protective stop: obstacle at {self.near:.2f} m")
            stop, self.reason, self.clear_t = True, "near", now
        elif stop and now - self.clear_t > 1.0:
            self.log.info("protective stop released")
            stop = False
        if stop != self.stopped:
            self.stopped = stop
            self.pub.publish(Bool(data=stop))


class VelocityMux(CNode):
    """twist_mux: teleop (priority 100) over autonomy (10), zero on safety stop; /dlv/cmd_vel 10 Hz."""

    TIMEOUT = 0.5

    def __init__(self) -> None:
        super().__init__("velocity_mux")
        self.declare_parameter("max_linear_speed", 1.6)
        self.declare_parameter("max_angular_speed", 1.0)
        self.add_on_set_parameters_callback(self.on_params)
        self.create_subscription(Twist, "autonomy/cmd_vel", lambda m: self._in("autonomy", m), RELIABLE)
        self.create_subscription(Twist, "teleop/cmd_vel", lambda m: self._in("teleop", m), RELIABLE)
        self.create_subscription(Bool, "safety/stop", self.on_stop, LATCHED)
        self.pub = self.create_publisher(TwistStamped, "cmd_vel", RELIABLE)
        self.active_pub = self.create_publisher(String, "velocity_mux/active", LATCHED)
        self.inputs: dict[str, tuple[float, Twist]] = {}
        self.stop = False
        self.source = None
        self.create_timer(0.1, self.tick)

    def on_params(self, params) -> SetParametersResult:
        for p in params:
            self.log.info(f"parameter {p.name} set to {p.value}")
        return SetParametersResult(successful=True)

    def _in(self, name: str, m: Twist) -> None:
        self.inputs[name] = (time.monotonic(), m)

    def on_stop(self, m: Bool) -> None:
        if m.data and not self.stop:
            self.log.warn("safety stop active: commanding zero velocity")
        self.stop = m.data

    def tick(self) -> None:
        now = time.monotonic()
        src = None
        for name in ("teleop", "autonomy"):
            if name in self.inputs and now - self.inputs[name][0] < self.TIMEOUT:
                src = name
                break
        label = "safety_stop" if self.stop and src else (src or "idle")
        if label != self.source:
            self.source = label
            self.log.info(f"active input: {label}")
            self.active_pub.publish(String(data=label))
        out = TwistStamped()
        out.header.stamp = self.stamp(0.0)
        out.header.frame_id = "base_link"
        if src and not self.stop:
            vmax = self.get_parameter("max_linear_speed").value
            wmax = self.get_parameter("max_angular_speed").value
            tw = self.inputs[src][1]
            out.twist.linear.x = max(-vmax, min(vmax, tw.linear.x))
            out.twist.angular.z = max(-wmax, min(wmax, tw.angular.z))
        self.pub.publish(out)


# ----------------------------------------------------------------------------------------- motion
WHEELS = [f"wheel_{s}_{p}" for p in ("front", "mid", "rear") for s in ("left", "right")]


class MotorController(CNode):
    """Six hub motors on CAN: consumes /dlv/cmd_vel, publishes /dlv/motor/joint_states 20 Hz."""

    def __init__(self) -> None:
        super().__init__("motor_controller")
        self.create_subscription(TwistStamped, "cmd_vel", self.on_cmd, RELIABLE)
        self.pub = self.create_publisher(JointState, "motor/joint_states", SENSOR)
        self.cmd_t = time.monotonic() + 3.0  # start-up grace
        self.v = 0.0
        self.pos = [0.0] * 6
        self.errored = False
        self.create_timer(1 / 20, self.tick)
        Diag(self, "vesc-can0", {"drive": self.status})

    def status(self):
        if self.errored:
            return ERROR, "encoder bus error", {"can_error": "0x31", "wheel": "wheel_left_rear"}
        return OK, "OK", {"speed": round(self.v, 2)}

    def on_cmd(self, m: TwistStamped) -> None:
        self.cmd_t = time.monotonic()
        self.v += 0.3 * (m.twist.linear.x - self.v)

    def tick(self) -> None:
        gap = time.monotonic() - self.cmd_t
        if gap > 0.5:
            self.log.warn(f"command timeout ({gap:.1f} s): braking", throttle_duration_sec=5.0)
            self.v = 0.0
        if self.fault == "error":
            if not self.errored:
                self.errored = True
                self.log.error("CAN: encoder frames from wheel_left_rear missing (error 0x31); "
                               "wheel state output halted")
            return
        w = self.v / 0.165
        self.pos = [p + w / 20 for p in self.pos]
        m = JointState()
        m.header.stamp = self.stamp(0.002)
        m.name = WHEELS
        m.position = self.pos
        m.velocity = [w + random.gauss(0, 0.01) for _ in range(6)]
        m.effort = [abs(w) * 0.4] * 6
        self.pub.publish(m)


class CargoBay(CNode):
    """Cargo bay lock: service /dlv/cargo_bay/unlock (std_srvs/Trigger), /dlv/cargo_bay/state latched."""

    def __init__(self) -> None:
        super().__init__("cargo_bay")
        self.create_service(Trigger, "cargo_bay/unlock", self.on_unlock)
        self.pub = self.create_publisher(String, "cargo_bay/state", LATCHED)
        self.locked_at = 0.0
        self.unlocked = False
        self.pub.publish(String(data="locked"))
        self.create_timer(1.0, self.tick)
        Diag(self, "lock-ctrl-7", {"lock": lambda: (OK, "unlocked" if self.unlocked else "locked", {})})

    def on_unlock(self, req, res):
        self.unlocked = True
        self.locked_at = time.monotonic() + 7.0
        self.pub.publish(String(data="unlocked"))
        self.log.info("cargo bay unlocked by mission executive")
        res.success, res.message = True, "lid open, relock in 7 s"
        return res

    def tick(self) -> None:
        if self.unlocked and time.monotonic() > self.locked_at:
            self.unlocked = False
            self.pub.publish(String(data="locked"))
            self.log.info("lid closed; cargo bay locked")


# ------------------------------------------------------------------------------------------ comms
class CellularModem(CNode):
    """LTE modem manager: /dlv/modem/link_quality 1 Hz (0..1)."""

    def __init__(self) -> None:
        super().__init__("cellular_modem")
        self.pub = self.create_publisher(Float32, "modem/link_quality", RELIABLE)
        self.weak = False
        self.q = 0.8
        self.create_timer(1.0, self.tick)
        Diag(self, "quectel-rm520n", {"modem": lambda: (WARN if self.weak else OK,
                                                        "signal weak" if self.weak else "connected",
                                                        {"quality": round(self.q, 2)})})

    def tick(self) -> None:
        self.q = max(0.0, min(1.0, world().link + random.gauss(0, 0.03)))
        weak = self.q < 0.5
        if weak != self.weak:
            self.weak = weak
            if weak:
                self.log.warn(f"signal weak: RSRP {-100 - 30 * (0.5 - self.q):.0f} dBm, "
                              f"SINR {self.q * 10:.1f} dB (band 20)")
            else:
                self.log.info("signal recovered: RSRP -88 dBm")
        self.pub.publish(Float32(data=self.q))


class TeleopGateway(CNode):
    """The remote supervisor's joystick, relayed from the cloud: /dlv/teleop/cmd_vel while driving."""

    def __init__(self) -> None:
        super().__init__("teleop_gateway")
        self.pub = self.create_publisher(Twist, "teleop/cmd_vel", RELIABLE)
        self.create_subscription(String, "uplink/stats", self.on_stats, RELIABLE)
        self.create_subscription(Bool, "mission/assistance", self.on_assist, LATCHED)
        self.stats_t = time.monotonic()
        self.driving = False
        self.create_timer(0.1, self.tick)

    def on_stats(self, m: String) -> None:
        self.stats_t = time.monotonic()

    def on_assist(self, m: Bool) -> None:
        if m.data:
            self.log.info("assistance requested; paging supervisor")

    def tick(self) -> None:
        w = world()
        drive = w.phase == "stuck" and w.t - w.t0 > 2.0 and w.t1 - w.t > 0.5
        if drive != self.driving:
            self.driving = drive
            if drive:
                self.log.info(f"supervisor ops-{w.plan.epoch % 5 + 1} took control")
            else:
                self.log.info("supervisor released control")
        if not drive:
            return
        gap = time.monotonic() - self.stats_t
        if gap > 3.0:
            self.log.warn(f"no video uplink for {gap:.0f} s: supervisor is driving blind",
                          throttle_duration_sec=5.0)
        m = Twist()
        m.linear.x = 0.3 + 0.2 * math.sin(w.t)
        m.angular.z = 0.4 * math.sin(w.t / 2.0)
        self.pub.publish(m)


class FleetBridge(CNode):
    """Link to the fleet cloud: delivery orders (latched), heartbeat 1 Hz, mission state upstream."""

    def __init__(self) -> None:
        super().__init__("fleet_bridge")
        self.order_pub = self.create_publisher(String, "fleet/order", LATCHED)
        self.hb = self.create_publisher(Header, "fleet/heartbeat", RELIABLE)
        self.create_subscription(String, "mission/state", self.on_state, LATCHED)
        self.epoch = None
        self.create_timer(1.0, self.poll_cloud)

    def poll_cloud(self) -> None:
        h = Header()
        h.stamp = self.stamp(0.0)
        h.frame_id = "fleet-cloud"
        self.hb.publish(h)
        w = world()
        msg = {"id": w.plan.order, "epoch": w.plan.epoch,
               "dropoff": {"name": f"{100 + w.plan.epoch % 80} Market St", "x": 180.0}}
        if self.fault == "crash":  # a new cloud release sends orders without the drop-off block
            msg = {"id": w.plan.order + "-r", "epoch": w.plan.epoch, "pickup": {"name": "hub"}}
            self.epoch = None
        if w.plan.epoch != self.epoch:
            order = self._parse(msg)
            self.epoch = w.plan.epoch
            self.log.info(f"new delivery order {order['id']} -> {order['dropoff']['name']}")
            self.order_pub.publish(String(data=json.dumps(order)))

    @staticmethod
    def _parse(msg: dict) -> dict:
        return {"id": msg["id"], "epoch": msg["epoch"],
                "dropoff": {"name": msg["dropoff"]["name"], "x": float(msg["dropoff"]["x"])}}

    def on_state(self, m: String) -> None:
        s = json.loads(m.data)
        if s["state"] == "returning":
            self.log.info(f"order {s['order']} reported delivered")
        elif s["state"] == "failed":
            self.log.warn(f"order {s['order']}: robot reports a failed leg")


class DataRecorder(CNode):
    """rosbag2-like recorder: raw subscriptions, splits its bag every 60 s."""

    TOPICS: ClassVar[list] = [("cmd_vel", TwistStamped, RELIABLE), ("odometry/filtered", Odometry, RELIABLE),
              ("gnss/fix", NavSatFix, SENSOR), ("mission/state", String, LATCHED),
              ("/diagnostics_agg", DiagnosticArray, RELIABLE), ("safety/stop", Bool, LATCHED),
              ("battery", BatteryState, RELIABLE), ("/tf_static", TransformStamped, TF_STATIC),
              ("velocity_mux/active", String, LATCHED)]

    def __init__(self) -> None:
        super().__init__("data_recorder")
        self.count = self.bytes = 0
        self.split = 0
        for topic, typ, qos in self.TOPICS:
            self.create_subscription(typ, topic, self.on_msg, qos, raw=True)
        self.create_timer(60.0, self.roll)
        self.log.info(f"recording {len(self.TOPICS)} topics to "
                      f"/data/bags/courier_{time.strftime('%Y%m%d_%H%M')}")

    def on_msg(self, data: bytes) -> None:
        self.count += 1
        self.bytes += len(data)

    def roll(self) -> None:
        self.log.info(f"split bag: courier_{self.split}.mcap closed ({self.count} msgs, "
                      f"{self.bytes / 1e6:.1f} MB)")
        self.split += 1
        self.count = self.bytes = 0


# ----------------------------------------------------------------------------------------- infra
class RobotStatePublisher(CNode):
    """Static frames of the chassis: /tf_static (latched), /robot_description."""

    FRAMES: ClassVar[dict] = {"lidar_link": (0.25, 0.0, 0.62), "front_camera_link": (0.38, 0.0, 0.55),
              "gnss_link": (-0.1, 0.0, 0.7), "imu_link": (0.0, 0.0, 0.2), "cargo_bay_link": (-0.05, 0.0, 0.4)}

    def __init__(self) -> None:
        super().__init__("robot_state_publisher", namespace="/")
        self.pub = self.create_publisher(TransformStamped, "/tf_static", TF_STATIC)
        self.desc = self.create_publisher(String, "/robot_description", LATCHED)
        now = self.stamp(0.0)
        for child, (x, y, z) in self.FRAMES.items():
            t = TransformStamped()
            t.header.stamp = now
            t.header.frame_id, t.child_frame_id = "base_link", child
            t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = x, y, z
            t.transform.rotation.w = 1.0
            self.pub.publish(t)
        self.desc.publish(String(data="<robot name='courier'>" + "".join(
            f"<link name='{f}'/>" for f in ("base_link", *self.FRAMES)) + "</robot>"))


class DiagnosticAggregator(CNode):
    """diagnostic_aggregator: /diagnostics -> /diagnostics_agg 1 Hz with analyzer paths, stale after 5 s."""

    PATHS: ClassVar[dict] = {
        "gnss_driver": "/Sensors/GNSS", "imu_driver": "/Sensors/IMU", "lidar_driver": "/Sensors/Lidar",
             "front_camera": "/Sensors/Cameras", "battery_monitor": "/Power/Battery",
             "motor_controller": "/Drive/Motors", "cargo_bay": "/Payload/CargoBay",
             "cellular_modem": "/Comms/Modem", "video_uplink": "/Comms/Uplink"}
    STALE_S = 5.0

    def __init__(self) -> None:
        super().__init__("diagnostic_aggregator", namespace="/")
        self.create_subscription(DiagnosticArray, "/diagnostics", self.on_diag, RELIABLE)
        self.pub = self.create_publisher(DiagnosticArray, "/diagnostics_agg", RELIABLE)
        self.seen: dict[str, tuple[float, DiagnosticStatus]] = {}
        self.create_timer(1.0, self.tick)

    def on_diag(self, m: DiagnosticArray) -> None:
        now = time.monotonic()
        for s in m.status:
            self.seen[s.name] = (now, s)

    def tick(self) -> None:
        now = time.monotonic()
        out = DiagnosticArray()
        out.header.stamp = self.stamp(0.0)
        groups: dict[str, int] = {}
        for name, (t, s) in sorted(self.seen.items()):
            node = name.split(":", 1)[0]
            path = self.PATHS.get(node, "/Other")
            level = s.level[0] if isinstance(s.level, bytes) else int(s.level)
            msg = s.message
            if now - t > self.STALE_S:
                level, msg = STALE, "Stale"
            out.status.append(DiagnosticStatus(level=bytes([level]), name=f"{path}/{name}", message=msg,
                                               hardware_id=s.hardware_id, values=s.values))
            for g in ("/" + path.split("/")[1], path):
                groups[g] = max(groups.get(g, 0), level)
        for g, level in sorted(groups.items()):
            out.status.append(DiagnosticStatus(level=bytes([level]), name=g,
                                               message=["OK", "Warning", "Error", "Stale"][level]))
        self.pub.publish(out)


# --------------------------------------------------------------------------------------- operator
class RemoteConsole(CNode):
    """The remote-ops console: watches the camera and the mission, sets the urban speed limit."""

    def __init__(self, run_for: float) -> None:
        super().__init__("remote_console")
        self.create_subscription(CompressedImage, "front_camera/image_raw/compressed", self.on_frame, SENSOR)
        self.create_subscription(String, "mission/state", self.on_state, LATCHED)
        self.create_subscription(DiagnosticArray, "/diagnostics_agg", self.on_diag, RELIABLE)
        self.create_subscription(String, "uplink/stats", lambda m: None, RELIABLE)
        self.params = self.create_client(SetParameters, "velocity_mux/set_parameters")
        self.frames = 0
        self.frame_t = time.monotonic()
        self.t0 = time.monotonic()
        self.run_for = run_for
        self.step = 0
        self.create_timer(1.0, self.tick)
        self.log.info("operator console connected")

    def on_frame(self, m: CompressedImage) -> None:
        self.frames += 1
        self.frame_t = time.monotonic()

    def on_state(self, m: String) -> None:
        self.log.info(f"mission: {json.loads(m.data)['state']}")

    def on_diag(self, m: DiagnosticArray) -> None:
        pass

    def _set_speed(self, v: float) -> bool:
        if not self.params.service_is_ready():
            self.log.info("waiting for /dlv/velocity_mux parameters...", throttle_duration_sec=5.0)
            return False
        req = SetParameters.Request(parameters=[Parameter("max_linear_speed", value=v).to_parameter_msg()])
        self.params.call_async(req)
        self.log.info(f"max_linear_speed -> {v} m/s")
        return True

    def tick(self) -> None:
        up = time.monotonic() - self.t0
        if self.step == 0 and up > 4.0 and self._set_speed(1.2):  # urban zone: the operator lowers it
            self.step = 1
        if self.step == 1 and self.run_for > 0 and up > self.run_for - 6.0 and self._set_speed(1.6):
            self.step = 2
        if up > 5.0 and time.monotonic() - self.frame_t > 3.0:
            self.log.warn("camera stream stalled", throttle_duration_sec=10.0)
        if int(up) % 15 == 0:
            self.log.info(f"camera: {self.frames / 15:.1f} fps")
            self.frames = 0


# -------------------------------------------------------------------------------------- processes
def _mt(n: int):
    return lambda: MultiThreadedExecutor(num_threads=n)


def _single():
    return SingleThreadedExecutor()


def _camera():
    g1, g2 = MutuallyExclusiveCallbackGroup(), MutuallyExclusiveCallbackGroup()
    return [FrontCamera(g1), ImageCompressor(g2)]


def _perception():
    g1, g2 = MutuallyExclusiveCallbackGroup(), MutuallyExclusiveCallbackGroup()
    return [ObstacleTracker(g1), CrosswalkDetector(g2)]


def _navigation():
    return [RoutePlanner(), LocalCostmap(MutuallyExclusiveCallbackGroup()),
            PathFollower(MutuallyExclusiveCallbackGroup())]


def _traffic_light():
    # the TensorRT engine deserializes for several seconds before the node exists
    print("[traffic_light] loading model traffic_light_yolov8n.engine ...", flush=True)
    if SHUTDOWN.wait(random.uniform(7.0, 9.0)):
        return []
    print("[traffic_light] model loaded", flush=True)
    return [TrafficLightDetector()]


# process -> (executor factory, node factory)
PROCESSES = {
    "sensor_container": (_single, lambda: [GnssDriver(), ImuDriver(), WheelOdometry(), BatteryMonitor()]),
    "lidar": (_single, lambda: [LidarDriver()]),
    "camera_container": (_single, _camera),
    "uplink": (_single, lambda: [VideoUplink()]),
    "perception": (_single, _perception),
    "traffic_light": (_single, _traffic_light),
    "localization": (_single, lambda: [EkfFilter(), NavsatTransform()]),
    "navigation": (_mt(3), _navigation),
    "executive": (_single, lambda: [MissionExecutive(), LifecycleManager()]),
    "safety": (_single, lambda: [VelocityMux(), SafetyMonitor()]),
    "motion": (_single, lambda: [MotorController(), CargoBay()]),
    "comms": (_single, lambda: [CellularModem(), TeleopGateway()]),
    "cloud_bridge": (_single, lambda: [FleetBridge()]),
    "infra": (_single, lambda: [RobotStatePublisher(), DiagnosticAggregator()]),
    "recorder": (_single, lambda: [DataRecorder()]),
    "console": (_single, None),  # built with RUN_FOR
}


def main(argv: list[str]) -> int:
    if len(argv) < 2 or argv[0] not in PROCESSES:
        print(f"usage: python -m bench.courier.robot {{{','.join(PROCESSES)}}} FAULT_DIR [RUN_FOR]")
        return 2
    process, fault_dir = argv[0], argv[1]
    run_for = float(argv[2]) if len(argv) > 2 else 0.0

    def on_signal(signum, frame) -> None:
        SHUTDOWN.set()

    signal.signal(signal.SIGINT, on_signal)
    signal.signal(signal.SIGTERM, on_signal)
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    BOARD.setup(fault_dir, process)
    make_exec, make_nodes = PROCESSES[process]
    nodes = [RemoteConsole(run_for)] if process == "console" else make_nodes()
    executor = make_exec()
    for n in nodes:
        executor.add_node(n)
    crashed: list[BaseException] = []

    def spin() -> None:
        try:
            executor.spin()
        except ExternalShutdownException:
            pass
        except BaseException as e:  # an uncaught exception in a callback ends the process
            crashed.append(e)
            SHUTDOWN.set()

    th = threading.Thread(target=spin, name="spin", daemon=True)
    if nodes:
        th.start()
    deadline = time.monotonic() + run_for if run_for > 0 else None
    while not SHUTDOWN.wait(0.5):
        if deadline is not None and time.monotonic() > deadline:
            break
    SHUTDOWN.set()
    if crashed:
        traceback.print_exception(crashed[0])
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(1)
    time.sleep(0.3)  # let running loops (an action's execute) finish while the executor still spins
    executor.shutdown(timeout_sec=3.0)
    th.join(3.0)
    for n in nodes:
        n.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
