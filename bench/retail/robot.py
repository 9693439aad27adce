"""The supermarket shelf-scanning inventory robot's processes.

``python -m bench.retail.robot PROCESS FAULT_DIR [RUN_FOR]``; ``python -m bench.retail.robot param_set
FAULT_DIR 0 NODE NAME VALUE`` is the ``ros2 param set`` a technician types (a short-lived CLI process).

One process of the robot described in `bench.retail.run` (its docstring lists every process, node,
topic, QoS and fault). Real rclpy nodes on wall time. A node's fault is read from
``FAULT_DIR/<namespace.name>`` (``rs.shelf_cam_right``, ``diagnostic_aggregator``); a process's CPU
burner and leak from ``FAULT_DIR/<process>.cpu`` / ``FAULT_DIR/<process>.leak``. ``RUN_FOR`` > 0:
the process ends by itself (exit code 0) after that many seconds (the associate's handheld).

The store is a schedule shared by every process through the wall clock (`shelf`, `shopper`): the
shelf segment in front of the cameras (a gap in it, an RFID tag on it) and the shoppers near the
robot; the robot's own motion comes from its odometry.
"""

from __future__ import annotations

import array
import functools
import json
import math
import os
import random
import sys
import threading
import time
from collections import deque
from pathlib import Path

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import (
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
from nav_msgs.msg import Odometry
from nav_msgs.msg import Path as PathMsg
from nav_msgs.srv import GetPlan
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue, SetParametersResult
from rcl_interfaces.srv import SetParameters
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import BatteryState, Image, PointCloud2, PointField
from std_msgs.msg import Bool, Float32, String
from std_srvs.srv import SetBool
from test_msgs.action import Fibonacci

from bench.robot_process import Diagnostics, header, single_threaded, spin, status, to_s, wait_future
from bench.robot_process import on_shutdown_quiet as quiet

NS = "rs"
FAULT_DIR = Path("/tmp")
PROCESS = ""

SENSOR = qos_profile_sensor_data  # best effort, keep last 5
RELIABLE = QoSProfile(depth=10)
COMMAND = QoSProfile(depth=1)
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
TF_STATIC = QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL)

OK, WARN, ERROR, STALE = (DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.ERROR,
                          DiagnosticStatus.STALE)


# ---------------------------------------- helpers


def fault(node: str) -> str:
    """The fault written for ``node`` (fully qualified), '' when none."""
    try:
        return (FAULT_DIR / node.strip("/").replace("/", ".")).read_text().strip()
    except OSError:
        return ""


def yaw_quat(yaw: float) -> Quaternion:
    return Quaternion(z=math.sin(yaw / 2), w=math.cos(yaw / 2))


def tf(parent: str, child: str, x=0.0, y=0.0, z=0.0, yaw=0.0, t: float | None = None) -> TransformStamped:
    m = TransformStamped(header=header(parent, t), child_frame_id=child)
    m.transform.translation.x, m.transform.translation.y, m.transform.translation.z = x, y, z
    m.transform.rotation = yaw_quat(yaw)
    return m


class Every:
    """A throttle: ``ok()`` is True at most once every ``period`` s (RCLCPP_WARN_THROTTLE)."""

    def __init__(self, period: float) -> None:
        self.period, self.last = period, 0.0

    def ok(self) -> bool:
        now = time.time()
        if now - self.last >= self.period:
            self.last = now
            return True
        return False


class Recurring:
    """A healthy robot's occasional log line: ``due()`` True every ``lo``-``hi`` s."""

    def __init__(self, lo: float, hi: float) -> None:
        self.lo, self.hi = lo, hi
        self.next = time.time() + random.uniform(lo, hi)

    def due(self) -> bool:
        if time.time() >= self.next:
            self.next = time.time() + random.uniform(self.lo, self.hi)
            return True
        return False


# ---------------------------------------- the store

SEGMENT_S = 3.0  # the shelf segment (bay) in front of the cameras changes every 3 s of wall time


@functools.lru_cache(maxsize=256)
def shelf(seg: int) -> tuple[bool, bool]:
    """(an out-of-stock gap in it, RFID-tagged) for shelf segment ``seg``."""
    rng = random.Random(seg * 104729 + 7)
    return rng.random() < 0.22, rng.random() < 0.5


@functools.lru_cache(maxsize=64)
def shopper_plan(k: int):
    rng = random.Random(k * 7919 + 3)
    if rng.random() < 0.4:
        return None
    a = rng.uniform(0.0, 20.0)
    return a, a + rng.uniform(4.0, 10.0), rng.uniform(1.2, 3.5)


