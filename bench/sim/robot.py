"""A rover prototyped in simulation: one OS process of it per call.

``python -m bench.sim.robot PROCESS FAULT_DIR [RUN_FOR]`` (see `bench.handwritten`): runs the
nodes of ``PROCESS`` in plain rclpy until SIGINT, or for ``RUN_FOR`` s of wall time (then exits
with code 0). ``FAULT_DIR/<node name>`` holds a node's fault (``hang``, ``stall``, ...),
``FAULT_DIR/<process>.cpu`` / ``.leak`` start the process's CPU burner or its leak.

The simulator (``gz_sim``) is on wall time: it publishes ``/clock`` at 50 Hz of
wall time with a real-time factor between 0.6 and 1.0 that changes with the physics load every
20-60 s. Every other node has ``use_sim_time`` set: its stamps and its timers are in sim time,
so their wall-clock rates follow the real-time factor (the bag recorder excepted: no
``--use-sim-time``, it records /clock as a topic). The bridge emits each sensor when the
sim time passes its next sample (several samples per clock step if need be), as the simulator's
sensors do.

No tf2_msgs in this environment: ``/tf`` and ``/tf_static`` carry one
geometry_msgs/TransformStamped per message (odom->base_link from the bridge, map->odom from
SLAM, the wheel joints from the robot_state_publisher). No nav2_msgs / bond either: goals come on
``/goal_pose`` (PoseStamped, as rviz sends them), the navigator hands the path to the controller
on ``/sim/follow_path`` (an empty path cancels), the planner serves nav_msgs/GetPlan on
``/sim/compute_path`` and the bonds are std_msgs/Header heartbeats on ``/sim/bond``. The
lifecycle of the nav servers is rclpy's (lifecycle_msgs services and transition events).
"""

from __future__ import annotations

import math
import os
import queue
import random
import socket
import sys
import threading
import time
from pathlib import Path
from typing import ClassVar

import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, TransformStamped, Twist
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState
from nav_msgs.msg import MapMetaData, OccupancyGrid, Odometry
from nav_msgs.msg import Path as NavPath
from nav_msgs.srv import GetPlan
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue, SetParametersResult
from rcl_interfaces.srv import SetParameters
from rclpy.clock import Clock, ClockType
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.task import Future
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import CameraInfo, Image, Imu, JointState, LaserScan
from std_msgs.msg import Header, String

SIM_TIME = [Parameter("use_sim_time", Parameter.Type.BOOL, True)]
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
TF_STATIC = QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                       reliability=ReliabilityPolicy.RELIABLE)
CLOCK_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT)
STEADY = Clock(clock_type=ClockType.STEADY_TIME)
ROOM = (-3.0, 6.0, -3.0, 6.0)  # the world's walls: x min, x max, y min, y max (m)
WAYPOINTS = ((3.0, 0.0), (3.0, 3.0), (0.0, 3.0), (0.0, 0.0))
WHEEL_R, WHEEL_SEP = 0.1, 0.4
URDF = """<?xml version="1.0"?>
<robot name="sim_rover">
  <link name="base_footprint"/><link name="base_link"/><link name="left_wheel"/><link name="right_wheel"/>
  <link name="imu_link"/><link name="lidar_link"/><link name="camera_link"/>
  <joint name="base_joint" type="fixed"><parent link="base_footprint"/><child link="base_link"/></joint>
  <joint name="left_wheel_joint" type="continuous"><parent link="base_link"/><child link="left_wheel"/>
    <origin xyz="0 0.2 0"/><axis xyz="0 1 0"/></joint>
  <joint name="right_wheel_joint" type="continuous"><parent link="base_link"/><child link="right_wheel"/>
    <origin xyz="0 -0.2 0"/><axis xyz="0 1 0"/></joint>
  <joint name="imu_joint" type="fixed"><parent link="base_link"/><child link="imu_link"/></joint>
  <joint name="lidar_joint" type="fixed"><parent link="base_link"/><child link="lidar_link"/>
    <origin xyz="0.1 0 0.2"/></joint>
  <joint name="camera_joint" type="fixed"><parent link="base_link"/><child link="camera_link"/>
    <origin xyz="0.2 0 0.15"/></joint>
</robot>
"""


class Faults:
    """A node's fault file, read at most every 0.5 s of wall time (the content, or '')."""

    def __init__(self, fault_dir: Path, name: str) -> None:
        self.path, self.value, self.read_at = fault_dir / name, "", 0.0

    def __call__(self) -> str:
        now = time.monotonic()
        if now - self.read_at > 0.5:
            self.read_at = now
            try:
                self.value = self.path.read_text().strip()
            except OSError:
                self.value = ""
        return self.value


def process_faults(fault_dir: Path, process: str) -> None:
    """The process's CPU burner (a runaway worker thread) and its leak (3 MB/s), started by their files."""
    def watch() -> None:
        burning = leaking = False
        hoard: list[bytes] = []
        while True:
            if not burning and (fault_dir / f"{process}.cpu").exists():
                burning = True
                threading.Thread(target=burn, daemon=True).start()
            leaking = leaking or (fault_dir / f"{process}.leak").exists()
            if leaking:
                hoard.append(b"\x5a" * (3 << 19))  # 1.5 MB every 0.5 s, every page touched
            time.sleep(0.5)

    def burn() -> None:
        x = 0
        while True:
            for i in range(20000):
                x = (x * 31 + i) & 0xFFFFFFFF

    threading.Thread(target=watch, daemon=True).start()


def stamp_of(node: Node) -> Time:
    return node.get_clock().now().to_msg()


def secs(t: Time) -> float:
    return t.sec + t.nanosec * 1e-9


def to_time(s: float) -> Time:
    sec = int(s)
    return Time(sec=sec, nanosec=int((s - sec) * 1e9))


def yaw_quat(yaw: float) -> tuple[float, float]:
    return math.sin(yaw / 2.0), math.cos(yaw / 2.0)


def transform(stamp: Time, parent: str, child: str, x: float = 0.0, y: float = 0.0, z: float = 0.0,
              yaw: float = 0.0) -> TransformStamped:
    t = TransformStamped()
    t.header.stamp, t.header.frame_id, t.child_frame_id = stamp, parent, child
    t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = x, y, z
    t.transform.rotation.z, t.transform.rotation.w = yaw_quat(yaw)
    return t


def grid(stamp: Time, frame: str, size: int, res: float, ox: float, oy: float, data) -> OccupancyGrid:
    g = OccupancyGrid()
    g.header.stamp, g.header.frame_id = stamp, frame
    g.info.map_load_time, g.info.resolution, g.info.width, g.info.height = stamp, res, size, size
    g.info.origin.position.x, g.info.origin.position.y = ox, oy
    g.info.origin.orientation.w = 1.0
    g.data = data
    return g


