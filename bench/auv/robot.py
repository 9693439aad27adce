"""An AUV's companion-computer stack, plain rclpy: ``python -m bench.auv.robot PROCESS FAULT_DIR [RUN_FOR]``.

Written the way a survey AUV's ROS 2 stack is laid out (see `bench.auv.run` for the whole robot, its
healthy dynamics and its faults): ``/sensors`` drivers (AHRS, DVL, pressure, GPS, USBL); ``/payload``
(a lifecycle multibeam driver, a downward camera switched on below 9 m altitude, a payload container
of three processing nodes on one single-threaded executor); ``/nav`` (the navigation EKF, the
navsat transform); ``/control`` (depth/heading/speed controller, thruster allocator, the ESC
bridge with its watchdog); ``/mission`` (the mission executive, a state machine running behaviours
through actions, the behaviour server, the survey planner); ``/auv`` (battery monitor, leak detector,
diagnostics aggregator); ``/comms`` (acoustic modem, tether telemetry bridge); a rosbag recorder; the
topside operator's console that comes and goes; and the HIL bench's vehicle simulator (``/sim``),
whose ground truth the drivers sample as they would sample their hardware.

Message types are the stock ones: setpoints are geometry_msgs/PoseStamped (``position.z`` the
target depth, negative down; ``header.frame_id`` the mode: ``waypoint``, ``hold``, ``surface``);
thruster commands and states sensor_msgs/JointState (``velocity`` in rpm, ``effort`` the ESC current);
an invalid DVL velocity has ``covariance[0] = -1`` (the DVL's ``velocity_valid`` false), an invalid
altitude ``range = inf``; mission behaviours are test_msgs/action/Fibonacci goals (``order`` the
target depth of a dive or the survey line's index; the feedback's ``sequence`` the percent done);
the survey planner answers nav_msgs/GetPlan.

Faults come from files: ``FAULT_DIR/<namespace>.<node>`` (``nav.ekf_filter``) holding a word the
target node acts on (``hang``, ``degrade``, ``slow``, ``stale``, ``reliable``, ``errlog``, ``bias``),
read by the process's watcher thread every 0.5 s; ``FAULT_DIR/<process>.cpu`` starts a thread
burning a core in that process, ``<process>.leak`` one leaking 2.5 MB/s. Crashes are SIGKILLs from
outside. RUN_FOR > 0 ends the process cleanly (exit 0) after that many seconds.
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
from geometry_msgs.msg import (
    PoseStamped,
    PoseWithCovarianceStamped,
    TwistWithCovarianceStamped,
    WrenchStamped,
)
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState
from nav_msgs.msg import Odometry
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
from sensor_msgs.msg import (
    BatteryState,
    FluidPressure,
    Image,
    Imu,
    JointState,
    NavSatFix,
    NavSatStatus,
    PointCloud2,
    PointField,
    Range,
)
from std_msgs.msg import Bool, Float32, String
from std_srvs.srv import Trigger
from test_msgs.action import Fibonacci

from stream_viz.demo.child import burn, leak

LEAK_MB_S = 2.5  # the telemetry bridge's outbound queue never drained

OK, WARN, ERROR, STALE = (
    DiagnosticStatus.OK,
    DiagnosticStatus.WARN,
    DiagnosticStatus.ERROR,
    DiagnosticStatus.STALE,
)
SENSOR = qos_profile_sensor_data  # best effort, keep last 5
RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
COMMAND = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE)  # only the newest command matters
LATCHED = QoSProfile(
    depth=1, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL
)

# rates (Hz)
SIM_HZ, AHRS_HZ, DVL_HZ, DEPTH_HZ, GPS_HZ, CONTROL_HZ, ESC_HZ = 20.0, 50.0, 8.0, 20.0, 5.0, 20.0, 20.0
CAMERA_HZ, CAMERA_ALTITUDE = 4.0, 9.0
RHO_G, P_ATM = 1025.0 * 9.81, 101325.0
LAT0, LON0 = 36.7983, -121.8470  # the survey area's datum (Monterey Bay)
THRUSTERS = ("port", "starboard", "vertical_fwd", "vertical_aft")
K_THRUST = 2.0e-5  # N / rpm^2
MAX_RPM = 2200.0


# --- the world: the seafloor under the survey box ------------------------------------------------------


def seafloor(x: float, y: float) -> float:
    """Water depth (m) at x, y: a sloping sandy bottom, a rocky ridge at x ~ 25 m (steep)."""
    d = 30.0 + 0.04 * y + 3.0 * math.sin(x / 23.0) + 2.0 * math.cos(y / 17.0)
    return d - 9.0 * math.exp(-(((x - 25.0) / 6.0) ** 2))


def slope(x: float, y: float) -> float:
    e = 0.5
    return math.hypot(seafloor(x + e, y) - seafloor(x - e, y), seafloor(x, y + e) - seafloor(x, y - e)) / (
        2 * e
    )


HOME = (0.0, -15.0)  # the launch point, 15 m south of the survey box
SURVEY_LINES = [
    ((-10.0, 10.0 * i), (50.0, 10.0 * i)) if i % 2 == 0 else ((50.0, 10.0 * i), (-10.0, 10.0 * i))
    for i in range(12)
]  # 60 m lawnmower lines 10 m apart, boustrophedon
LINES_PER_BLOCK = 3  # then surface for a GPS fix
SURVEY_ALTITUDE = 10.0


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


def wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def clamp(v: float, lo: float, hi: float) -> float:
    return max(lo, min(hi, v))


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


def paced(hz):
    """A driver thread's loop: yields at ``hz`` (a number or a callable giving it) while rclpy is up."""
    nxt = time.monotonic()
    while alive():
        nxt += 1.0 / (hz() if callable(hz) else hz)
        delay = nxt - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        elif delay < -0.5:
            nxt = time.monotonic()
        yield


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
    m.header = header
    m.data = pts.tobytes()
    return m


def points(msg: PointCloud2) -> np.ndarray:
    return np.frombuffer(msg.data, dtype=np.float32).reshape(-1, 4)


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


class AuvNode(Diagnosed, Node):
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


class Truth:
    """A driver's view of the HIL bench: the simulator's latest ground truth (what the hardware would
    measure), from /sim/ground_truth."""

    def __init__(self, node: Node) -> None:
        self.x = self.y = self.depth = self.yaw = self.u = self.w = self.r = 0.0
        self.x, self.y = HOME
        self.yaw = math.pi / 2
        self.at = None
        node.create_subscription(Odometry, "/sim/ground_truth", self.on_truth, SENSOR)

    def on_truth(self, m: Odometry) -> None:
        p = m.pose.pose
        self.x, self.y, self.depth, self.yaw = (
            p.position.x,
            p.position.y,
            -p.position.z,
            yaw_of(p.orientation),
        )
        self.u, self.w, self.r = m.twist.twist.linear.x, -m.twist.twist.linear.z, m.twist.twist.angular.z
        self.at = time.monotonic()

    @property
    def altitude(self) -> float:
        return seafloor(self.x, self.y) - self.depth


# --- the HIL bench's vehicle model --------------------------------------------------------------------


