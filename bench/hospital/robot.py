"""Hospital delivery robot ``hd_01`` (medicine and samples between wards), one OS process at a time.

``python -m bench.hospital.robot PROCESS FAULT_DIR [RUN_FOR]``

Runs the nodes of one process of the robot on their executor until SIGINT/SIGTERM or, with
RUN_FOR > 0, for RUN_FOR seconds; exits 0 either way. The whole robot, its topics, services, QoS,
healthy dynamics and faults are described in `bench.hospital.run`.

Faults are read from files (a watcher thread per process, every 0.5 s):
``FAULT_DIR/<namespace>.<node>`` holds a word the node acts on (``hang``, ``degrade``, ``stale``,
``reliable``, ``deactivate``, ``crashloop``, ...), ``FAULT_DIR/<process>.cpu`` starts a thread
spinning a core, ``FAULT_DIR/<process>.leak`` a thread leaking ~3 MB/s.

Substitutes for packages not installed here (no tf2_msgs, nav2_msgs, rmf_*, diagnostic_updater):
``/tf`` and ``/tf_static`` carry geometry_msgs/TransformStamped (one transform a message); every
Nav2 action (navigate_to_pose, follow_path, backup) is test_msgs/action/Fibonacci; the planner's
``compute_path_to_pose`` is the nav_msgs/srv/GetPlan service; the building's door/elevator
services, the drawer service and the fleet's incident report are test_msgs/srv/BasicTypes; orders,
robot and mission states, keypad events, building states are std_msgs/String (JSON); the particle
cloud is a geometry_msgs/PoseArray; the safety heartbeat a std_msgs/Header.
"""

from __future__ import annotations

import array
import json
import math
import os
import queue
import random
import signal
import sys
import threading
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

import rclpy
from builtin_interfaces.msg import Time as TimeMsg
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
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
from nav_msgs.msg import MapMetaData, OccupancyGrid, Odometry
from nav_msgs.msg import Path as PathMsg
from nav_msgs.srv import GetMap, GetPlan
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue, SetParametersResult
from rcl_interfaces.srv import SetParameters
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import Executor, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.node import Node
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_system_default,
)
from rclpy.service_introspection import ServiceIntrospectionState
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import (
    BatteryState,
    CameraInfo,
    CompressedImage,
    Image,
    Imu,
    JointState,
    LaserScan,
    PointCloud2,
    PointField,
)
from std_msgs.msg import Bool, Header, String
from test_msgs.action import Fibonacci
from test_msgs.srv import BasicTypes

NS = "/hd"
ROBOT_ID = "hd_01"

# QoS profiles as the team's launch files set them
SENSOR = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT, history=HistoryPolicy.KEEP_LAST)
RELIABLE = QoSProfile(depth=10)
COMMAND = QoSProfile(depth=1)
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
TF_STATIC = QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL)
TF = QoSProfile(depth=100)

# The map of floor 3 (floors 4 and 5 share its layout): named places (x, y) in metres, the index is
# the navigate_to_pose goal's ``order``.
PLACES: list[tuple[str, float, float]] = [
    ("meds_room", 2.0, 2.0),
    ("elevator_lobby", 6.0, 6.5),
    ("ward_a", 10.0, 2.0),
    ("ward_b", 10.0, 9.5),
    ("lab", 2.0, 9.5),
    ("dock", 4.0, 1.0),
]
PLACE_INDEX = {name: i for i, (name, _, _) in enumerate(PLACES)}
DROPOFFS = ("ward_a", "ward_b", "lab")
FLOORS = (3, 4, 5)

NAV_CODES = {
    0: "succeeded",
    1: "planner did not answer",
    2: "failed to make progress",
    3: "localization lost",
    4: "no valid plan",
    5: "canceled",
    6: "controller unavailable",
}


# ----------------------------------------------------------------------------------------------
# helpers


def stamp_now(node: Node) -> TimeMsg:
    return node.get_clock().now().to_msg()


def stamp_at(t: float) -> TimeMsg:
    sec = int(t)
    return TimeMsg(sec=sec, nanosec=int((t - sec) * 1e9))


def stamp_s(stamp: TimeMsg) -> float:
    return stamp.sec + stamp.nanosec * 1e-9


def yaw_quat(yaw: float) -> Quaternion:
    return Quaternion(z=math.sin(yaw / 2.0), w=math.cos(yaw / 2.0))


def quat_yaw(q: Quaternion) -> float:
    return 2.0 * math.atan2(q.z, q.w)


def wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


def wait_future(fut: Any, timeout: float, closing: threading.Event | None = None) -> bool:
    """Wait (from a thread that is not the executor's) until ``fut`` is done; False on timeout."""
    end = time.monotonic() + timeout
    while not fut.done():
        if time.monotonic() > end or (closing is not None and closing.is_set()):
            return False
        time.sleep(0.01)
    return True


def diag(
    node: Node, task: str, level: int, message: str, hardware_id: str = "", **values: Any
) -> DiagnosticStatus:
    """A diagnostic_updater-style status: ``name`` is ``<node name>: <task>``."""
    return DiagnosticStatus(
        level=bytes([level]),
        name=f"{node.get_name()}: {task}",
        message=message,
        hardware_id=hardware_id,
        values=[KeyValue(key=k, value=str(v)) for k, v in values.items()],
    )


class RateMeter:
    """Events per second over a sliding window (diagnostic_updater's FrequencyStatus)."""

    def __init__(self, window: float = 5.0) -> None:
        self.window = window
        self.times: deque[float] = deque()

    def tick(self) -> None:
        self.times.append(time.monotonic())

    def rate(self) -> float:
        now = time.monotonic()
        while self.times and self.times[0] < now - self.window:
            self.times.popleft()
        return len(self.times) / self.window


def hang_forever() -> None:
    """A blocking read without a timeout: the calling callback never returns."""
    threading.Event().wait()


class DiagPublisher:
    """A node's /diagnostics publisher (several nodes publish on /diagnostics)."""

    def __init__(self, node: Node) -> None:
        self.node = node
        self.pub = node.create_publisher(DiagnosticArray, "/diagnostics", RELIABLE)

    def publish(self, *statuses: DiagnosticStatus) -> None:
        self.pub.publish(DiagnosticArray(header=Header(stamp=stamp_now(self.node)), status=list(statuses)))


# ----------------------------------------------------------------------------------------------
# sensor_container: one SingleThreadedExecutor for the three drivers (a blocking callback in one
# starves the others)


class FrontLidar(Node):
    """2D lidar driver: ``/hd/scan`` 15 Hz best effort, stamped at the scan's first beam."""

    BEAMS = 360

    def __init__(self) -> None:
        super().__init__("front_lidar", namespace=NS)
        self.fault = ""
        self.declare_parameter("frame_id", "laser_link")
        self.declare_parameter("scan_frequency", 15.0)
        self.pub = self.create_publisher(LaserScan, "scan", SENSOR)
        self.diag = DiagPublisher(self)
        self.meter = RateMeter()
        base = [2.5 + 1.5 * abs(math.sin(i * math.pi / 90.0)) for i in range(self.BEAMS)]
        self.frames = [array.array("f", [r + random.uniform(-0.02, 0.02) for r in base]) for _ in range(6)]
        person = list(base)
        for i in range(165, 196):
            person[i] = 0.3 + random.uniform(0.0, 0.03)
        self.person = array.array("f", person)
        self.msg = LaserScan()
        self.msg.header.frame_id = "laser_link"
        self.msg.angle_min, self.msg.angle_max = -math.pi, math.pi
        self.msg.angle_increment = 2 * math.pi / self.BEAMS
        self.msg.time_increment = (1.0 / 15.0) / self.BEAMS
        self.msg.scan_time = 1.0 / 15.0
        self.msg.range_min, self.msg.range_max = 0.05, 25.0
        self.n = 0
        self.next_drop = time.monotonic() + random.uniform(60, 150)
        self.next_person = time.monotonic() + random.uniform(60, 150)
        self.person_until = 0.0
        self.create_timer(1.0 / 15.0, self._scan)
        self.create_timer(1.0, self._diagnostics)
        self.get_logger().info(
            "Connected to lidar at 192.168.1.201:2368, 360 beams at 15.0 Hz, frame 'laser_link'"
        )

    def _scan(self) -> None:
        now = time.monotonic()
        if self.fault == "degrade" and random.random() < 0.6:
            return  # UDP frames lost in the overflowing socket buffer
        if now > self.next_drop:
            self.next_drop = now + random.uniform(60, 150)
            self.get_logger().warn("Received incomplete scan packet (1184 of 1206 bytes), frame skipped")
            return
        if now > self.next_person:
            self.next_person = now + random.uniform(60, 150)
            self.person_until = now + random.uniform(0.7, 1.5)
        self.n += 1
        acquired = time.time() - 0.02
        if self.fault == "stale":
            acquired -= 2.0  # free-running clock after losing its time sync
        self.msg.header.stamp = stamp_at(acquired)
        self.msg.ranges = self.person if now < self.person_until else self.frames[self.n % len(self.frames)]
        self.pub.publish(self.msg)
        self.meter.tick()

    def _diagnostics(self) -> None:
        hz = self.meter.rate()
        ok = 13.5 <= hz <= 16.5
        self.diag.publish(
            diag(
                self,
                "/hd/scan topic status",
                0 if ok else 1,
                "Desired frequency met" if ok else "Frequency too low.",
                "lidar-192.168.1.201",
                **{"Actual frequency (Hz)": f"{hz:.2f}", "Target frequency (Hz)": "15.0"},
            )
        )


class DepthCamera(Node):
    """Depth camera driver: depth image 160x120 6 Hz, camera info, points 3 Hz; the color stream's
    compressed topic only while someone subscribes (lazy)."""

    W, H = 160, 120

    def __init__(self) -> None:
        super().__init__("depth_camera", namespace=NS)
        self.fault = ""
        self.declare_parameter("serial_no", "213622070519")
        self.depth_pub = self.create_publisher(Image, "~/depth/image_rect_raw", SENSOR)
        self.info_pub = self.create_publisher(CameraInfo, "~/depth/camera_info", SENSOR)
        self.points_pub = self.create_publisher(PointCloud2, "~/depth/points", SENSOR)
        self.color_pub = self.create_publisher(CompressedImage, "~/color/image_raw/compressed", SENSOR)
        self.diag = DiagPublisher(self)
        self.meter = RateMeter()
        self.opened_at = time.monotonic() + 1.5
        self.open_logged = False
        self.get_logger().error(
            "Failed to open /dev/video4: Device or resource busy (uvc); retrying in 1.5 s"
        )
        self.depth = Image(height=self.H, width=self.W, encoding="16UC1", step=self.W * 2)
        self.depth.header.frame_id = "camera_depth_optical_frame"
        self.depth.data = bytes(random.getrandbits(8) for _ in range(self.W * self.H * 2))
        self.info = CameraInfo(height=self.H, width=self.W, distortion_model="plumb_bob")
        self.info.header.frame_id = "camera_depth_optical_frame"
        self.info.k = [140.0, 0.0, 80.0, 0.0, 140.0, 60.0, 0.0, 0.0, 1.0]
        self.info.d = [0.0] * 5
        self.cloud = PointCloud2(
            height=30, width=40, is_bigendian=False, point_step=16, row_step=640, is_dense=True
        )
        self.cloud.header.frame_id = "camera_depth_optical_frame"
        self.cloud.fields = [
            PointField(name=n, offset=o, datatype=PointField.FLOAT32, count=1)
            for n, o in (("x", 0), ("y", 4), ("z", 8), ("intensity", 12))
        ]
        self.cloud.data = bytes(random.getrandbits(8) for _ in range(40 * 30 * 16))
        self.jpeg = CompressedImage(format="rgb8; jpeg compressed bgr8")
        self.jpeg.header.frame_id = "camera_color_optical_frame"
        self.jpeg.data = bytes(random.getrandbits(8) for _ in range(5200))
        self.streaming = False
        self.create_timer(1.0 / 6.0, self._depth)
        self.create_timer(1.0 / 3.0, self._points)
        self.create_timer(1.0 / 5.0, self._color)
        self.create_timer(1.0, self._diagnostics)

    def _ready(self) -> bool:
        if time.monotonic() < self.opened_at:
            return False
        if not self.open_logged:
            self.open_logged = True
            self.get_logger().info(
                "Device 213622070519 opened (USB 3.2): depth 160x120 @ 6 fps, color 160x120 @ 5 fps"
            )
        return True

    def _depth(self) -> None:
        if not self._ready():
            return
        if self.fault == "hang":
            hang_forever()  # the UVC read blocks without a timeout after a USB reset
        stamp = stamp_at(time.time() - 0.035)  # exposure time
        self.depth.header.stamp = stamp
        self.info.header.stamp = stamp
        self.depth_pub.publish(self.depth)
        self.info_pub.publish(self.info)
        self.meter.tick()

    def _points(self) -> None:
        if not self._ready():
            return
        self.cloud.header.stamp = stamp_at(time.time() - 0.05)
        self.points_pub.publish(self.cloud)

    def _color(self) -> None:
        if not self._ready():
            return
        subscribed = self.color_pub.get_subscription_count() > 0
        if subscribed != self.streaming:
            self.streaming = subscribed
            self.get_logger().info(
                "Color stream %s"
                % ("started: a subscriber connected" if subscribed else "stopped: no subscribers")
            )
        if subscribed:
            self.jpeg.header.stamp = stamp_now(self)
            self.color_pub.publish(self.jpeg)

    def _diagnostics(self) -> None:
        hz = self.meter.rate()
        ok = hz >= 5.0
        self.diag.publish(
            diag(
                self,
                "depth/image_rect_raw topic status",
                0 if ok else 1,
                "Desired frequency met" if ok else "Frequency too low.",
                "realsense-213622070519",
                **{"Actual frequency (Hz)": f"{hz:.2f}"},
            )
        )