def shopper(t: float) -> float:
    """The nearest shopper's distance in m at wall time ``t`` (99 when none), 30 s epochs."""
    k = int(t // 30.0)
    p = shopper_plan(k)
    if p is None or not p[0] <= t - k * 30.0 < p[1]:
        return 99.0
    return p[2] + 0.3 * math.sin(t)


# ---------------------------------------- camera_container (single-threaded)

CAMS = {  # camera -> hardware id
    "shelf_cam_left": "basler-ace2 a2A1920-51gcBAS sn 40211873",
    "shelf_cam_center": "basler-ace2 a2A1920-51gcBAS sn 40211877",
    "shelf_cam_right": "basler-ace2 a2A1920-51gcBAS sn 40211902",
}
W, H = 160, 120
TRIGGER_S = 0.2  # the trigger board's 5 Hz pulse
SLOP_S = 0.015


def camera(name: str, hwid: str) -> Node:
    node = Node(name, namespace=NS)
    fqn = f"/{NS}/{name}"
    pub = node.create_publisher(Image, f"{fqn}/image_raw", SENSOR)
    pixels = array.array("B", bytes(W * H))
    st = {"n": 0}
    node.get_logger().info(f"Opened {hwid} ({W}x{H} mono8, hardware trigger on Line1, exposure 4000 us)")

    def grab() -> None:
        now = time.time()
        trig = math.floor((now - 0.03) / TRIGGER_S) * TRIGGER_S  # exposure start = trigger edge
        if fault(fqn) == "drift":  # the trigger input's opto-isolator delays the edge: free-running
            trig += 0.041
        seg = int(trig // SEGMENT_S)
        gap, tagged = shelf(seg)
        pixels[0], pixels[1], pixels[2] = seg % 256, int(gap), int(tagged)
        pub.publish(Image(header=header(f"{name}_optical_frame", trig), height=H, width=W, encoding="mono8",
                          step=W, data=pixels))
        st["n"] += 1

    node.create_timer(TRIGGER_S, grab)
    Diagnostics(node, lambda: [status(OK, f"{name}: {fqn}/image_raw topic status", "Desired frequency met",
                                      hwid, frequency="5.0", frames=st["n"])])
    return node


def camera_container():
    # the cameras' frames are read 0.1 s after each trigger edge
    time.sleep(TRIGGER_S - (time.time() % TRIGGER_S) + 0.1)
    nodes = [camera(n, h) for n, h in CAMS.items()]
    st_node = Node("image_stitcher", namespace=NS)
    log = st_node.get_logger()
    pano_pub = st_node.create_publisher(Image, f"/{NS}/panorama", RELIABLE)
    queues: dict[str, deque] = {n: deque(maxlen=10) for n in CAMS}
    st = {"dropped": 0, "pub": 0, "last_pano": None}
    warn = Every(5.0)
    log.info(f"ApproximateTime synchronizer: 3 inputs, queue 10, slop {SLOP_S:.3f} s")

    def on_image(cam: str):
        def cb(m: Image) -> None:
            queues[cam].append((to_s(m.header.stamp), m))
            t = to_s(m.header.stamp)
            match = {}
            for c, q in queues.items():
                best = min(q, key=lambda e: abs(e[0] - t), default=None)
                if best is None or abs(best[0] - t) > SLOP_S:
                    break
                match[c] = best
            else:
                ts = [e[0] for e in match.values()]
                if max(ts) - min(ts) <= SLOP_S:
                    for c, q in queues.items():
                        while q and q[0][0] <= match[c][0]:
                            q.popleft()
                    stitch([match[c][1] for c in CAMS], min(ts))
                    return
            newest = max((q[-1][0] for q in queues.values() if q), default=t)
            for q in queues.values():
                while q and q[0][0] < newest - 1.0:
                    q.popleft()
                    st["dropped"] += 1
            if st["dropped"] and warn.ok():
                heads = ", ".join(f"{c.removeprefix('shelf_cam_')} {q[-1][0] % 100:.3f}"
                                  for c, q in queues.items() if q)
                log.warn(f"Dropped {st['dropped']} unmatched images: no set within slop {SLOP_S:.3f} s "
                         f"(latest stamps {heads})")
                st["dropped"] = 0

        return cb

    def stitch(imgs: list[Image], t: float) -> None:
        rows = []
        for r in range(H):
            for m in imgs:
                rows.append(bytes(m.data[r * W:(r + 1) * W]))
        pano = Image(header=header("pano_frame", t), height=H, width=3 * W, encoding="mono8", step=3 * W,
                     data=b"".join(rows))
        pano_pub.publish(pano)
        st["pub"] += 1
        st["last_pano"] = pano

    def archive() -> None:  # the audit archive on the USB SSD, every 2 s
        if fault(f"/{NS}/image_stitcher") == "hang":
            threading.Event().wait()  # write() on the hung USB-SSD never returns (task in D state)
        time.sleep(random.uniform(0.003, 0.012))

    for c in CAMS:
        st_node.create_subscription(Image, f"/{NS}/{c}/image_raw", on_image(c), SENSOR)
    st_node.create_timer(2.0, archive)
    return single_threaded(*nodes, st_node)


# ---------------------------------------- perception (multi-threaded container)


def perception():
    lr = Node("label_reader", namespace=NS)
    gd = Node("gap_detector", namespace=NS)
    sd = Node("shopper_detector", namespace=NS)
    motion = {"v": 0.0}

    def on_odom(m: Odometry) -> None:
        motion["v"] = abs(m.twist.twist.linear.x)

    odom_group = MutuallyExclusiveCallbackGroup()
    lr.create_subscription(Odometry, f"/{NS}/odom", on_odom, RELIABLE, callback_group=odom_group)

    # label reader: OCR of the shelf-edge labels and barcode decoding, once per new shelf segment
    ocr_group = MutuallyExclusiveCallbackGroup()
    labels_pub = lr.create_publisher(String, f"/{NS}/label_reader/labels", RELIABLE)
    ls = {"seg": -1, "cpu": False, "n": 0, "ms": 0.0}
    lr.get_logger().info("Loaded text recognition model crnn_shelf_labels_v4 (OpenVINO, GPU)")

    def on_pano_labels(m: Image) -> None:
        seg = m.data[0]
        if motion["v"] < 0.05 or seg == ls["seg"]:
            return
        ls["seg"] = seg
        t0 = time.time()
        time.sleep(random.uniform(0.02, 0.05) * (6 if ls["cpu"] else 1))
        ls["ms"] = (time.time() - t0) * 1000
        n = 3 + seg % 4
        labels = [{"ean": f"40{seg:05d}{i:05d}", "price": round(0.99 + (seg * 7 + i) % 9, 2)}
                  for i in range(n)]
        labels_pub.publish(String(data=json.dumps({"bay": int(seg), "stamp": to_s(m.header.stamp),
                                                   "labels": labels})))
        ls["n"] += 1

    lr.create_subscription(Image, f"/{NS}/panorama", on_pano_labels, RELIABLE, callback_group=ocr_group)
    Diagnostics(lr, lambda: [status(WARN if ls["cpu"] else OK, "label_reader: Text recognition",
                                    "CPU fallback" if ls["cpu"] else "OK", "intel-arc-a370m",
                                    labels=ls["n"], last_ms=round(ls["ms"], 1))], group=odom_group)

    def on_cpu() -> None:
        ls["cpu"] = True
        lr.get_logger().warn("[GPU] clWaitForEvents failed: CL_OUT_OF_RESOURCES; falling back to CPU "
                             "inference for crnn_shelf_labels_v4 (slow)")

    HOOKS["cpu"] = on_cpu

    # gap detector: out-of-stock detections, only when a gap is found
    gap_group = MutuallyExclusiveCallbackGroup()
    det_pub = gd.create_publisher(PoseArray, f"/{NS}/gap_detector/detections", RELIABLE)
    gs = {"seg": -1, "n": 0}
    facings = [4, 6, 3, 8, 5]

    def on_pano_gaps(m: Image) -> None:
        seg, gap = m.data[0], m.data[1]
        if fault(f"/{NS}/gap_detector") == "crash" and facings:
            facings.clear()  # the nightly planogram push arrives truncated: an empty facing table
            gd.get_logger().info("Reloaded planogram /var/lib/rs/planogram/store_0412_v38.json (0 bays)")
        expected = facings[seg % 5] if motion["v"] >= 0.05 else facings[0]
        if motion["v"] < 0.05 or not gap or seg == gs["seg"]:
            return
        gs["seg"] = seg
        p = Pose()
        p.position.x, p.position.y, p.position.z = 0.6, 0.1 * (seg % 7), 0.4 + 0.35 * (seg % 4)
        det_pub.publish(PoseArray(header=m.header, poses=[p] * max(1, expected // 3)))
        gs["n"] += 1
        gd.get_logger().info(f"Out-of-stock gap in bay {seg} ({expected} facings expected)")

    gd.create_subscription(Image, f"/{NS}/panorama", on_pano_gaps, RELIABLE, callback_group=gap_group)

    # shopper detector: people in the lidar's point cloud
    sh_pub = sd.create_publisher(PoseArray, f"/{NS}/shoppers", RELIABLE)
    ss = {"on": False, "id": 0}

    def on_cloud(m: PointCloud2) -> None:
        d = m.data[0] / 10.0  # the nearest person-shaped cluster
        on = d < 4.0
        if on != ss["on"]:
            ss["on"] = on
            if on:
                ss["id"] += 1
                sd.get_logger().info(f"Person track {ss['id']} started at {d:.1f} m")
            else:
                sd.get_logger().info(f"Person track {ss['id']} lost")
        if on:
            p = Pose()
            p.position.x = d
            sh_pub.publish(PoseArray(header=m.header, poses=[p]))

    sd.create_subscription(PointCloud2, f"/{NS}/lidar/points", on_cloud, SENSOR,
                           callback_group=ReentrantCallbackGroup())
    ex = MultiThreadedExecutor(num_threads=2)
    for n in (lr, gd, sd):
        ex.add_node(n)
    return ex


# ---------------------------------------- lidar_driver (lifecycle)

POINTS = 9600  # 16 B a point: 150 KB a cloud


class Lidar(LifecycleNode):
    def __init__(self) -> None:
        super().__init__("lidar", namespace=NS)
        self.declare_parameter("rpm", 600)
        self.declare_parameter("frame_id", "os_lidar")
        self.timer = None
        self.active = False
        self.n = 0
        self.hz = 10.0
        self.data = array.array("B", bytes(POINTS * 16))
        self.add_on_set_parameters_callback(self.on_params)
        self.contam = Recurring(70, 160)

    def on_params(self, params) -> SetParametersResult:
        for p in params:
            if p.name == "rpm":
                if p.value not in (300, 600, 1200):
                    return SetParametersResult(successful=False, reason="rpm must be 300, 600 or 1200")
                self.hz = p.value / 60.0
                self.get_logger().info(f"Setting lidar_mode to 1024x{int(self.hz)} (rpm {p.value}); "
                                       "reinitializing sensor")
                if self.timer is not None:
                    self.timer.cancel()
                    self.destroy_timer(self.timer)
                    self.timer = self.create_timer(1.0 / self.hz, self.scan)
        return SetParametersResult(successful=True)

    def on_configure(self, state) -> TransitionCallbackReturn:
        self.pub = self.create_lifecycle_publisher(PointCloud2, f"/{NS}/lidar/points", SENSOR)
        self.get_logger().info("Connected to os-992109000123.local: OS0-32 firmware v2.5.3, "
                               f"lidar_mode 1024x{int(self.hz)}")
        self.timer = self.create_timer(1.0 / self.hz, self.scan)
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        self.active = True
        self.get_logger().info("Sensor active: streaming")
        return super().on_activate(state)

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        self.active = False
        self.get_logger().info("Sensor standby")
        return super().on_deactivate(state)

    def scan(self) -> None:
        if not self.active:
            return
        now = time.time()
        self.data[0] = min(255, int(shopper(now) * 10))
        self.data[1] = self.n % 256
        m = PointCloud2(header=header("os_lidar", now - 0.05), height=1, width=POINTS, is_dense=True,
                        point_step=16, row_step=POINTS * 16, data=self.data,
                        fields=[PointField(name=c, offset=4 * i, datatype=PointField.FLOAT32, count=1)
                                for i, c in enumerate(("x", "y", "z", "intensity"))])
        self.pub.publish(m)
        self.n += 1
        if self.contam.due():
            self.get_logger().warn("Window blockage detected on 3.1 % of beams (zone 2); clean the window")


def lidar_driver():
    node = Lidar()
    Diagnostics(node, lambda: [status(OK if node.active else WARN, "lidar: Ouster OS0-32 status",
                                      "Streaming" if node.active else "Standby", "os-992109000123",
                                      rpm=node.get_parameter("rpm").value, clouds=node.n)])
    return single_threaded(node)


# ---------------------------------------- base (driver + robot_state_publisher)


def base():
    drv = Node("base_driver", namespace=NS)
    rsp = Node("robot_state_publisher", namespace=NS)
    log = drv.get_logger()
    odom_pub = drv.create_publisher(Odometry, f"/{NS}/odom", RELIABLE)
    tf_pub = drv.create_publisher(TransformStamped, "/tf", RELIABLE)
    bat_pub = drv.create_publisher(BatteryState, f"/{NS}/battery_state", RELIABLE)
    b = {"x": 0.0, "y": 0.0, "th": 0.0, "v": 0.0, "w": 0.0, "cmd_t": 0.0, "soc": 0.78, "charging": False}
    log.info("Opened /dev/ttyACM0: Kinco FD124S drives x2 on CANopen, 250 kbit/s")

    def on_cmd(m: Twist) -> None:
        b["v"], b["w"], b["cmd_t"] = m.linear.x, m.angular.z, time.time()

    def on_state(m: String) -> None:
        b["charging"] = m.data == "charging"

    drv.create_subscription(Twist, f"/{NS}/cmd_vel", on_cmd, RELIABLE)
    drv.create_subscription(String, f"/{NS}/mission_executive/state", on_state, LATCHED)
    period = 1 / 20  # odometry publish_rate 20

    def step() -> None:
        now = time.time()
        if now - b["cmd_t"] > 0.5:
            b["v"] = b["w"] = 0.0
        b["th"] += b["w"] * period
        b["x"] += b["v"] * math.cos(b["th"]) * period
        b["y"] += b["v"] * math.sin(b["th"]) * period
        o = Odometry(header=header("odom", now), child_frame_id="base_link")
        o.pose.pose.position.x, o.pose.pose.position.y = b["x"], b["y"]
        o.pose.pose.orientation = yaw_quat(b["th"])
        o.twist.twist.linear.x, o.twist.twist.angular.z = b["v"], b["w"]
        odom_pub.publish(o)
        tf_pub.publish(tf("odom", "base_link", b["x"], b["y"], 0.0, b["th"], now))

    def battery() -> None:
        b["soc"] = min(1.0, b["soc"] + 0.004) if b["charging"] else max(0.2, b["soc"] - 0.0004)
        bat_pub.publish(BatteryState(header=header("battery"), voltage=24.0 + 3 * b["soc"],
                                     current=6.2 if b["charging"] else -3.1, percentage=b["soc"],
                                     present=True, power_supply_status=1 if b["charging"] else 2))

    drv.create_timer(period, step)
    drv.create_timer(1.0, battery)
    Diagnostics(drv, lambda: [
        status(OK, "base_driver: Motor controller", "OK", "canopen:node_1 kinco-fd124s sn 21C0934",
               velocity=round(b["v"], 2)),
        status(OK, "base_driver: Battery", "Charging" if b["charging"] else "Discharging",
               "bms:0 smart-li-ion 24V 40Ah", soc=round(b["soc"], 3))])
    # robot_state_publisher: the URDF and the fixed frames
    desc = rsp.create_publisher(String, f"/{NS}/robot_description", LATCHED)
    desc.publish(String(data="<robot name='shelfscanner'>...</robot>"))
    static = rsp.create_publisher(TransformStamped, "/tf_static", TF_STATIC)
    for i, c in enumerate(CAMS):
        static.publish(tf("base_link", f"{c}_optical_frame", 0.15, 0.2, 0.4 + 0.5 * i, -math.pi / 2))
    static.publish(tf("base_link", "os_lidar", 0.2, 0.0, 0.35))
    static.publish(tf("base_link", "rfid_antenna", 0.1, 0.25, 0.8, -math.pi / 2))
    return single_threaded(drv, rsp)


# ---------------------------------------- navigation (multi-threaded container)


def navigation():
    loc = Node("localization", namespace=NS)
    planner = Node("planner", namespace=NS)
    follower = Node("path_follower", namespace=NS)
    lm = Node("lifecycle_manager", namespace=NS)

    # localization: odometry + point cloud -> pose at each cloud, map->odom
    loc_group = MutuallyExclusiveCallbackGroup()
    pose_pub = loc.create_publisher(PoseWithCovarianceStamped, f"/{NS}/localization/pose", RELIABLE)
    tf_pub = loc.create_publisher(TransformStamped, "/tf", RELIABLE)
    ls = {"odom": None, "low": Recurring(60, 150)}

    def on_odom(m: Odometry) -> None:
        ls["odom"] = m

    def on_cloud(m: PointCloud2) -> None:
        if ls["odom"] is None:
            return
        p = PoseWithCovarianceStamped(header=header("map", to_s(m.header.stamp)))
        p.pose.pose = ls["odom"].pose.pose
        pose_pub.publish(p)
        tf_pub.publish(tf("map", "odom", 1.5, -0.4, 0.0, 0.01, to_s(m.header.stamp) + 0.1))
        if ls["low"].due():
            loc.get_logger().warn("Scan match score 0.41 below 0.50 (featureless aisle end); "
                                  "increasing odometry weight")

    loc.create_subscription(Odometry, f"/{NS}/odom", on_odom, RELIABLE, callback_group=loc_group)
    loc.create_subscription(PointCloud2, f"/{NS}/lidar/points", on_cloud, SENSOR, callback_group=loc_group)

    # planner: GetPlan service (A* on the store map)
    def compute_path(req, resp):
        if fault(f"/{NS}/planner") == "hang":
            threading.Event().wait()  # the costmap's update thread holds its mutex forever (deadlock)
        time.sleep(random.uniform(0.05, 0.25))
        x0, y0 = req.start.pose.position.x, req.start.pose.position.y
        x1, y1 = req.goal.pose.position.x, req.goal.pose.position.y
        resp.plan = PathMsg(header=header("map"))
        for i in range(21):
            ps = PoseStamped(header=header("map"))
            ps.pose.position.x, ps.pose.position.y = x0 + (x1 - x0) * i / 20, y0 + (y1 - y0) * i / 20
            resp.plan.poses.append(ps)
        return resp

    planner.create_service(GetPlan, f"/{NS}/planner/compute_path", compute_path,
                           callback_group=MutuallyExclusiveCallbackGroup())
    planner.get_logger().info("Loaded store map /opt/rs/maps/store_0412.yaml (612 x 388 @ 0.05 m)")

    # path follower: drives along a new plan for 7 s (cmd_vel_nav 10 Hz while following)
    nav_pub = follower.create_publisher(Twist, f"/{NS}/cmd_vel_nav", COMMAND)
    fs = {"until": 0.0, "following": False}

    def on_plan(m: PathMsg) -> None:
        fs["until"] = time.time() + 7.0
        fs["following"] = True
        follower.get_logger().info(f"Following a new path of {len(m.poses)} poses")

    def follow() -> None:
        if not fs["following"]:
            return
        if time.time() > fs["until"]:
            fs["following"] = False
            nav_pub.publish(Twist())
            follower.get_logger().info("Reached the end of the path")
            return
        cmd = Twist()
        cmd.linear.x = 0.5
        nav_pub.publish(cmd)

    follower.create_subscription(PathMsg, f"/{NS}/plan", on_plan, RELIABLE)
    follower.create_timer(0.1, follow)

    # lifecycle manager: brings the lidar up, pauses it while charging, watches it
    group = ReentrantCallbackGroup()
    log = lm.get_logger()
    change = lm.create_client(ChangeState, f"/{NS}/lidar/change_state", callback_group=group)
    get = lm.create_client(GetState, f"/{NS}/lidar/get_state", callback_group=group)
    health = {"lidar": "unknown"}

    def transition(tid: int) -> bool:
        req = ChangeState.Request()
        req.transition.id = tid
        r = wait_future(change.call_async(req), 5.0)
        return bool(r and r.success)

    def set_active(req, resp):
        verb = "Activating" if req.data else "Deactivating"
        log.info(f"{verb} lidar")
        ok = transition(Transition.TRANSITION_ACTIVATE if req.data else Transition.TRANSITION_DEACTIVATE)
        resp.success, resp.message = ok, "" if ok else f"{verb} lidar failed"
        if not ok:
            log.error(f"Failed to change state for node: lidar ({verb.lower()})")
        return resp

    lm.create_service(SetBool, f"/{NS}/lifecycle_manager/set_active", set_active, callback_group=group)

    @quiet
    def bringup() -> None:
        log.info("Starting managed nodes bringup...")
        while not change.wait_for_service(timeout_sec=2.0):
            log.info("Waiting for service /rs/lidar/change_state...")
        for tid, verb in ((Transition.TRANSITION_CONFIGURE, "Configuring"),
                          (Transition.TRANSITION_ACTIVATE, "Activating")):
            log.info(f"{verb} lidar")
            transition(tid)
        log.info("Managed nodes are active")
        while rclpy.ok():
            time.sleep(2.0)
            r = wait_future(get.call_async(GetState.Request()), 4.0)
            if r is None:
                health["lidar"] = "down"
                log.error("CRITICAL FAILURE: SERVER lidar IS DOWN after not receiving a heartbeat "
                          "for 4000 ms.")
                continue
            health["lidar"] = r.current_state.label

    Diagnostics(lm, lambda: [status(OK if health["lidar"] in ("active", "inactive") else ERROR,
                                    "lifecycle_manager: Managed nodes", health["lidar"], "", **health)],
                period=2.0, group=group)
    threading.Thread(target=bringup, daemon=True, name="bringup").start()
    ex = MultiThreadedExecutor(num_threads=3)
    for n in (loc, planner, follower, lm):
        ex.add_node(n)
    return ex


# ---------------------------------------- safety (speed limiter + velocity mux)


def safety():
    sl = Node("speed_limiter", namespace=NS)
    mux = Node("velocity_mux", namespace=NS)
    reliable = fault(f"/{NS}/speed_limiter") == "reliable"
    qos = QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE) if reliable else SENSOR
    sl.get_logger().info("Loaded parameters from /opt/rs/config/safety.yaml (cloud_qos: "
                         f"{'reliable, depth 5' if reliable else 'sensor_data'}, slow_zone 2.5 m, "
                         "slow_speed 0.30 m/s, max_speed 0.80 m/s)")
    limit_pub = sl.create_publisher(Float32, f"/{NS}/speed_limit", LATCHED)
    st = {"cloud_t": 0.0, "near": 99.0, "near_t": 0.0, "limit": None, "why": "", "mission": "", "idle_t": 0.0}
    stale_warn = Every(5.0)

    def on_cloud(m: PointCloud2) -> None:
        st["cloud_t"] = time.time()

    def on_shoppers(m: PoseArray) -> None:
        st["near"], st["near_t"] = min(p.position.x for p in m.poses), time.time()

    def on_mission(m: String) -> None:
        st["mission"] = m.data
        if m.data in ("charging", "undocking"):
            st["idle_t"] = time.time()

    def check() -> None:
        now = time.time()
        expected_quiet = st["mission"] in ("charging", "undocking") or now - st["idle_t"] < 3.0
        if now - st["cloud_t"] > 0.5 and not expected_quiet:
            limit, why = 0.0, "safety field data stale"
            if stale_warn.ok():
                age = f"for {now - st['cloud_t']:.1f} s" if st["cloud_t"] else "since start"
                sl.get_logger().warn(f"No point cloud on /{NS}/lidar/points {age}: "
                                     "safety field data stale, speed limited to 0.00 m/s")
        elif now - st["near_t"] < 1.0 and st["near"] < 2.5:
            limit, why = 0.3, f"shopper at {st['near']:.1f} m"
        else:
            limit, why = 0.8, "clear"
        if limit != st["limit"]:
            if limit == 0.3:
                sl.get_logger().info(f"Shopper within 2.5 m ({st['near']:.1f} m): speed limit 0.30 m/s")
            elif limit == 0.8 and st["limit"] is not None:
                sl.get_logger().info("Zone clear: speed limit 0.80 m/s")
            st["limit"], st["why"] = limit, why
            limit_pub.publish(Float32(data=limit))

    sl.create_subscription(PointCloud2, f"/{NS}/lidar/points", on_cloud, qos)
    sl.create_subscription(PoseArray, f"/{NS}/shoppers", on_shoppers, RELIABLE)
    sl.create_subscription(String, f"/{NS}/mission_executive/state", on_mission, LATCHED)
    sl.create_timer(0.1, check)
    Diagnostics(sl, lambda: [status(WARN if st["limit"] == 0.0 else OK, "speed_limiter: Safety field",
                                    st["why"], "", limit=st["limit"])])

    out = mux.create_publisher(Twist, f"/{NS}/cmd_vel", RELIABLE)
    active_pub = mux.create_publisher(String, f"/{NS}/velocity_mux/active", LATCHED)
    mx = {"limit": 0.8, "active": None, "t": {"teleop": 0.0, "docking": 0.0, "mission": 0.0}}
    prio = {"teleop": 100, "docking": 50, "mission": 10}

    def on_limit(m: Float32) -> None:
        mx["limit"] = m.data

    def on_input(source: str):
        def cb(m: Twist) -> None:
            now = time.time()
            mx["t"][source] = now
            live = [s for s, t in mx["t"].items() if now - t < 0.5]
            winner = max(live, key=prio.get)
            if winner != mx["active"]:
                mx["active"] = winner
                active_pub.publish(String(data=winner))
                mux.get_logger().info(f"Switched to input '{winner}'")
            if winner != source:
                return
            o = Twist()
            o.angular.z = m.angular.z
            cap = mx["limit"] if source == "mission" else 1.0
            o.linear.x = max(-cap, min(cap, m.linear.x))
            out.publish(o)

        return cb

    def idle() -> None:
        now = time.time()
        if mx["active"] is not None and all(now - t > 0.5 for t in mx["t"].values()):
            mx["active"] = None
            active_pub.publish(String(data="idle"))
            out.publish(Twist())

    active_pub.publish(String(data="idle"))
    mux.create_subscription(Float32, f"/{NS}/speed_limit", on_limit, LATCHED)
    mux.create_subscription(Twist, f"/{NS}/cmd_vel_nav", on_input("mission"), COMMAND)
    mux.create_subscription(Twist, f"/{NS}/cmd_vel_dock", on_input("docking"), COMMAND)
    mux.create_subscription(Twist, f"/{NS}/cmd_vel_teleop", on_input("teleop"), COMMAND)
    mux.create_timer(0.25, idle)
    return single_threaded(sl, mux)


# ---------------------------------------- rfid


def rfid():
    node = Node("rfid_reader", namespace=NS)
    log = node.get_logger()
    fqn = f"/{NS}/rfid_reader"
    reads_pub = node.create_publisher(String, f"/{NS}/rfid/reads", RELIABLE)
    st = {"v": 0.0, "n": 0, "started": time.time(), "dying": 0.0}
    antenna = Recurring(60, 150)
    log.info("Connecting to reader 192.168.20.50:5084 (LLRP)")
    log.info("Impinj R700 connected: 4 antennas, session 1, target A, 30 dBm")

    def on_odom(m: Odometry) -> None:
        st["v"] = abs(m.twist.twist.linear.x)

    def poll() -> None:  # the reader's RO_ACCESS_REPORTs, drained at 20 Hz
        now = time.time()
        if fault(fqn) == "crashloop" and not st["dying"]:
            st["dying"] = max(now + random.uniform(0.2, 0.8), st["started"] + random.uniform(2.0, 3.0))
        if st["dying"] and now >= st["dying"]:
            log.fatal("LLRP: ERROR_MESSAGE from reader: M_FieldError (ROSpec 1: AntennaID 3 not supported); "
                      "reader firmware 8.1.0 rejects the configuration")
            raise RuntimeError("failed to start ROSpec on reader 192.168.20.50")
        if st["v"] < 0.05:
            return
        seg = int(now // SEGMENT_S)
        if not shelf(seg)[1]:
            return
        rng = random.Random(int(now * 20))
        epcs = [f"3034257BF7194E4{seg % 100000:05d}{rng.randrange(100):03d}"
                for _ in range(rng.randint(1, 6))]
        reads_pub.publish(String(data=json.dumps({"antenna": rng.randint(1, 4), "epc": epcs,
                                                  "rssi": rng.randint(-70, -45)})))
        st["n"] += len(epcs)
        if antenna.due():
            log.warn("Antenna 3: reflected power -11.8 dBm above threshold -15.0 dBm (check cable)")

    node.create_subscription(Odometry, f"/{NS}/odom", on_odom, RELIABLE)
    node.create_timer(0.05, poll)
    Diagnostics(node, lambda: [status(OK, "rfid_reader: Impinj R700 link", "Connected",
                                      "impinj-r700 sn 37021120549", tags_read=st["n"])])
    return single_threaded(node)


# ---------------------------------------- docking (action server)


def docking():
    node = Node("dock_server", namespace=NS)
    log = node.get_logger()
    fqn = f"/{NS}/dock_server"
    vel = node.create_publisher(Twist, f"/{NS}/cmd_vel_dock", COMMAND)
    charging_pub = node.create_publisher(Bool, f"/{NS}/dock_server/charging", LATCHED)
    charging_pub.publish(Bool(data=False))
    st = {"contacts": "open", "goals": 0}
    busy = threading.Lock()

    def on_goal(req) -> GoalResponse:
        if busy.locked():
            log.warn("Rejecting dock goal: a docking action is already running")
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def execute(gh):
        with busy:
            dock = gh.request.order != 0
            st["goals"] += 1
            what = "Docking at charger 'dock_aisle_0'" if dock else "Undocking"
            log.info(f"{what}")
            secs, v = (5.0, -0.1) if dock else (2.0, 0.15)
            t0 = time.time()
            if not dock:
                charging_pub.publish(Bool(data=False))
                st["contacts"] = "open"
            while time.time() - t0 < secs:
                if gh.is_cancel_requested:
                    gh.canceled()
                    return Fibonacci.Result(sequence=[5])
                cmd = Twist()
                cmd.linear.x = v
                vel.publish(cmd)
                left = int(100 * (secs - (time.time() - t0)) * abs(v))
                gh.publish_feedback(Fibonacci.Feedback(sequence=[left]))
                time.sleep(0.1)
            vel.publish(Twist())
            if dock:
                if fault(fqn) == "abort":
                    st["contacts"] = "fault"
                    log.error("Charger contacts not detected after docking (contact voltage 0.0 V, expected "
                              "27.5 V): aborting dock")
                    gh.abort()
                    return Fibonacci.Result(sequence=[3])
                st["contacts"] = "charging"
                charging_pub.publish(Bool(data=True))
                log.info("Docked: charging at 27.5 V / 6.2 A")
            else:
                log.info("Undocked")
            gh.succeed()
            return Fibonacci.Result(sequence=[0])

    ActionServer(node, Fibonacci, f"/{NS}/dock_server/dock", execute_callback=execute, goal_callback=on_goal,
                 cancel_callback=lambda _g: CancelResponse.ACCEPT, callback_group=ReentrantCallbackGroup())
    Diagnostics(node, lambda: [status(ERROR if st["contacts"] == "fault" else OK,
                                      "dock_server: Charger contacts", st["contacts"],
                                      "wibotic-tr301 sn WB-4410872", goals=st["goals"])])
    ex = MultiThreadedExecutor(num_threads=3)
    ex.add_node(node)
    return ex


# ---------------------------------------- mission executive

CYCLE_S = 40.0  # three aisle legs of 10 s, then a top-up charge at the dock
AISLES = [(2.0 + 3.0 * i, 1.5) for i in range(12)]


def mission():
    node = Node("mission_executive", namespace=NS)
    log = node.get_logger()
    group = ReentrantCallbackGroup()
    plan_cli = node.create_client(GetPlan, f"/{NS}/planner/compute_path", callback_group=group)
    dock_cli = ActionClient(node, Fibonacci, f"/{NS}/dock_server/dock", callback_group=group)
    lc_cli = node.create_client(SetBool, f"/{NS}/lifecycle_manager/set_active", callback_group=group)
    plan_pub = node.create_publisher(PathMsg, f"/{NS}/plan", RELIABLE)
    state_pub = node.create_publisher(String, f"/{NS}/mission_executive/state", LATCHED)
    st = {"state": "", "pose": None, "aisle": 0}

    def set_state(s: str) -> None:
        if s != st["state"]:
            st["state"] = s
            state_pub.publish(String(data=s))

    def on_pose(m: PoseWithCovarianceStamped) -> None:
        st["pose"] = m.pose.pose

    node.create_subscription(PoseWithCovarianceStamped, f"/{NS}/localization/pose", on_pose, RELIABLE,
                             callback_group=group)

    def leg() -> None:
        a = st["aisle"] % len(AISLES)
        st["aisle"] += 1
        set_state(f"scanning:aisle_{a + 1}")
        req = GetPlan.Request()
        req.start = PoseStamped(header=header("map"))
        if st["pose"] is not None:
            req.start.pose = st["pose"]
        req.goal = PoseStamped(header=header("map"))
        req.goal.pose.position.x, req.goal.pose.position.y = AISLES[a]
        if not plan_cli.service_is_ready():
            log.warn(f"Planner service /{NS}/planner/compute_path not available; skipping aisle {a + 1}")
            return
        r = wait_future(plan_cli.call_async(req), 5.0)
        if r is None:
            log.error(f"Failed to plan to aisle {a + 1}: service /{NS}/planner/compute_path did not answer "
                      "within 5.0 s; skipping aisle")
            return
        plan_pub.publish(r.plan)
        log.info(f"Scanning aisle {a + 1} ({len(r.plan.poses)} poses)")

    def dock_goal(order: int, timeout: float) -> tuple[bool, str]:
        if not dock_cli.wait_for_server(timeout_sec=2.0):
            return False, f"action server /{NS}/dock_server/dock not available"
        gh = wait_future(dock_cli.send_goal_async(Fibonacci.Goal(order=order)), 3.0)
        if gh is None or not gh.accepted:
            return False, "goal rejected"
        res = wait_future(gh.get_result_async(), timeout)
        if res is None:
            return False, f"no result within {timeout:.0f} s"
        if res.status != 4:  # GoalStatus.STATUS_SUCCEEDED
            code = res.result.sequence[0] if res.result.sequence else -1
            how = "aborted" if res.status == 6 else "ended"
            return False, f"goal {how} by /{NS}/dock_server (code {code})"
        return True, ""

    def lidar(active: bool) -> None:
        if lc_cli.service_is_ready():
            wait_future(lc_cli.call_async(SetBool.Request(data=active)), 6.0)

    @quiet
    def worker() -> None:
        for what, ready in ((f"service /{NS}/planner/compute_path", plan_cli.wait_for_service),
                            (f"action server /{NS}/dock_server/dock", dock_cli.wait_for_server)):
            if not ready(timeout_sec=10.0):
                log.warn(f"{what} not available after 10 s; starting anyway")
        t0 = time.time()
        log.info("Mission 'nightly_inventory' started: 12 aisles, top-up charge every 40 s")
        k = 0
        while rclpy.ok():
            base_t = t0 + k * CYCLE_S
            for i in range(3):
                time.sleep(max(0.0, base_t + 10.0 * i - time.time()))
                leg()
            time.sleep(max(0.0, base_t + 28.0 - time.time()))
            set_state("docking")
            log.info("Battery top-up: docking")
            ok, why = dock_goal(1, 15.0)
            if not ok:
                log.error(f"Docking failed: {why}; retrying in 3 s")
                time.sleep(3.0)
                ok, why = dock_goal(1, 15.0)
            if not ok:
                log.error(f"Docking failed twice: {why}; continuing the mission without charging")
                set_state("dock_failed")
            else:
                set_state("charging")
                lidar(False)
                time.sleep(max(0.0, base_t + 36.0 - time.time()))
                lidar(True)
                set_state("undocking")
                ok, why = dock_goal(0, 8.0)
                if not ok:
                    log.error(f"Undocking failed: {why}")
            k += 1
            while t0 + k * CYCLE_S < time.time():
                k += 1

    threading.Thread(target=worker, daemon=True, name="mission").start()
    return single_threaded(node)


# ---------------------------------------- cloud uploader


def cloud():
    node = Node("cloud_uploader", namespace=NS)
    log = node.get_logger()
    node.declare_parameter("upload_period", 10.0)
    node.declare_parameter("endpoint", "https://inventory.store0412.example-retail.com/api/v2/scans")
    status_pub = node.create_publisher(String, f"/{NS}/cloud_uploader/status", RELIABLE)
    buf: list[str] = []
    lock = threading.Lock()
    st = {"period": 10.0, "batch": 0, "sent": 0, "fail": Recurring(60, 140), "link": "OK"}

    def on_params(params) -> SetParametersResult:
        for p in params:
            if p.name == "upload_period":
                st["period"] = float(p.value)
                log.info(f"upload_period set to {p.value:.1f} s")
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(on_params)

    def keep(kind: str):
        def cb(m) -> None:
            with lock:
                buf.append(kind + ":" + (m.data if isinstance(m, String) else str(len(m.poses))))

        return cb

    node.create_subscription(String, f"/{NS}/label_reader/labels", keep("labels"), RELIABLE)
    node.create_subscription(PoseArray, f"/{NS}/gap_detector/detections", keep("gap"), RELIABLE)
    node.create_subscription(String, f"/{NS}/rfid/reads", keep("rfid"), RELIABLE)

    @quiet
    def uploader() -> None:  # the HTTPS client's own thread
        while rclpy.ok():
            time.sleep(st["period"])
            with lock:
                batch = list(buf)
                buf.clear()
            if not batch:
                continue
            if st["fail"].due():
                st["link"] = "retrying"
                url = node.get_parameter("endpoint").value
                log.warn(f"Upload failed: HTTP 503 Service Unavailable from {url}; retrying in 5 s")
                time.sleep(5.0)
            time.sleep(random.uniform(0.3, 0.9))  # POST, gzip JSON
            st["link"] = "OK"
            st["batch"] += 1
            st["sent"] += len(batch)
            size = sum(len(b) for b in batch) // 1024 + 1
            log.info(f"Uploaded batch {st['batch']}: {len(batch)} records ({size} KB)")
            status_pub.publish(String(data=json.dumps({"batch": st["batch"], "records": len(batch)})))

    threading.Thread(target=uploader, daemon=True, name="uploader").start()
    Diagnostics(node, lambda: [status(OK, "cloud_uploader: Upload link", st["link"], "lte0 quectel-em06",
                                      sent=st["sent"], pending=len(buf))])
    return single_threaded(node)


# ---------------------------------------- diagnostics aggregator


def aggregator():
    node = Node("diagnostic_aggregator")
    pub = node.create_publisher(DiagnosticArray, "/diagnostics_agg", RELIABLE)
    seen: dict[str, tuple[float, DiagnosticStatus]] = {}
    groups = (("shelf_cam", "Cameras"), ("lidar", "Sensors"), ("rfid", "Sensors"), ("base_driver", "Base"),
              ("dock", "Base"), ("speed_limiter", "Safety"), ("label_reader", "Perception"),
              ("lifecycle", "Navigation"), ("cloud", "Connectivity"))

    def on_diag(m: DiagnosticArray) -> None:
        now = time.time()
        for s in m.status:
            seen[s.name] = (now, s)

    def publish() -> None:
        now = time.time()
        out, worst = [], {}
        for name, (t, s) in sorted(seen.items()):
            g = next((grp for pre, grp in groups if name.startswith(pre)), "Other")
            level = STALE if now - t > 5.0 else s.level
            out.append(DiagnosticStatus(level=level, name=f"/Shelfscanner/{g}/{name.split(': ', 1)[-1]}",
                                        message="Stale" if level == STALE else s.message,
                                        hardware_id=s.hardware_id, values=s.values))
            worst[g] = max(worst.get(g, OK), level)
        for g, lv in worst.items():
            out.append(DiagnosticStatus(level=lv, name=f"/Shelfscanner/{g}",
                                        message="OK" if lv == OK else "Error"))
        pub.publish(DiagnosticArray(header=header(""), status=out))

    node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, RELIABLE)
    node.create_timer(1.0, publish)
    return single_threaded(node)


# ---------------------------------------- handheld (operator)


def handheld():
    node = Node("associate_handheld", namespace=NS)
    log = node.get_logger()
    log.info("Store associate app connected (Zebra TC58, store 0412)")
    node.create_subscription(DiagnosticArray, "/diagnostics_agg", lambda _m: None, RELIABLE)
    node.create_subscription(String, f"/{NS}/mission_executive/state", lambda _m: None, LATCHED)
    node.create_subscription(PoseArray, f"/{NS}/gap_detector/detections",
                             lambda m: log.info(f"Gap alert: {len(m.poses)} facings to restock"), RELIABLE)
    teleop = node.create_publisher(Twist, f"/{NS}/cmd_vel_teleop", COMMAND)
    params = node.create_client(SetParameters, f"/{NS}/cloud_uploader/set_parameters")
    t0 = time.time()
    st = {"param": False}

    def tick() -> None:
        el = time.time() - t0
        if el > 5.0 and not st["param"] and params.service_is_ready():
            st["param"] = True
            v = random.choice((5.0, 8.0, 15.0))
            p = Parameter(name="upload_period",
                          value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=v))
            params.call_async(SetParameters.Request(parameters=[p]))
            log.info(f"Set /{NS}/cloud_uploader upload_period to {v}")
        if 18.0 < el < 21.0:  # the associate nudges the robot out of a shopper's way
            cmd = Twist()
            cmd.linear.x = -0.2
            teleop.publish(cmd)

    node.create_timer(0.1, tick)
    return single_threaded(node)


# ---------------------------------------- ros2 param set (a technician's CLI call)


def param_set(target: str, name: str, value: str) -> int:
    rclpy.init()
    node = Node(f"_ros2cli_{os.getpid()}")
    cli = node.create_client(SetParameters, f"{target}/set_parameters")
    if not cli.wait_for_service(timeout_sec=5.0):
        print(f"Node not found: {target}", flush=True)
        return 1
    pv = ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=int(value)) if value.isdigit() \
        else ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=value)
    fut = cli.call_async(SetParameters.Request(parameters=[Parameter(name=name, value=pv)]))
    rclpy.spin_until_future_complete(node, fut, timeout_sec=5.0)
    r = fut.result()
    print("Set parameter successful" if r and r.results[0].successful
          else f"Setting parameter failed: {r.results[0].reason if r else 'timeout'}", flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


# ---------------------------------------- process main

PROCESSES = {
    "camera_container": camera_container,
    "perception": perception,
    "lidar_driver": lidar_driver,
    "base": base,
    "navigation": navigation,
    "safety": safety,
    "rfid": rfid,
    "docking": docking,
    "mission": mission,
    "cloud": cloud,
    "diagnostics": aggregator,
    "handheld": handheld,
}
HOOKS: dict = {}  # "cpu" / "leak" -> what the process logs or does when its fault file appears


def main() -> int:
    global FAULT_DIR, PROCESS
    PROCESS, FAULT_DIR = sys.argv[1], Path(sys.argv[2])
    run_for = float(sys.argv[3]) if len(sys.argv) > 3 else 0.0
    if PROCESS == "param_set":
        return param_set(*sys.argv[4:7])
    if PROCESS == "cloud":
        print("Waiting for the LTE modem (wwan0) ...", flush=True)
        time.sleep(12.0)  # the modem comes up before the uploader node exists: it joins late
    rclpy.init()
    spin(PROCESSES[PROCESS](), FAULT_DIR, PROCESS, run_for, HOOKS)


if __name__ == "__main__":
    sys.exit(main())