def room_grid(size: int, res: float, ox: float, oy: float, known: float = 1.0) -> bytes:
    """The room as an occupancy grid (walls 100, free 0, unknown -1 beyond ``known`` of the room)."""
    x0, x1, y0, y1 = ROOM
    cells = bytearray(size * size)
    for j in range(size):
        y = oy + (j + 0.5) * res
        for i in range(size):
            x = ox + (i + 0.5) * res
            if x < x0 - res or x > x1 + res or y < y0 - res or y > y1 + res:
                v = 255  # -1
            elif min(abs(x - x0), abs(x - x1), abs(y - y0), abs(y - y1)) < res:
                v = 100
            elif x > x0 + known * (x1 - x0):
                v = 255
            else:
                v = 0
            cells[j * size + i] = v
    return bytes(cells)


def signed(data: bytes) -> list[int]:
    return [v - 256 if v > 127 else v for v in data]


# --- the simulator ---------------------------------------------------------------------------------

class GzSim(Node):
    """The simulator's ROS side: /clock at 50 Hz of wall time, sim time from 0, RTF 0.6-1.0."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("gz_sim")
        self.fault = Faults(fault_dir, "gz_sim")
        self.clock_pub = self.create_publisher(ClockMsg, "/clock", CLOCK_QOS)
        self.sim, self.last = 0.0, time.monotonic()
        self.rtf, self.load_until = 1.0, self.last + random.uniform(20.0, 60.0)
        self.get_logger().info("Serving world [empty_room] with physics [dart], step size 1 ms")
        self.create_timer(0.02, self._step)

    def _step(self) -> None:
        now = time.monotonic()
        if now >= self.load_until:  # the physics load changes (contacts, sensors, rendering)
            self.rtf, self.load_until = random.uniform(0.6, 1.0), now + random.uniform(20.0, 60.0)
        rtf = 0.2 if self.fault() == "slow" else self.rtf  # a collision mesh gone pathological
        self.sim += min(now - self.last, 0.1) * rtf
        self.last = now
        self.clock_pub.publish(ClockMsg(clock=to_time(self.sim)))


class GzBridge(Node):
    """ros_gz_bridge: the simulated sensors and the diff drive, emitted at their sim-time rates."""

    RATES: ClassVar[dict[str, float]] = {"imu": 200.0, "odom": 50.0, "joints": 50.0, "scan": 10.0,
                                         "camera": 15.0}

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("ros_gz_bridge", parameter_overrides=SIM_TIME)
        self.fault = Faults(fault_dir, "ros_gz_bridge")
        self.imu_pub = self.create_publisher(Imu, "/imu", 10)
        self.odom_pub = self.create_publisher(Odometry, "/odom", 10)
        self.joints_pub = self.create_publisher(JointState, "/joint_states", 10)
        self.scan_pub = self.create_publisher(LaserScan, "/scan", 10)
        self.image_pub = self.create_publisher(Image, "/camera/image_raw", qos_profile_sensor_data)
        self.info_pub = self.create_publisher(CameraInfo, "/camera/camera_info", qos_profile_sensor_data)
        self.tf_pub = self.create_publisher(TransformStamped, "/tf", 10)
        self.create_subscription(Twist, "/cmd_vel", self._cmd, 10)
        self.x = self.y = self.yaw = 0.0
        self.v = self.w = 0.0
        self.cmd_at = -1.0
        self.wl = self.wr = 0.0
        self.t = None
        self.due = dict.fromkeys(self.RATES, 0.0)
        self.frames = []
        for k in range(3):  # a few rendered frames of the camera, 320x240 rgb8 (230 KB)
            img = Image(height=240, width=320, encoding="rgb8", is_bigendian=0, step=960)
            img.header.frame_id = "camera_link"
            img.data = bytes(((i * 7 + k * 40) & 0xFF) for i in range(256)) * 900
            self.frames.append(img)
        self.frame = 0
        self.info = CameraInfo(height=240, width=320, distortion_model="plumb_bob")
        self.info.header.frame_id = "camera_link"
        self.info.k = [277.0, 0.0, 160.0, 0.0, 277.0, 120.0, 0.0, 0.0, 1.0]
        self.info.p = [277.0, 0.0, 160.0, 0.0, 0.0, 277.0, 120.0, 0.0, 0.0, 0.0, 1.0, 0.0]
        self.cos = [math.cos(math.radians(a)) for a in range(360)]
        self.sin = [math.sin(math.radians(a)) for a in range(360)]
        for topic in ("/clock", "/imu", "/odom", "/joint_states", "/scan", "/camera/image_raw",
                      "/camera/camera_info", "/tf", "/cmd_vel"):
            self.get_logger().info(f"Creating GZ->ROS Bridge: [{topic}]")
        self.create_timer(0.005, self._step)  # at most once per clock step: emits what is due

    def _cmd(self, msg: Twist) -> None:
        self.v, self.w = max(-1.0, min(1.0, msg.linear.x)), max(-2.0, min(2.0, msg.angular.z))
        self.cmd_at = self.t or 0.0

    def _step(self) -> None:
        t = self.get_clock().now().nanoseconds * 1e-9
        if self.t is None:
            self.t = t
            self.due = dict.fromkeys(self.RATES, t)
            return
        dt, self.t = t - self.t, t
        if dt <= 0.0:
            return
        if t - self.cmd_at > 0.5:  # the diff drive's command timeout
            self.v = self.w = 0.0
        self.yaw = (self.yaw + self.w * dt) % (2 * math.pi)
        self.x += self.v * math.cos(self.yaw) * dt
        self.y += self.v * math.sin(self.yaw) * dt
        self.wl += (self.v - self.w * WHEEL_SEP / 2) / WHEEL_R * dt
        self.wr += (self.v + self.w * WHEEL_SEP / 2) / WHEEL_R * dt
        degraded = self.fault() == "degrade"  # the IMU sensor's update rate halved (a bad SDF reload)
        for sensor, rate in self.RATES.items():
            period = 1.0 / (rate / 2 if degraded and sensor == "imu" else rate)
            if self.due[sensor] < t - 1.0:
                self.due[sensor] = t
            while self.due[sensor] <= t:
                getattr(self, "_" + sensor)(to_time(self.due[sensor]))
                self.due[sensor] += period

    def _imu(self, stamp: Time) -> None:
        m = Imu()
        m.header.stamp, m.header.frame_id = stamp, "imu_link"
        m.orientation.z, m.orientation.w = yaw_quat(self.yaw)
        m.angular_velocity.z = self.w + random.gauss(0.0, 0.002)
        m.linear_acceleration.x = random.gauss(0.0, 0.02)
        m.linear_acceleration.z = 9.81 + random.gauss(0.0, 0.02)
        self.imu_pub.publish(m)

    def _odom(self, stamp: Time) -> None:
        m = Odometry()
        m.header.stamp, m.header.frame_id, m.child_frame_id = stamp, "odom", "base_link"
        m.pose.pose.position.x, m.pose.pose.position.y = self.x, self.y
        m.pose.pose.orientation.z, m.pose.pose.orientation.w = yaw_quat(self.yaw)
        m.twist.twist.linear.x, m.twist.twist.angular.z = self.v, self.w
        self.odom_pub.publish(m)
        self.tf_pub.publish(transform(stamp, "odom", "base_link", self.x, self.y, 0.0, self.yaw))

    def _joints(self, stamp: Time) -> None:
        left, right = (self.v - self.w * WHEEL_SEP / 2) / WHEEL_R, (self.v + self.w * WHEEL_SEP / 2) / WHEEL_R
        m = JointState(name=["left_wheel_joint", "right_wheel_joint"], position=[self.wl, self.wr],
                       velocity=[left, right])
        m.header.stamp = stamp
        self.joints_pub.publish(m)

    def _scan(self, stamp: Time) -> None:
        x0, x1, y0, y1 = ROOM
        base = int(math.degrees(self.yaw))
        ranges = []
        for i in range(360):
            a = (base + i) % 360
            c, s = self.cos[a], self.sin[a]
            rx = (x1 - self.x) / c if c > 1e-6 else (x0 - self.x) / c if c < -1e-6 else 99.0
            ry = (y1 - self.y) / s if s > 1e-6 else (y0 - self.y) / s if s < -1e-6 else 99.0
            ranges.append(min(rx, ry, 12.0) + random.gauss(0.0, 0.01))
        m = LaserScan(angle_min=0.0, angle_max=2 * math.pi - math.radians(1), angle_increment=math.radians(1),
                      scan_time=0.1, range_min=0.12, range_max=12.0, ranges=ranges)
        m.header.stamp, m.header.frame_id = stamp, "lidar_link"
        self.scan_pub.publish(m)

    def _camera(self, stamp: Time) -> None:
        img = self.frames[self.frame]
        self.frame = (self.frame + 1) % len(self.frames)
        img.header.stamp = self.info.header.stamp = stamp
        self.image_pub.publish(img)
        self.info_pub.publish(self.info)


class RobotStatePublisher(Node):
    """robot_state_publisher: the URDF and the fixed joints latched, the wheels from /joint_states."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("robot_state_publisher", parameter_overrides=SIM_TIME)
        self.declare_parameter("robot_description", URDF)
        self.declare_parameter("publish_frequency", 20.0)
        desc = self.create_publisher(String, "/robot_description", LATCHED)
        desc.publish(String(data=URDF))
        self.static = self.create_publisher(TransformStamped, "/tf_static", TF_STATIC)
        zero = Time()
        for parent, child, x, z in (("base_footprint", "base_link", 0.0, 0.1),
                                    ("base_link", "imu_link", 0.0, 0.05),
                                    ("base_link", "lidar_link", 0.1, 0.2),
                                    ("base_link", "camera_link", 0.2, 0.15)):
            self.static.publish(transform(zero, parent, child, x, 0.0, z))
        self.tf_pub = self.create_publisher(TransformStamped, "/tf", 10)
        self.create_subscription(JointState, "/joint_states", self._joints, 10)
        self.published = -1.0
        self.get_logger().info("Robot initialized")

    def _joints(self, msg: JointState) -> None:
        t = secs(msg.header.stamp)
        if t - self.published < 1.0 / 20.0 - 1e-3:  # publish_frequency: at most 20 Hz of moving joints
            return
        self.published = t
        for name, pos in zip(msg.name, msg.position, strict=True):
            side = name.split("_")[0]
            y = 0.2 if side == "left" else -0.2
            t = transform(msg.header.stamp, "base_link", f"{side}_wheel", 0.0, y)
            t.transform.rotation.y, t.transform.rotation.w = math.sin(pos / 2), math.cos(pos / 2)
            t.transform.rotation.z = 0.0
            self.tf_pub.publish(t)