class VehicleSimulator(AuvNode):
    """The HIL bench's 4-DOF vehicle model (surge, heave, yaw; a 0.05 m/s tidal current to the east):
    thrust from the ESCs' reported rpm (zero when the ESC bridge is silent for 0.5 s), the vehicle
    slightly positively buoyant; publishes /sim/ground_truth at 20 Hz from its physics thread."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("vehicle_simulator", "sim", fault_dir)
        self.declare_parameter("buoyancy_n", 2.0)
        self.pub = self.create_publisher(Odometry, "/sim/ground_truth", SENSOR)
        self.create_subscription(JointState, "/control/thrusters/state", self.on_esc, SENSOR)
        self.rpm = [0.0] * 4
        self.rpm_at = None
        self.x, self.y = HOME
        self.depth, self.yaw, self.u, self.w, self.r = 0.0, math.pi / 2, 0.0, 0.0, 0.0
        self.get_logger().info("HIL vehicle model up: 4-DOF, buoyancy +2.0 N, current 0.05 m/s east")
        threading.Thread(target=self.physics, daemon=True, name="physics").start()

    def on_esc(self, msg: JointState) -> None:
        self.rpm = list(msg.velocity)[:4]
        self.rpm_at = time.monotonic()

    def physics(self) -> None:
        dt = 1.0 / SIM_HZ
        m = Odometry()
        m.header.frame_id, m.child_frame_id = "world", "base_link"
        for _ in paced(SIM_HZ):
            rpm = self.rpm if self.rpm_at is not None and time.monotonic() - self.rpm_at < 0.5 else [0.0] * 4
            f = [K_THRUST * r * abs(r) for r in rpm]
            fx, mz, fz = f[0] + f[1], (f[0] - f[1]) * 0.3, f[2] + f[3]
            self.u += dt * (fx - 25.0 * self.u * abs(self.u)) / 60.0
            self.r += dt * (mz - 8.0 * self.r * abs(self.r) - 2.0 * self.r) / 10.0
            self.w += dt * (fz - 2.0 - 40.0 * self.w * abs(self.w) - 4.0 * self.w) / 70.0
            self.yaw = wrap(self.yaw + self.r * dt)
            self.x += dt * (self.u * math.cos(self.yaw) + 0.05)
            self.y += dt * self.u * math.sin(self.yaw)
            self.depth += self.w * dt
            if self.depth < 0.0:
                self.depth, self.w = 0.0, max(self.w, 0.0)
            floor = seafloor(self.x, self.y) - 0.5
            if self.depth > floor:
                self.depth, self.w = floor, min(self.w, 0.0)
            m.header.stamp = self.get_clock().now().to_msg()
            p = m.pose.pose
            p.position.x, p.position.y, p.position.z = self.x, self.y, -self.depth
            set_yaw(p.orientation, self.yaw)
            m.twist.twist.linear.x, m.twist.twist.linear.z, m.twist.twist.angular.z = self.u, -self.w, self.r
            if not published((self.pub, m)):
                return


# --- sensors ------------------------------------------------------------------------------------------


class AhrsDriver(AuvNode):
    """The AHRS (a MEMS IMU with a magnetometer-aided heading) on its serial port: 50 Hz, sensor QoS."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("ahrs_driver", "sensors/ahrs", fault_dir)
        self.declare_parameter("port", "/dev/ttyUSB0")
        self.declare_parameter("baud", 921600)
        self.truth = Truth(self)
        self.pub = self.create_publisher(Imu, "/sensors/ahrs/imu", SENSOR)
        self.n = 0
        self.bias = 0.0
        self.get_logger().info("AHRS on /dev/ttyUSB0 @ 921600: 50 Hz, magnetometer calibration 2026-10-02")
        self.create_timer(1.0, self.on_second)
        threading.Thread(target=self.serial, daemon=True, name="serial").start()

    def serial(self) -> None:
        m = Imu()
        m.header.frame_id = "ahrs_link"
        m.orientation_covariance[0] = m.orientation_covariance[4] = m.orientation_covariance[8] = 0.0003
        for _ in paced(AHRS_HZ):
            t = self.truth
            if self.fault == "bias":  # a corrupted hard-iron calibration: the heading walks away
                self.bias += 1.5 / AHRS_HZ * math.pi / 180.0
            m.header.stamp = self.get_clock().now().to_msg()
            set_yaw(m.orientation, wrap(t.yaw + self.bias + self.rng.gauss(0.0, 0.003)))
            m.angular_velocity.z = t.r + self.rng.gauss(0.0, 0.002)
            m.linear_acceleration.z = 9.81 + self.rng.gauss(0.0, 0.02)
            self.n += 1
            if not published((self.pub, m)):
                return

    def on_second(self) -> None:
        n, self.n = self.n, 0
        self.publish_diagnostics(
            self.status(
                "ahrs_status",
                "ahrs-3dm-gx5-25",
                OK,
                "OK",
                rate_hz=n,
                mag_field_ut=f"{48.0 + self.rng.gauss(0, 0.3):.1f}",
            )
        )


class DvlDriver(AuvNode):
    """The DVL (600 kHz, TCP): 8 Hz velocity and altitude; no bottom lock within 3 m of the surface
    (aerated layer), beyond 40 m altitude, often over the steep ridge and in short dropouts now and
    then; then it publishes the invalid velocity (covariance[0] = -1) and an infinite range."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("dvl_driver", "sensors/dvl", fault_dir)
        self.declare_parameter("ip", "192.168.194.95")
        self.declare_parameter("max_altitude", 40.0)
        self.truth = Truth(self)
        self.twist_pub = self.create_publisher(TwistWithCovarianceStamped, "/sensors/dvl/twist", SENSOR)
        self.alt_pub = self.create_publisher(Range, "/sensors/dvl/altitude", SENSOR)
        self.locked = False
        self.changed_at = None
        self.dropout_until = 0.0
        self.next_dropout = time.monotonic() + self.rng.uniform(30.0, 70.0)
        self.valid = self.n = 0
        self.get_logger().info("DVL A50 at 192.168.194.95:16171, firmware 2.4.4: velocity reports at 8 Hz")
        self.create_timer(1.0, self.on_second)
        threading.Thread(target=self.tcp, daemon=True, name="tcp").start()

    def tcp(self) -> None:
        tw, rg = TwistWithCovarianceStamped(), Range()
        tw.header.frame_id = rg.header.frame_id = "dvl_link"
        rg.radiation_type, rg.field_of_view, rg.min_range, rg.max_range = Range.ULTRASOUND, 0.4, 0.05, 40.0
        for _ in paced(DVL_HZ):
            t, now = self.truth, time.monotonic()
            if now > self.next_dropout:
                self.dropout_until = now + self.rng.uniform(1.0, 4.0)
                self.next_dropout = now + self.rng.uniform(30.0, 70.0)
            alt = t.altitude
            lock = (
                t.depth > 3.0
                and alt < 40.0
                and now > self.dropout_until
                and not (slope(t.x, t.y) > 0.6 and self.rng.random() < 0.7)
            )
            if lock == self.locked:
                self.changed_at = None
            elif self.changed_at is None:
                self.changed_at = now
            elif now - self.changed_at >= 1.0:  # the lock state reported once it held for 1 s
                self.locked, self.changed_at = lock, None
                if lock:
                    self.get_logger().info(f"Bottom lock acquired (altitude {alt:.1f} m)")
                elif t.depth > 3.0:
                    self.get_logger().warn(f"Bottom lock lost (altitude {alt:.1f} m)")
            stamp = self.get_clock().now().to_msg()
            if self.fault == "stale":  # time sync reset: the driver falls back to the DVL's own clock
                stamp = to_stamp(secs(stamp) - 2.5)
            tw.header.stamp = rg.header.stamp = stamp
            v = tw.twist.twist.linear
            if lock:
                v.x = t.u + 0.05 * math.cos(t.yaw) + self.rng.gauss(0.0, 0.01)  # over ground: the current too
                v.y = -0.05 * math.sin(t.yaw) + self.rng.gauss(0.0, 0.01)
                v.z = t.w + self.rng.gauss(0.0, 0.01)
                tw.twist.covariance[0] = tw.twist.covariance[7] = tw.twist.covariance[14] = 1e-4
                rg.range = alt + self.rng.gauss(0.0, 0.05)
                self.valid += 1
            else:
                v.x = v.y = v.z = 0.0
                tw.twist.covariance[0] = -1.0
                rg.range = math.inf
            self.n += 1
            if not published((self.twist_pub, tw), (self.alt_pub, rg)):
                return

    def on_second(self) -> None:
        level, text = (OK, "bottom lock") if self.locked else (WARN, "no bottom lock")
        self.publish_diagnostics(
            self.status("dvl_status", "dvl-a50-1877", level, text, rate_hz=self.n, valid=self.valid)
        )
        self.n = self.valid = 0


class PressureDriver(AuvNode):
    """The depth sensor (Bar30 on I2C): 20 Hz FluidPressure, sensor QoS."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("pressure_driver", "sensors/depth", fault_dir)
        self.declare_parameter("i2c_bus", 1)
        self.declare_parameter("fluid_density", 1025.0)
        self.truth = Truth(self)
        self.pub = self.create_publisher(FluidPressure, "/sensors/depth/pressure", SENSOR)
        self.n = 0
        self.get_logger().info("Bar30 (MS5837-30BA) on i2c-1 at 0x76: 20 Hz")
        self.create_timer(1.0, self.on_second)
        threading.Thread(target=self.i2c, daemon=True, name="i2c").start()

    def rate(self) -> float:
        # I2C clock stretching: most conversions time out and are retried
        return 6.0 if self.fault == "degrade" else DEPTH_HZ

    def i2c(self) -> None:
        m = FluidPressure()
        m.header.frame_id, m.variance = "depth_link", 40.0
        for _ in paced(self.rate):
            m.header.stamp = self.get_clock().now().to_msg()
            m.fluid_pressure = P_ATM + RHO_G * self.truth.depth + self.rng.gauss(0.0, 20.0)
            self.n += 1
            if not published((self.pub, m)):
                return

    def on_second(self) -> None:
        self.publish_diagnostics(
            self.status(
                "pressure_sensor",
                "bar30-i2c-1-0x76",
                OK,
                "OK",
                rate_hz=self.n,
                water_temp_c=f"{11.5 + self.rng.gauss(0, 0.05):.2f}",
            )
        )
        self.n = 0