class ImuDriver(Node):
    """IMU driver: ``/hd/imu/data`` at 100 Hz (best effort)."""

    def __init__(self) -> None:
        super().__init__("imu", namespace=NS)
        self.fault = ""
        self.pub = self.create_publisher(Imu, "~/data", SENSOR)
        self.diag = DiagPublisher(self)
        self.meter = RateMeter(2.0)
        self.msg = Imu()
        self.msg.header.frame_id = "imu_link"
        self.msg.orientation_covariance = [0.01, 0.0, 0.0, 0.0, 0.01, 0.0, 0.0, 0.0, 0.01]
        self.msg.linear_acceleration.z = 9.81
        self.create_timer(0.01, self._sample)
        self.create_timer(1.0, self._diagnostics)
        self.get_logger().info("IMU on /dev/ttyUSB1 at 921600 baud, 100 Hz output")

    def _sample(self) -> None:
        if self.fault == "degrade" and random.random() < 0.6:
            return  # serial frames dropped (checksum errors on a loose connector)
        self.msg.header.stamp = stamp_now(self)
        self.msg.angular_velocity.z = random.gauss(0.0, 0.002)
        self.pub.publish(self.msg)
        self.meter.tick()

    def _diagnostics(self) -> None:
        hz = self.meter.rate()
        ok = hz >= 70.0
        self.diag.publish(
            diag(
                self,
                "/hd/imu/data topic status",
                0 if ok else 1,
                "Desired frequency met" if ok else "Frequency too low.",
                "xsens-mti-3",
                **{"Actual frequency (Hz)": f"{hz:.1f}"},
            )
        )


# ----------------------------------------------------------------------------------------------
# nav_container: Nav2-style lifecycle nodes on one MultiThreadedExecutor


class ManagedNode(LifecycleNode):
    """A lifecycle node whose own callbacks share one mutually exclusive group (its default)."""

    def __init__(self, name: str) -> None:
        super().__init__(name, namespace=NS)
        self.fault = ""
        self.active = False
        self.reentrant = ReentrantCallbackGroup()

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = True
        self.get_logger().info("Activating")
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.active = False
        self.get_logger().info("Deactivating")
        return super().on_deactivate(state)


class MapServer(ManagedNode):
    """Latches ``/hd/map`` once active, serves ``~/map``; refreshes its keep-out zones every 20 s."""

    def __init__(self) -> None:
        super().__init__("map_server")
        self.declare_parameter("yaml_filename", "/opt/hd/maps/st_marys_floor3.yaml")

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.pub = self.create_lifecycle_publisher(OccupancyGrid, "/hd/map", LATCHED)
        self.grid = OccupancyGrid()
        self.grid.header.frame_id = "map"
        self.grid.info = MapMetaData(resolution=0.05, width=260, height=220)
        cells = [0] * (260 * 220)
        for i in range(260):
            cells[i] = cells[219 * 260 + i] = 100
        self.grid.data = array.array("b", cells)
        self.create_service(GetMap, "~/map", self._get_map)
        self.create_timer(20.0, self._keepout)
        self.get_logger().info("Loading yaml file: /opt/hd/maps/st_marys_floor3.yaml (260 x 220 at 0.05 m)")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        result = super().on_activate(state)
        self.grid.header.stamp = stamp_now(self)
        self.pub.publish(self.grid)
        return result

    def _get_map(self, request: GetMap.Request, response: GetMap.Response) -> GetMap.Response:
        response.map = self.grid
        return response

    def _keepout(self) -> None:
        # slow periodic work: re-reads the keep-out zones the facilities team edits
        time.sleep(random.uniform(0.2, 0.4))


class Amcl(ManagedNode):
    """Localization: scans + odometry -> ``/hd/amcl_pose`` (5 Hz moving, 1 Hz still), map->odom."""

    def __init__(self) -> None:
        super().__init__("amcl")
        self.declare_parameter("initial_pose.x", PLACES[PLACE_INDEX["dock"]][1])
        self.declare_parameter("initial_pose.y", PLACES[PLACE_INDEX["dock"]][2])
        self.declare_parameter("transform_tolerance", 0.5)
        self.odom: Odometry | None = None
        self.last_scan = time.monotonic()
        self.last_warn_noscan = 0.0
        self.last_drop_warn = 0.0
        self.last_pose = 0.0
        self.last_cloud = 0.0
        self.n = 0

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.pose_pub = self.create_lifecycle_publisher(PoseWithCovarianceStamped, "/hd/amcl_pose", LATCHED)
        self.cloud_pub = self.create_lifecycle_publisher(PoseArray, "/hd/particle_cloud", SENSOR)
        self.tf_pub = self.create_lifecycle_publisher(TransformStamped, "/tf", TF)
        self.create_subscription(LaserScan, "/hd/scan", self._scan, SENSOR)
        self.create_subscription(Odometry, "/hd/odom", self._odom, RELIABLE)
        self.create_timer(1.0, self._watchdog)
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        result = super().on_activate(state)
        self.get_logger().warn(
            "AMCL cannot publish a pose or update the transform. Please set the initial pose..."
        )
        x, y = self.get_parameter("initial_pose.x").value, self.get_parameter("initial_pose.y").value
        self.get_logger().info(f"Setting pose: {x:.3f} {y:.3f} 0.000 (initial_pose parameters)")
        self.last_scan = time.monotonic()
        return result

    def _odom(self, msg: Odometry) -> None:
        self.odom = msg

    def _scan(self, msg: LaserScan) -> None:
        if not self.active:
            return
        now = time.time()
        if now - stamp_s(msg.header.stamp) > 1.0:
            if now - self.last_drop_warn > 2.0:
                self.last_drop_warn = now
                self.get_logger().warn(
                    "Message Filter dropping message: frame 'laser_link' at time "
                    f"{stamp_s(msg.header.stamp):.3f} for reason 'the timestamp on the message is "
                    "earlier than all the data in the transform cache'"
                )
            return
        self.last_scan = time.monotonic()
        odom = self.odom
        if odom is None:
            return
        moving = abs(odom.twist.twist.linear.x) > 0.01 or abs(odom.twist.twist.angular.z) > 0.01
        if now - self.last_pose < (0.2 if moving else 1.0) - 0.01:
            return
        self.last_pose = now
        p = odom.pose.pose
        out = PoseWithCovarianceStamped()
        out.header.stamp = msg.header.stamp
        out.header.frame_id = "map"
        out.pose.pose.position.x = p.position.x + random.gauss(0.0, 0.01)
        out.pose.pose.position.y = p.position.y + random.gauss(0.0, 0.01)
        out.pose.pose.orientation = p.orientation
        out.pose.covariance[0] = out.pose.covariance[7] = 0.02
        out.pose.covariance[35] = 0.01
        self.pose_pub.publish(out)
        tf = TransformStamped()
        tf.header.stamp = stamp_at(stamp_s(msg.header.stamp) + 0.5)  # post-dated: transform_tolerance
        tf.header.frame_id, tf.child_frame_id = "map", "odom"
        tf.transform.rotation.w = 1.0
        self.tf_pub.publish(tf)
        if now - self.last_cloud >= 1.0:
            self.last_cloud = now
            cloud = PoseArray()
            cloud.header = out.header
            cloud.poses = [
                Pose(
                    position=Point(
                        x=p.position.x + random.gauss(0, 0.05), y=p.position.y + random.gauss(0, 0.05)
                    ),
                    orientation=p.orientation,
                )
                for _ in range(40)
            ]
            self.cloud_pub.publish(cloud)

    def _watchdog(self) -> None:
        if self.fault == "deactivate" and self.active:
            self.fault = "deactivated"
            self.trigger_deactivate()  # its laser-model watchdog deactivates it (a misread config)
            return
        if not self.active:
            return
        now = time.monotonic()
        if now - self.last_scan > 5.0 and now - self.last_warn_noscan > 5.0:
            self.last_warn_noscan = now
            self.get_logger().warn(
                f"No laser scan received (and thus no pose updates have been published) for "
                f"{now - self.last_scan:.1f} seconds.  Verify that data is being published on the "
                "/hd/scan topic."
            )


class PlannerServer(ManagedNode):
    """Global planner: ``/hd/compute_path_to_pose`` (GetPlan), publishes each plan on ``/hd/plan``."""

    def __init__(self) -> None:
        super().__init__("planner_server")
        self.declare_parameter("expected_planner_frequency", 1.0)
        self.declare_parameter("GridBased.tolerance", 0.5)

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.plan_pub = self.create_lifecycle_publisher(PathMsg, "/hd/plan", RELIABLE)
        self.create_service(GetPlan, "/hd/compute_path_to_pose", self._plan)
        self.create_timer(1.0, self._costmap_update)
        self.get_logger().info(
            "Created global planner plugin GridBased of type nav2_navfn_planner::NavfnPlanner"
        )
        return TransitionCallbackReturn.SUCCESS

    def _costmap_update(self) -> None:
        if self.fault == "hang":
            hang_forever()  # deadlocks on the global costmap's mutex

    def _plan(self, request: GetPlan.Request, response: GetPlan.Response) -> GetPlan.Response:
        if not self.active:
            self.get_logger().warn("Planner server inactive, rejecting request")
            return response
        time.sleep(random.uniform(0.02, 0.08))  # NavFn's Dijkstra
        sx, sy = request.start.pose.position.x, request.start.pose.position.y
        gx, gy = request.goal.pose.position.x, request.goal.pose.position.y
        d = math.hypot(gx - sx, gy - sy)
        n = max(2, int(d / 0.2) + 1)
        path = PathMsg()
        path.header.stamp = stamp_now(self)
        path.header.frame_id = "map"
        yaw = math.atan2(gy - sy, gx - sx)
        for i in range(n):
            f = i / (n - 1)
            ps = PoseStamped()
            ps.header = path.header
            ps.pose.position.x, ps.pose.position.y = sx + f * (gx - sx), sy + f * (gy - sy)
            ps.pose.orientation = yaw_quat(yaw)
            path.poses.append(ps)
        self.plan_pub.publish(path)
        response.plan = path
        return response


