"""A tractor spraying a field, plain rclpy: ``python -m bench.field.robot PROCESS FAULT_DIR [RUN_FOR]``.

Written as an agricultural robot's software is: a ros2_control-style controller manager (one
process, a multi-threaded executor) holding a joint state broadcaster (100 Hz), a drive
controller (odometry and the odom->base_link transform at 50 Hz), a sprayer boom controller (50
Hz) and a three-point-hitch controller (20 Hz), each switched on by a short-lived spawner
process at bring-up that sets the controller's type on the manager and calls its
``load_controller`` service; a robot_state_publisher (the URDF latched on
``/field/robot_description``, the static transforms latched on ``/tf_static``, the boom and
hitch transforms at <= 20 Hz from the joint states); a 500 Hz IMU and an RTK GNSS receiver (10
Hz, RTK float: a supervisor warns about it every 15 s) read on one single-threaded executor (the
IMU's samples from a reader thread, in 4 ms USB packets of two); an EKF that queues its inputs
in their subscriptions and takes them all at each 30 Hz update; a 1 MiB point cloud at 10 Hz
(best effort, keep last 1) read by a crop-row detector that needs 150 ms a cloud (it gets about
one cloud in two); a perception container (isolated: a single-threaded executor per node, each
in its own thread) with a camera (15 fps, a parameter that the mission planner lowers to 5 fps
for 30 s in each headland turn), a lazy image republisher that subscribes to the camera only
while its compressed output has subscribers, a weed detector publishing one detection message
per image; a sprayer that commands its nozzles on each detection message, the boom and the
hitch, fetches its prescription map from a farm bridge service every 15 s (an ERROR naming the
service when it does not answer in 5 s) and reports a tank level that goes WARN for 20 s every 3
minutes (refilled at the headland); the farm bridge relays the farm's weather station every 20
s; a row navigator serving a ``navigate_row`` action (test_msgs/Fibonacci stands in: the goal's
order is the row's length in seconds, the feedback ``[row, percent]`` at 5 Hz, an async execute
callback on a single-threaded executor) that a mission planner sends every ~35 s; a twist mux
between the navigator, the operator console and its e-stop lock; a telemetry uplink whose remote
viewer watches the compressed camera stream 40 s on, 40 s off; an operator console that an
operator opens and closes. Three nodes publish ``/diagnostics`` (diagnostic_updater names
``"<node>: <task>"``). tf2_msgs is not in the environment: ``/tf`` and ``/tf_static`` carry
geometry_msgs/TransformStamped, one transform a message.

Besides the robot's processes this module runs two kinds of short-lived ones: ``spawner:NAME``
(a controller spawner, node ``/field/spawner_NAME``, exits 0 once NAME is active) and
``cli:VERB:TOPIC`` (a developer's ``ros2 topic echo|hz TOPIC``: node ``/_ros2cli_<pid>``, no
parameter services, subscribes for 10 s and exits 0).

Faults come from files: ``FAULT_DIR/<namespace>.<node>`` (``field.imu_driver``) holding
``hang`` (the node blocks for good in a callback, and with it its single-threaded executor),
``degrade`` (the boom controller skips every other update), ``lag`` (the twist mux holds each
command 300 ms), ``stall`` (the farm bridge's prescription service never answers), ``stuck``
(the row navigator stops its feedback and never finishes the goal), ``stale`` (the camera's
stamps 1 s old), ``reliable`` (the row detector re-creates its point-cloud subscription as
RELIABLE on the best-effort topic) or ``errlog`` (an ERROR a second, work goes on); checked
every 0.5 s. ``FAULT_DIR/<process>.cpu`` starts a thread burning a core in that process,
``<process>.leak`` one leaking 3 MB/s. Crashes are SIGKILLs from outside. A third argument,
RUN_FOR, ends the process cleanly after that many seconds (the console).
"""

from __future__ import annotations

import math
import os
import random
import sys
import threading
import time
from array import array
from collections import deque
from pathlib import Path

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from diagnostic_msgs.srv import AddDiagnostics  # stands in for controller_manager_msgs/LoadController
from geometry_msgs.msg import Pose, PoseArray, TransformStamped, TwistStamped
from nav_msgs.msg import OccupancyGrid, Odometry
from nav_msgs.srv import GetMap
from rcl_interfaces.msg import SetParametersResult
from rclpy.action import ActionClient, ActionServer, CancelResponse
from rclpy.callback_groups import CallbackGroup, MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.duration import Duration
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from rclpy.task import Future
from sensor_msgs.msg import (
    CameraInfo,
    CompressedImage,
    Image,
    Imu,
    JointState,
    NavSatFix,
    NavSatStatus,
    PointCloud2,
    PointField,
    RelativeHumidity,
    Temperature,
)
from std_msgs.msg import Bool, Float32MultiArray, Float64MultiArray, String
from std_srvs.srv import Trigger
from test_msgs.action import Fibonacci  # stands in for a navigate-row action

from stream_viz.demo.child import burn, leak

LEAK_MB_S = 3.0  # a cache never trimmed
NS = "/field"
OK, WARN = DiagnosticStatus.OK, DiagnosticStatus.WARN
LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
STATIC_TF = QoSProfile(depth=16, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL)
LAST_ONE = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST, reliability=ReliabilityPolicy.BEST_EFFORT)
CONTROLLER_TYPES = {
    "joint_state_broadcaster": "joint_state_broadcaster/JointStateBroadcaster",
    "drive_controller": "tricycle_controller/TricycleController",
    "boom_controller": "joint_trajectory_controller/JointTrajectoryController",
    "hitch_controller": "position_controllers/JointGroupPositionController",
}
JOINTS = ["rear_left_wheel", "rear_right_wheel", "front_steering", "boom_lift", "boom_fold_left",
          "boom_fold_right", "hitch_lift"]
URDF = """<?xml version="1.0"?>
<robot name="field_tractor">
  <link name="base_link"/><link name="imu_link"/><link name="gnss_link"/><link name="lidar_link"/>
  <link name="camera_link"/><link name="hitch_link"/><link name="boom_link"/>
  <joint name="imu_joint" type="fixed"><parent link="base_link"/><child link="imu_link"/></joint>
  <joint name="gnss_joint" type="fixed"><parent link="base_link"/><child link="gnss_link"/></joint>
  <joint name="lidar_joint" type="fixed"><parent link="base_link"/><child link="lidar_link"/></joint>
  <joint name="camera_joint" type="fixed"><parent link="base_link"/><child link="camera_link"/></joint>
  <joint name="hitch_lift" type="prismatic"><parent link="base_link"/><child link="hitch_link"/></joint>
  <joint name="boom_lift" type="prismatic"><parent link="hitch_link"/><child link="boom_link"/></joint>
</robot>
"""
STATIC = {"imu_link": (0.3, 0.0, 0.9), "gnss_link": (0.1, 0.0, 2.8), "lidar_link": (2.1, 0.0, 1.9),
          "camera_link": (2.3, 0.0, 2.2)}


