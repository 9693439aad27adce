"""The hotel-lobby concierge robot's processes.

``python -m bench.concierge.robot PROCESS FAULT_DIR [RUN_FOR]``.

One process of the robot described in `bench.concierge.run` (its docstring lists every process,
node, topic, QoS and fault). Real rclpy nodes on wall time. A node's fault is read from
``FAULT_DIR/<namespace.name>`` (``cg.vad``, ``hotel_pms_bridge``); a process's CPU burner and leak
from ``FAULT_DIR/<process>.cpu`` / ``FAULT_DIR/<process>.leak``. ``RUN_FOR`` > 0: the process ends
by itself (exit code 0) after that many seconds (the front-desk console).

The guests are a schedule shared by every process through the wall clock (`world`): the head camera
sees a guest's face, the microphones hear what the guest says (the intent is coded in the audio
chunks) and the chest tablet feels the guest's touches, all from the same plan.
"""

from __future__ import annotations

import functools
import json
import math
import os
import random
import sys
import threading
import time
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
    TwistStamped,
)
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from nav_msgs.msg import OccupancyGrid, Odometry
from nav_msgs.msg import Path as PathMsg
from nav_msgs.srv import GetMap
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue, SetParametersResult
from rcl_interfaces.srv import SetParameters
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import CameraInfo, CompressedImage, Image, Imu, JointState, LaserScan
from std_msgs.msg import Bool, Header, String, UInt8MultiArray
from std_srvs.srv import Trigger
from test_msgs.action import Fibonacci
from test_msgs.srv import BasicTypes

from bench.robot_process import (
    Diagnostics,
    header,
    on_shutdown_quiet,
    single_threaded,
    spin,
    stamp,
    status,
    to_s,
    wait_future,
)

NS = "cg"
FAULT_DIR = Path("/tmp")
PROCESS = ""

SENSOR = qos_profile_sensor_data  # best effort, keep last 5
RELIABLE = QoSProfile(depth=10)
COMMAND = QoSProfile(depth=1)
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
TF_STATIC = QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL)

OK, WARN, ERROR, STALE = (
    DiagnosticStatus.OK,
    DiagnosticStatus.WARN,
    DiagnosticStatus.ERROR,
    DiagnosticStatus.STALE,
)


# ---------------------------------------- helpers


def fault(node: str) -> str:
    """The fault written for ``node`` (fully qualified), '' when none."""
    try:
        return (FAULT_DIR / node.strip("/").replace("/", ".")).read_text().strip()
    except OSError:
        return ""


def yaw_quat(yaw: float) -> Quaternion:
    return Quaternion(z=math.sin(yaw / 2), w=math.cos(yaw / 2))


def quat_yaw(q) -> float:
    return 2 * math.atan2(q.z, q.w)


def tf(parent: str, child: str, x=0.0, y=0.0, z=0.0, yaw=0.0, t: float | None = None) -> TransformStamped:
    m = TransformStamped(header=header(parent, t), child_frame_id=child)
    m.transform.translation.x, m.transform.translation.y, m.transform.translation.z = x, y, z
    m.transform.rotation = yaw_quat(yaw)
    return m


# ---------------------------------------- the guests

EPOCH_S = 45.0
INTENTS = ("", "hello", "check_in", "directions", "guide", "late_checkout", "amenity", "goodbye")


@functools.lru_cache(maxsize=64)
def guest_plan(k: int):
    """Epoch ``k``'s guest: (arrives, leaves, [(start, end, intent)], touch) in s of the epoch, or None."""
    rng = random.Random(k * 7919 + 13)
    if rng.random() < 0.15:
        return None
    a = rng.uniform(2.0, 9.0)
    b = a + rng.uniform(22.0, 33.0)
    utts, t, first = [], a + rng.uniform(3.0, 4.5), True
    while t + 3.0 < b:
        if first and rng.random() < 0.4:
            intent = "hello"
        else:
            intent = rng.choices(INTENTS[2:8], weights=(3, 2, 2, 1, 1, 1))[0]
        first = False
        dur = rng.uniform(1.0, 2.4)
        utts.append((t, t + dur, INTENTS.index(intent)))
        t += dur + rng.uniform(7.0, 9.5)
    touch = a + rng.uniform(5.0, 15.0) if rng.random() < 0.4 else None
    return a, b, tuple(utts), touch