# --- navigation: one component container, single-threaded ------------------------------------------

class NavServer(LifecycleNode):
    """A nav2 lifecycle server in the container: a bond heartbeat once active."""

    def __init__(self, name: str, fault_dir: Path) -> None:
        super().__init__(name, namespace="sim", parameter_overrides=SIM_TIME)
        self.fault = Faults(fault_dir, name)
        self.active = False
        self.bond = self.create_publisher(Header, "bond", 10)
        self.create_timer(1.0, self._heartbeat)

    def _heartbeat(self) -> None:
        if self.active:
            self.bond.publish(Header(stamp=stamp_of(self), frame_id=self.get_name()))

    def on_configure(self, state) -> TransitionCallbackReturn:
        self.get_logger().info("Configuring")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        self.get_logger().info("Activating")
        self.get_logger().info(f"Creating bond ({self.get_name()}) to lifecycle manager.")
        self.active = True
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        self.active = False
        return TransitionCallbackReturn.SUCCESS


class ControllerServer(NavServer):
    """Follows the path it is handed at 20 Hz (sim) on /cmd_vel_nav; the local costmap at 1 Hz."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("controller_server", fault_dir)
        self.declare_parameter("controller_frequency", 20.0)
        self.declare_parameter("FollowPath.desired_linear_vel", 0.5)
        self.declare_parameter("FollowPath.lookahead_dist", 0.6)
        self.declare_parameter("FollowPath.max_angular_vel", 1.2)
        self.add_on_set_parameters_callback(self._params)
        self.cmd_pub = self.create_publisher(Twist, "/cmd_vel_nav", 10)
        self.costmap_pub = self.create_publisher(OccupancyGrid, "local_costmap/costmap", 10)
        self.create_subscription(Odometry, "/odom", self._odom, 10)
        self.create_subscription(NavPath, "follow_path", self._path, 10)
        self.pose = None
        self.path: list[tuple[float, float]] = []
        self.loop_wall = self.loop_sim = None
        self.warned_at = -1e9
        self.local = room_grid(60, 0.05, -1.5, -1.5)
        self.create_timer(0.05, self._control)
        self.create_timer(1.0, self._costmap)
        self.create_timer(1.0, self._errlog, clock=STEADY)

    def _params(self, params) -> SetParametersResult:
        for p in params:
            self.get_logger().info(f"Parameter {p.name} set to {p.value}")
        return SetParametersResult(successful=True)

    def _odom(self, msg: Odometry) -> None:
        if self.fault() == "hang":  # waits on a mutex a dead plugin thread still holds
            threading.Event().wait()
        q = msg.pose.pose.orientation
        self.pose = (msg.pose.pose.position.x, msg.pose.pose.position.y, 2 * math.atan2(q.z, q.w))

    def _path(self, msg: NavPath) -> None:
        if not self.active:
            return
        was = bool(self.path)
        self.path = [(p.pose.position.x, p.pose.position.y) for p in msg.poses]
        if self.path and not was:
            self.get_logger().info("Received a goal, begin computing control effort.")
            self.loop_wall = self.loop_sim = None
        elif not self.path and was:
            self.cmd_pub.publish(Twist())

    def _control(self) -> None:
        if not self.active or not self.path or self.pose is None:
            return
        now_wall, now_sim = time.monotonic(), self.get_clock().now().nanoseconds * 1e-9
        if self.loop_wall is not None and now_wall - self.loop_wall > 0.0:
            rate = 1.0 / (now_wall - self.loop_wall)
            rtf = (now_sim - self.loop_sim) / (now_wall - self.loop_wall)
            if rtf < 0.75 and now_sim - self.warned_at > 30.0:
                self.warned_at = now_sim
                self.get_logger().warn(f"Control loop missed its desired rate of 20.0000 Hz. "
                                       f"Current loop rate is {rate:.4f} Hz.")
        self.loop_wall, self.loop_sim = now_wall, now_sim
        x, y, yaw = self.pose
        look = self.get_parameter("FollowPath.lookahead_dist").value
        while len(self.path) > 1 and math.hypot(self.path[0][0] - x, self.path[0][1] - y) < look:
            self.path.pop(0)
        gx, gy = self.path[0]
        dist = math.hypot(gx - x, gy - y)
        cmd = Twist()
        if len(self.path) == 1 and dist < 0.15:
            self.path = []
            self.get_logger().info("Reached the goal!")
        else:
            bearing = math.atan2(gy - y, gx - x) - yaw
            err = math.atan2(math.sin(bearing), math.cos(bearing))
            wmax = self.get_parameter("FollowPath.max_angular_vel").value
            cmd.angular.z = max(-wmax, min(wmax, 2.0 * err))
            v = self.get_parameter("FollowPath.desired_linear_vel").value
            cmd.linear.x = v * max(0.0, math.cos(err)) ** 2 * min(1.0, dist / 0.5 + 0.3)
        self.cmd_pub.publish(cmd)

    def _costmap(self) -> None:
        if self.fault() == "hang":  # the costmap update waits on the same mutex
            threading.Event().wait()
        if self.active and self.pose is not None:
            x, y = self.pose[0] - 1.5, self.pose[1] - 1.5
            self.costmap_pub.publish(grid(stamp_of(self), "odom", 60, 0.05, x, y, self.local))

    def _errlog(self) -> None:
        if self.fault() == "errlog":  # the costmap's obstacle layer rejects every scan, the loop goes on
            x, y = (self.pose or (0.0, 0.0))[:2]
            self.get_logger().error(f"Sensor origin at ({x:.2f}, {y:.2f}) is out of map bounds "
                                    "(local_costmap). The costmap cannot raytrace for it.")


class PlannerServer(NavServer):
    """Serves /sim/compute_path (planning on its worker thread); the global costmap at 0.2 Hz."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("planner_server", fault_dir)
        self.declare_parameter("expected_planner_frequency", 1.0)
        self.declare_parameter("GridBased.tolerance", 0.5)
        # the response is deferred to the planning thread (rclcpp's deferred service response)
        self.srv = self.create_service(GetPlan, "compute_path", self._accept)
        self.respond = self.srv.send_response
        self.srv.send_response = self._defer
        self.accepted: dict[int, GetPlan.Request] = {}
        self.plan_pub = self.create_publisher(NavPath, "plan", 10)
        self.costmap_pub = self.create_publisher(OccupancyGrid, "global_costmap/costmap", 10)
        self.global_map = signed(room_grid(100, 0.1, -3.5, -3.5))
        self.requests: queue.Queue = queue.Queue()
        self.done: queue.Queue = queue.Queue()
        self.wake = self.create_guard_condition(self._finish)
        threading.Thread(target=self._worker, daemon=True).start()
        self.create_timer(5.0, self._costmap)

    def _accept(self, request: GetPlan.Request, response: GetPlan.Response) -> GetPlan.Response:
        self.accepted[id(response)] = request
        return response

    def _defer(self, response: GetPlan.Response, header) -> None:
        self.requests.put((self.accepted.pop(id(response)), header))

    def _worker(self) -> None:
        while True:
            request, header = self.requests.get()
            t0 = time.monotonic()
            while self.fault() == "stall":  # the costmap lock is never released: no plan ever
                time.sleep(0.5)
            path = self._plan(request)
            self.done.put((header, path, time.monotonic() - t0))
            self.wake.trigger()

    def _plan(self, request: GetPlan.Request) -> NavPath:
        sx, sy = request.start.pose.position.x, request.start.pose.position.y
        gx, gy = request.goal.pose.position.x, request.goal.pose.position.y
        length = max(0.01, math.hypot(gx - sx, gy - sy))
        n = max(2, int(length / 0.05))
        path = NavPath()
        path.header.frame_id = "map"
        path.header.stamp = stamp_of(self)
        for i in range(n + 1):
            f = i / n
            p = PoseStamped()
            p.header = path.header
            bow = 0.15 * math.sin(math.pi * f) / length  # around the obstacle inflation
            p.pose.position.x = sx + (gx - sx) * f - bow * (gy - sy)
            p.pose.position.y = sy + (gy - sy) * f + bow * (gx - sx)
            p.pose.orientation.w = 1.0
            path.poses.append(p)
        return path

    def _finish(self) -> None:
        while not self.done.empty():
            header, path, took = self.done.get()
            self.plan_pub.publish(path)
            end = path.poses[-1].pose.position
            self.get_logger().info(f"Computed path of {len(path.poses)} poses to ({end.x:.2f}, {end.y:.2f}) "
                                   f"in {took * 1000:.1f} ms (GridBased)")
            self.respond(GetPlan.Response(plan=path), header)

    def _costmap(self) -> None:
        if self.active:
            self.costmap_pub.publish(grid(stamp_of(self), "map", 100, 0.1, -3.5, -3.5, self.global_map))