class ControllerServer(ManagedNode):
    """Local controller: ``/hd/follow_path`` (action), pure pursuit at 20 Hz on ``/hd/cmd_vel_nav``."""

    def __init__(self) -> None:
        super().__init__("controller_server")
        self.declare_parameter("controller_frequency", 20.0)
        self.declare_parameter("FollowPath.max_vel_x", 0.8)
        self.declare_parameter("progress_checker.required_movement_radius", 0.2)
        self.declare_parameter("progress_checker.movement_time_allowance", 8.0)
        self.plan: PathMsg | None = None
        self.odom: Odometry | None = None
        self.pose_t = 0.0
        self.following = False
        self.outcome: int | None = None
        self.remaining = 0.0
        self.idx = 0
        self.progress_ref = (0.0, 0.0, 0.0)
        self.last_cloud_warn = 0.0
        self.lock = threading.Lock()

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.cmd_pub = self.create_lifecycle_publisher(Twist, "/hd/cmd_vel_nav", COMMAND)
        self.create_subscription(PathMsg, "/hd/plan", self._on_plan, RELIABLE)
        self.create_subscription(Odometry, "/hd/odom", self._on_odom, RELIABLE)
        self.create_subscription(PoseWithCovarianceStamped, "/hd/amcl_pose", self._on_pose, LATCHED)
        self.create_subscription(PointCloud2, "/hd/depth_camera/depth/points", self._on_cloud, SENSOR)
        self.control_timer = self.create_timer(0.05, self._control)
        self.control_timer.cancel()  # runs only while following a path
        self.server = ActionServer(
            self,
            Fibonacci,
            "/hd/follow_path",
            execute_callback=self._execute,
            goal_callback=self._goal,
            cancel_callback=lambda _: CancelResponse.ACCEPT,
            callback_group=self.reentrant,
        )
        self.get_logger().info("Created controller : FollowPath of type dwb_core::DWBLocalPlanner")
        return TransitionCallbackReturn.SUCCESS

    def _on_plan(self, msg: PathMsg) -> None:
        with self.lock:
            self.plan = msg
            self.idx = 0

    def _on_odom(self, msg: Odometry) -> None:
        self.odom = msg

    def _on_pose(self, msg: PoseWithCovarianceStamped) -> None:
        self.pose_t = time.monotonic()

    def _on_cloud(self, msg: PointCloud2) -> None:
        if time.time() - stamp_s(msg.header.stamp) > 1.0 and time.time() - self.last_cloud_warn > 5.0:
            self.last_cloud_warn = time.time()
            self.get_logger().warn("local_costmap: point cloud older than 1.0 s dropped (depth_camera)")

    def _goal(self, goal: Fibonacci.Goal) -> GoalResponse:
        return GoalResponse.ACCEPT if self.active else GoalResponse.REJECT

    def _finish(self, code: int) -> None:
        self.following = False
        self.control_timer.cancel()
        self.outcome = code
        self.cmd_pub.publish(Twist())

    def _control(self) -> None:
        if not self.following or not self.active:
            return
        odom, plan = self.odom, self.plan
        if odom is None or plan is None or not plan.poses:
            return
        now = time.monotonic()
        if now - self.pose_t > 1.5:
            self.get_logger().error(
                f"Robot pose is {now - self.pose_t:.1f} s old (amcl): localization lost, aborting"
            )
            self._finish(3)
            return
        p = odom.pose.pose
        x, y, yaw = p.position.x, p.position.y, quat_yaw(p.orientation)
        goal = plan.poses[-1].pose.position
        dist = math.hypot(goal.x - x, goal.y - y)
        self.remaining = dist
        if dist < 0.15:
            self.get_logger().info("Reached the goal!")
            self._finish(0)
            return
        rx, ry, rt = self.progress_ref
        if math.hypot(x - rx, y - ry) > 0.2:
            self.progress_ref = (x, y, now)
        elif now - rt > 8.0:
            self.get_logger().error("Failed to make progress")
            self._finish(2)
            return
        with self.lock:
            poses = plan.poses
            while (
                self.idx < len(poses) - 1
                and math.hypot(poses[self.idx].pose.position.x - x, poses[self.idx].pose.position.y - y) < 0.6
            ):
                self.idx += 1
            target = poses[self.idx].pose.position
        err = wrap(math.atan2(target.y - y, target.x - x) - yaw)
        cmd = Twist()
        vmax = float(self.get_parameter("FollowPath.max_vel_x").value)
        if abs(err) > 0.8:
            cmd.angular.z = math.copysign(0.8, err)
        else:
            cmd.linear.x = min(vmax * max(0.0, math.cos(err)), 0.25 + 0.5 * dist)
            cmd.angular.z = max(-1.0, min(1.0, 2.0 * err))
        self.cmd_pub.publish(cmd)

    def _execute(self, goal_handle: Any) -> Fibonacci.Result:
        result = Fibonacci.Result()
        t0 = time.monotonic()
        while time.monotonic() - t0 < 1.0:  # the plan this goal follows
            plan = self.plan
            if plan is not None and time.time() - stamp_s(plan.header.stamp) < 1.5:
                break
            time.sleep(0.02)
        self.outcome = None
        self.progress_ref = (0.0, 0.0, time.monotonic())
        if self.odom is not None:
            p = self.odom.pose.pose.position
            self.progress_ref = (p.x, p.y, time.monotonic())
        self.following = True
        self.control_timer.reset()
        last_fb = 0.0
        while self.outcome is None:
            if goal_handle.is_cancel_requested or not self.active:
                self._finish(5)
                goal_handle.canceled()
                result.sequence = [5]
                return result
            if time.monotonic() - last_fb > 0.5:
                last_fb = time.monotonic()
                goal_handle.publish_feedback(Fibonacci.Feedback(sequence=[int(self.remaining * 100)]))
            time.sleep(0.05)
        result.sequence = [self.outcome]
        if self.outcome == 0:
            goal_handle.succeed()
        else:
            goal_handle.abort()
        return result


class BehaviorServer(ManagedNode):
    """Recovery behaviours: ``/hd/backup`` (action, order = cm) drives backwards on cmd_vel_nav."""

    def __init__(self) -> None:
        super().__init__("behavior_server")
        self.declare_parameter("behavior_plugins", ["spin", "backup", "wait"])

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.cmd_pub = self.create_lifecycle_publisher(Twist, "/hd/cmd_vel_nav", COMMAND)
        self.server = ActionServer(
            self,
            Fibonacci,
            "/hd/backup",
            execute_callback=self._backup,
            goal_callback=lambda _: GoalResponse.ACCEPT if self.active else GoalResponse.REJECT,
            cancel_callback=lambda _: CancelResponse.ACCEPT,
            callback_group=self.reentrant,
        )
        self.get_logger().info("Configuring behaviors: spin, backup, wait")
        return TransitionCallbackReturn.SUCCESS

    def _backup(self, goal_handle: Any) -> Fibonacci.Result:
        dist = goal_handle.request.order / 100.0
        self.get_logger().info(f"Running backup ({dist:.2f} m)")
        end = time.monotonic() + dist / 0.1
        cmd = Twist()
        cmd.linear.x = -0.1
        while time.monotonic() < end:
            if goal_handle.is_cancel_requested:
                goal_handle.canceled()
                return Fibonacci.Result(sequence=[5])
            self.cmd_pub.publish(cmd)
            time.sleep(0.1)
        self.cmd_pub.publish(Twist())
        self.get_logger().info("backup completed successfully")
        goal_handle.succeed()
        return Fibonacci.Result(sequence=[0])


class BtNavigator(ManagedNode):
    """``/hd/navigate_to_pose`` (action, order = place index): plan, follow, re-plan every 1 s,
    one back-up recovery on a progress failure."""

    def __init__(self) -> None:
        super().__init__("bt_navigator")
        self.declare_parameter("default_nav_to_pose_bt_xml", "navigate_to_pose_w_replanning_and_recovery.xml")
        self.declare_parameter("replan_period", 1.0)
        self.pose: PoseWithCovarianceStamped | None = None
        self.pose_t = 0.0
        self.clients_group = ReentrantCallbackGroup()

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.create_subscription(PoseWithCovarianceStamped, "/hd/amcl_pose", self._on_pose, LATCHED)
        self.planner = self.create_client(
            GetPlan, "/hd/compute_path_to_pose", callback_group=self.clients_group
        )
        self.follow = ActionClient(self, Fibonacci, "/hd/follow_path", callback_group=self.clients_group)
        self.backup = ActionClient(self, Fibonacci, "/hd/backup", callback_group=self.clients_group)
        self.server = ActionServer(
            self,
            Fibonacci,
            "/hd/navigate_to_pose",
            execute_callback=self._navigate,
            goal_callback=lambda _: GoalResponse.ACCEPT if self.active else GoalResponse.REJECT,
            cancel_callback=lambda _: CancelResponse.ACCEPT,
            callback_group=self.reentrant,
        )
        return TransitionCallbackReturn.SUCCESS

    def _on_pose(self, msg: PoseWithCovarianceStamped) -> None:
        self.pose, self.pose_t = msg, time.monotonic()

    def _compute_path(self, gx: float, gy: float) -> PathMsg | None:
        pose = self.pose
        assert pose is not None
        req = GetPlan.Request()
        req.start.header.frame_id = req.goal.header.frame_id = "map"
        req.start.pose = pose.pose.pose
        req.goal.pose.position.x, req.goal.pose.position.y = gx, gy
        fut = self.planner.call_async(req)
        if not wait_future(fut, 2.0):
            self.planner.remove_pending_request(fut)
            self.get_logger().error(
                "compute_path_to_pose: planner server did not respond within 2.0 s (/hd/compute_path_to_pose)"
            )
            return None
        return fut.result().plan

    def _run_action(self, client: ActionClient, order: int, timeout: float) -> Any:
        if not client.wait_for_server(timeout_sec=2.0):
            return None
        fut = client.send_goal_async(Fibonacci.Goal(order=order))
        if not wait_future(fut, 2.0) or not fut.result().accepted:
            return None
        return fut.result()

    def _navigate(self, goal_handle: Any) -> Fibonacci.Result:
        idx = goal_handle.request.order
        name, gx, gy = PLACES[idx]
        self.get_logger().info(f"Begin navigating from current location to ({gx:.2f}, {gy:.2f}) [{name}]")

        def end(code: int) -> Fibonacci.Result:
            if code == 0:
                goal_handle.succeed()
            elif code == 5:
                goal_handle.canceled()
            else:
                goal_handle.abort()
                self.get_logger().error(f"Goal failed: {NAV_CODES[code]}")
            return Fibonacci.Result(sequence=[code])

        if self.pose is None or time.monotonic() - self.pose_t > 2.5:
            return end(3)
        plan = self._compute_path(gx, gy)
        if plan is None:
            return end(1)
        if not plan.poses:
            return end(4)
        recoveries = 0
        handle = self._run_action(self.follow, idx, 2.0)
        if handle is None:
            return end(6)
        result_fut = handle.get_result_async()
        last_plan = time.monotonic()
        last_fb = 0.0
        while True:
            if goal_handle.is_cancel_requested:
                handle.cancel_goal_async()
                return end(5)
            if result_fut.done():
                code = result_fut.result().result.sequence[0] if result_fut.result().result.sequence else 6
                if code == 2 and recoveries < 1:
                    recoveries += 1
                    self.get_logger().warn("Controller failed to make progress: running recovery 'backup'")
                    bh = self._run_action(self.backup, 15, 2.0)
                    if bh is not None:
                        wait_future(bh.get_result_async(), 5.0)
                    plan = self._compute_path(gx, gy)
                    if plan is None:
                        return end(1)
                    handle = self._run_action(self.follow, idx, 2.0)
                    if handle is None:
                        return end(6)
                    result_fut = handle.get_result_async()
                    continue
                return end(code)
            now = time.monotonic()
            if now - last_plan >= 1.0:
                last_plan = now
                if time.monotonic() - self.pose_t > 2.5:
                    handle.cancel_goal_async()
                    return end(3)
                if self._compute_path(gx, gy) is None:
                    handle.cancel_goal_async()
                    return end(1)
            if now - last_fb >= 1.0 and self.pose is not None:
                last_fb = now
                p = self.pose.pose.pose.position
                goal_handle.publish_feedback(
                    Fibonacci.Feedback(sequence=[int(math.hypot(gx - p.x, gy - p.y) * 100), recoveries])
                )
            time.sleep(0.05)


