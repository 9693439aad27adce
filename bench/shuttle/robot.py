"""An Autoware-style shuttle, plain rclpy: ``python -m bench.shuttle.robot PROCESS FAULT_DIR [RUN_FOR]``.

Written the way an Autoware-based shuttle stack is laid out (see `bench.shuttle.run` for the whole
robot, its healthy dynamics and its faults): ``/sensing`` drivers (lidar, camera, IMU, GNSS) and a
pointcloud preprocessor container (crop box, ground filter, voxel downsample on one
single-threaded executor: every process runs one rclpy C++ EventsExecutor); ``/localization``
(NDT scan matcher, EKF, pose initializer);
``/perception`` (camera detector, euclidean clustering, a multi-object tracker with an
approximate-time synchronizer, a traffic-light classifier activated only near intersections);
``/planning`` (mission planner with route services and a latched route, behavior path planner,
motion velocity smoother, planning validator); ``/control`` (trajectory follower, vehicle command
gate); ``/vehicle`` (the CAN bridge, simulating the vehicle); ``/system`` (topic state monitor,
component state monitor, emergency handler, diagnostics aggregator, system monitor); a rosbag
recorder; the AD API nodes (localization initialization, routing on a station timetable) and a
remote operator console that comes and goes.

No autoware_*_msgs in this environment: a trajectory or path is a nav_msgs/Path whose poses carry
the point's velocity (limit) in ``position.z``; control commands are geometry_msgs/TwistStamped
(``linear.x`` the target speed, ``angular.z`` the target yaw rate); the velocity report a
TwistWithCovarianceStamped; states (route, MRM, operation mode, gate mode, traffic signals) are
std_msgs/String; routes are nav_msgs/GetPlan calls; the pose initializer and the NDT alignment are
std_srvs/Trigger.

The world: a loop road (a 220 m x 100 m rounded rectangle, 620 m) with three stations (Depot at
0 m, Library at 230 m, Clinic at 420 m) and three signalised intersections (120, 360, 560 m).

Faults come from files: ``FAULT_DIR/<namespace>.<node>`` (``localization.pose_estimator.ndt_scan_matcher``)
holding a word the target node acts on (``hang``, ``degrade``, ``slow``, ``stale``, ``reliable``,
``errlog``), read by the process's watcher thread every 0.5 s; ``FAULT_DIR/<process>.cpu`` starts a
thread burning a core in that process, ``<process>.leak`` one leaking 2.5 MB/s. Crashes are SIGKILLs
from outside. RUN_FOR > 0 ends the process cleanly (exit 0) after that many seconds.
"""

from __future__ import annotations

import math
import random
import signal
import socket
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
from geometry_msgs.msg import (
    Pose,
    PoseArray,
    PoseStamped,
    PoseWithCovarianceStamped,
    TwistStamped,
    TwistWithCovarianceStamped,
)
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from nav_msgs.srv import GetPlan
from rcl_interfaces.msg import Log, SetParametersResult
from rcl_interfaces.srv import SetParameters
from rclpy.executors import ExternalShutdownException
from rclpy.experimental import EventsExecutor
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import (
    BatteryState,
    CameraInfo,
    Image,
    Imu,
    NavSatFix,
    NavSatStatus,
    PointCloud2,
    PointField,
)
from std_msgs.msg import Bool, Float32, String
from std_srvs.srv import Trigger

from stream_viz.demo.child import burn, leak

LEAK_MB_S = 2.5  # the tracker's history never trimmed

OK, WARN, ERROR, STALE = (
    DiagnosticStatus.OK,
    DiagnosticStatus.WARN,
    DiagnosticStatus.ERROR,
    DiagnosticStatus.STALE,
)
SENSOR = qos_profile_sensor_data  # best effort, keep last 5
RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
LATEST = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)
COMMAND = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)  # the gate -> CAN bridge command

# rates (Hz)
LIDAR_HZ, CAMERA_HZ, IMU_HZ, GNSS_HZ, VEHICLE_HZ = 10.0, 15.0, 50.0, 5.0, 50.0
EKF_HZ, BIASED_POSE_EVERY, FOLLOWER_HZ, GATE_HZ, PLANNER_HZ = 50.0, 5, 30.0, 30.0, 10.0

LANE_SPEED_LIMIT = 5.5  # m/s, the lanelets' speed limit
ARRIVAL_DISTANCE = 2.0


# --- the map (every planning node loads the same lanelet2 map) ----------------------------------------


def build_track(width: float = 220.0, height: float = 100.0, radius: float = 12.0):
    """The loop road as points ~1 m apart: x, y, yaw (counter-clockwise from the depot)."""
    xs, ys, yaws = [], [], []
    x, y, yaw = radius, 0.0, 0.0
    for straight in (width - 2 * radius, height - 2 * radius, width - 2 * radius, height - 2 * radius):
        for _ in range(round(straight)):
            xs.append(x)
            ys.append(y)
            yaws.append(yaw)
            x += math.cos(yaw)
            y += math.sin(yaw)
        n = round(math.pi / 2 * radius)
        dyaw, step = (math.pi / 2) / n, (math.pi / 2 * radius) / n
        for _ in range(n):
            xs.append(x)
            ys.append(y)
            yaws.append(yaw)
            mid = yaw + dyaw / 2
            x += step * math.cos(mid)
            y += step * math.sin(mid)
            yaw += dyaw
    return np.array(xs), np.array(ys), np.array(yaws)


TRACK_X, TRACK_Y, TRACK_YAW = build_track()
TRACK_N = len(TRACK_X)
STATIONS = {"Depot": 0, "Library": 230, "Clinic": 420}  # track index (m)
TIMETABLE = ("Library", "Clinic", "Depot")
TRAFFIC_LIGHTS = {1201: 120, 1202: 360, 1203: 560}  # light group id -> track index of the stop line + 4 m


def light_color(group: int, t: float) -> str:
    """What the signal head shows: a 45 s cycle (green 28 s, amber 3 s, red 14 s), offset per group."""
    phase = (t + group * 17.0) % 45.0
    return "GREEN" if phase < 28.0 else "AMBER" if phase < 31.0 else "RED"


def nearest_track_index(x: float, y: float) -> int:
    return int(np.argmin((TRACK_X - x) ** 2 + (TRACK_Y - y) ** 2))


# --- helpers ------------------------------------------------------------------------------------------


def to_stamp(t: float) -> Time:
    sec = int(t)
    return Time(sec=sec, nanosec=int((t - sec) * 1e9))


def secs(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


def yaw_of(q) -> float:
    return 2.0 * math.atan2(q.z, q.w)


def set_yaw(q, yaw: float) -> None:
    q.z, q.w = math.sin(yaw / 2), math.cos(yaw / 2)


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


def paced(hz: float):
    """A driver thread's loop: yields at ``hz`` (catching up no more than 0.5 s) while rclpy is up."""
    period = 1.0 / hz
    nxt = time.monotonic()
    while alive():
        nxt += period
        delay = nxt - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        elif delay < -0.5:
            nxt = time.monotonic()
        yield


def busy(seconds: float) -> float:
    """Python-level CPU work for ``seconds`` (a registration step, a graph search ...)."""
    t0 = time.perf_counter()
    acc = 0.0
    while time.perf_counter() - t0 < seconds:
        for i in range(300):
            acc += math.sqrt(i * 1.0001)
    return acc


POINT_FIELDS = [
    PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1)
    for i, n in enumerate(("x", "y", "z", "intensity"))
]


def cloud(header, pts: np.ndarray) -> PointCloud2:
    pts = np.ascontiguousarray(pts, dtype=np.float32)
    m = PointCloud2(
        height=1,
        width=len(pts),
        fields=POINT_FIELDS,
        is_bigendian=False,
        point_step=16,
        row_step=16 * len(pts),
        is_dense=True,
    )
    if header is not None:
        m.header = header
    m.data = pts.tobytes()
    return m


def points(msg: PointCloud2) -> np.ndarray:
    return np.frombuffer(msg.data, dtype=np.float32).reshape(-1, 4)


# --- fault hooks and the nodes' common parts ----------------------------------------------------------


def hook(node: Node, fault_dir: Path) -> None:
    """The bench's fault hooks: ``fault`` (the word in ``FAULT_DIR/<namespace>.<name>``, set by the
    watcher thread) and ``on_fault(word)``, run in the executor by `apply_faults` once it changed
    (the events executor has no guard conditions)."""
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


class ShuttleNode(Node):
    """A node of the shuttle: fault hooks and diagnostic_updater-style statuses on /diagnostics."""

    def __init__(self, name: str, namespace: str, fault_dir: Path, **kw) -> None:
        super().__init__(name, namespace=namespace, **kw)
        hook(self, fault_dir)
        self.rng = random.Random()
        self._diag_pub = None
        self._throttled: dict[str, float] = {}

    def on_fault(self, fault: str | None) -> None:
        pass

    def status(
        self, task: str, hardware_id: str, level: bytes = OK, message: str = "OK", **values
    ) -> DiagnosticStatus:
        kvs = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
        return DiagnosticStatus(
            level=level,
            name=f"{self.get_name()}: {task}",
            hardware_id=hardware_id,
            message=message,
            values=kvs,
        )

    def publish_diagnostics(self, *statuses: DiagnosticStatus) -> None:
        if self._diag_pub is None:
            self._diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", RELIABLE)
        arr = DiagnosticArray(status=list(statuses))
        arr.header.stamp = self.get_clock().now().to_msg()
        self._diag_pub.publish(arr)

    def throttle(self, key: str, period: float) -> bool:
        """True at most once per ``period`` s for ``key`` (RCLCPP_WARN_THROTTLE)."""
        now = time.monotonic()
        if now - self._throttled.get(key, -1e9) < period:
            return False
        self._throttled[key] = now
        return True


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


# --- sensing: drivers ---------------------------------------------------------------------------------


