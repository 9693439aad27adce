"""The harbour patrol / survey surface vessel's (USV's) processes.

``python -m bench.usv.robot PROCESS FAULT_DIR [RUN_FOR]``; ``python -m bench.usv.robot lifecycle_set
FAULT_DIR 0 NODE TRANSITION`` is the ``ros2 lifecycle set`` a crew member types (a short-lived CLI
process with its own hidden node).

One process of the robot described in `bench.usv.run` (its docstring lists every process, node,
topic, QoS and fault). Real rclpy nodes on wall time. A node's fault is read from
``FAULT_DIR/<namespace.name>`` (``usv.mavros.global_position``, ``usv.radar``); a process's CPU
burner and leak from ``FAULT_DIR/<process>.cpu`` / ``.leak``. ``RUN_FOR`` > 0: the process ends by
itself (exit code 0) after that many seconds (the shore operator's console).

The sea around the vessel is a schedule shared by every process through the wall clock
(`contacts`: the vessels near it, coming and going; `link_up`: the shore radio's outages).
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
from pathlib import Path

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import Pose, PoseArray, PoseStamped, Quaternion, TransformStamped, Twist
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
from sensor_msgs.msg import BatteryState, CompressedImage, Image, Imu, JointState, NavSatFix, NavSatStatus
from std_msgs.msg import Float32, String
from std_srvs.srv import SetBool
from test_msgs.action import Fibonacci

from bench.robot_process import (
    PYTHON_EXIT,
    Diagnostics,
    header,
    single_threaded,
    spin,
    status,
    to_s,
    wait_future,
)
from bench.robot_process import on_shutdown_quiet as quiet

NS = "usv"
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
HOME = (54.3233, 10.1394)  # Kiel harbour: the datum


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
    """A healthy vessel's occasional log line: ``due()`` True every ``lo``-``hi`` s."""

    def __init__(self, lo: float, hi: float) -> None:
        self.lo, self.hi = lo, hi
        self.next = time.time() + random.uniform(lo, hi)

    def due(self) -> bool:
        if time.time() >= self.next:
            self.next = time.time() + random.uniform(self.lo, self.hi)
            return True
        return False


def double(name: str, v: float) -> Parameter:
    return Parameter(name=name, value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=v))


# ---------------------------------------- the sea

SLOTS, EPOCH_S = 4, 45.0


@functools.lru_cache(maxsize=256)
def _plan(slot: int, k: int):
    rng = random.Random(k * 7919 + slot * 104729 + 11)
    if rng.random() < 0.4:
        return None
    a = rng.uniform(0.0, 18.0)
    return (
        a,
        a + rng.uniform(10.0, 25.0),
        rng.uniform(1500.0, 2800.0),
        rng.uniform(150.0, 1100.0),
        rng.uniform(0.0, 360.0),
        211000000 + rng.randrange(999999),
        rng.choice((0.5, 0.33, 0.1)),
    )