class BtNavigator(NavServer):
    """Navigates to each /goal_pose: replans at 1 Hz (sim) through /sim/compute_path, hands the path
    to the controller, declares success near the goal; aborts when the planner does not answer."""

    TIMEOUT = 5.0

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("bt_navigator", fault_dir)
        self.declare_parameter("default_nav_to_pose_bt_xml", "navigate_w_replanning_and_recovery.xml")
        self.declare_parameter("bt_loop_duration", 10)
        self.planner = self.create_client(GetPlan, "compute_path")
        self.path_pub = self.create_publisher(NavPath, "follow_path", 10)
        self.create_subscription(PoseStamped, "/goal_pose", self._goal, 10)
        self.create_subscription(Odometry, "/odom", self._odom, 10)
        self.goal = None
        self.pose = (0.0, 0.0)
        self.pending = None
        self.sent_at = 0.0
        self.create_timer(1.0, self._tick)

    def _odom(self, msg: Odometry) -> None:
        self.pose = (msg.pose.pose.position.x, msg.pose.pose.position.y)

    def _goal(self, msg: PoseStamped) -> None:
        if not self.active:
            self.get_logger().warn("Received goal while inactive, rejecting")
            return
        if self.goal is not None:
            self.get_logger().info("Received goal preemption request")
        self.goal = msg
        self.started = self.now()
        x, y = self.pose
        self.get_logger().info(f"Begin navigating from current location ({x:.2f}, {y:.2f}) to "
                               f"({msg.pose.position.x:.2f}, {msg.pose.position.y:.2f})")
        self._tick()

    def now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _end(self) -> None:
        self.goal = None
        if self.pending is not None:
            self.planner.remove_pending_request(self.pending)
            self.pending = None
        self.path_pub.publish(NavPath())

    def _tick(self) -> None:
        if self.goal is None:
            return
        g = self.goal.pose.position
        if math.hypot(g.x - self.pose[0], g.y - self.pose[1]) < 0.25:
            self.get_logger().info("Goal succeeded")
            self._end()
            return
        if self.pending is not None:
            if self.now() - self.sent_at > self.TIMEOUT:
                self.get_logger().error(f"\"compute_path\" service server /sim/compute_path did not respond "
                                        f"within {self.TIMEOUT:.1f} s: ComputePathToPose failed")
                self.get_logger().error("Goal failed")
                self._end()
            return
        if self.now() - self.started > 120.0:
            self.get_logger().error("Goal failed: navigation time limit exceeded")
            self._end()
            return
        if not self.planner.service_is_ready():
            return
        req = GetPlan.Request(goal=self.goal, tolerance=0.5)
        req.start.header.frame_id = "map"
        req.start.pose.position.x, req.start.pose.position.y = self.pose
        self.pending, self.sent_at = self.planner.call_async(req), self.now()
        self.pending.add_done_callback(self._planned)

    def _planned(self, future: Future) -> None:
        if future is not self.pending:
            return
        self.pending = None
        if self.goal is not None and future.result() is not None:
            self.path_pub.publish(future.result().plan)


