"""A mobile manipulator in a research lab, plain rclpy: ``python -m bench.lab.robot PROCESS FAULT_DIR``.

Written as a lab's robot is: a base (a 200 Hz IMU read by two nodes, odometry, a velocity input
``/lab/cmd_vel_in`` that an autonomy node feeds all the time and a joystick only while its
deadman button is held), a lidar whose driver stamps scans with the device's own clock (+0.4 s
off the computer's), a SLAM mapper whose memory grows while it maps (keyframes) and a latched map
every 2 s, a coverage planner that computes hard for 2-2.6 s every ~21 s, lifecycle drivers (the
lidar, a depth camera) brought up by a lifecycle manager that also switches the depth camera off
for ~10 s every minute to save power, a colour camera that drops from 15 to 5 fps in a power-save
mode for 30 s every ~2 minutes (a parameter on itself), a perception container (three nodes on
one single-threaded executor), two arm controllers with the same name under ``/arm/left`` and
``/arm/right`` on one multi-threaded executor, a grasp planner whose service answers in 3-8 s
(a multi-threaded executor, a reentrant group, service introspection on), called every ~30 s by
a task manager, a log player replaying a recorded motion-capture stream in loops (45 s, a 2 s
pause, stamps back to the loop's start), a disk monitor running ``df`` in a child process every
30 s, ``/diagnostics`` from several nodes with one standing WARN (the right gripper is not
calibrated), and an operator console that an operator opens and closes.

Faults come from files: ``FAULT_DIR/<namespace>.<node>`` (``lab.imu_driver``,
``arm.left.controller``) holding ``hang`` (the node blocks in a callback for good, and with it
its executor),
``degrade`` (the IMU drops 3 samples in 10), ``stall`` (the grasp planner's service never
answers), ``block_state`` (an arm controller's hardware-interface group blocks; its diagnostics
group goes on), ``stop`` (the log player stops for good) or ``errlog``; checked every 0.5 s.
``FAULT_DIR/<process>.cpu`` starts a thread burning a core in that process, ``<process>.leak``
one leaking 2 MB/s. Crashes are SIGKILLs from outside. A third argument, RUN_FOR, ends the
process cleanly after that many seconds (the console).
"""

from __future__ import annotations

import math
import os
import random
import subprocess
import sys
import threading
import time
from array import array
from collections import deque
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import ClassVar

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import Pose, PoseArray, PoseStamped, Twist
from lifecycle_msgs.msg import State, Transition
from lifecycle_msgs.srv import ChangeState, GetState
from nav_msgs.msg import OccupancyGrid, Odometry
from nav_msgs.msg import Path as PathMsg
from rcl_interfaces.msg import SetParametersResult
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import Executor, ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import (
    DurabilityPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_sensor_data,
    qos_profile_system_default,
)
from rclpy.service_introspection import ServiceIntrospectionState
from rclpy.time import Time
from sensor_msgs.msg import CameraInfo, Image, Imu, JointState, LaserScan
from std_msgs.msg import Header
from std_srvs.srv import Trigger

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
OK, WARN = DiagnosticStatus.OK, DiagnosticStatus.WARN
JOINTS = [f"joint_{i}" for i in range(1, 7)]


class Hooks:
    """The bench's fault hooks, mixed into a node: ``gate()`` at the top of each callback; the fault
    file ``FAULT_DIR/<namespace>.<name>``, watched by a thread of the process (`_watch`), sets
    ``fault`` and triggers a guard condition whose callback passes the gate at once (a ``hang``
    blocks the node's executor then, as a driver stuck in a device read does)."""

    fault: str | None

    def hooks(self, fault_dir: Path) -> None:
        ns = self.get_namespace().strip("/").replace("/", ".")
        self.fault_file = fault_dir / f"{ns}.{self.get_name()}"
        self.fault = None
        self.fault_set = self.create_guard_condition(self.gate,
                                                     callback_group=MutuallyExclusiveCallbackGroup())

    def on_errlog(self) -> None:
        self.get_logger().error("device read failed: timeout")

    def gate(self) -> None:
        if self.fault == "hang":
            threading.Event().wait()

    def stamp(self):
        return self.get_clock().now().to_msg()

    def after(self, seconds: float, fn: Callable[[], None], callback_group=None) -> None:
        """Call ``fn`` once, ``seconds`` from now."""
        box = []

        def fire() -> None:
            box[0].cancel()
            self.destroy_timer(box[0])
            fn()
        box.append(self.create_timer(seconds, fire, callback_group=callback_group))

    def status(self, task: str, hardware_id: str, level: bytes = OK, message: str = "OK",
               **values: str) -> DiagnosticStatus:
        """A diagnostic_updater-style status: ``"<node name>: <task>"``."""
        return DiagnosticStatus(level=level, name=f"{self.get_name()}: {task}", hardware_id=hardware_id,
                                message=message, values=[KeyValue(key=k, value=v) for k, v in values.items()])


class LabNode(Hooks, Node):
    def __init__(self, name: str, namespace: str, fault_dir: Path) -> None:
        super().__init__(name, namespace=namespace)
        self.hooks(fault_dir)


class LabLifecycleNode(Hooks, LifecycleNode):
    def __init__(self, name: str, namespace: str, fault_dir: Path) -> None:
        super().__init__(name, namespace=namespace)
        self.hooks(fault_dir)


# --- the base --------------------------------------------------------------------------------


