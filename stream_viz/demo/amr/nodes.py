"""The AMR's node behaviours: drivers, perception, the base, navigation, behaviour, lifecycle, system.

Each class is one node of :data:`~stream_viz.demo.amr.topology.AMR_GROUPS`; :data:`BEHAVIOURS`
maps the node's fully qualified name to it. Stamped messages carry the time their data was
taken (a merged scan keeps the front scan's stamp, a detection its image's), as real drivers do.
"""

from __future__ import annotations

import math
import random
import time
from collections import deque
from typing import Any

from lifecycle_msgs.msg import Transition
from rcl_interfaces.msg import SetParametersResult
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient

from stream_viz.demo.amr.base import Behaviour, qos_for
from stream_viz.demo.amr.topology import ANALYZERS, DIAG, NS, UPDATERS, T, n
from stream_viz.demo.messages import load_type

_IMAGE_W, _IMAGE_H = 160, 120
_IMAGE = bytes(random.Random(1).randrange(256) for _ in range(_IMAGE_W * _IMAGE_H * 3))
_MAP_SIZE, _MAP_RES = 60, 0.5  # a 30 m x 30 m warehouse floor


def _msg(type_key: str) -> Any:
    return load_type(T[type_key])()


def _bursts(seed: int, gap: tuple[float, float], length: tuple[float, float], horizon: float = 7200.0,
            first: float = 0.0):
    """Seeded ``[(start, end)]`` in s from now: active for the ``first`` s, then quiet ``gap`` s and
    active ``length`` s, repeated."""
    rng, t, out = random.Random(seed), first, [(0.0, first)] if first > 0 else []
    while t < horizon:
        t += rng.uniform(*gap)
        d = rng.uniform(*length)
        out.append((t, t + d))
        t += d
    return out


class _Schedule:
    """Whether now falls inside one of the bursts (counted from construction)."""

    def __init__(self, bursts: list[tuple[float, float]]) -> None:
        self.t0, self.bursts = time.monotonic(), deque(bursts)

    def active(self) -> bool:
        t = time.monotonic() - self.t0
        while self.bursts and self.bursts[0][1] < t:
            self.bursts.popleft()
        return bool(self.bursts) and self.bursts[0][0] <= t


def warehouse_grid() -> list[int]:
    """The occupancy grid of the warehouse: walls and rows of shelves (100), aisles free (0)."""
    cells = []
    for y in range(_MAP_SIZE):
        for x in range(_MAP_SIZE):
            wall = x in (0, _MAP_SIZE - 1) or y in (0, _MAP_SIZE - 1)
            shelf = 8 <= y <= 52 and x % 10 in (4, 5) and y != 30
            cells.append(100 if wall or shelf else 0)
    return cells


# -- sensors container ---------------------------------------------------------------------------
class ScanDriver(Behaviour):
    """A safety laser scanner: 10 Hz LaserScan, best effort."""

    def setup(self) -> None:
        self.topic = self.spec.pubs[0].topic
        self.publisher(self.topic, "scan")
        self.frame = self.short.replace("_lidar", "_laser")
        self.seq = 0
        self.ranges = [3.0 + math.sin(i * 0.07) for i in range(270)]
        self.timer(0.1, self.tick)

    def tick(self) -> None:
        self.seq += 1
        msg = _msg("scan")
        msg.header.stamp, msg.header.frame_id = self.stamp(), self.frame
        msg.angle_min, msg.angle_max, msg.angle_increment = -2.36, 2.36, 4.72 / 270
        msg.range_min, msg.range_max, msg.scan_time = 0.05, 30.0, 0.1
        k = self.seq % 270
        msg.ranges = self.ranges[k:] + self.ranges[:k]
        self.send(self.topic, msg)


class ImuDriver(Behaviour):
    def setup(self) -> None:
        self.publisher(n("imu"), "imu")
        self.seq = 0
        self.timer(1 / 30, self.tick)

    def tick(self) -> None:
        self.seq += 1
        msg = _msg("imu")
        msg.header.stamp, msg.header.frame_id = self.stamp(), "imu_link"
        msg.orientation.w = 1.0
        msg.angular_velocity.z = 0.05 * math.sin(self.seq * 0.01)
        msg.linear_acceleration.z = 9.81
        self.send(n("imu"), msg)