# --- fault hooks --------------------------------------------------------------------------------


class FieldNode(Node):
    """A node of the tractor with the bench's fault hooks: the fault file
    ``FAULT_DIR/<namespace>.<name>``, read by the process's watcher thread, sets ``fault`` and
    triggers a guard condition whose callback (`on_fault`) runs in the node's executor; ``gate()``
    at the top of a callback blocks for good under ``hang`` (as a driver stuck in a device read)."""

    def __init__(self, name: str, fault_dir: Path, **kw) -> None:
        super().__init__(name, namespace=NS, **kw)
        self.fault_file = fault_dir / f"{NS.strip('/')}.{name}"
        self.fault: str | None = None
        self.rng = random.Random(name)
        self._errlog_timer = None
        self.fault_set = self.create_guard_condition(self._fault_changed,
                                                     callback_group=MutuallyExclusiveCallbackGroup())

    def _fault_changed(self) -> None:
        if self.fault == "errlog" and self._errlog_timer is None:
            self._errlog_timer = self.create_timer(1.0, self.on_errlog)
        self.on_fault(self.fault)
        self.gate()

    def on_fault(self, fault: str | None) -> None:
        pass

    def on_errlog(self) -> None:
        self.get_logger().error("device read failed")

    def gate(self) -> None:
        if self.fault == "hang":
            threading.Event().wait()

    def stamp(self):
        return self.get_clock().now().to_msg()

    def status(self, task: str, hardware_id: str, level: bytes = OK, message: str = "OK",
               **values: str) -> DiagnosticStatus:
        return DiagnosticStatus(level=level, name=f"{self.get_name()}: {task}", hardware_id=hardware_id,
                                message=message, values=[KeyValue(key=k, value=v) for k, v in values.items()])


def watch(nodes: list[FieldNode], fault_dir: Path, process: str) -> None:
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


# --- the controller manager (one process, multi-threaded) --------------------------------------


class Hardware:
    """The tractor's hardware interface, shared by the controllers of the manager's process."""

    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.position = dict.fromkeys(JOINTS, 0.0)
        self.velocity = dict.fromkeys(JOINTS, 0.0)
        self.position["boom_lift"], self.position["hitch_lift"] = 0.6, 0.35


class ControllerManager(FieldNode):
    def __init__(self, fault_dir: Path) -> None:
        super().__init__("controller_manager", fault_dir, allow_undeclared_parameters=True)
        self.declare_parameter("update_rate", 100)
        self.hw = Hardware()
        self.active: set[str] = set()
        self.loaded: dict[str, str] = {}
        self.create_service(AddDiagnostics, "~/load_controller", self.load)
        self.create_service(Trigger, "~/list_controllers", self.list_controllers)
        self.diag = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.create_timer(1.0, self.diagnostics)
        self.controllers: list[Controller] = []
        self.overruns = 0

    def realtime_loop(self) -> None:
        """ros2_control_node's loop: read, every active controller's update, write at update_rate,
        in its own thread beside the executor."""
        period = 1.0 / self.get_parameter("update_rate").value
        cycle, deadline = 0, time.monotonic()
        while rclpy.ok():
            deadline += period
            try:
                for c in self.controllers:
                    if c.running:
                        c.update(cycle)
            except Exception:
                if rclpy.ok():  # not a publish cut short by Ctrl-C
                    raise
                return
            cycle += 1
            delay = deadline - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            elif delay < -0.1:  # far behind (a stalled computer): start again from now
                self.overruns += 1
                deadline = time.monotonic()

    def load(self, req: AddDiagnostics.Request, res: AddDiagnostics.Response) -> AddDiagnostics.Response:
        self.gate()
        name = req.load_namespace
        kind = self.get_parameter_or(f"{name}.type", Parameter(f"{name}.type", value="")).value
        if name not in CONTROLLER_TYPES or not kind:
            res.success, res.message = False, f"controller '{name}' has no type parameter"
            self.get_logger().error(f"Loading controller '{name}' failed: no type")
            return res
        self.loaded[name] = kind
        self.get_logger().info(f"Loading controller '{name}'")
        self.get_logger().info(f"Configuring controller: '{name}'")
        self.active.add(name)
        self.get_logger().info(f"Activating controllers: [ {name} ]")
        res.success, res.message = True, "active"
        return res

    def list_controllers(self, req: Trigger.Request, res: Trigger.Response) -> Trigger.Response:
        res.success = True
        res.message = ", ".join(f"{n}[{t}] {'active' if n in self.active else 'inactive'}"
                                for n, t in sorted(self.loaded.items()))
        return res

    def diagnostics(self) -> None:
        self.gate()
        msg = DiagnosticArray()
        msg.header.stamp = self.stamp()
        msg.status = [
            self.status("Controllers Activity", "", message=f"{len(self.active)} active",
                        **{n: "active" for n in sorted(self.active)}),
            self.status("Hardware Components Activity", "tractor_ecu", message="tractor_ecu active",
                        can_bus_load="23 %"),
        ]
        self.diag.publish(msg)


class Controller(FieldNode):
    """A controller of the manager: updates only once a spawner has activated it."""

    every = 1  # publishes every n-th cycle of the manager's loop

    def __init__(self, name: str, manager: ControllerManager, fault_dir: Path) -> None:
        super().__init__(name, fault_dir)
        self.manager, self.hw = manager, manager.hw
        manager.controllers.append(self)

    def update(self, cycle: int) -> None:
        raise NotImplementedError

    @property
    def running(self) -> bool:
        return self.get_name() in self.manager.active


class JointStateBroadcaster(Controller):
    def __init__(self, manager: ControllerManager, fault_dir: Path) -> None:
        super().__init__("joint_state_broadcaster", manager, fault_dir)
        self.pub = self.create_publisher(JointState, "joint_states", 10)

    def update(self, cycle: int) -> None:
        with self.hw.lock:
            msg = JointState(name=JOINTS, position=[self.hw.position[j] for j in JOINTS],
                             velocity=[self.hw.velocity[j] for j in JOINTS])
        msg.header.stamp = self.stamp()
        self.pub.publish(msg)


