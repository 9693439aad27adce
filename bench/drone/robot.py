"""A quadrotor's companion computer, plain rclpy: ``python -m bench.drone.robot PROCESS FAULT_DIR [RUN_FOR]``.

Written the way a drone team's companion-computer stack looks (see `bench.drone.run` for the
whole robot, its healthy dynamics and its faults): a PX4 bridge under ``/fmu`` whose serial
reader thread publishes the flight controller's IMU (200 Hz) and odometry (100 Hz) best effort;
a camera driver with its capture thread; a rangefinder whose stamps come from its own clock
(0.3 s behind the computer's); a visual-inertial odometry estimator on a multi-threaded executor
(images in a reentrant callback group, IMU in a mutually exclusive one); a perception container
(one single-threaded executor: obstacle detector, height synchronizer, precision-landing
lifecycle node); a mapper with periodic loop-closure optimisation; a flight process (mission
action server and offboard controller, multi-threaded executor); a safety process (geofence,
heartbeat watchdog, battery monitor); a telemetry downlink; the diagnostics aggregator and
system monitor; and a ground station that comes and goes.

No px4_msgs / mavros_msgs / example_interfaces / tf2_msgs in this environment: vehicle commands
are std_msgs/String (``ARM``, ``OFFBOARD``, ``LAND`` ...), the vehicle status a std_msgs/String
of ``key=value`` pairs, the mission action test_msgs/Fibonacci (goal ``order`` = the mission's
duration in s, feedback ``sequence`` = [elapsed s, waypoint, percent]), heartbeats std_msgs/Header
(``frame_id`` = the sender's fully qualified node name).

Faults come from files: ``FAULT_DIR/<namespace>.<node>`` (``vio.estimator``) holding a word the
target node acts on (``hang``, ``degrade``, ``slow``, ``skew``, ``reliable``, ``errlog``,
``die``), read by the process's watcher thread every 0.5 s; ``FAULT_DIR/<process>.cpu`` starts a
thread burning a core in that process, ``<process>.leak`` one leaking 3 MB/s. Crashes are SIGKILLs
from outside. RUN_FOR > 0 ends the process cleanly (exit 0) after that many seconds.
"""

from __future__ import annotations

import math
import random
import socket
import sys
import threading
import time
from collections import deque
from pathlib import Path
from typing import ClassVar

import numpy as np
import rclpy
from action_msgs.msg import GoalStatus
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState
from nav_msgs.msg import OccupancyGrid, Odometry
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import BatteryState, CameraInfo, Image, Imu, LaserScan, Range
from std_msgs.msg import Header, String
from test_msgs.action import Fibonacci  # stands in for a mission action

from stream_viz.demo.child import burn, leak

OK, WARN, ERROR, STALE = (DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR,
                          DiagnosticStatus.STALE)
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
BEST_EFFORT = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
RELIABLE = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
RANGEFINDER_CLOCK_OFFSET = 0.3  # the rangefinder's own clock runs this far behind the computer's
PAD = (0.0, 0.0)  # the landing pad, in the local frame
LEAK_MB_S = 3.0  # a cache never trimmed


def now_s() -> float:
    return time.time()


def to_stamp(t: float):
    from builtin_interfaces.msg import Time
    sec = int(t)
    return Time(sec=sec, nanosec=int((t - sec) * 1e9))


def secs(stamp) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


# --- fault hooks --------------------------------------------------------------------------------


def hook(node: Node, fault_dir: Path) -> None:
    """Give ``node`` the bench's fault hooks: ``fault`` (the word in its fault file
    ``FAULT_DIR/<namespace>.<name>``) and ``on_fault(word)`` run in the node's executor when it
    changes (through a guard condition the watcher thread triggers)."""
    node.fault_file = fault_dir / f"{node.get_namespace().strip('/').replace('/', '.')}.{node.get_name()}"
    node.fault = None
    node.fault_set = node.create_guard_condition(lambda: node.on_fault(node.fault),
                                                 callback_group=MutuallyExclusiveCallbackGroup())


class DroneNode(Node):
    """A node of the drone: fault hooks, a heartbeat and diagnostic_updater-style statuses."""

    def __init__(self, name: str, namespace: str, fault_dir: Path, **kw) -> None:
        super().__init__(name, namespace=namespace, **kw)
        hook(self, fault_dir)
        self.rng = random.Random()
        self._heartbeat_pub = None
        self._diag_pub = None

    def on_fault(self, fault: str | None) -> None:
        pass

    def heartbeat(self, callback_group=None) -> None:
        """A 1 Hz heartbeat on /heartbeat, from a timer of this node."""
        self._heartbeat_pub = self.create_publisher(Header, "/heartbeat", RELIABLE)
        self.create_timer(1.0, self._beat, callback_group=callback_group)

    def _beat(self) -> None:
        self._heartbeat_pub.publish(Header(stamp=self.get_clock().now().to_msg(),
                                           frame_id=self.get_fully_qualified_name()))

    def status(self, task: str, hardware_id: str, level: bytes = OK, message: str = "OK",
               **values) -> DiagnosticStatus:
        kvs = [KeyValue(key=k, value=str(v)) for k, v in values.items()]
        return DiagnosticStatus(level=level, name=f"{self.get_name()}: {task}", hardware_id=hardware_id,
                                message=message, values=kvs)

    def publish_diagnostics(self, *statuses: DiagnosticStatus) -> None:
        if self._diag_pub is None:
            self._diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", RELIABLE)
        arr = DiagnosticArray(status=list(statuses))
        arr.header.stamp = self.get_clock().now().to_msg()
        self._diag_pub.publish(arr)


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
            if word != n.fault:
                n.fault = word
                n.fault_set.trigger()
        for how, target, arg in (("cpu", burn, 1.0), ("leak", leak, LEAK_MB_S)):
            if how not in started and (fault_dir / f"{process}.{how}").exists():
                started.add(how)  # the demo's own burner and leak, until the process ends
                threading.Thread(target=target, args=(threading.Event(), arg), daemon=True, name=how).start()


def alive() -> bool:
    return rclpy.ok()


def published(*sends: tuple) -> bool:
    """Publish each ``(publisher, message)`` from a thread of ours; False once the context is
    going down (the thread then ends), any other failure raised."""
    try:
        for pub, msg in sends:
            pub.publish(msg)
    except Exception:
        if alive():
            raise
        return False
    return True


# --- the flight controller bridge ------------------------------------------------------------------