def world(t: float):
    """(guest id or 0, intent code being spoken or 0, utterance number, touching) at wall time ``t``."""
    k = int(t // EPOCH_S)
    plan = guest_plan(k)
    if plan is None:
        return 0, 0, 0, False
    off = t - k * EPOCH_S
    a, b, utts, touch = plan
    if not a <= off < b:
        return 0, 0, 0, False
    for i, (s, e, intent) in enumerate(utts):
        if s <= off < e:
            return k, intent, (k * 8 + i) % 65536, False
    return k, 0, 0, touch is not None and touch <= off < touch + 2.0


# ---------------------------------------- controller_manager

LEFT = [
    f"left_{j}_joint"
    for j in ("shoulder_pan", "shoulder_lift", "upper_arm_roll", "elbow", "wrist_pitch", "wrist_roll")
]
RIGHT = [j.replace("left_", "right_") for j in LEFT]
HEAD = ["torso_lift_joint", "head_pan_joint", "head_tilt_joint"]
WHEELS = ["wheel_left_joint", "wheel_right_joint"]
BOARDS = {  # motor board -> (hardware_id, its joints)
    "left_arm_board": ("ethercat:slave_1 elmo-gold-twitter-x6 sn 44A0172", LEFT),
    "right_arm_board": ("ethercat:slave_2 elmo-gold-twitter-x6 sn 44A0175", RIGHT),
    "torso_head_board": ("ethercat:slave_3 elmo-gold-twitter-x3 sn 44A0190", HEAD),
    "base_board": ("can0:node_7 roboteq-sbl2360 sn R2360-1183", WHEELS),
}


class ArmController:
    """A joint_trajectory_controller: ~/follow_joint_trajectory (order = 0.1 s), ~/controller_state."""

    def __init__(self, name: str, joints: list[str]) -> None:
        self.node = Node(name, namespace=NS)
        self.fqn, self.joints = f"/{NS}/{name}", joints
        self.active, self.goal = True, None  # goal: (t0, duration, amplitude)
        self.pos = [0.0] * len(joints)
        self.error_logged = False
        group = ReentrantCallbackGroup()
        self.server = ActionServer(
            self.node,
            Fibonacci,
            f"/{NS}/{name}/follow_joint_trajectory",
            execute_callback=self.execute,
            goal_callback=self.on_goal,
            cancel_callback=lambda _g: CancelResponse.ACCEPT,
            callback_group=group,
        )
        self.state_pub = self.node.create_publisher(JointState, f"/{NS}/{name}/controller_state", RELIABLE)
        self.node.create_timer(0.1, self.publish_state)  # state_publish_rate 10

    def on_goal(self, req) -> GoalResponse:
        if not self.active:
            self.node.get_logger().warn("Can't accept new action goals. Controller is not running.")
            return GoalResponse.REJECT
        self.node.get_logger().info("Received new action goal")
        return GoalResponse.ACCEPT

    def execute(self, gh):
        d = max(0.5, gh.request.order / 10.0)
        self.node.get_logger().info(f"Accepted new action goal ({d:.1f} s trajectory)")
        self.goal = (time.time(), d, 0.4 + 0.1 * (gh.request.order % 3))
        result = Fibonacci.Result()
        while True:
            time.sleep(0.1)
            if not self.active:
                self.node.get_logger().warn("Goal aborted: controller deactivated")
                gh.abort()
                result.sequence = [1]
                return result
            if gh.is_cancel_requested:
                gh.canceled()
                self.goal = None
                result.sequence = [2]
                return result
            if self.goal is None or time.time() - self.goal[0] >= d:
                break
            gh.publish_feedback(Fibonacci.Feedback(sequence=[int(100 * (time.time() - self.goal[0]) / d)]))
        self.goal = None
        self.node.get_logger().info("Goal reached, success!")
        gh.succeed()
        result.sequence = [0]
        return result

    def update(self, now: float) -> bool:
        """One control cycle (the controller manager's loop); False: an error, the controller stops."""
        if fault(self.fqn) == "error" and not self.error_logged:
            self.error_logged = True
            self.node.get_logger().error(
                f"Aborted due to state tolerance violation: joint '{self.joints[3]}' "
                "position error 0.312 rad > "
                "0.250 rad (goal 0.41, actual 0.10); holding position"
            )
            return False
        if self.goal is not None:
            t0, d, amp = self.goal
            s = min(1.0, (now - t0) / d)
            for i in range(len(self.pos)):
                self.pos[i] = amp * math.sin(math.pi * s) * (1.0 if i % 2 else 0.6)
        return True

    def publish_state(self) -> None:
        if self.active:
            self.state_pub.publish(
                JointState(
                    header=header("base_link"),
                    name=self.joints,
                    position=self.pos,
                    velocity=[0.0] * len(self.pos),
                    effort=[0.0] * len(self.pos),
                )
            )


def controller_manager():
    cm = Node("controller_manager", namespace=NS)
    jsb = Node("joint_state_broadcaster", namespace=NS)
    left, right = ArmController("left_arm_controller", LEFT), ArmController("right_arm_controller", RIGHT)
    dd = Node("diff_drive_controller", namespace=NS)
    log = cm.get_logger()
    for c in (
        "joint_state_broadcaster",
        "left_arm_controller",
        "right_arm_controller",
        "diff_drive_controller",
    ):
        log.info(f"Loading controller '{c}'")
    log.info(
        "Activating controllers: [ joint_state_broadcaster left_arm_controller right_arm_controller "
        "diff_drive_controller ]"
    )
    js_pub = jsb.create_publisher(JointState, f"/{NS}/joint_states", RELIABLE)
    odom_pub = dd.create_publisher(Odometry, f"/{NS}/odom", RELIABLE)
    tf_pub = dd.create_publisher(TransformStamped, "/tf", RELIABLE)
    base = {"x": 0.0, "y": 0.0, "th": 0.0, "v": 0.0, "w": 0.0, "cmd_t": 0.0, "wl": 0.0, "wr": 0.0}
    lock = threading.Lock()

    def on_cmd(m: TwistStamped) -> None:
        with lock:
            base["v"], base["w"], base["cmd_t"] = m.twist.linear.x, m.twist.angular.z, time.time()

    dd.create_subscription(TwistStamped, f"/{NS}/diff_drive_controller/cmd_vel", on_cmd, RELIABLE)
    controllers = {"left_arm_controller": left, "right_arm_controller": right}
    states = {
        "joint_state_broadcaster": "active",
        "left_arm_controller": "active",
        "right_arm_controller": "active",
        "diff_drive_controller": "active",
    }
    head = [0.12, 0.0, 0.0]
    stop = threading.Event()
    overrun = {"next": time.time() + random.uniform(60, 140)}

    @on_shutdown_quiet
    def loop() -> None:  # the realtime update loop, 50 Hz
        period, i = 0.02, 0
        nxt = time.monotonic()
        while not stop.is_set():
            nxt += period
            now = time.time()
            for name, c in controllers.items():
                if c.active and not c.update(now):
                    c.active = False
                    states[name] = "inactive"
                    log.error(
                        f"Deactivating following controllers as their update resulted in an error: [ {name} ]"
                    )
            with lock:
                if now - base["cmd_t"] > 0.5:  # cmd_vel_timeout
                    base["v"] = base["w"] = 0.0
                v, w = base["v"], base["w"]
                base["th"] += w * period
                base["x"] += v * math.cos(base["th"]) * period
                base["y"] += v * math.sin(base["th"]) * period
                base["wl"] += (v - w * 0.22) / 0.08 * period
                base["wr"] += (v + w * 0.22) / 0.08 * period
            head[1] = 0.3 * math.sin(now / 7.0)
            js_pub.publish(
                JointState(
                    header=header("", now),
                    name=LEFT + RIGHT + HEAD + WHEELS,
                    position=left.pos + right.pos + head + [base["wl"], base["wr"]],
                )
            )
            if i % 2 == 0:  # odometry publish_rate 25
                o = Odometry(header=header("odom", now), child_frame_id="base_link")
                o.pose.pose.position.x, o.pose.pose.position.y = base["x"], base["y"]
                o.pose.pose.orientation = yaw_quat(base["th"])
                o.twist.twist.linear.x, o.twist.twist.angular.z = v, w
                odom_pub.publish(o)
                tf_pub.publish(tf("odom", "base_link", base["x"], base["y"], 0.0, base["th"], now))
            i += 1
            if now > overrun["next"]:
                overrun["next"] = now + random.uniform(60, 140)
                log.warn(
                    "Overrun detected! The controller manager missed its desired rate of 50 Hz. "
                    "The loop took "
                    f"{random.uniform(21, 29):.2f} ms (missed cycles : 1)."
                )
            time.sleep(max(0.0, nxt - time.monotonic()))
            if nxt < time.monotonic() - 1.0:
                nxt = time.monotonic()

    def list_controllers(_req, resp):
        resp.success, resp.message = True, json.dumps(states)
        return resp

    cm.create_service(Trigger, f"/{NS}/controller_manager/list_controllers", list_controllers)

    def boards():
        for board, (hw, joints) in BOARDS.items():
            temp = 38 + 6 * random.random()
            yield status(
                OK,
                f"controller_manager: {board}",
                "OK",
                hw,
                joints=len(joints),
                temperature=f"{temp:.1f}",
                bus_voltage="48.1",
            )
        bad = [n for n, s in states.items() if s != "active"]
        yield status(
            WARN if bad else OK,
            "controller_manager: Controllers Activity",
            f"inactive: {', '.join(bad)}" if bad else "All controllers are active",
            "",
            **states,
        )

    Diagnostics(cm, boards)
    threading.Thread(target=loop, daemon=True, name="cm_update").start()
    ex = MultiThreadedExecutor(num_threads=4)
    for n in (cm, jsb, left.node, right.node, dd):
        ex.add_node(n)
    return ex


# ---------------------------------------- head_container


def head_container():
    cam = Node("head_camera", namespace=NS)
    det = Node("face_detector", namespace=NS)
    trk = Node("person_tracker", namespace=NS)
    img_pub = cam.create_publisher(Image, f"/{NS}/head_camera/image_raw", SENSOR)
    info_pub = cam.create_publisher(CameraInfo, f"/{NS}/head_camera/camera_info", SENSOR)
    comp_pub = cam.create_publisher(CompressedImage, f"/{NS}/head_camera/image_raw/compressed", SENSOR)
    static = cam.create_publisher(TransformStamped, "/tf_static", TF_STATIC)
    static.publish(tf("head_camera_link", "head_camera_optical_frame", yaw=-math.pi / 2))
    pixels = bytearray(64 * 48 * 3)
    seq = {"n": 0, "lazy": False}
    cam.get_logger().info("Opened /dev/video0 (64x48 rgb8 @ 15 fps, auto exposure)")

    def grab() -> None:
        now = time.time()
        guest = world(now)[0]
        pixels[0] = 200 if guest else 20
        pixels[1] = guest % 256
        h = header("head_camera_optical_frame", now - 0.03)
        img_pub.publish(Image(header=h, height=48, width=64, encoding="rgb8", step=192, data=bytes(pixels)))
        info_pub.publish(CameraInfo(header=h, height=48, width=64, distortion_model="plumb_bob"))
        seq["n"] += 1
        if seq["n"] % 3 == 0:
            subscribed = comp_pub.get_subscription_count() > 0
            if subscribed != seq["lazy"]:
                seq["lazy"] = subscribed
                cam.get_logger().info(
                    "Compressed stream "
                    + ("started (subscriber connected)" if subscribed else "stopped (no subscribers)")
                )
            if subscribed:
                comp_pub.publish(CompressedImage(header=h, format="jpeg", data=bytes(pixels[:1200])))

    cam.create_timer(1 / 15, grab)
    Diagnostics(
        cam,
        lambda: [
            status(
                OK,
                "head_camera: /cg/head_camera/image_raw topic status",
                "Desired frequency met",
                "realsense-d435 sn 047122071356",
                frequency="15.0",
            )
        ],
    )
    faces_pub = det.create_publisher(PoseArray, f"/{NS}/face_detector/faces", RELIABLE)

    def on_image(m: Image) -> None:
        if m.data[0] > 128:
            p = Pose()
            p.position.x, p.position.y, p.position.z = 1.2, 0.05 * math.sin(time.time()), 1.65
            faces_pub.publish(PoseArray(header=m.header, poses=[p]))

    det.create_subscription(Image, f"/{NS}/head_camera/image_raw", on_image, SENSOR)
    people_pub = trk.create_publisher(PoseArray, f"/{NS}/people", RELIABLE)
    present_pub = trk.create_publisher(Bool, f"/{NS}/person_tracker/guest_present", LATCHED)
    present_pub.publish(Bool(data=False))
    track = {"last": 0.0, "id": 0, "since": 0.0, "pose": None, "on": False}

    def on_faces(m: PoseArray) -> None:
        track["last"], track["pose"] = time.time(), m.poses[0]

    def tick() -> None:
        now = time.time()
        on = now - track["last"] < 1.5
        if on != track["on"]:
            track["on"] = on
            if on:
                track["id"] += 1
                track["since"] = now
                trk.get_logger().info(f"Track {track['id']} started (face at 1.2 m)")
            else:
                trk.get_logger().info(f"Track {track['id']} lost after {now - track['since']:.1f} s")
            present_pub.publish(Bool(data=on))
        if on:
            people_pub.publish(PoseArray(header=header("base_link", now), poses=[track["pose"]]))

    def save_gallery() -> None:  # re-identification gallery written to the NAS every 3 s
        if fault(f"/{NS}/person_tracker") == "hang":
            threading.Event().wait()  # the NFS write never returns (hard mount, server gone)
        time.sleep(random.uniform(0.005, 0.02))

    trk.create_subscription(PoseArray, f"/{NS}/face_detector/faces", on_faces, RELIABLE)
    trk.create_timer(0.2, tick)
    trk.create_timer(3.0, save_gallery)
    return single_threaded(cam, det, trk)


# ---------------------------------------- base_sensors


def base_sensors():
    lidar = Node("base_lidar", namespace=NS)
    imu = Node("imu", namespace=NS)
    scan_pub = lidar.create_publisher(LaserScan, f"/{NS}/scan", SENSOR)
    st = {"dirty": time.time() + random.uniform(50, 110), "stale_logged": False}
    lidar.get_logger().info("Connected to SICK TiM571 at 192.168.0.1:2112, 270 beams @ 10 Hz")

    def scan() -> None:
        now = time.time()
        lag = 0.02
        if fault(f"/{NS}/base_lidar") == "stale":
            lag = 2.6  # the scanner's clock lost its PTP sync and free-runs behind: every stamp 2.6 s old
        guest = world(now)[0]
        ranges = [3.0 + 1.5 * math.sin(i / 20.0) for i in range(270)]
        if guest:
            for i in range(125, 146):
                ranges[i] = 0.9
        scan_pub.publish(
            LaserScan(
                header=header("base_laser", now - lag),
                angle_min=-2.35,
                angle_max=2.35,
                angle_increment=4.7 / 270,
                scan_time=0.1,
                range_min=0.05,
                range_max=25.0,
                ranges=ranges,
            )
        )
        if now > st["dirty"]:
            st["dirty"] = now + random.uniform(60, 150)
            lidar.get_logger().warn("Contamination warning: front window partly dirty (level 1)")

    lidar.create_timer(0.1, scan)
    Diagnostics(
        lidar,
        lambda: [
            status(
                OK,
                "base_lidar: /cg/scan topic status",
                "Desired frequency met",
                "sick-tim571 sn 22150471",
                frequency="10.0",
            )
        ],
    )
    imu_pub = imu.create_publisher(Imu, f"/{NS}/imu/data", SENSOR)

    def sample() -> None:
        m = Imu(header=header("imu_link"))
        m.orientation.w = 1.0
        m.linear_acceleration.z = 9.81 + random.gauss(0, 0.02)
        imu_pub.publish(m)

    imu.create_timer(0.02, sample)
    Diagnostics(
        imu,
        lambda: [
            status(
                OK,
                "imu: /cg/imu/data topic status",
                "Desired frequency met",
                "bosch-bmi088 spi1.0",
                frequency="50.0",
            )
        ],
    )
    return single_threaded(lidar, imu)


# ---------------------------------------- speech


class Vad(LifecycleNode):
    """Voice activity detector (lifecycle, autostart): voice chunks and utterance ends while active."""

    def __init__(self) -> None:
        super().__init__("vad", namespace=NS)
        self.active = False
        self.speaking, self.quiet, self.start, self.seq, self.n = False, 0, 0.0, 0, 0
        self.ring = [0] * 64
        self.idx = 0

    def on_configure(self, state) -> TransitionCallbackReturn:
        self.voice_pub = self.create_lifecycle_publisher(UInt8MultiArray, f"/{NS}/speech/voice", RELIABLE)
        self.vad_pub = self.create_publisher(Bool, f"/{NS}/speech/vad", LATCHED)
        self.utt_pub = self.create_publisher(Header, f"/{NS}/speech/utterance", RELIABLE)
        self.vad_pub.publish(Bool(data=False))
        self.create_subscription(UInt8MultiArray, f"/{NS}/audio/raw", self.on_audio, RELIABLE)
        self.get_logger().info("Configured: webrtc VAD mode 2, 64 ms frames, hangover 256 ms")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        self.active = True
        self.get_logger().info("Activated")
        return super().on_activate(state)

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        self.active = False
        if self.speaking:
            self.end()
        self.get_logger().info("Deactivated")
        return super().on_deactivate(state)

    def on_audio(self, m: UInt8MultiArray) -> None:
        if fault(f"/{NS}/vad") == "crash":
            self.idx = len(self.ring) * 256  # a frame count overflowing the ring buffer's index
        self.ring[self.idx % 65536] = m.data[0]  # IndexError once the index is out of range
        self.idx = (self.idx + 1) % len(self.ring)
        if not self.active:
            return
        loud = m.data[0] > 100
        if loud and not self.speaking:
            self.speaking, self.start, self.n = True, time.time(), 0
            self.seq = m.data[2] | (m.data[3] << 8)
            self.vad_pub.publish(Bool(data=True))
        if self.speaking:
            self.n += 1
            self.voice_pub.publish(m)
            self.quiet = 0 if loud else self.quiet + 1
            if self.quiet >= 4:
                self.end()

    def end(self) -> None:
        self.speaking = False
        self.vad_pub.publish(Bool(data=False))
        self.utt_pub.publish(Header(stamp=stamp(self.start), frame_id=f"utt-{self.seq}:{self.n}"))


def speech():
    cap = Node("audio_capture", namespace=NS)
    pub = cap.create_publisher(UInt8MultiArray, f"/{NS}/audio/raw", RELIABLE)
    info = cap.create_publisher(String, f"/{NS}/audio/info", LATCHED)
    info.publish(
        String(data=json.dumps({"sample_rate": 16000, "channels": 1, "format": "S16LE", "chunk": 1024}))
    )
    cap.get_logger().info("Capturing from hw:2,0 (ReSpeaker 4-Mic Array), 16000 Hz, 1024-sample chunks")
    chunk = bytearray(2048)
    st = {"dropped": 0, "logged": 0.0}

    def capture() -> None:
        now = time.time()
        if fault(f"/{NS}/audio_capture") == "degrade" and random.random() < 0.65:
            st["dropped"] += 1024
            if now - st["logged"] > 3.0:
                cap.get_logger().warn(
                    f"overrun!!! (at least {st['dropped'] / 16:.3f} ms long) on capture device "
                    "hw:2,0, dropping frames"
                )
                st["logged"], st["dropped"] = now, 0
            return
        _, intent, utt, _ = world(now)
        chunk[0] = random.randint(150, 220) if intent else random.randint(3, 40)
        chunk[1], chunk[2], chunk[3] = intent, utt & 0xFF, utt >> 8
        pub.publish(UInt8MultiArray(data=bytes(chunk)))

    cap.create_timer(1024 / 16000, capture)
    Diagnostics(
        cap,
        lambda: [
            status(
                OK,
                "audio_capture: ReSpeaker 4-Mic Array",
                "capturing",
                "usb-SEEED_ReSpeaker_4_Mic_Array_v2.0-00",
                rate="16000",
                xruns="0",
            )
        ],
    )
    vad = Vad()
    vad.trigger_configure()
    vad.trigger_activate()
    return single_threaded(cap, vad)


# ---------------------------------------- asr

TEXTS = {
    1: "hello there",
    2: "hi I'd like to check in please",
    3: "where is the restaurant",
    4: "can you take me to the elevators",
    5: "could I get a late checkout",
    6: "can I have more towels",
    7: "thank you goodbye",
}


def asr():
    node = Node("speech_recognizer", namespace=NS)
    node.get_logger().info("Model ggml-small.en loaded (8.1 s), beam size 5, device cuda:0")
    group = ReentrantCallbackGroup()
    heard: dict[int, list[int]] = {}
    st = {"cpu": False, "count": 0}

    def on_voice(m: UInt8MultiArray) -> None:
        seq = m.data[2] | (m.data[3] << 8)
        heard.setdefault(seq, []).append(m.data[1])
        while len(heard) > 20:
            heard.pop(next(iter(heard)))

    def transcribe(req, resp):
        seq_s, _, n_s = req.string_value.removeprefix("utt-").partition(":")
        got = heard.pop(int(seq_s), []) if seq_s.isdigit() else []
        expected = max(1, int(n_s) if n_s.isdigit() else 1)
        time.sleep(random.uniform(0.25, 0.6) * (5 if st["cpu"] else 1))
        intent = max(set(got), key=got.count) if got else 0
        conf = min(1.0, len(got) / expected) * random.uniform(0.78, 0.97)
        resp.string_value = TEXTS.get(intent, "")
        resp.float32_value = conf
        resp.int32_value = intent
        resp.bool_value = bool(got)
        st["count"] += 1
        return resp

    node.create_subscription(UInt8MultiArray, f"/{NS}/speech/voice", on_voice, RELIABLE, callback_group=group)
    node.create_service(BasicTypes, f"/{NS}/speech_recognizer/transcribe", transcribe, callback_group=group)
    Diagnostics(
        node,
        lambda: [
            status(
                WARN if st["cpu"] else OK,
                "speech_recognizer: inference",
                "CPU fallback" if st["cpu"] else "OK",
                "cuda:0",
                transcriptions=st["count"],
            )
        ],
    )

    def on_cpu() -> None:
        st["cpu"] = True
        node.get_logger().warn(
            "CUDA error: an illegal memory access was encountered; falling back to CPU inference (slow)"
        )

    HOOKS["cpu"] = on_cpu
    ex = MultiThreadedExecutor(num_threads=3)
    ex.add_node(node)
    return ex


# ---------------------------------------- hri

PHRASES = [
    ("Welcome to the Grand Lobby Hotel! How can I help you?", 3.2),
    ("Let me look up your booking.", 1.8),
    ("The restaurant is on the first floor, to your left.", 2.8),
    ("Please follow me.", 1.2),
    ("Let me check that for you.", 1.5),
    ("I'll ask housekeeping to bring them up.", 2.2),
    ("Sorry, I didn't catch that. Could you say it again?", 2.6),
    ("Here is your key card. Enjoy your stay!", 2.4),
    ("I'm sorry, I can't reach the reservation system. Please see the front desk.", 3.8),
    ("Your late checkout until 2 pm is confirmed.", 2.5),
    ("Here are the elevators.", 1.4),
    ("Goodbye, have a nice day!", 1.6),
    ("Housekeeping is on the way.", 1.6),
]
REPLY = {
    "hello": 0,
    "check_in": 1,
    "directions": 2,
    "guide": 3,
    "late_checkout": 4,
    "amenity": 5,
    "goodbye": 11,
}


def hri():
    dm = Node("dialogue_manager", namespace=NS)
    tab = Node("chest_tablet", namespace=NS)
    log = dm.get_logger()
    intent_pub = dm.create_publisher(String, f"/{NS}/dialogue/intent", RELIABLE)
    state_pub = dm.create_publisher(String, f"/{NS}/dialogue_manager/state", LATCHED)
    asr_cli = dm.create_client(BasicTypes, f"/{NS}/speech_recognizer/transcribe")
    vad_cli = dm.create_client(ChangeState, f"/{NS}/vad/change_state")
    page_cli = dm.create_client(SetParameters, f"/{NS}/chest_tablet/set_parameters")
    tts = ActionClient(dm, Fibonacci, f"/{NS}/tts/say")
    st = {"state": "", "task": None, "task_t": 0.0, "says": [], "saying": False, "history": []}

    def set_state(s: str) -> None:
        if s != st["state"]:
            st["state"] = s
            state_pub.publish(String(data=json.dumps({"state": s, "t": round(time.time(), 1)})))
            if page_cli.service_is_ready():
                p = Parameter(
                    name="page", value=ParameterValue(type=ParameterType.PARAMETER_STRING, string_value=s)
                )
                page_cli.call_async(SetParameters.Request(parameters=[p]))

    def vad(transition: int) -> None:
        if vad_cli.service_is_ready():
            req = ChangeState.Request()
            req.transition.id = transition
            vad_cli.call_async(req)

    def say(phrase: int) -> None:
        st["says"].append(phrase)
        if not st["saying"]:
            next_say()

    def next_say() -> None:
        if not st["says"]:
            st["saying"] = False
            vad(Transition.TRANSITION_ACTIVATE)
            set_state("listening" if st["state"] != "idle" else "idle")
            return
        phrase = st["says"].pop(0)
        if not tts.server_is_ready():
            log.warn(f"TTS server not available, dropping phrase {phrase}")
            st["says"].clear()
            st["saying"] = False
            return
        if not st["saying"]:
            vad(Transition.TRANSITION_DEACTIVATE)  # no barge-in: do not hear ourselves
        st["saying"] = True
        set_state("speaking")
        fut = tts.send_goal_async(Fibonacci.Goal(order=phrase))

        def accepted(f) -> None:
            gh = f.result()
            if gh is None or not gh.accepted:
                log.warn("TTS goal rejected")
                next_say()
                return
            gh.get_result_async().add_done_callback(lambda _r: next_say())

        fut.add_done_callback(accepted)

    def on_present(m: Bool) -> None:
        if m.data:
            log.info("Guest detected, greeting")
            set_state("greeting")
            say(0)
            intent_pub.publish(String(data=json.dumps({"intent": "hello", "utterance": "greeting"})))
        else:
            log.info("Guest left")
            set_state("idle")

    def on_utterance(m: Header) -> None:
        if not asr_cli.service_is_ready():
            log.warn("Speech recognizer not available, ignoring utterance")
            return
        set_state("thinking")
        t0 = time.time()
        fut = asr_cli.call_async(BasicTypes.Request(string_value=m.frame_id))
        pending = {"done": False}

        def done(f) -> None:
            if pending["done"]:
                return
            pending["done"] = True
            tm.cancel()
            r = f.result()
            if r is None or not r.bool_value or r.float32_value < 0.6:
                conf = r.float32_value if r is not None else 0.0
                log.warn(f"Low ASR confidence {conf:.2f} for {m.frame_id}, asking the guest to repeat")
                say(6)
                return
            intent = INTENTS[r.int32_value] if 0 < r.int32_value < len(INTENTS) else ""
            log.info(
                f"Heard '{r.string_value}' (confidence {r.float32_value:.2f}, {time.time() - t0:.2f} s) "
                f"-> intent {intent}"
            )
            st["history"].append(r.string_value)
            say(REPLY.get(intent, 6))
            if intent:
                st["task"], st["task_t"] = intent, time.time()
                intent_pub.publish(String(data=json.dumps({"intent": intent, "utterance": m.frame_id})))

        def timeout() -> None:
            tm.cancel()
            if pending["done"]:
                return
            pending["done"] = True
            log.warn(f"Speech recognizer did not answer within 5.0 s ({m.frame_id})")
            say(6)

        tm = dm.create_timer(5.0, timeout)
        fut.add_done_callback(done)

    def on_result(m: String) -> None:
        r = json.loads(m.data)
        st["task"] = None
        if r.get("phrase") is not None:
            say(r["phrase"])

    def watch() -> None:
        if st["task"] and time.time() - st["task_t"] > 60.0:
            log.warn(f"No result from the task executive for '{st['task']}' after 60 s")
            st["task"] = None

    def on_touch(m: String) -> None:
        ev = json.loads(m.data)
        if ev.get("button") == "check_in" and ev.get("phase") == "up":
            log.info("Tablet: check-in button")
            st["task"], st["task_t"] = "check_in", time.time()
            intent_pub.publish(String(data=json.dumps({"intent": "check_in", "utterance": "tablet"})))

    dm.create_subscription(Bool, f"/{NS}/person_tracker/guest_present", on_present, LATCHED)
    dm.create_subscription(Header, f"/{NS}/speech/utterance", on_utterance, RELIABLE)
    dm.create_subscription(String, f"/{NS}/task_executive/task_result", on_result, RELIABLE)
    dm.create_subscription(String, f"/{NS}/tablet/touch", on_touch, RELIABLE)
    dm.create_timer(1.0, watch)
    set_state("idle")
    HOOKS["leak"] = lambda: threading.Thread(target=leak_history, args=(st["history"],), daemon=True).start()

    # the chest tablet
    tab.declare_parameter("page", "idle")
    tab.declare_parameter("brightness", 0.8)
    page_pub = tab.create_publisher(String, f"/{NS}/chest_tablet/page", LATCHED)
    touch_pub = tab.create_publisher(String, f"/{NS}/tablet/touch", RELIABLE)
    page_pub.publish(String(data="idle"))

    def on_params(params) -> SetParametersResult:
        for p in params:
            if p.name == "page":
                page_pub.publish(String(data=p.value))
        return SetParametersResult(successful=True)

    tab.add_on_set_parameters_callback(on_params)
    touching = {"on": False, "n": 0}

    def touch() -> None:
        on = world(time.time())[3]
        if on:
            touching["n"] += 1
            touch_pub.publish(
                String(
                    data=json.dumps(
                        {
                            "button": "check_in" if touching["n"] % 4 == 0 else "scroll",
                            "phase": "up" if touching["n"] % 2 == 0 else "down",
                            "x": random.randint(0, 1280),
                            "y": random.randint(0, 800),
                        }
                    )
                )
            )
        touching["on"] = on

    tab.create_timer(0.25, touch)
    return single_threaded(dm, tab)


def leak_history(history: list) -> None:
    """The dialogue context (audio features and transcripts) kept for every turn and never trimmed."""
    while True:
        history.append(b"x" * 300_000)
        time.sleep(0.1)


# ---------------------------------------- tts


def tts():
    node = Node("tts", namespace=NS)
    log = node.get_logger()
    node.declare_parameter("volume", 0.8)
    node.declare_parameter("voice", "en_US-amy-medium")

    def on_params(params) -> SetParametersResult:
        for p in params:
            if p.name == "volume":
                log.info(f"Volume set to {p.value:.2f}")
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(on_params)
    audio = node.create_publisher(UInt8MultiArray, f"/{NS}/audio/tts_out", RELIABLE)
    speaking = node.create_publisher(Bool, f"/{NS}/tts/speaking", LATCHED)
    speaking.publish(Bool(data=False))
    lock = threading.Lock()
    log.info("Loading voice 'en_US-amy-medium' (piper, 22050 Hz)")
    started = time.time()
    dying = {"at": 0.0}

    def device() -> None:  # the output device is re-checked before each buffer: a busy device aborts
        if not dying["at"] and fault(f"/{NS}/tts") == "crashloop":
            dying["at"] = max(time.time() + random.uniform(0.3, 1.0), started + random.uniform(2.0, 3.0))
        if dying["at"] and time.time() >= dying["at"]:
            log.fatal("ALSA: snd_pcm_open(plughw:1,0) failed: Device or resource busy")
            sys.stderr.write(
                "terminate called after throwing an instance of 'std::runtime_error'\n"
                "  what():  audio output device unavailable\n"
            )
            sys.stderr.flush()
            os._exit(134)

    node.create_timer(0.25, device)

    def execute(gh):
        text, secs = PHRASES[gh.request.order % len(PHRASES)]
        with lock:
            log.info(f"Saying: '{text}'")
            speaking.publish(Bool(data=True))
            t0, words, chunk = time.time(), text.split(), bytes(2048)
            while time.time() - t0 < secs:
                audio.publish(UInt8MultiArray(data=chunk))
                gh.publish_feedback(
                    Fibonacci.Feedback(sequence=[int(len(words) * (time.time() - t0) / secs)])
                )
                time.sleep(1 / 16)
            speaking.publish(Bool(data=False))
        gh.succeed()
        return Fibonacci.Result(sequence=[0])

    ActionServer(
        node, Fibonacci, f"/{NS}/tts/say", execute_callback=execute, callback_group=ReentrantCallbackGroup()
    )
    Diagnostics(node, lambda: [status(OK, "tts: audio output", "OK", "usb-Jabra_SPEAK_510-00")])
    ex = MultiThreadedExecutor(num_threads=3)
    ex.add_node(node)
    return ex


# ---------------------------------------- executive

PLACES = {"home": (0.0, 0.0), "elevators": (5.5, 2.5), "restaurant": (-3.5, 4.0), "front_desk": (2.5, -2.5)}
PLACE_IDX = list(PLACES)


def executive():
    node = Node("task_executive", namespace=NS)
    log = node.get_logger()
    group = ReentrantCallbackGroup()
    nav = ActionClient(node, Fibonacci, f"/{NS}/navigate_to_pose", callback_group=group)
    arms = {
        s: ActionClient(
            node, Fibonacci, f"/{NS}/{s}_arm_controller/follow_joint_trajectory", callback_group=group
        )
        for s in ("left", "right")
    }
    pms = {
        s: node.create_client(BasicTypes, f"/hotel/{s}", callback_group=group)
        for s in ("lookup_booking", "encode_key", "request_service")
    }
    names = {
        id(nav): f"/{NS}/navigate_to_pose",
        **{id(c): f"/{NS}/{s}_arm_controller/follow_joint_trajectory" for s, c in arms.items()},
    }
    status_pub = node.create_publisher(String, f"/{NS}/task_executive/status", LATCHED)
    result_pub = node.create_publisher(String, f"/{NS}/task_executive/task_result", RELIABLE)
    bt_pub = node.create_publisher(String, f"/{NS}/task_executive/bt_log", RELIABLE)
    queue: list[dict] = []
    cond = threading.Condition()
    st = {"status": ""}

    def set_status(s: str, **kw) -> None:
        if s != st["status"]:
            st["status"] = s
            status_pub.publish(String(data=json.dumps({"status": s, **kw})))

    def bt(name: str, state: str) -> None:
        bt_pub.publish(String(data=json.dumps({"node": name, "status": state, "t": round(time.time(), 2)})))

    def on_intent(m: String) -> None:
        it = json.loads(m.data)
        with cond:
            if len(queue) >= 3:
                dropped = queue.pop(0)
                log.warn(f"Task queue full, dropping '{dropped['intent']}'")
            queue.append(it)
            cond.notify()

    def action(client: ActionClient, order: int, what: str, timeout: float) -> int:
        bt(what, "RUNNING")
        server = names[id(client)]
        if not client.wait_for_server(timeout_sec=1.0):
            log.error(f"{what}: action server {server} not available")
            bt(what, "FAILURE")
            return 9
        gh = wait_future(client.send_goal_async(Fibonacci.Goal(order=order)), 3.0)
        if gh is None or not gh.accepted:
            log.error(f"{what}: goal rejected by {server}")
            bt(what, "FAILURE")
            return 8
        res = wait_future(gh.get_result_async(), timeout)
        if res is None:
            log.error(f"{what}: no result within {timeout:.0f} s, canceling")
            gh.cancel_goal_async()
            bt(what, "FAILURE")
            return 7
        code = res.result.sequence[0] if len(res.result.sequence) else 0
        bt(what, "SUCCESS" if code == 0 else "FAILURE")
        return code

    def call(service: str, timeout: float, **fields):
        cli = pms[service]
        bt(service, "RUNNING")
        if not cli.wait_for_service(timeout_sec=1.0):
            log.error(f"{service}: service /hotel/{service} not available")
            bt(service, "FAILURE")
            return None
        r = wait_future(cli.call_async(BasicTypes.Request(**fields)), timeout)
        if r is None:
            log.error(f"{service}: service /hotel/{service} did not answer within {timeout:.1f} s")
        bt(service, "SUCCESS" if r is not None and r.bool_value else "FAILURE")
        return r

    def run(intent: str) -> int | None:
        if intent in ("hello", "goodbye"):
            action(arms["right"], 20, "wave", 8.0)
            return None
        if intent == "directions":
            action(arms["left"], 15, "point", 8.0)
            return None
        if intent == "guide":
            code = action(nav, PLACE_IDX.index("elevators"), "navigate_to_elevators", 60.0)
            if code != 0:
                log.warn(f"Guiding failed (code {code}), returning to the post")
            action(nav, 0, "navigate_home", 60.0)
            return 10 if code == 0 else 8
        if intent in ("check_in", "late_checkout"):
            r = call("lookup_booking", 5.0, string_value=f"guest-{random.randint(1000, 9999)}")
            if r is None:
                return 8
            if intent == "late_checkout":
                return 9 if call("request_service", 5.0, string_value="late_checkout") is not None else 8
            r = call("encode_key", 8.0, string_value=r.string_value, int32_value=r.int32_value)
            if r is None:
                return 8
            action(arms["right"], 15, "hand_over_key", 8.0)
            return 7
        if intent == "amenity":
            return 12 if call("request_service", 5.0, string_value="towels") is not None else 8
        return None

    def worker() -> None:
        while True:
            with cond:
                while not queue:
                    set_status("idle")
                    cond.wait()
                it = queue.pop(0)
            intent = it.get("intent", "")
            set_status("busy", task=intent)
            log.info(f"Starting task '{intent}'")
            t0 = time.time()
            try:
                phrase = run(intent)
            except Exception as e:  # a task's error must not end the executive
                log.error(f"Task '{intent}' failed: {e}")
                phrase = 8
            ok = phrase not in (8,)
            if ok:
                log.info(f"Task '{intent}' succeeded in {time.time() - t0:.1f} s")
            else:
                log.warn(f"Task '{intent}' failed in {time.time() - t0:.1f} s")
            result_pub.publish(String(data=json.dumps({"task": intent, "ok": ok, "phrase": phrase})))

    node.create_subscription(String, f"/{NS}/dialogue/intent", on_intent, RELIABLE, callback_group=group)
    threading.Thread(target=worker, daemon=True, name="bt_worker").start()
    ex = MultiThreadedExecutor(num_threads=3)
    ex.add_node(node)
    return ex


# ---------------------------------------- navigation


class MapServer(LifecycleNode):
    def __init__(self) -> None:
        super().__init__("map_server", namespace=NS)

    def on_configure(self, state) -> TransitionCallbackReturn:
        self.pub = self.create_lifecycle_publisher(OccupancyGrid, f"/{NS}/map", LATCHED)
        self.grid = OccupancyGrid(header=header("map"))
        self.grid.info.resolution, self.grid.info.width, self.grid.info.height = 0.1, 200, 150
        self.grid.info.origin.position.x, self.grid.info.origin.position.y = -10.0, -7.5
        self.grid.data = [0] * (200 * 150)
        self.create_service(GetMap, f"/{NS}/map_server/map", self.get_map)
        self.get_logger().info("Loading yaml file: /opt/cg/maps/lobby_level0.yaml (200 x 150 @ 0.10 m)")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        r = super().on_activate(state)
        self.pub.publish(self.grid)
        return r

    def get_map(self, _req, resp):
        resp.map = self.grid
        return resp


class Localization(LifecycleNode):
    """Scan-matching localisation: pose at each scan while moving (10 Hz), 1 Hz still; map->odom on /tf."""

    def __init__(self) -> None:
        super().__init__("localization", namespace=NS)
        self.active = False
        self.odom = None
        self.moved_t = 0.0
        self.last_pub = 0.0
        self.drop_log = 0.0

    def on_configure(self, state) -> TransitionCallbackReturn:
        group = MutuallyExclusiveCallbackGroup()
        self.pose_pub = self.create_lifecycle_publisher(
            PoseWithCovarianceStamped, f"/{NS}/localization/pose", RELIABLE
        )
        self.tf_pub = self.create_publisher(TransformStamped, "/tf", RELIABLE)
        self.create_subscription(LaserScan, f"/{NS}/scan", self.on_scan, SENSOR, callback_group=group)
        self.create_subscription(Odometry, f"/{NS}/odom", self.on_odom, RELIABLE, callback_group=group)
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        self.active = True
        self.get_logger().info("Activating: waiting for the first scan and odometry")
        return super().on_activate(state)

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        self.active = False
        return super().on_deactivate(state)

    def on_odom(self, m: Odometry) -> None:
        self.odom = m
        if abs(m.twist.twist.linear.x) > 0.01 or abs(m.twist.twist.angular.z) > 0.01:
            self.moved_t = time.time()

    def on_scan(self, m: LaserScan) -> None:
        if not self.active or self.odom is None:
            return
        if fault(f"/{NS}/localization") == "deactivate":
            self.get_logger().error(
                "Scan matching diverged: best match score 0.08 < 0.30 for 50 consecutive "
                "scans; deactivating, relocalization required"
            )
            self.trigger_deactivate()
            return
        now = time.time()
        if now - to_s(m.header.stamp) > 0.5:
            if now - self.drop_log > 2.0:
                self.drop_log = now
                self.get_logger().warn(
                    "Message Filter dropping message: frame 'base_laser' at time "
                    f"{to_s(m.header.stamp):.3f} for "
                    "reason 'the timestamp on the message is earlier than all the data in the "
                    "transform cache'"
                )
            return
        if now - self.moved_t > 1.0 and now - self.last_pub < 1.0:
            return
        self.last_pub = now
        p = PoseWithCovarianceStamped(header=header("map", to_s(m.header.stamp)))
        p.pose.pose = self.odom.pose.pose
        self.pose_pub.publish(p)
        self.tf_pub.publish(tf("map", "odom", 0.02, -0.01, 0.0, 0.003, to_s(m.header.stamp) + 0.2))


class Navigator(LifecycleNode):
    """navigate_to_pose (order = place index), a straight-line plan and a pursuit controller at 20 Hz."""

    def __init__(self) -> None:
        super().__init__("navigator", namespace=NS)
        self.active = False
        self.pose = None
        self.pose_t = 0.0

    def on_configure(self, state) -> TransitionCallbackReturn:
        self.cmd_pub = self.create_lifecycle_publisher(Twist, f"/{NS}/cmd_vel_nav", COMMAND)
        self.plan_pub = self.create_lifecycle_publisher(PathMsg, f"/{NS}/plan", RELIABLE)
        self.create_subscription(
            PoseWithCovarianceStamped, f"/{NS}/localization/pose", self.on_pose, RELIABLE
        )
        self.server = ActionServer(
            self,
            Fibonacci,
            f"/{NS}/navigate_to_pose",
            execute_callback=self.execute,
            goal_callback=self.on_goal,
            cancel_callback=lambda _g: CancelResponse.ACCEPT,
            callback_group=ReentrantCallbackGroup(),
        )
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        self.active = True
        return super().on_activate(state)

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        self.active = False
        return super().on_deactivate(state)

    def on_pose(self, m: PoseWithCovarianceStamped) -> None:
        self.pose, self.pose_t = m.pose.pose, time.time()

    def on_goal(self, req) -> GoalResponse:
        if not self.active:
            self.get_logger().warn("Received goal request but the navigator is not active, rejecting")
            return GoalResponse.REJECT
        if time.time() - self.pose_t > 3.0:
            self.get_logger().error(
                f"Initial robot pose is not available (last pose {time.time() - self.pose_t:.1f} "
                "s old), rejecting goal"
            )
            return GoalResponse.REJECT
        return GoalResponse.ACCEPT

    def execute(self, gh):
        name = PLACE_IDX[gh.request.order % len(PLACE_IDX)]
        gx, gy = PLACES[name]
        log = self.get_logger()
        log.info(f"Begin navigating to '{name}' ({gx:.1f}, {gy:.1f})")
        result = Fibonacci.Result(sequence=[0])
        last_plan, progress_t, progress_d = 0.0, time.time(), None
        while True:
            now = time.time()
            if not self.active:
                gh.abort()
                result.sequence = [6]
                return result
            if gh.is_cancel_requested:
                self.cmd_pub.publish(Twist())
                gh.canceled()
                result.sequence = [5]
                return result
            if now - self.pose_t > 1.5:
                self.cmd_pub.publish(Twist())
                log.error(
                    f"Robot pose is {now - self.pose_t:.1f} s old (localization): localization lost, aborting"
                )
                gh.abort()
                result.sequence = [3]
                return result
            x, y, th = self.pose.position.x, self.pose.position.y, quat_yaw(self.pose.orientation)
            d = math.hypot(gx - x, gy - y)
            if progress_d is None or progress_d - d > 0.2:
                progress_d, progress_t = d, now
            elif now - progress_t > 10.0:
                self.cmd_pub.publish(Twist())
                log.error("Failed to make progress: the robot moved less than 0.2 m in 10 s")
                gh.abort()
                result.sequence = [2]
                return result
            if d < 0.2:
                self.cmd_pub.publish(Twist())
                log.info(f"Goal '{name}' succeeded")
                gh.succeed()
                return result
            if now - last_plan > 2.0:
                last_plan = now
                path = PathMsg(header=header("map"))
                for i in range(11):
                    ps = PoseStamped(header=path.header)
                    ps.pose.position.x, ps.pose.position.y = x + (gx - x) * i / 10, y + (gy - y) * i / 10
                    path.poses.append(ps)
                self.plan_pub.publish(path)
                gh.publish_feedback(Fibonacci.Feedback(sequence=[int(d * 100)]))
            err = math.atan2(
                math.sin(math.atan2(gy - y, gx - x) - th), math.cos(math.atan2(gy - y, gx - x) - th)
            )
            cmd = Twist()
            cmd.angular.z = max(-0.8, min(0.8, 1.5 * err))
            cmd.linear.x = min(0.5, d) if abs(err) < 0.35 else 0.0
            self.cmd_pub.publish(cmd)
            time.sleep(0.05)


def navigation():
    ms, loc, navr = MapServer(), Localization(), Navigator()
    lm = Node("lifecycle_manager_navigation", namespace=NS)
    log = lm.get_logger()
    group = ReentrantCallbackGroup()
    managed = ("map_server", "localization", "navigator")
    change = {
        n: lm.create_client(ChangeState, f"/{NS}/{n}/change_state", callback_group=group) for n in managed
    }
    get = {n: lm.create_client(GetState, f"/{NS}/{n}/get_state", callback_group=group) for n in managed}
    health = {n: "unknown" for n in managed}
    warned: dict[str, str] = {}

    def bringup() -> None:
        time.sleep(0.5)
        for tid, verb in (
            (Transition.TRANSITION_CONFIGURE, "Configuring"),
            (Transition.TRANSITION_ACTIVATE, "Activating"),
        ):
            for n in managed:
                log.info(f"{verb} {n}")
                change[n].wait_for_service(timeout_sec=5.0)
                req = ChangeState.Request()
                req.transition.id = tid
                wait_future(change[n].call_async(req), 5.0)
        log.info("Managed nodes are active")
        while True:
            time.sleep(2.0)
            for n in managed:
                r = wait_future(get[n].call_async(GetState.Request()), 4.0)
                if r is None:
                    health[n] = "down"
                    log.error(
                        f"CRITICAL FAILURE: SERVER {n} IS DOWN after not receiving a heartbeat for 4000 ms."
                    )
                    continue
                health[n] = r.current_state.label
                if health[n] != "active" and warned.get(n) != health[n]:
                    log.warn(f"Managed node '{n}' reports state '{health[n]}', expected 'active'")
                warned[n] = health[n]

    Diagnostics(
        lm,
        lambda: [
            status(
                OK if all(v == "active" for v in health.values()) else ERROR,
                "lifecycle_manager_navigation: Nav2 Health",
                "Nav2 is active" if all(v == "active" for v in health.values()) else "Nav2 is inactive",
                "",
                **health,
            )
        ],
        period=2.0,
    )
    threading.Thread(target=bringup, daemon=True, name="bringup").start()
    ex = MultiThreadedExecutor(num_threads=4)
    for n in (ms, loc, navr, lm):
        ex.add_node(n)
    return ex


# ---------------------------------------- safety


def safety():
    cm = Node("collision_monitor", namespace=NS)
    mux = Node("velocity_mux", namespace=NS)
    reliable = fault(f"/{NS}/collision_monitor") == "reliable"
    qos = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE) if reliable else SENSOR
    cm.get_logger().info(
        "Loaded parameters from /opt/cg/config/safety.yaml (scan_qos: "
        f"{'reliable, depth 10' if reliable else 'sensor_data'}, stop_distance 0.30 m)"
    )
    stop_pub = cm.create_publisher(Bool, f"/{NS}/safety/stop", LATCHED)
    st = {"scan_t": 0.0, "stamp": 0.0, "near": 9.0, "stop": None, "why": ""}

    def on_scan(m: LaserScan) -> None:
        st["scan_t"], st["stamp"] = time.time(), to_s(m.header.stamp)
        st["near"] = min(m.ranges[120:151])

    def check() -> None:
        now = time.time()
        why = []
        if now - st["scan_t"] > 0.5 or now - st["stamp"] > 0.5:
            why.append("scan data stale")
        if st["near"] < 0.3:
            why.append(f"obstacle at {st['near']:.2f} m")
        stop = bool(why)
        if stop != st["stop"]:
            if stop:
                cm.get_logger().warn(f"Protective stop: {', '.join(why)}")
            elif st["stop"] is not None:
                cm.get_logger().info("Protective stop cleared")
            st["stop"], st["why"] = stop, ", ".join(why)
            stop_pub.publish(Bool(data=stop))

    cm.create_subscription(LaserScan, f"/{NS}/scan", on_scan, qos)
    cm.create_timer(0.1, check)
    Diagnostics(
        cm,
        lambda: [
            status(
                WARN if st["stop"] else OK,
                "collision_monitor: Protective field",
                st["why"] or "clear",
                "",
                stop=st["stop"],
            )
        ],
    )
    out = mux.create_publisher(TwistStamped, f"/{NS}/diff_drive_controller/cmd_vel", RELIABLE)
    active_pub = mux.create_publisher(String, f"/{NS}/velocity_mux/active", LATCHED)
    mx = {"stop": False, "active": None, "t": {"teleop": 0.0, "navigation": 0.0}}
    prio = {"teleop": 100, "navigation": 10}

    def on_stop(m: Bool) -> None:
        mx["stop"] = m.data

    def on_input(source: str):
        def cb(m: Twist) -> None:
            now = time.time()
            mx["t"][source] = now
            live = [s for s, t in mx["t"].items() if now - t < 0.5]
            winner = max(live, key=prio.get)
            if winner != mx["active"]:
                mx["active"] = winner
                active_pub.publish(String(data=winner))
            if winner != source:
                return
            o = TwistStamped(header=header("base_link", now))
            if not mx["stop"]:
                o.twist = m
            out.publish(o)

        return cb

    def idle() -> None:
        now = time.time()
        if mx["active"] is not None and all(now - t > 0.5 for t in mx["t"].values()):
            mx["active"] = None
            active_pub.publish(String(data="idle"))
            out.publish(TwistStamped(header=header("base_link", now)))

    active_pub.publish(String(data="idle"))
    mux.create_subscription(Bool, f"/{NS}/safety/stop", on_stop, LATCHED)
    mux.create_subscription(Twist, f"/{NS}/cmd_vel_nav", on_input("navigation"), COMMAND)
    mux.create_subscription(Twist, f"/{NS}/cmd_vel_teleop", on_input("teleop"), COMMAND)
    mux.create_timer(0.25, idle)
    return single_threaded(cm, mux)