class ScanMerger(Behaviour):
    """Merges the front and rear scans into one 360° scan per front scan (needs a fresh rear one)."""

    def setup(self) -> None:
        self.rear: Any = None
        self.publisher(n("scan"), "scan")
        self.subscribe(n("scan_rear"), "scan", self.on_rear)
        self.subscribe(n("scan_front"), "scan", self.on_front)

    def on_rear(self, msg: Any) -> None:
        self.rear = msg

    def on_front(self, front: Any) -> None:
        if self.stale(0.5, n("scan_rear")):
            self.log.warn(f"not merging: no fresh {n('scan_rear')}", throttle_duration_sec=5.0)
            return
        msg = _msg("scan")
        msg.header.stamp, msg.header.frame_id = front.header.stamp, "base_link"  # keeps the data's time
        msg.angle_min, msg.angle_max, msg.angle_increment = -math.pi, math.pi, 2 * math.pi / 540
        msg.range_min, msg.range_max = 0.05, 30.0
        msg.ranges = list(front.ranges) + list(self.rear.ranges)
        self.send(n("scan"), msg)


# -- camera and perception ----------------------------------------------------------------------
class CameraDriver(Behaviour):
    def setup(self) -> None:
        self.publisher(n("camera/image_raw"), "image")
        self.timer(0.1, self.tick)

    def tick(self) -> None:
        msg = _msg("image")
        msg.header.stamp, msg.header.frame_id = self.stamp(), "camera_optical"
        msg.height, msg.width, msg.encoding, msg.step = _IMAGE_H, _IMAGE_W, "rgb8", _IMAGE_W * 3
        msg.data = _IMAGE
        self.send(n("camera/image_raw"), msg)


class ImageRectifier(Behaviour):
    def setup(self) -> None:
        self.publisher(n("camera/image_rect"), "image")
        self.subscribe(n("camera/image_raw"), "image", lambda msg: self.send(n("camera/image_rect"), msg))


class PalletDetector(Behaviour):
    """Publishes detections only while a pallet is in view: 3-30 s (the robot passing a rack or
    approaching a pallet: often longer than a monitor's warm-up), then none for 15-40 s. The robot
    starts at its pickup station, a pallet in view for the first 20 s."""

    def setup(self) -> None:
        self.view = _Schedule(_bursts(7, gap=(15.0, 40.0), length=(3.0, 30.0), first=20.0))
        self.publisher(n("pallet_detections"), "poses")
        self.subscribe(n("camera/image_rect"), "image", self.on_image)

    def on_image(self, image: Any) -> None:
        if not self.view.active():
            return
        geo = load_type("geometry_msgs/msg/Pose")
        msg = _msg("poses")
        msg.header = image.header  # a detection is as old as the image it was found in
        pose = geo()
        pose.position.x, pose.position.y, pose.orientation.w = 2.5, 0.1 * math.sin(time.time()), 1.0
        msg.poses = [pose]
        self.send(n("pallet_detections"), msg)