class GpsDriver(AuvNode):
    """The GPS on the mast (NMEA over serial): a 5 Hz fix while surfaced; submerged, 1 Hz NO_FIX."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("gps_driver", "sensors/gps", fault_dir)
        self.declare_parameter("port", "/dev/ttyAMA0")
        self.truth = Truth(self)
        self.pub = self.create_publisher(NavSatFix, "/sensors/gps/fix", SENSOR)
        self.fix = False
        self.fix_from = None
        self.get_logger().info("NMEA GPS on /dev/ttyAMA0 @ 115200")
        threading.Thread(target=self.serial, daemon=True, name="nmea").start()
        self.create_timer(1.0, self.on_second)

    def serial(self) -> None:
        m = NavSatFix()
        m.header.frame_id = "gps_link"
        k = 0
        for _ in paced(GPS_HZ):
            t = self.truth
            surfaced = t.depth < 0.3
            if surfaced and self.fix_from is None:
                self.fix_from = time.monotonic() + self.rng.uniform(2.0, 5.0)  # a cold-ish fix after the dunk
            if not surfaced:
                self.fix_from = None
            fix = surfaced and time.monotonic() >= self.fix_from
            if fix != self.fix:
                self.fix = fix
                if fix:
                    self.get_logger().info(f"GPS fix acquired ({self.rng.randint(7, 12)} satellites)")
                else:
                    self.get_logger().info("GPS fix lost (antenna submerged)")
            k += 1
            if not fix and k % 5:
                continue
            m.header.stamp = self.get_clock().now().to_msg()
            if fix:
                m.status.status = NavSatStatus.STATUS_FIX
                m.latitude = LAT0 + (t.y + self.rng.gauss(0, 1.2)) / 111320.0
                m.longitude = LON0 + (t.x + self.rng.gauss(0, 1.2)) / (
                    111320.0 * math.cos(math.radians(LAT0))
                )
                m.position_covariance[0] = m.position_covariance[4] = 2.0
                m.position_covariance_type = NavSatFix.COVARIANCE_TYPE_APPROXIMATED
            else:
                m.status.status = NavSatStatus.STATUS_NO_FIX
                m.latitude = m.longitude = math.nan
                m.position_covariance_type = NavSatFix.COVARIANCE_TYPE_UNKNOWN
            if not published((self.pub, m)):
                return

    def on_second(self) -> None:
        self.publish_diagnostics(
            self.status("gps_status", "gps-ublox-m8n", OK, "3D fix" if self.fix else "no fix (submerged)")
        )


class UsblReceiver(AuvNode):
    """The USBL transponder's position fixes relayed down by the topside USBL: every 2-6 s while the
    vehicle is deeper than 2 m, stamped with the interrogation time (0.2-0.6 s before it arrives);
    ~6 % are multipath outliers 20-40 m off."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("usbl_receiver", "sensors/usbl", fault_dir)
        self.declare_parameter("beacon_id", 3)
        self.truth = Truth(self)
        self.pub = self.create_publisher(PoseWithCovarianceStamped, "/sensors/usbl/fix", RELIABLE)
        self.fixes = 0
        self.next_at = time.monotonic() + 3.0
        self.create_timer(0.1, self.poll)
        self.create_timer(1.0, self.on_second)

    def poll(self) -> None:
        t, now = self.truth, time.monotonic()
        if now < self.next_at:
            return
        self.next_at = now + self.rng.uniform(2.0, 6.0)
        if t.depth < 2.0:
            return
        rng_m = math.hypot(t.x - HOME[0], t.y - HOME[1], t.depth)
        m = PoseWithCovarianceStamped()
        m.header.frame_id = "world"
        m.header.stamp = to_stamp(time.time() - 0.2 - rng_m / 1500.0 * 2 - self.rng.uniform(0.0, 0.3))
        sd = 0.5 + 0.01 * rng_m
        ex, ey = self.rng.gauss(0, sd), self.rng.gauss(0, sd)
        if self.rng.random() < 0.06:
            a = self.rng.uniform(0, 2 * math.pi)
            ex, ey = ex + 30.0 * math.cos(a), ey + 30.0 * math.sin(a)
        m.pose.pose.position.x, m.pose.pose.position.y, m.pose.pose.position.z = t.x + ex, t.y + ey, -t.depth
        m.pose.covariance[0] = m.pose.covariance[7] = sd * sd
        self.pub.publish(m)
        self.fixes += 1

    def on_second(self) -> None:
        self.publish_diagnostics(self.status("usbl_link", "usbl-beacon-3", OK, "OK", fixes=self.fixes))


# --- payload -----------------------------------------------------------------------------------------


class MultibeamDriver(Diagnosed, LifecycleNode):
    """The multibeam echosounder, a lifecycle node: configured at bring-up, activated by the mission
    executive for each survey block and deactivated before surfacing. Active, it pings at a rate set by
    its range (range = 3 x altitude + 10 m; 350/range Hz, at most 10 Hz), 256 beams a ping."""

    def __init__(self, fault_dir: Path) -> None:
        LifecycleNode.__init__(self, "multibeam_driver", namespace="payload/multibeam")
        hook(self, fault_dir)
        self.rng = random.Random()
        self.declare_parameter("ip", "192.168.194.40")
        self.declare_parameter("beams", 256)
        self.truth = Truth(self)
        self.pub = None
        self.active = False
        self.pings = 0
        self.range = 40.0
        self.create_timer(1.0, self.on_second)
        threading.Thread(target=self.sonar, daemon=True, name="sonar").start()

    def on_configure(self, state) -> TransitionCallbackReturn:
        self.pub = self.create_lifecycle_publisher(PointCloud2, "/payload/multibeam/points", SENSOR)
        self.get_logger().info("Configured: sonar head at 192.168.194.40, 256 beams, 400 kHz")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        self.active = True
        self.get_logger().info("Activated: pinging")
        return super().on_activate(state)

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        self.active = False
        self.get_logger().info(f"Deactivated after {self.pings} pings")
        return super().on_deactivate(state)

    def rate(self) -> float:
        alt = self.truth.altitude
        self.range = clamp(3.0 * alt + 10.0, 20.0, 120.0)
        return min(10.0, 350.0 / self.range)

    def sonar(self) -> None:
        angles = np.linspace(-1.05, 1.05, 256)
        for _ in paced(self.rate):
            if not self.active:
                continue
            t = self.truth
            across = t.altitude * np.tan(angles)
            xs = t.x - across * math.sin(t.yaw)
            ys = t.y + across * math.cos(t.yaw)
            zs = np.array([-seafloor(float(a), float(b)) for a, b in zip(xs[::16], ys[::16], strict=True)])
            zs = np.repeat(zs, 16) + np.random.normal(0.0, 0.05, 256)
            # sensor-frame soundings: along-track, across-track, down from the transducer; intensity
            pts = np.column_stack([np.zeros(256), across, -zs - t.depth, np.random.rand(256)])
            h = PoseStamped().header
            h.frame_id, h.stamp = "multibeam_link", self.get_clock().now().to_msg()
            try:
                if self.pub is not None:
                    self.pub.publish(cloud(h, pts))
            except Exception:
                if alive():
                    raise
                return
            self.pings += 1

    def on_second(self) -> None:
        if self.active:
            self.publish_diagnostics(
                self.status(
                    "sonar_head",
                    "mbes-400-0233",
                    OK,
                    "pinging",
                    range_m=f"{self.range:.0f}",
                    pings=self.pings,
                )
            )