class WaypointFollower(NavServer):
    """Patrols the waypoints: the next goal 6 s (sim, ``waypoint_pause_duration``) after the navigator
    ends the previous one (its empty path to the controller), or 60 s after sending it."""

    PAUSE, GIVE_UP = 6.0, 60.0

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("waypoint_follower", fault_dir)
        self.declare_parameter("loop_rate", 20)
        self.declare_parameter("stop_on_failure", False)
        self.declare_parameter("waypoint_pause_duration", int(self.PAUSE * 1000))
        self.goal_pub = self.create_publisher(PoseStamped, "/goal_pose", 10)
        self.create_subscription(NavPath, "follow_path", self._followed, 10)
        self.i = 0
        self.sent_at = None  # sim time of the goal under way
        self.next_at = 10.0  # sim time of the next goal
        self.create_timer(1.0, self._next)

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _followed(self, msg: NavPath) -> None:
        if not msg.poses and self.sent_at is not None:  # the navigator ended the goal
            self.sent_at, self.next_at = None, self._now() + self.PAUSE

    def _next(self) -> None:
        now = self._now()
        if not self.active:
            return
        if self.sent_at is not None and now - self.sent_at > self.GIVE_UP:
            self.get_logger().warn(f"Waypoint {self.i % len(WAYPOINTS)} not reached after "
                                   f"{self.GIVE_UP:.0f} s, moving on")
            self.sent_at, self.next_at = None, now
        if self.sent_at is not None or now < self.next_at:
            return
        x, y = WAYPOINTS[self.i % len(WAYPOINTS)]
        self.i += 1
        self.get_logger().info(f"Following waypoint {self.i % len(WAYPOINTS)} of {len(WAYPOINTS)}")
        goal = PoseStamped()
        goal.header.stamp, goal.header.frame_id = stamp_of(self), "map"
        goal.pose.position.x, goal.pose.position.y, goal.pose.orientation.w = x, y, 1.0
        self.sent_at = now
        self.goal_pub.publish(goal)


class LifecycleManager(Node):
    """lifecycle_manager_navigation: configures then activates the servers in order; watches their bonds."""

    ORDER = ("controller_server", "smoother_server", "planner_server", "behavior_server", "bt_navigator",
             "waypoint_follower")

    def __init__(self) -> None:
        super().__init__("lifecycle_manager_navigation", namespace="sim", parameter_overrides=SIM_TIME)
        self.declare_parameter("autostart", True)
        self.declare_parameter("node_names", list(self.ORDER))
        self.declare_parameter("bond_timeout", 4.0)
        self.clients_ = {n: self.create_client(ChangeState, f"/sim/{n}/change_state") for n in self.ORDER}
        self.create_subscription(Header, "bond", self._bond, 10)
        self.bonds: dict[str, float] = {}
        self.broken: set[str] = set()
        self.bond_pub = self.create_publisher(Header, "bond", 10)
        self.steps = [(label, tid, n) for label, tid in (("Configuring", Transition.TRANSITION_CONFIGURE),
                                                         ("Activating", Transition.TRANSITION_ACTIVATE))
                      for n in self.ORDER]
        self.waiting = False
        self.get_logger().info("Starting managed nodes bringup...")
        self.startup = self.create_timer(0.2, self._bringup, clock=STEADY)
        self.create_timer(1.0, self._watch)

    def _bringup(self) -> None:
        """The next transition of the bring-up, once the previous one answered and its server is up."""
        if self.waiting:
            return
        if not self.steps:
            self.startup.cancel()
            self.get_logger().info("Managed nodes are active")
            now = self.get_clock().now().nanoseconds * 1e-9
            self.bonds = dict.fromkeys(self.ORDER, now)
            return
        label, tid, n = self.steps[0]
        client = self.clients_[n]
        if not client.service_is_ready():
            return
        self.get_logger().info(f"{label} {n}")
        self.waiting = True
        client.call_async(ChangeState.Request(transition=Transition(id=tid))).add_done_callback(self._changed)

    def _changed(self, future: Future) -> None:
        _, _, n = self.steps.pop(0)
        if not future.result() or not future.result().success:
            self.get_logger().error(f"Failed to change state for node: {n}")
            self.steps = []
            self.startup.cancel()
            return
        self.waiting = False
        self._bringup()

    def _bond(self, msg: Header) -> None:
        if msg.frame_id in self.bonds:
            self.bonds[msg.frame_id] = secs(msg.stamp)

    def _watch(self) -> None:
        now = self.get_clock().now().nanoseconds * 1e-9
        self.bond_pub.publish(Header(stamp=stamp_of(self), frame_id=self.get_name()))
        for n, t in self.bonds.items():
            if now - t > 4.0 and n not in self.broken:
                self.broken.add(n)
                self.get_logger().error(f"Server {n} was unable to be reached after 4.00s by bond. "
                                        "This server may have crashed.")