class LifecycleManager(Node):
    """Configures and activates the navigation servers, then polls each ``~/get_state`` every 2 s
    (its bond): 4 s without an answer is a broken bond."""

    MANAGED = ("map_server", "amcl", "planner_server", "controller_server", "behavior_server", "bt_navigator")

    def __init__(self) -> None:
        super().__init__("lifecycle_manager_navigation", namespace=NS)
        self.declare_parameter("node_names", list(self.MANAGED))
        self.declare_parameter("bond_timeout", 4.0)
        self.group = ReentrantCallbackGroup()
        self.change = {
            n: self.create_client(ChangeState, f"{NS}/{n}/change_state", callback_group=self.group)
            for n in self.MANAGED
        }
        self.get = {
            n: self.create_client(GetState, f"{NS}/{n}/get_state", callback_group=self.group)
            for n in self.MANAGED
        }
        self.pending: dict[str, tuple[Any, float]] = {}
        self.broken: set[str] = set()
        self.wrong_state: set[str] = set()
        self.up = False
        self.diag = DiagPublisher(self)
        self.closing = threading.Event()
        self.create_timer(2.0, self._bond)
        threading.Thread(target=self._startup, daemon=True).start()

    def close(self) -> None:
        self.closing.set()

    def _transition(self, name: str, tid: int, label: str) -> bool:
        client = self.change[name]
        if not client.wait_for_service(timeout_sec=10.0):
            self.get_logger().error(f"Failed to change state for node: {name} (service not available)")
            return False
        fut = client.call_async(ChangeState.Request(transition=Transition(id=tid)))
        if not wait_future(fut, 5.0, self.closing) or not fut.result().success:
            self.get_logger().error(f"Failed to change state for node: {name}")
            return False
        return True

    def _startup(self) -> None:
        self.get_logger().info("Starting managed nodes bringup...")
        for name in self.MANAGED:
            self.get_logger().info(f"Configuring {name}")
            if not self._transition(name, Transition.TRANSITION_CONFIGURE, "configure"):
                return
        for name in self.MANAGED:
            self.get_logger().info(f"Activating {name}")
            if not self._transition(name, Transition.TRANSITION_ACTIVATE, "activate"):
                return
        self.get_logger().info("Managed nodes are active")
        self.get_logger().info("Creating bond timer...")
        self.up = True

    def _bond(self) -> None:
        if not self.up:
            return
        now = time.monotonic()
        for name in self.MANAGED:
            if name in self.pending:
                fut, sent = self.pending[name]
                if not fut.done():
                    if now - sent > 4.0 and name not in self.broken:
                        self.broken.add(name)
                        self.get_logger().error(
                            f"CRITICAL FAILURE: SERVER {name} IS DOWN after not receiving a heartbeat "
                            "for 4000 ms."
                        )
                    continue
                del self.pending[name]
                label = fut.result().current_state.label
                if name in self.broken:
                    self.broken.discard(name)
                    self.get_logger().info(f"Heartbeat from {name} restored")
                if label != "active" and name not in self.wrong_state:
                    self.wrong_state.add(name)
                    self.get_logger().warn(f"Managed node {name} reports state '{label}', expected 'active'")
                elif label == "active":
                    self.wrong_state.discard(name)
            self.pending[name] = (self.get[name].call_async(GetState.Request()), now)
        bad = self.broken | self.wrong_state
        self.diag.publish(
            diag(
                self,
                "Nav2 Health",
                2 if bad else 0,
                "Managed nodes are active"
                if not bad
                else "Managed nodes not active: " + ", ".join(sorted(bad)),
            )
        )


# ----------------------------------------------------------------------------------------------
# base: base controller, battery and motor driver in one process


class BaseController(Node):
    """Differential drive: ``/hd/cmd_vel`` -> ``/hd/odom`` and odom->base_link at 20 Hz, wheel
    ``/hd/joint_states`` at 10 Hz; fuses the IMU's yaw rate (falls back to the wheels without it)."""

    def __init__(self) -> None:
        super().__init__("base_controller", namespace=NS)
        self.fault = ""
        self.declare_parameter("wheel_separation", 0.46)
        self.declare_parameter("wheel_radius", 0.0825)
        self.declare_parameter("cmd_vel_timeout", 0.5)
        self.odom_pub = self.create_publisher(Odometry, "/hd/odom", RELIABLE)
        self.tf_pub = self.create_publisher(TransformStamped, "/tf", TF)
        self.js_pub = self.create_publisher(JointState, "/hd/joint_states", RELIABLE)
        self.estop_pub = self.create_publisher(Bool, "/hd/base/estop", LATCHED)
        self.create_subscription(Twist, "/hd/cmd_vel", self._cmd, RELIABLE)
        self.create_subscription(Imu, "/hd/imu/data", self._imu, SENSOR)
        self.x, self.y, self.yaw = PLACES[PLACE_INDEX["dock"]][1], PLACES[PLACE_INDEX["dock"]][2], 0.0
        self.v = self.w = 0.0
        self.cmd = Twist()
        self.cmd_t = 0.0
        self.wheels = [0.0, 0.0]
        self.imu = RateMeter(2.0)
        self.imu_t = time.monotonic()
        self.last_imu_warn = 0.0
        self.tick = 0
        self.started = time.monotonic()
        self.estop_pub.publish(Bool(data=False))
        self.create_timer(0.05, self._update)
        self.get_logger().info(
            "Motor controller connected on /dev/ttyACM0 (roboteq SBL2360), odometry at 20 Hz"
        )

    def _cmd(self, msg: Twist) -> None:
        self.cmd, self.cmd_t = msg, time.monotonic()

    def _imu(self, msg: Imu) -> None:
        self.imu.tick()
        self.imu_t = time.monotonic()

    def _update(self) -> None:
        dt = 0.05
        now = time.monotonic()
        cmd = self.cmd if now - self.cmd_t < 0.5 else Twist()
        self.v += max(-0.04, min(0.04, cmd.linear.x - self.v))
        self.w += max(-0.1, min(0.1, cmd.angular.z - self.w))
        self.yaw = wrap(self.yaw + self.w * dt)
        self.x += self.v * math.cos(self.yaw) * dt
        self.y += self.v * math.sin(self.yaw) * dt
        self.wheels[0] += (self.v - self.w * 0.23) / 0.0825 * dt
        self.wheels[1] += (self.v + self.w * 0.23) / 0.0825 * dt
        stamp = stamp_now(self)
        odom = Odometry()
        odom.header.stamp = stamp
        odom.header.frame_id, odom.child_frame_id = "odom", "base_link"
        odom.pose.pose.position.x, odom.pose.pose.position.y = self.x, self.y
        odom.pose.pose.orientation = yaw_quat(self.yaw)
        odom.twist.twist.linear.x, odom.twist.twist.angular.z = self.v, self.w
        self.odom_pub.publish(odom)
        tf = TransformStamped()
        tf.header = odom.header
        tf.child_frame_id = "base_link"
        tf.transform.translation.x, tf.transform.translation.y = self.x, self.y
        tf.transform.rotation = odom.pose.pose.orientation
        self.tf_pub.publish(tf)
        self.tick += 1
        if self.tick % 2 == 0:
            self.js_pub.publish(
                JointState(
                    header=Header(stamp=stamp),
                    name=["wheel_left_joint", "wheel_right_joint"],
                    position=list(self.wheels),
                    velocity=[(self.v - self.w * 0.23) / 0.0825, (self.v + self.w * 0.23) / 0.0825],
                )
            )
        if self.tick % 20 == 0 and now - self.started > 5.0 and now - self.last_imu_warn > 5.0:
            hz = self.imu.rate()
            if now - self.imu_t > 1.0:
                self.last_imu_warn = now
                self.get_logger().warn(
                    f"IMU timeout: no /hd/imu/data for {now - self.imu_t:.1f} s, yaw from wheel odometry only"
                )
            elif hz < 60.0:
                self.last_imu_warn = now
                self.get_logger().warn(
                    f"IMU rate {hz:.1f} Hz below 60 Hz on /hd/imu/data: yaw fused from wheel odometry only"
                )


class BatteryMonitor(Node):
    """Battery pack: ``/hd/battery_state`` 1 Hz and its diagnostics."""

    def __init__(self) -> None:
        super().__init__("battery_monitor", namespace=NS)
        self.fault = ""
        self.pub = self.create_publisher(BatteryState, "/hd/battery_state", RELIABLE)
        self.diag = DiagPublisher(self)
        self.charge = random.uniform(0.62, 0.9)
        self.create_timer(1.0, self._update)

    def _update(self) -> None:
        self.charge = max(0.05, self.charge - 0.00004)
        msg = BatteryState(
            voltage=24.0 + 4.0 * self.charge,
            current=-random.uniform(1.8, 4.5),
            percentage=self.charge,
            capacity=40.0,
            design_capacity=40.0,
            power_supply_status=BatteryState.POWER_SUPPLY_STATUS_DISCHARGING,
            power_supply_health=BatteryState.POWER_SUPPLY_HEALTH_GOOD,
            power_supply_technology=BatteryState.POWER_SUPPLY_TECHNOLOGY_LION,
            present=True,
        )
        msg.header.stamp = stamp_now(self)
        msg.header.frame_id = "battery_link"
        self.pub.publish(msg)
        self.diag.publish(
            diag(
                self,
                "Battery pack",
                0,
                "OK",
                "bq40z50@i2c-1:0x0b",
                charge=f"{self.charge * 100:.1f} %",
                voltage=f"{msg.voltage:.2f} V",
            )
        )


class MotorDriver(Node):
    """The motor controller's diagnostics (both wheels), 1 Hz."""

    def __init__(self) -> None:
        super().__init__("motor_driver", namespace=NS)
        self.fault = ""
        self.diag = DiagPublisher(self)
        self.temp = [34.0, 35.0]
        self.speed = 0.0
        self.create_subscription(Twist, "/hd/cmd_vel", self._cmd, RELIABLE)
        self.create_timer(1.0, self._update)

    def _cmd(self, msg: Twist) -> None:
        self.speed = abs(msg.linear.x) + abs(msg.angular.z) * 0.2

    def _update(self) -> None:
        out = []
        for i, side in enumerate(("Left", "Right")):
            self.temp[i] += 0.05 * (34.0 + 20.0 * self.speed - self.temp[i])
            out.append(
                diag(
                    self,
                    f"{side} wheel motor",
                    0,
                    "OK",
                    "roboteq-sbl2360:/dev/ttyACM0",
                    temperature=f"{self.temp[i]:.1f} C",
                    current=f"{0.4 + 6.0 * self.speed:.2f} A",
                )
            )
        self.diag.publish(*out)


# ----------------------------------------------------------------------------------------------
# robot_state_publisher


URDF = """<?xml version="1.0"?>
<robot name="hd_01">
  <link name="base_footprint"/><link name="base_link"/><link name="laser_link"/><link name="imu_link"/>
  <link name="camera_link"/><link name="camera_depth_optical_frame"/>
  <link name="wheel_left_link"/><link name="wheel_right_link"/>
  <joint name="wheel_left_joint" type="continuous">
    <parent link="base_link"/><child link="wheel_left_link"/></joint>
  <joint name="wheel_right_joint" type="continuous">
    <parent link="base_link"/><child link="wheel_right_link"/></joint>
</robot>"""