class CameraDriver(AuvNode):
    """The downward stills camera and its strobes: on only below 9 m altitude (with a valid DVL
    altitude), 4 Hz mono 320x240, sensor QoS."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("camera_driver", "payload/camera", fault_dir)
        self.declare_parameter("exposure_us", 4000)
        self.declare_parameter("max_altitude", CAMERA_ALTITUDE)
        self.pub = self.create_publisher(Image, "/payload/camera/image_raw", SENSOR)
        self.create_subscription(Range, "/sensors/dvl/altitude", self.on_altitude, SENSOR)
        self.altitude = math.inf
        self.alt_at = 0.0
        self.on = False
        self.frames = 0
        self.base = np.random.randint(40, 90, (240, 320), dtype=np.uint8)
        self.create_timer(1.0 / CAMERA_HZ, self.capture)
        self.create_timer(1.0, self.on_second)

    def on_altitude(self, msg: Range) -> None:
        if math.isfinite(msg.range):
            self.altitude, self.alt_at = msg.range, time.monotonic()

    def capture(self) -> None:
        want = time.monotonic() - self.alt_at < 3.0 and self.altitude < CAMERA_ALTITUDE
        if want != self.on:
            self.on = want
            self.get_logger().info(
                f"Camera {'on' if want else 'off'}: strobes {'enabled' if want else 'disabled'}"
                f" (altitude {self.altitude:.1f} m)"
            )
        if not self.on:
            return
        m = Image(height=240, width=320, encoding="mono8", step=320)
        m.header.stamp, m.header.frame_id = self.get_clock().now().to_msg(), "camera_link"
        m.data = np.roll(self.base, self.frames * 7, axis=0).tobytes()
        self.pub.publish(m)
        self.frames += 1

    def on_second(self) -> None:
        self.publish_diagnostics(
            self.status(
                "camera_status", "cam-imx296-01", OK, "capturing" if self.on else "idle", frames=self.frames
            )
        )


class BathymetryProcessor(AuvNode):
    """Georeferences each multibeam ping with the navigation solution: /payload/multibeam/bathymetry
    (world-frame soundings, the ping's stamp)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("bathymetry_processor", "payload/multibeam", fault_dir)
        self.declare_parameter("sound_velocity", 1500.0)
        self.pub = self.create_publisher(PointCloud2, "/payload/multibeam/bathymetry", SENSOR)
        self.create_subscription(PointCloud2, "/payload/multibeam/points", self.on_ping, SENSOR)
        self.create_subscription(Odometry, "/nav/odometry", self.on_odom, SENSOR)
        self.pose = None

    def on_odom(self, msg: Odometry) -> None:
        self.pose = msg.pose.pose

    def on_ping(self, msg: PointCloud2) -> None:
        if self.fault == "hang":  # a ray-tracing loop that never converges on a bad sound-velocity layer
            threading.Event().wait()
        if self.pose is None:
            return
        p = points(msg).copy()
        yaw, x0, y0 = yaw_of(self.pose.orientation), self.pose.position.x, self.pose.position.y
        across = p[:, 1].copy()
        p[:, 0] = x0 - across * math.sin(yaw)
        p[:, 1] = y0 + across * math.cos(yaw)
        p[:, 2] = self.pose.position.z - p[:, 2]
        out = cloud(msg.header, p)
        out.header.frame_id = "world"
        self.pub.publish(out)


class ImageEnhancer(AuvNode):
    """Underwater colour/contrast correction (a CLAHE-like stretch) of every other camera frame."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("image_enhancer", "payload/camera", fault_dir)
        self.pub = self.create_publisher(Image, "/payload/camera/image_enhanced", SENSOR)
        self.create_subscription(Image, "/payload/camera/image_raw", self.on_image, SENSOR)
        self.n = 0

    def on_image(self, msg: Image) -> None:
        self.n += 1
        if self.n % 2:
            return
        a = np.frombuffer(msg.data, dtype=np.uint8).reshape(msg.height, msg.width)[::2, ::2]
        lo, hi = np.percentile(a, (2, 98))
        b = np.clip((a.astype(np.float32) - lo) * (255.0 / max(hi - lo, 1.0)), 0, 255).astype(np.uint8)
        out = Image(height=b.shape[0], width=b.shape[1], encoding="mono8", step=b.shape[1], data=b.tobytes())
        out.header = msg.header
        self.pub.publish(out)


class CoverageMonitor(AuvNode):
    """Survey coverage: the bathymetry binned in a 2 m grid; /payload/coverage (% of the box) at 1 Hz,
    a WARN when soundings stop for 5 s while the multibeam is active (its diagnostics)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("coverage_monitor", "payload", fault_dir)
        self.pub = self.create_publisher(Float32, "/payload/coverage", RELIABLE)
        self.create_subscription(PointCloud2, "/payload/multibeam/bathymetry", self.on_bathy, SENSOR)
        self.grid = np.zeros((35, 60), dtype=bool)  # x -10..60, y -5..115 at 2 m
        self.last = None
        self.soundings = 0
        self.create_timer(1.0, self.on_second)

    def on_bathy(self, msg: PointCloud2) -> None:
        p = points(msg)
        i = ((p[:, 0] + 10.0) / 2.0).astype(int)
        j = ((p[:, 1] + 5.0) / 2.0).astype(int)
        ok = (i >= 0) & (i < 35) & (j >= 0) & (j < 60)
        self.grid[i[ok], j[ok]] = True
        self.last = time.monotonic()
        self.soundings += len(p)

    def on_second(self) -> None:
        self.pub.publish(Float32(data=float(self.grid.mean() * 100.0)))
        quiet = self.last is not None and time.monotonic() - self.last > 5.0
        self.publish_diagnostics(
            self.status(
                "coverage",
                "payload-computer",
                OK,
                "OK",
                coverage_pct=f"{self.grid.mean() * 100:.1f}",
                soundings=self.soundings,
                idle_s=f"{time.monotonic() - self.last:.0f}" if self.last else "-",
                quiet=quiet,
            )
        )


# --- navigation ---------------------------------------------------------------------------------------


class NavsatTransform(AuvNode):
    """GPS fixes to the local world frame (the survey datum): /nav/gps_pose, only valid fixes."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("navsat_transform", "nav", fault_dir)
        self.declare_parameter("datum", [LAT0, LON0, 0.0])
        self.pub = self.create_publisher(PoseWithCovarianceStamped, "/nav/gps_pose", RELIABLE)
        self.create_subscription(NavSatFix, "/sensors/gps/fix", self.on_fix, SENSOR)

    def on_fix(self, msg: NavSatFix) -> None:
        if msg.status.status < NavSatStatus.STATUS_FIX:
            return
        m = PoseWithCovarianceStamped()
        m.header.stamp, m.header.frame_id = msg.header.stamp, "world"
        m.pose.pose.position.x = (msg.longitude - LON0) * 111320.0 * math.cos(math.radians(LAT0))
        m.pose.pose.position.y = (msg.latitude - LAT0) * 111320.0
        m.pose.covariance[0] = m.pose.covariance[7] = msg.position_covariance[0]
        self.pub.publish(m)


class EkfFilter(AuvNode):
    """The navigation filter: predicts on each AHRS message (heading, yaw rate) with the DVL's
    velocity (dead reckoning on the last commanded-speed estimate while it has no bottom lock),
    depth from the pressure sensor, position corrected by USBL fixes (gated at 12 m) and, surfaced,
    GPS. /nav/odometry at 25 Hz (every other AHRS message) stamped with that AHRS message's stamp;
    /nav/status latched (WAITING_FOR_GPS, OK, DEAD_RECKONING); inputs older than 1 s are rejected."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("ekf_filter", "nav", fault_dir)
        self.declare_parameter("usbl_gate_m", 12.0)
        self.declare_parameter("max_input_age", 1.0)
        self.odom_pub = self.create_publisher(Odometry, "/nav/odometry", SENSOR)
        self.status_pub = self.create_publisher(String, "/nav/status", LATCHED)
        self.imu_sub = self.create_subscription(Imu, "/sensors/ahrs/imu", self.on_imu, SENSOR)
        self.create_subscription(TwistWithCovarianceStamped, "/sensors/dvl/twist", self.on_dvl, SENSOR)
        self.create_subscription(FluidPressure, "/sensors/depth/pressure", self.on_pressure, SENSOR)
        self.create_subscription(PoseWithCovarianceStamped, "/sensors/usbl/fix", self.on_usbl, RELIABLE)
        self.create_subscription(PoseWithCovarianceStamped, "/nav/gps_pose", self.on_gps, RELIABLE)
        self.x = self.y = self.depth = self.yaw = self.r = self.u = self.v = self.w = 0.0
        self.sigma = 50.0
        self.initialized = False
        self.state = None
        self.dvl_at = self.imu_at = self.depth_at = None
        self.last_t = None
        self.started = time.monotonic()
        self.n = 0
        self.counts = {"imu": 0, "dvl": 0, "depth": 0, "usbl": 0, "usbl_rejected": 0}
        self.odom = Odometry()
        self.odom.header.frame_id, self.odom.child_frame_id = "world", "base_link"
        self.set_state("WAITING_FOR_GPS")
        self.create_timer(1.0, self.on_second)

    def on_fault(self, fault: str | None) -> None:
        if fault == "reliable":  # a reloaded ekf.yaml asks for a reliable AHRS subscription
            self.get_logger().info("Parameters reloaded from ekf.yaml: re-creating the AHRS subscription")
            self.destroy_subscription(self.imu_sub)
            self.imu_sub = self.create_subscription(
                Imu,
                "/sensors/ahrs/imu",
                self.on_imu,
                QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE),
            )

    def set_state(self, state: str) -> None:
        if state != self.state:
            self.state = state
            self.status_pub.publish(String(data=state))
            if state == "DEAD_RECKONING":
                self.get_logger().warn("Navigation state: DEAD_RECKONING (no DVL bottom lock)")
            else:
                self.get_logger().info(f"Navigation state: {state}")

    def fresh(self, stamp) -> bool:
        return time.time() - secs(stamp) <= 1.0

    def on_dvl(self, msg: TwistWithCovarianceStamped) -> None:
        if not self.fresh(msg.header.stamp):
            if self.throttle("dvl_old", 5.0):
                self.get_logger().warn(
                    f"DVL velocity {time.time() - secs(msg.header.stamp):.2f} s old: rejected"
                )
            return
        if msg.twist.covariance[0] < 0.0:  # no bottom lock
            return
        v = msg.twist.twist.linear
        self.u, self.v, self.w = v.x, v.y, v.z
        self.dvl_at = time.monotonic()
        self.counts["dvl"] += 1

    def on_pressure(self, msg: FluidPressure) -> None:
        self.depth = max(0.0, (msg.fluid_pressure - P_ATM) / RHO_G)
        self.depth_at = time.monotonic()
        self.counts["depth"] += 1

    def on_usbl(self, msg: PoseWithCovarianceStamped) -> None:
        if not self.initialized:
            return
        p = msg.pose.pose.position
        innov = math.hypot(p.x - self.x, p.y - self.y)
        if innov > self.get_parameter("usbl_gate_m").value:
            self.counts["usbl_rejected"] += 1
            self.get_logger().warn(f"USBL fix rejected: innovation {innov:.1f} m beyond the gate")
            return
        var = msg.pose.covariance[0]
        k = self.sigma**2 / (self.sigma**2 + var)
        self.x += k * (p.x - self.x)
        self.y += k * (p.y - self.y)
        self.sigma = math.sqrt((1 - k) * self.sigma**2)
        self.counts["usbl"] += 1

    def on_gps(self, msg: PoseWithCovarianceStamped) -> None:
        p = msg.pose.pose.position
        if not self.initialized:
            self.x, self.y, self.sigma = p.x, p.y, 2.0
            self.initialized = True
            self.get_logger().info(f"Initialized from GPS at ({p.x:.1f}, {p.y:.1f})")
            self.set_state("OK")
            return
        k = 0.3
        self.x += k * (p.x - self.x)
        self.y += k * (p.y - self.y)
        self.sigma = min(self.sigma, 2.0)

    def on_imu(self, msg: Imu) -> None:
        self.counts["imu"] += 1
        self.imu_at = time.monotonic()
        t = secs(msg.header.stamp)
        self.yaw, self.r = yaw_of(msg.orientation), msg.angular_velocity.z
        dt = 0.0 if self.last_t is None else clamp(t - self.last_t, 0.0, 0.2)
        self.last_t = t
        dvl_ok = self.dvl_at is not None and time.monotonic() - self.dvl_at < 3.0
        if not dvl_ok:
            self.u *= 1.0 - 0.02 * dt  # the velocity model decays without bottom lock
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        self.x += dt * (self.u * c - self.v * s)
        self.y += dt * (self.u * s + self.v * c)
        self.sigma += dt * (0.01 if dvl_ok else 0.05)
        self.n += 1
        if self.n % 2 or not self.initialized:
            return
        o = self.odom
        o.header.stamp = msg.header.stamp
        p = o.pose.pose
        p.position.x, p.position.y, p.position.z = self.x, self.y, -self.depth
        set_yaw(p.orientation, self.yaw)
        o.pose.covariance[0] = o.pose.covariance[7] = self.sigma**2
        o.twist.twist.linear.x, o.twist.twist.linear.z, o.twist.twist.angular.z = self.u, -self.w, self.r
        self.odom_pub.publish(o)

    def on_second(self) -> None:
        now = time.monotonic()
        if self.initialized:
            dvl_ok = self.dvl_at is not None and now - self.dvl_at < 3.0
            self.set_state("OK" if dvl_ok or self.depth < 3.0 else "DEAD_RECKONING")
        if (self.imu_at is None and now - self.started > 5.0) or (
            self.imu_at is not None and now - self.imu_at > 1.0
        ):
            if self.throttle("imu", 5.0):
                self.get_logger().error("No AHRS data for 1 s: navigation solution not updated")
        c = self.counts
        level = OK if self.state == "OK" else WARN
        if self.imu_at is None or now - self.imu_at > 1.0 or self.sigma > 15.0:
            level = ERROR
        self.publish_diagnostics(
            self.status(
                "navigation_solution",
                "nav-ekf",
                level,
                self.state,
                sigma_m=f"{self.sigma:.1f}",
                imu_hz=c["imu"],
                depth_hz=c["depth"],
                dvl_hz=c["dvl"],
                usbl_fixes=c["usbl"],
                usbl_rejected=c["usbl_rejected"],
            )
        )
        self.counts = dict.fromkeys(c, 0)