class ImuDriver(LabNode):
    """/lab/imu at 200 Hz (best effort), published by the serial reader thread as the board's
    frames come in (as IMU drivers do), not from the executor."""

    PERIOD = 0.005

    def __init__(self, fd: Path) -> None:
        super().__init__("imu_driver", "/lab", fd)
        self.pub = self.create_publisher(Imu, "imu", qos_profile_sensor_data)
        self.k = 0
        threading.Thread(target=self.reader, daemon=True).start()
        self.get_logger().info("IMU board bmi088 opened on /dev/ttyACM0 at 200 Hz")

    def reader(self) -> None:
        due = time.monotonic()
        while rclpy.ok():
            due += self.PERIOD
            wait = due - time.monotonic()
            if wait > 0:
                time.sleep(wait)
            elif wait < -0.1:  # far behind (the computer stalled): frames lost, resynchronise
                due = time.monotonic()
            try:
                self.frame()
            except Exception:  # the context shut down under it (Ctrl-C)
                if rclpy.ok():
                    raise
                return

    def frame(self) -> None:
        self.gate()
        self.k += 1
        if self.fault == "degrade" and self.k % 10 in (0, 3, 6):  # frames lost on a failing USB link
            return
        t = self.k * self.PERIOD
        m = Imu(header=Header(stamp=self.stamp(), frame_id="imu_link"))
        m.orientation.z, m.orientation.w = math.sin(0.05 * t), math.cos(0.05 * t)
        m.angular_velocity.z = 0.1 * math.sin(0.3 * t) + random.gauss(0.0, 0.002)
        m.linear_acceleration.x = random.gauss(0.0, 0.02)
        m.linear_acceleration.z = 9.81 + random.gauss(0.0, 0.02)
        self.pub.publish(m)


class BaseController(LabNode):
    """Takes /lab/cmd_vel_in (the latest command wins; none for 0.5 s: stop), fuses the IMU's yaw
    rate, publishes /lab/odom at 20 Hz and its motor drivers' diagnostics."""

    def __init__(self, fd: Path) -> None:
        super().__init__("base_controller", "/lab", fd)
        self.odom_pub = self.create_publisher(Odometry, "odom", 10)
        self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_subscription(Twist, "cmd_vel_in", self.on_cmd, 10)
        self.create_subscription(Imu, "imu", self.on_imu, qos_profile_sensor_data)
        self.v = self.w_cmd = self.gyro = 0.0
        self.cmd_t = 0.0
        self.x = self.y = self.yaw = 0.0
        self.last = time.monotonic()
        self.create_timer(0.05, self.tick)
        self.create_timer(1.0, self.diagnostics)
        self.get_logger().info("motor drivers enabled, odometry at 20 Hz")

    def on_cmd(self, msg: Twist) -> None:
        self.gate()
        self.v, self.w_cmd, self.cmd_t = msg.linear.x, msg.angular.z, time.monotonic()

    def on_imu(self, msg: Imu) -> None:
        self.gate()
        self.gyro = 0.98 * self.gyro + 0.02 * msg.angular_velocity.z

    def tick(self) -> None:
        self.gate()
        now = time.monotonic()
        dt, self.last = min(now - self.last, 0.2), now
        if now - self.cmd_t > 0.5:
            self.v = self.w_cmd = 0.0
        self.yaw += (0.8 * self.w_cmd + 0.2 * self.gyro) * dt
        self.x += self.v * math.cos(self.yaw) * dt
        self.y += self.v * math.sin(self.yaw) * dt
        m = Odometry(header=Header(stamp=self.stamp(), frame_id="odom"), child_frame_id="base_link")
        m.pose.pose.position.x, m.pose.pose.position.y = self.x, self.y
        m.pose.pose.orientation.z, m.pose.pose.orientation.w = math.sin(self.yaw / 2), math.cos(self.yaw / 2)
        m.twist.twist.linear.x, m.twist.twist.angular.z = self.v, self.w_cmd
        self.odom_pub.publish(m)

    def diagnostics(self) -> None:
        self.gate()
        self.diag_pub.publish(DiagnosticArray(header=Header(stamp=self.stamp()), status=[
            self.status("motor drivers", "roboteq-sbl2360-0031", temperature=f"{38 + random.random():.1f}",
                        bus_voltage=f"{47.5 + random.random():.1f}")]))


# --- drivers (lifecycle) ---------------------------------------------------------------------


class LidarDriver(LabLifecycleNode):
    """A lifecycle driver: /lab/scan at 10 Hz while active, stamped with the lidar's own clock
    (which runs 0.4 s ahead of the computer's; the driver does not correct it)."""

    DEVICE_OFFSET_NS = 400_000_000

    def __init__(self, fd: Path) -> None:
        super().__init__("lidar_driver", "/lab", fd)
        self.pub = self.diag_pub = self.timer = self.diag_timer = None
        self.ranges: list[array] = []
        self.k = 0

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.pub = self.create_lifecycle_publisher(LaserScan, "scan", qos_profile_sensor_data)
        self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        for k in range(10):  # the lab: walls, a table, people walking by
            r = array("f", (4.0 + 2.0 * abs(math.cos(math.radians(a))) for a in range(360)))
            for a in range(20 + 30 * k, 35 + 30 * k):
                r[a % 360] = 1.5
            self.ranges.append(r)
        self.diag_timer = self.create_timer(1.0, self.diagnostics)
        self.get_logger().info("connected to sick-tim571 at 192.168.1.10:2112, firmware 4.11")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.timer = self.create_timer(0.1, self.tick)
        self.get_logger().info("scanning at 10 Hz")
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.destroy_timer(self.timer)
        self.get_logger().info("scanning stopped")
        return super().on_deactivate(state)

    def on_errlog(self) -> None:
        self.get_logger().error("scan packet checksum mismatch, datagram dropped")

    def tick(self) -> None:
        self.gate()
        self.k += 1
        device_ns = self.get_clock().now().nanoseconds + self.DEVICE_OFFSET_NS + random.randint(-1_000_000,
                                                                                                 1_000_000)
        self.pub.publish(LaserScan(
            header=Header(stamp=Time(nanoseconds=device_ns).to_msg(), frame_id="laser"),
            angle_min=-math.pi, angle_max=math.pi, angle_increment=math.pi / 180, scan_time=0.1,
            range_min=0.05, range_max=25.0, ranges=self.ranges[self.k % len(self.ranges)]))

    def diagnostics(self) -> None:
        self.gate()
        self.diag_pub.publish(DiagnosticArray(header=Header(stamp=self.stamp()), status=[
            self.status("scan", "sick-tim571-19330871", frequency="10.0", contamination="0")]))