class RobotStatePublisher(Node):
    """URDF -> ``/tf_static`` (latched), ``/hd/robot_description``; wheel joints -> ``/tf``."""

    STATIC = (
        ("base_footprint", "base_link", 0.0, 0.0, 0.09),
        ("base_link", "laser_link", 0.22, 0.0, 0.31),
        ("base_link", "imu_link", 0.0, 0.0, 0.12),
        ("base_link", "camera_link", 0.25, 0.0, 0.85),
        ("camera_link", "camera_depth_optical_frame", 0.0, 0.0, 0.0),
    )

    def __init__(self) -> None:
        super().__init__("robot_state_publisher", namespace=NS)
        self.fault = ""
        self.declare_parameter("robot_description", URDF)
        self.tf_pub = self.create_publisher(TransformStamped, "/tf", TF)
        static = self.create_publisher(TransformStamped, "/tf_static", TF_STATIC)
        desc = self.create_publisher(String, "/hd/robot_description", LATCHED)
        stamp = stamp_now(self)
        for parent, child, x, y, z in self.STATIC:
            t = TransformStamped()
            t.header.stamp, t.header.frame_id, t.child_frame_id = stamp, parent, child
            t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = x, y, z
            t.transform.rotation.w = 1.0
            static.publish(t)
        desc.publish(String(data=URDF))
        self.create_subscription(JointState, "/hd/joint_states", self._joints, RELIABLE)
        self.get_logger().info("Robot initialized: 8 links, 2 moving joints")

    def _joints(self, msg: JointState) -> None:
        for name, pos, y in zip(
            ("wheel_left_link", "wheel_right_link"), msg.position, (0.23, -0.23), strict=False
        ):
            t = TransformStamped()
            t.header.stamp, t.header.frame_id, t.child_frame_id = msg.header.stamp, "base_link", name
            t.transform.translation.y = y
            t.transform.rotation.y, t.transform.rotation.w = math.sin(pos / 2), math.cos(pos / 2)
            self.tf_pub.publish(t)


# ----------------------------------------------------------------------------------------------
# safety: safety monitor (scan stop zone, e-stop, heartbeat) and the velocity mux


class SafetyMonitor(Node):
    """Stops the base when the scan shows something within 0.35 m ahead, the scan is stale (0.5 s) or
    the e-stop is pressed: ``/hd/safety/heartbeat`` 10 Hz, ``/hd/safety/state`` latched."""

    def __init__(self) -> None:
        super().__init__("safety_monitor", namespace=NS)
        self.fault = ""
        self.declare_parameter("stop_distance", 0.35)
        self.declare_parameter("scan_timeout", 0.5)
        self.scan_qos = "best_effort"
        self.scan_sub = self.create_subscription(LaserScan, "/hd/scan", self._scan, SENSOR)
        self.create_subscription(Bool, "/hd/base/estop", self._estop, LATCHED)
        self.hb_pub = self.create_publisher(Header, "/hd/safety/heartbeat", COMMAND)
        self.state_pub = self.create_publisher(String, "/hd/safety/state", LATCHED)
        self.diag = DiagPublisher(self)
        self.scan_t = time.monotonic()
        self.near = False
        self.estop = False
        self.state = ""
        self.reasons: list[str] = []
        self.n = 0
        self.create_timer(0.1, self._update)

    def _scan(self, msg: LaserScan) -> None:
        self.scan_t = time.monotonic()
        self.near = min(msg.ranges[165:196]) < 0.35

    def _estop(self, msg: Bool) -> None:
        self.estop = msg.data

    def _update(self) -> None:
        if self.fault == "reliable" and self.scan_qos != "reliable":
            self.scan_qos = "reliable"  # a redeployed safety.yaml asks for a reliable scan
            self.get_logger().info("Parameters reloaded from safety.yaml: scan_qos.reliability=reliable")
            self.destroy_subscription(self.scan_sub)
            self.scan_sub = self.create_subscription(LaserScan, "/hd/scan", self._scan, QoSProfile(depth=5))
        now = time.monotonic()
        reasons = []
        if self.estop:
            reasons.append("e-stop pressed")
        if now - self.scan_t > 0.5:
            reasons.append(f"scan data stale ({now - self.scan_t:.1f} s)")
        elif self.near:
            reasons.append("obstacle within 0.35 m ahead")
        state = "STOP" if reasons else "RUN"
        if state != self.state:
            if state == "STOP":
                self.get_logger().warn("Protective stop: " + ", ".join(reasons))
            elif self.state:
                self.get_logger().info("Protective stop cleared")
            self.state = state
            self.state_pub.publish(String(data=json.dumps({"state": state, "reasons": reasons})))
        self.reasons = reasons
        self.hb_pub.publish(Header(stamp=stamp_now(self), frame_id=state))
        self.n += 1
        if self.n % 10 == 0:
            self.diag.publish(
                diag(
                    self,
                    "Protective stop",
                    1 if reasons else 0,
                    "; ".join(reasons) if reasons else "Running",
                    "safety-plc-1",
                )
            )


class CmdVelMux(Node):
    """Teleop over navigation -> ``/hd/cmd_vel``, capped by ``speed_limit``, zero while the safety
    heartbeat says STOP or is lost; silent while its inputs are."""

    def __init__(self) -> None:
        super().__init__("cmd_vel_mux", namespace=NS)
        self.fault = ""
        self.declare_parameter("speed_limit", 0.8)
        self.declare_parameter("angular_limit", 1.0)
        self.add_on_set_parameters_callback(self._params)
        self.limit = 0.8
        self.pub = self.create_publisher(Twist, "/hd/cmd_vel", RELIABLE)
        self.active_pub = self.create_publisher(String, "~/active", LATCHED)
        self.create_subscription(Twist, "/hd/cmd_vel_nav", lambda m: self._input("navigation", m), COMMAND)
        self.create_subscription(Twist, "/hd/cmd_vel_teleop", lambda m: self._input("teleop", m), COMMAND)
        self.create_subscription(Header, "/hd/safety/heartbeat", self._heartbeat, COMMAND)
        self.hb_t = 0.0
        self.hb_run = False
        self.last = {"navigation": 0.0, "teleop": 0.0}
        self.active = "idle"
        self.active_pub.publish(String(data="idle"))
        self.create_timer(0.1, self._watch)

    def _params(self, params: list[Any]) -> SetParametersResult:
        for p in params:
            if p.name == "speed_limit":
                self.limit = float(p.value)
                self.get_logger().info(f"Speed limit set to {self.limit:.2f} m/s")
        return SetParametersResult(successful=True)

    def _heartbeat(self, msg: Header) -> None:
        self.hb_t, self.hb_run = time.monotonic(), msg.frame_id == "RUN"

    def _set_active(self, source: str) -> None:
        if source != self.active:
            self.active = source
            self.active_pub.publish(String(data=source))
            self.get_logger().info(f"Active input: {source}")

    def _input(self, source: str, msg: Twist) -> None:
        now = time.monotonic()
        self.last[source] = now
        if source == "navigation" and now - self.last["teleop"] < 0.5:
            return
        self._set_active(source)
        out = Twist()
        if self.hb_run and now - self.hb_t < 0.3:
            out.linear.x = max(-self.limit, min(self.limit, msg.linear.x))
            out.angular.z = max(-1.0, min(1.0, msg.angular.z))
        self.pub.publish(out)

    def _watch(self) -> None:
        if self.active != "idle" and time.monotonic() - self.last[self.active] > 0.5:
            self.pub.publish(Twist())
            self._set_active("idle")


# ----------------------------------------------------------------------------------------------
# teleop: the remote assistance bridge (a remote operator drives only after a failed mission)


class RemoteTeleop(Node):
    """Publishes ``/hd/cmd_vel_teleop`` (10 Hz) only while a remote operator drives: a remote assist
    session 4-8 s after a mission failure, 5 s of backing up and turning."""

    def __init__(self) -> None:
        super().__init__("remote_teleop", namespace=NS)
        self.fault = ""
        self.pub = self.create_publisher(Twist, "/hd/cmd_vel_teleop", COMMAND)
        self.session_pub = self.create_publisher(String, "~/session", LATCHED)
        self.create_subscription(String, "/hd/mission_executor/status", self._status, LATCHED)
        self.session_pub.publish(String(data=json.dumps({"operator": None})))
        self.start_at = 0.0
        self.end_at = 0.0
        self.who = ""
        self.create_timer(0.1, self._drive)

    def _status(self, msg: String) -> None:
        st = json.loads(msg.data)
        if st.get("state") == "FAILED" and self.start_at == 0.0 and self.end_at == 0.0:
            self.start_at = time.monotonic() + random.uniform(4.0, 8.0)
            self.who = random.choice(("remote-ops-anna", "remote-ops-ben", "remote-ops-chidi"))

    def _drive(self) -> None:
        now = time.monotonic()
        if self.start_at and now >= self.start_at:
            self.start_at = 0.0
            self.end_at = now + 5.0
            self.get_logger().info(f"Remote operator '{self.who}' took control (assist request)")
            self.session_pub.publish(String(data=json.dumps({"operator": self.who})))
        if self.end_at:
            if now >= self.end_at:
                self.end_at = 0.0
                self.pub.publish(Twist())
                self.get_logger().info(f"Remote operator '{self.who}' released control")
                self.session_pub.publish(String(data=json.dumps({"operator": None})))
                return
            cmd = Twist()
            if self.end_at - now > 3.0:
                cmd.linear.x = -0.1
            else:
                cmd.angular.z = 0.4
            self.pub.publish(cmd)


# ----------------------------------------------------------------------------------------------
# mission: the delivery executor (a behaviour-tree-like state machine in a worker thread)


class MissionError(Exception):
    def __init__(self, phase: str, why: str) -> None:
        super().__init__(why)
        self.phase, self.why = phase, why