# -- base ----------------------------------------------------------------------------------------
class BaseDriver(Behaviour):
    """The motor controller: drives at the last /cmd_vel (stops after 0.5 s without one), odometry 20 Hz."""

    def setup(self) -> None:
        self.cmd: Any = None
        self.x = self.y = self.yaw = 0.0
        self.charge = 0.92
        for topic, key in (("odom", "odom"), ("joint_states", "joints"), ("battery_state", "battery")):
            self.publisher(n(topic), key)
        self.subscribe(n("cmd_vel"), "twist", self.on_cmd)
        self.timer(0.05, self.odom)
        self.timer(0.1, self.joints)
        self.timer(1.0, self.battery)

    def on_cmd(self, msg: Any) -> None:
        self.cmd = msg

    def velocity(self) -> tuple[float, float]:
        if self.cmd is None or self.stale(0.5, n("cmd_vel")):
            return 0.0, 0.0
        return self.cmd.linear.x, self.cmd.angular.z

    def odom(self) -> None:
        v, w = self.velocity()
        self.yaw += w * 0.05
        self.x += v * 0.05 * math.cos(self.yaw)
        self.y += v * 0.05 * math.sin(self.yaw)
        msg = _msg("odom")
        msg.header.stamp, msg.header.frame_id, msg.child_frame_id = self.stamp(), "odom", "base_link"
        msg.pose.pose.position.x, msg.pose.pose.position.y = self.x, self.y
        q = msg.pose.pose.orientation
        q.z, q.w = math.sin(self.yaw / 2), math.cos(self.yaw / 2)
        msg.twist.twist.linear.x, msg.twist.twist.angular.z = v, w
        self.send(n("odom"), msg)

    def joints(self) -> None:
        msg = _msg("joints")
        msg.header.stamp = self.stamp()
        msg.name = ["wheel_left_joint", "wheel_right_joint"]
        msg.position = [self.x / 0.1, self.x / 0.1]
        self.send(n("joint_states"), msg)

    def battery(self) -> None:
        self.charge = max(0.2, self.charge - 1e-4)
        msg = _msg("battery")
        msg.header.stamp, msg.header.frame_id = self.stamp(), "base_link"
        msg.voltage, msg.percentage, msg.present = 44.0 + 8.0 * self.charge, self.charge, True
        self.send(n("battery_state"), msg)

    def diagnostics(self) -> list[tuple[int, str]]:
        return [(0, "motors OK, 41 C"), (0, f"battery {100 * self.charge:.0f} %")]


class VelocityMux(Behaviour):
    """twist_mux: teleop (priority 100) over navigation (10); each source times out after 0.5 s."""

    def setup(self) -> None:
        self.source = "navigation"
        self.publisher(n("cmd_vel"), "twist")
        self.subscribe(n("cmd_vel_teleop"), "twist", lambda msg: self.forward("teleop", msg))
        self.subscribe(n("cmd_vel_nav"), "twist", lambda msg: self.forward("navigation", msg))

    def forward(self, source: str, msg: Any) -> None:
        if source == "navigation" and not self.stale(0.5, n("cmd_vel_teleop")):
            return  # teleop holds the robot
        if source != self.source:
            self.log.info(f"input {source} takes over {n('cmd_vel')}")
            self.source = source
        self.send(n("cmd_vel"), msg)


class TeleopJoy(Behaviour):
    """A joystick: 10 Hz commands only while the operator pushes it (2-4 s, every 40-90 s)."""

    def setup(self) -> None:
        self.push = _Schedule(_bursts(11, gap=(40.0, 90.0), length=(2.0, 4.0)))
        self.publisher(n("cmd_vel_teleop"), "twist")
        self.timer(0.1, self.tick)

    def tick(self) -> None:
        if self.push.active():
            msg = _msg("twist")
            msg.linear.x, msg.angular.z = 0.2, 0.3
            self.send(n("cmd_vel_teleop"), msg)


# -- navigation container (multi-threaded) ---------------------------------------------------------
class Amcl(Behaviour):
    """Localisation: a pose per second scan, from the map (latched), the scan and fresh odometry."""

    def setup(self) -> None:
        self.scans = 0
        self.odom_msg: Any = None
        self.publisher(n("amcl_pose"), "pose_cov")
        self.subscribe(n("map"), "grid", lambda msg: self.log.info("received the map"))
        self.subscribe(n("odom"), "odom", self.on_odom)
        self.subscribe(n("scan"), "scan", self.on_scan)

    def on_odom(self, msg: Any) -> None:
        self.odom_msg = msg

    def on_scan(self, scan: Any) -> None:
        self.scans += 1
        if self.scans % 2:
            return
        if n("map") not in self.last:
            self.log.warn("waiting for the map", throttle_duration_sec=5.0)
            return
        if self.stale(0.5, n("odom")):
            self.log.warn(f"no fresh {n('odom')}: pose not updated", throttle_duration_sec=5.0)
            return
        age = (self.node.get_clock().now().nanoseconds - _ns(self.odom_msg.header.stamp)) / 1e9
        if age > 0.2:
            self.log.warn(f"odometry is {age:.2f} s old: pose lags", throttle_duration_sec=5.0)
        msg = _msg("pose_cov")
        msg.header.stamp, msg.header.frame_id = scan.header.stamp, "map"
        msg.pose.pose = self.odom_msg.pose.pose
        msg.pose.covariance[0] = msg.pose.covariance[7] = 0.02
        self.send(n("amcl_pose"), msg)