class DriveController(Controller):
    """A tricycle-steered tractor: ``~/cmd_vel`` in, ``~/odom`` and odom->base_link out at 50 Hz."""

    def __init__(self, manager: ControllerManager, fault_dir: Path) -> None:
        super().__init__("drive_controller", manager, fault_dir)
        self.create_subscription(TwistStamped, "~/cmd_vel", self.on_cmd, 10)
        self.odom_pub = self.create_publisher(Odometry, "~/odom", 10)
        self.tf_pub = self.create_publisher(TransformStamped, "/tf", 100)
        self.cmd, self.cmd_t = (0.0, 0.0), 0.0
        self.x = self.y = self.yaw = 0.0

    def on_cmd(self, msg: TwistStamped) -> None:
        self.gate()
        self.cmd, self.cmd_t = (msg.twist.linear.x, msg.twist.angular.z), time.monotonic()

    def update(self, cycle: int) -> None:
        if cycle % 2:  # odometry at 50 Hz (publish_rate)
            return
        v, w = self.cmd if time.monotonic() - self.cmd_t < 0.5 else (0.0, 0.0)  # cmd_vel_timeout
        dt = 0.02
        self.yaw += w * dt
        self.x += v * math.cos(self.yaw) * dt
        self.y += v * math.sin(self.yaw) * dt
        with self.hw.lock:
            for j in ("rear_left_wheel", "rear_right_wheel"):
                self.hw.velocity[j] = v / 0.8
                self.hw.position[j] += v / 0.8 * dt
            self.hw.position["front_steering"] = math.atan2(w * 2.9, v) if abs(v) > 0.05 else 0.0
        now = self.stamp()
        odom = Odometry()
        odom.header.stamp, odom.header.frame_id, odom.child_frame_id = now, "odom", "base_link"
        odom.pose.pose.position.x, odom.pose.pose.position.y = self.x, self.y
        q = odom.pose.pose.orientation
        q.z, q.w = math.sin(self.yaw / 2), math.cos(self.yaw / 2)
        odom.twist.twist.linear.x, odom.twist.twist.angular.z = v, w
        self.odom_pub.publish(odom)
        tf = TransformStamped()
        tf.header.stamp, tf.header.frame_id, tf.child_frame_id = now, "odom", "base_link"
        tf.transform.translation.x, tf.transform.translation.y = self.x, self.y
        tf.transform.rotation = odom.pose.pose.orientation
        self.tf_pub.publish(tf)


class BoomController(Controller):
    """The sprayer boom: height and the two folds follow ``~/commands`` at 50 Hz."""

    def __init__(self, manager: ControllerManager, fault_dir: Path) -> None:
        super().__init__("boom_controller", manager, fault_dir)
        self.create_subscription(Float64MultiArray, "~/commands", self.on_cmd, 10)
        self.pub = self.create_publisher(JointState, "~/controller_state", 10)
        self.target = [0.6, 1.57, 1.57]

    def on_cmd(self, msg: Float64MultiArray) -> None:
        self.gate()
        if len(msg.data) == 3:
            self.target = list(msg.data)

    def update(self, cycle: int) -> None:
        if cycle % (4 if self.fault == "degrade" else 2):  # 50 Hz; its CAN frames overrun: 25 Hz
            return
        names = ["boom_lift", "boom_fold_left", "boom_fold_right"]
        with self.hw.lock:
            for j, t in zip(names, self.target, strict=True):
                step = max(-0.01, min(0.01, t - self.hw.position[j]))
                self.hw.position[j] += step
                self.hw.velocity[j] = step / 0.02
            msg = JointState(name=names, position=[self.hw.position[j] for j in names],
                             velocity=[self.hw.velocity[j] for j in names], effort=[0.0, 0.0, 0.0])
        msg.header.stamp = self.stamp()
        self.pub.publish(msg)


class HitchController(Controller):
    """The three-point hitch's lift, a position controller at 20 Hz."""

    def __init__(self, manager: ControllerManager, fault_dir: Path) -> None:
        super().__init__("hitch_controller", manager, fault_dir)
        self.create_subscription(Float64MultiArray, "~/commands", self.on_cmd, 10)
        self.pub = self.create_publisher(JointState, "~/controller_state", 10)
        self.target = 0.35

    def on_cmd(self, msg: Float64MultiArray) -> None:
        self.gate()
        if msg.data:
            self.target = msg.data[0]

    def update(self, cycle: int) -> None:
        if cycle % 5:  # 20 Hz
            return
        with self.hw.lock:
            p = self.hw.position["hitch_lift"]
            self.hw.position["hitch_lift"] = p + max(-0.005, min(0.005, self.target - p))
            msg = JointState(name=["hitch_lift"], position=[self.hw.position["hitch_lift"]])
        msg.header.stamp = self.stamp()
        self.pub.publish(msg)


def spawner(controller: str) -> int:
    """``ros2 run controller_manager spawner NAME``: the type parameter, load, exit."""
    node = rclpy.create_node(f"spawner_{controller}", namespace=NS)
    log = node.get_logger()
    try:
        cli = node.create_client(AddDiagnostics, "/field/controller_manager/load_controller")
        if not cli.wait_for_service(timeout_sec=10.0):
            log.error("Controller manager not available")
            return 1
        params = AsyncParameterClient(node, "/field/controller_manager")
        params.wait_for_services(timeout_sec=5.0)
        fut = params.set_parameters([Parameter(f"{controller}.type", value=CONTROLLER_TYPES[controller])])
        rclpy.spin_until_future_complete(node, fut, timeout_sec=5.0)
        if not fut.done():
            log.error(f"Setting the type of {controller} timed out")
            return 1
        fut = cli.call_async(AddDiagnostics.Request(load_namespace=controller))
        rclpy.spin_until_future_complete(node, fut, timeout_sec=10.0)
        if not fut.done() or not fut.result().success:
            log.error(f"Failed loading controller {controller}")
            return 1
        log.info(f"Configured and activated {controller}")
        return 0
    finally:
        node.destroy_node()


# --- the robot state publisher ---------------------------------------------------------------------


