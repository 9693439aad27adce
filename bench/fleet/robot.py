"""A two-robot delivery fleet in a simulator, plain rclpy: ``python -m bench.fleet.robot PROCESS FAULT_DIR``.

Written as a team prototyping in a Gazebo-like simulator has it, with structures the other robots
do not have: everything runs on simulation time (``use_sim_time``), driven by ``/clock`` from the
simulator, whose real-time factor wanders between ~0.6 and 1.0 and dips to ~0.5 while a heavy
scene is in view; the simulator's bridge publishes both robots' scans and odometry and takes
their velocity commands; robot r1's navigation is one composed process (an isolated container:
an executor and a thread per node, see `PROCESSES`), robot r2's the same nodes one to a process
plus an odometry filter; navigation goals are actions (`test_msgs` Fibonacci as a stand-in) from
a fleet manager, with idle gaps between them in which the controllers publish nothing; a path
and a map published once, transient-local; ``/tf_like`` (geometry_msgs/TransformStamped), a topic
both localizers publish on, as /tf; a dispatcher calling the manager's service; a recorder that
subscribes to every topic it discovers (as ``rosbag record -a``) and a diagnostics node; a teleop
an operator opens and closes (a clean exit, started again by its launcher). Healthy noise real
systems have: ERROR logs at startup until a service appears, a recurring WARN, a battery WARN in
the diagnostics for ~20 s every ~2 minutes.

Faults come from files: ``FAULT_DIR/<namespace>.<node>`` (``r1.planner``) holding ``hang``,
``degrade`` (the bridge: /r1/scan at a quarter of its rate), ``stale`` (the odometry filter:
stamps 0.8 s in the past), ``slow_service`` (the manager: 4 s a call), ``errlog`` or ``stop_tf``
(a localizer stops publishing /tf_like) makes that node misbehave from then on (checked every
0.5 s of wall time); ``FAULT_DIR/<process>.cpu`` starts a thread burning a core in that process,
``FAULT_DIR/<process>.leak`` one leaking 20 MB/s. Crashes are SIGKILLs from outside. A third
argument, RUN_FOR, ends the process cleanly after that many seconds (the teleop).
"""

from __future__ import annotations

import importlib
import math
import os
import random
import sys
import threading
import time
from array import array
from collections.abc import Callable
from functools import partial
from pathlib import Path

import rclpy
from action_msgs.msg import GoalStatus, GoalStatusArray
from builtin_interfaces.msg import Time as TimeMsg
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped, TransformStamped, Twist
from nav_msgs.msg import OccupancyGrid, Odometry
from nav_msgs.msg import Path as PathMsg
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.duration import Duration
from rclpy.executors import Executor, ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import (
    DurabilityPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_profile_action_status_default,
    qos_profile_sensor_data,
)
from rclpy.task import Future
from rclpy.time import Time
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import BatteryState, LaserScan
from std_msgs.msg import Header, String
from std_srvs.srv import Trigger
from test_msgs.action import Fibonacci

LATCHED = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)
ROBOTS = ("r1", "r2")
# /clock every 20 ms of wall time (Gazebo publishes it every step; 50 Hz keeps a dozen Python
# nodes on simulation time affordable), advancing 20 ms × the real-time factor
CLOCK_PERIOD = 0.02


class Part(Node):
    """A node of the fleet, on simulation time unless ``sim_time`` is False, with the bench's fault
    hooks: ``gate()`` before each callback; the fault file checked on a wall-clock timer."""

    def __init__(self, name: str, namespace: str, fault_dir: Path, sim_time: bool = True) -> None:
        super().__init__(name, namespace=namespace,
                         parameter_overrides=[Parameter("use_sim_time", value=sim_time)])
        self.fault_file = fault_dir / f"{namespace.strip('/')}.{name}"
        self.fault: str | None = None
        self.wall = Clock(clock_type=ClockType.STEADY_TIME)
        self.create_timer(0.5, self._check_fault, callback_group=MutuallyExclusiveCallbackGroup(),
                          clock=self.wall)

    def _check_fault(self) -> None:
        if self.fault is None and self.fault_file.exists():
            self.fault = self.fault_file.read_text().strip() or None  # empty: still being written
            if self.fault:
                self.get_logger().info(f"fault {self.fault}")
        if self.fault == "errlog":
            self.get_logger().error("failed to compute velocity command: transform timed out")

    def gate(self) -> None:
        if self.fault == "hang":
            threading.Event().wait()

    def stamp(self) -> TimeMsg:
        return self.get_clock().now().to_msg()

    def sim_s(self) -> float:
        return self.get_clock().now().nanoseconds / 1e9

    def after(self, seconds: float, fn: Callable[[], None], clock: Clock | None = None) -> None:
        """Call ``fn`` once, ``seconds`` from now on ``clock`` (this node's: simulation time)."""
        box = []

        def fire() -> None:
            box[0].cancel()
            self.destroy_timer(box[0])
            fn()
        box.append(self.create_timer(seconds, fire, clock=clock))

    async def sleep(self, seconds: float) -> None:
        """Await ``seconds`` of this node's (simulation) time, the executor free meanwhile."""
        done = Future()
        self.after(seconds, lambda: done.set_result(None))
        await done