class FcBridge(DroneNode):
    """The PX4 bridge (micro XRCE-DDS agent + the team's translation node): a serial reader thread
    receives the flight controller's sensor_combined at 200 Hz and its odometry at 100 Hz and
    publishes them best effort; the vehicle status (1 Hz and on change), the battery (1 Hz),
    diagnostics and a heartbeat from timers. The vehicle itself (its dynamics) is simulated in the
    reader thread: it follows the offboard setpoints while in OFFBOARD, falls back to HOLD when
    the setpoint stream stops (PX4's offboard-loss failsafe), lands in AUTO_LAND and disarms."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("fc_bridge", "fmu", fault_dir)
        self.declare_parameter("device", "/dev/ttyTHS1")
        self.declare_parameter("baudrate", 921600)
        self.declare_parameter("offboard_timeout", 0.5)
        self.imu_pub = self.create_publisher(Imu, "/fmu/out/imu", BEST_EFFORT)
        self.odom_pub = self.create_publisher(Odometry, "/fmu/out/odometry", BEST_EFFORT)
        self.status_pub = self.create_publisher(String, "/fmu/status", RELIABLE)
        self.battery_pub = self.create_publisher(BatteryState, "/fmu/battery", RELIABLE)
        self.create_subscription(String, "/fmu/in/vehicle_command", self.on_command, RELIABLE)
        self.create_subscription(PoseStamped, "/fmu/in/trajectory_setpoint", self.on_setpoint, BEST_EFFORT)
        self.lock = threading.Lock()
        self.pos = [0.0, 0.0, 0.0]
        self.vel = [0.0, 0.0, 0.0]
        self.acc = [0.0, 0.0, 0.0]
        self.yaw = 0.0
        self.sp = None
        self.sp_at = -1e9
        self.armed, self.nav_state, self.failsafe = False, "POSCTL", False
        self.battery = 96.0
        self.imu_count = 0
        self.imu_rate = 0.0
        self.status_changed = False
        self.imu_msg = Imu()  # reused: the reader thread fills and publishes one at a time
        self.imu_msg.header.frame_id, self.imu_msg.orientation.w = "base_link", 1.0
        self.odom_msg = Odometry()
        self.odom_msg.header.frame_id, self.odom_msg.child_frame_id = "odom", "base_link"
        self.odom_msg.pose.pose.orientation.w = 1.0
        self.get_logger().info("Connected to the flight controller on /dev/ttyTHS1 @ 921600 (PX4 v1.15.2)")
        self.get_logger().info("Timesync converged: offset to the FMU 412 us")
        self.create_timer(1.0, self.on_second)
        self.create_timer(0.1, self.on_status_change)
        self.heartbeat()
        threading.Thread(target=self.reader, daemon=True, name="serial").start()

    def on_command(self, msg: String) -> None:
        cmd = msg.data.split()[0] if msg.data else ""
        with self.lock:
            if cmd == "ARM":
                self.armed = True
                if self.nav_state == "AUTO_LAND":  # landed: arms in Hold
                    self.nav_state = "AUTO_LOITER"
                self.get_logger().info("Armed by external command")
            elif cmd == "DISARM":
                self.armed = False
            elif cmd == "OFFBOARD":
                if time.monotonic() - self.sp_at > 0.5:
                    self.get_logger().warn("Switching to Offboard rejected: no offboard setpoint stream")
                    return
                self.nav_state, self.failsafe = "OFFBOARD", False
                self.get_logger().info("Mode switch: OFFBOARD")
            elif cmd == "LAND":
                self.nav_state = "AUTO_LAND"
                self.get_logger().info("Mode switch: AUTO_LAND")
            elif cmd == "HOLD":
                self.nav_state = "AUTO_LOITER"
            self.status_changed = True

    def on_setpoint(self, msg: PoseStamped) -> None:
        with self.lock:
            self.sp = (msg.pose.position.x, msg.pose.position.y, msg.pose.position.z)
            self.sp_at = time.monotonic()

    def reader(self) -> None:
        """The serial link: a sensor_combined sample every 5 ms, odometry every other one."""
        period, n = 0.005, 0
        nxt = time.monotonic()
        while alive():
            nxt += period
            delay = nxt - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            elif delay < -0.1:
                nxt = time.monotonic()
            n += 1
            self.step(period)
            try:
                # a saturated link drops 2 of 5 sensor_combined messages: 120 Hz
                if not (self.fault == "degrade" and n % 5 in (1, 3)):
                    self.publish_imu()
                if n % 2 == 0:
                    self.publish_odom()
            except Exception:
                if not alive():
                    return
                raise

    def step(self, dt: float) -> None:
        with self.lock:
            now = time.monotonic()
            if self.nav_state == "OFFBOARD" and now - self.sp_at > 0.5:
                self.nav_state, self.failsafe = "AUTO_LOITER", True
                self.status_changed = True
                self.get_logger().warn("Failsafe activated: offboard control signal lost, switching to Hold")
            acc = [0.0, 0.0, 0.0]
            if self.armed:
                if self.nav_state == "OFFBOARD" and self.sp is not None:
                    target = self.sp
                elif self.nav_state == "AUTO_LAND":
                    target = (self.pos[0], self.pos[1], -0.5)
                else:
                    target = tuple(self.pos)
                for i in range(3):
                    a = 1.2 * (target[i] - self.pos[i]) - 1.8 * self.vel[i]
                    acc[i] = max(-4.0, min(4.0, a))
                    self.vel[i] += acc[i] * dt
                    self.pos[i] += self.vel[i] * dt
                if self.pos[2] <= 0.0:
                    self.pos[2], self.vel[2] = 0.0, max(0.0, self.vel[2])
                    if self.nav_state == "AUTO_LAND":
                        self.armed, self.vel = False, [0.0, 0.0, 0.0]
                        self.nav_state = "AUTO_LAND"
                        self.status_changed = True
                        self.get_logger().info("Landing detected, disarmed")
            self.acc = acc

    def publish_imu(self) -> None:
        m = self.imu_msg
        m.header.stamp = to_stamp(now_s())
        g = random.gauss
        m.linear_acceleration.x = self.acc[0] + g(0.0, 0.05)
        m.linear_acceleration.y = self.acc[1] + g(0.0, 0.05)
        m.linear_acceleration.z = 9.81 + self.acc[2] + g(0.0, 0.05)
        m.angular_velocity.x, m.angular_velocity.y, m.angular_velocity.z = g(0, 0.01), g(0, 0.01), g(0, 0.005)
        self.imu_pub.publish(m)
        self.imu_count += 1

    def publish_odom(self) -> None:
        m = self.odom_msg
        m.header.stamp = to_stamp(now_s())
        p, v = m.pose.pose.position, m.twist.twist.linear
        p.x, p.y, p.z = self.pos
        v.x, v.y, v.z = self.vel
        self.odom_pub.publish(m)

    def status_text(self) -> str:
        return (f"arming_state={'ARMED' if self.armed else 'STANDBY'} nav_state={self.nav_state} "
                f"failsafe={str(self.failsafe).lower()} battery={self.battery:.1f}")

    def on_status_change(self) -> None:
        if self.status_changed:
            self.status_changed = False
            self.status_pub.publish(String(data=self.status_text()))

    def on_second(self) -> None:
        self.imu_rate, self.imu_count = self.imu_count, 0
        self.battery -= 0.12 if self.armed else 0.005
        self.status_pub.publish(String(data=self.status_text()))
        b = BatteryState(voltage=14.0 + 2.6 * self.battery / 100.0, percentage=self.battery / 100.0,
                         current=-18.0 if self.armed else -0.9, present=True,
                         power_supply_status=BatteryState.POWER_SUPPLY_STATUS_DISCHARGING,
                         power_supply_technology=BatteryState.POWER_SUPPLY_TECHNOLOGY_LIPO)
        b.header.stamp = self.get_clock().now().to_msg()
        self.battery_pub.publish(b)
        self.publish_diagnostics(
            self.status("FCU connection", "px4_fmu-v6c", message="connected", mode=self.nav_state,
                        armed=self.armed, sensor_combined_hz=self.imu_rate, link="/dev/ttyTHS1"))


# --- sensors -----------------------------------------------------------------------------------------


class CameraDriver(DroneNode):
    """A global-shutter USB camera: 320x240 mono at 30 fps from its capture thread, best effort."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("camera_driver", "camera", fault_dir)
        self.declare_parameter("video_device", "/dev/video0")
        self.declare_parameter("framerate", 30.0)
        self.declare_parameter("pixel_format", "GREY")
        self.image_pub = self.create_publisher(Image, "/camera/image_raw", qos_profile_sensor_data)
        self.info_pub = self.create_publisher(CameraInfo, "/camera/camera_info", qos_profile_sensor_data)
        self.frames = []
        yy, xx = np.mgrid[0:240, 0:320]
        for k in range(4):
            checker = ((xx + 7 * k) // 16 + (yy + 3 * k) // 16) % 2 * 120
            pat = (checker + (xx * yy + k * 977) % 61).astype(np.uint8)
            self.frames.append(pat.tobytes())
        self.info = CameraInfo(height=240, width=320, distortion_model="plumb_bob")
        self.info.header.frame_id = "camera_optical"
        self.info.k = [261.0, 0.0, 160.0, 0.0, 261.0, 120.0, 0.0, 0.0, 1.0]
        self.info.d = [-0.28, 0.07, 0.0, 0.0, 0.0]
        self.info.p = [261.0, 0.0, 160.0, 0.0, 0.0, 261.0, 120.0, 0.0, 0.0, 0.0, 1.0, 0.0]
        self.sent = 0
        self.get_logger().info("Opened /dev/video0: 320x240 GREY @ 30 fps (global shutter)")
        self.heartbeat()
        self.create_timer(1.0, self.on_second)
        threading.Thread(target=self.capture, daemon=True, name="capture").start()

    def capture(self) -> None:
        period, k = 1.0 / 30.0, 0
        nxt = time.monotonic()
        while alive():
            nxt += period
            delay = nxt - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            elif delay < -0.5:
                nxt = time.monotonic()
            img = Image(height=240, width=320, encoding="mono8", is_bigendian=0, step=320)
            img.header.stamp, img.header.frame_id = self.get_clock().now().to_msg(), "camera_optical"
            img.data = self.frames[k % len(self.frames)]
            k += 1
            self.info.header.stamp = img.header.stamp
            if not published((self.image_pub, img), (self.info_pub, self.info)):
                return
            self.sent += 1

    def on_second(self) -> None:
        fps, self.sent = self.sent, 0
        self.publish_diagnostics(self.status("Frame rate", "/dev/video0", frames_per_second=fps,
                                             exposure_us=3500 + self.rng.randint(-200, 200)))


class Rangefinder(DroneNode):
    """A downward TFmini-S lidar on a UART: 30 Hz ranges best effort, stamped by the device's own
    clock (free-running, 0.3 s behind the computer's; the synchronizer corrects it)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("tfmini", "rangefinder", fault_dir)
        self.declare_parameter("port", "/dev/ttyUSB0")
        self.declare_parameter("frame_id", "rangefinder_link")
        self.pub = self.create_publisher(Range, "/rangefinder/range", qos_profile_sensor_data)
        self.height = 0.08
        self.get_logger().info("TFmini-S on /dev/ttyUSB0: firmware 2.1.6, 30 Hz")
        threading.Thread(target=self.reader, daemon=True, name="uart").start()

    def reader(self) -> None:
        period = 1.0 / 30.0
        nxt = time.monotonic()
        while alive():
            nxt += period
            delay = nxt - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            elif delay < -0.5:
                nxt = time.monotonic()
            # the device's clock: a free-running counter; its clock jumps 2 s back after a brown-out
            offset = RANGEFINDER_CLOCK_OFFSET + (2.0 if self.fault == "skew" else 0.0)
            m = Range(radiation_type=Range.INFRARED, field_of_view=0.035, min_range=0.1, max_range=12.0)
            m.header.stamp = to_stamp(now_s() - offset + random.uniform(-0.001, 0.001))
            m.header.frame_id = "rangefinder_link"
            self.height = max(0.1, self.height + random.gauss(0.0, 0.01))
            m.range = self.height if self.height < 12.0 else float("inf")
            if not published((self.pub, m)):
                return


# --- visual-inertial odometry (multi-threaded executor) ------------------------------------------


class VioEstimator(DroneNode):
    """A VIO front end + back end: images in a reentrant callback group (the pyramid is built in
    parallel, the tracker itself is one lock: a frame that finds it busy is dropped), the IMU
    pre-integration in a mutually exclusive group, housekeeping (diagnostics, heartbeat) in a third.
    Dropped frames are normal under load; a WARN only when tracking is starved (>= 80 % dropped).
    ``/vio/odometry`` at the camera rate, stamped with the frame's stamp."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("estimator", "vio", fault_dir)
        self.declare_parameter("max_features", 150)
        self.declare_parameter("imu_rate", 200)
        self.declare_parameter("camera_imu_time_offset", 0.0)
        self.image_group = ReentrantCallbackGroup()
        self.imu_group = MutuallyExclusiveCallbackGroup()
        self.house_group = MutuallyExclusiveCallbackGroup()
        self.odom_pub = self.create_publisher(Odometry, "/vio/odometry", RELIABLE)
        self.create_subscription(Image, "/camera/image_raw", self.on_image, qos_profile_sensor_data,
                                 callback_group=self.image_group)
        self.create_subscription(Imu, "/fmu/out/imu", self.on_imu, qos_profile_sensor_data,
                                 callback_group=self.imu_group)
        self.tracker = threading.Lock()
        self.state_lock = threading.Lock()
        self.vel = [0.0, 0.0, 0.0]
        self.pos = [0.0, 0.0, 0.0]
        self.last_imu = None
        self.tracked_at = time.monotonic()
        self.tracked = self.dropped = 0
        self.drops = deque()
        self.warned_at = 0.0
        self.get_logger().info("VIO initialised: 150 features, IMU 200 Hz, camera 30 Hz")
        self.heartbeat(self.house_group)
        self.create_timer(1.0, self.on_second, callback_group=self.house_group)

    def on_imu(self, msg: Imu) -> None:
        t = secs(msg.header.stamp)
        with self.state_lock:
            if self.last_imu is not None:
                dt = min(0.05, max(0.0, t - self.last_imu))
                a = (msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z - 9.81)
                for i in range(3):
                    self.vel[i] = 0.995 * self.vel[i] + a[i] * dt
                    self.pos[i] += self.vel[i] * dt
            self.last_imu = t

    def on_image(self, msg: Image) -> None:
        t0 = time.perf_counter()
        img = np.frombuffer(msg.data, dtype=np.uint8).reshape(msg.height, msg.width).astype(np.float32)
        # the pyramid and the FAST corners of the new frame (parallel across frames)
        small = (img[0::2, 0::2] + img[1::2, 0::2] + img[0::2, 1::2] + img[1::2, 1::2]) * 0.25
        grad = np.abs(np.diff(small, axis=0))[:, :-1] + np.abs(np.diff(small, axis=1))[:-1, :]
        if not self.tracker.acquire(blocking=False):  # the tracker busy with an earlier frame: drop this one
            self.dropped += 1
            self.drops.append(time.monotonic())
            return
        try:
            if self.fault == "hang":  # the back end's solver deadlocks on the marginalisation mutex
                threading.Event().wait()
            # KLT tracking against the last keyframe and the sliding-window optimisation
            budget = min(0.020, 0.010 + random.expovariate(1.0 / 0.0015))  # s of this frame
            score = 0.0
            while time.perf_counter() - t0 < budget:
                gx = np.diff(img, axis=1)
                gy = np.diff(img, axis=0)
                score += float((gx[:-1, :] * gy[:, :-1]).mean()) + float(grad.mean())
            with self.state_lock:
                pos = list(self.pos)
                vel = list(self.vel)
            m = Odometry()
            m.header.stamp, m.header.frame_id, m.child_frame_id = msg.header.stamp, "odom", "base_link"
            p, v = m.pose.pose.position, m.twist.twist.linear
            p.x, p.y, p.z = pos
            v.x, v.y, v.z = vel
            m.pose.pose.orientation.w = 1.0
            self.odom_pub.publish(m)
            self.tracked += 1
            self.tracked_at = time.monotonic()
        finally:
            self.tracker.release()

    def on_second(self) -> None:
        now = time.monotonic()
        while self.drops and now - self.drops[0] > 5.0:
            self.drops.popleft()
        if len(self.drops) >= 120 and now - self.warned_at > 5.0:
            self.warned_at = now
            self.get_logger().warn(f"Tracker busy: dropped {len(self.drops)} frames in the last 5 s")
        since = now - self.tracked_at
        if since > 1.0:
            st = self.status("Tracking", "vio", WARN, f"no frame tracked for {since:.1f} s",
                             tracked_hz=self.tracked, dropped=self.dropped)
        else:
            st = self.status("Tracking", "vio", tracked_hz=self.tracked, dropped=self.dropped, features=150)
        self.tracked = self.dropped = 0
        self.publish_diagnostics(st)


# --- the perception container (single-threaded executor) ----------------------------------------


class ObstacleDetector(DroneNode):
    """Stereo-less obstacle detection from the camera's image gradients: every frame is examined,
    the obstacle distance (72 sectors, PX4's ObstacleDistance as a LaserScan) goes out at 10 Hz."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("obstacle_detector", "perception", fault_dir)
        self.declare_parameter("min_distance", 0.3)
        self.declare_parameter("max_distance", 20.0)
        self.pub = self.create_publisher(LaserScan, "/perception/obstacles", qos_profile_sensor_data)
        self.create_subscription(Image, "/camera/image_raw", self.on_image, qos_profile_sensor_data)
        self.n = 0
        self.ranges = [20.0] * 72

    def on_image(self, msg: Image) -> None:
        if self.fault == "hang":  # the inference call never returns (the TensorRT context deadlocks)
            threading.Event().wait()
        img = np.frombuffer(msg.data, dtype=np.uint8).reshape(msg.height, msg.width)
        cols = img[::8, ::8].astype(np.int16)
        edge = np.abs(np.diff(cols, axis=1)).mean(axis=0)
        self.n += 1
        if self.n % 3:
            return
        scan = LaserScan(angle_min=-math.pi, angle_max=math.pi - math.radians(5),
                         angle_increment=math.radians(5), range_min=0.3, range_max=20.0)
        scan.header.stamp, scan.header.frame_id = msg.header.stamp, "base_link"
        for i in range(72):
            e = float(edge[i % len(edge)])
            self.ranges[i] = 0.8 * self.ranges[i] + 0.2 * max(2.0, min(20.0, 400.0 / (1.0 + e)))
        scan.ranges = self.ranges
        self.pub.publish(scan)


class HeightSync(DroneNode):
    """Approximate-time synchronizer (message_filters' ApproximateTime, by hand): each VIO
    odometry paired with the rangefinder sample whose stamp, corrected by the rangefinder's clock
    offset, is within 20 ms; the pair goes out as a height-above-ground odometry."""

    SLOP = 0.020

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("height_sync", "perception", fault_dir)
        self.declare_parameter("slop", self.SLOP)
        self.declare_parameter("rangefinder_time_offset", RANGEFINDER_CLOCK_OFFSET)
        self.declare_parameter("queue_size", 20)
        self.pub = self.create_publisher(Odometry, "/perception/height_odometry", RELIABLE)
        self.create_subscription(Odometry, "/vio/odometry", self.on_odom, RELIABLE)
        self.range_sub = self.create_subscription(Range, "/rangefinder/range", self.on_range,
                                                  qos_profile_sensor_data)
        self.ranges: deque = deque(maxlen=20)
        self.paired_at = time.monotonic()
        self.closest = None
        self.range_at = self.odom_at = time.monotonic()
        self.warned_at = 0.0
        self.create_timer(1.0, self.check)

    def on_fault(self, fault: str | None) -> None:
        if fault == "reliable":  # the reloaded config asks for a reliable rangefinder subscription
            self.get_logger().info("Parameters reloaded from height_sync.yaml: re-creating subscriptions")
            self.destroy_subscription(self.range_sub)
            reliable = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)
            self.range_sub = self.create_subscription(Range, "/rangefinder/range", self.on_range, reliable)

    def on_range(self, msg: Range) -> None:
        self.range_at = time.monotonic()
        self.ranges.append((secs(msg.header.stamp) + RANGEFINDER_CLOCK_OFFSET, msg.range))

    def on_odom(self, msg: Odometry) -> None:
        self.odom_at = time.monotonic()
        t = secs(msg.header.stamp)
        best = min(self.ranges, key=lambda r: abs(r[0] - t), default=None)
        if best is None:
            return
        dt = abs(best[0] - t)
        if dt > self.SLOP:
            self.closest = dt if self.closest is None else min(self.closest, dt)
            return
        out = Odometry()
        out.header, out.child_frame_id = msg.header, msg.child_frame_id
        out.pose = msg.pose
        out.pose.pose.position.z = best[1]
        out.twist = msg.twist
        self.pub.publish(out)
        self.paired_at = time.monotonic()
        self.closest = None

    def check(self) -> None:
        now = time.monotonic()
        closest, self.closest = self.closest, None  # the closest miss of the last second
        if now - self.paired_at < 5.0 or now - self.warned_at < 10.0:
            return
        self.warned_at = now
        if now - self.odom_at > 5.0:
            why = f"no VIO odometry for {now - self.odom_at:.1f} s"
        elif now - self.range_at > 5.0:
            why = f"no rangefinder sample for {now - self.range_at:.1f} s"
        else:
            why = f"closest pair {closest:.3f} s apart (slop {self.SLOP:.3f} s)" if closest else "no pairs"
        since = now - self.paired_at
        self.get_logger().warn(f"No synchronized VIO/rangefinder pair for {since:.1f} s: {why}")


class PrecisionLanding(LifecycleNode):
    """The landing-pad (AprilTag) detector, a lifecycle node the mission manager configures at
    bring-up and activates for the final approach only: subscribed to the camera and the height
    odometry while active, the pad's pose out at 15 Hz (every other frame)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("precision_landing", namespace="perception")
        hook(self, fault_dir)
        self.declare_parameter("tag_family", "tag36h11")
        self.declare_parameter("tag_size", 0.40)
        self.pub = None
        self.subs = []
        self.n = 0
        self.height = 1.0

    def on_fault(self, fault: str | None) -> None:
        pass

    def on_configure(self, state) -> TransitionCallbackReturn:
        self.pub = self.create_lifecycle_publisher(PoseStamped, "/perception/landing_target", RELIABLE)
        self.get_logger().info("Configured: tag36h11, size 0.40 m")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        self.subs = [
            self.create_subscription(Image, "/camera/image_raw", self.on_image, qos_profile_sensor_data),
            self.create_subscription(Odometry, "/perception/height_odometry", self.on_height, RELIABLE)]
        self.get_logger().info("Activated: searching for the landing pad")
        return super().on_activate(state)

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        for s in self.subs:
            self.destroy_subscription(s)
        self.subs = []
        self.get_logger().info("Deactivated")
        return super().on_deactivate(state)

    def on_height(self, msg: Odometry) -> None:
        self.height = msg.pose.pose.position.z

    def on_image(self, msg: Image) -> None:
        self.n += 1
        if self.n % 2:
            return
        img = np.frombuffer(msg.data, dtype=np.uint8).reshape(msg.height, msg.width)
        cy, cx = np.unravel_index(int(np.argmax(img[::4, ::4])), (60, 80))
        p = PoseStamped()
        p.header.stamp, p.header.frame_id = msg.header.stamp, "camera_optical"
        p.pose.position.x = (cx * 4 - 160) / 261.0 * self.height
        p.pose.position.y = (cy * 4 - 120) / 261.0 * self.height
        p.pose.position.z = self.height
        p.pose.orientation.w = 1.0
        self.pub.publish(p)


# --- mapping ---------------------------------------------------------------------------------------


class Mapper(DroneNode):
    """The local map: VIO keyframes and the obstacle distances into an occupancy grid; a
    pose-graph loop-closure optimisation every ~30 s (1-2 s of CPU, on the node's only thread);
    the map latched (transient local) and published only when it changed."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("mapper", "mapping", fault_dir)
        self.declare_parameter("resolution", 0.1)
        self.declare_parameter("keyframe_distance", 0.5)
        self.declare_parameter("loop_closure_period", 30.0)
        self.map_pub = self.create_publisher(OccupancyGrid, "/mapping/map", LATCHED)
        self.create_subscription(Odometry, "/vio/odometry", self.on_odom, RELIABLE)
        self.create_subscription(LaserScan, "/perception/obstacles", self.on_obstacles,
                                 qos_profile_sensor_data)
        self.grid = np.full((200, 200), -1, dtype=np.int8)
        self.keyframes: list[tuple[float, float, float]] = []
        self.pose = (0.0, 0.0, 0.0)
        self.dirty = False
        self.optimized_kf = 0
        self.heartbeat()
        self.create_timer(5.0, self.publish_map)
        self.create_timer(1.0, self.on_second)
        self.closure = self.create_timer(random.uniform(25.0, 35.0), self.loop_closure)
        self.get_logger().info("Mapper ready: 200x200 cells at 0.10 m")

    def on_odom(self, msg: Odometry) -> None:
        p = msg.pose.pose.position
        self.pose = (p.x, p.y, p.z)
        if p.z < 0.3:
            return  # on the ground: no keyframes
        last = self.keyframes[-1] if self.keyframes else None
        if last is None or math.dist(last, self.pose) > 0.5:
            self.keyframes.append(self.pose)

    def on_obstacles(self, msg: LaserScan) -> None:
        if self.pose[2] < 0.3:
            return
        x, y = self.pose[0], self.pose[1]
        for i in range(0, len(msg.ranges), 6):
            a = msg.angle_min + i * msg.angle_increment
            r = min(msg.ranges[i], 8.0)
            cx, cy = int(100 + (x + r * math.cos(a)) * 10), int(100 + (y + r * math.sin(a)) * 10)
            if 0 <= cx < 200 and 0 <= cy < 200 and self.grid[cy, cx] != 100:
                self.grid[cy, cx] = 100
                self.dirty = True

    def loop_closure(self) -> None:
        self.closure.cancel()
        self.closure = self.create_timer(random.uniform(25.0, 35.0), self.loop_closure)
        n = len(self.keyframes)
        t0 = time.perf_counter()
        budget = random.uniform(1.0, 2.0)
        rng = np.random.default_rng()
        a = rng.standard_normal((160, 160))
        h = a @ a.T + 160 * np.eye(160)
        iters = 0
        while time.perf_counter() - t0 < budget:  # Gauss-Newton on the pose graph, in Python
            b = rng.standard_normal(160)
            x = np.linalg.solve(h, b)
            for _ in range(200):
                x = x * 0.999 + 1e-4
            iters += 1
        if n > self.optimized_kf:
            self.optimized_kf = n
            self.dirty = True
        self.get_logger().info(f"Loop closure: optimized {n} keyframes in {time.perf_counter() - t0:.2f} s "
                               f"({iters} iterations)")

    def publish_map(self) -> None:
        if not self.dirty:
            return
        self.dirty = False
        g = OccupancyGrid()
        g.header.stamp, g.header.frame_id = self.get_clock().now().to_msg(), "odom"
        g.info.map_load_time, g.info.resolution, g.info.width, g.info.height = g.header.stamp, 0.1, 200, 200
        g.info.origin.position.x = g.info.origin.position.y = -10.0
        g.info.origin.orientation.w = 1.0
        g.data = self.grid.tobytes()
        self.map_pub.publish(g)

    def on_second(self) -> None:
        known = int((self.grid >= 0).sum())
        self.publish_diagnostics(self.status("Map", "mapper", keyframes=len(self.keyframes),
                                             known_cells=known))


# --- the flight process: mission manager and offboard controller (multi-threaded executor) -------


class MissionManager(DroneNode):
    """The mission action server (``/mission/execute``): takes off in OFFBOARD, flies a survey
    pattern through its waypoints, activates the precision-landing detector for the final 20 s
    approach to the pad, lands. Feedback at 5 Hz while a mission runs. Configures the detector
    at bring-up (lifecycle ``change_state``)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("mission_manager", "mission", fault_dir)
        self.declare_parameter("cruise_altitude", 4.0)
        self.declare_parameter("landing_approach_s", 20.0)
        self.group = ReentrantCallbackGroup()
        self.server = ActionServer(self, Fibonacci, "/mission/execute", self.execute,
                                   goal_callback=self.on_goal,
                                   cancel_callback=lambda _: CancelResponse.ACCEPT,
                                   callback_group=self.group)
        self.waypoint_pub = self.create_publisher(PoseStamped, "/mission/waypoint", LATCHED)
        self.command_pub = self.create_publisher(String, "/fmu/in/vehicle_command", RELIABLE)
        self.create_subscription(String, "/fmu/status", self.on_status, RELIABLE)
        self.landing = self.create_client(ChangeState, "/perception/precision_landing/change_state",
                                          callback_group=self.group)
        self.nav_state = "UNKNOWN"
        self.armed = False
        self.busy = False
        self.configured = False
        self.missions = 0
        self.heartbeat()
        self.bringup = self.create_timer(1.0, self.configure_landing)
        self.create_timer(1.0, self.on_second)
        self.set_waypoint(0.0, 0.0, 0.0)

    def on_status(self, msg: String) -> None:
        kv = dict(p.split("=", 1) for p in msg.data.split() if "=" in p)
        self.nav_state = kv.get("nav_state", self.nav_state)
        self.armed = kv.get("arming_state") == "ARMED"

    def configure_landing(self) -> None:
        if self.configured or not self.landing.service_is_ready():
            return
        self.configured = True
        self.bringup.cancel()
        self.landing.call_async(ChangeState.Request(transition=Transition(id=Transition.TRANSITION_CONFIGURE)))
        self.get_logger().info("Precision landing detector configured")

    def transition(self, tid: int, label: str) -> bool:
        if not self.landing.service_is_ready():
            self.get_logger().error(f"Precision landing: change_state unavailable ({label})")
            return False
        done = threading.Event()
        fut = self.landing.call_async(ChangeState.Request(transition=Transition(id=tid)))
        fut.add_done_callback(lambda _: done.set())
        if not done.wait(2.0) or not fut.result() or not fut.result().success:
            self.get_logger().error(f"Precision landing: {label} failed")
            return False
        return True

    def on_goal(self, request) -> GoalResponse:
        if self.fault == "slow":  # the mission planner's geofence/terrain check runs on a cold cache
            time.sleep(4.0)
        if self.busy:
            self.get_logger().warn("Rejecting mission: another mission is running")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def set_waypoint(self, x: float, y: float, z: float) -> None:
        p = PoseStamped()
        p.header.stamp, p.header.frame_id = self.get_clock().now().to_msg(), "odom"
        p.pose.position.x, p.pose.position.y, p.pose.position.z = x, y, z
        p.pose.orientation.w = 1.0
        self.waypoint_pub.publish(p)

    def command(self, cmd: str) -> None:
        self.command_pub.publish(String(data=cmd))

    def execute(self, goal_handle):
        self.busy = True
        self.missions += 1
        mid = self.missions
        try:
            return self.fly(goal_handle, mid)
        except Exception:
            if alive():
                raise
            return Fibonacci.Result(sequence=[mid, 0])
        finally:
            self.busy = False

    def abort(self, goal_handle, mid: int, why: str):
        self.get_logger().error(f"Mission {mid} aborted: {why}")
        self.command("LAND")
        self.set_waypoint(PAD[0], PAD[1], 0.0)
        goal_handle.abort()
        return Fibonacci.Result(sequence=[mid, 0])

    def fly(self, goal_handle, mid: int):
        duration = max(30, int(goal_handle.request.order))
        alt = self.get_parameter("cruise_altitude").value
        approach = self.get_parameter("landing_approach_s").value
        self.get_logger().info(f"Mission {mid} started: survey, {duration} s")
        self.set_waypoint(PAD[0], PAD[1], alt)
        self.command("ARM")
        time.sleep(0.3)
        self.command("OFFBOARD")
        t0 = time.monotonic()
        while self.nav_state != "OFFBOARD" or not self.armed:
            if time.monotonic() - t0 > 3.0:
                return self.abort(goal_handle, mid, f"vehicle did not enter OFFBOARD ({self.nav_state})")
            time.sleep(0.1)
        legs = [(6.0, 0.0), (6.0, 6.0), (-6.0, 6.0), (-6.0, -2.0), PAD]
        survey = duration - approach
        active = False
        leg = -1
        t0 = time.monotonic()
        while True:
            if self.fault == "slow":  # trajectory generation stalls on the terrain query
                time.sleep(10.0)
                return self.abort(goal_handle, mid, "trajectory generation timed out after 10.0 s")
            elapsed = time.monotonic() - t0
            if elapsed >= duration:
                break
            if self.nav_state != "OFFBOARD":
                if active:
                    self.transition(Transition.TRANSITION_DEACTIVATE, "deactivate")
                return self.abort(goal_handle, mid, f"vehicle left OFFBOARD ({self.nav_state})")
            if elapsed < survey:
                k = min(len(legs) - 2, int(elapsed / (survey / (len(legs) - 1))))
            else:
                k = len(legs) - 1
                if not active:
                    active = True
                    self.get_logger().info(f"Mission {mid}: final approach, activating precision landing")
                    self.transition(Transition.TRANSITION_ACTIVATE, "activate")
            if k != leg:
                leg = k
                x, y = legs[k]
                z = alt if k < len(legs) - 1 else 1.5
                self.set_waypoint(x, y, z)
                self.get_logger().info(f"Mission {mid}: waypoint {k + 1}/{len(legs)} "
                                       f"({x:.1f}, {y:.1f}, {z:.1f})")
            if not alive():
                break
            goal_handle.publish_feedback(Fibonacci.Feedback(sequence=[int(elapsed), k + 1,
                                                                      int(100 * elapsed / duration)]))
            time.sleep(0.2)
        self.command("LAND")
        self.set_waypoint(PAD[0], PAD[1], 0.0)
        if active:
            self.transition(Transition.TRANSITION_DEACTIVATE, "deactivate")
        self.get_logger().info(f"Mission {mid} complete: landing on the pad")
        goal_handle.succeed()
        return Fibonacci.Result(sequence=[mid, 1])

    def on_second(self) -> None:
        self.publish_diagnostics(self.status("Mission", "mission", message="running" if self.busy else "idle",
                                             missions=self.missions, nav_state=self.nav_state))


class OffboardController(DroneNode):
    """Streams trajectory setpoints to PX4 at 20 Hz from its own thread (PX4 leaves OFFBOARD if
    the stream stops for 0.5 s): a rate-limited approach to the mission's current waypoint,
    stopping short when the obstacle distance says so."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("offboard_controller", "control", fault_dir)
        self.declare_parameter("setpoint_rate", 20.0)
        self.declare_parameter("max_speed", 2.0)
        self.declare_parameter("collision_distance", 1.0)
        self.pub = self.create_publisher(PoseStamped, "/fmu/in/trajectory_setpoint", BEST_EFFORT)
        self.create_subscription(PoseStamped, "/mission/waypoint", self.on_waypoint, LATCHED)
        self.create_subscription(LaserScan, "/perception/obstacles", self.on_obstacles,
                                 qos_profile_sensor_data)
        self.target = (0.0, 0.0, 0.0)
        self.sp = [0.0, 0.0, 0.0]
        self.obstacles_at = None  # none yet: collision prevention starts with the first
        self.min_obstacle = 20.0
        self.stale = False
        self.heartbeat()
        self.create_timer(1.0, self.check_obstacles)
        threading.Thread(target=self.stream, daemon=True, name="setpoints").start()

    def on_waypoint(self, msg: PoseStamped) -> None:
        p = msg.pose.position
        self.target = (p.x, p.y, p.z)

    def on_obstacles(self, msg: LaserScan) -> None:
        self.obstacles_at = time.monotonic()
        self.min_obstacle = min(msg.ranges) if msg.ranges else 20.0

    def check_obstacles(self) -> None:
        if self.obstacles_at is None:
            return
        stale = time.monotonic() - self.obstacles_at > 1.0
        if stale and not self.stale:
            self.get_logger().warn("Obstacle distance timed out: collision prevention inactive")
        elif self.stale and not stale:
            self.get_logger().info("Obstacle distance back: collision prevention active")
        self.stale = stale

    def stream(self) -> None:
        period = 0.05
        while alive():
            time.sleep(period)
            if self.fault == "die":  # the transform lookup raises out of the loop: the thread is gone
                raise RuntimeError("Lookup would require extrapolation into the future: "
                                   "odom -> base_link at 0.042 s ahead")
            step = self.get_parameter("max_speed").value * period
            for i in range(3):
                d = self.target[i] - self.sp[i]
                self.sp[i] += max(-step, min(step, d))
            m = PoseStamped()
            m.header.stamp, m.header.frame_id = self.get_clock().now().to_msg(), "odom"
            m.pose.position.x, m.pose.position.y, m.pose.position.z = self.sp
            m.pose.orientation.w = 1.0
            if not published((self.pub, m)):
                return


# --- safety (single-threaded executor) -----------------------------------------------------------


class Geofence(DroneNode):
    """A cylinder geofence around home on the VIO's odometry (GPS-denied flight: the local
    position is the VIO's); its status at 2 Hz."""

    RADIUS, CEILING = 30.0, 20.0

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("geofence", "safety", fault_dir)
        self.declare_parameter("radius", self.RADIUS)
        self.declare_parameter("ceiling", self.CEILING)
        self.declare_parameter("fence_file", "/etc/drone/fence.kml")
        self.pub = self.create_publisher(String, "/safety/geofence_status", RELIABLE)
        self.create_subscription(Odometry, "/vio/odometry", self.on_odom, RELIABLE)
        self.pos = (0.0, 0.0, 0.0)
        self.create_timer(0.5, self.on_tick)
        self.create_timer(1.0, self.on_errlog)

    def on_odom(self, msg: Odometry) -> None:
        p = msg.pose.pose.position
        self.pos = (p.x, p.y, p.z)

    def on_tick(self) -> None:
        r = math.hypot(self.pos[0], self.pos[1])
        inside = r < self.RADIUS and self.pos[2] < self.CEILING
        self.pub.publish(String(data=f"{'INSIDE' if inside else 'BREACH'} "
                                     f"horizontal_margin={self.RADIUS - r:.1f} "
                                     f"vertical_margin={self.CEILING - self.pos[2]:.1f}"))

    def on_errlog(self) -> None:
        if self.fault == "errlog":  # a corrupted fence file: the check goes on with the cached fence
            self.get_logger().error("Fence file /etc/drone/fence.kml failed its checksum: "
                                    "using the cached fence (radius 30.0 m)")


class HeartbeatWatchdog(DroneNode):
    """Watches the components' 1 Hz heartbeats: a WARN when one is more than 1 s late, an ERROR
    when it has been silent 5 s, INFO when it is back; its summary at 2 Hz."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("heartbeat_watchdog", "safety", fault_dir)
        self.declare_parameter("expected_period", 1.0)
        self.declare_parameter("late_tolerance", 1.0)
        self.pub = self.create_publisher(String, "/safety/watchdog", RELIABLE)
        self.create_subscription(Header, "/heartbeat", self.on_beat, RELIABLE)
        self.last: dict[str, float] = {}
        self.state: dict[str, str] = {}
        self.create_timer(0.5, self.on_tick)

    def on_beat(self, msg: Header) -> None:
        who = msg.frame_id
        if self.state.get(who) in ("late", "lost"):
            gap = time.monotonic() - self.last[who]
            self.get_logger().info(f"Heartbeat from {who} back after {gap:.1f} s")
        self.last[who] = time.monotonic()
        self.state[who] = "ok"

    def on_tick(self) -> None:
        now = time.monotonic()
        late = []
        for who, t in self.last.items():
            overdue = now - t - 1.0
            if overdue > 4.0 and self.state[who] != "lost":
                self.state[who] = "lost"
                self.get_logger().error(f"Heartbeat from {who} lost: silent for {now - t:.1f} s")
            elif overdue > 1.0 and self.state[who] == "ok":
                self.state[who] = "late"
                self.get_logger().warn(f"Heartbeat from {who} late by {overdue:.1f} s")
            if self.state[who] != "ok":
                late.append(who)
        self.pub.publish(String(data="OK" if not late else "LATE " + ",".join(sorted(late))))


class BatteryMonitor(DroneNode):
    """The battery's diagnostics from the FCU's battery state (WARN under 30 %, ERROR under 15 %)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("battery_monitor", "safety", fault_dir)
        self.declare_parameter("warn_percent", 30.0)
        self.declare_parameter("critical_percent", 15.0)
        self.create_subscription(BatteryState, "/fmu/battery", self.on_battery, RELIABLE)

    def on_battery(self, msg: BatteryState) -> None:
        pct = msg.percentage * 100
        level, text = (OK, "OK") if pct >= 30 else (WARN, "low") if pct >= 15 else (ERROR, "critical")
        self.publish_diagnostics(self.status("Battery", "battery0", level, text, percentage=f"{pct:.1f}",
                                             voltage=f"{msg.voltage:.2f}", current=f"{msg.current:.1f}"))


# --- telemetry ----------------------------------------------------------------------------------------


class Downlink(DroneNode):
    """The telemetry radio's downlink: a summary of the vehicle at 10 Hz, throttled to 1 Hz while
    the link quality is low (10-20 s episodes at random times)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("downlink", "telemetry", fault_dir)
        self.declare_parameter("radio", "/dev/ttyUSB1")
        self.declare_parameter("rate", 10.0)
        self.declare_parameter("low_link_rate", 1.0)
        self.pub = self.create_publisher(String, "/telemetry/summary", RELIABLE)
        self.create_subscription(String, "/fmu/status", self.on_status, RELIABLE)
        self.create_subscription(BatteryState, "/fmu/battery", self.on_battery, RELIABLE)
        self.create_subscription(Odometry, "/vio/odometry", self.on_odom, RELIABLE)
        self.create_subscription(String, "/safety/geofence_status", self.on_fence, RELIABLE)
        self.vehicle, self.battery, self.fence = "", 0.0, ""
        self.pos = (0.0, 0.0, 0.0)
        self.low = False
        self.next_change = time.monotonic() + random.uniform(30.0, 90.0)
        self.tick = 0
        self.seq = 0
        self.heartbeat()
        self.create_timer(0.1, self.on_tick)
        self.create_timer(1.0, self.on_second)

    def on_status(self, msg: String) -> None:
        self.vehicle = msg.data

    def on_battery(self, msg: BatteryState) -> None:
        self.battery = msg.percentage

    def on_odom(self, msg: Odometry) -> None:
        p = msg.pose.pose.position
        self.pos = (p.x, p.y, p.z)

    def on_fence(self, msg: String) -> None:
        self.fence = msg.data.split()[0]

    def on_tick(self) -> None:
        now = time.monotonic()
        if now >= self.next_change:
            self.low = not self.low
            if self.low:
                self.next_change = now + random.uniform(10.0, 20.0)
                self.get_logger().warn(f"Link quality low (RSSI {random.randint(-97, -91)} dBm, "
                                       f"{random.randint(25, 45)} % loss): downlink throttled to 1 Hz")
            else:
                self.next_change = now + random.uniform(40.0, 120.0)
                self.get_logger().info("Link quality restored: downlink at 10 Hz")
        self.tick += 1
        if self.low and self.tick % 10:
            return
        self.seq += 1
        x, y, z = self.pos
        self.pub.publish(String(data=f"seq={self.seq} {self.vehicle} pos={x:.1f},{y:.1f},{z:.1f} "
                                     f"fence={self.fence} batt={self.battery:.2f}"))

    def on_second(self) -> None:
        if self.low:
            st = self.status("Radio link", "sik_radio", WARN, "link quality low, throttled to 1 Hz")
        else:
            st = self.status("Radio link", "sik_radio", rssi=random.randint(-75, -60))
        self.publish_diagnostics(st)


# --- system: diagnostics ----------------------------------------------------------------------------


class SystemMonitor(DroneNode):
    """The companion computer's CPU, memory and SoC temperature (diagnostic_updater style)."""

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
            self.status("CPU usage", self.host, OK if cpu < 95 else WARN, "OK" if cpu < 95 else "high load",
                        usage=f"{cpu:.1f}%"),
            self.status("Memory usage", self.host, used=f"{mem.percent:.1f}%"),
            self.status("SoC temperature", self.host, celsius=f"{52 + cpu * 0.2:.1f}"))


class DiagnosticAggregator(DroneNode):
    """/diagnostics grouped by analyzer into /diagnostics_agg at 1 Hz (STALE after 5 s)."""

    GROUPS: ClassVar[dict[str, str]] = {
        "fc_bridge": "/Flight", "mission_manager": "/Flight", "battery_monitor": "/Power",
        "camera_driver": "/Sensors", "estimator": "/Navigation", "mapper": "/Navigation",
        "downlink": "/Comms", "system_monitor": "/Computer"}

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
            group = self.GROUPS.get(name.split(":")[0], "/Other")
            level = STALE if now - t > 5.0 else st.level
            lv = level[0] if isinstance(level, bytes) else level
            out.append(DiagnosticStatus(level=level, name=f"{group}/{name}",
                                        message="Stale" if lv == STALE[0] else st.message,
                                        hardware_id=st.hardware_id, values=st.values))
            groups[group] = max(groups.get(group, 0), lv)
        for group, lv in sorted(groups.items()):
            out.insert(0, DiagnosticStatus(level=bytes([lv]), name=group,
                                           message={0: "OK", 1: "Warning", 2: "Error", 3: "Stale"}[lv]))
        arr = DiagnosticArray(status=out)
        arr.header.stamp = self.get_clock().now().to_msg()
        self.agg_pub.publish(arr)
        top = max(groups.values(), default=0)
        self.top_pub.publish(DiagnosticStatus(level=bytes([top]), name="toplevel_state",
                                              message={0: "OK", 1: "Warning", 2: "Error", 3: "Stale"}[top]))


# --- the ground station (the operator's) -------------------------------------------------------------


class GroundStation(DroneNode):
    """The operator's ground-control station bridge: sends a survey mission 5 s after it connects
    and every 60-75 s after that; shows the telemetry summary and the aggregated diagnostics."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("gcs", "ground_station", fault_dir)
        self.client = ActionClient(self, Fibonacci, "/mission/execute")
        self.create_subscription(String, "/telemetry/summary", self.on_summary, RELIABLE)
        self.create_subscription(DiagnosticArray, "/diagnostics_agg", self.on_diag, RELIABLE)
        self.next_at = time.monotonic() + 5.0
        self.sent = 0
        self.pending = None
        self.summaries = 0
        self.get_logger().info("Ground station connected (MAVLink/ROS 2 bridge)")
        self.create_timer(0.5, self.on_tick)

    def on_summary(self, msg: String) -> None:
        self.summaries += 1

    def on_diag(self, msg: DiagnosticArray) -> None:
        pass

    def on_tick(self) -> None:
        now = time.monotonic()
        if self.pending is not None:
            sent_at, n, fut = self.pending
            if not fut.done() and now - sent_at > 3.0:
                self.get_logger().warn(f"Mission {n}: no answer to the upload after 3 s")
                self.pending = (1e18, n, fut)
        if now < self.next_at or not self.client.server_is_ready():
            return
        self.next_at = now + random.uniform(60.0, 75.0)
        self.sent += 1
        duration = random.randint(40, 50)
        self.get_logger().info(f"Uploading mission {self.sent}: survey, {duration} s")
        fut = self.client.send_goal_async(Fibonacci.Goal(order=duration), feedback_callback=self.on_feedback)
        n = self.sent
        fut.add_done_callback(lambda f: self.on_accepted(f, n))
        self.pending = (now, n, fut)

    def on_feedback(self, msg) -> None:
        pass

    def on_accepted(self, fut, n: int) -> None:
        handle = fut.result()
        if not handle.accepted:
            self.get_logger().error(f"Mission {n} rejected by the vehicle")
            return
        self.get_logger().info(f"Mission {n} accepted")
        handle.get_result_async().add_done_callback(lambda f: self.on_result(f, n))

    def on_result(self, fut, n: int) -> None:
        status = fut.result().status
        if status == GoalStatus.STATUS_SUCCEEDED:
            self.get_logger().info(f"Mission {n} complete")
        else:
            self.get_logger().error(f"Mission {n} ended by the vehicle with status {status}")


# --- processes ------------------------------------------------------------------------------------------


def perception(d: Path) -> list:
    return [ObstacleDetector(d), HeightSync(d), PrecisionLanding(d)]


PROCESSES = {  # process -> (its nodes, multi-threaded executor threads or 0)
    "fmu": (lambda d: [FcBridge(d)], 0),
    "camera": (lambda d: [CameraDriver(d)], 0),
    "rangefinder": (lambda d: [Rangefinder(d)], 0),
    "vio": (lambda d: [VioEstimator(d)], 4),
    "perception": (perception, 0),
    "mapping": (lambda d: [Mapper(d)], 0),
    "flight": (lambda d: [MissionManager(d), OffboardController(d)], 4),
    "safety": (lambda d: [Geofence(d), HeartbeatWatchdog(d), BatteryMonitor(d)], 0),
    "telemetry": (lambda d: [Downlink(d)], 0),
    "system": (lambda d: [SystemMonitor(d), DiagnosticAggregator(d)], 0),
    "ground_station": (lambda d: [GroundStation(d)], 0),
}


def main(argv: list[str]) -> int:
    process, fault_dir = argv[0], Path(argv[1])
    run_for = float(argv[2]) if len(argv) > 2 else 0.0
    rclpy.init()
    try:
        make, threads = PROCESSES[process]
        nodes = make(fault_dir)
        threading.Thread(target=watch, args=(nodes, fault_dir, process), daemon=True, name="faults").start()
        ex = MultiThreadedExecutor(num_threads=threads) if threads else SingleThreadedExecutor()
        for n in nodes:
            ex.add_node(n)
        deadline = time.monotonic() + run_for if run_for > 0 else None
        try:
            while rclpy.ok() and (deadline is None or time.monotonic() < deadline):
                ex.spin_once(timeout_sec=0.5)
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        if deadline is not None and time.monotonic() >= deadline:
            nodes[0].get_logger().info("Closed by the operator")
        ex.shutdown(timeout_sec=1.0)
        for n in nodes:
            n.destroy_node()
        return 0
    finally:
        if rclpy.ok():
            rclpy.shutdown()


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