# ---------------------------------------- state_publisher


def state_publisher():
    node = Node("robot_state_publisher", namespace=NS)
    node.declare_parameter("publish_frequency", 10.0)
    desc = node.create_publisher(String, f"/{NS}/robot_description", LATCHED)
    desc.publish(String(data="<robot name='concierge'>" + "<link name='l'/>" * 40 + "</robot>"))
    static = node.create_publisher(TransformStamped, "/tf_static", TF_STATIC)
    for parent, child, x, z in (
        ("base_link", "base_laser", 0.25, 0.2),
        ("base_link", "imu_link", 0.0, 0.15),
        ("base_link", "torso_link", 0.0, 0.6),
        ("torso_link", "tablet_link", 0.15, 0.3),
        ("head_link", "head_camera_link", 0.08, 0.1),
        ("head_link", "mic_array_link", 0.0, 0.15),
    ):
        static.publish(tf(parent, child, x, 0.0, z))
    pub = node.create_publisher(TransformStamped, "/tf", RELIABLE)
    js = {"m": None}

    def on_js(m: JointState) -> None:
        js["m"] = m

    def publish() -> None:
        m = js["m"]
        if m is None:
            return
        pos = dict(zip(m.name, m.position, strict=False))
        t = to_s(m.header.stamp)
        pub.publish(
            tf(
                "torso_link",
                "head_link",
                0.0,
                0.0,
                0.5 + pos.get("torso_lift_joint", 0.0),
                pos.get("head_pan_joint", 0.0),
                t,
            )
        )
        pub.publish(
            tf("torso_link", "left_wrist_link", 0.1, 0.25, 0.2 + pos.get("left_elbow_joint", 0.0), 0.0, t)
        )
        pub.publish(
            tf("torso_link", "right_wrist_link", 0.1, -0.25, 0.2 + pos.get("right_elbow_joint", 0.0), 0.0, t)
        )

    node.create_subscription(JointState, f"/{NS}/joint_states", on_js, RELIABLE)
    node.create_timer(0.1, publish)
    return single_threaded(node)