# --- the simulator -------------------------------------------------------------------------


def world(fd: Path) -> Part:
    """/clock every CLOCK_PERIOD of wall time, advancing CLOCK_PERIOD × the real-time factor."""
    n = Part("world", "/sim", fd, sim_time=False)
    pub = n.create_publisher(ClockMsg, "/clock", 10)
    sim_ns = [0]
    rtf = [0.85]
    heavy = [time.monotonic() + random.uniform(90.0, 150.0), 0.0]  # next heavy scene, its end

    def tick() -> None:
        n.gate()
        sim_ns[0] += int(CLOCK_PERIOD * 1e9 * rtf[0])
        sec, nsec = divmod(sim_ns[0], 1_000_000_000)
        pub.publish(ClockMsg(clock=TimeMsg(sec=sec, nanosec=nsec)))

    def wander() -> None:
        now = time.monotonic()
        if now >= heavy[0]:
            heavy[:] = [now + random.uniform(100.0, 140.0), now + 8.0]
            n.get_logger().info(f"scene update: {random.randint(60, 90)} models in view")
        if now < heavy[1]:
            rtf[0] = max(0.45, min(0.55, 0.5 + random.gauss(0.0, 0.02)))
        else:
            rtf[0] = max(0.6, min(1.0, max(rtf[0], 0.6) + random.gauss(0.0, 0.03)))

    n.create_timer(CLOCK_PERIOD, tick)
    n.create_timer(1.0, wander)
    n.create_timer(10.0, lambda: n.get_logger().info(
        f"sim time {sim_ns[0] / 1e9:.1f} s, real time factor {rtf[0]:.2f}"))
    return n


def _scans() -> list[array]:
    """A few 360-beam scans of a room with a moving obstacle, to cycle through."""
    out = []
    for k in range(8):
        ranges = array("f", (3.0 + 1.5 * abs(math.cos(math.radians(a))) for a in range(360)))
        for a in range(40 + 10 * k, 55 + 10 * k):
            ranges[a % 360] = 1.2
        out.append(ranges)
    return out


def bridge(fd: Path) -> Part:
    """Per robot: LaserScan at 10 Hz, Odometry at 30 Hz (simulation time); takes cmd_vel."""
    n = Part("bridge", "/sim", fd)
    scans = _scans()
    for robot, x0 in (("r1", 0.0), ("r2", 4.0)):
        cg = MutuallyExclusiveCallbackGroup()
        st = {"x": x0, "y": 0.0, "yaw": 0.0, "v": 0.0, "w": 0.0, "cmd": -1.0, "t": -1.0, "k": 0}
        scan_pub = n.create_publisher(LaserScan, f"/{robot}/scan", qos_profile_sensor_data)
        odom_pub = n.create_publisher(Odometry, f"/{robot}/odom", 10)

        def on_cmd(msg: Twist, st: dict = st) -> None:
            st["v"], st["w"], st["cmd"] = msg.linear.x, msg.angular.z, n.sim_s()

        def scan(robot: str = robot, st: dict = st, pub=scan_pub) -> None:
            n.gate()
            st["k"] += 1
            if robot == "r1" and n.fault == "degrade" and st["k"] % 4:
                return
            pub.publish(LaserScan(header=Header(stamp=n.stamp(), frame_id=f"{robot}/laser"),
                                  angle_min=-math.pi, angle_max=math.pi, angle_increment=math.pi / 180,
                                  scan_time=0.1, range_min=0.1, range_max=12.0,
                                  ranges=scans[st["k"] % len(scans)]))

        def odom(robot: str = robot, st: dict = st, pub=odom_pub) -> None:
            n.gate()
            now = n.sim_s()
            dt = min(max(now - st["t"], 0.0), 0.1) if st["t"] >= 0 else 0.0
            st["t"] = now
            if now - st["cmd"] > 0.5:  # no command for 0.5 s: the robot stops
                st["v"] = st["w"] = 0.0
            st["yaw"] += st["w"] * dt
            st["x"] += st["v"] * math.cos(st["yaw"]) * dt
            st["y"] += st["v"] * math.sin(st["yaw"]) * dt
            m = Odometry(header=Header(stamp=n.stamp(), frame_id=f"{robot}/odom"),
                         child_frame_id=f"{robot}/base_link")
            m.pose.pose.position.x, m.pose.pose.position.y = st["x"], st["y"]
            q = m.pose.pose.orientation
            q.z, q.w = math.sin(st["yaw"] / 2), math.cos(st["yaw"] / 2)
            m.twist.twist.linear.x, m.twist.twist.angular.z = st["v"], st["w"]
            pub.publish(m)

        n.create_subscription(Twist, f"/{robot}/cmd_vel", on_cmd, 10, callback_group=cg)
        n.create_timer(0.1, scan, callback_group=cg)
        n.create_timer(1.0 / 30.0, odom, callback_group=cg)
    return n