class DepthCamera(LabLifecycleNode):
    """A lifecycle driver: 16-bit depth (160 x 120) and its camera info at 10 Hz while active."""

    def __init__(self, fd: Path) -> None:
        super().__init__("depth_camera", "/lab", fd)
        self.image_pub = self.info_pub = self.timer = None
        self.frame = array("B")

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.image_pub = self.create_lifecycle_publisher(Image, "depth/image_raw", qos_profile_sensor_data)
        self.info_pub = self.create_lifecycle_publisher(CameraInfo, "depth/camera_info",
                                                        qos_profile_sensor_data)
        self.frame = array("B", b"".join((1200 + (i % 160) * 4).to_bytes(2, "little")
                                         for i in range(160 * 120)))
        self.get_logger().info("depth sensor realsense-d435 (serial 843112071247) configured: 160x120 z16")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.timer = self.create_timer(0.1, self.tick)
        self.get_logger().info("depth stream started")
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.destroy_timer(self.timer)
        self.get_logger().info("depth stream stopped, emitter off")
        return super().on_deactivate(state)

    def tick(self) -> None:
        self.gate()
        header = Header(stamp=self.stamp(), frame_id="depth_optical_frame")
        self.image_pub.publish(Image(header=header, height=120, width=160, encoding="16UC1", step=320,
                                     data=self.frame))
        self.info_pub.publish(CameraInfo(header=header, height=120, width=160, distortion_model="plumb_bob"))


class RgbCamera(LabNode):
    """Colour images at 15 fps, 5 fps in the ``power_save`` mode (its ``mode`` parameter, which it
    sets itself for 30 s every ~2 minutes while the arms are idle); its timer re-created."""

    FPS: ClassVar[dict[str, float]] = {"normal": 15.0, "power_save": 5.0}

    def __init__(self, fd: Path) -> None:
        super().__init__("rgb_camera", "/lab", fd)
        self.declare_parameter("mode", "normal")
        self.image_pub = self.create_publisher(Image, "color/image_raw", qos_profile_sensor_data)
        self.info_pub = self.create_publisher(CameraInfo, "color/camera_info", qos_profile_sensor_data)
        self.frame = array("B", bytes((i * 7) % 251 for i in range(192 * 144 * 3)))
        self.timer = self.create_timer(1.0 / self.FPS["normal"], self.tick)
        self.add_on_set_parameters_callback(self.on_set)
        self.after(random.uniform(60.0, 120.0), self.power_save)
        self.get_logger().info("colour camera opened: 192x144 rgb8 at 15 fps")

    def on_set(self, params: list[Parameter]) -> SetParametersResult:
        for p in params:
            if p.name == "mode":
                if p.value not in self.FPS:
                    return SetParametersResult(successful=False, reason=f"unknown mode {p.value}")
                self.destroy_timer(self.timer)
                self.timer = self.create_timer(1.0 / self.FPS[p.value], self.tick)
                self.get_logger().info(f"mode {p.value}: {self.FPS[p.value]:.0f} fps")
        return SetParametersResult(successful=True)

    def power_save(self) -> None:
        self.gate()
        self.set_parameters([Parameter("mode", value="power_save")])
        self.after(30.0, self.wake)

    def wake(self) -> None:
        self.gate()
        self.set_parameters([Parameter("mode", value="normal")])
        self.after(random.uniform(85.0, 100.0), self.power_save)

    def tick(self) -> None:
        self.gate()
        header = Header(stamp=self.stamp(), frame_id="color_optical_frame")
        self.image_pub.publish(Image(header=header, height=144, width=192, encoding="rgb8", step=576,
                                     data=self.frame))
        self.info_pub.publish(CameraInfo(header=header, height=144, width=192, distortion_model="plumb_bob"))


class ObjectDetector(LabNode):
    """Detections (PoseArray) on each colour frame, placed in 3D with the latest depth frame when
    there is one (2D only while the depth camera is off)."""

    def __init__(self, fd: Path) -> None:
        super().__init__("object_detector", "/lab", fd)
        self.pub = self.create_publisher(PoseArray, "detections", 10)
        self.create_subscription(Image, "color/image_raw", self.on_color, qos_profile_sensor_data)
        self.create_subscription(Image, "depth/image_raw", self.on_depth, qos_profile_sensor_data)
        self.depth_t = 0.0
        self.frames = 0
        self.create_timer(30.0, self.report)
        self.get_logger().info("detector loaded: mobilenet-ssd-lite, 12 classes")

    def on_depth(self, msg: Image) -> None:
        self.gate()
        self.depth_t = time.monotonic()

    def on_color(self, msg: Image) -> None:
        self.gate()
        self.frames += 1
        if self.frames % 3:  # inference keeps up with every third frame
            return
        with_depth = time.monotonic() - self.depth_t < 0.5
        poses = []
        for k in range(1 + self.frames % 3):
            p = Pose()
            p.position.x, p.position.y = 0.6 + 0.1 * k, -0.2 + 0.2 * k
            p.position.z = 0.75 if with_depth else 0.0
            p.orientation.w = 1.0
            poses.append(p)
        self.pub.publish(PoseArray(header=Header(stamp=msg.header.stamp, frame_id="color_optical_frame"),
                                   poses=poses))

    def report(self) -> None:
        self.gate()
        depth = "3D" if time.monotonic() - self.depth_t < 0.5 else "2D only, no depth"
        self.get_logger().info(f"{self.frames} frames processed ({depth})")