def contacts(t: float) -> list[tuple[int, float, float, float]]:
    """The vessels near the USV at wall time ``t``: (MMSI, range m, bearing deg, AIS msgs/s)."""
    out = []
    for slot in range(SLOTS):
        off = slot * 11.0
        k = int((t + off) // EPOCH_S)
        p = _plan(slot, k)
        if p is None:
            continue
        a, b, r0, cpa, brg, mmsi, rate = p
        el = t + off - k * EPOCH_S
        if not a <= el < b:
            continue
        f = abs(2 * (el - a) / (b - a) - 1)  # 1 -> 0 (closest point of approach) -> 1
        out.append((mmsi, cpa + (r0 - cpa) * f, (brg + 20 * (el - a) / (b - a)) % 360, rate))
    return out


@functools.lru_cache(maxsize=64)
def _outage(k: int):
    rng = random.Random(k * 613 + 5)
    if rng.random() < 0.35:
        return None
    a = rng.uniform(5.0, 50.0)
    return a, a + rng.uniform(3.0, 6.0)


def link_up(t: float) -> bool:
    """The shore radio link at wall time ``t``: down for 3-6 s in 65 % of the minutes."""
    k = int(t // 60.0)
    o = _outage(k)
    return o is None or not o[0] <= t - k * 60.0 < o[1]


# ---------------------------------------- autopilot_bridge (mavros-like: a router and two plugins)


def autopilot_bridge():
    mav = Node("mavros", namespace=NS)
    imu = Node("imu", namespace=f"{NS}/mavros")
    gp = Node("global_position", namespace=f"{NS}/mavros")
    log = mav.get_logger()
    log.info("FCU URL: serial:///dev/ttyTHS1:921600, GCS URL: udp://@10.42.0.2:14550")
    state_pub = mav.create_publisher(String, f"/{NS}/mavros/state", RELIABLE)
    mode_pub = mav.create_publisher(String, f"/{NS}/mavros/mode", LATCHED)
    bat_pub = mav.create_publisher(BatteryState, f"/{NS}/mavros/battery", RELIABLE)
    st = {
        "t0": time.time(),
        "connected": False,
        "armed": False,
        "mode": "",
        "soc": 0.86,
        "ekf": Recurring(80, 170),
    }

    def set_mode(mode: str) -> None:
        if mode != st["mode"]:
            st["mode"] = mode
            mode_pub.publish(String(data=mode))

    def heartbeat() -> None:  # the FCU's HEARTBEAT, 1 Hz
        el = time.time() - st["t0"]
        if not st["connected"]:
            st["connected"] = True
            log.info("CON: Got HEARTBEAT, connected. FCU: ArduPilot (Rover 4.5.7, frame BOAT)")
            set_mode("HOLD")
        if not st["armed"] and el > 3.0:
            st["armed"] = True
            log.info("FCU: Arming motors")
        st["soc"] = max(0.25, st["soc"] - 0.00015)
        state_pub.publish(
            String(
                data=json.dumps(
                    {
                        "connected": True,
                        "armed": st["armed"],
                        "guided": True,
                        "mode": st["mode"],
                        "system_status": 4,
                    }
                )
            )
        )
        bat_pub.publish(
            BatteryState(
                header=header("base_link"),
                voltage=44.0 + 6 * st["soc"],
                current=-18.5,
                percentage=st["soc"],
                present=True,
                power_supply_status=2,
            )
        )
        if st["ekf"].due():
            log.warn("FCU: EKF3 IMU0 MAG0 ground mag anomaly, yaw re-aligned")

    def on_set_mode(req, resp):
        set_mode("GUIDED" if req.data else "HOLD")
        resp.success, resp.message = True, st["mode"]
        return resp

    mav.create_timer(1.0, heartbeat)
    mav.create_service(SetBool, f"/{NS}/mavros/set_mode", on_set_mode)
    Diagnostics(
        mav,
        lambda: [
            status(OK, "mavros: FCU connection", "connected", "pixhawk6c /dev/ttyTHS1", mode=st["mode"]),
            status(OK, "mavros: Battery", "Normal", "pixhawk6c /dev/ttyTHS1", soc=round(st["soc"], 3)),
        ],
    )

    # imu plugin: HIGHRES_IMU at the requested 50 Hz message interval
    imu_pub = imu.create_publisher(Imu, f"/{NS}/mavros/imu/data", SENSOR)
    im = {"n": 0, "warned": False}
    imu_fqn = f"/{NS}/mavros/imu"

    def on_imu() -> None:
        im["n"] += 1
        if fault(imu_fqn) == "rate":
            if not im["warned"]:
                im["warned"] = True
                imu.get_logger().warn(
                    "IMU: SET_MESSAGE_INTERVAL for HIGHRES_IMU (20000 us) denied by FCU "
                    "(MAV_RESULT_DENIED); stream at SR1_RAW_SENS"
                )
            if im["n"] % 3 == 0:  # ArduPilot's SR1_RAW_SENS fallback: ~33 Hz
                return
        now = time.time()
        m = Imu(header=header("base_link", now - 0.004))
        m.orientation = yaw_quat(0.3 * math.sin(now / 40.0))
        m.angular_velocity.z = 0.3 / 40.0 * math.cos(now / 40.0)
        m.linear_acceleration.z = 9.81 + 0.4 * math.sin(now * 1.7)  # the swell
        m.linear_acceleration.x = 0.1 * math.sin(now * 0.9)
        imu_pub.publish(m)

    imu.create_timer(0.02, on_imu)

    # global_position plugin: GPS_RAW_INT 10 Hz (u-blox F9P RTK), stamped through TIMESYNC
    fix_pub = gp.create_publisher(NavSatFix, f"/{NS}/mavros/global_position/raw/fix", SENSOR)
    gs = {"lag": 0.0, "last": time.time()}
    gp_fqn = f"/{NS}/mavros/global_position"

    def on_fix() -> None:
        now = time.time()
        if fault(gp_fqn) == "lag":  # TIMESYNC's offset estimate runs away: stamps lag more and more
            gs["lag"] = min(60.0, gs["lag"] + 0.15 * (now - gs["last"]))
        gs["last"] = now
        m = NavSatFix(
            header=header("gps", now - 0.08 - gs["lag"]),
            status=NavSatStatus(status=NavSatStatus.STATUS_GBAS_FIX, service=NavSatStatus.SERVICE_GPS),
            latitude=HOME[0] + 0.002 * math.sin(now / 60.0),
            longitude=HOME[1] + 0.003 * math.cos(now / 60.0),
            altitude=42.1,
        )
        m.position_covariance = [0.0004, 0, 0, 0, 0.0004, 0, 0, 0, 0.0025]
        m.position_covariance_type = NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN
        fix_pub.publish(m)

    gp.create_timer(0.1, on_fix)
    return single_threaded(mav, imu, gp)


# ---------------------------------------- thruster_control (ros2_control-like)

LOOP_HZ = 50.0


def thruster_control():
    cm = Node("controller_manager", namespace=NS)
    jsb = Node("thruster_state_broadcaster", namespace=NS)
    alloc = Node("thrust_allocator", namespace=NS)
    log = cm.get_logger()
    log.info("Loaded hardware 'twin_thrusters' (Blue Robotics T500 x2 via Basic ESC over PWM/DShot)")
    activity = cm.create_publisher(String, f"/{NS}/controller_manager/activity", LATCHED)
    for c in ("thruster_state_broadcaster", "thrust_allocator"):
        log.info(f"Loading controller '{c}'")
        log.info(f"Configuring controller '{c}'")
        log.info(f"Activating controller '{c}'")
    activity.publish(
        String(data=json.dumps({"thruster_state_broadcaster": "active", "thrust_allocator": "active"}))
    )
    js_pub = jsb.create_publisher(JointState, f"/{NS}/thruster_states", RELIABLE)
    cmd = {"v": 0.0, "w": 0.0, "t": 0.0}
    hw = {"rpm": [0.0, 0.0], "amps": [0.0, 0.0], "overruns": 0, "jitter_ms": 0.0}
    lock = threading.Lock()

    def on_cmd(m: Twist) -> None:
        with lock:
            cmd["v"], cmd["w"], cmd["t"] = m.linear.x, m.angular.z, time.time()

    alloc.create_subscription(Twist, f"/{NS}/cmd_vel", on_cmd, RELIABLE)
    overrun = Recurring(90, 200)

    @quiet
    def loop() -> None:  # the controller manager's update loop: read, update, write at 50 Hz
        period = 1.0 / LOOP_HZ
        nxt = time.time()
        while rclpy.ok():
            nxt += period
            now = time.time()
            with lock:
                v, w = (cmd["v"], cmd["w"]) if now - cmd["t"] < 0.5 else (0.0, 0.0)
            for i, sgn in enumerate((1.0, -1.0)):  # differential thrust: port, starboard
                target = 1400.0 * (v / 2.0) + sgn * 600.0 * w
                hw["rpm"][i] += 0.15 * (target - hw["rpm"][i])
                hw["amps"][i] = 0.4 + abs(hw["rpm"][i]) / 140.0
            js_pub.publish(
                JointState(
                    header=header("base_link", now),
                    name=["thruster_port", "thruster_stbd"],
                    position=[0.0, 0.0],
                    velocity=list(hw["rpm"]),
                    effort=list(hw["amps"]),
                )
            )
            if overrun.due():
                hw["overruns"] += 1
                log.warn(
                    f"Overrun detected! The controller manager missed its desired rate of {LOOP_HZ:.0f} Hz. "
                    "The loop took 23.4 ms (missed cycles : 1)."
                )
            time.sleep(max(0.0, nxt - time.time()))
            hw["jitter_ms"] = round(1000 * abs(time.time() - nxt), 2)

    threading.Thread(target=loop, daemon=True, name="cm_update_loop").start()
    Diagnostics(
        cm,
        lambda: [
            status(
                OK,
                "controller_manager: Controllers Activity",
                "All controllers are active",
                "",
                update_rate=int(LOOP_HZ),
                overruns=hw["overruns"],
                jitter_ms=hw["jitter_ms"],
            ),
            status(
                OK,
                "controller_manager: Hardware Components",
                "twin_thrusters active",
                "blue-robotics-t500 x2",
                port_a=round(hw["amps"][0], 1),
                stbd_a=round(hw["amps"][1], 1),
            ),
        ],
    )
    ex = MultiThreadedExecutor(num_threads=2)
    for n in (cm, jsb, alloc):
        ex.add_node(n)
    return ex


# ---------------------------------------- radar_driver (lifecycle)

SPOKES, BINS = 1024, 128  # 128 KB a revolution
RPM = 24.0  # 0.4 Hz


class Radar(LifecycleNode):
    def __init__(self) -> None:
        super().__init__("radar", namespace=NS)
        self.declare_parameter("range_m", 3000.0)
        self.declare_parameter("gain", "auto")
        self.timer = None
        self.active = False
        self.n = 0
        self.data = array.array("B", bytes(SPOKES * BINS))
        self.add_on_set_parameters_callback(self.on_params)
        self.sea = Recurring(70, 160)

    def on_params(self, params) -> SetParametersResult:
        for p in params:
            if p.name == "range_m":
                self.get_logger().info(
                    f"Range set to {p.value:.0f} m (pulse {'short' if p.value < 2000 else 'medium'})"
                )
        return SetParametersResult(successful=True)

    def on_configure(self, state) -> TransitionCallbackReturn:
        self.pub = self.create_lifecycle_publisher(Image, f"/{NS}/radar/scan", SENSOR)
        self.get_logger().info("Connected to Navico HALO24 at 236.6.7.8:6678 (serial 1912A40087), 24 rpm")
        self.timer = self.create_timer(60.0 / RPM, self.scan)
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        self.active = True
        self.get_logger().info("Transmit on")
        return super().on_activate(state)

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        self.active = False
        self.get_logger().info("Transmit off: standby")
        return super().on_deactivate(state)

    def scan(self) -> None:
        if not self.active:
            return
        now = time.time()
        rng = self.get_parameter("range_m").value
        cs = [c for c in contacts(now) if c[1] < rng][:20]
        self.data[0] = len(cs)
        for i, (_mmsi, r, b, _rate) in enumerate(cs):  # the echoes: range bin and spoke of each contact
            self.data[1 + 2 * i] = min(255, int(r / rng * BINS))
            self.data[2 + 2 * i] = int(b / 360.0 * 256) % 256
        self.data[64] = int(rng // 100) % 256
        self.pub.publish(
            Image(
                header=header("radar", now - 60.0 / RPM / 2),
                height=SPOKES,
                width=BINS,
                encoding="mono8",
                step=BINS,
                data=self.data,
            )
        )
        self.n += 1
        if self.sea.due():
            self.get_logger().warn("Sea clutter high in sector 040-110 deg; auto sea clutter raised to 62")


def radar_driver():
    node = Radar()
    Diagnostics(
        node,
        lambda: [
            status(
                OK if node.active else WARN,
                "radar: Navico HALO24 status",
                "Transmitting" if node.active else "Standby",
                "halo24 sn 1912A40087",
                range_m=node.get_parameter("range_m").value,
                revolutions=node.n,
            )
        ],
    )
    return single_threaded(node)


# ---------------------------------------- ais (receiver on a serial port)


def ais():
    node = Node("ais_receiver", namespace=NS)
    log = node.get_logger()
    fqn = f"/{NS}/ais_receiver"
    pub = node.create_publisher(String, f"/{NS}/ais/messages", RELIABLE)
    log.info("Opened /dev/ttyUSB1 (dAISy HAT, 38400 baud), channels A+B")
    st = {"n": 0, "started": time.time(), "dying": 0.0, "seen": set()}
    crc = Recurring(60, 150)

    def poll() -> None:  # the serial port's NMEA lines, read every 0.1 s
        now = time.time()
        if fault(fqn) == "crashloop" and not st["dying"]:
            st["dying"] = max(now + random.uniform(0.2, 0.8), st["started"] + random.uniform(1.5, 2.5))
        if st["dying"] and now >= st["dying"]:
            log.fatal(
                "Serial read failed on /dev/ttyUSB1: device reports readiness to read but returned no "
                "data (device disconnected or multiple access on port?)"
            )
            raise OSError(5, "Input/output error: '/dev/ttyUSB1'")
        for mmsi, r, b, rate in contacts(now):
            if random.random() < rate * 0.1:  # Poisson: Class A 2-10 s, Class B 30 s reporting interval
                if mmsi not in st["seen"]:
                    st["seen"].add(mmsi)
                    log.info(f"New AIS target MMSI {mmsi}")
                pub.publish(
                    String(
                        data=json.dumps(
                            {
                                "mmsi": mmsi,
                                "type": 1 if rate > 0.2 else 18,
                                "range_m": round(r, 1),
                                "bearing": round(b, 1),
                                "sog": 6.5,
                                "stamp": now,
                            }
                        )
                    )
                )
                st["n"] += 1
        if crc.due():
            log.warn(
                "NMEA checksum mismatch, dropped sentence: !AIVDM,1,1,,B,13u?etPv2;0n:dDPwUM1U1Cb069D,0*2"
            )

    node.create_timer(0.1, poll)
    Diagnostics(
        node,
        lambda: [
            status(
                OK,
                "ais_receiver: Serial link",
                "Receiving",
                "daisy-hat /dev/ttyUSB1",
                messages=st["n"],
                targets=len(st["seen"]),
            )
        ],
    )
    return single_threaded(node)


# ---------------------------------------- camera_container (single-threaded component container)


def camera_container():
    vis = Node("camera", namespace=NS)
    thermal = Node("thermal_camera", namespace=NS)
    vpub = vis.create_publisher(CompressedImage, f"/{NS}/camera/image_raw/compressed", SENSOR)
    tpub = thermal.create_publisher(CompressedImage, f"/{NS}/thermal_camera/image_raw/compressed", SENSOR)
    vis.get_logger().info("Opened FLIR Blackfly S BFS-PGE-31S4C (GigE, 1024x768, JPEG q 80, 10 fps)")
    thermal.get_logger().info("Opened FLIR Boson 640 on /dev/ttyACM0 + /dev/video2 (9 Hz, AGC auto)")
    vjpeg = bytes(random.getrandbits(8) for _ in range(38_000))
    tjpeg = bytes(random.getrandbits(8) for _ in range(14_000))
    st = {"v": 0, "t": 0, "ffc": 0}
    ptu = thermal.create_publisher(TransformStamped, "/tf", RELIABLE)
    ffc_due = Recurring(60, 120)
    fqn = f"/{NS}/thermal_camera"

    def grab_vis() -> None:
        now = time.time()
        n = len([c for c in contacts(now) if c[1] < 1200 and (c[2] < 60 or c[2] > 300)])
        vpub.publish(
            CompressedImage(
                header=header("camera_optical_frame", now - 0.03),
                format="rgb8; jpeg compressed bgr8",
                data=bytes([n]) + vjpeg,
            )
        )
        st["v"] += 1

    def grab_thermal() -> None:
        now = time.time()
        if st["t"] % 2 == 0:  # the pan-tilt unit's pan angle, with every other frame (4.5 Hz)
            ptu.publish(
                tf("ptu_base", "thermal_optical_frame", 0.05, 0.0, 0.1, 0.6 * math.sin(now / 20.0), now)
            )
        tpub.publish(
            CompressedImage(
                header=header("thermal_optical_frame", now - 0.05),
                format="mono8; jpeg compressed mono8",
                data=tjpeg,
            )
        )
        st["t"] += 1

    def ffc() -> None:  # flat field correction over the Boson's serial command channel
        hang = fault(fqn) == "hang"
        if not (hang or ffc_due.due()):
            return
        thermal.get_logger().info("Running flat field correction (shutter)")
        if hang:
            threading.Event().wait()  # the FSLP reply never comes: read() on /dev/ttyACM0 without a timeout
        time.sleep(0.25)
        st["ffc"] += 1

    vis.create_timer(0.1, grab_vis)
    thermal.create_timer(1 / 9.0, grab_thermal)
    thermal.create_timer(1.0, ffc)
    Diagnostics(
        vis,
        lambda: [
            status(
                OK,
                f"camera: /{NS}/camera/image_raw/compressed topic status",
                "Desired frequency met",
                "blackfly-s sn 22140518",
                frames=st["v"],
            )
        ],
    )
    Diagnostics(
        thermal,
        lambda: [
            status(
                OK,
                f"thermal_camera: /{NS}/thermal_camera/image_raw/compressed topic status",
                "Desired frequency met",
                "boson640 sn 394871",
                frames=st["t"],
                ffc=st["ffc"],
            )
        ],
    )
    return single_threaded(vis, thermal)


# ---------------------------------------- perception (multi-threaded container)


def perception():
    trk = Node("radar_tracker", namespace=NS)
    det = Node("vessel_detector", namespace=NS)
    omap = Node("obstacle_map", namespace=NS)
    lock = threading.Lock()
    fused: dict[str, tuple[float, float, float]] = {}  # key -> (t, range, bearing)

    # radar tracker: ARPA-like tracks from each revolution
    trk_pub = trk.create_publisher(PoseArray, f"/{NS}/radar/targets", RELIABLE)
    ts = {"tracks": 0, "scans": 0, "cells": 0}
    cfg = {"cell_m": 25.0}

    def on_scan(m: Image) -> None:
        n = m.data[0]
        rng = m.data[64] * 100.0 or 3000.0
        poses = []
        if fault(f"/{NS}/radar_tracker") == "crash" and cfg["cell_m"]:
            cfg["cell_m"] = 0.0  # a pushed arpa.yaml with an empty clutter_map section: cell size 0
            trk.get_logger().info(
                "Reloaded tracker config /opt/usv/config/arpa.yaml (clutter_map.cell_m: 0.0, gate 3.0 sigma)"
            )
        cells = int(rng / cfg["cell_m"])  # the clutter map's range cells for this revolution
        for i in range(n):
            r = m.data[1 + 2 * i] / BINS * rng
            b = m.data[2 + 2 * i] / 256.0 * 360.0
            p = Pose()
            p.position.x, p.position.y = r * math.cos(math.radians(b)), r * math.sin(math.radians(b))
            poses.append(p)
            with lock:
                fused[f"radar{i}"] = (time.time(), r, b)
        ts["scans"] += 1
        ts["cells"] = cells
        if n != ts["tracks"]:
            trk.get_logger().info(f"{n} radar tracks (was {ts['tracks']})")
            ts["tracks"] = n
        trk_pub.publish(PoseArray(header=m.header, poses=poses))

    trk.create_subscription(
        Image, f"/{NS}/radar/scan", on_scan, SENSOR, callback_group=MutuallyExclusiveCallbackGroup()
    )

    # vessel detector: YOLO on the visible camera, on the GPU (TensorRT)
    det_pub = det.create_publisher(PoseArray, f"/{NS}/vessel_detector/detections", RELIABLE)
    ds = {"cpu": False, "n": 0, "ms": 0.0}
    det.get_logger().info("Loaded TensorRT engine yolov8n_maritime_fp16.engine (Jetson Orin NX GPU)")

    def on_image(m: CompressedImage) -> None:
        t0 = time.time()
        time.sleep(random.uniform(0.010, 0.020) * (5 if ds["cpu"] else 1))
        ds["ms"] = (time.time() - t0) * 1000
        n = m.data[0]
        if n:
            det_pub.publish(PoseArray(header=m.header, poses=[Pose() for _ in range(n)]))
            ds["n"] += 1

    det.create_subscription(
        CompressedImage,
        f"/{NS}/camera/image_raw/compressed",
        on_image,
        SENSOR,
        callback_group=MutuallyExclusiveCallbackGroup(),
    )

    def on_cpu() -> None:
        ds["cpu"] = True
        det.get_logger().warn(
            "TensorRT: [executionContext.cpp::enqueueV3] Error Code 1: Cuda Runtime (out of "
            "memory); falling back to ONNX Runtime CPUExecutionProvider (slow)"
        )

    HOOKS["cpu"] = on_cpu
    Diagnostics(
        det,
        lambda: [
            status(
                WARN if ds["cpu"] else OK,
                "vessel_detector: Inference",
                "CPU fallback" if ds["cpu"] else "OK",
                "orin-nx gpu0",
                detections=ds["n"],
                last_ms=round(ds["ms"], 1),
            )
        ],
    )

    # obstacle map: radar tracks + AIS + camera -> obstacles (2 Hz)
    og = MutuallyExclusiveCallbackGroup()
    obs_pub = omap.create_publisher(PoseArray, f"/{NS}/obstacles", RELIABLE)
    ms = {"radar_t": time.time(), "mission": "", "ais": 0}
    warn = Every(10.0)

    def on_targets(m: PoseArray) -> None:
        ms["radar_t"] = time.time()

    def on_ais(m: String) -> None:
        d = json.loads(m.data)
        with lock:
            fused[f"ais{d['mmsi']}"] = (time.time(), d["range_m"], d["bearing"])
        ms["ais"] += 1

    def on_state(m: String) -> None:
        ms["mission"] = m.data

    def publish() -> None:
        now = time.time()
        with lock:
            for k in [k for k, v in fused.items() if now - v[0] > 12.0]:
                del fused[k]
            items = list(fused.values())
        poses = []
        for _t, r, b in items:
            p = Pose()
            p.position.x, p.position.y = r * math.cos(math.radians(b)), r * math.sin(math.radians(b))
            poses.append(p)
        obs_pub.publish(PoseArray(header=header("base_link", now), poses=poses))
        if now - ms["radar_t"] > 10.0 and ms["mission"] != "no_transmit_zone" and warn.ok():
            omap.get_logger().warn(
                f"No radar targets on /{NS}/radar/targets for {now - ms['radar_t']:.1f} s: "
                "obstacle map from AIS and camera only"
            )

    omap.create_subscription(PoseArray, f"/{NS}/radar/targets", on_targets, RELIABLE, callback_group=og)
    omap.create_subscription(String, f"/{NS}/ais/messages", on_ais, RELIABLE, callback_group=og)
    omap.create_subscription(
        PoseArray, f"/{NS}/vessel_detector/detections", lambda _m: None, RELIABLE, callback_group=og
    )
    omap.create_subscription(String, f"/{NS}/mission_executive/state", on_state, LATCHED, callback_group=og)
    omap.create_timer(0.5, publish, callback_group=og)
    ex = MultiThreadedExecutor(num_threads=2)
    for n in (trk, det, omap):
        ex.add_node(n)
    return ex


# ---------------------------------------- localization (single-threaded container: robot_localization)


def localization():
    nst = Node("navsat_transform", namespace=NS)
    ekf = Node("ekf_filter_node", namespace=NS)
    rsp = Node("robot_state_publisher", namespace=NS)
    nlog, elog = nst.get_logger(), ekf.get_logger()
    gps_pub = nst.create_publisher(Odometry, f"/{NS}/odometry/gps", RELIABLE)
    nlog.info(f"Datum set to lat {HOME[0]:.4f} lon {HOME[1]:.4f}, UTM zone 32U (from parameters)")
    ns_fqn = f"/{NS}/navsat_transform"

    def on_fix(m: NavSatFix) -> None:
        lat, lon = m.latitude - HOME[0], m.longitude - HOME[1]
        x, y = lon * 111320.0 * math.cos(math.radians(HOME[0])), lat * 110540.0
        if fault(ns_fqn) == "zone":  # a UTM zone flip at the datum: easting off by a zone's width
            x += 400_012.0
        o = Odometry(header=header("map", to_s(m.header.stamp)), child_frame_id="base_link")
        o.pose.pose.position.x, o.pose.pose.position.y = x, y
        gps_pub.publish(o)

    nst.create_subscription(NavSatFix, f"/{NS}/mavros/global_position/raw/fix", on_fix, SENSOR)

    # ekf: imu + gps odometry -> odometry/filtered and odom->base_link at 20 Hz
    odom_pub = ekf.create_publisher(Odometry, f"/{NS}/odometry/filtered", RELIABLE)
    tf_pub = ekf.create_publisher(TransformStamped, "/tf", RELIABLE)
    es = {
        "x": 0.0,
        "y": 0.0,
        "yaw": 0.0,
        "gps_t": 0.0,
        "imu_n": 0,
        "imu_hz": 50.0,
        "gps_bad": 0,
        "cov": 0.02,
        "last_gps": None,
    }
    stale_warn, jump_err = Every(5.0), Every(2.0)

    def on_imu(m: Imu) -> None:
        es["imu_n"] += 1
        q = m.orientation
        es["yaw"] = 2 * math.atan2(q.z, q.w)

    def on_gps(m: Odometry) -> None:
        now = time.time()
        age = now - to_s(m.header.stamp)
        if age > 1.0:
            es["gps_bad"] += 1
            if stale_warn.ok():
                elog.warn(
                    f"Measurement from /{NS}/odometry/gps is {age:.2f} s old, older than the history "
                    "length (1.00 s); ignoring it"
                )
            return
        px, py = m.pose.pose.position.x, m.pose.pose.position.y
        jump = math.hypot(px - es["x"], py - es["y"]) if es["last_gps"] else 0.0
        if jump > 50.0:
            es["gps_bad"] += 1
            if jump_err.ok():
                elog.error(
                    f"Rejecting /{NS}/odometry/gps: Mahalanobis distance {jump**2 / 0.04:.3g} exceeds "
                    f"threshold 25.0 (position jump {jump:.0f} m)"
                )
            return
        es["x"], es["y"], es["gps_t"], es["last_gps"], es["cov"] = px, py, now, now, 0.02

    def predict() -> None:
        now = time.time()
        if now - es["gps_t"] > 1.0:
            es["cov"] = min(500.0, es["cov"] * 1.05 + 0.01)
        o = Odometry(header=header("odom", now), child_frame_id="base_link")
        o.pose.pose.position.x, o.pose.pose.position.y = es["x"], es["y"]
        o.pose.pose.orientation = yaw_quat(es["yaw"])
        o.pose.covariance[0] = o.pose.covariance[7] = es["cov"]
        odom_pub.publish(o)
        tf_pub.publish(tf("odom", "base_link", es["x"], es["y"], 0.0, es["yaw"], now))

    def rate() -> None:
        es["imu_hz"], es["imu_n"] = es["imu_n"] / 2.0, 0

    ekf.create_subscription(Imu, f"/{NS}/mavros/imu/data", on_imu, SENSOR)
    ekf.create_subscription(Odometry, f"/{NS}/odometry/gps", on_gps, RELIABLE)
    ekf.create_timer(1 / 20.0, predict)
    ekf.create_timer(2.0, rate)

    def ekf_diag():
        imu_ok = 45.0 <= es["imu_hz"] <= 55.0
        gps_ok = time.time() - es["gps_t"] < 2.0
        return [
            status(
                OK if imu_ok else WARN,
                f"ekf_filter_node: /{NS}/mavros/imu/data topic status",
                "Desired frequency met" if imu_ok else "Frequency too low",
                "",
                frequency=es["imu_hz"],
                min_frequency=45.0,
            ),
            status(
                OK if gps_ok else WARN,
                "ekf_filter_node: Filter",
                "OK" if gps_ok else "GNSS not fused",
                "",
                rejected=es["gps_bad"],
                position_variance=round(es["cov"], 3),
            ),
        ]

    Diagnostics(ekf, ekf_diag)
    desc = rsp.create_publisher(String, f"/{NS}/robot_description", LATCHED)
    desc.publish(String(data="<robot name='usv_patrol_7m'>...</robot>"))
    static = rsp.create_publisher(TransformStamped, "/tf_static", TF_STATIC)
    for child, x, z in (
        ("radar", 0.5, 2.8),
        ("gps", -0.8, 2.2),
        ("camera_optical_frame", 2.9, 1.6),
        ("ptu_base", 2.9, 1.5),
        ("thruster_port", -3.2, -0.4),
        ("thruster_stbd", -3.2, -0.4),
    ):
        static.publish(tf("base_link", child, x, 0.0, z))
    return single_threaded(nst, ekf, rsp)


# ---------------------------------------- guidance (multi-threaded: planner, follower, COLREGs, mux)

LEG_S = 12


def guidance():
    planner = Node("route_planner", namespace=NS)
    follower = Node("waypoint_follower", namespace=NS)
    colregs = Node("colregs_avoidance", namespace=NS)
    mux = Node("cmd_vel_mux", namespace=NS)
    planner.get_logger().info("Loaded ENC cells DE521010, DE521020 (S-57, 2 cells, 4113 features)")

    def plan_route(req, resp):
        if fault(f"/{NS}/route_planner") == "slow":  # the chart database's spatial index is rebuilt per query
            time.sleep(random.uniform(8.0, 11.0))
        time.sleep(random.uniform(0.08, 0.3))
        x0, y0 = req.start.pose.position.x, req.start.pose.position.y
        x1, y1 = req.goal.pose.position.x, req.goal.pose.position.y
        resp.plan = PathMsg(header=header("map"))
        for i in range(31):
            ps = PoseStamped(header=header("map"))
            ps.pose.position.x, ps.pose.position.y = x0 + (x1 - x0) * i / 30, y0 + (y1 - y0) * i / 30
            resp.plan.poses.append(ps)
        return resp

    planner.create_service(
        GetPlan,
        f"/{NS}/route_planner/plan_route",
        plan_route,
        callback_group=MutuallyExclusiveCallbackGroup(),
    )

    # waypoint follower: one leg a goal (order = its seconds), cmd_vel_mission 10 Hz and feedback 2 Hz
    mis_pub = follower.create_publisher(Twist, f"/{NS}/cmd_vel_mission", COMMAND)
    busy = threading.Lock()
    flog = follower.get_logger()

    def on_goal(_req) -> GoalResponse:
        return GoalResponse.REJECT if busy.locked() else GoalResponse.ACCEPT

    def execute(gh):
        with busy:
            secs = float(gh.request.order)
            t0 = time.time()
            flog.info(f"Following leg ({secs:.0f} s at 2.0 m/s)")
            k = 0
            while time.time() - t0 < secs:
                if gh.is_cancel_requested:
                    mis_pub.publish(Twist())
                    gh.canceled()
                    return Fibonacci.Result(sequence=[5])
                c = Twist()
                c.linear.x, c.angular.z = 2.0, 0.05 * math.sin(time.time() / 5)
                mis_pub.publish(c)
                if k % 5 == 0:
                    gh.publish_feedback(Fibonacci.Feedback(sequence=[int(2 * (secs - (time.time() - t0)))]))
                k += 1
                time.sleep(0.1)
            mis_pub.publish(Twist())
            flog.info("Leg complete: waypoint reached")
            gh.succeed()
            return Fibonacci.Result(sequence=[0])

    ActionServer(
        follower,
        Fibonacci,
        f"/{NS}/waypoint_follower/follow_leg",
        execute_callback=execute,
        goal_callback=on_goal,
        cancel_callback=lambda _g: CancelResponse.ACCEPT,
        callback_group=ReentrantCallbackGroup(),
    )

    # COLREGs avoidance: a manoeuvre only while a contact is within safe_range_m
    colregs.declare_parameter("safe_range_m", 600.0)
    av_pub = colregs.create_publisher(Twist, f"/{NS}/cmd_vel_avoid", COMMAND)
    cs = {"near": None, "range": 1e9}
    clog = colregs.get_logger()

    def on_params(params) -> SetParametersResult:
        for p in params:
            if p.name == "safe_range_m":
                clog.info(f"safe_range_m set to {p.value:.0f} m")
        return SetParametersResult(successful=True)

    colregs.add_on_set_parameters_callback(on_params)

    def on_obstacles(m: PoseArray) -> None:
        cs["range"] = min((math.hypot(p.position.x, p.position.y) for p in m.poses), default=1e9)
        near = cs["range"] < colregs.get_parameter("safe_range_m").value
        if near and not cs["near"]:
            p = min(m.poses, key=lambda p: math.hypot(p.position.x, p.position.y))
            brg = math.degrees(math.atan2(p.position.y, p.position.x)) % 360
            rule = (
                "Rule 15 crossing, give-way"
                if brg < 112.5
                else "Rule 13 overtaking"
                if brg < 247.5
                else "Rule 17 stand-on"
            )
            clog.info(
                f"Contact at {cs['range']:.0f} m bearing {brg:.0f} deg: {rule}; altering course to starboard"
            )
        elif cs["near"] and not near:
            clog.info("Contact clear; resuming mission")
        cs["near"] = near

    def avoid() -> None:
        if cs["near"]:
            c = Twist()
            c.linear.x, c.angular.z = 1.2, -0.25
            av_pub.publish(c)

    cg = MutuallyExclusiveCallbackGroup()
    colregs.create_subscription(PoseArray, f"/{NS}/obstacles", on_obstacles, RELIABLE, callback_group=cg)
    colregs.create_timer(0.1, avoid, callback_group=cg)

    # cmd_vel mux: remote operator > avoidance > mission
    out = mux.create_publisher(Twist, f"/{NS}/cmd_vel", RELIABLE)
    active_pub = mux.create_publisher(String, f"/{NS}/cmd_vel_mux/active", LATCHED)
    mx = {"active": None, "t": {"teleop": 0.0, "avoidance": 0.0, "mission": 0.0}}
    prio = {"teleop": 100, "avoidance": 50, "mission": 10}
    mg = MutuallyExclusiveCallbackGroup()

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
            if winner == source:
                out.publish(m)

        return cb

    def idle() -> None:
        now = time.time()
        if mx["active"] is not None and all(now - t > 0.5 for t in mx["t"].values()):
            mx["active"] = None
            active_pub.publish(String(data="idle"))
            out.publish(Twist())

    active_pub.publish(String(data="idle"))
    for src, topic in (
        ("mission", "cmd_vel_mission"),
        ("avoidance", "cmd_vel_avoid"),
        ("teleop", "cmd_vel_teleop"),
    ):
        mux.create_subscription(Twist, f"/{NS}/{topic}", on_input(src), COMMAND, callback_group=mg)
    mux.create_timer(0.25, idle, callback_group=mg)
    ex = MultiThreadedExecutor(num_threads=3)
    for n in (planner, follower, colregs, mux):
        ex.add_node(n)
    return ex


# ---------------------------------------- mission (executive + lifecycle manager)

CYCLE_S = 60.0
WAYPOINTS = [(400.0, 250.0), (900.0, -150.0), (250.0, -600.0), (0.0, 0.0)]


def mission():
    node = Node("mission_executive", namespace=NS)
    lm = Node("lifecycle_manager", namespace=NS)
    log = node.get_logger()
    group = ReentrantCallbackGroup()
    plan_cli = node.create_client(GetPlan, f"/{NS}/route_planner/plan_route", callback_group=group)
    leg_cli = ActionClient(node, Fibonacci, f"/{NS}/waypoint_follower/follow_leg", callback_group=group)
    tx_cli = node.create_client(SetBool, f"/{NS}/lifecycle_manager/set_transmit", callback_group=group)
    mode_cli = node.create_client(SetBool, f"/{NS}/mavros/set_mode", callback_group=group)
    radar_params = node.create_client(SetParameters, f"/{NS}/radar/set_parameters", callback_group=group)
    route_pub = node.create_publisher(PathMsg, f"/{NS}/mission_executive/route", RELIABLE)
    state_pub = node.create_publisher(String, f"/{NS}/mission_executive/state", LATCHED)
    st = {"state": "", "pose": None, "wp": 0}

    def set_state(s: str) -> None:
        if s != st["state"]:
            st["state"] = s
            state_pub.publish(String(data=s))

    def call(cli, req, timeout: float):
        return wait_future(cli.call_async(req), timeout) if cli.service_is_ready() else None

    def leg() -> None:
        i = st["wp"] % len(WAYPOINTS)
        st["wp"] += 1
        set_state(f"transit:wp_{i + 1}")
        if i == 2:  # the inshore leg: short range
            call(radar_params, SetParameters.Request(parameters=[double("range_m", 1500.0)]), 3.0)
        elif i == 0:
            call(radar_params, SetParameters.Request(parameters=[double("range_m", 3000.0)]), 3.0)
        req = GetPlan.Request()
        req.start = PoseStamped(header=header("map"))  # from the previous waypoint
        req.start.pose.position.x, req.start.pose.position.y = WAYPOINTS[i - 1]
        req.goal = PoseStamped(header=header("map"))
        req.goal.pose.position.x, req.goal.pose.position.y = WAYPOINTS[i]
        if not plan_cli.service_is_ready():
            log.warn(f"Route planner /{NS}/route_planner/plan_route not available; holding station")
            return
        r = wait_future(plan_cli.call_async(req), 5.0)
        if r is None:
            log.error(
                f"Route planning to wp_{i + 1} failed: service /{NS}/route_planner/plan_route did not answer "
                "within 5.0 s; holding station"
            )
            set_state("holding")
            call(mode_cli, SetBool.Request(data=False), 2.0)
            return
        route_pub.publish(r.plan)
        call(mode_cli, SetBool.Request(data=True), 2.0)
        log.info(f"Transit to wp_{i + 1}: route of {len(r.plan.poses)} points")
        gh = wait_future(leg_cli.send_goal_async(Fibonacci.Goal(order=LEG_S)), 3.0)
        if gh is None or not gh.accepted:
            log.error(f"Leg to wp_{i + 1} rejected by /{NS}/waypoint_follower")
            return
        res = wait_future(gh.get_result_async(), LEG_S + 5.0)
        if res is None or res.status != 4:
            log.error(f"Leg to wp_{i + 1} did not complete")

    def transmit(on: bool) -> None:
        r = call(tx_cli, SetBool.Request(data=on), 6.0)
        if r is None or not r.success:
            log.warn(f"Could not switch radar transmit {'on' if on else 'off'}")

    @quiet
    def worker() -> None:
        for what, ready in (
            (f"service /{NS}/route_planner/plan_route", plan_cli.wait_for_service),
            (f"action server /{NS}/waypoint_follower/follow_leg", leg_cli.wait_for_server),
        ):
            if not ready(timeout_sec=10.0):
                log.warn(f"{what} not available after 10 s; starting anyway")
        t0 = time.time()
        log.info(
            "Mission 'harbour_patrol_kiel' started: 4 waypoints, 60 s cycle, no-transmit zone at the marina"
        )
        k = 0
        while rclpy.ok():
            base_t = t0 + k * CYCLE_S
            for i in range(3):
                time.sleep(max(0.0, base_t + 15.0 * i - time.time()))
                leg()
            time.sleep(max(0.0, base_t + 45.0 - time.time()))
            set_state("no_transmit_zone")
            log.info("Entering the marina's no-transmit zone: radar to standby")
            call(mode_cli, SetBool.Request(data=True), 2.0)
            transmit(False)
            time.sleep(max(0.0, base_t + 52.0 - time.time()))
            log.info("Leaving the no-transmit zone: radar transmit")
            transmit(True)
            set_state("patrol")
            k += 1
            while t0 + k * CYCLE_S < time.time():
                k += 1

    # lifecycle manager: brings the radar up, switches transmit, watches it
    lg = ReentrantCallbackGroup()
    llog = lm.get_logger()
    change = lm.create_client(ChangeState, f"/{NS}/radar/change_state", callback_group=lg)
    get = lm.create_client(GetState, f"/{NS}/radar/get_state", callback_group=lg)
    health = {"radar": "unknown", "want": "active"}

    def transition(tid: int) -> bool:
        req = ChangeState.Request()
        req.transition.id = tid
        r = wait_future(change.call_async(req), 5.0)
        return bool(r and r.success)

    def set_transmit(req, resp):
        verb = "Activating" if req.data else "Deactivating"
        llog.info(f"{verb} radar")
        health["want"] = "active" if req.data else "inactive"
        now = wait_future(get.call_async(GetState.Request()), 4.0)
        if now is not None and now.current_state.label == health["want"]:  # nothing to do
            llog.info(f"radar already {health['want']}")
            resp.success, resp.message = True, f"already {health['want']}"
            return resp
        ok = transition(Transition.TRANSITION_ACTIVATE if req.data else Transition.TRANSITION_DEACTIVATE)
        resp.success, resp.message = ok, "" if ok else f"{verb} radar failed"
        if not ok:
            llog.error(f"Failed to change state for node: radar ({verb.lower()})")
        return resp

    lm.create_service(SetBool, f"/{NS}/lifecycle_manager/set_transmit", set_transmit, callback_group=lg)

    @quiet
    def bringup() -> None:
        llog.info("Starting managed nodes bringup...")
        while not change.wait_for_service(timeout_sec=2.0):
            llog.info(f"Waiting for service /{NS}/radar/change_state...")
        for tid, verb in (
            (Transition.TRANSITION_CONFIGURE, "Configuring"),
            (Transition.TRANSITION_ACTIVATE, "Activating"),
        ):
            llog.info(f"{verb} radar")
            transition(tid)
        llog.info("Managed nodes are active")
        threading.Thread(target=worker, daemon=True, name="mission").start()
        while rclpy.ok():
            time.sleep(2.0)
            r = wait_future(get.call_async(GetState.Request()), 4.0)
            if r is None:
                health["radar"] = "down"
                llog.error(
                    "CRITICAL FAILURE: SERVER radar IS DOWN after not receiving a heartbeat for 4000 ms."
                )
                continue
            health["radar"] = r.current_state.label

    def lm_diag():
        level = (
            ERROR
            if health["radar"] == "down"
            else OK
            if health["radar"] in (health["want"], "unknown")
            else WARN
        )
        return [
            status(
                level,
                "lifecycle_manager: Managed nodes",
                f"radar {health['radar']}",
                "",
                expected=health["want"],
            )
        ]

    Diagnostics(lm, lm_diag, period=2.0, group=lg)
    threading.Thread(target=bringup, daemon=True, name="bringup").start()
    ex = MultiThreadedExecutor(num_threads=2)
    ex.add_node(node)
    ex.add_node(lm)
    return ex


# ---------------------------------------- shore_link (telemetry relay over the radio)


def shore_link():
    node = Node("telemetry_relay", namespace=NS)
    log = node.get_logger()
    reliable = fault(f"/{NS}/telemetry_relay") == "reliable"
    cam_qos = QoSProfile(depth=5, reliability=ReliabilityPolicy.RELIABLE) if reliable else SENSOR
    log.info(
        "Loaded /opt/usv/config/shore_relay.yaml: odometry 2 Hz, diagnostics 1 Hz, camera 1 Hz "
        f"(camera qos: {'reliable, depth 5' if reliable else 'sensor_data'}), "
        "radio silvus-sc4200 at 10.42.0.1"
    )
    lq_pub = node.create_publisher(Float32, f"/{NS}/radio/link_quality", RELIABLE)
    odom_pub = node.create_publisher(Odometry, f"/{NS}/shore/odometry", RELIABLE)
    diag_pub = node.create_publisher(DiagnosticArray, f"/{NS}/shore/diagnostics_agg", RELIABLE)
    cam_pub = node.create_publisher(CompressedImage, f"/{NS}/shore/camera/compressed", SENSOR)
    st = {"up": True, "odom": 0.0, "cam": 0.0, "sent": 0, "dropped": 0}

    def throttle(key: str, period: float, pub):
        def cb(m) -> None:
            now = time.time()
            if now - st[key] < period:
                return
            st[key] = now
            if not st["up"]:
                st["dropped"] += 1
                return
            pub.publish(m)
            st["sent"] += 1

        return cb

    def link() -> None:
        now = time.time()
        up = link_up(now)
        if up != st["up"]:
            st["up"] = up
            if up:
                log.info("Radio link to shore restored (RSSI -71 dBm); resuming telemetry")
            else:
                log.warn("Radio link to shore lost (RSSI -96 dBm, SNR 2 dB); pausing telemetry")
        lq_pub.publish(Float32(data=(0.6 + 0.3 * math.sin(now / 17.0)) if up else 0.0))

    st["diag"] = 0.0
    node.create_subscription(Odometry, f"/{NS}/odometry/filtered", throttle("odom", 0.5, odom_pub), RELIABLE)
    node.create_subscription(DiagnosticArray, "/diagnostics_agg", throttle("diag", 0.9, diag_pub), RELIABLE)
    node.create_subscription(
        CompressedImage, f"/{NS}/camera/image_raw/compressed", throttle("cam", 1.0, cam_pub), cam_qos
    )
    node.create_timer(1.0, link)
    Diagnostics(
        node,
        lambda: [
            status(
                OK if st["up"] else WARN,
                "telemetry_relay: Shore radio link",
                "Connected" if st["up"] else "Link lost",
                "silvus-sc4200 10.42.0.1",
                sent=st["sent"],
                dropped=st["dropped"],
            )
        ],
    )
    return single_threaded(node)


# ---------------------------------------- recorder (rosbag2-like, joins late)

RECORDED = {
    f"/{NS}/mavros/global_position/raw/fix": (NavSatFix, SENSOR),
    f"/{NS}/odometry/filtered": (Odometry, RELIABLE),
    f"/{NS}/radar/targets": (PoseArray, RELIABLE),
    f"/{NS}/ais/messages": (String, RELIABLE),
    f"/{NS}/obstacles": (PoseArray, RELIABLE),
    f"/{NS}/cmd_vel": (Twist, RELIABLE),
    f"/{NS}/thruster_states": (JointState, RELIABLE),
    f"/{NS}/mission_executive/state": (String, LATCHED),
    f"/{NS}/mavros/state": (String, RELIABLE),
    "/diagnostics": (DiagnosticArray, RELIABLE),
}


def recorder():
    node = Node("rosbag_recorder", namespace=NS)
    log = node.get_logger()
    bag = time.strftime("/data/bags/usv_%Y_%m_%d-%H_%M_%S")
    log.info(f"Recording to '{bag}' (mcap, zstd chunks, split every 120 s)")
    st = {"n": 0, "bytes": 0, "t0": time.time(), "split": 0}

    def rec(m) -> None:
        st["n"] += 1
        st["bytes"] += 200

    for topic, (typ, qos) in RECORDED.items():
        node.create_subscription(typ, topic, rec, qos)
        log.info(f"Subscribed to topic '{topic}'")

    def split() -> None:
        if time.time() - st["t0"] > 120.0 * (st["split"] + 1):
            st["split"] += 1
            log.info(f"Writing bag file '{bag}/usv_{st['split']}.mcap' ({st['bytes'] // 1024} KB so far)")

    node.create_timer(1.0, split)
    Diagnostics(
        node,
        lambda: [
            status(
                OK,
                "rosbag_recorder: Recording",
                "Recording",
                "nvme0n1 /data",
                messages=st["n"],
                topics=len(RECORDED),
            )
        ],
        period=2.0,
    )
    return single_threaded(node)


# ---------------------------------------- diagnostics aggregator


def aggregator():
    node = Node("diagnostic_aggregator")
    pub = node.create_publisher(DiagnosticArray, "/diagnostics_agg", RELIABLE)
    seen: dict[str, tuple[float, DiagnosticStatus]] = {}
    groups = (
        ("mavros", "Autopilot"),
        ("controller_manager", "Propulsion"),
        ("radar", "Sensors"),
        ("ais", "Sensors"),
        ("camera", "Sensors"),
        ("thermal", "Sensors"),
        ("vessel_detector", "Perception"),
        ("ekf", "Localization"),
        ("lifecycle", "Mission"),
        ("telemetry", "Communications"),
        ("rosbag", "Logging"),
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
                    name=f"/USV/{g}/{name}",
                    message="Stale" if level == STALE else s.message,
                    hardware_id=s.hardware_id,
                    values=s.values,
                )
            )
            worst[g] = max(worst.get(g, OK), level)
        for g, lv in worst.items():
            out.append(DiagnosticStatus(level=lv, name=f"/USV/{g}", message="OK" if lv == OK else "Error"))
        pub.publish(DiagnosticArray(header=header(""), status=out))

    node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, RELIABLE)
    node.create_timer(1.0, publish)
    return single_threaded(node)


# ---------------------------------------- operator (the shore station's console)


def operator():
    node = Node("operator_console", namespace=NS)
    log = node.get_logger()
    log.info("Shore console connected (Kiel harbour master's office, operator 'wachhabender_2')")
    node.create_subscription(Odometry, f"/{NS}/shore/odometry", lambda _m: None, RELIABLE)
    node.create_subscription(DiagnosticArray, f"/{NS}/shore/diagnostics_agg", lambda _m: None, RELIABLE)
    node.create_subscription(CompressedImage, f"/{NS}/shore/camera/compressed", lambda _m: None, SENSOR)
    node.create_subscription(
        String, f"/{NS}/mission_executive/state", lambda m: log.info(f"Mission state: {m.data}"), LATCHED
    )
    teleop = node.create_publisher(Twist, f"/{NS}/cmd_vel_teleop", COMMAND)
    params = node.create_client(SetParameters, f"/{NS}/colregs_avoidance/set_parameters")
    t0 = time.time()
    st = {"param": False, "took": False}

    def tick() -> None:
        el = time.time() - t0
        if el > 5.0 and not st["param"] and params.service_is_ready():
            st["param"] = True
            v = random.choice((500.0, 700.0, 800.0))
            params.call_async(SetParameters.Request(parameters=[double("safe_range_m", v)]))
            log.info(f"Set /{NS}/colregs_avoidance safe_range_m to {v:.0f}")
        if 20.0 < el < 23.0:  # the operator takes the helm to steer around a buoy
            if not st["took"]:
                st["took"] = True
                log.info("Remote helm: taking control")
            c = Twist()
            c.linear.x, c.angular.z = 1.0, 0.2
            teleop.publish(c)

    node.create_timer(0.1, tick)
    return single_threaded(node)


# ---------------------------------------- ros2 lifecycle set (a crew member's CLI call)


def lifecycle_set(target: str, transition: str) -> int:
    rclpy.init()
    node = Node(f"_ros2cli_{os.getpid()}")
    cli = node.create_client(ChangeState, f"{target}/change_state")
    if not cli.wait_for_service(timeout_sec=5.0):
        print(f"Node not found: {target}", flush=True)
        return 1
    ids = {
        "configure": Transition.TRANSITION_CONFIGURE,
        "activate": Transition.TRANSITION_ACTIVATE,
        "deactivate": Transition.TRANSITION_DEACTIVATE,
        "cleanup": Transition.TRANSITION_CLEANUP,
    }
    req = ChangeState.Request()
    req.transition.id = ids[transition]
    fut = cli.call_async(req)
    rclpy.spin_until_future_complete(node, fut, timeout_sec=5.0)
    r = fut.result()
    print("Transitioning successful" if r and r.success else "Transitioning failed", flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


# ---------------------------------------- process main

PROCESSES = {
    "autopilot_bridge": autopilot_bridge,
    "thruster_control": thruster_control,
    "radar_driver": radar_driver,
    "ais": ais,
    "camera_container": camera_container,
    "perception": perception,
    "localization": localization,
    "guidance": guidance,
    "mission": mission,
    "shore_link": shore_link,
    "recorder": recorder,
    "diagnostics": aggregator,
    "operator": operator,
}
HOOKS: dict = {}  # "cpu" / "leak" -> what the process logs or does when its fault file appears


def main() -> int:
    global FAULT_DIR, PROCESS
    PROCESS, FAULT_DIR = sys.argv[1], Path(sys.argv[2])
    run_for = float(sys.argv[3]) if len(sys.argv) > 3 else 0.0
    if PROCESS == "lifecycle_set":
        return lifecycle_set(*sys.argv[4:6])
    if PROCESS == "perception":  # its launch file runs it as a Python container: Python's exit on a crash
        os.environ[PYTHON_EXIT] = "1"
    if PROCESS == "recorder":
        print("Waiting for /data (NVMe, LUKS) to be unlocked and mounted ...", flush=True)
        time.sleep(15.0)  # the recorder node exists only once the data disk is mounted: it joins late
    rclpy.init()
    spin(PROCESSES[PROCESS](), FAULT_DIR, PROCESS, run_for, HOOKS)


if __name__ == "__main__":
    sys.exit(main())