class MissionExecutor(Node):
    """Executes delivery orders from ``/fleet/orders``: pick-up at the floor's meds room, doors,
    elevator, drop-off with the nurse's PIN; reports to the fleet server."""

    def __init__(self) -> None:
        super().__init__("mission_executor", namespace=NS)
        self.fault = ""
        self.declare_parameter("robot_id", ROBOT_ID)
        self.declare_parameter("pin_timeout", 45.0)
        self.declare_parameter("elevator_timeout", 40.0)
        self.declare_parameter("door_timeout", 8.0)
        self.group = ReentrantCallbackGroup()
        self.status_pub = self.create_publisher(String, "~/status", LATCHED)
        self.state_pub = self.create_publisher(String, "~/robot_state", RELIABLE)
        self.create_subscription(String, "/fleet/orders", self._order, RELIABLE)
        self.create_subscription(String, "/hd/hmi/keypad", self._key, RELIABLE)
        self.create_subscription(PoseWithCovarianceStamped, "/hd/amcl_pose", self._pose, LATCHED)
        self.create_subscription(BatteryState, "/hd/battery_state", self._battery, RELIABLE)
        self.nav = ActionClient(self, Fibonacci, "/hd/navigate_to_pose", callback_group=self.group)
        self.door = self.create_client(BasicTypes, "/building/door/open", callback_group=self.group)
        self.elevator = self.create_client(
            BasicTypes, "/building/elevator/request", callback_group=self.group
        )
        self.elevator.configure_introspection(
            self.get_clock(), qos_profile_system_default, ServiceIntrospectionState.METADATA
        )
        self.drawer = self.create_client(
            BasicTypes, "/hd/drawer_controller/open_drawer", callback_group=self.group
        )
        self.mux_params = self.create_client(
            SetParameters, "/hd/cmd_vel_mux/set_parameters", callback_group=self.group
        )
        self.incident = self.create_client(
            BasicTypes, "/fleet_server/report_incident", callback_group=self.group
        )
        self.orders: queue.Queue[dict] = queue.Queue()
        self.pins: queue.Queue[str] = queue.Queue()
        self.closing = threading.Event()
        self.state = "IDLE"
        self.order_id = ""
        self.floor = 3
        self.place = "dock"
        self.last_order = ""
        self.last_result = ""
        self.pose = (0.0, 0.0)
        self.battery = 0.0
        self.remaining = 0.0
        self._publish_status()
        self.create_timer(1.0, self._robot_state)
        self.worker = threading.Thread(target=self._run, daemon=True)
        self.worker.start()
        self.get_logger().info(
            f"Mission executor for {ROBOT_ID} ready (floor {self.floor}, at '{self.place}')"
        )

    def close(self) -> None:
        self.closing.set()

    # -- inputs
    def _order(self, msg: String) -> None:
        order = json.loads(msg.data)
        if order.get("robot") == ROBOT_ID:
            self.orders.put(order)

    def _key(self, msg: String) -> None:
        ev = json.loads(msg.data)
        if ev.get("event") == "enter":
            self.pins.put(ev.get("pin", ""))

    def _pose(self, msg: PoseWithCovarianceStamped) -> None:
        self.pose = (msg.pose.pose.position.x, msg.pose.pose.position.y)

    def _battery(self, msg: BatteryState) -> None:
        self.battery = msg.percentage

    # -- outputs
    def _publish_status(self) -> None:
        self.status_pub.publish(
            String(
                data=json.dumps(
                    {"state": self.state, "order_id": self.order_id, "floor": self.floor, "place": self.place}
                )
            )
        )

    def _set_state(self, state: str) -> None:
        self.state = state
        self._publish_status()

    def _robot_state(self) -> None:
        self.state_pub.publish(
            String(
                data=json.dumps(
                    {
                        "robot": ROBOT_ID,
                        "state": self.state,
                        "order_id": self.order_id,
                        "floor": self.floor,
                        "place": self.place,
                        "battery": round(self.battery, 3),
                        "last_order": self.last_order,
                        "last_result": self.last_result,
                        "x": round(self.pose[0], 2),
                        "y": round(self.pose[1], 2),
                    }
                )
            )
        )

    # -- the worker
    def _run(self) -> None:
        while not self.closing.is_set():
            try:
                order = self.orders.get(timeout=0.5)
            except queue.Empty:
                continue
            self._execute(order)

    def _execute(self, order: dict) -> None:
        oid = order["order_id"]
        self.order_id = oid
        t0 = time.monotonic()
        self.get_logger().info(
            f"[{oid}] Order accepted: {order['kind']} for {order['dropoff']} "
            f"(floor {order['floor']}), drawer {order['drawer']}"
        )
        phase = "start"
        try:
            phase = "to_pickup"
            self._set_state("TO_PICKUP")
            self._navigate("meds_room", phase)
            phase = "loading"
            self._set_state("LOADING")
            self._drawer(order["drawer"], True, oid, phase)
            self.get_logger().info(
                f"[{oid}] Drawer {order['drawer']} open for loading at meds room (floor {self.floor})"
            )
            self._sleep(random.uniform(3.0, 5.0))
            self._drawer(order["drawer"], False, oid, phase)
            phase = "leave_meds_room"
            self._door(f"meds_room_f{self.floor}", phase)
            if order["floor"] != self.floor:
                phase = "to_elevator"
                self._set_state("TO_ELEVATOR")
                self._navigate("elevator_lobby", phase)
                phase = "elevator"
                self._set_state("ELEVATOR")
                self._elevator(order["floor"], phase)
            phase = "to_dropoff"
            self._set_state("TO_DROPOFF")
            self._door(f"{order['dropoff']}_f{self.floor}", phase)
            self._navigate(order["dropoff"], phase)
            phase = "handover"
            self._set_state("WAITING_FOR_PIN")
            self._wait_pin(order["pin"], phase)
            self._set_state("UNLOADING")
            self._drawer(order["drawer"], True, oid, phase)
            self._sleep(random.uniform(2.5, 4.0))
            self._drawer(order["drawer"], False, oid, phase)
            self.last_result = "delivered"
            self.get_logger().info(
                f"[{oid}] Delivered to {order['dropoff']} (floor {self.floor}) "
                f"in {time.monotonic() - t0:.1f} s"
            )
        except MissionError as e:
            self.last_result = "failed"
            self.get_logger().error(f"[{oid}] Order failed in phase '{e.phase}': {e.why}")
            self._set_state("FAILED")
            self._report(oid, e)
            self._sleep(2.0)
        self.last_order = oid
        self.order_id = ""
        self._set_state("IDLE")

    def _sleep(self, s: float) -> None:
        self.closing.wait(s)

    def _call(self, client: Any, req: Any, timeout: float, phase: str, what: str) -> Any:
        if not client.wait_for_service(timeout_sec=2.0):
            raise MissionError(phase, f"service {client.srv_name} not available ({what})")
        fut = client.call_async(req)
        if not wait_future(fut, timeout, self.closing):
            client.remove_pending_request(fut)
            raise MissionError(
                phase, f"service {client.srv_name} did not answer within {timeout:.1f} s ({what})"
            )
        return fut.result()

    def _speed_limit(self, v: float, zone: str) -> None:
        req = SetParameters.Request(
            parameters=[
                Parameter(
                    name="speed_limit",
                    value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=v),
                )
            ]
        )
        if not self.mux_params.wait_for_service(timeout_sec=1.0):
            self.get_logger().warn(
                f"Could not set speed limit for zone '{zone}': cmd_vel_mux parameters unavailable"
            )
            return
        fut = self.mux_params.call_async(req)
        if not wait_future(fut, 2.0, self.closing):
            self.mux_params.remove_pending_request(fut)
            self.get_logger().warn(f"Could not set speed limit for zone '{zone}': no answer within 2.0 s")
            return
        self.get_logger().info(f"Entering speed zone '{zone}': {v:.2f} m/s")

    def _navigate(self, place: str, phase: str) -> None:
        if self.place == place:
            return
        self._speed_limit(0.8, "corridor")
        if not self.nav.wait_for_server(timeout_sec=3.0):
            raise MissionError(phase, "navigate_to_pose action server not available")
        self.remaining = 99.0
        fut = self.nav.send_goal_async(
            Fibonacci.Goal(order=PLACE_INDEX[place]), feedback_callback=self._feedback
        )
        if not wait_future(fut, 3.0, self.closing) or not fut.result().accepted:
            raise MissionError(phase, f"navigation goal to '{place}' rejected")
        self.get_logger().info(f"Navigating to '{place}'")
        self.place = ""
        res = fut.result().get_result_async()
        quiet = False
        end = time.monotonic() + 90.0
        while not res.done():
            if self.closing.is_set():
                return
            if time.monotonic() > end:
                fut.result().cancel_goal_async()
                raise MissionError(phase, f"navigation to '{place}' took more than 90 s")
            if not quiet and self.remaining < 3.0 and place != "elevator_lobby" and place != "meds_room":
                quiet = True
                self._speed_limit(0.45, f"{place} quiet zone")
            time.sleep(0.05)
        seq = res.result().result.sequence
        code = seq[0] if seq else 6
        if code != 0:
            raise MissionError(phase, f"navigation to '{place}' aborted: {NAV_CODES.get(code, code)}")
        self.place = place
        self.get_logger().info(f"Arrived at '{place}'")

    def _feedback(self, msg: Any) -> None:
        if msg.feedback.sequence:
            self.remaining = msg.feedback.sequence[0] / 100.0

    def _door(self, door: str, phase: str) -> None:
        t = time.monotonic()
        res = self._call(self.door, BasicTypes.Request(string_value=door), 8.0, phase, f"door '{door}'")
        if not res.bool_value:
            raise MissionError(phase, f"door '{door}' refused: {res.string_value}")
        dt = time.monotonic() - t
        if dt > 2.5:
            self.get_logger().warn(f"Door '{door}' slow to open ({dt:.1f} s)")
        else:
            self.get_logger().info(f"Door '{door}' open")

    def _elevator(self, floor: int, phase: str) -> None:
        self.get_logger().info(f"Requesting elevator: floor {self.floor} -> {floor}")
        t = time.monotonic()
        req = BasicTypes.Request(int32_value=floor, int64_value=self.floor, string_value=ROBOT_ID)
        res = self._call(self.elevator, req, 40.0, phase, f"floor {self.floor} -> {floor}")
        if not res.bool_value:
            raise MissionError(phase, f"elevator refused: {res.string_value}")
        self.floor = floor
        self.place = "elevator_lobby"
        self.get_logger().info(f"Elevator ride to floor {floor} done in {time.monotonic() - t:.1f} s")

    def _drawer(self, drawer: int, unlock: bool, oid: str, phase: str) -> None:
        req = BasicTypes.Request(int32_value=drawer, bool_value=unlock, string_value=oid)
        res = self._call(self.drawer, req, 3.0, phase, f"{'unlock' if unlock else 'lock'} drawer {drawer}")
        if not res.bool_value:
            raise MissionError(phase, f"drawer {drawer}: {res.string_value}")

    def _wait_pin(self, pin: str, phase: str) -> None:
        self.get_logger().info("Waiting for the nurse's PIN at the drop-off")
        while not self.pins.empty():
            self.pins.get_nowait()
        end = time.monotonic() + 45.0
        attempts = 0
        while time.monotonic() < end and not self.closing.is_set():
            try:
                got = self.pins.get(timeout=0.2)
            except queue.Empty:
                continue
            attempts += 1
            if got == pin:
                self.get_logger().info("PIN accepted")
                return
            self.get_logger().warn(f"Wrong PIN entered at the drop-off (attempt {attempts}/3)")
            if attempts >= 3:
                raise MissionError(phase, "three wrong PINs, returning the load")
        raise MissionError(phase, "no PIN entered within 45.0 s")

    def _report(self, oid: str, e: MissionError) -> None:
        req = BasicTypes.Request(
            string_value=json.dumps({"robot": ROBOT_ID, "order_id": oid, "phase": e.phase, "why": e.why})
        )
        try:
            self._call(self.incident, req, 2.0, e.phase, "incident report")
        except MissionError as r:
            self.get_logger().warn(f"Could not report the incident to the fleet server: {r.why}")


# ----------------------------------------------------------------------------------------------
# drawers: the secure compartments


class DrawerController(Node):
    """Four locked compartments: ``~/open_drawer`` (BasicTypes: int32 drawer, bool unlock),
    ``~/state`` latched (changes on events only), diagnostics 1 Hz."""

    def __init__(self) -> None:
        super().__init__("drawer_controller", namespace=NS)
        self.fault = ""
        self.declare_parameter("compartments", 4)
        self.declare_parameter("can_interface", "can0")
        self.started = time.monotonic()
        self.locked = [True] * 4
        self.owner = [""] * 4
        self.state_pub = self.create_publisher(String, "~/state", LATCHED)
        self.diag = DiagPublisher(self)
        self.create_service(BasicTypes, "~/open_drawer", self._open)
        self.get_logger().info("Homing 4 compartments on can0 (locker board 0x21)...")
        self._publish()
        self.create_timer(1.0, self._diagnostics)
        self.get_logger().info("Compartments homed and locked")

    def _publish(self) -> None:
        self.state_pub.publish(
            String(
                data=json.dumps(
                    [
                        {"drawer": i + 1, "locked": lk, "order": o}
                        for i, (lk, o) in enumerate(zip(self.locked, self.owner, strict=True))
                    ]
                )
            )
        )

    def _open(self, req: BasicTypes.Request, res: BasicTypes.Response) -> BasicTypes.Response:
        i = req.int32_value - 1
        if not 0 <= i < 4:
            res.bool_value, res.string_value = False, f"no drawer {req.int32_value}"
            return res
        time.sleep(0.15)  # the solenoid
        self.locked[i] = not req.bool_value
        self.owner[i] = req.string_value if req.bool_value else self.owner[i]
        self.get_logger().info(
            f"Drawer {i + 1} {'unlocked' if req.bool_value else 'locked'} ({req.string_value})"
        )
        self._publish()
        res.bool_value, res.string_value = True, "ok"
        return res

    def _diagnostics(self) -> None:
        if self.fault == "crashloop" and time.monotonic() - self.started > 3.0:
            self.get_logger().fatal(
                "Compartment 3 lock feedback out of range (0x7ff): calibration table "
                "/opt/hd/config/locker_cal.yaml corrupt; aborting"
            )
            time.sleep(0.2)
            os._exit(134)
        self.diag.publish(
            diag(
                self,
                "Compartment locks",
                0,
                "All compartments OK",
                "locker-can:0x21",
                locked=sum(self.locked),
            )
        )