# --- mapping and planning --------------------------------------------------------------------


def _lab_map() -> array:
    """The lab's true 200 x 200 occupancy at 5 cm: walls, benches and a pillar."""
    grid = array("b", bytes(200 * 200))
    for i in range(200 * 200):
        r, c = divmod(i, 200)
        if r < 2 or r > 197 or c < 2 or c > 197 or (60 <= r < 70 and 20 <= c < 120) \
                or (130 <= r < 140 and 80 <= c < 180) or (95 <= r < 105 and 150 <= c < 160):
            grid[i] = 100
    return grid


class SlamMapper(LabNode):
    """Scan matching on /lab/scan with the IMU's yaw rate as a prior; each scan becomes a keyframe kept
    for loop closure (its memory grows ~0.3 MB/s for as long as it maps); /lab/map every 2 s,
    transient-local, more of the lab known at each."""

    def __init__(self, fd: Path) -> None:
        super().__init__("slam_mapper", "/lab", fd)
        self.map_pub = self.create_publisher(OccupancyGrid, "map", LATCHED)
        self.create_subscription(LaserScan, "scan", self.on_scan, qos_profile_sensor_data)
        self.create_subscription(Imu, "imu", self.on_imu, qos_profile_sensor_data)
        self.truth = _lab_map()
        self.known = 0  # rows of the map known so far
        self.keyframes: list[bytes] = []
        self.yaw_rate = self.yaw = 0.0
        self.stamp_ns = 0
        self.create_timer(2.0, self.publish_map)
        self.create_timer(30.0, self.report)
        self.get_logger().info("mapping started: 200 x 200 cells at 0.05 m")

    def on_scan(self, msg: LaserScan) -> None:
        self.gate()
        # a keyframe: the scan and its local submap, kept for loop closure (resident: written)
        self.keyframes.append(msg.ranges.tobytes() * 20)

    def on_imu(self, msg: Imu) -> None:  # the yaw prior between scans: the gyro integrated
        self.gate()
        ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        if self.stamp_ns:
            self.yaw += msg.angular_velocity.z * min(ns - self.stamp_ns, 50_000_000) * 1e-9
        self.stamp_ns = ns

    def publish_map(self) -> None:
        self.gate()
        self.known = min(200, self.known + 3)
        m = OccupancyGrid(header=Header(stamp=self.stamp(), frame_id="map"))
        m.info.resolution, m.info.width, m.info.height = 0.05, 200, 200
        m.info.origin.position.x = m.info.origin.position.y = -5.0
        m.info.origin.orientation.w = 1.0
        n = self.known * 200
        m.data = self.truth[:n] + array("b", b"\xff" * (200 * 200 - n))
        self.map_pub.publish(m)

    def report(self) -> None:
        self.gate()
        self.get_logger().info(f"map: {self.known * 200 * 0.0025:.1f} m2 known, "
                               f"{len(self.keyframes)} keyframes, heading {math.degrees(self.yaw):.0f} deg")


class CoveragePlanner(LabNode):
    """Every ~21 s, a coverage plan over the latest map: an anytime search over start cells and
    sweep directions (wavefronts on a 100 x 100 grid) for 2-2.6 s of hard computing, then a
    boustrophedon path on /lab/coverage_path (transient-local)."""

    def __init__(self, fd: Path) -> None:
        super().__init__("coverage_planner", "/lab", fd)
        self.pub = self.create_publisher(PathMsg, "coverage_path", LATCHED)
        self.create_subscription(OccupancyGrid, "map", self.on_map, LATCHED)
        self.grid: OccupancyGrid | None = None
        self.plans = 0
        self.after(random.uniform(8.0, 14.0), self.plan)
        self.get_logger().info("coverage planner ready, replanning every ~20 s")

    def on_map(self, msg: OccupancyGrid) -> None:
        self.gate()
        self.grid = msg

    def plan(self) -> None:
        self.gate()
        self.after(random.uniform(19.0, 23.0), self.plan)
        if self.grid is None:
            self.get_logger().info("no map yet, plan postponed")
            return
        t0 = time.monotonic()
        budget = random.uniform(2.0, 2.6)
        data, w = self.grid.data, self.grid.info.width
        free = [[0 <= data[2 * r * w + 2 * c] < 50 for c in range(100)] for r in range(100)]
        best, tried = None, 0
        while time.monotonic() - t0 < budget:  # anytime: the best start cell found in the budget
            sr, sc = random.randrange(5, 95), random.randrange(5, 95)
            if not free[sr][sc]:
                continue
            tried += 1
            dist = {(sr, sc): 0}
            queue = deque([(sr, sc)])
            while queue:
                r, c = queue.popleft()
                d = dist[(r, c)] + 1
                for nr, nc in ((r + 1, c), (r - 1, c), (r, c + 1), (r, c - 1)):
                    if 0 <= nr < 100 and 0 <= nc < 100 and free[nr][nc] and (nr, nc) not in dist:
                        dist[(nr, nc)] = d
                        queue.append((nr, nc))
            cost = sum(dist.values()) / len(dist) - len(dist) / 100.0
            if best is None or cost < best[0]:
                best = (cost, sr, sc, len(dist))
        path = PathMsg(header=Header(stamp=self.stamp(), frame_id="map"))
        for k, r in enumerate(range(10, 100, 10)):  # boustrophedon rows over the free cells
            cols = [c for c in range(5, 95, 5) if free[r][c]]
            for c in (cols if k % 2 == 0 else cols[::-1]):
                p = PoseStamped(header=path.header)
                p.pose.position.x, p.pose.position.y = -5.0 + 0.1 * c, -5.0 + 0.1 * r
                p.pose.orientation.w = 1.0
                path.poses.append(p)
        self.pub.publish(path)
        self.plans += 1
        reach = best[3] if best else 0
        self.get_logger().info(f"coverage plan {self.plans}: {len(path.poses)} waypoints, {reach} cells "
                               f"reachable, {tried} starts evaluated in {time.monotonic() - t0:.1f} s")