# --- control ------------------------------------------------------------------------------------------


class DepthHeadingController(AuvNode):
    """Depth, heading and speed PID loops at 20 Hz on /nav/odometry towards the behaviours' setpoint
    (line-of-sight heading to the waypoint; ``cruise_speed`` a runtime parameter): /control/wrench.
    Zero wrench (an ERROR) when the navigation solution is older than 1 s."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("depth_heading_controller", "control", fault_dir)
        self.declare_parameter("cruise_speed", 1.0)
        self.declare_parameter("depth_kp", 10.0)
        self.declare_parameter("heading_kp", 6.0)
        self.add_on_set_parameters_callback(self.on_params)
        self.pub = self.create_publisher(WrenchStamped, "/control/wrench", COMMAND)
        self.create_subscription(Odometry, "/nav/odometry", self.on_odom, SENSOR)
        self.create_subscription(PoseStamped, "/control/setpoint", self.on_setpoint, COMMAND)
        self.odom = self.odom_at = self.sp = None
        self.dz_int = 0.0
        self.timed_out = False
        self.create_timer(1.0 / CONTROL_HZ, self.loop)
        self.create_timer(1.0, self.on_second)

    def on_params(self, params) -> SetParametersResult:
        for p in params:
            if p.name == "cruise_speed":
                if not 0.2 <= p.value <= 2.0:
                    return SetParametersResult(successful=False, reason="cruise_speed out of 0.2-2.0 m/s")
                self.get_logger().info(f"cruise_speed set to {p.value:.2f} m/s")
        return SetParametersResult(successful=True)

    def on_odom(self, msg: Odometry) -> None:
        self.odom, self.odom_at = msg, time.monotonic()

    def on_setpoint(self, msg: PoseStamped) -> None:
        self.sp = msg

    def loop(self) -> None:
        m = WrenchStamped()
        m.header.stamp, m.header.frame_id = self.get_clock().now().to_msg(), "base_link"
        stale = self.odom_at is None or time.monotonic() - self.odom_at > 1.0
        if stale and self.odom_at is not None and not self.timed_out:
            self.timed_out = True
            self.get_logger().error("Navigation timeout: thrust zeroed")
        elif not stale and self.timed_out:
            self.timed_out = False
            self.get_logger().info("Navigation solution back: control resumed")
        if not stale and self.sp is not None:
            o, sp = self.odom, self.sp
            p = o.pose.pose.position
            yaw, depth, w = yaw_of(o.pose.pose.orientation), -p.z, -o.twist.twist.linear.z
            mode = sp.header.frame_id
            dx, dy = sp.pose.position.x - p.x, sp.pose.position.y - p.y
            dist = math.hypot(dx, dy)
            speed = (
                0.0
                if mode in ("hold", "surface")
                else min(self.get_parameter("cruise_speed").value, 0.25 * dist)
            )
            yaw_d = math.atan2(dy, dx) if dist > 2.0 else yaw
            m.wrench.force.x = 30.0 * (speed - o.twist.twist.linear.x) + 25.0 * speed * speed
            m.wrench.torque.z = 6.0 * wrap(yaw_d - yaw) - 8.0 * o.twist.twist.angular.z
            if mode == "surface":
                m.wrench.force.z = -15.0
            else:
                dz = -sp.pose.position.z - depth
                self.dz_int = clamp(self.dz_int + dz / CONTROL_HZ, -5.0, 5.0)
                m.wrench.force.z = clamp(10.0 * dz + 0.4 * self.dz_int - 40.0 * w + 2.0, -40.0, 40.0)
        self.pub.publish(m)

    def on_second(self) -> None:
        level, text = (ERROR, "navigation timeout") if self.timed_out else (OK, "OK")
        mode = self.sp.header.frame_id if self.sp is not None else "none"
        self.publish_diagnostics(self.status("control_loop", "control", level, text, mode=mode))


class ThrusterAllocator(AuvNode):
    """Wrench -> the four thrusters' rpm (port/starboard surge and differential yaw, two vertical):
    /control/thrusters/command, reliable depth 1, one per wrench."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("thruster_allocator", "control", fault_dir)
        self.declare_parameter("lever_arm", 0.3)
        self.pub = self.create_publisher(JointState, "/control/thrusters/command", COMMAND)
        self.create_subscription(WrenchStamped, "/control/wrench", self.on_wrench, COMMAND)
        self.saturated = 0

    @staticmethod
    def rpm(f: float) -> float:
        return math.copysign(math.sqrt(abs(f) / K_THRUST), f)

    def on_wrench(self, msg: WrenchStamped) -> None:
        f = msg.wrench
        forces = (
            f.force.x / 2 + f.torque.z / 0.6,
            f.force.x / 2 - f.torque.z / 0.6,
            f.force.z / 2,
            f.force.z / 2,
        )
        rpms = [self.rpm(x) for x in forces]
        if max(abs(r) for r in rpms) > MAX_RPM:
            self.saturated += 1
            if self.throttle("sat", 10.0):
                self.get_logger().warn("Thrust saturated: commands scaled down")
            s = MAX_RPM / max(abs(r) for r in rpms)
            rpms = [r * s for r in rpms]
        m = JointState(name=list(THRUSTERS), velocity=rpms)
        m.header.stamp = msg.header.stamp
        self.pub.publish(m)


class ThrusterDriver(AuvNode):
    """The ESC bridge (four ESCs on RS-485): its bus thread writes the newest command at 20 Hz (rpm
    slew-limited) and reads back rpm and current: /control/thrusters/state (JointState). Watchdog: no
    command for 0.5 s stops the thrusters (an ERROR, until commands come back)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("thruster_driver", "control", fault_dir)
        self.declare_parameter("port", "/dev/ttyS2")
        self.declare_parameter("watchdog_timeout", 0.5)
        self.pub = self.create_publisher(JointState, "/control/thrusters/state", SENSOR)
        self.create_subscription(JointState, "/control/thrusters/command", self.on_cmd, COMMAND)
        self.lock = threading.Lock()
        self.cmd = [0.0] * 4
        self.cmd_at = None
        self.rpm = [0.0] * 4
        self.tripped = False
        self.get_logger().info("ESC bridge on /dev/ttyS2: 4 ESCs found (BlueESC fw 1.3)")
        self.create_timer(1.0, self.on_second)
        threading.Thread(target=self.bus, daemon=True, name="rs485").start()

    def on_cmd(self, msg: JointState) -> None:
        with self.lock:
            self.cmd = list(msg.velocity)
            self.cmd_at = time.monotonic()

    def bus(self) -> None:
        m = JointState(name=list(THRUSTERS))
        for _ in paced(ESC_HZ):
            now = time.monotonic()
            with self.lock:
                cmd, at = self.cmd, self.cmd_at
            if at is not None and now - at > 0.5:
                if not self.tripped:
                    self.tripped = True
                    self.get_logger().error(
                        f"Watchdog: no thruster command for {now - at:.2f} s, thrusters stopped"
                    )
                cmd = [0.0] * 4
            elif at is not None and self.tripped:
                self.tripped = False
                self.get_logger().info("Thruster commands back: watchdog cleared")
            self.rpm = [r + clamp(c - r, -150.0, 150.0) for r, c in zip(self.rpm, cmd, strict=True)]
            m.header.stamp = self.get_clock().now().to_msg()
            m.velocity = list(self.rpm)
            m.effort = [0.2 + 1.5e-6 * r * r for r in self.rpm]
            if not published((self.pub, m)):
                return

    def on_second(self) -> None:
        level, text = (ERROR, "watchdog tripped") if self.tripped else (OK, "OK")
        self.publish_diagnostics(
            self.status(
                "esc_bus",
                "esc-rs485-ttyS2",
                level,
                text,
                current_a=f"{sum(0.2 + 1.5e-6 * r * r for r in self.rpm):.1f}",
            )
        )


# --- mission ------------------------------------------------------------------------------------------


class SurveyPlanner(AuvNode):
    """The survey planner: ``/mission/survey_planner/plan_line`` (GetPlan; the goal's ``position.z``
    is the line index) answers the line's waypoints checked against the terrain model (~0.1-0.3 s)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("survey_planner", "mission", fault_dir)
        self.declare_parameter("line_spacing", 10.0)
        self.declare_parameter("terrain_tiles", "/data/terrain/monterey_2m.tif")
        self.create_service(GetPlan, "/mission/survey_planner/plan_line", self.on_plan)
        self.get_logger().info("Terrain model loaded: 2 m grid, 12 survey lines")

    def on_plan(self, request, response):
        i = int(request.goal.pose.position.z)
        time.sleep(self.rng.uniform(0.1, 0.3))  # the terrain model's clearance checks
        if self.fault == "slow":  # the terrain tile cache thrashes: every tile re-read from the SD card
            time.sleep(6.0)
        (x0, y0), (x1, y1) = SURVEY_LINES[i % len(SURVEY_LINES)]
        response.plan.header.frame_id = "world"
        response.plan.header.stamp = self.get_clock().now().to_msg()
        for k in range(7):
            ps = PoseStamped()
            ps.pose.position.x, ps.pose.position.y = x0 + (x1 - x0) * k / 6, y0 + (y1 - y0) * k / 6
            ps.pose.position.z = -(seafloor(ps.pose.position.x, ps.pose.position.y) - SURVEY_ALTITUDE)
            response.plan.poses.append(ps)
        self.get_logger().info(f"Planned survey line {i}: {len(response.plan.poses)} waypoints")
        return response