def _ns(stamp: Any) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


class LocalCostmap(Behaviour):
    """A rolling 20 m costmap from the scan, 2 Hz; not updated without a fresh scan."""

    def setup(self) -> None:
        self.publisher(n("local_costmap/costmap"), "grid")
        self.subscribe(n("scan"), "scan")
        self.cells = [0] * (40 * 40)
        self.timer(0.5, self.tick)

    def tick(self) -> None:
        if self.stale(1.0, n("scan")):
            self.log.warn(f"costmap not updated: no fresh {n('scan')}", throttle_duration_sec=5.0)
            return
        msg = _msg("grid")
        msg.header.stamp, msg.header.frame_id = self.stamp(), "odom"
        msg.info.resolution, msg.info.width, msg.info.height = 0.5, 40, 40
        msg.info.origin.orientation.w = 1.0
        msg.data = self.cells
        self.send(n("local_costmap/costmap"), msg)


class PlannerServer(Behaviour):
    """Serves ``compute_path`` (nav_msgs/GetPlan): a breadth-first search on the map per call."""

    def setup(self) -> None:
        self.grid: list[int] | None = None
        self.subscribe(n("map"), "grid", self.on_map)
        # its own group: a long plan does not hold up the map subscription
        self.node.create_service(load_type(T["get_plan"]), n("compute_path"), self.serve,
                                 callback_group=MutuallyExclusiveCallbackGroup())

    def on_map(self, msg: Any) -> None:
        self.grid, self.width = list(msg.data), msg.info.width

    def serve(self, request: Any, response: Any) -> Any:
        if not self.gate():
            return response
        self.slow_service()
        if self.grid is None:
            self.log.warn("no map yet: cannot plan")
            return response
        cells = self.search(self.cell(request.start.pose.position), self.cell(request.goal.pose.position))
        geo = load_type("geometry_msgs/msg/PoseStamped")
        response.plan.header.stamp, response.plan.header.frame_id = self.stamp(), "map"
        for c in cells:
            p = geo()
            p.header.frame_id = "map"
            p.pose.position.x, p.pose.position.y = (c % self.width) * _MAP_RES, (c // self.width) * _MAP_RES
            p.pose.orientation.w = 1.0
            response.plan.poses.append(p)
        return response

    def cell(self, pos: Any) -> int:
        x = min(self.width - 2, max(1, int(pos.x / _MAP_RES)))
        y = min(self.width - 2, max(1, int(pos.y / _MAP_RES)))
        return y * self.width + x

    def search(self, start: int, goal: int) -> list[int]:
        prev, frontier, w = {start: start}, deque([start]), self.width
        while frontier:
            c = frontier.popleft()
            if c == goal:
                break
            for d in (1, -1, w, -w):
                m = c + d
                if 0 <= m < len(self.grid) and m not in prev and self.grid[m] == 0:
                    prev[m] = c
                    frontier.append(m)
        if goal not in prev:
            return []
        path = [goal]
        while path[-1] != start:
            path.append(prev[path[-1]])
        return path[::-1]


class ControllerServer(Behaviour):
    """Follows the plan at 10 Hz, within ``max_vel_x`` (a parameter the zone manager sets)."""

    def setup(self) -> None:
        self.max_vel = self.node.declare_parameter("max_vel_x", 0.8).value

        def on_params(params: list) -> Any:
            for p in params:
                if p.name == "max_vel_x":
                    self.log.info(f"max_vel_x {self.max_vel} -> {p.value}")
                    self.max_vel = p.value
            return SetParametersResult(successful=True)

        self.node.add_on_set_parameters_callback(on_params)
        self.publisher(n("cmd_vel_nav"), "twist")
        for topic, key in (("plan", "path"), ("odom", "odom"), ("local_costmap/costmap", "grid")):
            self.subscribe(n(topic), key)
        self.timer(0.1, self.tick)

    def tick(self) -> None:
        stale = self.stale(5.0, n("plan")) + self.stale(2.0, n("local_costmap/costmap")) + \
            self.stale(0.5, n("odom"))
        if stale:
            self.log.warn(f"not following the path: no fresh {', '.join(stale)}", throttle_duration_sec=5.0)
            return
        msg = _msg("twist")
        msg.linear.x, msg.angular.z = min(0.5, self.max_vel), 0.1 * math.sin(time.time() / 5)
        self.send(n("cmd_vel_nav"), msg)


# -- behaviour -----------------------------------------------------------------------------------
class BtNavigator(Behaviour):
    """Asks the planner for a path every 2 s (3 s timeout) and publishes it; logs when planning fails."""

    def setup(self) -> None:
        self.pose: Any = None
        self.pending: tuple[Any, float] | None = None
        self.goals = [(25.0, 25.0), (3.0, 25.0), (25.0, 3.0), (3.0, 3.0)]
        self.client = self.node.create_client(load_type(T["get_plan"]), n("compute_path"),
                                              callback_group=self.cg)
        self.publisher(n("plan"), "path")
        self.subscribe(n("amcl_pose"), "pose_cov", self.on_pose)
        self.timer(2.0, self.tick)

    def on_pose(self, msg: Any) -> None:
        self.pose = msg

    def tick(self) -> None:
        now = time.monotonic()
        if self.pending is not None:
            future, sent = self.pending
            if not future.done() and now - sent < 3.0:
                return
            if not future.done():
                self.client.remove_pending_request(future)
                self.log.error(f"{n('compute_path')} did not answer within 3 s: navigation stalled")
            self.pending = None
        if not self.client.service_is_ready():
            self.log.warn(f"waiting for service {n('compute_path')}", throttle_duration_sec=5.0)
            return
        if self.pose is None or self.stale(2.0, n("amcl_pose")):
            self.log.warn(f"no fresh {n('amcl_pose')}: not planning", throttle_duration_sec=5.0)
            return
        req = load_type(T["get_plan"]).Request()
        req.start.header.frame_id = req.goal.header.frame_id = "map"
        req.start.pose = self.pose.pose.pose
        gx, gy = self.goals[int(time.time() / 60) % len(self.goals)]
        req.goal.pose.position.x, req.goal.pose.position.y = gx, gy
        future = self.client.call_async(req)
        future.add_done_callback(self.answered)
        self.pending = (future, now)

    def answered(self, future: Any) -> None:
        if future.cancelled() or future.result() is None:
            return
        plan = future.result().plan
        if not plan.poses:
            self.log.warn("the planner returned no path", throttle_duration_sec=5.0)
            return
        self.last[n("compute_path")] = time.monotonic()
        plan.header.stamp = self.stamp()
        self.send(n("plan"), plan)


class ZoneManager(Behaviour):
    """Sets the controller's speed limit as the robot moves between warehouse zones (every 20 s)."""

    def setup(self) -> None:
        self.params = AsyncParameterClient(self.node, n("controller_server"), callback_group=self.cg)
        self.zone = 0
        self.subscribe(n("amcl_pose"), "pose_cov")
        self.timer(20.0, self.tick)

    def tick(self) -> None:
        if not self.params.services_are_ready():
            return
        self.zone = 1 - self.zone
        limit = (0.8, 0.3)[self.zone]
        self.log.info(f"entering zone {'AB'[self.zone]}: speed limit {limit} m/s")
        self.params.set_parameters([Parameter("max_vel_x", value=limit)])


# -- lifecycle -------------------------------------------------------------------------------------
class _ManagedNode(LifecycleNode):
    """A LifecycleNode whose transitions run its behaviour's ``on_<transition>`` (rclpy's own first)."""

    owner: _Managed

    def on_configure(self, state: Any) -> TransitionCallbackReturn:
        return self.owner.transition("configure", super().on_configure(state))

    def on_activate(self, state: Any) -> TransitionCallbackReturn:
        return self.owner.transition("activate", super().on_activate(state))

    def on_deactivate(self, state: Any) -> TransitionCallbackReturn:
        return self.owner.transition("deactivate", super().on_deactivate(state))


class _Managed(Behaviour):
    """A lifecycle node: its publishers are lifecycle publishers, silent unless the node is active."""

    def make_node(self, name: str, namespace: str, context: Any) -> Any:
        node = _ManagedNode(name, namespace=namespace, context=context)
        node.owner = self
        return node

    def lifecycle_publisher(self, topic: str, type_key: str) -> None:
        cls = load_type(T[type_key])
        self._pubs[topic] = self.node.create_lifecycle_publisher(cls, topic, qos_for(topic))

    def transition(self, name: str, result: TransitionCallbackReturn) -> TransitionCallbackReturn:
        if not self.gate() or result != TransitionCallbackReturn.SUCCESS:
            return TransitionCallbackReturn.FAILURE
        getattr(self, f"on_{name}")()
        self.log.info(f"{name.removesuffix('e')}ed")
        return result

    def on_configure(self) -> None:
        pass

    def on_activate(self) -> None:
        pass

    def on_deactivate(self) -> None:
        pass


class MapServer(_Managed):
    """Publishes the warehouse map once, latched, when activated."""

    def on_configure(self) -> None:
        self.lifecycle_publisher(n("map"), "grid")

    def on_activate(self) -> None:
        msg = _msg("grid")
        msg.header.stamp, msg.header.frame_id = self.stamp(), "map"
        msg.info.resolution, msg.info.width, msg.info.height = _MAP_RES, _MAP_SIZE, _MAP_SIZE
        msg.info.origin.orientation.w = 1.0
        msg.data = warehouse_grid()
        self.send(n("map"), msg)


class DockingServer(_Managed):
    """Publishes the charging dock's pose at 5 Hz while active (the lifecycle manager's docking phases)."""

    def setup(self) -> None:
        self.active = False
        self.timer(0.2, self.tick)

    def on_configure(self) -> None:
        self.lifecycle_publisher(n("dock_pose"), "pose")

    def on_activate(self) -> None:
        self.active = True

    def on_deactivate(self) -> None:
        self.active = False

    def tick(self) -> None:
        if self.active:
            msg = _msg("pose")
            msg.header.stamp, msg.header.frame_id = self.stamp(), "map"
            msg.pose.position.x, msg.pose.orientation.w = 1.0, 1.0
            self.send(n("dock_pose"), msg)


class LifecycleManager(Behaviour):
    """Configures and activates the map server, configures docking, then docks 10 s of every 30 s."""

    def setup(self) -> None:
        cls = load_type(T["change_state"])
        self.clients = {name: self.node.create_client(cls, n(f"{name}/change_state"), callback_group=self.cg)
                        for name in ("map_server", "docking_server")}
        self.startup = deque([("map_server", Transition.TRANSITION_CONFIGURE),
                              ("map_server", Transition.TRANSITION_ACTIVATE),
                              ("docking_server", Transition.TRANSITION_CONFIGURE)])
        self.up_at = 0.0
        self.docking = False
        self.pending: Any = None
        self.timer(0.5, self.tick)

    def tick(self) -> None:
        if self.pending is not None and not self.pending.done():
            return
        self.pending = None
        if self.startup:
            name, transition = self.startup[0]
            if self.clients[name].service_is_ready():
                self.startup.popleft()
                self.change(name, transition)
                self.up_at = time.monotonic()
            return
        dock = (time.monotonic() - self.up_at) % 30.0 >= 20.0
        if dock != self.docking:
            self.docking = dock
            self.change("docking_server", Transition.TRANSITION_ACTIVATE if dock else
                        Transition.TRANSITION_DEACTIVATE)

    def change(self, name: str, transition: int) -> None:
        req = load_type(T["change_state"]).Request()
        req.transition.id = transition
        self.pending = self.clients[name].call_async(req)


# -- system --------------------------------------------------------------------------------------
_URDF = "<robot name='amr1'>" + "".join(
    f"<link name='{name}'/>" for name in ("base_link", "front_laser", "rear_laser", "imu_link", "camera_link",
                                         "wheel_left", "wheel_right")) + "</robot>"


class RobotStatePublisher(Behaviour):
    def setup(self) -> None:
        self.publisher(n("robot_description"), "string")
        self.subscribe(n("joint_states"), "joints")
        msg = _msg("string")
        msg.data = _URDF
        self.send(n("robot_description"), msg)  # once, latched


class DiagnosticAggregator(Behaviour):
    """diagnostic_aggregator: statuses regrouped under /AMR/<analyzer path>/<name>, 1 Hz, 5 s timeout."""

    def setup(self) -> None:
        self.items: dict[str, tuple[Any, float]] = {}
        self.publisher("/diagnostics_agg", "diag")
        self.publisher("/diagnostics_toplevel_state", "diag_status")
        self.subscribe(DIAG, "diag", self.on_diag)
        self.timer(1.0, self.tick)

    def on_diag(self, arr: Any) -> None:
        for st in arr.status:
            self.items[st.name] = (st, time.monotonic())

    def tick(self) -> None:
        status_type = load_type(T["diag_status"])
        kv = load_type("diagnostic_msgs/msg/KeyValue")
        groups: dict[str, list[Any]] = {}
        now = time.monotonic()
        for name, (st, t) in sorted(self.items.items()):
            path = "/AMR/" + ANALYZERS.get(name.partition(":")[0], "Other")
            level = 3 if now - t > 5.0 else _level(st)
            item = status_type(level=bytes([level]), name=f"{path}/{name.replace('/', ' ')}",
                               message="Stale" if level == 3 else st.message, hardware_id=st.hardware_id,
                               values=st.values)
            groups.setdefault(path, []).append(item)
        out, top = _msg("diag"), 0
        out.header.stamp = self.stamp()
        for path, items in groups.items():
            level = max(_level(i) for i in items)
            top = max(top, level)
            values = [kv(key=i.name.rpartition("/")[2], value=i.message) for i in items]
            out.status.append(status_type(level=bytes([level]), name=path, message=_LEVELS[level],
                                          values=values))
            out.status.extend(items)
        out.status.insert(0, status_type(level=bytes([top]), name="/AMR", message=_LEVELS[top]))
        self.send("/diagnostics_agg", out)
        self.send("/diagnostics_toplevel_state", status_type(level=bytes([top]), name="toplevel_state",
                                                             message=_LEVELS[top]))


_LEVELS = ("OK", "Warning", "Error", "Stale")


def _level(status: Any) -> int:
    return status.level[0] if isinstance(status.level, bytes) else int(status.level)


# -- jobs and late joiners ---------------------------------------------------------------------------
class ImuCalibration(Behaviour):
    """A one-shot job: averages the IMU for its run, logs the bias, and its process exits with 0."""

    def setup(self) -> None:
        self.samples: list[float] = []
        self.subscribe(n("imu"), "imu", lambda msg: self.samples.append(msg.angular_velocity.z))
        self.log.info("collecting IMU samples")

    def finish(self) -> None:
        bias = sum(self.samples) / len(self.samples) if self.samples else 0.0
        self.log.info(f"gyro z bias {bias:.5f} rad/s from {len(self.samples)} samples; done")


class OperatorConsole(Behaviour):
    """The operator's console, started late: diagnostics, battery, detections, the latched map and URDF."""

    def setup(self) -> None:
        for topic, key in (("/diagnostics_agg", "diag"), (n("battery_state"), "battery"),
                           (n("pallet_detections"), "poses"), (n("map"), "grid"),
                           (n("robot_description"), "string")):
            self.subscribe(topic, key)
        self.log.info(f"operator console connected to {NS}")


BEHAVIOURS: dict[str, type[Behaviour]] = {
    n("front_lidar"): ScanDriver, n("rear_lidar"): ScanDriver, n("imu_driver"): ImuDriver,
    n("scan_merger"): ScanMerger, n("camera_driver"): CameraDriver, n("image_rectifier"): ImageRectifier,
    n("pallet_detector"): PalletDetector, n("base_driver"): BaseDriver, n("velocity_mux"): VelocityMux,
    n("teleop_joy"): TeleopJoy, n("amcl"): Amcl, n("local_costmap"): LocalCostmap,
    n("planner_server"): PlannerServer, n("controller_server"): ControllerServer,
    n("bt_navigator"): BtNavigator, n("zone_manager"): ZoneManager, n("lifecycle_manager"): LifecycleManager,
    n("map_server"): MapServer, n("docking_server"): DockingServer,
    n("robot_state_publisher"): RobotStatePublisher, n("diagnostic_aggregator"): DiagnosticAggregator,
    n("imu_calibration"): ImuCalibration, n("operator_console"): OperatorConsole,
}
assert set(UPDATERS) <= set(BEHAVIOURS)