class RobotStatePublisher(FieldNode):
    def __init__(self, fault_dir: Path) -> None:
        super().__init__("robot_state_publisher", fault_dir)
        self.declare_parameter("robot_description", URDF)
        self.declare_parameter("publish_frequency", 20.0)
        self.create_publisher(String, "robot_description", LATCHED).publish(String(data=URDF))
        static = self.create_publisher(TransformStamped, "/tf_static", STATIC_TF)
        now = self.stamp()
        for child, (x, y, z) in STATIC.items():
            tf = TransformStamped()
            tf.header.stamp, tf.header.frame_id, tf.child_frame_id = now, "base_link", child
            tf.transform.translation.x, tf.transform.translation.y, tf.transform.translation.z = x, y, z
            tf.transform.rotation.w = 1.0
            static.publish(tf)
        self.tf_pub = self.create_publisher(TransformStamped, "/tf", 100)
        self.create_subscription(JointState, "joint_states", self.on_joints, 10)
        self.last = 0.0
        self.get_logger().info(f"got segment {', '.join(['base_link', *STATIC, 'hitch_link', 'boom_link'])}")

    def on_joints(self, msg: JointState) -> None:
        self.gate()
        now = time.monotonic()
        if now - self.last < 1.0 / self.get_parameter("publish_frequency").value:
            return
        self.last = now
        pos = dict(zip(msg.name, msg.position, strict=False))
        for parent, child, joint in (("base_link", "hitch_link", "hitch_lift"),
                                     ("hitch_link", "boom_link", "boom_lift")):
            tf = TransformStamped()
            tf.header.stamp, tf.header.frame_id, tf.child_frame_id = msg.header.stamp, parent, child
            tf.transform.translation.x = -1.2 if child == "hitch_link" else -0.4
            tf.transform.translation.z = pos.get(joint, 0.0)
            tf.transform.rotation.w = 1.0
            self.tf_pub.publish(tf)


# --- sensors ----------------------------------------------------------------------------------------


class ImuDriver(FieldNode):
    """A 500 Hz IMU on USB."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("imu_driver", fault_dir)
        self.pub = self.create_publisher(Imu, "imu/data_raw", qos_profile_sensor_data)
        self.msg = Imu()
        self.msg.header.frame_id = "imu_link"
        self.msg.orientation_covariance[0] = -1.0  # no orientation estimate
        self.n = 0
        self.port = threading.Lock()  # the serial port, shared by the reader and the status poll
        self.create_timer(1.0, self.poll_status)
        threading.Thread(target=self.reader, daemon=True, name="imu_reader").start()

    def poll_status(self) -> None:
        """The device's status register, over the same port as the samples."""
        self.gate()
        with self.port:
            pass

    def reader(self) -> None:
        """The reader: a USB packet every 4 ms with two samples (500 Hz), each stamped at its sample."""
        deadline = time.monotonic()
        while rclpy.ok():
            deadline += 0.004
            delay = deadline - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            elif delay < -0.1:
                deadline = time.monotonic()
            self.gate()
            with self.port:
                now = self.get_clock().now()
                try:
                    self.read(now - Duration(nanoseconds=2_000_000))
                    self.read(now)
                except Exception:
                    if rclpy.ok():  # not a publish cut short by Ctrl-C
                        raise
                    return

    def read(self, at) -> None:
        self.n += 1
        m = self.msg
        m.header.stamp = at.to_msg()
        m.angular_velocity.z = 0.01 * math.sin(self.n * 0.001)
        m.linear_acceleration.x = 0.05 * math.sin(self.n * 0.013)
        m.linear_acceleration.z = 9.81 + 0.02 * math.sin(self.n * 0.7)
        self.pub.publish(m)


class GnssDriver(FieldNode):
    """An RTK GNSS receiver at 10 Hz, in RTK float on this field (a weak correction link)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("gnss_driver", fault_dir)
        self.pub = self.create_publisher(NavSatFix, "gnss/fix", 10)
        self.n = 0
        self.create_timer(0.1, self.read)

    def read(self) -> None:
        self.gate()
        self.n += 1
        msg = NavSatFix()
        msg.header.stamp, msg.header.frame_id = self.stamp(), "gnss_link"
        msg.status.status, msg.status.service = NavSatStatus.STATUS_SBAS_FIX, NavSatStatus.SERVICE_GPS
        msg.latitude = 52.2297 + 1e-6 * self.n
        msg.longitude = 4.8352 + 1e-7 * math.sin(self.n / 50)
        msg.altitude = 3.1
        msg.position_covariance = [0.0625, 0.0, 0.0, 0.0, 0.0625, 0.0, 0.0, 0.0, 0.25]
        msg.position_covariance_type = NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN
        self.pub.publish(msg)

    def on_errlog(self) -> None:
        self.get_logger().error("RTCM3 frame 1077: CRC mismatch, correction dropped")


class LidarDriver(FieldNode):
    """A 64-beam lidar: 1 MiB clouds (65536 points x,y,z,intensity) at 10 Hz, best effort, keep last 1."""

    POINTS = 65536

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("lidar_driver", fault_dir)
        self.pub = self.create_publisher(PointCloud2, "lidar/points", LAST_ONE)
        self.frames = [array("B", os.urandom(self.POINTS * 16)) for _ in range(3)]
        self.fields = [PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1)
                       for i, n in enumerate(("x", "y", "z", "intensity"))]
        self.n = 0
        self.create_timer(0.1, self.scan)

    def scan(self) -> None:
        self.gate()
        self.n += 1
        msg = PointCloud2(height=1, width=self.POINTS, fields=self.fields, is_bigendian=False,
                          point_step=16, row_step=16 * self.POINTS, is_dense=True)
        msg.header.stamp, msg.header.frame_id = self.stamp(), "lidar_link"
        msg.data = self.frames[self.n % 3]
        self.pub.publish(msg)


# --- perception (one container, multi-threaded) -------------------------------------------------


class CameraDriver(FieldNode):
    """The boom camera: 640x480 rgb8 at ``fps`` (a parameter, 15)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("camera_driver", fault_dir)
        self.declare_parameter("fps", 15.0)
        self.declare_parameter("frame_id", "camera_link")
        self.pub = self.create_publisher(Image, "camera/image_raw", 2)
        self.info_pub = self.create_publisher(CameraInfo, "camera/camera_info", 2)
        self.frames = [array("B", os.urandom(640 * 480 * 3)) for _ in range(2)]
        self.n = 0
        self.timer = self.create_timer(1.0 / 15.0, self.grab)
        self.add_on_set_parameters_callback(self.on_params)

    def on_params(self, params: list[Parameter]) -> SetParametersResult:
        for p in params:
            if p.name == "fps":
                if not 0.5 <= float(p.value) <= 30.0:
                    return SetParametersResult(successful=False, reason="fps out of range [0.5, 30]")
                self.timer.timer_period_ns = int(1e9 / float(p.value))
                self.timer.reset()
                self.get_logger().info(f"frame rate set to {float(p.value):g} fps")
        return SetParametersResult(successful=True)

    def grab(self) -> None:
        self.gate()
        self.n += 1
        now = self.get_clock().now()
        if self.fault == "stale":  # the driver's frame queue backs up: frames delivered 1 s late
            now = now - Duration(seconds=1.0)
        img = Image(height=480, width=640, encoding="rgb8", is_bigendian=0, step=640 * 3)
        img.header.stamp, img.header.frame_id = now.to_msg(), "camera_link"
        img.data = self.frames[self.n % 2]
        self.pub.publish(img)
        info = CameraInfo(height=480, width=640, distortion_model="plumb_bob")
        info.header = img.header
        info.k = [525.0, 0.0, 320.0, 0.0, 525.0, 240.0, 0.0, 0.0, 1.0]
        self.info_pub.publish(info)