# ----------------------------------------------------------------------------------------------
# hmi: the robot's own touchscreen (the nurse types the PIN)


class Touchscreen(Node):
    """Publishes ``/hd/hmi/keypad`` only when someone types (a burst of key presses at drop-off)."""

    def __init__(self) -> None:
        super().__init__("touchscreen", namespace=f"{NS}/hmi")
        self.fault = ""
        self.declare_parameter("announce_volume", 60)
        self.declare_parameter("language", "en")
        self.keypad = self.create_publisher(String, "/hd/hmi/keypad", RELIABLE)
        self.page_pub = self.create_publisher(String, "~/page", LATCHED)
        self.create_subscription(String, "/hd/mission_executor/status", self._status, LATCHED)
        self.create_subscription(String, "/fleet/orders", self._order, RELIABLE)
        self.add_on_set_parameters_callback(self._params)
        self.pins: dict[str, str] = {}
        self.page = ""
        self.keys: deque[tuple[float, dict]] = deque()
        self._set_page("idle")
        self.create_timer(0.1, self._type)

    def _params(self, params: list[Any]) -> SetParametersResult:
        for p in params:
            self.get_logger().info(f"Parameter {p.name} set to {p.value}")
        return SetParametersResult(successful=True)

    def _set_page(self, page: str) -> None:
        if page != self.page:
            self.page = page
            self.page_pub.publish(String(data=page))

    def _order(self, msg: String) -> None:
        o = json.loads(msg.data)
        self.pins[o["order_id"]] = o["pin"]

    def _status(self, msg: String) -> None:
        st = json.loads(msg.data)
        state = st.get("state", "")
        self._set_page(
            {
                "WAITING_FOR_PIN": "enter_pin",
                "LOADING": "loading",
                "UNLOADING": "take_items",
                "IDLE": "idle",
                "FAILED": "error",
            }.get(state, "driving")
        )
        if state == "WAITING_FOR_PIN" and not self.keys:
            pin = self.pins.get(st.get("order_id", ""), "0000")
            t = time.monotonic() + random.uniform(3.0, 9.0)  # the nurse walks up to the robot
            attempts = [pin]
            if random.random() < 0.1:
                attempts.insert(0, "".join(random.choice("0123456789") for _ in range(4)))
            for typed in attempts:
                for d in typed:
                    t += random.uniform(0.2, 0.45)
                    self.keys.append((t, {"event": "key", "key": d}))
                t += random.uniform(0.3, 0.6)
                self.keys.append((t, {"event": "enter", "pin": typed}))
                t += random.uniform(1.5, 2.5)

    def _type(self) -> None:
        now = time.monotonic()
        while self.keys and self.keys[0][0] <= now:
            _, ev = self.keys.popleft()
            self.keypad.publish(String(data=json.dumps(ev)))


# ----------------------------------------------------------------------------------------------
# building_gateway: doors and elevators through the hospital's building management system


class BuildingGateway(Node):
    """``/building/door/open`` (1-2.5 s) and ``/building/elevator/request`` (5-25 s): each request
    waits on the BMS link thread; ``/building/elevator/status`` 2 Hz and the diagnostics come from a
    relay thread, ``/building/doors/state`` latched on events."""

    def __init__(self) -> None:
        super().__init__("building_gateway")
        self.fault = ""
        self.declare_parameter("bms_endpoint", "opc.tcp://bms.stmarys.local:4840")
        group = ReentrantCallbackGroup()
        self.door_srv = self.create_service(
            BasicTypes, "/building/door/open", self._door, callback_group=group
        )
        self.elev_srv = self.create_service(
            BasicTypes, "/building/elevator/request", self._elevator, callback_group=group
        )
        self.elev_srv.configure_introspection(
            self.get_clock(), qos_profile_system_default, ServiceIntrospectionState.CONTENTS
        )
        self.status_pub = self.create_publisher(String, "/building/elevator/status", RELIABLE)
        self.doors_pub = self.create_publisher(String, "/building/doors/state", LATCHED)
        self.diag = DiagPublisher(self)
        self.jobs: list[tuple[float, threading.Event, Callable[[], None]]] = []
        self.lock = threading.Lock()
        self.car_floor = 3
        self.car_moving = False
        self.doors: dict[str, str] = {}
        self.closing = threading.Event()
        self.doors_pub.publish(String(data=json.dumps(self.doors)))
        threading.Thread(target=self._bms_link, daemon=True).start()
        threading.Thread(target=self._relay, daemon=True).start()
        self.get_logger().info(
            "Connected to BMS at opc.tcp://bms.stmarys.local:4840 (elevator bank B, 14 doors)"
        )

    def close(self) -> None:
        self.closing.set()

    def _submit(self, delay: float, then: Callable[[], None]) -> threading.Event:
        done = threading.Event()
        with self.lock:
            self.jobs.append((time.monotonic() + delay, done, then))
        return done

    def _bms_link(self) -> None:
        while not self.closing.wait(0.1):
            if self.fault == "hang":
                hang_forever()  # the OPC-UA session is half-open: reads block, nothing completes
            now = time.monotonic()
            with self.lock:
                due = [j for j in self.jobs if j[0] <= now]
                self.jobs = [j for j in self.jobs if j[0] > now]
            for _, ev, then in due:
                then()
                ev.set()

    def _relay(self) -> None:
        n = 0
        while not self.closing.wait(0.5):
            self.status_pub.publish(
                String(
                    data=json.dumps(
                        {"bank": "B", "car": 1, "floor": self.car_floor, "moving": self.car_moving}
                    )
                )
            )
            n += 1
            if n % 2 == 0:
                self.diag.publish(
                    diag(self, "BMS link", 0, "Connected", "bms.stmarys.local:4840", pending=len(self.jobs))
                )

    def _door(self, req: BasicTypes.Request, res: BasicTypes.Response) -> BasicTypes.Response:
        door = req.string_value

        def opened() -> None:
            self.doors[door] = "open"
            self.doors_pub.publish(String(data=json.dumps(self.doors)))

        self._submit(
            random.uniform(1.0, 2.0) if random.random() > 0.08 else random.uniform(2.6, 3.5), opened
        ).wait()
        res.bool_value, res.string_value = True, f"{door} open"
        return res

    def _elevator(self, req: BasicTypes.Request, res: BasicTypes.Response) -> BasicTypes.Response:
        src, dst = int(req.int64_value), int(req.int32_value)
        self.get_logger().info(f"Elevator request from {req.string_value}: floor {src} -> {dst} (car 1)")
        arrive = abs(self.car_floor - src) * 3.0 + random.uniform(1.0, 3.0)
        ride = (
            abs(dst - src) * 3.0
            + random.uniform(3.0, 6.0)
            + (random.uniform(4.0, 8.0) if random.random() < 0.2 else 0.0)
        )

        def called() -> None:
            self.car_floor, self.car_moving = src, True

        def arrived() -> None:
            self.car_floor, self.car_moving = dst, False

        self._submit(arrive, called).wait()
        self._submit(ride, arrived).wait()
        res.bool_value, res.string_value = True, f"arrived at floor {dst}"
        self.get_logger().info(f"Elevator car 1 at floor {dst}, doors open for {req.string_value}")
        return res


# ----------------------------------------------------------------------------------------------
# fleet_server: orders and robot tracking


class FleetServer(Node):
    """Dispatches an order 5-20 s after the robot reports idle, re-queues failed ones, marks the robot
    lost after 5 s without its state."""

    def __init__(self) -> None:
        super().__init__("fleet_server")
        self.fault = ""
        self.orders_pub = self.create_publisher(String, "/fleet/orders", RELIABLE)
        self.fleet_pub = self.create_publisher(String, "/fleet/fleet_state", RELIABLE)
        self.create_subscription(String, f"{NS}/mission_executor/robot_state", self._state, RELIABLE)
        self.create_service(BasicTypes, "~/report_incident", self._incident)
        self.state: dict = {}
        self.state_t = 0.0
        self.lost = False
        self.outstanding: dict | None = None
        self.sent_t = 0.0
        self.requeue: list[dict] = []
        self.next_dispatch = 0.0
        self.n = 0
        self.create_timer(1.0, self._tick)
        self.get_logger().info("Fleet server up: 1 robot registered (hd_01)")

    def _state(self, msg: String) -> None:
        self.state, self.state_t = json.loads(msg.data), time.monotonic()
        if self.lost:
            self.lost = False
            self.get_logger().info(f"Robot {ROBOT_ID} is back online")

    def _incident(self, req: BasicTypes.Request, res: BasicTypes.Response) -> BasicTypes.Response:
        inc = json.loads(req.string_value)
        self.get_logger().warn(
            f"Incident from {inc['robot']}: order {inc['order_id']} failed in {inc['phase']}"
        )
        res.bool_value = True
        return res

    def _new_order(self) -> dict:
        self.n += 1
        floor = random.choice(FLOORS) if random.random() < 0.4 else self.state.get("floor", 3)
        return {
            "order_id": f"ord-{self.n:04d}",
            "robot": ROBOT_ID,
            "kind": random.choice(("medication", "medication", "lab_sample", "blood_products")),
            "dropoff": random.choice(DROPOFFS),
            "floor": floor,
            "drawer": random.randint(1, 4),
            "pin": f"{random.randint(0, 9999):04d}",
        }

    def _tick(self) -> None:
        now = time.monotonic()
        if self.state_t and now - self.state_t > 5.0 and not self.lost:
            self.lost = True
            self.get_logger().error(
                f"Robot {ROBOT_ID}: no state for {now - self.state_t:.1f} s, marking it lost"
            )
        st = self.state
        self.fleet_pub.publish(
            String(
                data=json.dumps(
                    {
                        "robots": [{"id": ROBOT_ID, "lost": self.lost, "state": st.get("state", "UNKNOWN")}],
                        "queued": len(self.requeue),
                    }
                )
            )
        )
        if self.lost or not st:
            return
        if self.outstanding is not None:
            oid = self.outstanding["order_id"]
            if st.get("last_order") == oid and st.get("state") == "IDLE":
                if st.get("last_result") == "failed":
                    self.get_logger().warn(f"Order {oid} failed on {ROBOT_ID}: re-queued")
                    self.requeue.append(self.outstanding)
                else:
                    self.get_logger().info(f"Order {oid} completed by {ROBOT_ID}")
                self.outstanding = None
                self.next_dispatch = now + random.uniform(5.0, 20.0)
            elif now - self.sent_t > 10.0 and st.get("order_id") != oid and st.get("state") == "IDLE":
                self.get_logger().warn(f"Order {oid} not acknowledged by {ROBOT_ID}: re-sending")
                self.sent_t = now
                self.orders_pub.publish(String(data=json.dumps(self.outstanding)))
            return
        if st.get("state") != "IDLE":
            return
        if not self.next_dispatch:
            self.next_dispatch = now + random.uniform(4.0, 8.0)
        if now < self.next_dispatch:
            return
        order = self.requeue.pop(0) if self.requeue else self._new_order()
        self.outstanding, self.sent_t = order, now
        self.get_logger().info(
            f"Dispatching {order['order_id']} to {ROBOT_ID}: {order['kind']} -> "
            f"{order['dropoff']} floor {order['floor']}"
        )
        self.orders_pub.publish(String(data=json.dumps(order)))