def map_server(fd: Path) -> Part:
    """/map once, transient-local: a 50x50 room with walls."""
    n = Part("map_server", "/sim", fd)
    pub = n.create_publisher(OccupancyGrid, "/map", LATCHED)
    grid = OccupancyGrid(header=Header(stamp=n.stamp(), frame_id="map"))
    grid.info.resolution, grid.info.width, grid.info.height = 0.2, 50, 50
    grid.data = [100 if i < 50 or i >= 2450 or i % 50 in (0, 49) else 0 for i in range(2500)]
    pub.publish(grid)
    n.get_logger().info("map loaded: 50 x 50 cells at 0.2 m")
    return n


# --- navigation of one robot ---------------------------------------------------------------


def localizer(fd: Path, robot: str, odom_topic: str) -> Part:
    """Pose at 10 Hz (stamped with the last scan) and map→odom on /tf_like at 20 Hz."""
    n = Part("localizer", f"/{robot}", fd)
    pose_pub = n.create_publisher(PoseWithCovarianceStamped, f"/{robot}/pose", 10)
    tf_pub = n.create_publisher(TransformStamped, "/tf_like", 100)
    last: dict = {"scan": None, "odom": None}
    cov = array("d", [0.05 if i in (0, 7, 35) else 0.0 for i in range(36)])

    def on_scan(msg: LaserScan) -> None:
        n.gate()
        if last["scan"] is None:
            n.get_logger().info("first scan received, localization running")
        last["scan"] = msg.header.stamp

    def on_odom(msg: Odometry) -> None:
        n.gate()
        last["odom"] = msg

    def pose() -> None:
        n.gate()
        if last["scan"] is None or last["odom"] is None:
            return
        m = PoseWithCovarianceStamped(header=Header(stamp=last["scan"], frame_id="map"))
        m.pose.pose = last["odom"].pose.pose
        m.pose.covariance = cov
        pose_pub.publish(m)

    def tf() -> None:
        n.gate()
        if last["odom"] is None or n.fault == "stop_tf":
            return
        t = TransformStamped(header=Header(stamp=last["odom"].header.stamp, frame_id="map"),
                             child_frame_id=f"{robot}/odom")
        t.transform.translation.x, t.transform.rotation.w = 0.02, 1.0
        tf_pub.publish(t)

    n.create_subscription(LaserScan, f"/{robot}/scan", on_scan, qos_profile_sensor_data)
    n.create_subscription(Odometry, odom_topic, on_odom, 10)
    n.create_timer(0.1, pose)
    n.create_timer(0.05, tf)
    return n