# ---------------------------------------- pms_bridge


def pms_bridge():
    node = Node("hotel_pms_bridge")
    log = node.get_logger()
    group = ReentrantCallbackGroup()
    st = {"calls": 0, "last_ms": 0.0, "ratelimit": time.time() + random.uniform(40, 120)}
    log.info("Connected to Opera Cloud PMS https://pms.grandlobby.example/ohip (property GLH01)")

    def http(what: str) -> float:  # the PMS REST call (requests, no timeout)
        if fault("/hotel_pms_bridge") == "hang":
            threading.Event().wait()  # TLS session half-open: the read never returns
        if time.time() > st["ratelimit"]:
            st["ratelimit"] = time.time() + random.uniform(60, 150)
            log.warn(f"PMS API rate limited (HTTP 429) on {what}, retrying in 1.0 s")
            time.sleep(1.0)
        d = random.uniform(0.2, 1.2)
        time.sleep(d)
        st["calls"] += 1
        st["last_ms"] = d * 1000
        return d

    def lookup(req, resp):
        http("GET /reservations")
        resp.bool_value, resp.string_value, resp.int32_value = (
            True,
            f"res-{random.randint(10000, 99999)}",
            412,
        )
        log.info(f"Reservation found for {req.string_value}: room {resp.int32_value}")
        return resp

    def encode(req, resp):
        http("POST /keys/encode")
        resp.bool_value, resp.string_value = True, f"key-{req.int32_value}-{random.randint(0, 9999):04d}"
        log.info(f"Key card encoded for room {req.int32_value}")
        return resp

    def service(req, resp):
        http("POST /serviceRequests")
        resp.bool_value, resp.string_value = True, f"sr-{random.randint(1000, 9999)}"
        return resp

    node.create_service(BasicTypes, "/hotel/lookup_booking", lookup, callback_group=group)
    node.create_service(BasicTypes, "/hotel/encode_key", encode, callback_group=group)
    node.create_service(BasicTypes, "/hotel/request_service", service, callback_group=group)
    rooms = node.create_publisher(String, "/hotel/room_status", RELIABLE)
    diag = node.create_publisher(DiagnosticArray, "/diagnostics", RELIABLE)

    @on_shutdown_quiet
    def relay() -> None:  # the PMS event stream (websocket), its own thread
        i = 0
        while True:
            time.sleep(1.0)
            i += 1
            if i % 2 == 0:
                rooms.publish(
                    String(
                        data=json.dumps(
                            {"clean": random.randint(180, 200), "occupied": 212, "t": round(time.time())}
                        )
                    )
                )
            diag.publish(
                DiagnosticArray(
                    header=header(""),
                    status=[
                        status(
                            OK,
                            "hotel_pms_bridge: Opera PMS link",
                            "connected",
                            "opera-cloud GLH01",
                            calls=st["calls"],
                            last_call_ms=f"{st['last_ms']:.0f}",
                        )
                    ],
                )
            )

    threading.Thread(target=relay, daemon=True, name="pms_events").start()
    ex = MultiThreadedExecutor(num_threads=4)
    ex.add_node(node)
    return ex