class LidarDriver(ShuttleNode):
    """The roof lidar (16 channels, 10 Hz): its packet thread assembles a scan and publishes it
    best effort; a scan with a lost UDP packet is dropped now and then (normal)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("lidar_driver", "sensing/lidar/top", fault_dir)
        self.declare_parameter("device_ip", "192.168.1.201")
        self.declare_parameter("rpm", 600)
        self.declare_parameter("frame_id", "velodyne_top")
        self.pub = self.create_publisher(PointCloud2, "/sensing/lidar/top/pointcloud_raw", SENSOR)
        rng = np.random.default_rng(7)
        self.scans = []
        elev = np.radians(np.linspace(-15.0, 15.0, 16))
        az = np.radians(np.arange(0.0, 360.0, 3.0))
        for _ in range(3):
            e, a = np.meshgrid(elev, az)
            e, a = e.ravel(), a.ravel()
            rng_m = np.where(e < -0.02, 1.8 / np.tan(-np.minimum(e, -0.02)), rng.uniform(4.0, 45.0, e.size))
            rng_m = np.minimum(rng_m, 60.0)
            xyz = np.stack(
                [
                    rng_m * np.cos(e) * np.cos(a),
                    rng_m * np.cos(e) * np.sin(a),
                    np.maximum(rng_m * np.sin(e), -1.8),
                ],
                axis=1,
            )
            inten = rng.uniform(5.0, 90.0, e.size)[:, None]
            self.scans.append(np.hstack([xyz, inten]).astype(np.float32))
        self.sent = self.dropped = 0
        self.get_logger().info("Connected to VLP-16 at 192.168.1.201: 600 rpm, 16 channels")
        self.create_timer(1.0, self.on_second)
        threading.Thread(target=self.packets, daemon=True, name="packets").start()

    def packets(self) -> None:
        k = 0
        rng = np.random.default_rng()
        for _ in paced(LIDAR_HZ):
            k += 1
            if random.random() < 0.006:  # a lost packet: the incomplete scan is discarded
                self.dropped += 1
                continue
            pts = self.scans[k % 3].copy()
            pts[:, :3] += rng.standard_normal((len(pts), 3)).astype(np.float32) * 0.02
            m = cloud(None, pts)
            m.header.stamp, m.header.frame_id = self.get_clock().now().to_msg(), "velodyne_top"
            if not published((self.pub, m)):
                return
            self.sent += 1

    def on_second(self) -> None:
        hz, self.sent = self.sent, 0
        self.publish_diagnostics(
            self.status(
                "velodyne_connection",
                "VLP-16_top",
                scans_per_second=hz,
                dropped_scans=self.dropped,
                temperature=f"{41 + random.random():.1f}",
            )
        )


class CameraDriver(ShuttleNode):
    """The front camera: 160x120 rgb8 at 15 fps (binned) from its capture thread, best effort."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("camera_driver", "sensing/camera/camera0", fault_dir)
        self.declare_parameter("video_device", "/dev/video0")
        self.declare_parameter("framerate", CAMERA_HZ)
        self.image_pub = self.create_publisher(Image, "/sensing/camera/camera0/image_raw", SENSOR)
        self.info_pub = self.create_publisher(CameraInfo, "/sensing/camera/camera0/camera_info", SENSOR)
        yy, xx = np.mgrid[0:120, 0:160]
        self.frames = []
        for k in range(4):
            r = ((xx + 5 * k) % 40 * 6).astype(np.uint8)
            g = ((yy * 2 + 3 * k) % 255).astype(np.uint8)
            b = (((xx // 10 + yy // 10 + k) % 2) * 200).astype(np.uint8)
            self.frames.append(np.dstack([r, g, b]).tobytes())
        self.info = CameraInfo(height=120, width=160, distortion_model="plumb_bob")
        self.info.header.frame_id = "camera0/camera_optical_link"
        self.info.k = [130.0, 0.0, 80.0, 0.0, 130.0, 60.0, 0.0, 0.0, 1.0]
        self.info.d = [-0.31, 0.09, 0.0, 0.0, 0.0]
        self.info.p = [130.0, 0.0, 80.0, 0.0, 0.0, 130.0, 60.0, 0.0, 0.0, 0.0, 1.0, 0.0]
        self.sent = 0
        self.get_logger().info("Opened /dev/video0: 160x120 rgb8 @ 15 fps (2x2 binning)")
        self.create_timer(1.0, self.on_second)
        threading.Thread(target=self.capture, daemon=True, name="capture").start()

    def capture(self) -> None:
        k = 0
        for _ in paced(CAMERA_HZ):
            img = Image(height=120, width=160, encoding="rgb8", is_bigendian=0, step=480)
            img.header.stamp, img.header.frame_id = (
                self.get_clock().now().to_msg(),
                "camera0/camera_optical_link",
            )
            img.data = self.frames[k % 4]
            k += 1
            self.info.header.stamp = img.header.stamp
            if not published((self.image_pub, img), (self.info_pub, self.info)):
                return
            self.sent += 1

    def on_second(self) -> None:
        fps, self.sent = self.sent, 0
        self.publish_diagnostics(
            self.status(
                "camera_status",
                "camera0",
                frames_per_second=fps,
                exposure_us=8000 + self.rng.randint(-500, 500),
            )
        )


class ImuDriver(ShuttleNode):
    """The IMU on its serial port: 50 Hz from the reader thread, best effort."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("imu_driver", "sensing/imu", fault_dir)
        self.declare_parameter("port", "/dev/ttyUSB0")
        self.declare_parameter("baudrate", 115200)
        self.pub = self.create_publisher(Imu, "/sensing/imu/imu_data", SENSOR)
        self.count = 0
        self.msg = Imu()
        self.msg.header.frame_id, self.msg.orientation.w = "imu_link", 1.0
        self.get_logger().info("Tamagawa TAG264 on /dev/ttyUSB0 @ 115200: 50 Hz")
        self.create_timer(1.0, self.on_second)
        threading.Thread(target=self.reader, daemon=True, name="serial").start()

    def reader(self) -> None:
        n = 0
        g = random.gauss
        for _ in paced(IMU_HZ):
            n += 1
            if self.fault == "degrade" and n % 5 in (1, 2, 3):  # the UART overruns: 3 of 5 frames lost
                continue
            m = self.msg
            m.header.stamp = self.get_clock().now().to_msg()
            m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z = (
                g(0, 0.003),
                g(0, 0.003),
                g(0, 0.004),
            )
            a = m.linear_acceleration
            a.x, a.y, a.z = g(0.0, 0.05), g(0.0, 0.05), 9.80 + g(0.0, 0.05)
            if not published((self.pub, m)):
                return
            self.count += 1

    def on_second(self) -> None:
        hz, self.count = self.count, 0
        self.publish_diagnostics(
            self.status("imu_status", "tamagawa_imu", rate_hz=hz, temperature=f"{35.0 + random.random():.1f}")
        )


class GnssDriver(ShuttleNode):
    """The GNSS receiver (u-blox F9P, RTK): 5 Hz fixes best effort; it loses RTK fix now and then
    (multipath near buildings: a WARN, back to fixed a few seconds later)."""

    ORIGIN = (35.6812, 139.7671)

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("gnss_driver", "sensing/gnss", fault_dir)
        self.declare_parameter("port", "/dev/ttyACM0")
        self.pub = self.create_publisher(NavSatFix, "/sensing/gnss/nav_sat_fix", SENSOR)
        self.float_until = 0.0
        self.next_float = time.monotonic() + random.uniform(30.0, 80.0)
        self.fixes = 0
        self.get_logger().info("u-blox ZED-F9P on /dev/ttyACM0: RTK corrections from NTRIP caster")
        self.create_timer(1.0 / GNSS_HZ, self.on_fix)
        self.create_timer(1.0, self.on_second)

    def on_fix(self) -> None:
        now = time.monotonic()
        if now >= self.next_float:
            self.float_until = now + random.uniform(3.0, 8.0)
            self.next_float = now + random.uniform(40.0, 90.0)
            self.get_logger().warn(
                f"RTK fix lost: float solution ({random.randint(9, 14)} satellites, multipath suspected)"
            )
        rtk = now >= self.float_until
        if not rtk and now + 1.0 / GNSS_HZ >= self.float_until:
            self.get_logger().info("RTK fix restored")
        sd = 0.02 if rtk else 0.6
        m = NavSatFix()
        m.header.stamp, m.header.frame_id = self.get_clock().now().to_msg(), "gnss_link"
        m.status.status = NavSatStatus.STATUS_GBAS_FIX if rtk else NavSatStatus.STATUS_FIX
        m.status.service = NavSatStatus.SERVICE_GPS | NavSatStatus.SERVICE_GALILEO
        m.latitude = self.ORIGIN[0] + random.gauss(0.0, sd) * 9e-6
        m.longitude = self.ORIGIN[1] + random.gauss(0.0, sd) * 1.1e-5
        m.altitude = 41.2 + random.gauss(0.0, sd)
        m.position_covariance = [sd * sd, 0.0, 0.0, 0.0, sd * sd, 0.0, 0.0, 0.0, 4 * sd * sd]
        m.position_covariance_type = NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN
        self.pub.publish(m)
        self.fixes += 1

    def on_second(self) -> None:
        rtk = time.monotonic() >= self.float_until
        self.publish_diagnostics(
            self.status(
                "fix_status",
                "ublox_f9p",
                message="RTK fixed" if rtk else "RTK float",
                fixes=self.fixes,
                satellites=random.randint(14, 19),
            )
        )


class GnssPoser(ShuttleNode):
    """The GNSS fix projected into the map frame (MGRS): a pose with covariance per fix."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("gnss_poser", "sensing/gnss", fault_dir)
        self.declare_parameter("coordinate_system", "MGRS")
        self.pub = self.create_publisher(
            PoseWithCovarianceStamped, "/sensing/gnss/pose_with_covariance", RELIABLE
        )
        self.create_subscription(NavSatFix, "/sensing/gnss/nav_sat_fix", self.on_fix, SENSOR)

    def on_fix(self, msg: NavSatFix) -> None:
        out = PoseWithCovarianceStamped()
        out.header.stamp, out.header.frame_id = msg.header.stamp, "map"
        p = out.pose.pose.position
        p.x = TRACK_X[0] + (msg.longitude - GnssDriver.ORIGIN[1]) / 1.1e-5
        p.y = TRACK_Y[0] + (msg.latitude - GnssDriver.ORIGIN[0]) / 9e-6
        p.z = msg.altitude - 41.2
        out.pose.pose.orientation.w = 1.0
        c = msg.position_covariance
        out.pose.covariance[0], out.pose.covariance[7], out.pose.covariance[14] = c[0], c[4], c[8]
        self.pub.publish(out)


# --- sensing: the pointcloud preprocessor container (one single-threaded executor) --------------------


class CropBoxFilter(ShuttleNode):
    """Removes the shuttle's own body and everything beyond 60 m."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("crop_box_filter", "sensing/lidar/top", fault_dir)
        self.declare_parameter("min_x", -2.5)
        self.declare_parameter("max_x", 2.5)
        self.declare_parameter("min_y", -1.2)
        self.declare_parameter("max_y", 1.2)
        self.pub = self.create_publisher(PointCloud2, "/sensing/lidar/top/pointcloud", SENSOR)
        self.create_subscription(PointCloud2, "/sensing/lidar/top/pointcloud_raw", self.on_cloud, SENSOR)

    def on_cloud(self, msg: PointCloud2) -> None:
        p = points(msg)
        body = (np.abs(p[:, 0]) < 2.5) & (np.abs(p[:, 1]) < 1.2)
        far = (np.abs(p[:, 0]) > 60.0) | (np.abs(p[:, 1]) > 60.0)
        self.pub.publish(cloud(msg.header, p[~(body | far)]))


class GroundFilter(ShuttleNode):
    """Ray-ground filter: removes the road surface, the rest goes to perception."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("ground_filter", "sensing/lidar/top", fault_dir)
        self.declare_parameter("sensor_height", 1.8)
        self.declare_parameter("global_slope_max_angle_deg", 10.0)
        self.pub = self.create_publisher(PointCloud2, "/sensing/lidar/top/no_ground/pointcloud", SENSOR)
        self.create_subscription(PointCloud2, "/sensing/lidar/top/pointcloud", self.on_cloud, SENSOR)

    def on_cloud(self, msg: PointCloud2) -> None:
        if self.fault == "hang":  # the ray bins' while-loop never ends on a NaN point (a driver glitch)
            threading.Event().wait()
        p = points(msg)
        r = np.hypot(p[:, 0], p[:, 1])
        ground = p[:, 2] < -1.8 + 0.15 + 0.03 * r / 10.0
        self.pub.publish(cloud(msg.header, p[~ground]))


class VoxelDownsampleFilter(ShuttleNode):
    """1 m voxel grid downsampling of the cropped cloud, for the NDT scan matcher."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("voxel_grid_downsample_filter", "sensing/lidar/top", fault_dir)
        self.declare_parameter("voxel_size", 1.0)
        self.pub = self.create_publisher(PointCloud2, "/sensing/lidar/top/downsampled/pointcloud", SENSOR)
        self.create_subscription(PointCloud2, "/sensing/lidar/top/pointcloud", self.on_cloud, SENSOR)

    def on_cloud(self, msg: PointCloud2) -> None:
        p = points(msg)
        keys = np.floor(p[:, :3]).astype(np.int32)
        _, first = np.unique(keys, axis=0, return_index=True)
        self.pub.publish(cloud(msg.header, p[np.sort(first)]))


# --- localization -------------------------------------------------------------------------------------


class NdtScanMatcher(ShuttleNode):
    """NDT scan matching of the downsampled scan against the point cloud map, the EKF's pose
    (interpolated to the scan's stamp) as the initial guess; the pose out stamped with the scan's
    stamp. Enabled by the alignment service at initialization. The dynamic map loader swaps map
    cells every ~30 s on the node's only thread (0.4-0.7 s of CPU)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("ndt_scan_matcher", "localization/pose_estimator", fault_dir)
        self.declare_parameter("resolution", 2.0)
        self.declare_parameter("max_iterations", 30)
        self.declare_parameter("initial_pose_timeout_sec", 1.0)
        self.declare_parameter("dynamic_map_loading_update_distance", 20.0)
        self.pose_pub = self.create_publisher(
            PoseWithCovarianceStamped, "/localization/pose_estimator/pose_with_covariance", RELIABLE
        )
        self.create_subscription(
            PointCloud2, "/sensing/lidar/top/downsampled/pointcloud", self.on_scan, SENSOR
        )
        self.create_subscription(
            PoseWithCovarianceStamped,
            "/localization/pose_twist_fusion_filter/biased_pose_with_covariance",
            self.on_ekf_pose,
            LATEST,  # the newest pose: the matcher keeps its own history of them
        )
        self.create_service(Trigger, "/localization/pose_estimator/ndt_align_srv", self.on_align)
        rng = np.random.default_rng(3)
        self.map = rng.uniform(-40.0, 40.0, (1500, 3)).astype(np.float32)
        self.map_sq = (self.map**2).sum(1)
        self.guesses: deque = deque(maxlen=30)  # (stamp, x, y, yaw)
        self.enabled = False
        self.exe_ms = deque(maxlen=20)
        self.skipped = self.matched = 0
        self.score = 0.0
        self.get_logger().info("Loaded the pointcloud map metadata: 342 cells (20 m)")
        self.create_timer(1.0, self.on_second)
        self.map_timer = self.create_timer(random.uniform(25.0, 35.0), self.update_map)

    def on_ekf_pose(self, msg: PoseWithCovarianceStamped) -> None:
        p = msg.pose.pose
        self.guesses.append((secs(msg.header.stamp), p.position.x, p.position.y, yaw_of(p.orientation)))

    def on_align(self, request, response):
        busy(0.25)  # the Monte-Carlo initial pose search
        self.enabled = True
        response.success, response.message = True, "aligned: score 3.12 (particles 200)"
        self.get_logger().info("Initial pose alignment done: score 3.12")
        return response

    def register(self, scan: np.ndarray, iterations: int) -> float:
        """Nearest map points of the scan, a few Gauss-Newton iterations (numpy), on at most 400 of
        its points (the matcher's own sampling)."""
        pts = scan[:: max(1, len(scan) // 400), :3]
        score = 0.0
        for _ in range(iterations):
            d = (pts**2).sum(1)[:, None] + self.map_sq[None, :] - 2.0 * pts @ self.map.T
            score = float(np.sqrt(np.maximum(d.min(1), 0.0)).mean())
            pts = pts * 0.999
        return score

    def on_scan(self, msg: PointCloud2) -> None:
        if not self.enabled:
            return
        t0 = time.perf_counter()
        stamp = secs(msg.header.stamp)
        if not self.guesses:
            if self.throttle("noguess", 5.0):
                self.get_logger().warn("No initial pose from the EKF yet: scan skipped")
            return
        gt, x, y, yaw = min(self.guesses, key=lambda g: abs(g[0] - stamp))  # interpolated, roughly
        if stamp - gt > 1.0:  # the initial pose is too old to be interpolated to the scan
            self.skipped += 1
            if self.throttle("old", 2.0):
                self.get_logger().warn(
                    f"Validation error: the initial pose is {stamp - gt:.2f} s older than the "
                    "scan (limit 1.00 s): skipping the alignment"
                )
            return
        if self.fault == "slow":  # the map loader's lock is contended: every alignment waits for it
            time.sleep(0.25)
            busy(0.05)
        self.score = self.register(points(msg), 3)
        out = PoseWithCovarianceStamped()
        out.header.stamp, out.header.frame_id = msg.header.stamp, "map"
        p = out.pose.pose
        p.position.x = x + random.gauss(0.0, 0.03)
        p.position.y = y + random.gauss(0.0, 0.03)
        set_yaw(p.orientation, yaw + random.gauss(0.0, 0.002))
        out.pose.covariance[0] = out.pose.covariance[7] = 0.0225
        out.pose.covariance[35] = 0.000625
        self.pose_pub.publish(out)
        self.matched += 1
        self.exe_ms.append((time.perf_counter() - t0) * 1000.0)

    def update_map(self) -> None:
        self.map_timer.cancel()
        self.map_timer = self.create_timer(random.uniform(25.0, 35.0), self.update_map)
        t0 = time.perf_counter()
        busy(random.uniform(0.4, 0.7))  # the new cells' voxel covariances
        rng = np.random.default_rng()
        self.map = rng.uniform(-40.0, 40.0, (1500, 3)).astype(np.float32)
        self.map_sq = (self.map**2).sum(1)
        added, removed = random.randint(8, 16), random.randint(8, 16)
        self.get_logger().info(
            f"Dynamic map update: {added} cells loaded, {removed} removed ({time.perf_counter() - t0:.2f} s)"
        )

    def on_second(self) -> None:
        exe = max(self.exe_ms, default=0.0)
        level, text = (OK, "OK") if exe < 100.0 else (WARN, "NDT processing time is too long")
        if not self.enabled:
            level, text = WARN, "not activated (waiting for the initial pose)"
        self.publish_diagnostics(
            self.status(
                "scan_matching_status",
                "ndt",
                level,
                text,
                execution_time_ms=f"{exe:.1f}",
                transform_probability=f"{self.score:.2f}",
                matched=self.matched,
                skipped=self.skipped,
            )
        )
        self.matched = self.skipped = 0


class EkfLocalizer(ShuttleNode):
    """The EKF: predicts on each velocity report (50 Hz) from the wheel odometry and the IMU's yaw
    rate (saves a 50 Hz timer on the ECU), corrects with the
    NDT pose (delay-compensated through its state buffer: a measurement older than 1.0 s is
    rejected). ``/localization/kinematic_state`` at 50 Hz and the biased pose at 10 Hz, stamped
    with the stamp of the velocity report the prediction was made from. Starts on ``/initialpose3d``."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("ekf_localizer", "localization/pose_twist_fusion_filter", fault_dir)
        self.declare_parameter("predict_frequency", EKF_HZ)
        self.declare_parameter("extend_state_step", 50)
        self.declare_parameter("pose_gate_dist", 10000.0)
        self.odom_pub = self.create_publisher(Odometry, "/localization/kinematic_state", LATEST)
        self.pose_pub = self.create_publisher(
            PoseWithCovarianceStamped,
            "/localization/pose_twist_fusion_filter/biased_pose_with_covariance",
            RELIABLE,
        )
        self.create_subscription(
            PoseWithCovarianceStamped,
            "/localization/pose_estimator/pose_with_covariance",
            self.on_pose,
            RELIABLE,
        )
        self.create_subscription(
            TwistWithCovarianceStamped, "/vehicle/status/velocity_status", self.on_twist, RELIABLE
        )
        self.create_subscription(Imu, "/sensing/imu/imu_data", self.on_imu, SENSOR)
        self.create_subscription(PoseWithCovarianceStamped, "/initialpose3d", self.on_initialpose, RELIABLE)
        self.state = None  # x, y, yaw
        self.v = self.wz = self.gyro = 0.0
        self.twist_stamp = None
        self.pose_at = None
        self.pose_delay = 0.0
        self.rejected = 0
        self.imu_n = self.twist_n = self.pose_n = 0
        self.tick = 0
        self.last = time.monotonic()
        self.create_timer(1.0, self.on_second)

    def on_initialpose(self, msg: PoseWithCovarianceStamped) -> None:
        p = msg.pose.pose
        self.state = [p.position.x, p.position.y, yaw_of(p.orientation)]
        self.pose_at = time.monotonic()
        self.get_logger().info(f"Initialized with the initial pose ({p.position.x:.1f}, {p.position.y:.1f})")

    def on_twist(self, msg: TwistWithCovarianceStamped) -> None:
        self.v, self.wz = msg.twist.twist.linear.x, msg.twist.twist.angular.z
        self.twist_stamp = msg.header.stamp
        self.twist_n += 1
        self.predict()  # the prediction step runs on each velocity report (50 Hz)

    def on_imu(self, msg: Imu) -> None:
        self.gyro = 0.98 * self.gyro + 0.02 * msg.angular_velocity.z
        self.imu_n += 1

    def on_pose(self, msg: PoseWithCovarianceStamped) -> None:
        if self.state is None:
            return
        self.pose_n += 1
        delay = self.get_clock().now().nanoseconds * 1e-9 - secs(msg.header.stamp)
        self.pose_delay = delay
        if delay > 1.0:  # beyond the state buffer (extend_state_step * dt)
            self.rejected += 1
            if self.throttle("delay", 5.0):
                self.get_logger().warn(
                    f"Pose delay {delay:.2f} s exceeds the compensation limit (1.00 s): measurement ignored"
                )
            return
        p = msg.pose.pose
        # the innovation, applied at the measurement's time, propagated to now
        gain = 0.2
        self.state[0] += gain * (p.position.x + self.v * math.cos(self.state[2]) * delay - self.state[0])
        self.state[1] += gain * (p.position.y + self.v * math.sin(self.state[2]) * delay - self.state[1])
        self.pose_at = time.monotonic()

    def predict(self) -> None:
        now = time.monotonic()
        dt, self.last = min(0.1, now - self.last), now
        if self.state is None or self.twist_stamp is None:
            return
        wz = self.wz + 0.1 * (self.gyro - 0.0)
        self.state[2] += wz * dt
        self.state[0] += self.v * math.cos(self.state[2]) * dt
        self.state[1] += self.v * math.sin(self.state[2]) * dt
        stamp = self.twist_stamp
        if self.fault == "stale":  # the output index into the state buffer is off: the oldest state's time
            stamp = to_stamp(secs(stamp) - 1.5)
        m = Odometry()
        m.header.stamp, m.header.frame_id, m.child_frame_id = stamp, "map", "base_link"
        p = m.pose.pose
        p.position.x, p.position.y = self.state[0], self.state[1]
        set_yaw(p.orientation, self.state[2])
        m.twist.twist.linear.x, m.twist.twist.angular.z = self.v, wz
        self.odom_pub.publish(m)
        self.tick += 1
        if self.tick % BIASED_POSE_EVERY == 0:
            b = PoseWithCovarianceStamped()
            b.header = m.header
            b.pose.pose = m.pose.pose
            b.pose.covariance[0] = b.pose.covariance[7] = 0.04
            self.pose_pub.publish(b)

    def on_second(self) -> None:
        if self.state is None:
            st = self.status("localization_status", "ekf", WARN, "not initialized")
        else:
            since = time.monotonic() - (self.pose_at or 0.0)
            if since > 3.0:
                st = self.status(
                    "localization_status",
                    "ekf",
                    WARN,
                    f"pose not updated for {since:.1f} s",
                    pose_hz=self.pose_n,
                    twist_hz=self.twist_n,
                    imu_hz=self.imu_n,
                )
                if self.throttle("nopose", 10.0):
                    self.get_logger().warn(
                        f"The pose has not been updated for {since:.1f} s: dead reckoning only"
                    )
            else:
                st = self.status(
                    "localization_status",
                    "ekf",
                    pose_hz=self.pose_n,
                    twist_hz=self.twist_n,
                    imu_hz=self.imu_n,
                    pose_delay=f"{self.pose_delay:.3f}",
                    rejected=self.rejected,
                )
        self.imu_n = self.twist_n = self.pose_n = 0
        self.publish_diagnostics(st)


class PoseInitializer(ShuttleNode):
    """``/localization/initialize``: accepted at once, then the GNSS pose refined by the NDT's
    alignment service (its answer polled at 10 Hz), then ``/initialpose3d`` for the EKF; the
    initialization state latched."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("pose_initializer", "localization/util", fault_dir)
        self.declare_parameter("gnss_enabled", True)
        self.declare_parameter("ndt_enabled", True)
        self.state_pub = self.create_publisher(String, "/localization/initialization_state", LATCHED)
        self.initial_pub = self.create_publisher(PoseWithCovarianceStamped, "/initialpose3d", RELIABLE)
        self.create_subscription(
            PoseWithCovarianceStamped, "/sensing/gnss/pose_with_covariance", self.on_gnss, RELIABLE
        )
        self.align = self.create_client(Trigger, "/localization/pose_estimator/ndt_align_srv")
        self.aligning = None  # the alignment call under way
        self.create_service(Trigger, "/localization/initialize", self.on_initialize)
        self.gnss = None
        self.state_pub.publish(String(data="UNINITIALIZED"))

    def on_gnss(self, msg: PoseWithCovarianceStamped) -> None:
        self.gnss = msg

    def on_initialize(self, request, response):
        if self.gnss is None:
            response.success, response.message = False, "no GNSS pose"
            return response
        if not self.align.service_is_ready():
            response.success, response.message = False, "ndt_align_srv not available"
            return response
        if self.aligning is None:
            self.state_pub.publish(String(data="INITIALIZING"))
            self.aligning = self.align.call_async(Trigger.Request())
            self.poll = self.create_timer(0.1, self.on_poll)
        response.success, response.message = True, "initialization started"
        return response

    def on_poll(self) -> None:
        if not self.aligning.done():
            return
        result, self.aligning = self.aligning.result(), None
        self.destroy_timer(self.poll)
        if result is None or not result.success:
            self.state_pub.publish(String(data="UNINITIALIZED"))
            self.get_logger().error("Initialization failed: the NDT alignment failed")
            return
        pose = PoseWithCovarianceStamped()
        pose.header.stamp, pose.header.frame_id = self.get_clock().now().to_msg(), "map"
        g = self.gnss.pose.pose.position
        pose.pose.pose.position.x, pose.pose.pose.position.y = g.x, g.y
        set_yaw(pose.pose.pose.orientation, float(TRACK_YAW[nearest_track_index(g.x, g.y)]))
        self.initial_pub.publish(pose)
        self.state_pub.publish(String(data="INITIALIZED"))
        self.get_logger().info("Initialization succeeded: " + result.message)


# --- perception ---------------------------------------------------------------------------------------


class YoloxDetector(ShuttleNode):
    """The camera object detector (a small YOLOX): every frame inferred, the ROIs published only
    when objects are found (pedestrians and cyclists come and go: bursty output)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("tensorrt_yolox", "perception/object_recognition/detection", fault_dir)
        self.declare_parameter("model_path", "/opt/autoware/data/yolox-tiny.onnx")
        self.declare_parameter("score_threshold", 0.35)
        self.pub = self.create_publisher(
            PoseArray, "/perception/object_recognition/detection/rois0", RELIABLE
        )
        self.create_subscription(Image, "/sensing/camera/camera0/image_raw", self.on_image, SENSOR)
        self.kernel = np.random.default_rng(1).standard_normal((8, 27)).astype(np.float32)
        self.scene_until = 0.0
        self.next_scene = time.monotonic() + random.uniform(2.0, 8.0)
        self.objects = 0
        self.get_logger().info("TensorRT engine loaded: yolox-nano FP16 (40x30 input)")

    def on_image(self, msg: Image) -> None:
        img = np.frombuffer(msg.data, dtype=np.uint8).reshape(msg.height, msg.width, 3).astype(np.float32)
        x = img[::4, ::4] * (1.0 / 255.0)  # the network's 40x30 input
        patches = np.concatenate(
            [
                x[:-2, :-2],
                x[1:-1, 1:-1],
                x[2:, 2:],
                x[:-2, 2:],
                x[2:, :-2],
                x[1:-1, :-2],
                x[1:-1, 2:],
                x[:-2, 1:-1],
                x[2:, 1:-1],
            ],
            axis=2,
        ).reshape(-1, 27)
        feat = np.maximum(patches @ self.kernel.T, 0.0).mean(0)
        now = time.monotonic()
        if now >= self.next_scene:  # somebody walks into view
            self.scene_until = now + random.uniform(2.0, 6.0)
            self.next_scene = self.scene_until + random.uniform(3.0, 15.0)
            self.objects = random.randint(1, 3)
        if now >= self.scene_until or random.random() < 0.15:  # nothing (or a missed frame)
            return
        out = PoseArray()
        out.header = msg.header
        for i in range(self.objects):
            p = Pose()
            p.position.x, p.position.y = 8.0 + 6.0 * i + float(feat[i % 8]), -3.0 + 3.0 * i
            p.orientation.w = 1.0
            out.poses.append(p)
        self.pub.publish(out)


class EuclideanCluster(ShuttleNode):
    """Clusters the obstacle points on a 2 m grid: centroids of the occupied cells, 10 Hz."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("euclidean_cluster", "perception/object_recognition/detection/clustering", fault_dir)
        self.declare_parameter("tolerance", 0.7)
        self.declare_parameter("min_cluster_size", 10)
        self.pub = self.create_publisher(
            PoseArray, "/perception/object_recognition/detection/clustering/clusters", RELIABLE
        )
        self.create_subscription(
            PointCloud2, "/sensing/lidar/top/no_ground/pointcloud", self.on_cloud, SENSOR
        )

    def on_cloud(self, msg: PointCloud2) -> None:
        p = points(msg)
        near = p[np.hypot(p[:, 0], p[:, 1]) < 30.0]
        cells = np.floor(near[:, :2] / 2.0).astype(np.int32)
        _, inverse, counts = np.unique(cells, axis=0, return_inverse=True, return_counts=True)
        out = PoseArray()
        out.header = msg.header
        for k in np.nonzero(counts >= 10)[0][:20]:
            c = near[inverse.ravel() == k, :3].mean(0)
            pose = Pose()
            pose.position.x, pose.position.y, pose.position.z = float(c[0]), float(c[1]), float(c[2])
            pose.orientation.w = 1.0
            out.poses.append(pose)
        self.pub.publish(out)


class MultiObjectTracker(ShuttleNode):
    """Tracks objects from the lidar clusters, fused with the camera ROIs by an approximate-time
    synchronizer (message_filters' ApproximateTime by hand: a cluster set is paired with the ROIs
    whose stamp is within 50 ms; when the detector saw nothing the cluster set goes on alone once
    the next set has come, ~100 ms later). Objects out on each cluster set, stamped with it."""

    SLOP = 0.05

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("multi_object_tracker", "perception/object_recognition/tracking", fault_dir)
        self.declare_parameter("world_frame_id", "map")
        self.declare_parameter("sync_slop", self.SLOP)
        self.pub = self.create_publisher(PoseArray, "/perception/object_recognition/objects", RELIABLE)
        self.create_subscription(
            PoseArray,
            "/perception/object_recognition/detection/clustering/clusters",
            self.on_clusters,
            RELIABLE,
        )
        self.create_subscription(
            PoseArray, "/perception/object_recognition/detection/rois0", self.on_rois, RELIABLE
        )
        self.clusters: deque = deque(maxlen=10)
        self.rois: deque = deque(maxlen=10)
        self.tracks: dict[int, list[float]] = {}
        self.next_id = 0
        self.fused = self.alone = 0

    def on_clusters(self, msg: PoseArray) -> None:
        self.clusters.append((secs(msg.header.stamp), time.monotonic(), msg))
        self.match()

    def on_rois(self, msg: PoseArray) -> None:
        self.rois.append((secs(msg.header.stamp), msg))
        self.match()

    def match(self) -> None:
        while self.clusters:
            t, _, cl = self.clusters[0]
            pair = min(self.rois, key=lambda r: abs(r[0] - t), default=None)
            if pair is not None and abs(pair[0] - t) <= self.SLOP:
                self.clusters.popleft()
                while self.rois and self.rois[0][0] <= pair[0]:
                    self.rois.popleft()
                self.fused += 1
                self.track(cl, pair[1])
            elif len(self.clusters) > 1 or (self.rois and self.rois[-1][0] > t + self.SLOP):
                # no pair can come any more (a newer set is here): the set goes on alone
                self.clusters.popleft()
                self.alone += 1
                self.track(cl, None)
            else:
                return

    def track(self, clusters: PoseArray, rois: PoseArray | None) -> None:
        seen = {}
        for pose in clusters.poses:
            x, y = pose.position.x, pose.position.y
            best = min(
                self.tracks.items(), key=lambda kv: math.hypot(kv[1][0] - x, kv[1][1] - y), default=None
            )
            if best is not None and math.hypot(best[1][0] - x, best[1][1] - y) < 2.0 and best[0] not in seen:
                tid = best[0]
            else:
                tid, self.next_id = self.next_id, self.next_id + 1
            seen[tid] = [x, y, 0]
        for tid, tr in self.tracks.items():
            if tid not in seen and tr[2] < 3:  # coasting
                seen[tid] = [tr[0], tr[1], tr[2] + 1]
        self.tracks = seen
        out = PoseArray()
        out.header = clusters.header
        out.header.frame_id = "base_link"
        for x, y, _ in self.tracks.values():
            p = Pose()
            p.position.x, p.position.y = x, y
            p.orientation.w = 1.0
            out.poses.append(p)
        if rois is not None:
            out.poses.extend(rois.poses)
        self.pub.publish(out)


class TrafficLightClassifier(LifecycleNode):
    """The traffic-light classifier, a lifecycle node the behavior planner configures at bring-up and
    activates only when an intersection is ahead: active, it takes the camera, the route and the
    EKF's pose (to find the signal in the image) and publishes the signal of the group ahead for
    every other frame (7.5 Hz)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("traffic_light_classifier", namespace="perception/traffic_light_recognition")
        hook(self, fault_dir)
        self.declare_parameter("classifier_type", "cnn")
        self.declare_parameter("model_path", "/opt/autoware/data/traffic_light_classifier_mobilenetv2.onnx")
        self.pub = None
        self.subs = []
        self.route: list[int] = []
        self.pose = None
        self.n = 0

    def on_fault(self, fault: str | None) -> None:
        pass

    def on_configure(self, state) -> TransitionCallbackReturn:
        self.pub = self.create_lifecycle_publisher(
            String, "/perception/traffic_light_recognition/traffic_signals", RELIABLE
        )
        self.get_logger().info("Configured: mobilenetv2 classifier loaded")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        self.subs = [
            self.create_subscription(Image, "/sensing/camera/camera0/image_raw", self.on_image, SENSOR),
            self.create_subscription(PathMsg, "/planning/mission_planning/route", self.on_route, LATCHED),
            self.create_subscription(
                PoseWithCovarianceStamped,
                "/localization/pose_twist_fusion_filter/biased_pose_with_covariance",
                self.on_pose,
                RELIABLE,
            ),
        ]
        self.get_logger().info("Activated: intersection ahead")
        return super().on_activate(state)

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        for s in self.subs:
            self.destroy_subscription(s)
        self.subs = []
        self.pose = None
        self.get_logger().info("Deactivated")
        return super().on_deactivate(state)

    def on_route(self, msg: PathMsg) -> None:
        if msg.poses:
            first = nearest_track_index(msg.poses[0].pose.position.x, msg.poses[0].pose.position.y)
            self.route = [(first + i) % TRACK_N for i in range(len(msg.poses))]

    def on_pose(self, msg: PoseWithCovarianceStamped) -> None:
        self.pose = (msg.pose.pose.position.x, msg.pose.pose.position.y)

    def on_image(self, msg: Image) -> None:
        self.n += 1
        if self.n % 2 or self.pose is None or self.pub is None:
            return
        here = nearest_track_index(*self.pose)
        ahead = [(g, (s - here) % TRACK_N) for g, s in TRAFFIC_LIGHTS.items() if (s - here) % TRACK_N < 80]
        if not ahead:
            return
        group, dist = min(ahead, key=lambda a: a[1])
        img = np.frombuffer(msg.data, dtype=np.uint8).reshape(msg.height, msg.width, 3)
        roi = img[10:40, 70:90].astype(np.float32)
        conf = 0.85 + 0.1 * float(roi.std() > 1.0) * random.random()
        color = light_color(group, time.time())
        self.pub.publish(
            String(
                data=f"group={group} color={color} confidence={conf:.2f} distance={dist:.0f} "
                f"stamp={secs(msg.header.stamp):.3f}"
            )
        )


# --- planning -----------------------------------------------------------------------------------------


def route_path(indices: list[int], stamp) -> PathMsg:
    path = PathMsg()
    path.header.stamp, path.header.frame_id = stamp, "map"
    for i in indices:
        p = PoseStamped()
        p.header.frame_id = "map"
        p.pose.position.x, p.pose.position.y = float(TRACK_X[i]), float(TRACK_Y[i])
        set_yaw(p.pose.orientation, float(TRACK_YAW[i]))
        path.poses.append(p)
    return path


class MissionPlanner(ShuttleNode):
    """The route: ``set_route_points`` (nav_msgs/GetPlan, the goal only: the start is the current
    pose) plans on the lanelet routing graph and publishes the route latched, once per route;
    ``plan_route`` plans without setting (the AD API's ETA). The route state (UNSET, SET, ARRIVED)
    latched; arrival when the EKF pose stays within 2 m of the goal for 1 s."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("mission_planner", "planning/mission_planning", fault_dir)
        self.declare_parameter("map_path", "/opt/autoware/maps/campus_loop/lanelet2_map.osm")
        self.declare_parameter("arrival_check_distance", ARRIVAL_DISTANCE)
        self.declare_parameter("arrival_check_duration", 1.0)
        self.route_pub = self.create_publisher(PathMsg, "/planning/mission_planning/route", LATCHED)
        self.state_pub = self.create_publisher(String, "/planning/mission_planning/state", LATCHED)
        self.create_subscription(
            PoseWithCovarianceStamped,
            "/localization/pose_twist_fusion_filter/biased_pose_with_covariance",
            self.on_pose,
            RELIABLE,
        )
        self.create_service(GetPlan, "/planning/mission_planning/set_route_points", self.on_set_route)
        self.create_service(GetPlan, "/planning/mission_planning/plan_route", self.on_plan_route)
        self.pose = None
        self.goal = None
        self.state = ""
        self.near = 0
        self.routes = 0
        self.set_state("UNSET")
        self.get_logger().info("Lanelet2 map loaded: 41 lanelets, 3 stations, 3 traffic light groups")

    def set_state(self, state: str) -> None:
        self.state = state
        self.state_pub.publish(String(data=state))

    def on_pose(self, msg: PoseWithCovarianceStamped) -> None:
        self.pose = (msg.pose.pose.position.x, msg.pose.pose.position.y)
        self.check_arrival()

    def plan(self, goal: PoseStamped) -> list[int] | None:
        if (
            self.fault == "slow"
        ):  # the routing graph cache is invalidated: rebuilt from the map server each call
            time.sleep(4.8)
            busy(0.2)
        if self.pose is None:
            return None
        busy(0.015)  # the routing graph search
        start = nearest_track_index(*self.pose)
        end = nearest_track_index(goal.pose.position.x, goal.pose.position.y)
        n = (end - start) % TRACK_N
        return [(start + i) % TRACK_N for i in range(n + 1)]

    def on_set_route(self, request, response):
        route = self.plan(request.goal)
        if route is None or len(route) < 5:
            self.get_logger().error(
                "Failed to plan a route: no current pose"
                if route is None
                else "Failed to plan a route: the goal is the current position"
            )
            return response
        self.routes += 1
        path = route_path(route, self.get_clock().now().to_msg())
        self.goal = (float(TRACK_X[route[-1]]), float(TRACK_Y[route[-1]]))
        self.near = 0
        self.route_pub.publish(path)
        self.set_state("SET")
        self.get_logger().info(f"Route {self.routes} set: {len(route)} m, {len(route) // 40 + 1} lanelets")
        response.plan = path
        return response

    def on_plan_route(self, request, response):
        route = self.plan(request.goal)
        if route is not None:
            response.plan = route_path(route, self.get_clock().now().to_msg())
        return response

    def check_arrival(self) -> None:
        if self.state != "SET" or self.pose is None or self.goal is None:
            return
        if math.dist(self.pose, self.goal) < ARRIVAL_DISTANCE:
            self.near += 1
            if self.near >= 10:
                self.set_state("ARRIVED")
                self.get_logger().info("Goal reached: route completed")
        else:
            self.near = 0


class BehaviorPathPlanner(ShuttleNode):
    """Lane following on the route at 10 Hz (the ego pose and speed from the EKF's 10 Hz biased
    pose: the 50 Hz kinematic state is the controller's): the path 80 m ahead with the lane's speed limit per
    point, zero from the stop point on (the route's goal, or a stop line at a red or unknown
    signal). Activates the traffic-light classifier within 70 m of an intersection and deactivates
    it past it. Idle (no path) without a route or once arrived."""

    HORIZON, LIGHT_RANGE, STOP_OFFSET = 80, 70, 4

    def __init__(self, fault_dir: Path) -> None:
        super().__init__(
            "behavior_path_planner", "planning/scenario_planning/lane_driving/behavior_planning", fault_dir
        )
        self.declare_parameter("forward_path_length", float(self.HORIZON))
        self.declare_parameter("traffic_light.stop_margin", float(self.STOP_OFFSET))
        self.pub = self.create_publisher(
            PathMsg, "/planning/scenario_planning/lane_driving/behavior_planning/path", LATEST
        )
        self.create_subscription(PathMsg, "/planning/mission_planning/route", self.on_route, LATCHED)
        self.create_subscription(String, "/planning/mission_planning/state", self.on_state, LATCHED)
        self.create_subscription(
            PoseWithCovarianceStamped,
            "/localization/pose_twist_fusion_filter/biased_pose_with_covariance",
            self.on_pose,
            RELIABLE,
        )
        self.create_subscription(
            PoseArray, "/perception/object_recognition/objects", self.on_objects, RELIABLE
        )
        self.create_subscription(
            String, "/perception/traffic_light_recognition/traffic_signals", self.on_signal, RELIABLE
        )
        self.tl = self.create_client(
            ChangeState, "/perception/traffic_light_recognition/traffic_light_classifier/change_state"
        )
        self.route: list[int] = []
        self.state = "UNSET"
        self.ego = None
        self.ego_t = 0.0
        self.v = 0.0
        self.idx = 0
        self.signals: dict[int, tuple[str, float]] = {}
        self.objects_at = None
        self.tl_state = "unconfigured"  # unconfigured, inactive, active (the requested one)
        self.transitions: list = []  # (label, future) of the change_state calls under way
        self.idle_logged = False
        self.create_timer(1.0 / PLANNER_HZ, self.plan)
        self.create_timer(1.0, self.bringup)

    def bringup(self) -> None:
        self.check_transitions()
        if self.tl_state == "unconfigured" and self.tl.service_is_ready():
            self.tl_state = "inactive"
            self.transition(Transition.TRANSITION_CONFIGURE, "configure")
        if (
            self.objects_at is not None
            and time.monotonic() - self.objects_at > 2.0
            and self.throttle("obj", 10.0)
        ):
            self.get_logger().warn(
                "No objects from perception for "
                f"{time.monotonic() - self.objects_at:.1f} s: planning without obstacles"
            )

    def transition(self, tid: int, label: str) -> None:
        fut = self.tl.call_async(ChangeState.Request(transition=Transition(id=tid)))
        self.transitions.append((label, fut))

    def check_transitions(self) -> None:
        for item in [t for t in self.transitions if t[1].done()]:
            self.transitions.remove(item)
            r = item[1].result()
            if r is None or not r.success:
                self.get_logger().error(f"Traffic light classifier: {item[0]} failed")

    def on_route(self, msg: PathMsg) -> None:
        if not msg.poses:
            return
        first = nearest_track_index(msg.poses[0].pose.position.x, msg.poses[0].pose.position.y)
        self.route = [(first + i) % TRACK_N for i in range(len(msg.poses))]
        self.idx = 0
        self.get_logger().info(f"New route received: {len(self.route)} m")

    def on_state(self, msg: String) -> None:
        self.state = msg.data

    def on_pose(self, msg: PoseWithCovarianceStamped) -> None:
        p = msg.pose.pose.position
        t = secs(msg.header.stamp)
        if self.ego is not None and t > self.ego_t:
            self.v = 0.7 * self.v + 0.3 * math.hypot(p.x - self.ego[0], p.y - self.ego[1]) / (t - self.ego_t)
        self.ego, self.ego_t = (p.x, p.y), t

    def on_objects(self, msg: PoseArray) -> None:
        self.objects_at = time.monotonic()

    def on_signal(self, msg: String) -> None:
        kv = dict(p.split("=", 1) for p in msg.data.split())
        self.signals[int(kv["group"])] = (kv["color"], time.monotonic())

    def set_classifier(self, active: bool) -> None:
        if self.tl_state == "unconfigured" or (self.tl_state == "active") == active:
            return
        self.tl_state = "active" if active else "inactive"
        self.transition(
            Transition.TRANSITION_ACTIVATE if active else Transition.TRANSITION_DEACTIVATE,
            "activate" if active else "deactivate",
        )

    def plan(self) -> None:
        if self.state != "SET" or not self.route or self.ego is None:
            self.set_classifier(False)
            if not self.idle_logged:
                self.idle_logged = True
                self.get_logger().info("No route: waiting")
            return
        self.idle_logged = False
        lo, hi = max(0, self.idx - 5), min(len(self.route), self.idx + 40)
        window = np.array(self.route[lo:hi])
        d = (TRACK_X[window] - self.ego[0]) ** 2 + (TRACK_Y[window] - self.ego[1]) ** 2
        self.idx = lo + int(np.argmin(d))
        end = min(len(self.route), self.idx + self.HORIZON)
        stop = len(self.route) - 1 if end == len(self.route) else None
        near = False
        now = time.monotonic()
        for group, s in TRAFFIC_LIGHTS.items():
            ahead = (s - self.route[self.idx]) % TRACK_N
            if ahead > self.LIGHT_RANGE or self.idx + ahead >= len(self.route):
                continue
            near = True
            color, at = self.signals.get(group, ("UNKNOWN", -1e9))
            if now - at > 1.0:
                color = "UNKNOWN"
            line = self.idx + ahead - self.STOP_OFFSET
            if line < self.idx:
                continue  # past the stop line already
            dist = line - self.idx
            if (
                color == "RED"
                or color == "UNKNOWN"
                or (color == "AMBER" and dist > self.v * self.v / 3.0 + 2.0)
            ):
                stop = line if stop is None else min(stop, line)
        self.set_classifier(near)
        path = PathMsg()
        path.header.stamp, path.header.frame_id = self.get_clock().now().to_msg(), "map"
        for k in range(self.idx, end, 2):
            i = self.route[k]
            p = PoseStamped()
            p.pose.position.x, p.pose.position.y = float(TRACK_X[i]), float(TRACK_Y[i])
            p.pose.position.z = 0.0 if stop is not None and k >= stop else LANE_SPEED_LIMIT
            set_yaw(p.pose.orientation, float(TRACK_YAW[i]))
            path.poses.append(p)
        if stop is not None and stop < end and (stop - self.idx) % 2:  # the stop point itself
            i = self.route[stop]
            p = PoseStamped()
            p.pose.position.x, p.pose.position.y = float(TRACK_X[i]), float(TRACK_Y[i])
            set_yaw(p.pose.orientation, float(TRACK_YAW[i]))
            path.poses.insert((stop - self.idx) // 2 + 1, p)
        self.pub.publish(path)


class MotionVelocitySmoother(ShuttleNode):
    """The velocity profile of the path: the operator's ``max_velocity`` (a runtime parameter),
    the lateral acceleration limit on curves, the deceleration limit before stops."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("motion_velocity_smoother", "planning/scenario_planning", fault_dir)
        self.declare_parameter("max_velocity", 4.5)
        self.declare_parameter("max_lateral_accel", 1.2)
        self.declare_parameter("normal.min_acc", -0.8)
        self.add_on_set_parameters_callback(self.on_params)
        self.pub = self.create_publisher(
            PathMsg, "/planning/scenario_planning/motion_velocity_smoother/trajectory", LATEST
        )
        self.create_subscription(
            PathMsg, "/planning/scenario_planning/lane_driving/behavior_planning/path", self.on_path, LATEST
        )

    def on_params(self, params) -> SetParametersResult:
        for p in params:
            if p.name == "max_velocity":
                if not 0.5 <= float(p.value) <= LANE_SPEED_LIMIT:
                    return SetParametersResult(successful=False, reason="max_velocity out of [0.5, 5.5]")
                self.get_logger().info(
                    f"max_velocity changed: {self.get_parameter('max_velocity').value:.1f} -> "
                    f"{float(p.value):.1f} m/s"
                )
        return SetParametersResult(successful=True)

    def on_path(self, msg: PathMsg) -> None:
        n = len(msg.poses)
        if n < 2:
            return
        vmax = float(self.get_parameter("max_velocity").value)
        alat = float(self.get_parameter("max_lateral_accel").value)
        dec = -float(self.get_parameter("normal.min_acc").value)
        xs = np.array([p.pose.position.x for p in msg.poses])
        ys = np.array([p.pose.position.y for p in msg.poses])
        yaw = np.array([yaw_of(p.pose.orientation) for p in msg.poses])
        v = np.minimum(np.array([p.pose.position.z for p in msg.poses]), vmax)
        ds = np.maximum(np.hypot(np.diff(xs), np.diff(ys)), 1e-3)
        dyaw = np.abs((np.diff(yaw) + math.pi) % (2 * math.pi) - math.pi)
        kappa = np.concatenate([dyaw / ds, [0.0]])
        v = np.minimum(v, np.sqrt(alat / np.maximum(kappa, 1e-6)))
        for i in range(n - 2, -1, -1):  # the deceleration limit, backwards from the stops
            v[i] = min(v[i], math.sqrt(v[i + 1] ** 2 + 2.0 * dec * ds[i]))
        out = PathMsg()
        out.header = msg.header
        for p, vi in zip(msg.poses, v, strict=True):
            p.pose.position.z = float(vi)
            out.poses.append(p)
        self.pub.publish(out)


class PlanningValidator(ShuttleNode):
    """Checks the smoothed trajectory (finite, speeds within the limits, no sharp jumps between
    points) and publishes it as ``/planning/scenario_planning/trajectory``; an invalid one is
    replaced by the previous one."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("planning_validator", "planning", fault_dir)
        self.declare_parameter("thresholds.velocity_deviation", 2.0)
        self.declare_parameter("thresholds.interval", 100.0)
        self.pub = self.create_publisher(PathMsg, "/planning/scenario_planning/trajectory", LATEST)
        self.create_subscription(
            PathMsg,
            "/planning/scenario_planning/motion_velocity_smoother/trajectory",
            self.on_trajectory,
            LATEST,
        )
        self.previous = None
        self.valid = self.invalid = 0
        self.create_timer(1.0, self.on_second)

    def on_trajectory(self, msg: PathMsg) -> None:
        ok = True
        last = None
        for p in msg.poses:
            q = p.pose.position
            if not (math.isfinite(q.x) and math.isfinite(q.z)) or q.z > LANE_SPEED_LIMIT + 0.1 or q.z < 0.0:
                ok = False
                break
            if last is not None and math.hypot(q.x - last[0], q.y - last[1]) > 5.0:
                ok = False
                break
            last = (q.x, q.y)
        if ok:
            self.valid += 1
            self.previous = msg
            self.pub.publish(msg)
        else:
            self.invalid += 1
            if self.throttle("invalid", 5.0):
                self.get_logger().warn("Invalid trajectory detected: publishing the previous one")
            if self.previous is not None:
                self.pub.publish(self.previous)

    def on_second(self) -> None:
        level = OK if not self.invalid else WARN
        self.publish_diagnostics(
            self.status(
                "trajectory_validation_status",
                "planning_validator",
                level,
                "OK" if not self.invalid else "invalid trajectories",
                valid=self.valid,
                invalid=self.invalid,
            )
        )
        self.valid = self.invalid = 0


# --- control ------------------------------------------------------------------------------------------


class TrajectoryFollower(ShuttleNode):
    """Pure-pursuit lateral and PID-like longitudinal control at 30 Hz on the latest trajectory and
    kinematic state; a smooth stop before the trajectory's first zero-speed point; stops (holds the
    brake) when the trajectory is more than 1 s old (at stations: normal)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("controller_node_exe", "control/trajectory_follower", fault_dir)
        self.declare_parameter("lateral_controller_mode", "pure_pursuit")
        self.declare_parameter("longitudinal_controller_mode", "pid")
        self.declare_parameter("ctrl_period", 1.0 / FOLLOWER_HZ)
        self.pub = self.create_publisher(TwistStamped, "/control/trajectory_follower/control_cmd", LATEST)
        self.create_subscription(Odometry, "/localization/kinematic_state", self.on_odom, LATEST)
        self.create_subscription(
            PathMsg, "/planning/scenario_planning/trajectory", self.on_trajectory, LATEST
        )
        self.traj = None
        self.traj_at = -1e9
        self.ego = None
        self.lat_err = 0.0
        self.create_timer(1.0 / FOLLOWER_HZ, self.control)
        self.create_timer(1.0, self.on_second)

    def on_odom(self, msg: Odometry) -> None:
        p = msg.pose.pose
        self.ego = (p.position.x, p.position.y, yaw_of(p.orientation), msg.twist.twist.linear.x)

    def on_trajectory(self, msg: PathMsg) -> None:
        if len(msg.poses) < 2:
            return
        self.traj = (
            np.array([p.pose.position.x for p in msg.poses]),
            np.array([p.pose.position.y for p in msg.poses]),
            np.array([p.pose.position.z for p in msg.poses]),
        )
        self.traj_at = time.monotonic()

    def control(self) -> None:
        v_cmd = wz = 0.0
        if self.ego is not None and self.traj is not None and time.monotonic() - self.traj_at < 1.0:
            x, y, yaw, v = self.ego
            xs, ys, vs = self.traj
            d = np.hypot(xs - x, ys - y)
            i = int(np.argmin(d))
            self.lat_err = float(d[i])
            v_ref = float(vs[i])
            zeros = np.nonzero(vs[i:] <= 0.01)[0]
            if len(zeros):
                d_stop = float(d[i + zeros[0]])
                v_ref = min(v_ref, math.sqrt(2.0 * 0.8 * max(0.0, d_stop - 0.5)))
            v_cmd = v_ref
            ld = max(4.0, 1.2 * max(v, 0.5))
            j = i + int(np.argmax(d[i:] >= ld)) if np.any(d[i:] >= ld) else len(xs) - 1
            alpha = math.atan2(ys[j] - y, xs[j] - x) - yaw
            alpha = (alpha + math.pi) % (2 * math.pi) - math.pi
            wz = 2.0 * max(v, 0.3) * math.sin(alpha) / max(ld, float(d[j]), 1.0)
        m = TwistStamped()
        m.header.stamp, m.header.frame_id = self.get_clock().now().to_msg(), "base_link"
        m.twist.linear.x, m.twist.angular.z = v_cmd, wz
        self.pub.publish(m)

    def on_second(self) -> None:
        if self.fault == "errlog":  # the steering sensor reports garbage: the estimate is used instead
            self.get_logger().error(
                "Steering angle 1.12 rad out of range (limit 0.70 rad): using the estimated steering angle"
            )
        self.publish_diagnostics(
            self.status(
                "control_state",
                "trajectory_follower",
                lateral_error=f"{self.lat_err:.2f}",
                trajectory_age=f"{min(99.0, time.monotonic() - self.traj_at):.2f}",
            )
        )


class VehicleCmdGate(ShuttleNode):
    """Selects the command for the vehicle: the remote operator's while their stream is fresh (they
    only publish while holding control), else the trajectory follower's in AUTONOMOUS (each passed
    on as it comes, 30 Hz), else a stop; during an MRM, a comfortable-stop ramp (the gate's own
    10 Hz output, as for the stop). Published best effort, keep last 1 (only the newest command
    matters to the CAN bridge)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("vehicle_cmd_gate", "control", fault_dir)
        self.declare_parameter("update_rate", GATE_HZ)
        self.declare_parameter("external_emergency_stop_heartbeat_timeout", 0.5)
        self.declare_parameter("mrm_decel", 1.0)
        self.pub = self.create_publisher(TwistStamped, "/control/command/control_cmd", COMMAND)
        self.mode_pub = self.create_publisher(String, "/control/current_gate_mode", LATCHED)
        self.create_subscription(
            TwistStamped, "/control/trajectory_follower/control_cmd", self.on_auto, LATEST
        )
        self.create_subscription(TwistStamped, "/external/selected/control_cmd", self.on_remote, LATEST)
        self.create_subscription(String, "/system/fail_safe/mrm_state", self.on_mrm, RELIABLE)
        self.create_subscription(String, "/api/operation_mode/state", self.on_mode, LATCHED)
        self.auto = self.remote = None
        self.auto_at = self.remote_at = -1e9
        self.mrm = "NORMAL"
        self.op_mode = "STOP"
        self.source = ""
        self.v_out = 0.0
        self.set_source("STOP")
        self.create_timer(0.1, self.tick)
        self.create_timer(1.0, self.on_second)

    def on_auto(self, msg: TwistStamped) -> None:
        self.auto, self.auto_at = msg, time.monotonic()
        if self.select() == "AUTO":
            self.send(msg.twist.linear.x, msg.twist.angular.z)

    def on_remote(self, msg: TwistStamped) -> None:
        self.remote, self.remote_at = msg, time.monotonic()
        if self.select() == "REMOTE":
            self.send(msg.twist.linear.x, msg.twist.angular.z)

    def on_mrm(self, msg: String) -> None:
        self.mrm = msg.data.split()[0]

    def on_mode(self, msg: String) -> None:
        self.op_mode = msg.data

    def set_source(self, source: str) -> None:
        if source != self.source:
            if self.source:
                self.get_logger().info(f"Gate mode: {self.source} -> {source}")
            self.source = source
            self.mode_pub.publish(String(data=source))

    def select(self) -> str:
        now = time.monotonic()
        if now - self.remote_at < 0.5:
            source = "REMOTE"
        elif self.mrm != "NORMAL" and self.op_mode == "AUTONOMOUS":
            source = "EMERGENCY"
        elif self.op_mode == "AUTONOMOUS" and now - self.auto_at < 0.5:
            source = "AUTO"
        else:
            source = "STOP"
        self.set_source(source)
        return source

    def tick(self) -> None:
        """The gate's own output while no source drives it (10 Hz): a stop, or the MRM's ramp."""
        source = self.select()
        if source == "EMERGENCY":
            self.send(max(0.0, self.v_out - 0.1), 0.0)  # 1.0 m/s2
        elif source == "STOP":
            self.send(0.0, 0.0)

    def send(self, v: float, wz: float) -> None:
        self.v_out = v
        m = TwistStamped()
        m.header.stamp, m.header.frame_id = self.get_clock().now().to_msg(), "base_link"
        m.twist.linear.x, m.twist.angular.z = v, wz
        self.pub.publish(m)

    def on_second(self) -> None:
        self.publish_diagnostics(
            self.status(
                "gate_status",
                "vehicle_cmd_gate",
                source=self.source,
                mrm=self.mrm,
                operation_mode=self.op_mode,
            )
        )


# --- vehicle ------------------------------------------------------------------------------------------


class VehicleInterface(ShuttleNode):
    """The CAN bridge: its CAN thread reads the vehicle's status at 50 Hz (the velocity report,
    best effort consumers welcome) and writes the latest command; no command for 1.0 s: it brakes
    to a standstill (an ERROR, the brake held until commands come back). The vehicle itself is
    simulated in the CAN thread (speed and yaw-rate tracking with acceleration limits)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("vehicle_interface", "vehicle", fault_dir)
        self.declare_parameter("can_interface", "can0")
        self.declare_parameter("command_timeout", 1.0)
        self.declare_parameter("wheel_base", 2.7)
        self.vel_pub = self.create_publisher(
            TwistWithCovarianceStamped, "/vehicle/status/velocity_status", RELIABLE
        )
        self.mode_pub = self.create_publisher(String, "/vehicle/status/control_mode", RELIABLE)
        self.battery_pub = self.create_publisher(BatteryState, "/vehicle/status/battery", RELIABLE)
        self.cmd_sub = self.create_subscription(
            TwistStamped, "/control/command/control_cmd", self.on_cmd, COMMAND
        )
        self.lock = threading.Lock()
        self.cmd = (0.0, 0.0)
        self.cmd_at = None
        self.timed_out = False
        self.v = self.wz = 0.0
        self.soc = 87.0
        self.msg = TwistWithCovarianceStamped()
        self.msg.header.frame_id = "base_link"
        self.get_logger().info("CAN bridge up on can0 (500 kbit/s): vehicle ECU firmware 3.4.1")
        self.create_timer(1.0, self.on_second)
        threading.Thread(target=self.can, daemon=True, name="can").start()

    def on_fault(self, fault: str | None) -> None:
        if fault == "reliable":  # a reloaded interface config asks for a reliable command subscription
            self.get_logger().info(
                "Parameters reloaded from vehicle_interface.param.yaml: re-creating the command subscription"
            )
            self.destroy_subscription(self.cmd_sub)
            self.cmd_sub = self.create_subscription(
                TwistStamped,
                "/control/command/control_cmd",
                self.on_cmd,
                QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE),
            )

    def on_cmd(self, msg: TwistStamped) -> None:
        with self.lock:
            self.cmd = (msg.twist.linear.x, msg.twist.angular.z)
            self.cmd_at = time.monotonic()

    def can(self) -> None:
        dt = 1.0 / VEHICLE_HZ
        for _ in paced(VEHICLE_HZ):
            now = time.monotonic()
            with self.lock:
                cmd, at = self.cmd, self.cmd_at
            if at is not None and now - at > 1.0:
                if not self.timed_out:
                    self.timed_out = True
                    self.get_logger().error(
                        f"Control command timeout ({now - at:.2f} s): braking to a standstill"
                    )
                cmd = (0.0, 0.0)
            elif at is not None and self.timed_out:
                self.timed_out = False
                self.get_logger().info("Control commands back: brake released")
            target_v, target_wz = cmd
            acc = max(-2.5, min(1.0, (target_v - self.v) / dt))
            self.v = max(0.0, self.v + acc * dt)
            lim = self.v * math.tan(0.6) / 2.7 + 0.05
            self.wz = max(-lim, min(lim, target_wz)) if self.v > 0.01 else 0.0
            m = self.msg
            m.header.stamp = self.get_clock().now().to_msg()
            m.twist.twist.linear.x = self.v + random.gauss(0.0, 0.005) * (self.v > 0)
            m.twist.twist.angular.z = self.wz
            if not published((self.vel_pub, m)):
                return

    def on_second(self) -> None:
        self.soc -= 0.004 + 0.002 * self.v
        self.mode_pub.publish(String(data="AUTONOMOUS" if self.cmd_at is not None else "MANUAL"))
        b = BatteryState(
            voltage=48.0 + 6.0 * self.soc / 100.0,
            percentage=self.soc / 100.0,
            present=True,
            current=-8.0 - 12.0 * self.v,
        )
        b.header.stamp = self.get_clock().now().to_msg()
        self.battery_pub.publish(b)
        level, text = (ERROR, "control command timeout") if self.timed_out else (OK, "OK")
        self.publish_diagnostics(
            self.status("can_status", "can0", level, text, speed=f"{self.v:.2f}", soc=f"{self.soc:.1f}")
        )


# --- system -------------------------------------------------------------------------------------------


class TopicStateMonitor(ShuttleNode):
    """Watches the topics each component must keep publishing (Autoware's topic_state_monitor, one
    node for all): its statuses on /diagnostics at 1 Hz, ERROR on a timeout. The trajectory only
    while a route is set (3 s of grace after it is)."""

    TOPICS: ClassVar[list[tuple[str, str, type, str, float]]] = [  # short, component, type, topic, timeout
        ("pointcloud", "sensing", PointCloud2, "/sensing/lidar/top/pointcloud", 1.0),
        (
            "ndt_pose",
            "localization",
            PoseWithCovarianceStamped,
            "/localization/pose_estimator/pose_with_covariance",
            2.0,
        ),
        ("objects", "perception", PoseArray, "/perception/object_recognition/objects", 1.0),
        ("trajectory", "planning", PathMsg, "/planning/scenario_planning/trajectory", 1.0),
    ]

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("topic_state_monitor", "system", fault_dir)
        self.declare_parameter("update_rate", 1.0)
        self.last: dict[str, float | None] = {}
        self.count: dict[str, int] = {}
        for short, _, typ, topic, _ in self.TOPICS:
            self.last[short] = None
            self.count[short] = 0
            self.create_subscription(typ, topic, lambda _m, s=short: self.on_msg(s), SENSOR, raw=True)
        self.create_subscription(String, "/api/routing/state", self.on_routing, LATCHED)
        self.routing = "UNSET"
        self.routing_at = time.monotonic()
        self.create_timer(1.0, self.on_second)

    def on_msg(self, short: str) -> None:
        self.last[short] = time.monotonic()
        self.count[short] += 1

    def on_routing(self, msg: String) -> None:
        self.routing, self.routing_at = msg.data, time.monotonic()

    def on_second(self) -> None:
        now = time.monotonic()
        out = []
        for short, component, _, topic, timeout in self.TOPICS:
            name = f"topic_state_monitor_{short}: {component}_topic_status"
            hz = self.count[short]
            self.count[short] = 0
            last = self.last[short]
            kv = [KeyValue(key="topic", value=topic), KeyValue(key="measured_rate", value=str(hz))]
            if short == "trajectory" and (self.routing != "SET" or now - self.routing_at < 3.0):
                level, msg = OK, "not monitored (no route)"
            elif last is None:
                level, msg = WARN, "not received"
            elif now - last > timeout:
                level, msg = ERROR, f"timeout ({now - last:.1f} s)"
            else:
                level, msg = OK, "OK"
            out.append(
                DiagnosticStatus(
                    level=level, name=name, message=msg, hardware_id="topic_state_monitor", values=kv
                )
            )
        self.publish_diagnostics(*out)


class ComponentStateMonitor(ShuttleNode):
    """Each component's readiness for autonomous driving from the aggregated diagnostics of its
    topic monitors: ``/system/component_state_monitor/component/autonomous/<component>`` at 1 Hz."""

    COMPONENTS = ("sensing", "localization", "perception", "planning")

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("component_state_monitor", "system", fault_dir)
        self.pubs = {
            c: self.create_publisher(
                Bool, f"/system/component_state_monitor/component/autonomous/{c}", RELIABLE
            )
            for c in self.COMPONENTS
        }
        self.create_subscription(DiagnosticArray, "/diagnostics_agg", self.on_agg, RELIABLE)
        self.ready = dict.fromkeys(self.COMPONENTS, False)

    def on_agg(self, msg: DiagnosticArray) -> None:
        levels: dict[str, int] = {}
        for st in msg.status:
            if "topic_state_monitor_" not in st.name:
                continue
            component = st.name.rsplit(": ", 1)[-1].removesuffix("_topic_status")
            lv = st.level[0] if isinstance(st.level, bytes) else st.level
            levels[component] = max(levels.get(component, 0), lv)
        for c in self.COMPONENTS:
            ready = c in levels and levels[c] < ERROR[0]
            if ready != self.ready[c]:
                self.ready[c] = ready
                if ready:
                    self.get_logger().info(f"Component {c}: ready")
                else:
                    self.get_logger().warn(f"Component {c}: not ready")
            self.pubs[c].publish(Bool(data=ready))


class EmergencyHandler(ShuttleNode):
    """The MRM: in AUTONOMOUS, a component not ready starts a comfortable stop (MRM_OPERATING, an
    ERROR), MRM_SUCCEEDED 6 s later; NORMAL again once every component has been ready for 3 s.
    ``/system/fail_safe/mrm_state`` at 5 Hz."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("emergency_handler", "system", fault_dir)
        self.declare_parameter("update_rate", 5.0)
        self.declare_parameter("timeout_hazard_status", 0.5)
        self.pub = self.create_publisher(String, "/system/fail_safe/mrm_state", RELIABLE)
        self.ready: dict[str, tuple[bool, float]] = {}
        for c in ComponentStateMonitor.COMPONENTS:
            self.create_subscription(
                Bool,
                f"/system/component_state_monitor/component/autonomous/{c}",
                lambda m, c=c: self.on_component(c, m),
                RELIABLE,
            )
        self.create_subscription(String, "/api/operation_mode/state", self.on_mode, LATCHED)
        self.op_mode = "STOP"
        self.state = "NORMAL"
        self.since = time.monotonic()
        self.good_since = time.monotonic()
        self.create_timer(0.2, self.tick)

    def on_component(self, c: str, msg: Bool) -> None:
        self.ready[c] = (msg.data, time.monotonic())

    def on_mode(self, msg: String) -> None:
        self.op_mode = msg.data

    def tick(self) -> None:
        now = time.monotonic()
        bad = sorted(c for c, (ok, at) in self.ready.items() if not ok or now - at > 3.0)
        if bad:
            self.good_since = now
        if self.state == "NORMAL" and bad and self.op_mode == "AUTONOMOUS":
            self.state, self.since = "MRM_OPERATING", now
            self.get_logger().error(f"Emergency: {', '.join(bad)} not ready: starting MRM (comfortable stop)")
        elif self.state == "MRM_OPERATING" and now - self.since > 6.0:
            self.state = "MRM_SUCCEEDED"
            self.get_logger().warn("MRM succeeded: the vehicle is stopped")
        elif self.state != "NORMAL" and not bad and now - self.good_since > 3.0:
            self.state = "NORMAL"
            self.get_logger().info("Recovered from the emergency: MRM released")
        behavior = "comfortable_stop" if self.state != "NORMAL" else "none"
        self.pub.publish(String(data=f"{self.state} behavior={behavior}"))


class SystemMonitor(ShuttleNode):
    """The ECU's CPU, memory and temperature (diagnostic_updater style)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("system_monitor", "system", fault_dir)
        import psutil

        self.psutil = psutil
        self.host = socket.gethostname()
        psutil.cpu_percent()
        self.create_timer(1.0, self.on_second)

    def on_second(self) -> None:
        cpu, mem = self.psutil.cpu_percent(), self.psutil.virtual_memory()
        self.publish_diagnostics(
            self.status(
                "CPU Usage",
                self.host,
                OK if cpu < 90 else WARN,
                "OK" if cpu < 90 else "high load",
                usage=f"{cpu:.1f}%",
            ),
            self.status("Memory Usage", self.host, used=f"{mem.percent:.1f}%"),
            self.status("CPU Temperature", self.host, celsius=f"{48 + cpu * 0.25:.1f}"),
        )


class DiagnosticAggregator(ShuttleNode):
    """/diagnostics grouped by analyzer into /diagnostics_agg at 1 Hz (STALE after 5 s)."""

    GROUPS: ClassVar[dict[str, str]] = {
        "lidar_driver": "/autoware/sensing/lidar",
        "camera_driver": "/autoware/sensing/camera",
        "imu_driver": "/autoware/sensing/imu",
        "gnss_driver": "/autoware/sensing/gnss",
        "ndt_scan_matcher": "/autoware/localization",
        "ekf_localizer": "/autoware/localization",
        "planning_validator": "/autoware/planning",
        "controller_node_exe": "/autoware/control",
        "vehicle_cmd_gate": "/autoware/control",
        "vehicle_interface": "/autoware/vehicle",
        "system_monitor": "/autoware/system/resource",
    }

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("diagnostic_aggregator", "system", fault_dir)
        self.declare_parameter("pub_rate", 1.0)
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
            head = name.split(":")[0]
            group = (
                "/autoware/system/topic_state_monitor"
                if head.startswith("topic_state_monitor")
                else self.GROUPS.get(head, "/autoware/other")
            )
            level = STALE if now - t > 5.0 else st.level
            lv = level[0] if isinstance(level, bytes) else level
            out.append(
                DiagnosticStatus(
                    level=level,
                    name=f"{group}/{name}",
                    message="Stale" if lv == STALE[0] else st.message,
                    hardware_id=st.hardware_id,
                    values=st.values,
                )
            )
            groups[group] = max(groups.get(group, 0), lv)
        for group, lv in sorted(groups.items()):
            out.insert(
                0,
                DiagnosticStatus(
                    level=bytes([lv]), name=group, message={0: "OK", 1: "Warning", 2: "Error", 3: "Stale"}[lv]
                ),
            )
        arr = DiagnosticArray(status=out)
        arr.header.stamp = self.get_clock().now().to_msg()
        self.agg_pub.publish(arr)
        top = max(groups.values(), default=0)
        self.top_pub.publish(
            DiagnosticStatus(
                level=bytes([top]),
                name="toplevel_state",
                message={0: "OK", 1: "Warning", 2: "Error", 3: "Stale"}[top],
            )
        )


class BagRecorder(Node):
    """``ros2 bag record`` of the operations topics (serialized, as it does): it subscribes to each
    topic of its list once a publisher shows up, writes the messages to the bag and splits it
    every 60 s (two splits kept on this bench)."""

    TOPICS: ClassVar[dict[str, tuple[type, QoSProfile]]] = {
        "/planning/mission_planning/route": (PathMsg, LATCHED),
        "/planning/mission_planning/state": (String, LATCHED),
        "/planning/scenario_planning/trajectory": (PathMsg, SENSOR),
        "/perception/traffic_light_recognition/traffic_signals": (String, SENSOR),
        "/system/fail_safe/mrm_state": (String, SENSOR),
        "/control/current_gate_mode": (String, LATCHED),
        "/api/routing/state": (String, LATCHED),
        "/api/operation_mode/state": (String, LATCHED),
        "/api/routing/eta": (Float32, SENSOR),
        "/vehicle/status/control_mode": (String, SENSOR),
        "/vehicle/status/battery": (BatteryState, SENSOR),
        "/diagnostics_agg": (DiagnosticArray, SENSOR),
        "/rosout": (
            Log,
            QoSProfile(
                depth=100, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
            ),
        ),
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
        self.get_logger().info("Press SPACE for pausing/resuming")
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
        head = f"{topic} {time.time_ns()} {len(data)}\n".encode()
        self.file.write(head)
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


# --- the AD API ---------------------------------------------------------------------------------------


class AdApiLocalization(ShuttleNode):
    """Calls ``/localization/initialize`` once at startup (retrying every 2 s until it is accepted)
    and follows the initialization state until INITIALIZED."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("localization", "default_ad_api/node", fault_dir)
        self.client = self.create_client(Trigger, "/localization/initialize")
        self.pending = None
        self.done = self.started = False
        self.create_subscription(String, "/localization/initialization_state", self.on_state, LATCHED)
        self.timer = self.create_timer(2.0, self.try_initialize)

    def on_state(self, msg: String) -> None:
        if msg.data == "INITIALIZED" and not self.done:
            self.done = True
            self.timer.cancel()
            self.get_logger().info("Localization initialized")
        elif msg.data == "UNINITIALIZED" and self.started:
            self.started = False
            self.get_logger().warn("Localization initialization failed: retrying")

    def try_initialize(self) -> None:
        if self.pending is not None and self.pending.done():
            r, self.pending = self.pending.result(), None
            if r is not None and r.success:
                self.started = True
            else:
                self.get_logger().warn(
                    f"Localization initialization refused: {r.message if r else 'no answer'}; retrying"
                )
        if self.done or self.started or self.pending is not None or not self.client.service_is_ready():
            return
        self.get_logger().info("Requesting localization initialization (GNSS + NDT)")
        self.pending = self.client.call_async(Trigger.Request())


class AdApiRouting(ShuttleNode):
    """The shuttle's timetable on the AD API: once localization is initialized, the route to the next
    station (``set_route_points``); at each arrival a 10-20 s dwell, then the next station. While a
    route is set, the ETA for the passenger display every 10 s (``plan_route``: the remaining
    route). Calls time out after 3 s (an ERROR). Publishes the routing state and engages
    AUTONOMOUS with the first route."""

    TIMEOUT = 3.0

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("routing", "default_ad_api/node", fault_dir)
        self.declare_parameter("dwell_min", 10.0)
        self.declare_parameter("dwell_max", 20.0)
        self.set_route = self.create_client(GetPlan, "/planning/mission_planning/set_route_points")
        self.plan_route = self.create_client(GetPlan, "/planning/mission_planning/plan_route")
        self.state_pub = self.create_publisher(String, "/api/routing/state", LATCHED)
        self.mode_pub = self.create_publisher(String, "/api/operation_mode/state", LATCHED)
        self.eta_pub = self.create_publisher(Float32, "/api/routing/eta", RELIABLE)
        self.create_subscription(String, "/localization/initialization_state", self.on_init, LATCHED)
        self.create_subscription(String, "/planning/mission_planning/state", self.on_planner_state, LATCHED)
        self.initialized = False
        self.state = "UNSET"
        self.next_stop = 0
        self.depart_at = None
        self.pending: list[tuple[str, float, object]] = []
        self.retries = 0
        self.unanswered = False  # a route request timed out: the planner may still set it
        self.eta_at = time.monotonic() + 10.0
        self.engaged = False
        self.publish_state("UNSET")
        self.mode_pub.publish(String(data="STOP"))
        self.create_timer(0.5, self.tick)

    def publish_state(self, state: str) -> None:
        self.state = state
        self.state_pub.publish(String(data=state))

    def on_init(self, msg: String) -> None:
        if msg.data == "INITIALIZED" and not self.initialized:
            self.initialized = True
            self.depart_at = time.monotonic() + 3.0

    def on_planner_state(self, msg: String) -> None:
        if msg.data == "SET" and self.unanswered and self.state != "SET":
            self.unanswered = False
            self.retries = 0
            self.depart_at = None
            self.next_stop += 1
            self.publish_state("SET")
            self.get_logger().warn("The mission planner set the route after all (its answer came too late)")
        elif msg.data == "ARRIVED" and self.state == "SET":
            station = TIMETABLE[(self.next_stop - 1) % len(TIMETABLE)]
            dwell = random.uniform(
                self.get_parameter("dwell_min").value, self.get_parameter("dwell_max").value
            )
            self.get_logger().info(f"Arrived at {station}: departing in {dwell:.0f} s")
            self.publish_state("ARRIVED")
            self.depart_at = time.monotonic() + dwell

    def goal(self) -> GetPlan.Request:
        station = TIMETABLE[self.next_stop % len(TIMETABLE)]
        i = STATIONS[station]
        req = GetPlan.Request(tolerance=0.5)
        req.goal.header.frame_id = "map"
        req.goal.pose.position.x, req.goal.pose.position.y = float(TRACK_X[i]), float(TRACK_Y[i])
        set_yaw(req.goal.pose.orientation, float(TRACK_YAW[i]))
        return req

    def tick(self) -> None:
        now = time.monotonic()
        for item in list(self.pending):
            kind, sent, fut = item
            if fut.done():
                self.pending.remove(item)
                self.on_answer(kind, fut.result())
            elif now - sent > self.TIMEOUT:
                self.pending.remove(item)
                client = self.set_route if kind == "set" else self.plan_route
                client.remove_pending_request(fut)
                self.get_logger().error(f"Timed out waiting for {client.srv_name} ({self.TIMEOUT:.1f} s)")
                if kind == "set":
                    self.unanswered = True
                    self.retries += 1
                    if self.retries < 3:
                        self.depart_at = now + 2.0
                    else:
                        self.get_logger().error("Failed to set the route after 3 attempts: retrying in 30 s")
                        self.retries = 0
                        self.depart_at = now + 30.0
        if self.depart_at is not None and now >= self.depart_at and self.set_route.service_is_ready():
            self.depart_at = None
            station = TIMETABLE[self.next_stop % len(TIMETABLE)]
            self.get_logger().info(f"Departing for {station}: requesting the route")
            self.pending.append(("set", now, self.set_route.call_async(self.goal())))
        if self.state == "SET" and now >= self.eta_at and self.plan_route.service_is_ready():
            self.eta_at = now + 10.0
            if not any(k == "eta" for k, _, _ in self.pending):
                self.pending.append(("eta", now, self.plan_route.call_async(self.goal())))

    def on_answer(self, kind: str, result) -> None:
        if kind == "set":
            if result is None or not result.plan.poses:
                self.get_logger().error("The route was rejected by the mission planner")
                self.depart_at = time.monotonic() + 5.0
                return
            self.retries = 0
            self.unanswered = False
            self.next_stop += 1
            self.publish_state("SET")
            self.eta_at = time.monotonic() + 10.0
            if not self.engaged:
                self.engaged = True
                self.mode_pub.publish(String(data="AUTONOMOUS"))
                self.get_logger().info("Operation mode: AUTONOMOUS")
        elif result is not None and result.plan.poses:
            self.eta_pub.publish(Float32(data=len(result.plan.poses) / 4.0))


# --- the remote operator's console --------------------------------------------------------------------


class OperatorConsole(ShuttleNode):
    """The remote monitoring console: watches the diagnostics, the MRM and routing states; 6 s after
    it connects the operator sets the shuttle's maximum speed (the smoother's ``max_velocity``
    through its parameter service); at each station arrival it takes remote control for 5 s (a
    door check, zero commands at 10 Hz on ``/external/selected/control_cmd``) and releases it."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("operator_console", "remote", fault_dir)
        self.params = self.create_client(
            SetParameters, "/planning/scenario_planning/motion_velocity_smoother/set_parameters"
        )
        self.cmd_pub = self.create_publisher(TwistStamped, "/external/selected/control_cmd", LATEST)
        self.create_subscription(DiagnosticArray, "/diagnostics_agg", self.on_diag, RELIABLE)
        self.create_subscription(String, "/system/fail_safe/mrm_state", self.on_mrm, RELIABLE)
        self.create_subscription(String, "/api/routing/state", self.on_routing, LATCHED)
        self.speed_at = time.monotonic() + 6.0
        self.hold_from = self.hold_until = None
        self.holding = False
        self.routing = None
        self.mrm = "NORMAL"
        self.level = 0
        self.get_logger().info("Remote monitoring console connected")
        self.create_timer(0.1, self.tick)

    def on_diag(self, msg: DiagnosticArray) -> None:
        self.level = max(
            (s.level[0] if isinstance(s.level, bytes) else s.level for s in msg.status), default=0
        )

    def on_mrm(self, msg: String) -> None:
        state = msg.data.split()[0]
        if state != self.mrm:
            if state != "NORMAL":
                self.get_logger().warn(f"The shuttle reports {state}")
            self.mrm = state

    def on_routing(self, msg: String) -> None:
        if msg.data == "ARRIVED" and self.routing == "SET":  # an arrival seen live (not the latched state)
            self.hold_from = time.monotonic() + 2.0
            self.hold_until = self.hold_from + 5.0
        self.routing = msg.data

    def tick(self) -> None:
        now = time.monotonic()
        if self.speed_at is not None and now >= self.speed_at and self.params.service_is_ready():
            self.speed_at = None
            speed = random.choice((4.0, 4.2, 5.0))
            self.get_logger().info(f"Setting the maximum speed to {speed:.1f} m/s")
            req = SetParameters.Request(
                parameters=[Parameter("max_velocity", value=speed).to_parameter_msg()]
            )
            self.params.call_async(req)
        if self.hold_from is None or now < self.hold_from:
            return
        if now < self.hold_until:
            if not self.holding:
                self.holding = True
                self.get_logger().info("Remote control: holding the shuttle for the door check")
            m = TwistStamped()
            m.header.stamp, m.header.frame_id = self.get_clock().now().to_msg(), "base_link"
            self.cmd_pub.publish(m)
        else:
            self.hold_from = self.hold_until = None
            self.holding = False
            self.get_logger().info("Remote control released")


# --- processes ----------------------------------------------------------------------------------------


PROCESSES = {  # process -> its nodes
    "vehicle": lambda d: [VehicleInterface(d)],
    "imu": lambda d: [ImuDriver(d)],
    "gnss": lambda d: [GnssDriver(d), GnssPoser(d)],
    "lidar": lambda d: [LidarDriver(d)],
    "camera": lambda d: [CameraDriver(d)],
    "pointcloud_container": lambda d: [CropBoxFilter(d), GroundFilter(d), VoxelDownsampleFilter(d)],
    "ndt": lambda d: [NdtScanMatcher(d)],
    "localization": lambda d: [EkfLocalizer(d), PoseInitializer(d)],
    "detector": lambda d: [YoloxDetector(d)],
    "perception": lambda d: [EuclideanCluster(d), MultiObjectTracker(d)],
    "traffic_light": lambda d: [TrafficLightClassifier(d)],
    "mission_planning": lambda d: [MissionPlanner(d)],
    "planning": lambda d: [BehaviorPathPlanner(d), MotionVelocitySmoother(d), PlanningValidator(d)],
    "control": lambda d: [TrajectoryFollower(d), VehicleCmdGate(d)],
    "system": lambda d: [
        TopicStateMonitor(d),
        ComponentStateMonitor(d),
        EmergencyHandler(d),
        DiagnosticAggregator(d),
        SystemMonitor(d),
    ],
    "recorder": lambda d: [BagRecorder(d)],
    "ad_api": lambda d: [AdApiLocalization(d), AdApiRouting(d)],
    "operator": lambda d: [OperatorConsole(d)],
}


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
        ex = EventsExecutor()  # the C++ events executor: a fraction of the dispatch CPU of rclpy's own
        for n in nodes:
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