def planner(fd: Path, robot: str) -> Part:
    """The navigate action: a path once (transient-local), feedback every 0.5 s (sim) to the end."""
    n = Part("planner", f"/{robot}", fd)
    path_pub = n.create_publisher(PathMsg, f"/{robot}/path", LATCHED)

    def on_goal(request) -> GoalResponse:
        n.gate()
        return GoalResponse.ACCEPT

    async def execute(goal) -> Fibonacci.Result:
        n.gate()
        duration = 2.0 * goal.request.order
        heading = random.uniform(-math.pi, math.pi)
        path = PathMsg(header=Header(stamp=n.stamp(), frame_id="map"))
        for i in range(20):
            p = PoseStamped(header=path.header)
            p.pose.position.x = 0.2 * duration * i / 19 * math.cos(heading)
            p.pose.position.y = 0.2 * duration * i / 19 * math.sin(heading)
            path.poses.append(p)
        path_pub.publish(path)
        n.get_logger().info(f"goal accepted: {len(path.poses)} waypoints, {duration:.0f} s")
        end = n.sim_s() + duration
        done: list[int] = []
        while n.sim_s() < end:
            await n.sleep(0.5)
            n.gate()
            if goal.is_cancel_requested:
                goal.canceled()
                n.get_logger().info("goal canceled")
                return Fibonacci.Result(sequence=done[-5:])
            done.append(len(done))
            goal.publish_feedback(Fibonacci.Feedback(sequence=done[-5:]))
        goal.succeed()
        n.get_logger().info("goal reached")
        return Fibonacci.Result(sequence=done[-5:])

    ActionServer(n, Fibonacci, f"/{robot}/navigate", execute, goal_callback=on_goal,
                 cancel_callback=lambda goal: CancelResponse.ACCEPT)
    return n


def controller(fd: Path, robot: str) -> Part:
    """cmd_vel at 20 Hz (sim) toward the path's end while a navigate goal executes; else nothing."""
    n = Part("controller", f"/{robot}", fd)
    pub = n.create_publisher(Twist, f"/{robot}/cmd_vel", 10)
    st: dict = {"goal": None, "pose": None, "active": False, "joy": 0.0}

    def on_path(msg: PathMsg) -> None:
        n.gate()
        if msg.poses:
            st["goal"] = msg.poses[-1].pose.position
            n.get_logger().info(f"new path with {len(msg.poses)} poses")

    def on_pose(msg: PoseWithCovarianceStamped) -> None:
        n.gate()
        st["pose"] = msg.pose.pose

    def on_status(msg: GoalStatusArray) -> None:
        n.gate()
        st["active"] = any(s.status == GoalStatus.STATUS_EXECUTING for s in msg.status_list)

    def on_joy(msg: Twist) -> None:
        st["joy"] = time.monotonic()

    def tick() -> None:
        n.gate()
        if not st["active"]:
            return
        cmd = Twist()
        if st["goal"] is not None and st["pose"] is not None:
            p, q = st["pose"].position, st["pose"].orientation
            yaw = 2.0 * math.atan2(q.z, q.w)
            dx, dy = st["goal"].x - p.x, st["goal"].y - p.y
            err = math.atan2(math.sin(math.atan2(dy, dx) - yaw), math.cos(math.atan2(dy, dx) - yaw))
            cmd.linear.x = min(0.5, math.hypot(dx, dy)) * max(0.0, math.cos(err))
            cmd.angular.z = max(-1.0, min(1.0, 1.5 * err))
            if time.monotonic() - st["joy"] < 0.5:  # an operator on the joystick: slow down
                cmd.linear.x *= 0.5
        pub.publish(cmd)

    n.create_subscription(PathMsg, f"/{robot}/path", on_path, LATCHED)
    n.create_subscription(PoseWithCovarianceStamped, f"/{robot}/pose", on_pose, 10)
    n.create_subscription(GoalStatusArray, f"/{robot}/navigate/_action/status", on_status,
                          qos_profile_action_status_default)
    if robot == "r1":
        n.create_subscription(Twist, "/r1/joy_cmd", on_joy, 10)
    n.create_timer(0.05, tick)
    return n


def odom_filter(fd: Path) -> Part:
    """/r2/odom smoothed to /r2/odom_filtered, keeping the input's stamp."""
    n = Part("odom_filter", "/r2", fd)
    pub = n.create_publisher(Odometry, "/r2/odom_filtered", 10)
    v = [0.0, 0.0]

    def on_odom(msg: Odometry) -> None:
        n.gate()
        v[0] = 0.7 * v[0] + 0.3 * msg.twist.twist.linear.x
        v[1] = 0.7 * v[1] + 0.3 * msg.twist.twist.angular.z
        msg.twist.twist.linear.x, msg.twist.twist.angular.z = v
        if n.fault == "stale":
            t = Time.from_msg(msg.header.stamp) - Duration(seconds=0.8)
            msg.header.stamp = t.to_msg()
        pub.publish(msg)

    n.create_subscription(Odometry, "/r2/odom", on_odom, 10)
    return n