# --- manipulation ----------------------------------------------------------------------------


class ArmController(LabNode):
    """An arm's controller (the same node under /arm/left and /arm/right): the hardware interface
    (joint states at 20 Hz, joint commands) in one callback group, its diagnostics in another;
    the right arm carries the gripper, never calibrated (a standing WARN)."""

    def __init__(self, fd: Path, side: str) -> None:
        super().__init__("controller", f"/arm/{side}", fd)
        self.side = side
        hw = MutuallyExclusiveCallbackGroup()
        diag = MutuallyExclusiveCallbackGroup()
        self.state_pub = self.create_publisher(JointState, "joint_states", 10)
        self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_subscription(JointState, "joint_command", self.on_command, 10, callback_group=hw)
        self.q = [0.0, -1.2, 1.5, -0.3, 0.0, 0.0]
        self.goal = list(self.q)
        self.cycles = 0
        self.create_timer(0.05, self.read_write, callback_group=hw)
        self.create_timer(1.0, self.diagnostics, callback_group=diag)
        self.get_logger().info(f"{side} arm ur5e connected, hardware interface at 20 Hz")

    def on_command(self, msg: JointState) -> None:
        self.gate()
        self.goal = list(msg.position)
        self.get_logger().info(f"{self.side} arm: new joint goal")

    def read_write(self) -> None:
        self.gate()
        if self.fault == "block_state":  # the hardware read never returns (the driver's socket)
            threading.Event().wait()
        self.cycles += 1
        self.q = [q + max(-0.02, min(0.02, g - q)) for q, g in zip(self.q, self.goal, strict=False)]
        self.state_pub.publish(JointState(header=Header(stamp=self.stamp()), name=JOINTS,
                                          position=self.q, velocity=[0.0] * 6, effort=[0.0] * 6))

    def diagnostics(self) -> None:
        self.gate()
        hw = f"ur5e-{self.side}-2021{'3318' if self.side == 'left' else '3407'}"
        out = [self.status("motors", hw, temperature=f"{34 + random.random():.1f}", cycles=str(self.cycles))]
        if self.side == "right":
            out.append(self.status("gripper calibration", "robotiq-2f85-0117", WARN, "not calibrated",
                                   stroke_mm="85"))
        self.diag_pub.publish(DiagnosticArray(header=Header(stamp=self.stamp()), status=out))


class GraspPlanner(LabNode):
    """/lab/plan_grasp (std_srvs/Trigger): a grasp for the latest detections, 3-8 s a call (it waits
    on the lab's GPU inference server); reentrant, so it serves while it plans; introspected."""

    def __init__(self, fd: Path) -> None:
        super().__init__("grasp_planner", "/lab", fd)
        group = ReentrantCallbackGroup()
        self.pub = self.create_publisher(PoseArray, "grasp_poses", 10)
        self.create_subscription(PoseArray, "detections", self.on_detections, 10, callback_group=group)
        self.srv = self.create_service(Trigger, "plan_grasp", self.plan, callback_group=group)
        self.srv.configure_introspection(self.get_clock(), qos_profile_system_default,
                                         ServiceIntrospectionState.CONTENTS)
        self.objects: list[Pose] = []
        self.get_logger().info("grasp planner ready: contact-graspnet via inference server gpu-02")

    def on_detections(self, msg: PoseArray) -> None:
        self.gate()
        self.objects = list(msg.poses)

    def plan(self, request: Trigger.Request, response: Trigger.Response) -> Trigger.Response:
        self.gate()
        took = random.uniform(3.0, 8.0)
        end = time.monotonic() + took
        while time.monotonic() < end:  # waiting on the inference server
            if self.fault == "stall":  # its answer never comes back
                threading.Event().wait()
            time.sleep(0.1)
        n = len(self.objects)
        grasps = PoseArray(header=Header(stamp=self.stamp(), frame_id="base_link"), poses=self.objects[:1])
        self.pub.publish(grasps)
        response.success = n > 0
        response.message = f"{n} objects, best grasp score {random.uniform(0.6, 0.95):.2f}" if n \
            else "no objects detected"
        self.get_logger().info(f"grasp planned in {took:.1f} s: {response.message}")
        return response