class BehaviorServer(AuvNode):
    """The behaviours, as actions (test_msgs/Fibonacci): ``/mission/dive`` (order = depth),
    ``/mission/follow_line`` (order = line; the line from the latched /mission/current_line),
    ``/mission/surface``, ``/mission/go_home``. Each runs in the reentrant group and steers the
    controller through /control/setpoint (5 Hz, from a timer in its own group)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("behavior_server", "mission", fault_dir)
        self.actions = ReentrantCallbackGroup()
        self.io = MutuallyExclusiveCallbackGroup()
        self.sp_pub = self.create_publisher(PoseStamped, "/control/setpoint", COMMAND)
        self.create_subscription(Odometry, "/nav/odometry", self.on_odom, SENSOR, callback_group=self.io)
        self.create_subscription(
            PathMsg, "/mission/current_line", self.on_line, LATCHED, callback_group=self.io
        )
        self.odom = None
        self.line = None
        self.sp = PoseStamped()
        self.sp.header.frame_id = "hold"
        self.sp_lock = threading.Lock()
        for name, run in (
            ("dive", self.dive),
            ("follow_line", self.follow_line),
            ("surface", self.surface),
            ("go_home", self.go_home),
        ):
            ActionServer(
                self,
                Fibonacci,
                f"/mission/{name}",
                execute_callback=run,
                callback_group=self.actions,
                goal_callback=lambda g: GoalResponse.ACCEPT,
                cancel_callback=lambda g: CancelResponse.ACCEPT,
            )
        self.create_timer(0.2, self.publish_setpoint, callback_group=self.io)

    def on_odom(self, msg: Odometry) -> None:
        self.odom = msg

    def on_line(self, msg: PathMsg) -> None:
        self.line = msg

    def set(self, mode: str, x: float, y: float, depth: float) -> None:
        with self.sp_lock:
            self.sp.header.frame_id = mode
            self.sp.pose.position.x, self.sp.pose.position.y, self.sp.pose.position.z = x, y, -depth

    def publish_setpoint(self) -> None:
        with self.sp_lock:
            self.sp.header.stamp = self.get_clock().now().to_msg()
            self.sp_pub.publish(self.sp)

    def here(self) -> tuple[float, float, float]:
        if self.odom is None:
            return (*HOME, 0.0)
        p = self.odom.pose.pose.position
        return p.x, p.y, -p.z

    def run(self, goal, done, feedback, limit: float):
        """Loop at 5 Hz until ``done()`` (a 0..1 progress or None) reaches 1, cancelled or ``limit`` s."""
        t0 = time.monotonic()
        fb = Fibonacci.Feedback()
        while alive():
            if goal.is_cancel_requested:
                goal.canceled()
                return Fibonacci.Result()
            progress = done()
            if progress >= 1.0:
                goal.succeed()
                return Fibonacci.Result(sequence=[100])
            if time.monotonic() - t0 > limit:
                goal.abort()
                return Fibonacci.Result(sequence=[int(progress * 100)])
            fb.sequence = [int(progress * 100)]
            goal.publish_feedback(fb)
            time.sleep(0.2)
        goal.abort()
        return Fibonacci.Result()

    def dive(self, goal):
        target = float(goal.request.order)
        x, y, d0 = self.here()
        self.get_logger().info(f"Dive to {target:.0f} m")
        self.set("hold", x, y, target)
        return self.run(
            goal, lambda: clamp((self.here()[2] - d0) / max(target - 1.0 - d0, 0.1), 0.0, 1.0), None, 90.0
        )

    def follow_line(self, goal):
        line = self.line
        if line is None or not line.poses:
            goal.abort()
            return Fibonacci.Result()
        wps = [(p.pose.position.x, p.pose.position.y, -p.pose.position.z) for p in line.poses]
        self.get_logger().info(f"Following survey line {goal.request.order} ({len(wps)} waypoints)")
        state = {"i": 0}

        def done() -> float:
            x, y, _ = self.here()
            i = state["i"]
            if math.hypot(wps[i][0] - x, wps[i][1] - y) < 3.0 and i < len(wps) - 1:
                state["i"] = i = i + 1
            self.set("waypoint", *wps[i])
            if i == len(wps) - 1 and math.hypot(wps[i][0] - x, wps[i][1] - y) < 3.0:
                return 1.0
            return i / len(wps)

        return self.run(goal, done, None, 150.0)

    def surface(self, goal):
        x, y, _ = self.here()
        self.get_logger().info("Surfacing")
        self.set("surface", x, y, 0.0)
        return self.run(
            goal,
            lambda: 1.0 if self.here()[2] < 0.2 else clamp(1.0 - self.here()[2] / 25.0, 0, 0.99),
            None,
            120.0,
        )

    def go_home(self, goal):
        self.get_logger().info("Returning to the launch point")
        self.set("waypoint", HOME[0], HOME[1], 0.0)

        def done() -> float:
            x, y, _ = self.here()
            dist = math.hypot(HOME[0] - x, HOME[1] - y)
            if dist < 3.0:
                self.set("hold", HOME[0], HOME[1], 0.0)
                return 1.0
            return clamp(1.0 - dist / 150.0, 0.0, 0.99)

        return self.run(goal, done, None, 300.0)


class MissionExecutive(AuvNode):
    """The mission state machine (2 Hz): PREFLIGHT (nav initialized from GPS, the leak detector's
    self test, the multibeam configured) -> DIVE -> SURVEY (multibeam active; per line: plan it with
    the survey planner, 4 s timeout, then the follow_line action) -> after 3 lines SURFACE (multibeam
    deactivated) -> GPS_FIX (20 s on the surface) -> DIVE ... until the 12 lines are done -> GO_HOME
    -> COMPLETE. /mission/state latched; ``/mission/report`` (Trigger) for the topside."""

    PLAN_TIMEOUT = 4.0

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("mission_executive", "mission", fault_dir)
        self.declare_parameter("survey_altitude", SURVEY_ALTITUDE)
        self.declare_parameter("lines_per_block", LINES_PER_BLOCK)
        self.group = MutuallyExclusiveCallbackGroup()
        self.state_pub = self.create_publisher(String, "/mission/state", LATCHED)
        self.line_pub = self.create_publisher(PathMsg, "/mission/current_line", LATCHED)
        self.create_subscription(String, "/nav/status", self.on_nav, LATCHED, callback_group=self.group)
        self.create_subscription(
            Float32, "/payload/coverage", self.on_coverage, RELIABLE, callback_group=self.group
        )
        self.create_subscription(Bool, "/auv/leak", self.on_leak, LATCHED, callback_group=self.group)
        self.acts = {
            n: ActionClient(self, Fibonacci, f"/mission/{n}", callback_group=self.group)
            for n in ("dive", "follow_line", "surface", "go_home")
        }
        self.planner = self.create_client(
            GetPlan, "/mission/survey_planner/plan_line", callback_group=self.group
        )
        self.self_test = self.create_client(
            Trigger, "/auv/leak_detector/self_test", callback_group=self.group
        )
        self.mbes = self.create_client(
            ChangeState, "/payload/multibeam/multibeam_driver/change_state", callback_group=self.group
        )
        self.create_service(Trigger, "/mission/report", self.on_report, callback_group=self.group)
        self.nav = None
        self.coverage = 0.0
        self.leak = False
        self.state = None
        self.line = 0
        self.block_lines = 0
        self.pending = None  # (kind, sent, future)
        self.goal_handle = None
        self.result_future = None
        self.wait_until = 0.0
        self.retries = 0
        self.preflight = {"test": False, "mbes": False}
        self.set_state("PREFLIGHT")
        self.create_timer(0.5, self.tick, callback_group=self.group)

    def set_state(self, state: str) -> None:
        self.state = state
        self.state_pub.publish(String(data=state))
        self.get_logger().info(f"Mission state: {state}")

    def on_nav(self, msg: String) -> None:
        self.nav = msg.data

    def on_coverage(self, msg: Float32) -> None:
        self.coverage = msg.data

    def on_leak(self, msg: Bool) -> None:
        if msg.data and not self.leak:
            self.get_logger().error("LEAK detected: aborting the mission")
        self.leak = msg.data

    def on_report(self, request, response):
        response.success = True
        response.message = json.dumps(
            {"state": self.state, "line": self.line, "nav": self.nav, "coverage": round(self.coverage, 1)}
        )
        return response

    def send(self, name: str, order: int) -> None:
        self.goal_handle = None
        self.result_future = None
        self.pending = (
            "goal:" + name,
            time.monotonic(),
            self.acts[name].send_goal_async(Fibonacci.Goal(order=order)),
        )

    def mbes_transition(self, tid: int) -> None:
        self.pending = (
            "mbes",
            time.monotonic(),
            self.mbes.call_async(ChangeState.Request(transition=Transition(id=tid))),
        )

    def action_done(self) -> str | None:
        """The running action's outcome once it is known: 'ok', 'failed' or None."""
        if self.pending is not None and self.pending[0].startswith("goal:"):
            fut = self.pending[2]
            if not fut.done():
                return None
            self.pending = None
            self.goal_handle = fut.result()
            if not self.goal_handle.accepted:
                return "failed"
            self.result_future = self.goal_handle.get_result_async()
        if self.result_future is None or not self.result_future.done():
            return None
        status = self.result_future.result().status
        self.result_future = None
        return "ok" if status == 4 else "failed"  # GoalStatus.STATUS_SUCCEEDED

    def tick(self) -> None:
        now = time.monotonic()
        s = self.state
        if self.leak and s not in ("SURFACE", "ABORT_SURFACE", "COMPLETE"):
            self.set_state("ABORT_SURFACE")
            self.send("surface", 0)
            return
        if s == "PREFLIGHT":
            if self.pending is not None:
                kind, _sent, fut = self.pending
                if fut.done():
                    self.pending = None
                    if kind == "test":
                        self.preflight["test"] = fut.result().success
                        self.get_logger().info(f"Leak detector self test: {fut.result().message}")
                    else:
                        self.preflight["mbes"] = fut.result().success
                        self.get_logger().info("Multibeam configured")
                return
            if not self.preflight["test"] and self.self_test.service_is_ready():
                self.pending = ("test", now, self.self_test.call_async(Trigger.Request()))
            elif not self.preflight["mbes"] and self.mbes.service_is_ready():
                self.mbes_transition(Transition.TRANSITION_CONFIGURE)
            elif all(self.preflight.values()) and self.nav == "OK" and self.acts["dive"].server_is_ready():
                self.start_dive()
            elif self.throttle("wait", 10.0):
                self.get_logger().info(f"Preflight: waiting (nav {self.nav}, checks {self.preflight})")
        elif s == "DIVE":
            out = self.action_done()
            if out == "ok":
                self.get_logger().info("On station: starting the survey block")
                self.set_state("SURVEY")
                self.block_lines = 0
                self.mbes_transition(Transition.TRANSITION_ACTIVATE)
                self.wait_until = now
            elif out == "failed":
                self.get_logger().error("Dive failed: surfacing")
                self.start_surface()
        elif s == "SURVEY":
            self.survey(now)
        elif s in ("SURFACE", "ABORT_SURFACE"):
            out = self.action_done()
            if out is not None:
                self.set_state("GPS_FIX" if s == "SURFACE" else "COMPLETE")
                self.wait_until = now + 20.0
        elif s == "GPS_FIX":
            if now >= self.wait_until and self.nav == "OK":
                if self.line >= len(SURVEY_LINES):
                    self.set_state("GO_HOME")
                    self.send("go_home", 0)
                else:
                    self.start_dive()
        elif s == "GO_HOME":
            if self.action_done() is not None:
                self.set_state("COMPLETE")

    def start_dive(self) -> None:
        x, y = SURVEY_LINES[self.line][0]
        target = round(seafloor(x, y) - SURVEY_ALTITUDE)
        self.set_state("DIVE")
        self.send("dive", target)

    def start_surface(self) -> None:
        self.set_state("SURFACE")
        self.send("surface", 0)

    def survey(self, now: float) -> None:
        if self.pending is not None and self.pending[0] == "mbes":
            if self.pending[2].done():
                self.pending = None
            return
        if self.pending is not None and self.pending[0] == "plan":
            _, sent, fut = self.pending
            if fut.done():
                self.pending = None
                self.retries = 0
                plan = fut.result().plan
                plan.header.stamp = self.get_clock().now().to_msg()
                self.line_pub.publish(plan)
                self.send("follow_line", self.line)
            elif now - sent > self.PLAN_TIMEOUT:
                self.planner.remove_pending_request(fut)
                self.pending = None
                self.retries += 1
                self.get_logger().error(
                    f"Timed out waiting for {self.planner.srv_name} ({self.PLAN_TIMEOUT:.0f} s),"
                    f" attempt {self.retries}: holding position"
                )
                self.wait_until = now + 2.0
            return
        if self.pending is None and self.result_future is None:
            if self.block_lines >= self.get_parameter("lines_per_block").value or self.line >= len(
                SURVEY_LINES
            ):
                self.get_logger().info("Survey block done: surfacing for a GPS fix")
                self.mbes_transition(Transition.TRANSITION_DEACTIVATE)
                self.pending = None
                self.start_surface()
                return
            if now >= self.wait_until and self.planner.service_is_ready():
                req = GetPlan.Request()
                req.goal.pose.position.z = float(self.line)
                self.pending = ("plan", now, self.planner.call_async(req))
            return
        out = self.action_done()
        if out == "ok":
            self.get_logger().info(f"Survey line {self.line} done")
            self.line += 1
            self.block_lines += 1
        elif out == "failed":
            self.get_logger().warn(f"Survey line {self.line} aborted: replanning")
            self.wait_until = now + 2.0