# --- the fleet -------------------------------------------------------------------------------


def manager(fd: Path) -> Part:
    """Goals to both robots with idle gaps of 5-40 s (sim); the /fleet/assign service."""
    n = Part("manager", "/fleet", fd)
    orders = [0]

    def assign(request, response):
        n.gate()
        time.sleep(4.0 if n.fault == "slow_service" else 0.01)
        orders[0] += 1
        response.success = True
        response.message = f"order {orders[0]} assigned to {random.choice(ROBOTS)}"
        return response

    def loaded() -> None:  # the order database takes a few seconds to load
        n.create_service(Trigger, "/fleet/assign", assign)
        n.get_logger().info(f"order database loaded: {random.randint(80, 140)} open orders")
    n.after(3.0, loaded, clock=n.wall)

    def flow(robot: str) -> None:
        client = ActionClient(n, Fibonacci, f"/{robot}/navigate")
        k = [0]

        def idle(low: float = 5.0, high: float = 40.0) -> None:
            n.after(random.uniform(low, high), send)

        def send() -> None:
            n.gate()
            if not client.server_is_ready():
                n.get_logger().warn(f"{robot}: navigate server not available, retrying")
                n.after(2.0, send)
                return
            k[0] += 1
            order = random.randint(4, 10)
            n.get_logger().info(f"{robot}: delivery {k[0]}, {2 * order} s route")
            sent = client.send_goal_async(Fibonacci.Goal(order=order))
            sent.add_done_callback(lambda fut: accepted(fut, order, k[0]))

            def unanswered(waited: float = 10.0, delivery: int = k[0]) -> None:
                if not sent.done():
                    n.get_logger().warn(f"{robot}: delivery {delivery} not acknowledged by the planner "
                                        f"after {waited:.0f} s")
                    n.after(10.0, lambda: unanswered(waited + 10.0))
            n.after(10.0, unanswered)

        def accepted(fut, order: int, delivery: int) -> None:
            handle = fut.result()
            if not handle.accepted:
                n.get_logger().warn(f"{robot}: delivery {delivery} rejected")
                idle()
                return
            state = {"open": True}

            def finished(res) -> None:
                if state["open"]:
                    state["open"] = False
                    n.get_logger().info(f"{robot}: delivery {delivery} done (status {res.result().status})")
                    idle()

            def overdue() -> None:
                if state["open"]:
                    state["open"] = False
                    n.get_logger().warn(f"{robot}: delivery {delivery} overdue, canceling")
                    handle.cancel_goal_async()
                    idle()
            handle.get_result_async().add_done_callback(finished)
            n.after(2.0 * order + 30.0, overdue)

        idle(3.0, 10.0)

    for robot in ROBOTS:
        flow(robot)
    return n


def battery(fd: Path) -> Part:
    """BatteryState per robot at 1 Hz (sim), /fleet/status at 0.2 Hz; r2's pack sags now and then."""
    n = Part("battery", "/fleet", fd)
    pubs = {r: n.create_publisher(BatteryState, f"/{r}/battery", 10) for r in ROBOTS}
    status = n.create_publisher(String, "/fleet/status", 10)
    level = {"r1": 0.92, "r2": 0.81}
    sag = [random.uniform(90.0, 150.0), 0.0]  # sim s of r2's next sag, its end

    def publish() -> None:
        n.gate()
        now = n.sim_s()
        if now >= sag[0]:
            sag[:] = [now + random.uniform(100.0, 140.0), now + 20.0]
        for r, pub in pubs.items():
            level[r] = level[r] - 0.0004 if level[r] > 0.3 else 0.95  # swapped at the dock
            pct = 0.15 if r == "r2" and now < sag[1] else level[r]
            pub.publish(BatteryState(header=Header(stamp=n.stamp()), voltage=22.0 + 3.0 * pct,
                                     percentage=pct, present=True,
                                     power_supply_status=BatteryState.POWER_SUPPLY_STATUS_DISCHARGING))

    def report() -> None:
        n.gate()
        status.publish(String(data=", ".join(f"{r} {100 * level[r]:.0f}%" for r in ROBOTS)))

    n.create_timer(1.0, publish)
    n.create_timer(5.0, report)
    return n