class ImageRepublisher(FieldNode):
    """image_transport's republisher, lazy: subscribes to the raw images only while its
    compressed output has a subscriber."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("image_republisher", fault_dir)
        self.pub = self.create_publisher(CompressedImage, "camera/image_raw/compressed", 2)
        self.sub = None
        self.create_timer(1.0, self.check_subscribers)

    def check_subscribers(self) -> None:
        self.gate()
        wanted = self.pub.get_subscription_count() > 0
        if wanted and self.sub is None:
            self.sub = self.create_subscription(Image, "camera/image_raw", self.on_image, 1)
            self.get_logger().debug("subscribed to camera/image_raw")
        elif not wanted and self.sub is not None:
            self.destroy_subscription(self.sub)
            self.sub = None
            self.get_logger().debug("unsubscribed from camera/image_raw")

    def on_image(self, img: Image) -> None:
        self.gate()
        out = CompressedImage(format="rgb8; jpeg compressed bgr8")
        out.header = img.header
        out.data = img.data[: 38000 + (img.header.stamp.nanosec >> 20) % 4000]  # a JPEG's size
        self.pub.publish(out)


class WeedDetector(FieldNode):
    """One detection message per image (weeds as poses in the camera frame); 20 ms inference."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("weed_detector", fault_dir)
        self.create_subscription(Image, "camera/image_raw", self.on_image, 2)
        self.pub = self.create_publisher(PoseArray, "weed_detector/detections", 10)

    def on_image(self, img: Image) -> None:
        self.gate()
        time.sleep(0.02)  # the accelerator's inference
        out = PoseArray()
        out.header = img.header
        for _ in range(self.rng.randint(0, 4)):
            p = Pose()
            p.position.x, p.position.y = self.rng.uniform(0.5, 2.0), self.rng.uniform(-6.0, 6.0)
            p.orientation.w = 1.0
            out.poses.append(p)
        self.pub.publish(out)


class RowDetector(FieldNode):
    """Crop rows from the lidar, 150 ms a cloud: with keep-last-1 it takes the newest cloud and
    drops the others (about one in two)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("row_detector", fault_dir)
        self.declare_parameter("input_reliability", "best_effort")
        self.pub = self.create_publisher(PoseArray, "row_detector/rows", 10)
        self.sub = self.create_subscription(PointCloud2, "lidar/points", self.on_cloud, LAST_ONE)

    def on_fault(self, fault: str | None) -> None:
        if fault == "reliable":  # a configuration change: the input re-created as RELIABLE
            self.get_logger().info("input_reliability changed to 'reliable': re-creating the lidar/points "
                                   "subscription")
            self.destroy_subscription(self.sub)
            qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE)
            self.sub = self.create_subscription(PointCloud2, "lidar/points", self.on_cloud, qos)

    def on_cloud(self, cloud: PointCloud2) -> None:
        self.gate()
        time.sleep(0.15)  # RANSAC over the ground-removed cloud
        out = PoseArray()
        out.header = cloud.header
        for k in range(4):
            p = Pose()
            p.position.x, p.position.y = 5.0, -1.125 + 0.75 * k + self.rng.gauss(0, 0.02)
            p.orientation.w = 1.0
            out.poses.append(p)
        self.pub.publish(out)


# --- localization -------------------------------------------------------------------------------------


class Drained(CallbackGroup):
    """A callback group the executor never runs: its subscriptions' queues are taken by hand
    (`drain`), as a filter does that buffers its measurements and fuses them at its own rate."""

    def can_execute(self, entity) -> bool:
        return False

    def beginning_execution(self, entity) -> bool:
        return False

    def ending_execution(self, entity) -> None:
        pass


def drain(sub, callback) -> None:
    """Every message waiting in ``sub``'s queue (a `Drained` subscription) to ``callback``."""
    while (taken := sub.handle.take_message(sub.msg_type, sub.raw)) is not None:
        callback(taken[0])