# --- SLAM, command mux, teleop -----------------------------------------------------------------------

class SlamToolbox(Node):
    """slam_toolbox (online async): /map every 5 s of sim time, map->odom at 20 Hz (sim)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("slam_toolbox", parameter_overrides=SIM_TIME)
        self.fault = Faults(fault_dir, "slam_toolbox")
        self.declare_parameter("mode", "mapping")
        self.declare_parameter("map_update_interval", 5.0)
        self.declare_parameter("transform_publish_period", 0.05)
        self.map_pub = self.create_publisher(OccupancyGrid, "/map", LATCHED)
        self.meta_pub = self.create_publisher(MapMetaData, "/map_metadata", LATCHED)
        self.tf_pub = self.create_publisher(TransformStamped, "/tf", 10)
        self.create_subscription(LaserScan, "/scan", self._scan, qos_profile_sensor_data)
        self.scans = 0
        self.drift = 0.0
        self.frozen = None
        self.known = 0.3
        self.get_logger().info("Using solver plugin solver_plugins::CeresSolver")
        self.get_logger().info("CeresSolver: Using SCHUR_JACOBI preconditioner.")
        self.create_timer(0.05, self._tf)
        self.create_timer(5.0, self._map)

    def _scan(self, msg: LaserScan) -> None:
        if self.scans == 0:
            self.get_logger().info("Registering sensor: [Custom Described Lidar]")
        self.scans += 1
        self.drift = 0.02 * math.sin(self.scans / 300.0)  # the scan matcher's correction wanders

    def _tf(self) -> None:
        stamp = stamp_of(self)
        if self.fault() == "stale":  # the transform thread stops taking new scan stamps
            self.frozen = self.frozen or stamp
            stamp = self.frozen
        else:
            self.frozen = None
        stamp = to_time(secs(stamp) + 0.2)  # transform_timeout: future-dated as slam_toolbox does
        self.tf_pub.publish(transform(stamp, "map", "odom", self.drift, -self.drift, 0.0, self.drift / 4))

    def _map(self) -> None:
        if not self.scans:
            return
        self.known = min(1.0, self.known + 0.05)
        cells = signed(room_grid(180, 0.05, -3.5, -3.5, self.known))
        g = grid(stamp_of(self), "map", 180, 0.05, -3.5, -3.5, cells)
        self.map_pub.publish(g)
        self.meta_pub.publish(g.info)


class TwistMux(Node):
    """twist_mux: /cmd_vel_teleop (priority 100) over /cmd_vel_nav (10) into /cmd_vel; its diagnostics."""

    INPUTS: ClassVar[dict[str, tuple[str, int]]] = {"teleop": ("/cmd_vel_teleop", 100),
                                                    "navigation": ("/cmd_vel_nav", 10)}

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("twist_mux", parameter_overrides=SIM_TIME)
        self.fault = Faults(fault_dir, "twist_mux")
        for name, (topic, prio) in self.INPUTS.items():
            self.declare_parameter(f"topics.{name}.topic", topic)
            self.declare_parameter(f"topics.{name}.priority", prio)
            self.declare_parameter(f"topics.{name}.timeout", 0.5)
        self.pub = self.create_publisher(Twist, "/cmd_vel", 10)
        self.diag_pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.last = dict.fromkeys(self.INPUTS, -1e9)
        self.subs = {name: self._subscribe(name, QoSProfile(depth=10)) for name in self.INPUTS}
        self.reconfigured = False
        self.create_timer(1.0, self._diagnostics)
        self.create_timer(0.5, self._check, clock=STEADY)

    def _subscribe(self, name: str, qos: QoSProfile):
        topic = self.INPUTS[name][0]
        self.get_logger().info(f"Topic handler '{name}' subscribed to topic '{topic}': timeout = 0.5s, "
                               f"priority = {self.INPUTS[name][1]}")
        return self.create_subscription(Twist, topic, lambda m, n=name: self._input(n, m), qos)

    def _check(self) -> None:
        if self.fault() == "qos" and not self.reconfigured:  # a config reload asks for latched commands
            self.reconfigured = True
            self.destroy_subscription(self.subs["navigation"])
            self.subs["navigation"] = self._subscribe(
                "navigation", QoSProfile(depth=10, durability=DurabilityPolicy.TRANSIENT_LOCAL))

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _input(self, name: str, msg: Twist) -> None:
        now = self._now()
        self.last[name] = now
        prio = self.INPUTS[name][1]
        if any(now - self.last[o] < 0.5 and self.INPUTS[o][1] > prio for o in self.INPUTS if o != name):
            return
        self.pub.publish(msg)

    def _diagnostics(self) -> None:
        now = self._now()
        active = [n for n in self.INPUTS if now - self.last[n] < 0.5]
        prio = max((self.INPUTS[n][1] for n in active), default=0)
        st = DiagnosticStatus(level=DiagnosticStatus.OK, name="twist_mux: Twist mux status",
                              message="ok", hardware_id="none",
                              values=[KeyValue(key="current priority",
                                               value=str(prio)),
                                      *[KeyValue(key=f"topic {n}", value="active" if n in active else "idle")
                                        for n in self.INPUTS]])
        arr = DiagnosticArray(status=[st])
        arr.header.stamp = stamp_of(self)
        self.diag_pub.publish(arr)


class Teleop(Node):
    """teleop_twist_keyboard: bursts of key presses (5-20 commands at 10 Hz) every 10-60 s."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("teleop_twist_keyboard", parameter_overrides=SIM_TIME)
        self.declare_parameter("speed", 0.3)
        self.declare_parameter("turn", 0.8)
        self.pub = self.create_publisher(Twist, "/cmd_vel_teleop", 10)
        self.left = 0
        self.key = Twist()
        self.next_at = None
        self.create_timer(0.1, self._tick)

    def _tick(self) -> None:
        now = self.get_clock().now().nanoseconds * 1e-9
        if self.next_at is None:
            self.next_at = now + random.uniform(5.0, 20.0)
        if self.left == 0 and now >= self.next_at:
            self.left = random.randint(5, 20)
            self.key = Twist()
            k = random.choice("ijlu,")
            self.key.linear.x = {"i": 0.3, ",": -0.3, "u": 0.3}.get(k, 0.0)
            self.key.angular.z = {"j": 0.8, "l": -0.8, "u": 0.8}.get(k, 0.0)
        if self.left:
            self.pub.publish(self.key)
            self.left -= 1
            if self.left == 0:
                self.next_at = now + random.uniform(10.0, 60.0)