def dispatcher(fd: Path) -> Part:
    """Calls /fleet/assign every 3-10 s (sim), 2 s timeout (wall); ERRORs until the service is up."""
    n = Part("dispatcher", "/fleet", fd)
    client = n.create_client(Trigger, "/fleet/assign")
    pending: dict[Future, float] = {}

    def startup() -> None:
        if not client.service_is_ready():
            n.get_logger().error("assign service not available, retrying")
            return
        boot.cancel()
        n.get_logger().info("assign service available")
        n.after(random.uniform(3.0, 10.0), call)
        n.create_timer(15.0, lambda: n.get_logger().warn(
            f"order queue long: {random.randint(12, 30)} orders waiting"))

    def call() -> None:
        n.gate()
        fut = client.call_async(Trigger.Request())
        pending[fut] = time.monotonic()
        fut.add_done_callback(lambda f: pending.pop(f, None))
        n.after(random.uniform(3.0, 10.0), call)

    def watchdog() -> None:
        for fut, t in list(pending.items()):
            if time.monotonic() - t > 2.0:
                pending.pop(fut, None)
                client.remove_pending_request(fut)
                fut.cancel()
                n.get_logger().error("assign service /fleet/assign did not answer within 2 s")

    boot = n.create_timer(1.0, startup, clock=n.wall)
    n.create_timer(0.25, watchdog, clock=n.wall)
    startup()
    return n


# --- tools -----------------------------------------------------------------------------------


def _msg_type(name: str):
    """``pkg/msg/Type`` → its class, or None when the package is not installed."""
    pkg, kind, typ = name.split("/")
    try:
        return getattr(importlib.import_module(f"{pkg}.{kind}"), typ)
    except (ImportError, AttributeError):
        return None


def recorder(fd: Path) -> Part:
    """Subscribes to every topic it discovers (every 5 s), QoS as its publishers'; wall time."""
    n = Part("recorder", "/tools", fd, sim_time=False)
    subs: dict[str, object] = {}
    count = [0, 0]

    def on_msg(data: bytes) -> None:
        count[0] += 1
        count[1] += len(data)

    def discover() -> None:
        n.gate()
        for name, types in n.get_topic_names_and_types():
            if name in subs or any(part.startswith("_") for part in name.split("/")):
                continue
            infos = n.get_publishers_info_by_topic(name)
            if not infos:
                continue
            typ = _msg_type(types[0])
            if typ is None:
                subs[name] = None
                n.get_logger().warn(f"topic '{name}': unknown type {types[0]}, not recorded")
                continue
            reliable = all(i.qos_profile.reliability == ReliabilityPolicy.RELIABLE for i in infos)
            latched = all(i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos)
            qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE if reliable
                             else ReliabilityPolicy.BEST_EFFORT,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL if latched
                             else DurabilityPolicy.VOLATILE)
            subs[name] = n.create_subscription(typ, name, on_msg, qos, raw=True)
            n.get_logger().info(f"subscribed to topic '{name}'")

    def report() -> None:
        n.gate()
        recorded = sum(1 for s in subs.values() if s is not None)
        n.get_logger().info(f"recording {recorded} topics: {count[0]} messages, {count[1] / 1e6:.1f} MB")

    n.create_timer(5.0, discover)
    n.create_timer(10.0, report)
    discover()
    return n


def diag(fd: Path) -> Part:
    """/diagnostics at 1 Hz (wall): each robot's localization and battery, from their topics."""
    n = Part("diag", "/tools", fd, sim_time=False)
    pub = n.create_publisher(DiagnosticArray, "/diagnostics", 10)
    pose: dict[str, float] = {}
    batt: dict[str, BatteryState] = {}
    for r in ROBOTS:
        n.create_subscription(PoseWithCovarianceStamped, f"/{r}/pose",
                              lambda m, r=r: pose.__setitem__(r, time.monotonic()), 10)
        n.create_subscription(BatteryState, f"/{r}/battery", lambda m, r=r: batt.__setitem__(r, m), 10)

    def status(level: bytes, name: str, hw: str, message: str, **values: str) -> DiagnosticStatus:
        return DiagnosticStatus(level=level, name=name, hardware_id=hw, message=message,
                                values=[KeyValue(key=k, value=v) for k, v in values.items()])

    def publish() -> None:
        n.gate()
        out = []
        for r in ROBOTS:
            if r in pose:
                age = time.monotonic() - pose[r]
                level = DiagnosticStatus.OK if age < 2.0 else \
                    DiagnosticStatus.WARN if age < 5.0 else DiagnosticStatus.ERROR
                out.append(status(level, f"{r}_localizer: localization", f"{r}-lidar-ust10lx",
                                  "localized" if age < 2.0 else f"no pose for {age:.0f} s",
                                  pose_age=f"{age:.2f}"))
            if r in batt:
                pct = batt[r].percentage
                out.append(status(DiagnosticStatus.WARN if pct < 0.2 else DiagnosticStatus.OK,
                                  f"fleet_battery: Battery {r}", f"{r}-bms-0{3 if r == 'r1' else 7}",
                                  "battery low" if pct < 0.2 else "OK",
                                  percentage=f"{100 * pct:.0f}", voltage=f"{batt[r].voltage:.1f}"))
        pub.publish(DiagnosticArray(header=Header(stamp=n.stamp()), status=out))

    n.create_timer(1.0, publish)
    return n