# ---------------------------------------- diagnostics


def aggregator():
    node = Node("diagnostic_aggregator")
    pub = node.create_publisher(DiagnosticArray, "/diagnostics_agg", RELIABLE)
    top = node.create_publisher(DiagnosticStatus, "/diagnostics_toplevel_state", RELIABLE)
    seen: dict[str, tuple[float, DiagnosticStatus]] = {}
    groups = (
        ("controller_manager", "Motors"),
        ("head_camera", "Sensors"),
        ("base_lidar", "Sensors"),
        ("imu", "Sensors"),
        ("audio_capture", "Sensors"),
        ("speech_recognizer", "Speech"),
        ("tts", "Speech"),
        ("lifecycle_manager", "Navigation"),
        ("collision_monitor", "Safety"),
        ("hotel_pms_bridge", "Hotel"),
    )

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
            out.append(
                DiagnosticStatus(
                    level=level,
                    name=f"/Robot/{g}/{name.split(': ', 1)[-1]}",
                    message="Stale" if level == STALE else s.message,
                    hardware_id=s.hardware_id,
                    values=s.values,
                )
            )
            worst[g] = max(worst.get(g, OK), level)
        for g, lv in worst.items():
            out.append(DiagnosticStatus(level=lv, name=f"/Robot/{g}", message="OK" if lv == OK else "Error"))
        lv = max(worst.values(), default=OK)
        out.append(DiagnosticStatus(level=lv, name="/Robot", message="OK" if lv == OK else "Error"))
        pub.publish(DiagnosticArray(header=header(""), status=out))
        top.publish(DiagnosticStatus(level=lv, name="toplevel_state"))

    node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, RELIABLE)
    node.create_timer(1.0, publish)
    return single_threaded(node)