# --- vehicle health -----------------------------------------------------------------------------------


class BatteryMonitor(AuvNode):
    """The BMS over SMBus: /auv/battery (BatteryState, 1 Hz), the pack's current from the thrusters'."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("battery_monitor", "auv", fault_dir)
        self.declare_parameter("capacity_wh", 1200.0)
        self.declare_parameter("low_soc_warn", 0.3)
        self.pub = self.create_publisher(BatteryState, "/auv/battery", RELIABLE)
        self.create_subscription(JointState, "/control/thrusters/state", self.on_esc, SENSOR)
        self.current = 2.5
        self.soc = 0.82
        self.create_timer(1.0, self.on_second)

    def on_esc(self, msg: JointState) -> None:
        self.current = 2.5 + sum(msg.effort)

    def on_second(self) -> None:
        if self.fault == "errlog":  # a flaky SMBus: cell 7's reading fails its CRC, the BMS still reports
            self.get_logger().error(
                "BMS: cell 7 voltage read failed (SMBus CRC mismatch), using the pack estimate"
            )
        self.soc -= self.current * 16.0 / 3600.0 / 1200.0
        b = BatteryState(
            voltage=14.0 + 2.6 * self.soc,
            current=-self.current,
            percentage=self.soc,
            present=True,
            power_supply_status=BatteryState.POWER_SUPPLY_STATUS_DISCHARGING,
        )
        b.header.stamp = self.get_clock().now().to_msg()
        self.pub.publish(b)
        level = WARN if self.soc < 0.3 else OK
        self.publish_diagnostics(
            self.status(
                "battery",
                "bms-4s-smbus",
                level,
                "OK" if level == OK else "low",
                soc=f"{self.soc * 100:.1f}",
                current_a=f"{self.current:.1f}",
            )
        )


class LeakDetector(AuvNode):
    """The leak probes in the main and battery tubes on GPIO: /auv/leak (Bool, latched, on change);
    a self test service ``/auv/leak_detector/self_test``."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("leak_detector", "auv", fault_dir)
        self.declare_parameter("gpio_pins", [27, 22])
        self.pub = self.create_publisher(Bool, "/auv/leak", LATCHED)
        self.create_service(Trigger, "/auv/leak_detector/self_test", self.on_test)
        self.pub.publish(Bool(data=False))
        self.create_timer(1.0, self.on_second)

    def on_test(self, request, response):
        response.success, response.message = True, "probes 27, 22 dry, pull-ups OK"
        return response

    def on_second(self) -> None:
        self.publish_diagnostics(
            self.status("leak_probes", "gpio-27-22", OK, "dry", main_tube="dry", battery_tube="dry")
        )


class DiagnosticAggregator(AuvNode):
    """/diagnostics grouped by analyzer into /diagnostics_agg at 1 Hz (STALE after 5 s)."""

    GROUPS: ClassVar[dict[str, str]] = {
        "ahrs_driver": "/auv/sensors/ahrs",
        "dvl_driver": "/auv/sensors/dvl",
        "pressure_driver": "/auv/sensors/depth",
        "gps_driver": "/auv/sensors/gps",
        "usbl_receiver": "/auv/sensors/usbl",
        "multibeam_driver": "/auv/payload",
        "camera_driver": "/auv/payload",
        "coverage_monitor": "/auv/payload",
        "ekf_filter": "/auv/navigation",
        "depth_heading_controller": "/auv/control",
        "thruster_driver": "/auv/control",
        "battery_monitor": "/auv/power",
        "leak_detector": "/auv/safety",
        "acoustic_modem": "/auv/comms",
        "telemetry_bridge": "/auv/comms",
    }

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("diagnostic_aggregator", "auv", fault_dir)
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
            group = self.GROUPS.get(name.split(":")[0], "/auv/other")
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


# --- comms --------------------------------------------------------------------------------------------