class EkfFilter(FieldNode):
    """robot_localization's ekf_node: the IMU, wheel odometry and GNSS fused, 30 Hz out; the
    measurements queue up in their subscriptions and each update takes them all."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("ekf_filter", fault_dir)
        self.declare_parameter("frequency", 30.0)
        qos = QoSProfile(depth=64, reliability=ReliabilityPolicy.BEST_EFFORT)
        queued = Drained()
        self.inputs = [(self.create_subscription(kind, topic, callback, q, callback_group=queued), callback)
                       for kind, topic, callback, q in ((Imu, "imu/data_raw", self.on_imu, qos),
                                                        (Odometry, "drive_controller/odom", self.on_odom, 10),
                                                        (NavSatFix, "gnss/fix", self.on_fix, 10))]
        self.pub = self.create_publisher(Odometry, "odometry/filtered", 10)
        self.yaw_rate = 0.0
        self.odom: Odometry | None = None
        self.create_timer(1.0 / 30.0, self.update)

    def on_imu(self, msg: Imu) -> None:
        self.yaw_rate = 0.98 * self.yaw_rate + 0.02 * msg.angular_velocity.z

    def on_odom(self, msg: Odometry) -> None:
        self.odom = msg

    def on_fix(self, msg: NavSatFix) -> None:
        pass

    def update(self) -> None:
        self.gate()
        for sub, callback in self.inputs:
            drain(sub, callback)
        if self.odom is None:
            return
        out = Odometry()
        out.header.stamp, out.header.frame_id, out.child_frame_id = self.stamp(), "odom", "base_link"
        out.pose.pose = self.odom.pose.pose
        out.twist.twist = self.odom.twist.twist
        out.twist.twist.angular.z = self.yaw_rate
        self.pub.publish(out)


# --- navigation -----------------------------------------------------------------------------------------


class RowNavigator(FieldNode):
    """Follows a crop row (the ``navigate_row`` action: order = the row's length in s), its
    path-tracking output on ``row_navigator/cmd_vel`` at 20 Hz (standing still between rows)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("row_navigator", fault_dir)
        self.pub = self.create_publisher(TwistStamped, "row_navigator/cmd_vel", 10)
        self.create_subscription(PoseArray, "row_detector/rows", self.on_rows, 10)
        self.odom_sub = self.create_subscription(Odometry, "odometry/filtered", self.on_odom, 10,
                                                 callback_group=Drained())  # read in the control loop
        self.offset = 0.0
        self.pose = None
        self.driving = False
        self.server = ActionServer(self, Fibonacci, "navigate_row", self.execute,
                                   cancel_callback=lambda _: CancelResponse.ACCEPT)
        self.create_timer(0.05, self.control)
        self.row = 0

    def on_rows(self, msg: PoseArray) -> None:
        self.gate()
        if msg.poses:
            self.offset = sum(p.position.y for p in msg.poses) / len(msg.poses)

    def on_odom(self, msg: Odometry) -> None:
        self.pose = msg.pose.pose

    def control(self) -> None:
        self.gate()
        drain(self.odom_sub, self.on_odom)
        cmd = TwistStamped()
        cmd.header.stamp, cmd.header.frame_id = self.stamp(), "base_link"
        if self.driving:
            cmd.twist.linear.x, cmd.twist.angular.z = 1.8, -0.2 * self.offset
        self.pub.publish(cmd)

    async def sleep(self, seconds: float) -> None:
        done = Future()
        timer = self.create_timer(seconds, lambda: done.done() or done.set_result(True))
        try:
            await done
        finally:
            self.destroy_timer(timer)

    async def execute(self, goal):
        self.row += 1
        length = float(goal.request.order)
        self.get_logger().info(f"row {self.row}: following for {length:.0f} s")
        self.driving = True
        t0 = time.monotonic()
        fb = Fibonacci.Feedback()
        try:
            while True:
                if goal.is_cancel_requested:
                    goal.canceled()
                    self.get_logger().info(f"row {self.row}: canceled")
                    return Fibonacci.Result(sequence=[self.row, -1])
                elapsed = time.monotonic() - t0
                if self.fault == "stuck" and elapsed > 3.0:  # waits for an end-of-row mark it never sees
                    await self.sleep(0.2)
                    continue
                if elapsed >= length:
                    break
                fb.sequence = [self.row, int(100 * elapsed / length)]
                goal.publish_feedback(fb)
                await self.sleep(0.2)
        finally:
            self.driving = False
        goal.succeed()
        self.get_logger().info(f"row {self.row}: done")
        return Fibonacci.Result(sequence=[self.row, int(1.8 * length)])


class TwistMux(FieldNode):
    """twist_mux (stamped): the operator's teleop over the navigator, the console's e-stop as a lock."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("twist_mux", fault_dir)
        self.pub = self.create_publisher(TwistStamped, "drive_controller/cmd_vel", 10)
        self.create_subscription(TwistStamped, "row_navigator/cmd_vel", lambda m: self.on_cmd(m, 10), 10)
        self.create_subscription(TwistStamped, "operator_console/cmd_vel", lambda m: self.on_cmd(m, 100), 10)
        self.create_subscription(Bool, "operator_console/e_stop", self.on_lock, 10)
        self.locked = False
        self.teleop_t = 0.0
        self.held: deque = deque()
        self.flush_timer = None

    def on_lock(self, msg: Bool) -> None:
        self.gate()
        if msg.data != self.locked:
            self.get_logger().warn("e-stop lock engaged" if msg.data else "e-stop lock released")
        self.locked = msg.data

    def on_cmd(self, msg: TwistStamped, priority: int) -> None:
        self.gate()
        now = time.monotonic()
        if priority == 100:
            self.teleop_t = now
        elif now - self.teleop_t < 0.5:  # the operator's teleop holds the input for 0.5 s
            return
        if self.locked:
            msg.twist.linear.x = msg.twist.angular.z = 0.0
        if self.fault == "lag":  # the output queue stalls behind a blocking write: 300 ms late
            self.held.append((now + 0.3, msg))
            return
        self.pub.publish(msg)

    def on_fault(self, fault: str | None) -> None:
        if fault == "lag" and self.flush_timer is None:
            self.flush_timer = self.create_timer(0.01, self.flush)

    def flush(self) -> None:
        now = time.monotonic()
        while self.held and self.held[0][0] <= now:
            self.pub.publish(self.held.popleft()[1])


# --- mission and the farm ---------------------------------------------------------------------------------


class MissionPlanner(FieldNode):
    """Sends a row every ~35 s (the first at 12 s) and lowers the camera to 5 fps for 30 s in the
    headland turn every 150 s (the first at 100 s), through the camera's parameter services."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("mission_planner", fault_dir)
        self.client = ActionClient(self, Fibonacci, "navigate_row")
        self.camera = AsyncParameterClient(self, "/field/camera_driver")
        self.t0 = time.monotonic()
        self.next_row, self.next_turn = 12.0, 100.0
        self.goal = None
        self.goal_t = 0.0
        self.row = 0
        self.feedback = 0
        self.create_timer(0.5, self.tick)

    def tick(self) -> None:
        self.gate()
        t = time.monotonic() - self.t0
        if self.goal is None and t >= self.next_row:
            self.next_row += self.rng.uniform(33.0, 37.0)
            self.send_row()
        if self.goal is not None and self.goal is not True and time.monotonic() - self.goal_t > 60.0:
            self.get_logger().error(f"navigate_row: row {self.row} has no result after 60 s, canceling")
            self.goal.cancel_goal_async()
            self.goal = None
        if t >= self.next_turn:
            self.next_turn += 150.0
            self.set_fps(5.0)
            self.restore = self.create_timer(30.0, self._restore_fps)

    def _restore_fps(self) -> None:
        self.destroy_timer(self.restore)
        self.set_fps(15.0)

    def set_fps(self, fps: float) -> None:
        if not self.camera.services_are_ready():
            self.get_logger().warn("camera_driver parameters not available")
            return
        self.get_logger().info(f"headland turn: camera to {fps:g} fps" if fps < 15
                               else "in the row: camera to 15 fps")
        self.camera.set_parameters([Parameter("fps", value=fps)])

    def send_row(self) -> None:
        if not self.client.server_is_ready():
            self.get_logger().warn("navigate_row server not ready, row postponed")
            return
        self.row += 1
        self.feedback = 0
        goal = Fibonacci.Goal(order=self.rng.randint(8, 20))
        self.goal, self.goal_t = True, time.monotonic()
        fut = self.client.send_goal_async(goal, feedback_callback=self.on_feedback)
        fut.add_done_callback(self.on_accepted)

    def on_feedback(self, fb) -> None:
        self.feedback += 1

    def on_accepted(self, fut: Future) -> None:
        handle = fut.result()
        if not handle.accepted:
            self.get_logger().error(f"navigate_row: row {self.row} rejected")
            self.goal = None
            return
        self.goal = handle
        handle.get_result_async().add_done_callback(self.on_result)

    def on_result(self, fut: Future) -> None:
        res = fut.result().result
        if self.goal is not None:
            self.get_logger().info(f"row {self.row} finished ({self.feedback} feedbacks, "
                                   f"{res.sequence[-1] if res.sequence else 0} m)")
        self.goal = None


class FarmBridge(FieldNode):
    """The farm management system's bridge: the prescription map as a service and the farm's
    weather station relayed every 20 s."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("farm_bridge", fault_dir)
        grid = OccupancyGrid()
        grid.header.frame_id = "map"
        grid.info.resolution, grid.info.width, grid.info.height = 2.0, 200, 200
        grid.data = array("b", bytes(self.rng.randrange(20, 80) for _ in range(200 * 200)))
        self.grid = grid
        self.never = Future()
        self.create_service(GetMap, "farm_bridge/get_prescription", self.prescription,
                            callback_group=ReentrantCallbackGroup())
        self.temp_pub = self.create_publisher(Temperature, "weather/temperature", 10)
        self.hum_pub = self.create_publisher(RelativeHumidity, "weather/humidity", 10)
        self.create_timer(20.0, self.weather)

    async def prescription(self, req: GetMap.Request, res: GetMap.Response) -> GetMap.Response:
        if self.fault == "stall":  # the farm server's HTTP request never completes
            await self.never
        self.grid.header.stamp = self.stamp()
        res.map = self.grid
        return res

    def weather(self) -> None:
        self.gate()
        t = Temperature(temperature=14.0 + self.rng.gauss(0, 0.3), variance=0.04)
        t.header.stamp, t.header.frame_id = self.stamp(), "weather_station"
        self.temp_pub.publish(t)
        h = RelativeHumidity(relative_humidity=0.71 + self.rng.gauss(0, 0.01), variance=0.0001)
        h.header = t.header
        self.hum_pub.publish(h)


class SprayerController(FieldNode):
    """The sprayer's ECU bridge: nozzles on each detection message, the boom height at 5 Hz, the
    hitch at 1 Hz, the prescription map every 15 s, diagnostics at 1 Hz."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("sprayer_controller", fault_dir)
        self.create_subscription(PoseArray, "weed_detector/detections", self.on_detections, 10)
        self.nozzles = self.create_publisher(Float32MultiArray, "sprayer/nozzle_commands", 10)
        self.boom = self.create_publisher(Float64MultiArray, "boom_controller/commands", 10)
        self.hitch = self.create_publisher(Float64MultiArray, "hitch_controller/commands", 10)
        self.diag = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.prescription = self.create_client(GetMap, "farm_bridge/get_prescription")
        self.pending: tuple[Future, float] | None = None
        self.t0 = time.monotonic()
        self.create_timer(0.2, self.boom_height)
        self.create_timer(1.0, self.hitch_and_diagnostics)
        self.create_timer(15.0, self.fetch_prescription)

    def on_detections(self, msg: PoseArray) -> None:
        self.gate()
        duty = [0.0] * 24
        for p in msg.poses:
            duty[max(0, min(23, int((p.position.y + 6.0) / 0.5)))] = 1.0
        self.nozzles.publish(Float32MultiArray(data=duty))

    def boom_height(self) -> None:
        self.gate()
        t = time.monotonic() - self.t0
        self.boom.publish(Float64MultiArray(data=[0.6 + 0.05 * math.sin(t / 3), 1.57, 1.57]))

    def fetch_prescription(self) -> None:
        self.gate()
        if self.pending is not None:
            return
        if not self.prescription.service_is_ready():
            self.get_logger().warn("prescription service not available, spraying the default rate")
            return
        self.pending = (self.prescription.call_async(GetMap.Request()), time.monotonic())

    def hitch_and_diagnostics(self) -> None:
        self.gate()
        self.hitch.publish(Float64MultiArray(data=[0.35]))
        if self.pending is not None:
            fut, t = self.pending
            if fut.done():
                self.pending = None
            elif time.monotonic() - t > 5.0:
                self.get_logger().error("service /field/farm_bridge/get_prescription did not answer in 5 s; "
                                        "keeping the last prescription map")
                self.prescription.remove_pending_request(fut)
                self.pending = None
        t = time.monotonic() - self.t0
        low = (t - 65.0) % 180.0 < 20.0 if t >= 65.0 else False  # the tank runs low before each refill
        msg = DiagnosticArray()
        msg.header.stamp = self.stamp()
        msg.status = [
            self.status("Tank level", "isobus_sprayer_ecu", WARN if low else OK,
                        "tank below 15 %, refill at the next headland" if low else "OK",
                        tank="12 %" if low else "64 %"),
            self.status("Boom pressure", "isobus_sprayer_ecu", message="OK", pressure="3.1 bar"),
            self.status("Nozzle flow", "isobus_sprayer_ecu", message="OK", nozzles="24/24"),
        ]
        self.diag.publish(msg)


class SystemMonitor(FieldNode):
    """The supervisor: the GNSS fix quality (a WARN every 15 s while RTK is not fixed) and the
    computer's diagnostics at 1 Hz."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("system_monitor", fault_dir)
        self.create_subscription(NavSatFix, "gnss/fix", self.on_fix, 10)
        self.diag = self.create_publisher(DiagnosticArray, "/diagnostics", 10)
        self.fix_status = None
        self.create_timer(15.0, self.check_rtk)
        self.create_timer(1.0, self.diagnostics)

    def on_fix(self, msg: NavSatFix) -> None:
        self.gate()
        self.fix_status = msg.status.status

    def check_rtk(self) -> None:
        self.gate()
        if self.fix_status is not None and self.fix_status < NavSatStatus.STATUS_GBAS_FIX:
            self.get_logger().warn("GNSS RTK float, not fixed (correction age 2.4 s): row guidance "
                                   "limited to 0.25 m")

    def diagnostics(self) -> None:
        self.gate()
        load = os.getloadavg()[0]
        msg = DiagnosticArray()
        msg.header.stamp = self.stamp()
        msg.status = [
            self.status("CPU Usage", "tractor_pc", message="OK", load_1min=f"{load:.2f}"),
            self.status("Disk Usage", "tractor_pc", message="OK", free="41 %"),
            self.status("GNSS", "gnss_receiver", message="RTK float", satellites="17"),
        ]
        self.diag.publish(msg)


class TelemetryUplink(FieldNode):
    """The farm office's link: the GNSS position for the fleet map, the weather, and the compressed
    camera stream while someone watches it (40 s on, 40 s off)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("telemetry_uplink", fault_dir)
        self.create_subscription(NavSatFix, "gnss/fix", self.on_fix, 10)
        self.create_subscription(Temperature, "weather/temperature", self.on_any, 10)
        self.video = None
        self.frames = 0
        self.t0 = time.monotonic()
        self.create_timer(1.0, self.viewer)

    def on_fix(self, msg: NavSatFix) -> None:
        self.gate()

    def on_any(self, msg) -> None:
        self.gate()

    def viewer(self) -> None:
        self.gate()
        watching = (time.monotonic() - self.t0 - 5.0) % 80.0 < 40.0 and time.monotonic() - self.t0 >= 5.0
        if watching and self.video is None:
            self.get_logger().info("remote viewer connected: streaming camera/image_raw/compressed")
            self.video = self.create_subscription(CompressedImage, "camera/image_raw/compressed",
                                                  self.on_frame, 2)
        elif not watching and self.video is not None:
            self.get_logger().info(f"remote viewer disconnected after {self.frames} frames")
            self.destroy_subscription(self.video)
            self.video, self.frames = None, 0

    def on_frame(self, msg: CompressedImage) -> None:
        self.gate()
        self.frames += 1


class OperatorConsole(FieldNode):
    """The operator's tablet: the camera, the position, the diagnostics, the e-stop heartbeat
    (10 Hz, a lock on the twist mux) and the controllers' list when it opens."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("operator_console", fault_dir)
        self.create_subscription(NavSatFix, "gnss/fix", self.on_any, 10)
        self.create_subscription(DiagnosticArray, "/diagnostics", self.on_any, 10)
        self.create_subscription(CompressedImage, "camera/image_raw/compressed", self.on_any, 2)
        self.estop = self.create_publisher(Bool, "operator_console/e_stop", 10)
        self.create_publisher(TwistStamped, "operator_console/cmd_vel", 10)  # the joystick, not held
        self.controllers = self.create_client(Trigger, "/field/controller_manager/list_controllers")
        self.asked = False
        self.create_timer(0.1, self.heartbeat)

    def on_any(self, msg) -> None:
        self.gate()

    def heartbeat(self) -> None:
        self.gate()
        self.estop.publish(Bool(data=False))
        if not self.asked and self.controllers.service_is_ready():
            self.asked = True
            self.controllers.call_async(Trigger.Request()).add_done_callback(
                lambda f: self.get_logger().info(f"controllers: {f.result().message}"))


# --- a developer's command line ------------------------------------------------------------------------

CLI_TYPES = {"/field/gnss/fix": (NavSatFix, 10), "/field/imu/data_raw": (Imu, qos_profile_sensor_data),
             "/diagnostics": (DiagnosticArray, 10), "/field/joint_states": (JointState, 10),
             "/field/lidar/points": (PointCloud2, qos_profile_sensor_data)}


def cli_tool(verb: str, topic: str) -> int:
    """``ros2 topic echo|hz TOPIC`` for 10 s, then Ctrl-C (exits 0)."""
    node = rclpy.create_node(f"_ros2cli_{os.getpid()}", start_parameter_services=False)
    kind, qos = CLI_TYPES[topic]
    if verb == "hz":
        qos = qos_profile_sensor_data
    stamps: list[float] = []

    def on_msg(msg) -> None:
        stamps.append(time.monotonic())
        if verb == "echo" and len(stamps) <= 3:
            print(str(msg)[:300], flush=True)
    node.create_subscription(kind, topic, on_msg, qos)
    end = time.monotonic() + 10.0
    try:
        while time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.2)
    finally:
        if verb == "hz" and len(stamps) > 1:
            print(f"average rate: {(len(stamps) - 1) / (stamps[-1] - stamps[0]):.3f}", flush=True)
        node.destroy_node()
    return 0


# --- the processes -------------------------------------------------------------------------------------


class IsolatedExecutor:
    """component_container_isolated's: a single-threaded executor for each node, each in a thread."""

    def __init__(self) -> None:
        self.executors: list[SingleThreadedExecutor] = []
        self.threads: list[threading.Thread] = []

    def add_node(self, node: Node) -> None:
        ex = SingleThreadedExecutor()
        ex.add_node(node)
        self.executors.append(ex)

    def spin(self) -> None:
        self.threads = [threading.Thread(target=self._spin, args=(ex,), daemon=True)
                        for ex in self.executors[1:]]
        for t in self.threads:
            t.start()
        self.executors[0].spin()

    def shutdown(self, timeout_sec: float | None = None) -> None:
        for t in self.threads:  # each ends its spin when the context shuts down
            t.join(timeout_sec)
        for ex in self.executors:
            ex.shutdown(timeout_sec=timeout_sec)

    @staticmethod
    def _spin(ex: SingleThreadedExecutor) -> None:
        try:
            ex.spin()
        except ExternalShutdownException:
            pass
        except Exception:
            if rclpy.ok():  # not a callback cut short by Ctrl-C
                raise


def build(process: str, fault_dir: Path) -> tuple[list[FieldNode], object]:
    """The process's nodes and its executor."""
    if process == "control":
        cm = ControllerManager(fault_dir)
        nodes = [cm, JointStateBroadcaster(cm, fault_dir), DriveController(cm, fault_dir),
                 BoomController(cm, fault_dir), HitchController(cm, fault_dir)]
        threading.Thread(target=cm.realtime_loop, daemon=True, name="realtime").start()
        return nodes, MultiThreadedExecutor(num_threads=2)
    single = {
        "state_publisher": [RobotStatePublisher],
        "sensors": [ImuDriver, GnssDriver],
        "lidar": [LidarDriver],
        "localization": [EkfFilter],
        "mission": [MissionPlanner, FarmBridge],
        "implement": [SprayerController],
        "supervisor": [SystemMonitor],
        "uplink": [TelemetryUplink],
        "console": [OperatorConsole],
        "navigation": [RowNavigator, TwistMux],
    }
    if process in single:
        return [cls(fault_dir) for cls in single[process]], SingleThreadedExecutor()
    assert process == "perception", process
    return [cls(fault_dir) for cls in (CameraDriver, ImageRepublisher, WeedDetector, RowDetector)], \
        IsolatedExecutor()


def main(argv: list[str]) -> int:
    process, fault_dir = argv[1], Path(argv[2])
    run_for = float(argv[3]) if len(argv) > 3 else 0.0
    ending: list = []
    rclpy.init()
    try:
        if process.startswith("spawner:"):
            return spawner(process.split(":", 1)[1])
        if process.startswith("cli:"):
            _, verb, topic = process.split(":", 2)
            return cli_tool(verb, topic)
        nodes, executor = build(process, fault_dir)
        ending.append(executor)
        for n in nodes:
            executor.add_node(n)
        threading.Thread(target=watch, args=(nodes, fault_dir, process), daemon=True, name="faults").start()
        if run_for > 0:
            end = time.monotonic() + run_for
            while rclpy.ok() and time.monotonic() < end:
                executor.spin_once(timeout_sec=0.2)
        else:
            executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        for executor in ending:
            executor.shutdown(timeout_sec=1.0)
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