class TaskManager(LabNode):
    """A pick task every ~30 s: asks /lab/plan_grasp (12 s timeout), then moves both arms."""

    TIMEOUT = 12.0

    def __init__(self, fd: Path) -> None:
        super().__init__("task_manager", "/lab", fd)
        self.client = self.create_client(Trigger, "plan_grasp")
        self.client.configure_introspection(self.get_clock(), qos_profile_system_default,
                                            ServiceIntrospectionState.METADATA)
        self.arms = {s: self.create_publisher(JointState, f"/arm/{s}/joint_command", 10)
                     for s in ("left", "right")}
        self.pending: dict = {}
        self.tasks = 0
        self.after(random.uniform(8.0, 14.0), self.next_task)
        self.create_timer(0.5, self.watchdog)
        self.get_logger().info("task manager up: pick-and-place demo")

    def next_task(self) -> None:
        self.gate()
        self.after(random.uniform(27.0, 33.0), self.next_task)
        if not self.client.service_is_ready():
            self.get_logger().warn(f"service {self.client.srv_name} not available, task skipped")
            return
        self.tasks += 1
        task = self.tasks
        self.get_logger().info(f"task {task}: planning a grasp")
        fut = self.client.call_async(Trigger.Request())
        self.pending[fut] = (time.monotonic(), task)
        fut.add_done_callback(self.answered)

    def answered(self, fut) -> None:
        t, task = self.pending.pop(fut, (None, None))
        if t is None or fut.cancelled():
            return
        res = fut.result()
        self.get_logger().info(f"task {task}: grasp plan after {time.monotonic() - t:.1f} s ({res.message})")
        if res.success:
            for side, pub in self.arms.items():
                q = [random.uniform(-0.5, 0.5), -1.0, 1.3, -0.4, 0.2 if side == "left" else -0.2, 0.0]
                pub.publish(JointState(header=Header(stamp=self.stamp()), name=JOINTS, position=q))

    def watchdog(self) -> None:
        self.gate()
        for fut, (t, task) in list(self.pending.items()):
            if time.monotonic() - t > self.TIMEOUT:
                self.pending.pop(fut, None)
                self.client.remove_pending_request(fut)
                fut.cancel()
                self.get_logger().error(f"task {task}: service {self.client.srv_name} did not answer "
                                        f"within {self.TIMEOUT:.0f} s, task aborted")


class Navigator(LabNode):
    """Autonomy: follows /lab/coverage_path on /lab/odom, /lab/cmd_vel_in at 10 Hz all the time
    (zero when it has nothing to do); logs its tracking error against the motion capture."""

    def __init__(self, fd: Path) -> None:
        super().__init__("navigator", "/lab", fd)
        self.pub = self.create_publisher(Twist, "cmd_vel_in", 10)
        self.create_subscription(PathMsg, "coverage_path", self.on_path, LATCHED)
        self.create_subscription(Odometry, "odom", self.on_odom, 10)
        self.create_subscription(PoseStamped, "mocap/pose", self.on_mocap, 10)
        self.path: list[tuple[float, float]] = []
        self.i = 0
        self.pose = (0.0, 0.0, 0.0)
        self.mocap: PoseStamped | None = None
        self.create_timer(0.1, self.tick)
        self.create_timer(30.0, self.report)
        self.get_logger().info("navigator up, waiting for a coverage path")

    def on_path(self, msg: PathMsg) -> None:
        self.gate()
        self.path = [(p.pose.position.x, p.pose.position.y) for p in msg.poses]
        self.i = 0

    def on_odom(self, msg: Odometry) -> None:
        self.gate()
        q = msg.pose.pose.orientation
        self.pose = (msg.pose.pose.position.x, msg.pose.pose.position.y, 2.0 * math.atan2(q.z, q.w))

    def on_mocap(self, msg: PoseStamped) -> None:
        self.gate()
        self.mocap = msg

    def tick(self) -> None:
        self.gate()
        cmd = Twist()
        if self.path:
            x, y, yaw = self.pose
            gx, gy = self.path[self.i % len(self.path)]
            if math.hypot(gx - x, gy - y) < 0.2:
                self.i += 1
            err = math.atan2(gy - y, gx - x) - yaw
            err = math.atan2(math.sin(err), math.cos(err))
            cmd.linear.x = 0.3 * max(0.0, math.cos(err))
            cmd.angular.z = max(-0.8, min(0.8, 1.2 * err))
        self.pub.publish(cmd)

    def report(self) -> None:
        self.gate()
        where = f"waypoint {self.i % len(self.path) + 1}/{len(self.path)}" if self.path else "no path"
        seen = "mocap tracking" if self.mocap else "no mocap"
        self.get_logger().info(f"coverage: {where}, {seen}")


class LifecycleManager(LabNode):
    """Brings its managed nodes up (configure, activate, through their change_state services),
    checks their state every 2 s, and switches the depth camera off for ~10 s every minute."""

    MANAGED = ("/lab/lidar_driver", "/lab/depth_camera")

    def __init__(self, fd: Path) -> None:
        super().__init__("lifecycle_manager", "/lab", fd)
        self.change = {n: self.create_client(ChangeState, f"{n}/change_state") for n in self.MANAGED}
        self.get = {n: self.create_client(GetState, f"{n}/get_state") for n in self.MANAGED}
        self.up = self.busy = False
        self.asked: dict[str, float] = {}
        self.missing: set[str] = set()
        self.queue = [(n, t) for n in self.MANAGED
                      for t in (Transition.TRANSITION_CONFIGURE, Transition.TRANSITION_ACTIVATE)]
        self.boot = self.create_timer(0.5, self.bring_up)
        self.create_timer(2.0, self.heartbeat)
        self.get_logger().info(f"managing {', '.join(self.MANAGED)}")

    def transition(self, node: str, tid: int, then: Callable[[bool], None]) -> None:
        label = {Transition.TRANSITION_CONFIGURE: "configuring", Transition.TRANSITION_ACTIVATE: "activating",
                 Transition.TRANSITION_DEACTIVATE: "deactivating"}[tid]
        self.get_logger().info(f"{label} {node}")
        fut = self.change[node].call_async(ChangeState.Request(transition=Transition(id=tid)))
        fut.add_done_callback(lambda f: then(bool(f.result() and f.result().success)))

    def bring_up(self) -> None:
        self.gate()
        if not self.queue or self.busy:
            return
        node, tid = self.queue[0]
        if not self.change[node].service_is_ready():
            return
        self.busy = True

        def done(ok: bool) -> None:
            self.busy = False
            if not ok:
                self.get_logger().error(f"failed to bring up {node}, retrying")
                return
            self.queue.pop(0)
            if not self.queue:
                self.boot.cancel()
                self.up = True
                self.get_logger().info("managed nodes are active")
                self.after(random.uniform(40.0, 60.0), self.power_save)
        self.transition(node, tid, done)

    def power_save(self) -> None:
        self.gate()
        cam = "/lab/depth_camera"
        self.get_logger().info(f"{cam}: no manipulation task for a while, power saving")

        def off(ok: bool) -> None:
            self.after(random.uniform(9.0, 11.0), lambda: self.transition(cam, Transition.TRANSITION_ACTIVATE,
                                                                          on))

        def on(ok: bool) -> None:
            self.after(random.uniform(48.0, 52.0), self.power_save)
        self.transition(cam, Transition.TRANSITION_DEACTIVATE, off)

    def heartbeat(self) -> None:
        self.gate()
        if not self.up:
            return
        now = time.monotonic()
        for node, client in self.get.items():
            t = self.asked.get(node)
            if t is not None:
                if now - t > 4.0 and node not in self.missing:
                    self.missing.add(node)
                    self.get_logger().error(f"have not received a heartbeat from {node} for 4 s")
                continue
            self.asked[node] = now
            client.call_async(GetState.Request()).add_done_callback(partial(self.alive, node))

    def alive(self, node: str, fut) -> None:
        self.asked.pop(node, None)
        if node in self.missing:
            self.missing.discard(node)
            self.get_logger().info(f"{node} answers again")
        state = fut.result().current_state if fut.result() else None
        if state is not None and state.id not in (State.PRIMARY_STATE_ACTIVE, State.PRIMARY_STATE_INACTIVE):
            self.get_logger().warn(f"{node} is {state.label}")