# ---------------------------------------- recorder

RECORD = (
    "/tf",
    "/tf_static",
    "/diagnostics",
    f"/{NS}/odom",
    f"/{NS}/diff_drive_controller/cmd_vel",
    f"/{NS}/localization/pose",
    f"/{NS}/speech/utterance",
    f"/{NS}/dialogue/intent",
    f"/{NS}/task_executive/status",
    f"/{NS}/task_executive/task_result",
    f"/{NS}/face_detector/faces",
    f"/{NS}/people",
    f"/{NS}/safety/stop",
    f"/{NS}/plan",
    "/hotel/room_status",
    f"/{NS}/map",
    f"/{NS}/dialogue_manager/state",
    f"/{NS}/velocity_mux/active",
)


def recorder():
    import importlib

    node = Node("rosbag2_recorder")
    log = node.get_logger()
    buf: list[bytes] = []
    lock = threading.Lock()
    subs = {}
    st = {"bytes": 0, "file": 0}
    log.info("Recording to 'lobby_2024_bag' (mcap, zstd, max 200 MB per file)")

    def discover() -> None:
        for topic, types in node.get_topic_names_and_types():
            if topic in RECORD and topic not in subs:
                pkg, _, name = types[0].split("/")
                cls = getattr(importlib.import_module(f"{pkg}.msg"), name)
                qos = (
                    TF_STATIC
                    if topic in ("/tf_static", f"/{NS}/map")
                    else QoSProfile(depth=50, reliability=ReliabilityPolicy.BEST_EFFORT)
                )

                def cb(raw: bytes, _t=topic) -> None:
                    with lock:
                        buf.append(raw)

                subs[topic] = node.create_subscription(cls, topic, cb, qos, raw=True)
                log.info(f"Subscribed to topic '{topic}'")

    def writer() -> None:
        while True:
            time.sleep(0.1)
            with lock:
                chunk = list(buf)
                buf.clear()
            st["bytes"] += sum(len(c) for c in chunk)
            if st["bytes"] > 40_000_000:
                st["bytes"] = 0
                st["file"] += 1
                log.info(f"Writing to a new bag file: lobby_2024_bag_{st['file']}.mcap")

    node.create_timer(1.0, discover)
    threading.Thread(target=writer, daemon=True, name="writer").start()
    return single_threaded(node)