# --- tools ---------------------------------------------------------------------------------------------

def adapted_qos(node: Node, topic: str) -> QoSProfile | None:
    """The QoS rosbag2 / foxglove_bridge subscribe with: what every publisher offers (None: no publisher)."""
    infos = node.get_publishers_info_by_topic(topic)
    if not infos:
        return None
    be = any(i.qos_profile.reliability == ReliabilityPolicy.BEST_EFFORT for i in infos)
    tl = all(i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos)
    return QoSProfile(depth=100 if tl else 10,
                      reliability=ReliabilityPolicy.BEST_EFFORT if be else ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if tl else DurabilityPolicy.VOLATILE)


class Recorder(Node):
    """rosbag2 recorder (``ros2 bag record -a``): a subscription for every topic it discovers."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("rosbag2_recorder")  # no --use-sim-time: /clock is recorded as a topic
        self.subs: dict[str, object] = {}
        self.bytes = self.messages = 0
        bag = f"rosbag2_{time.strftime('%Y_%m_%d-%H_%M_%S')}"
        self.get_logger().info(f"Press SPACE for pausing/resuming; writing to {bag}")
        self.get_logger().info("Listening for topics...")
        self.create_timer(1.0, self._discover, clock=STEADY)
        self.get_logger().info("Recording...")

    def _discover(self) -> None:
        for topic, types in self.get_topic_names_and_types():
            if topic in self.subs or len(types) != 1:
                continue
            qos = adapted_qos(self, topic)
            if qos is None:
                continue
            typ = self._type(types[0])
            self.subs[topic] = self.create_subscription(typ, topic, self._write, qos, raw=True)
            self.get_logger().info(f"Subscribed to topic '{topic}'")

    @staticmethod
    def _type(name: str):
        pkg, _, cls = name.split("/")
        return getattr(__import__(f"{pkg}.msg", fromlist=[cls]), cls)

    def _write(self, data: bytes) -> None:
        self.messages += 1
        self.bytes += len(data)

    def close(self) -> None:
        line = f"Recording stopped: {self.messages} messages, {self.bytes / 1e6:.1f} MB"
        if rclpy.ok():
            self.get_logger().info(line)
        else:  # Ctrl-C: the context is already shut down
            print(line, flush=True)


class FoxgloveBridge(Node):
    """foxglove_bridge: a client connected 40 s, then 80 s not; its six channels subscribed meanwhile."""

    TOPICS: ClassVar[dict[str, type]] = {"/tf": TransformStamped, "/tf_static": TransformStamped,
                                         "/scan": LaserScan, "/odom": Odometry,
              "/map": OccupancyGrid, "/camera/image_raw": Image}

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("foxglove_bridge", parameter_overrides=SIM_TIME)
        self.declare_parameter("port", 8765)
        self.declare_parameter("address", "0.0.0.0")
        self.get_logger().info("Starting foxglove_bridge (ros2, 0.8.3) with WebSocket++/0.8.2")
        self.get_logger().info("Server listening on port 8765")
        self.subs: dict[str, object] = {}
        self.t0 = time.monotonic()
        self.connected = False
        self.forwarded = 0
        self.create_timer(1.0, self._client, clock=STEADY)

    def _client(self) -> None:
        phase = (time.monotonic() - self.t0 - 10.0) % 120.0
        want = time.monotonic() - self.t0 >= 10.0 and phase < 40.0
        if want and not self.connected:
            self.connected = True
            port = random.randint(40000, 60000)
            self.get_logger().info(f"Client 127.0.0.1:{port} connected via Foxglove WebSocket")
            for ch, (topic, typ) in enumerate(self.TOPICS.items(), 1):
                qos = adapted_qos(self, topic) or QoSProfile(depth=10)
                self.subs[topic] = self.create_subscription(typ, topic, self._forward, qos, raw=True)
                self.get_logger().info(f"Subscribing to topic \"{topic}\" on channel {ch}")
        elif not want and self.connected:
            self.connected = False
            for topic, sub in self.subs.items():
                self.destroy_subscription(sub)
                self.get_logger().info(f"Unsubscribing from topic \"{topic}\"")
            self.subs = {}
            self.get_logger().info("Client disconnected")

    def _forward(self, data: bytes) -> None:
        self.forwarded += 1


class Rviz(Node):
    """rviz2 with the nav2 config: the map, the scan, tf, the robot model, the plan and costmaps;
    the user sends one 2D goal pose a while after opening it."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("rviz2", parameter_overrides=SIM_TIME)
        self.get_logger().info("Stereo is NOT SUPPORTED")
        self.get_logger().info("OpenGl version: 4.5 (GLSL 4.5)")
        self.create_subscription(OccupancyGrid, "/map", self._draw, LATCHED)
        self.create_subscription(LaserScan, "/scan", self._draw, qos_profile_sensor_data)
        self.create_subscription(TransformStamped, "/tf", self._draw, 100)
        self.create_subscription(TransformStamped, "/tf_static", self._draw, TF_STATIC)
        self.create_subscription(String, "/robot_description", self._draw, LATCHED)
        self.create_subscription(NavPath, "/sim/plan", self._draw, 10)
        self.create_subscription(OccupancyGrid, "/sim/local_costmap/costmap", self._draw, 10)
        self.create_subscription(OccupancyGrid, "/sim/global_costmap/costmap", self._draw, 10)
        self.goal_pub = self.create_publisher(PoseStamped, "/goal_pose", 10)
        self.opened = time.monotonic()
        self.sent = False
        self.create_timer(1.0, self._user, clock=STEADY)

    def _draw(self, msg) -> None:
        pass

    def _user(self) -> None:
        if not self.sent and time.monotonic() - self.opened > 15.0:
            self.sent = True
            goal = PoseStamped()
            goal.header.stamp, goal.header.frame_id = stamp_of(self), "map"
            goal.pose.position.x, goal.pose.position.y = random.uniform(0.0, 3.0), random.uniform(0.0, 3.0)
            goal.pose.orientation.w = 1.0
            self.get_logger().info(f"Setting goal pose: Frame:map, Position({goal.pose.position.x:.3f}, "
                                   f"{goal.pose.position.y:.3f}, 0)")
            self.goal_pub.publish(goal)