class AcousticModem(AuvNode):
    """The acoustic modem (a 32-byte status every 5 s while submerged, /comms/modem/tx; the topside's
    short commands, every 8-15 s, /comms/modem/rx); silent on the surface (the radio takes over)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("acoustic_modem", "comms", fault_dir)
        self.declare_parameter("port", "/dev/ttyUSB1")
        self.declare_parameter("address", 2)
        self.tx_pub = self.create_publisher(String, "/comms/modem/tx", RELIABLE)
        self.rx_pub = self.create_publisher(String, "/comms/modem/rx", RELIABLE)
        self.create_subscription(Odometry, "/nav/odometry", self.on_odom, SENSOR)
        self.create_subscription(BatteryState, "/auv/battery", self.on_battery, RELIABLE)
        self.create_subscription(String, "/mission/state", self.on_mission, LATCHED)
        self.pose = None
        self.soc = 0.0
        self.mission = "?"
        self.sent = self.received = 0
        self.rx_at = time.monotonic() + self.rng.uniform(8.0, 15.0)
        self.create_timer(5.0, self.transmit)
        self.create_timer(0.5, self.listen)
        self.create_timer(1.0, self.on_second)

    def on_odom(self, msg: Odometry) -> None:
        self.pose = msg.pose.pose.position

    def on_battery(self, msg: BatteryState) -> None:
        self.soc = msg.percentage

    def on_mission(self, msg: String) -> None:
        self.mission = msg.data

    def submerged(self) -> bool:
        return self.pose is not None and -self.pose.z > 1.0

    def transmit(self) -> None:
        if not self.submerged():
            return
        p = self.pose
        self.tx_pub.publish(
            String(data=f"$S,{p.x:.0f},{p.y:.0f},{-p.z:.1f},{self.soc * 100:.0f},{self.mission[:4]}")
        )
        self.sent += 1

    def listen(self) -> None:
        if time.monotonic() < self.rx_at:
            return
        self.rx_at = time.monotonic() + self.rng.uniform(8.0, 15.0)
        if not self.submerged():
            return
        if self.rng.random() < 0.15:
            self.get_logger().warn("Acoustic packet dropped: CRC error (multipath)")
            return
        self.rx_pub.publish(String(data="$C,PING"))
        self.received += 1

    def on_second(self) -> None:
        self.publish_diagnostics(
            self.status("modem_link", "modem-m64-ttyUSB1", OK, "OK", sent=self.sent, received=self.received)
        )


class TelemetryBridge(AuvNode):
    """The tether/radio telemetry bridge: subscribes to the topics the topside wants, queues them and
    sends a 1 Hz digest down the link (/comms/telemetry, JSON) plus the operator's view of the
    diagnostics; its outbound queue is drained each second."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("telemetry_bridge", "comms", fault_dir)
        self.declare_parameter("link", "fibre-tether")
        self.declare_parameter("rate_hz", 1.0)
        self.pub = self.create_publisher(String, "/comms/telemetry", RELIABLE)
        self.latest: dict[str, object] = {}
        self.queue: deque = deque()
        subs = (
            ("/nav/odometry", Odometry, SENSOR),
            ("/nav/status", String, LATCHED),
            ("/mission/state", String, LATCHED),
            ("/auv/battery", BatteryState, RELIABLE),
            ("/auv/leak", Bool, LATCHED),
            ("/payload/coverage", Float32, RELIABLE),
            ("/sensors/gps/fix", NavSatFix, SENSOR),
            ("/sensors/dvl/altitude", Range, SENSOR),
            ("/control/thrusters/state", JointState, SENSOR),
            ("/comms/modem/rx", String, RELIABLE),
            ("/diagnostics_toplevel_state", DiagnosticStatus, RELIABLE),
        )
        for topic, typ, qos in subs:
            self.create_subscription(typ, topic, lambda m, t=topic: self.on_msg(t, m), qos)
        self.create_timer(1.0, self.send)

    def on_msg(self, topic: str, msg) -> None:
        self.latest[topic] = msg
        self.queue.append(topic)

    def send(self) -> None:
        digest = {}
        odom = self.latest.get("/nav/odometry")
        if odom is not None:
            p = odom.pose.pose.position
            digest["pos"] = [round(p.x, 1), round(p.y, 1), round(-p.z, 1)]
        for topic in ("/nav/status", "/mission/state"):
            if topic in self.latest:
                digest[topic] = self.latest[topic].data
        if "/auv/battery" in self.latest:
            digest["soc"] = round(self.latest["/auv/battery"].percentage * 100, 1)
        if "/payload/coverage" in self.latest:
            digest["coverage"] = round(self.latest["/payload/coverage"].data, 1)
        alt = self.latest.get("/sensors/dvl/altitude")
        digest["altitude"] = round(alt.range, 1) if alt is not None and math.isfinite(alt.range) else None
        digest["queued"] = len(self.queue)
        self.pub.publish(String(data=json.dumps(digest)))
        self.queue.clear()
        self.publish_diagnostics(
            self.status("link", "tether-fibre-0", OK, "OK", digest_bytes=len(json.dumps(digest)))
        )


class BagRecorder(Node):
    """``ros2 bag record`` of the mission topics (serialized, as it does): it subscribes to each
    topic of its list once a publisher shows up and splits the bag every 60 s."""

    TOPICS: ClassVar[dict[str, tuple[type, QoSProfile]]] = {
        "/nav/odometry": (Odometry, SENSOR),
        "/nav/status": (String, LATCHED),
        "/sensors/usbl/fix": (PoseWithCovarianceStamped, RELIABLE),
        "/sensors/gps/fix": (NavSatFix, SENSOR),
        "/sensors/dvl/twist": (TwistWithCovarianceStamped, SENSOR),
        "/payload/multibeam/bathymetry": (PointCloud2, SENSOR),
        "/mission/state": (String, LATCHED),
        "/mission/current_line": (PathMsg, LATCHED),
        "/control/setpoint": (PoseStamped, SENSOR),
        "/auv/battery": (BatteryState, SENSOR),
        "/auv/leak": (Bool, LATCHED),
        "/comms/modem/tx": (String, SENSOR),
        "/comms/modem/rx": (String, SENSOR),
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


# --- the topside operator's console -------------------------------------------------------------------


class OperatorConsole(AuvNode):
    """The topside console over the tether: watches the telemetry digest and the aggregated
    diagnostics, asks the executive for a report every 10 s (``/mission/report``) and, 5 s after it
    connects, sets the controller's ``cruise_speed`` (0.9, 1.0 or 1.2 m/s) through its parameter
    service."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("operator_console", "topside", fault_dir)
        self.params = self.create_client(SetParameters, "/control/depth_heading_controller/set_parameters")
        self.report = self.create_client(Trigger, "/mission/report")
        self.create_subscription(String, "/comms/telemetry", self.on_telemetry, RELIABLE)
        self.create_subscription(DiagnosticArray, "/diagnostics_agg", self.on_diag, RELIABLE)
        self.speed_at = time.monotonic() + 5.0
        self.report_at = time.monotonic() + 2.0
        self.pending = None
        self.level = 0
        self.digest = ""
        self.get_logger().info("Topside console connected over the tether")
        self.create_timer(0.2, self.tick)

    def on_telemetry(self, msg: String) -> None:
        self.digest = msg.data

    def on_diag(self, msg: DiagnosticArray) -> None:
        level = max((s.level[0] if isinstance(s.level, bytes) else s.level for s in msg.status), default=0)
        if level >= 2 and self.level < 2:
            self.get_logger().warn("The vehicle reports an ERROR in its diagnostics")
        self.level = level

    def tick(self) -> None:
        now = time.monotonic()
        if self.speed_at is not None and now >= self.speed_at and self.params.service_is_ready():
            self.speed_at = None
            speed = random.choice((0.9, 1.0, 1.2))
            self.get_logger().info(f"Setting the cruise speed to {speed:.1f} m/s")
            self.params.call_async(
                SetParameters.Request(parameters=[Parameter("cruise_speed", value=speed).to_parameter_msg()])
            )
        if self.pending is not None:
            sent, fut = self.pending
            if fut.done():
                self.pending = None
                self.get_logger().info(f"Vehicle report: {fut.result().message}")
            elif now - sent > 5.0:
                self.report.remove_pending_request(fut)
                self.pending = None
                self.get_logger().warn("No answer to the report request in 5 s")
        elif now >= self.report_at and self.report.service_is_ready():
            self.report_at = now + 10.0
            self.pending = (now, self.report.call_async(Trigger.Request()))


# --- processes ----------------------------------------------------------------------------------------


PROCESSES = {  # process -> its nodes
    "sim": lambda d: [VehicleSimulator(d)],
    "ahrs": lambda d: [AhrsDriver(d)],
    "dvl": lambda d: [DvlDriver(d)],
    "depth": lambda d: [PressureDriver(d)],
    "positioning": lambda d: [GpsDriver(d), UsblReceiver(d)],
    "payload_drivers": lambda d: [MultibeamDriver(d), CameraDriver(d)],
    "payload_container": lambda d: [BathymetryProcessor(d), ImageEnhancer(d), CoverageMonitor(d)],
    "navigation": lambda d: [EkfFilter(d), NavsatTransform(d)],
    "control": lambda d: [DepthHeadingController(d), ThrusterAllocator(d)],
    "thrusters": lambda d: [ThrusterDriver(d)],
    "planner": lambda d: [SurveyPlanner(d)],
    "mission": lambda d: [MissionExecutive(d), BehaviorServer(d)],
    "health": lambda d: [BatteryMonitor(d), LeakDetector(d), DiagnosticAggregator(d)],
    "comms": lambda d: [AcousticModem(d), TelemetryBridge(d)],
    "recorder": lambda d: [BagRecorder(d)],
    "operator": lambda d: [OperatorConsole(d)],
}
MULTI_THREADED = {"mission": 4}  # process -> threads (its actions block in their execute callbacks)


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