# --- tools -----------------------------------------------------------------------------------


class LogPlayer(LabNode):
    """Replays a recorded motion-capture stream (/lab/mocap/pose, 10 Hz, 45 s) in loops, as
    ``ros2 bag play --loop``: the recorded stamps (from the first loop's start) again each loop,
    a 2 s pause between loops."""

    LENGTH, RATE, PAUSE = 45.0, 10.0, 2.0

    def __init__(self, fd: Path) -> None:
        super().__init__("log_player", "/lab", fd)
        self.pub = self.create_publisher(PoseStamped, "mocap/pose", 10)
        self.recorded_ns = self.get_clock().now().nanoseconds  # the recording's first stamp
        self.count = int(self.LENGTH * self.RATE)
        self.k = 0
        self.loops = 1
        self.paused_until = 0.0
        self.create_timer(1.0 / self.RATE, self.tick)
        self.get_logger().info(f"playing mocap_lab_run3 ({self.count} messages, {self.LENGTH:.0f} s) "
                               "in a loop")

    def tick(self) -> None:
        self.gate()
        if self.fault == "stop":  # the player's reader thread died: nothing published any more
            return
        if self.paused_until:
            if time.monotonic() < self.paused_until:
                return
            self.paused_until = 0.0
            self.k = 0
            self.loops += 1
            self.get_logger().warn(f"loop restart: playing mocap_lab_run3 again (loop {self.loops})")
        t = self.k / self.RATE
        m = PoseStamped(header=Header(stamp=Time(nanoseconds=self.recorded_ns + int(t * 1e9)).to_msg(),
                                      frame_id="mocap"))
        m.pose.position.x = 2.0 * math.sin(2 * math.pi * t / self.LENGTH)
        m.pose.position.y = math.sin(4 * math.pi * t / self.LENGTH)
        m.pose.orientation.w = 1.0
        self.pub.publish(m)
        self.k += 1
        if self.k >= self.count:
            self.get_logger().info("end of recording reached")
            self.paused_until = time.monotonic() + self.PAUSE


class DiskMonitor(LabNode):
    """Checks the free space of the data disk every 30 s with ``df`` (a child process) and reports
    it in /diagnostics every second."""

    def __init__(self, fd: Path) -> None:
        super().__init__("disk_monitor", "/lab", fd)
        self.pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.free_pct = -1.0
        self.checking = False
        self.create_timer(30.0, self.check)
        self.create_timer(1.0, self.diagnostics)
        self.check()
        self.get_logger().info("disk monitor up: checking / every 30 s")

    def check(self) -> None:
        self.gate()
        if not self.checking:
            self.checking = True
            threading.Thread(target=self._df, daemon=True).start()

    def _df(self) -> None:
        try:
            out = subprocess.run(["sh", "-c", "df -Pk / && sleep 1"], capture_output=True, text=True,
                                 timeout=20, check=False).stdout.splitlines()
            used = int(out[1].split()[4].rstrip("%"))
            self.free_pct = 100.0 - used
        except (OSError, subprocess.SubprocessError, IndexError, ValueError) as e:
            self.get_logger().warn(f"df failed: {e}")
        finally:
            self.checking = False

    def diagnostics(self) -> None:
        self.gate()
        if self.free_pct < 0:
            return
        level = OK if self.free_pct > 3.0 else WARN
        self.pub.publish(DiagnosticArray(header=Header(stamp=self.stamp()), status=[
            self.status("disk space", "data-disk-vda", level, "OK" if level == OK else "disk almost full",
                        free_percent=f"{self.free_pct:.0f}")]))