class SystemMonitor(Node):
    """The host's diagnostics (diagnostic_updater style): CPU, memory, and the GPU (software rendering)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("system_monitor", parameter_overrides=SIM_TIME)
        import psutil
        self.psutil = psutil
        self.host = socket.gethostname()
        self.pub = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        psutil.cpu_percent()
        self.create_timer(1.0, self._update)

    def _update(self) -> None:
        cpu, mem = self.psutil.cpu_percent(), self.psutil.virtual_memory()
        sts = [
            DiagnosticStatus(level=DiagnosticStatus.OK if cpu < 95 else DiagnosticStatus.WARN,
                             name="system_monitor: CPU usage", message="OK" if cpu < 95 else "High CPU load",
                             hardware_id=self.host, values=[KeyValue(key="usage", value=f"{cpu:.1f}%")]),
            DiagnosticStatus(level=DiagnosticStatus.OK, name="system_monitor: Memory usage", message="OK",
                             hardware_id=self.host,
                             values=[KeyValue(key="used", value=f"{mem.percent:.1f}%")]),
            DiagnosticStatus(level=DiagnosticStatus.WARN, name="system_monitor: GPU",
                             message="software rendering (llvmpipe), no GPU acceleration",
                             hardware_id=self.host,
                             values=[KeyValue(key="renderer", value="llvmpipe (LLVM 15.0.7, 256 bits)")]),
        ]
        arr = DiagnosticArray(status=sts)
        arr.header.stamp = stamp_of(self)
        self.pub.publish(arr)


class DiagnosticAggregator(Node):
    """diagnostic_aggregator: /diagnostics grouped by analyzer into /diagnostics_agg at 1 Hz (sim)."""

    GROUPS: ClassVar[dict[str, str]] = {"system_monitor": "/Computers", "twist_mux": "/Navigation"}

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("diagnostic_aggregator", parameter_overrides=SIM_TIME)
        self.declare_parameter("pub_rate", 1.0)
        self.latest: dict[str, tuple[DiagnosticStatus, float]] = {}
        self.create_subscription(DiagnosticArray, "/diagnostics", self._diag, 50)
        self.agg_pub = self.create_publisher(DiagnosticArray, "/diagnostics_agg", 10)
        self.top_pub = self.create_publisher(DiagnosticStatus, "/diagnostics_toplevel_state", 10)
        self.create_timer(1.0, self._publish)

    def _now(self) -> float:
        return self.get_clock().now().nanoseconds * 1e-9

    def _diag(self, msg: DiagnosticArray) -> None:
        for st in msg.status:
            self.latest[st.name] = (st, self._now())

    def _publish(self) -> None:
        now, out, groups = self._now(), [], {}
        for name, (st, t) in sorted(self.latest.items()):
            group = self.GROUPS.get(name.split(":")[0], "/Other")
            level = DiagnosticStatus.STALE if now - t > 5.0 else st.level
            msg = "Stale" if level == DiagnosticStatus.STALE else st.message
            out.append(DiagnosticStatus(level=level, name=f"{group}/{name}", message=msg,
                                        hardware_id=st.hardware_id, values=st.values))
            groups[group] = max(groups.get(group, 0), level[0] if isinstance(level, bytes) else level)
        for group, level in groups.items():
            out.insert(0, DiagnosticStatus(level=bytes([level]), name=group,
                                           message={0: "OK", 1: "Warning", 2: "Error", 3: "Stale"}[level]))
        arr = DiagnosticArray(status=out)
        arr.header.stamp = stamp_of(self)
        self.agg_pub.publish(arr)
        top = max(groups.values(), default=0)
        self.top_pub.publish(DiagnosticStatus(level=bytes([top]), name="toplevel_state",
                                              message={0: "OK", 1: "Warning", 2: "Error", 3: "Stale"}[top]))


def param_set(fault_dir: Path) -> int:
    """``ros2 param set /sim/controller_server FollowPath.desired_linear_vel V``: set, print, exit."""
    node = Node(f"_ros2cli_{os.getpid()}")
    client = node.create_client(SetParameters, "/sim/controller_server/set_parameters")
    if not client.wait_for_service(timeout_sec=5.0):
        print("Node not found", flush=True)
        node.destroy_node()
        return 0
    value = random.choice((0.35, 0.45, 0.5))
    req = SetParameters.Request(parameters=[ParameterMsg(
        name="FollowPath.desired_linear_vel",
        value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=value))])
    future = client.call_async(req)
    rclpy.spin_until_future_complete(node, future, timeout_sec=5.0)
    res = future.result()
    ok = res is not None and res.results[0].successful
    print("Set parameter successful" if ok else "Setting parameter failed", flush=True)
    node.destroy_node()
    return 0


NAV = {"controller_server": ControllerServer, "smoother_server": None, "planner_server": PlannerServer,
       "behavior_server": None, "bt_navigator": BtNavigator, "waypoint_follower": WaypointFollower}


def navigation(fault_dir: Path) -> list[Node]:
    nodes: list[Node] = []
    for name, cls in NAV.items():
        nodes.append(cls(fault_dir) if cls else NavServer(name, fault_dir))
    nodes.append(LifecycleManager())
    for n in nodes:
        n.get_logger().info(f"Load Library: lib{n.get_name()}_core.so") if n.get_name() in NAV else None
    return nodes


PROCESSES = {
    "gz_sim": lambda d: [GzSim(d)],
    "bridge": lambda d: [GzBridge(d)],
    "state_publisher": lambda d: [RobotStatePublisher(d)],
    "navigation": navigation,
    "slam": lambda d: [SlamToolbox(d)],
    "mux": lambda d: [TwistMux(d)],
    "teleop": lambda d: [Teleop(d)],
    "recorder": lambda d: [Recorder(d)],
    "foxglove": lambda d: [FoxgloveBridge(d)],
    "system_monitor": lambda d: [SystemMonitor(d)],
    "diagnostics": lambda d: [DiagnosticAggregator(d)],
    "rviz": lambda d: [Rviz(d)],
}


def main(argv: list[str]) -> int:
    process, fault_dir = argv[0], Path(argv[1])
    run_for = float(argv[2]) if len(argv) > 2 else 0.0
    rclpy.init()
    try:
        if process == "param_set":
            return param_set(fault_dir)
        process_faults(fault_dir, process)
        nodes = PROCESSES[process](fault_dir)
        ex = SingleThreadedExecutor()
        for n in nodes:
            ex.add_node(n)
        deadline = time.monotonic() + run_for if run_for > 0 else None
        try:
            while rclpy.ok() and (deadline is None or time.monotonic() < deadline):
                ex.spin_once(timeout_sec=0.5)
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        for n in nodes:
            if hasattr(n, "close"):
                n.close()
        ex.shutdown()
        for n in nodes:
            n.destroy_node()
        return 0
    finally:
        if rclpy.ok():
            rclpy.shutdown()


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