def teleop(fd: Path) -> Part:
    """An operator's joystick: /r1/joy_cmd at 10 Hz (wall)."""
    n = Part("teleop", "/r1", fd, sim_time=False)
    pub = n.create_publisher(Twist, "/r1/joy_cmd", 10)
    n.get_logger().info("joystick connected")

    def tick() -> None:
        n.gate()
        cmd = Twist()
        cmd.linear.x = 0.1 * math.sin(time.monotonic())
        pub.publish(cmd)

    n.create_timer(0.1, tick)
    return n


# process -> (executor, node factories): "single" one SingleThreadedExecutor for all its nodes;
# "isolated" a composed container, a SingleThreadedExecutor per node each in a thread of its own
# (as Nav2's component_container_isolated), or with FLEET_EXECUTOR=multi in the environment one
# MultiThreadedExecutor (each node's callbacks in its node's default, mutually exclusive group)
PROCESSES = {
    "sim": ("isolated", (world, bridge, map_server)),
    "r1_nav": ("isolated", (partial(localizer, robot="r1", odom_topic="/r1/odom"),
                            partial(planner, robot="r1"), partial(controller, robot="r1"))),
    "r2_localizer": ("single", (partial(localizer, robot="r2", odom_topic="/r2/odom_filtered"),)),
    "r2_planner": ("single", (partial(planner, robot="r2"),)),
    "r2_controller": ("single", (partial(controller, robot="r2"),)),
    "r2_odom_filter": ("single", (odom_filter,)),
    "fleet": ("single", (manager, battery)),
    "dispatcher": ("single", (dispatcher,)),
    "tools": ("single", (recorder, diag)),
    "teleop": ("single", (teleop,)),
}


def _burn(fd: Path, process: str) -> None:
    flag = fd / f"{process}.cpu"
    while not flag.exists():
        time.sleep(0.2)
    while True:
        pass


def _leak(fd: Path, process: str) -> None:
    flag = fd / f"{process}.leak"
    while not flag.exists():
        time.sleep(0.2)
    kept = []
    while True:
        kept.append(b"\xab" * (20 << 20))  # written, so resident
        time.sleep(1.0)


def _spin(ex, stop: threading.Event) -> None:
    try:
        while rclpy.ok() and not stop.is_set():
            ex.spin_once(timeout_sec=0.1)
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
    if kind == "single":
        executors: list[Executor] = [SingleThreadedExecutor()]
    elif os.environ.get("FLEET_EXECUTOR") == "multi":
        executors = [MultiThreadedExecutor(num_threads=4)]
    else:
        executors = [SingleThreadedExecutor() for _ in nodes]
    for i, node in enumerate(nodes):
        executors[i % len(executors)].add_node(node)
    stop = threading.Event()
    spinners = [threading.Thread(target=_spin, args=(ex, stop), daemon=True) for ex in executors]
    for watch in (_burn, _leak):
        threading.Thread(target=watch, args=(fd, process), daemon=True).start()
    for t in spinners:
        t.start()
    print("ready", flush=True)
    end = time.monotonic() + run_for if run_for else float("inf")
    try:
        while rclpy.ok() and time.monotonic() < end:
            time.sleep(0.1)
    except KeyboardInterrupt:
        pass
    stop.set()
    for t in spinners:
        t.join(2.0)
    if any(t.is_alive() for t in spinners):  # a hung callback: leave without cleaning up
        os._exit(0)
    for ex in executors:
        ex.shutdown()
    for node in nodes:
        node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