class Joystick(LabNode):
    """An operator's gamepad (teleop_twist_joy style): /lab/cmd_vel_in at 20 Hz only while the
    deadman button is held, a few seconds every ~40 s."""

    def __init__(self, fd: Path) -> None:
        super().__init__("joystick", "/lab", fd)
        self.pub = self.create_publisher(Twist, "cmd_vel_in", 10)
        self.timer = None
        self.after(random.uniform(25.0, 45.0), self.press)
        self.get_logger().info("gamepad connected: Logitech F710")

    def press(self) -> None:
        self.gate()
        hold = random.uniform(3.0, 6.0)
        self.get_logger().info(f"deadman held: teleop for {hold:.1f} s")
        self.timer = self.create_timer(0.05, self.tick)
        self.after(hold, self.release)
        self.after(random.uniform(35.0, 45.0), self.press)

    def release(self) -> None:
        self.gate()
        self.destroy_timer(self.timer)
        self.pub.publish(Twist())  # a last zero command, as teleop_twist_joy sends on release
        self.get_logger().info("deadman released")

    def tick(self) -> None:
        self.gate()
        cmd = Twist()
        cmd.linear.x, cmd.angular.z = 0.15, 0.3 * math.sin(time.monotonic())
        self.pub.publish(cmd)


class Console(LabNode):
    """The operator's console: watches the map, the plan, the detections and the diagnostics."""

    def __init__(self, fd: Path) -> None:
        super().__init__("console", "/lab", fd)
        self.seen: dict[str, int] = {}
        self.warned: set[str] = set()
        for topic, typ, qos in (("map", OccupancyGrid, LATCHED), ("coverage_path", PathMsg, LATCHED),
                                ("detections", PoseArray, 10), ("/diagnostics", DiagnosticArray, 10),
                                ("grasp_poses", PoseArray, 10)):
            self.create_subscription(typ, topic, partial(self.on_msg, topic), qos)
        self.cam = self.create_client(GetState, "depth_camera/get_state")
        self.create_timer(10.0, self.report)
        self.get_logger().info("operator console connected")

    def on_msg(self, topic: str, msg) -> None:
        self.gate()
        self.seen[topic] = self.seen.get(topic, 0) + 1
        if isinstance(msg, DiagnosticArray):
            for s in msg.status:
                if s.level != OK and s.name not in self.warned:
                    self.warned.add(s.name)
                    self.get_logger().info(f"diagnostics: {s.name}: {s.message}")

    def report(self) -> None:
        self.gate()
        if self.cam.service_is_ready():
            self.cam.call_async(GetState.Request()).add_done_callback(
                lambda f: self.get_logger().info(f"depth camera {f.result().current_state.label}"))
        counts = ", ".join(f"{t} {n}" for t, n in sorted(self.seen.items()))
        self.get_logger().info(f"received: {counts}")


# process -> (executor, node factories): "single" one SingleThreadedExecutor for all its nodes
# (the perception container: three nodes composed on one), "multi" one MultiThreadedExecutor
PROCESSES: dict[str, tuple[str, tuple[Callable[[Path], Node], ...]]] = {
    "base": ("single", (ImuDriver, BaseController)),
    "lidar": ("single", (LidarDriver,)),
    "perception": ("single", (DepthCamera, RgbCamera, ObjectDetector)),
    "slam": ("single", (SlamMapper,)),
    "coverage": ("single", (CoveragePlanner,)),
    "arms": ("multi", (partial(ArmController, side="left"), partial(ArmController, side="right"))),
    "grasping": ("multi", (GraspPlanner,)),
    "executive": ("single", (LifecycleManager, TaskManager, Navigator)),
    "tools": ("single", (LogPlayer, DiskMonitor)),
    "teleop": ("single", (Joystick,)),
    "console": ("single", (Console,)),
}


def _burn() -> None:
    while True:
        pass


def _leak() -> None:
    kept = []
    while True:
        kept.append(b"\xab" * (2 << 20))  # written, so resident
        time.sleep(1.0)


def _watch(fd: Path, process: str, nodes: list[Hooks]) -> None:
    """Every 0.5 s: the process's fault (``<process>.cpu``: a thread burning a core, ``.leak``: one
    leaking 2 MB/s), a node's new fault from its file (its guard condition triggered); a node with
    ``errlog`` logs an ERROR every second."""
    started: set[str] = set()
    k = 0
    while True:
        k += 1
        for how, target in (("cpu", _burn), ("leak", _leak)):
            if how not in started and (fd / f"{process}.{how}").exists():
                started.add(how)
                threading.Thread(target=target, daemon=True).start()
        for node in nodes:
            if node.fault is None and node.fault_file.exists():
                node.fault = node.fault_file.read_text().strip() or None  # empty: still being written
                if node.fault:
                    node.fault_set.trigger()
            if node.fault == "errlog" and k % 2 == 0:
                node.on_errlog()
        time.sleep(0.5)


def _spin(ex: Executor) -> None:
    try:
        ex.spin()  # until the executor is shut down or the context (Ctrl-C)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:  # the context shut down under it (Ctrl-C)
        if rclpy.ok():
            raise


def main(argv: list[str]) -> int:
    process, fd = argv[0], Path(argv[1])
    run_for = float(argv[2]) if len(argv) > 2 else 0.0
    kind, factories = PROCESSES[process]
    rclpy.init()
    nodes = [f(fd) for f in factories]
    ex: Executor = MultiThreadedExecutor(num_threads=4) if kind == "multi" else SingleThreadedExecutor()
    for node in nodes:
        ex.add_node(node)
    spinner = threading.Thread(target=_spin, args=(ex,), daemon=True)
    threading.Thread(target=_watch, args=(fd, process, nodes), daemon=True).start()
    spinner.start()
    print("ready", flush=True)
    end = time.monotonic() + run_for if run_for else float("inf")
    try:
        while rclpy.ok() and time.monotonic() < end:
            time.sleep(0.1)
    except KeyboardInterrupt:
        pass
    if any(node.fault in ("hang", "stall", "block_state") for node in nodes):
        os._exit(0)  # a hung callback: leave without cleaning up
    ex.shutdown(timeout_sec=2.0)
    spinner.join(2.0)
    if spinner.is_alive():
        os._exit(0)
    for node in nodes:
        node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