# ---------------------------------------- console (operator)


def console():
    node = Node("teleop_console", namespace=NS)
    log = node.get_logger()
    log.info("Front desk console connected")
    node.create_subscription(DiagnosticArray, "/diagnostics_agg", lambda _m: None, RELIABLE)
    node.create_subscription(String, f"/{NS}/task_executive/status", lambda _m: None, LATCHED)
    node.create_subscription(
        CompressedImage, f"/{NS}/head_camera/image_raw/compressed", lambda _m: None, SENSOR
    )
    teleop = node.create_publisher(Twist, f"/{NS}/cmd_vel_teleop", COMMAND)
    params = node.create_client(SetParameters, f"/{NS}/tts/set_parameters")
    t0 = time.time()
    st = {"volume": False}

    def tick() -> None:
        el = time.time() - t0
        if el > 4.0 and not st["volume"] and params.service_is_ready():
            st["volume"] = True
            v = round(random.uniform(0.5, 0.9), 2)
            p = Parameter(
                name="volume", value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=v)
            )
            params.call_async(SetParameters.Request(parameters=[p]))
            log.info(f"Set /cg/tts volume to {v}")
        if 20.0 < el < 23.0:  # the front desk turns the robot to face the entrance
            cmd = Twist()
            cmd.angular.z = 0.3
            teleop.publish(cmd)

    node.create_timer(0.1, tick)
    return single_threaded(node)


# ---------------------------------------- process main

PROCESSES = {
    "controller_manager": controller_manager,
    "head_container": head_container,
    "navigation": navigation,
    "base_sensors": base_sensors,
    "speech": speech,
    "asr": asr,
    "hri": hri,
    "tts": tts,
    "executive": executive,
    "safety": safety,
    "state_publisher": state_publisher,
    "pms_bridge": pms_bridge,
    "diagnostics": aggregator,
    "recorder": recorder,
    "console": console,
}
HOOKS: dict = {}  # "cpu" / "leak" -> what the process logs or does when its fault file appears


def main() -> int:
    global FAULT_DIR, PROCESS
    PROCESS, FAULT_DIR = sys.argv[1], Path(sys.argv[2])
    run_for = float(sys.argv[3]) if len(sys.argv) > 3 else 0.0
    if PROCESS == "asr":
        print("Loading model ggml-small.en.bin ...", flush=True)
        time.sleep(8.0)  # the model loads before the node exists: it joins late
    rclpy.init()
    spin(PROCESSES[PROCESS](), FAULT_DIR, PROCESS, run_for, HOOKS)


if __name__ == "__main__":
    sys.exit(main())