# ----------------------------------------------------------------------------------------------
# diagnostics: the aggregator


class DiagnosticAggregator(Node):
    """``/diagnostics`` -> ``/diagnostics_agg`` at 1 Hz grouped by analyzer, STALE after 5 s."""

    GROUPS = (
        ("Base", ("base_controller", "battery_monitor", "motor_driver")),
        ("Sensors", ("front_lidar", "depth_camera", "imu")),
        ("Navigation", ("lifecycle_manager_navigation",)),
        ("Safety", ("safety_monitor",)),
        ("Payload", ("drawer_controller",)),
        ("Building", ("building_gateway",)),
    )

    def __init__(self) -> None:
        super().__init__("diagnostic_aggregator")
        self.fault = ""
        self.pub = self.create_publisher(DiagnosticArray, "/diagnostics_agg", RELIABLE)
        self.top = self.create_publisher(DiagnosticStatus, "/diagnostics_toplevel_state", RELIABLE)
        self.create_subscription(DiagnosticArray, "/diagnostics", self._diag, QoSProfile(depth=50))
        self.seen: dict[str, tuple[DiagnosticStatus, float]] = {}
        self.create_timer(1.0, self._publish)

    def _diag(self, msg: DiagnosticArray) -> None:
        now = time.monotonic()
        for s in msg.status:
            self.seen[s.name] = (s, now)

    def _group(self, name: str) -> str:
        node = name.split(":", 1)[0]
        for g, nodes in self.GROUPS:
            if node in nodes:
                return g
        return "Other"

    def _publish(self) -> None:
        now = time.monotonic()
        out = DiagnosticArray(header=Header(stamp=stamp_now(self)))
        worst: dict[str, int] = {}
        for name, (s, t) in sorted(self.seen.items()):
            g = self._group(name)
            level = 3 if now - t > 5.0 else s.level[0]
            msg = "Stale" if level == 3 else s.message
            out.status.append(
                DiagnosticStatus(
                    level=bytes([level]),
                    name=f"/{g}/{name}",
                    message=msg,
                    hardware_id=s.hardware_id,
                    values=s.values,
                )
            )
            worst[g] = max(worst.get(g, 0), level)
        for g, lv in worst.items():
            out.status.append(
                DiagnosticStatus(
                    level=bytes([lv]), name=f"/{g}", message=("OK", "Warning", "Error", "Stale")[lv]
                )
            )
        self.pub.publish(out)
        top = max(worst.values(), default=0)
        self.top.publish(
            DiagnosticStatus(
                level=bytes([top]), name="toplevel_state", message=("OK", "Warning", "Error", "Stale")[top]
            )
        )


# ----------------------------------------------------------------------------------------------
# recorder: a rosbag2-like recorder of the robot's low-rate topics


RECORDED: dict[str, tuple[type, QoSProfile]] = {
    "/hd/scan": (LaserScan, SENSOR),
    "/hd/odom": (Odometry, RELIABLE),
    "/tf": (TransformStamped, TF),
    "/tf_static": (TransformStamped, TF_STATIC),
    "/hd/cmd_vel": (Twist, RELIABLE),
    "/hd/amcl_pose": (PoseWithCovarianceStamped, LATCHED),
    "/hd/plan": (PathMsg, RELIABLE),
    "/hd/battery_state": (BatteryState, RELIABLE),
    "/diagnostics": (DiagnosticArray, RELIABLE),
    "/hd/safety/state": (String, LATCHED),
    "/hd/mission_executor/status": (String, LATCHED),
    "/hd/mission_executor/robot_state": (String, RELIABLE),
    "/fleet/orders": (String, RELIABLE),
    "/hd/drawer_controller/state": (String, LATCHED),
    "/hd/hmi/keypad": (String, RELIABLE),
    "/building/elevator/status": (String, RELIABLE),
    "/building/doors/state": (String, LATCHED),
    "/hd/cmd_vel_mux/active": (String, LATCHED),
    "/hd/map": (OccupancyGrid, LATCHED),
}


class Recorder(Node):
    """Serialized subscriptions to the recorded topics as they appear, drained by a writer thread
    at 10 Hz; a new bag file every 60 s."""

    def __init__(self) -> None:
        super().__init__("rosbag2_recorder")
        self.fault = ""
        self.declare_parameter("storage_id", "mcap")
        self.declare_parameter("max_bag_duration", 60)
        self.buffer: deque[tuple[str, float, bytes]] = deque()
        self.subs: dict[str, Any] = {}
        self.closing = threading.Event()
        self.bytes = 0
        self.n_file = 0
        self.get_logger().info("Recording to 'bags/hd01_delivery_log' (mcap), 19 topics requested")
        self.create_timer(2.0, self._discover)
        threading.Thread(target=self._writer, daemon=True).start()

    def close(self) -> None:
        self.closing.set()

    def _discover(self) -> None:
        present = {name for name, _ in self.get_topic_names_and_types()}
        for topic, (mtype, qos) in RECORDED.items():
            if topic in present and topic not in self.subs:
                self.subs[topic] = self.create_subscription(
                    mtype, topic, lambda m, t=topic: self.buffer.append((t, time.time(), m)), qos, raw=True
                )
                self.get_logger().info(f"Subscribed to topic '{topic}'")

    def _writer(self) -> None:
        start = time.monotonic()
        while not self.closing.wait(0.1):
            while self.buffer:
                _, _, data = self.buffer.popleft()
                self.bytes += len(data)
            if time.monotonic() - start >= 60.0 * (self.n_file + 1):
                self.n_file += 1
                self.get_logger().info(
                    f"Writing to a new bag file: bags/hd01_delivery_log/"
                    f"hd01_delivery_log_{self.n_file}.mcap ({self.bytes / 1e6:.1f} MB so far)"
                )


# ----------------------------------------------------------------------------------------------
# tablet (the operator): the ward's nurse-station tablet app


class WardTablet(Node):
    """The nurse station's tablet app: watches the robot (camera stream, mission, battery,
    diagnostics) and sets the touchscreen's announcement volume when it connects."""

    def __init__(self) -> None:
        super().__init__("ward_tablet", namespace=NS)
        self.fault = ""
        self.frames = 0
        self.create_subscription(
            CompressedImage, "/hd/depth_camera/color/image_raw/compressed", self._frame, SENSOR
        )
        self.create_subscription(String, "/hd/mission_executor/status", self._status, LATCHED)
        self.create_subscription(BatteryState, "/hd/battery_state", lambda m: None, RELIABLE)
        self.create_subscription(DiagnosticArray, "/diagnostics_agg", lambda m: None, RELIABLE)
        self.params = self.create_client(SetParameters, "/hd/hmi/touchscreen/set_parameters")
        self.volume_set = False
        self.started = time.monotonic()
        self.create_timer(1.0, self._tick)
        self.get_logger().info("Nurse station tablet connected (ward 4B)")

    def _frame(self, msg: CompressedImage) -> None:
        self.frames += 1

    def _status(self, msg: String) -> None:
        st = json.loads(msg.data)
        if st.get("state") == "FAILED":
            self.get_logger().warn(f"Robot reports a failed delivery ({st.get('order_id')})")

    def _tick(self) -> None:
        if not self.volume_set and time.monotonic() - self.started > 3.0 and self.params.service_is_ready():
            self.volume_set = True
            v = random.choice((40, 50, 70))
            self.params.call_async(
                SetParameters.Request(
                    parameters=[
                        Parameter(
                            name="announce_volume",
                            value=ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=v),
                        )
                    ]
                )
            )
            self.get_logger().info(
                f"Announcement volume set to {v} (night mode)"
                if v < 60
                else f"Announcement volume set to {v}"
            )


# ----------------------------------------------------------------------------------------------
# processes


def _single(*nodes: Node) -> tuple[list[Node], Executor]:
    return list(nodes), SingleThreadedExecutor()


PROCESSES: dict[str, Callable[[], tuple[list[Node], Executor]]] = {
    "nav_container": lambda: (
        [
            MapServer(),
            Amcl(),
            PlannerServer(),
            ControllerServer(),
            BehaviorServer(),
            BtNavigator(),
            LifecycleManager(),
        ],
        MultiThreadedExecutor(num_threads=8),
    ),
    "sensor_container": lambda: _single(FrontLidar(), DepthCamera(), ImuDriver()),
    "base": lambda: _single(BaseController(), BatteryMonitor(), MotorDriver()),
    "robot_state_publisher": lambda: _single(RobotStatePublisher()),
    "safety": lambda: _single(SafetyMonitor(), CmdVelMux()),
    "teleop": lambda: _single(RemoteTeleop()),
    "mission": lambda: _single(MissionExecutor()),
    "drawers": lambda: _single(DrawerController()),
    "hmi": lambda: _single(Touchscreen()),
    "building_gateway": lambda: ([BuildingGateway()], MultiThreadedExecutor(num_threads=4)),
    "fleet_server": lambda: _single(FleetServer()),
    "diagnostics": lambda: _single(DiagnosticAggregator()),
    "recorder": lambda: _single(Recorder()),
    "tablet": lambda: _single(WardTablet()),
}


def _burn() -> None:
    x = 0
    while True:
        x = (x * 31 + 7) % 1000003


def _leak() -> None:
    hoard = []
    while True:
        hoard.append(b"\x5a" * 300_000)
        time.sleep(0.1)


def _watch_faults(fault_dir: Path, process: str, nodes: list[Node]) -> None:
    """Every 0.5 s: the node fault files and the process's cpu/leak files."""
    by_file = {n.get_fully_qualified_name().strip("/").replace("/", "."): n for n in nodes}
    started: set[str] = set()
    while True:
        for fname, node in by_file.items():
            p = fault_dir / fname
            try:
                word = p.read_text().strip() if p.exists() else ""
            except OSError:
                word = ""
            if word and word != getattr(node, "_fault_seen", ""):
                node._fault_seen = word  # type: ignore[attr-defined]
                node.fault = word  # type: ignore[attr-defined]
        for how, fn in (("cpu", _burn), ("leak", _leak)):
            if how not in started and (fault_dir / f"{process}.{how}").exists():
                started.add(how)
                threading.Thread(target=fn, daemon=True).start()
        time.sleep(0.5)


def main(argv: list[str]) -> int:
    if len(argv) < 3 or argv[1] not in PROCESSES:
        print(
            f"usage: python -m bench.hospital.robot {{{','.join(PROCESSES)}}} FAULT_DIR [RUN_FOR]",
            file=sys.stderr,
        )
        return 2
    process, fault_dir = argv[1], Path(argv[2])
    run_for = float(argv[3]) if len(argv) > 3 else 0.0
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    nodes, executor = PROCESSES[process]()
    for node in nodes:
        executor.add_node(node)
    threading.Thread(target=_watch_faults, args=(fault_dir, process, nodes), daemon=True).start()

    def spin() -> None:
        try:
            executor.spin()
        except Exception as e:  # an external shutdown while ending
            if not stop.is_set():
                print(f"executor ended: {e!r}", file=sys.stderr)
                stop.set()

    threading.Thread(target=spin, daemon=True).start()
    deadline = time.monotonic() + run_for if run_for > 0 else None
    while not stop.wait(0.2):
        if deadline is not None and time.monotonic() >= deadline:
            break
    for node in nodes:
        close = getattr(node, "close", None)
        if close is not None:
            close()
    ended = False
    try:
        ended = executor.shutdown(timeout_sec=1.0)
    except Exception:
        pass
    if ended:
        for node in nodes:
            try:
                node.destroy_node()
            except Exception:
                pass
    rclpy.try_shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)


if __name__ == "__main__":
    sys.exit(main(sys.argv))
