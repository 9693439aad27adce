"""The tunnel crawler's processes: ``python -m bench.tunnel.robot PROCESS FAULT_DIR [RUN_FOR]``.

Every process builds its nodes (`build`), reads its nodes' fault files (``FAULT_DIR/tc.<node>``) and
spins as `bench.robot_process.spin` says. The inspection cycle is shared by every process through
the wall clock from ``TC_T0`` (`phase`, `flooded`, `line_dropout`, `failover_test`, `gas_levels`,
`nudge`); see `bench.tunnel.run` for the robot.
"""

from __future__ import annotations

import array
import json
import math
import os
import random
import sys
import tempfile
import threading
import time
import zlib
from collections import deque
from pathlib import Path

import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from geometry_msgs.msg import Quaternion, TransformStamped, Twist, Vector3Stamped
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import SetParametersResult
from rcl_interfaces.srv import SetParameters
from rclpy.action import ActionClient, ActionServer, CancelResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
from sensor_msgs.msg import BatteryState, CompressedImage, Imu, JointState, LaserScan
from std_msgs.msg import String
from test_msgs.action import Fibonacci
from test_msgs.srv import BasicTypes

from bench.robot_process import (
    RELIABLE,
    Diagnostics,
    header,
    on_shutdown_quiet,
    single_threaded,
    spin,
    status,
    to_s,
    wait_future,
)

OK, WARN, ERROR, STALE = (
    DiagnosticStatus.OK,
    DiagnosticStatus.WARN,
    DiagnosticStatus.ERROR,
    DiagnosticStatus.STALE,
)
NS = "/tc"
SENSOR = qos_profile_sensor_data  # best effort, keep last 5
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
COMMAND = QoSProfile(depth=1)

# ---------------------------------------------------------------------------------------------
# The inspection cycle, shared by every process through the wall clock.

T0 = float(os.environ.get("TC_T0", repr(time.time())))
BRINGUP_S = 10.0  # lowered through manhole MH-14, tether clamped, self-test
SEGMENT_S = 56.0
PHASES = (  # name, start, end (s into a segment)
    ("transit", 0.0, 18.0),
    ("inspect", 18.0, 40.0),
    ("survey", 40.0, 48.0),
    ("reel_sync", 48.0, SEGMENT_S),
)
SPEED_MM_S = {"transit": 250, "inspect": 80}
FRAME_RATE = {"transit": 5.0, "inspect": 10.0, "survey": 10.0, "reel_sync": 5.0, "bringup": 5.0}
PIPE_R = 0.30  # DN600 vitrified clay


def elapsed(t: float | None = None) -> float:
    return (time.time() if t is None else t) - T0


def segment_of(t: float | None = None) -> tuple[int, float]:
    """The pipe segment being inspected (-1: bring-up) and the seconds into it."""
    e = elapsed(t) - BRINGUP_S
    if e < 0:
        return -1, e
    k = int(e // SEGMENT_S)
    return k, e - k * SEGMENT_S


def segment_start(k: int) -> float:
    return T0 + BRINGUP_S + k * SEGMENT_S


def phase(t: float | None = None) -> tuple[int, str, float]:
    """The segment, the phase's name and the seconds into the segment."""
    k, s = segment_of(t)
    if k < 0:
        return k, "bringup", s
    for name, a, b in PHASES:
        if a <= s < b:
            return k, name, s
    return k, "reel_sync", s


def flooded(t: float | None = None) -> bool:
    """The crawler's sonar transducer below the water line: the sag in every segment (26-44 s)."""
    k, s = segment_of(t)
    return k >= 0 and 26.0 <= s < 44.0


def nudge(t: float | None = None) -> bool:
    """The surface operator nudges the crawler with the joystick at the survey of every third
    segment (44-47 s into segments 1, 4, 7, ...)."""
    k, s = segment_of(t)
    return k >= 0 and k % 3 == 1 and 44.0 <= s < 47.0


def line_dropout(t: float | None = None) -> bool:
    """VDSL2 line A's brief dropouts: 1-3 s once in every 90 s window (seeded, 20-80 s into it)."""
    e = elapsed(t)
    w = int(e // 90)
    rng = random.Random(600 + w)
    start = w * 90 + rng.uniform(20, 80)
    return start <= e < start + rng.uniform(1.0, 3.0)


def failover_test(t: float | None = None) -> bool:
    """The scheduled hot-standby test: modem A releases the link for 10 s at 150 s, then every 300 s."""
    e = elapsed(t)
    return e >= 150 and (e - 150) % 300 < 10


def gas_levels(t: float | None = None) -> tuple[float, float, float]:
    """H2S ppm, CH4 %LEL, O2 %vol; an H2S pocket at a lateral in every fourth segment (2, 6, ...)."""
    t = time.time() if t is None else t
    k, s = segment_of(t)
    h2s = 1.1 + 0.4 * math.sin(t / 17.0)
    if k >= 0 and k % 4 == 2 and 20.0 <= s < 36.0:
        h2s += 7.0 * (1 - abs(s - 28.0) / 8.0)
    ch4 = 2.0 + 0.8 * math.sin(t / 41.0)
    o2 = 20.8 - 0.05 * math.sin(t / 23.0)
    return h2s, ch4, o2


def quat(roll: float = 0.0, pitch: float = 0.0, yaw: float = 0.0) -> Quaternion:
    cr, sr = math.cos(roll / 2), math.sin(roll / 2)
    cp, sp = math.cos(pitch / 2), math.sin(pitch / 2)
    cy, sy = math.cos(yaw / 2), math.sin(yaw / 2)
    return Quaternion(
        w=cr * cp * cy + sr * sp * sy,
        x=sr * cp * cy - cr * sp * sy,
        y=cr * sp * cy + sr * cp * sy,
        z=cr * cp * sy - sr * sp * cy,
    )


class FaultFile:
    """A node's fault file ``FAULT_DIR/tc.<node>`` (`bench.handwritten.NamespacedRobot.fault_file`):
    its word, read at start and every 0.5 s."""

    def __init__(self, fault_dir: Path, node: str) -> None:
        self.path = fault_dir / f"{NS.strip('/')}.{node}"
        self.word = self._read()
        threading.Thread(target=self._poll, daemon=True).start()

    def _read(self) -> str:
        try:
            return self.path.read_text().strip()
        except OSError:
            return ""

    def _poll(self) -> None:
        while True:
            time.sleep(0.5)
            self.word = self._read()


# ---------------------------------------------------------------------------------------------
# crawler_base: the track drives (EtherCAT), the IMU, the velocity mux and the power monitor


class Base:
    """What the track driver, the IMU and the mux share in the crawler_base process."""

    def __init__(self) -> None:
        self.v = 0.0  # m/s, actual
        self.w = 0.0
        self.cmd_v = self.cmd_w = 0.0
        self.cmd_t = 0.0


class TrackDriver(Node):
    """Two brushless track motors on EtherCAT (Elmo Gold Twitter): ``/tc/cmd_vel`` ->
    ``/tc/tracks/odom`` 25 Hz (stamped 3 ms back) and ``/tc/tracks/joint_states`` 10 Hz."""

    def __init__(self, base: Base) -> None:
        super().__init__("track_driver", namespace=NS)
        self.b = base
        self.x = self.yaw = 0.0
        self.left = self.right = 0.0
        self.last = time.time()
        self.odom = self.create_publisher(Odometry, "tracks/odom", RELIABLE)
        self.joints = self.create_publisher(JointState, "tracks/joint_states", RELIABLE)
        self.create_subscription(Twist, "cmd_vel", self.on_cmd, COMMAND)
        self.create_timer(0.04, self.tick)
        self.create_timer(0.1, self.tick_joints)
        self.log = self.get_logger()
        self.log.info("EtherCAT master up on eth1: 2 slaves (track_left 0x1001, track_right 0x1002) in OP")
        Diagnostics(self, self.diag)

    def on_cmd(self, msg: Twist) -> None:
        self.b.cmd_v, self.b.cmd_w, self.b.cmd_t = msg.linear.x, msg.angular.z, time.time()

    def tick(self) -> None:
        now = time.time()
        dt, self.last = now - self.last, now
        if now - self.b.cmd_t > 0.5:
            self.b.cmd_v = self.b.cmd_w = 0.0
        dv = max(-0.25 * dt, min(0.25 * dt, self.b.cmd_v - self.b.v))  # 0.25 m/s^2 in the sludge
        self.b.v += dv
        self.b.w = self.b.cmd_w
        self.x += self.b.v * dt
        self.yaw += self.b.w * dt
        self.left += (self.b.v - 0.11 * self.b.w) * dt / 0.045
        self.right += (self.b.v + 0.11 * self.b.w) * dt / 0.045
        msg = Odometry(header=header("odom", now - 0.003), child_frame_id="base_link")
        msg.pose.pose.position.x = self.x
        msg.pose.pose.orientation = quat(yaw=self.yaw)
        msg.twist.twist.linear.x = self.b.v + random.gauss(0, 0.002)
        msg.twist.twist.angular.z = self.b.w
        self.odom.publish(msg)

    def tick_joints(self) -> None:
        wl = (self.b.v - 0.11 * self.b.w) / 0.045
        wr = (self.b.v + 0.11 * self.b.w) / 0.045
        self.joints.publish(
            JointState(
                header=header("base_link"),
                name=["track_left", "track_right"],
                position=[self.left, self.right],
                velocity=[wl, wr],
                effort=[1.8 + abs(wl) * 0.1, 1.8 + abs(wr) * 0.1],
            )
        )

    def diag(self):
        return [
            status(
                OK,
                "track_driver: EtherCAT",
                "OP",
                "ecat-elmo-0x1001-0x1002",
                motor_temp_c=round(38 + elapsed() / 40, 1),
                speed=round(self.b.v, 3),
                bus_voltage=47.6,
            )
        ]


class ImuDriver(Node):
    """VectorNav VN-100 on UART: ``/tc/imu/data`` 50 Hz best effort, stamped 2 ms back."""

    def __init__(self, fault_dir: Path, base: Base) -> None:
        super().__init__("imu_driver", namespace=NS)
        self.fault = FaultFile(fault_dir, "imu_driver")
        self.b = base
        self.pub = self.create_publisher(Imu, "imu/data", SENSOR)
        self.timer = self.create_timer(0.02, self.sample)
        self.slow = False
        self.get_logger().info("VN-100 on /dev/ttyTHS0 at 921600 baud: async output 50 Hz (YPR, accel, gyro)")

    def sample(self) -> None:
        if self.fault.word == "rate" and not self.slow:
            self.slow = True
            self.get_logger().warn(
                "UART framing errors on /dev/ttyTHS0 (37 in 1 s): falling back to 230400 "
                "baud, async output rate reduced to 20 Hz"
            )
            self.timer.cancel()
            self.timer = self.create_timer(0.05, self.sample)
        t = time.time()
        roll = 0.04 * math.sin(t * 0.7) * (1.0 + 4 * abs(self.b.v))  # riding up the pipe wall
        msg = Imu(header=header("imu_link", t - 0.002))
        msg.orientation = quat(roll=roll, pitch=-0.004)
        msg.angular_velocity.z = self.b.w + random.gauss(0, 0.002)
        msg.linear_acceleration.x = random.gauss(0, 0.03)
        msg.linear_acceleration.z = 9.81 + random.gauss(0, 0.03)
        self.pub.publish(msg)


class CmdVelMux(Node):
    """twist_mux-like: ``/tc/cmd_vel/auto`` (priority 10) and ``/tc/cmd_vel/joy`` (priority 100, the
    surface operator's joystick) -> ``/tc/cmd_vel``; ``~/active`` latched on change."""

    INPUTS = (("joystick", "cmd_vel/joy", 100), ("navigation", "cmd_vel/auto", 10))

    def __init__(self) -> None:
        super().__init__("cmd_vel_mux", namespace=NS)
        self.pub = self.create_publisher(Twist, "cmd_vel", COMMAND)
        self.active_pub = self.create_publisher(String, "~/active", LATCHED)
        self.last = {name: 0.0 for name, _t, _p in self.INPUTS}
        for name, topic, prio in self.INPUTS:
            self.create_subscription(Twist, topic, lambda m, n=name, p=prio: self.on_input(n, p, m), COMMAND)
        self.active = "idle"
        self.active_pub.publish(String(data="idle"))
        self.create_timer(0.5, self.check)

    def _set(self, name: str) -> None:
        if name != self.active:
            if name == "joystick":
                self.get_logger().info(f"Input 'joystick' (priority 100) took over from '{self.active}'")
            self.active = name
            self.active_pub.publish(String(data=name))

    def on_input(self, name: str, prio: int, msg: Twist) -> None:
        now = time.time()
        self.last[name] = now
        higher = [n for n, _t, p in self.INPUTS if p > prio and now - self.last[n] < 0.5]
        if higher:
            return
        self._set(name)
        self.pub.publish(msg)

    def check(self) -> None:
        now = time.time()
        live = [n for n, _t, _p in self.INPUTS if now - self.last[n] < 0.5]
        if not live:
            self._set("idle")


class PowerMonitor(Node):
    """The tether power module (380 VDC down the tether -> 48 V bus): ``/tc/power/state`` 1 Hz."""

    def __init__(self, base: Base) -> None:
        super().__init__("power_monitor", namespace=NS)
        self.b = base
        self.pub = self.create_publisher(BatteryState, "power/state", RELIABLE)
        self.create_timer(1.0, self.tick)
        Diagnostics(self, self.diag, 2.0)

    def current(self) -> float:
        return 2.4 + 9.0 * abs(self.b.v)

    def tick(self) -> None:
        self.pub.publish(
            BatteryState(
                header=header("power_module"),
                voltage=47.9 - 0.05 * self.current(),
                current=-self.current(),
                percentage=float("nan"),
                present=True,
                power_supply_status=BatteryState.POWER_SUPPLY_STATUS_NOT_CHARGING,
            )
        )

    def diag(self):
        return [
            status(
                OK,
                "power_monitor: DC-DC 380/48 V",
                "OK",
                "vicor-dcm-380-48",
                bus_current_a=round(self.current(), 2),
                module_temp_c=46,
            )
        ]


# ---------------------------------------------------------------------------------------------
# sensor_container: laser ring profiler, sonar profiler, inclinometer (ONE single-threaded executor)


class LaserProfiler(Node):
    """Laser ring profiler (structured-light ring + camera), hardware-triggered every 20 mm of track
    travel: ``~/profile`` LaserScan 360 beams only while the crawler moves (12.5 Hz in transit, 4 Hz
    inspecting); ``~/ovality`` every 10 profiles (0.2 m of pipe)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("laser_profiler", namespace=NS)
        self.fault = FaultFile(fault_dir, "laser_profiler")
        self.pub = self.create_publisher(LaserScan, "~/profile", SENSOR)
        self.ov_pub = self.create_publisher(Vector3Stamped, "~/ovality", RELIABLE)
        self.create_subscription(JointState, "tracks/joint_states", self.on_joints, RELIABLE)
        self.speed = 0.0
        self.dist = 0.0
        self.last = time.monotonic()
        self.n = 0
        self.rng = random.Random(3)
        base = [PIPE_R * (1 + 0.02 * math.cos(2 * math.radians(i))) for i in range(360)]
        self.shapes = [array.array("f", (r + self.rng.gauss(0, 0.0008) for r in base)) for _ in range(6)]
        self.dry = array.array("f", [900.0] * 360)
        self.wet = array.array("f", [900.0] * 225 + [6.0] * 90 + [900.0] * 45)  # 225-315 deg: water
        self.log = self.get_logger()
        self.log.info("Ring profiler on /dev/ttyTHS1 (460800 baud): trigger every 20 mm of travel, 360 pts")
        self.create_timer(0.04, self.tick)
        Diagnostics(self, self.diag)

    def on_joints(self, msg: JointState) -> None:
        self.speed = abs(sum(msg.velocity) / 2 * 0.045)

    def tick(self) -> None:
        now = time.monotonic()
        self.dist += self.speed * (now - self.last)
        self.last = now
        if self.dist < 0.02:
            return
        self.dist -= 0.02
        if self.dist > 0.04:
            self.dist = 0.0
        if self.fault.word == "hang":
            self.log.warn(
                "Serial frame timeout on /dev/ttyTHS1 (no 0xAA55 sync word for 250 ms); "
                "re-synchronizing with the profiler head"
            )
            threading.Event().wait()  # the blocking read() with no timeout: the container stalls
        self.n += 1
        msg = LaserScan(
            header=header("profiler_link", time.time() - 0.01),
            angle_min=0.0,
            angle_max=2 * math.pi * 359 / 360,
            angle_increment=2 * math.pi / 360,
            time_increment=0.0,
            scan_time=0.002,
            range_min=0.05,
            range_max=1.5,
        )
        msg.ranges = self.shapes[self.n % 6]
        msg.intensities = self.wet if flooded() else self.dry
        self.pub.publish(msg)
        if self.n % 10 == 0:
            k, s = segment_of()
            ov = 1.8 + 0.6 * math.sin(self.n / 37.0) + (4.6 if k % 2 == 1 and 30.0 <= s < 33.0 else 0.0)
            self.ov_pub.publish(
                Vector3Stamped(
                    header=msg.header,
                    vector=_v3(ov, 2 * PIPE_R * (1 - ov / 200), 2 * PIPE_R * (1 + ov / 200)),
                )
            )

    def diag(self):
        return [
            status(
                OK,
                "laser_profiler: ring head",
                "Triggered" if self.speed > 0.005 else "Idle (no travel)",
                "ringprofiler-RP600-0117",
                profiles=self.n,
                laser_temp_c=33,
            )
        ]


def _v3(x: float, y: float, z: float):
    v = Vector3Stamped().vector
    v.x, v.y, v.z = x, y, z
    return v


class SonarProfiler(Node):
    """Imaging sonar profiler for the flooded invert: ``~/profile`` LaserScan 200 beams at 5 Hz ONLY
    while the transducer is submerged (its wet switch); mode switches logged."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("sonar_profiler", namespace=NS)
        self.fault = FaultFile(fault_dir, "sonar_profiler")
        self.pub = self.create_publisher(LaserScan, "~/profile", SENSOR)
        self.wet = False
        self.n = 0
        rng = random.Random(11)
        self.ranges = [array.array("f", (PIPE_R + rng.gauss(0, 0.003) for _ in range(200))) for _ in range(4)]
        self.log = self.get_logger()
        self.create_timer(0.2, self.tick)
        Diagnostics(self, self.diag)

    def tick(self) -> None:
        wet = flooded() and self.fault.word != "stuck"  # a stuck wet switch reads dry for good
        if wet != self.wet:
            self.wet = wet
            self.log.info(
                "Transducer submerged (wet switch closed): sonar profiling on, 2.25 MHz, 200 beams"
                if wet
                else "Transducer dry (wet switch open): sonar profiling off, laser only"
            )
        if not wet:
            return
        self.n += 1
        msg = LaserScan(
            header=header("sonar_link", time.time() - 0.05),
            angle_min=math.radians(200),
            angle_max=math.radians(340),
            angle_increment=math.radians(140 / 199),
            scan_time=0.2,
            range_min=0.05,
            range_max=1.0,
        )
        msg.ranges = self.ranges[self.n % 4]
        self.pub.publish(msg)

    def diag(self):
        return [
            status(
                OK,
                "sonar_profiler: transducer",
                "Profiling" if self.wet else "Dry: standby",
                "sonar-SP2250-0042",
                profiles=self.n,
            )
        ]


class Inclinometer(Node):
    """Dual-axis inclinometer (SCL3300): ``~/tilt`` Vector3Stamped (roll, pitch rad) 5 Hz."""

    def __init__(self) -> None:
        super().__init__("inclinometer", namespace=NS)
        self.pub = self.create_publisher(Vector3Stamped, "~/tilt", RELIABLE)
        self.n = 0
        self.create_timer(0.2, self.tick)
        Diagnostics(self, self.diag, 2.0)

    def tick(self) -> None:
        t = time.time()
        self.n += 1
        self.pub.publish(
            Vector3Stamped(
                header=header("inclinometer_link", t - 0.005),
                vector=_v3(0.04 * math.sin(t * 0.7), -0.004 + random.gauss(0, 0.0003), 0.0),
            )
        )

    def diag(self):
        return [status(OK, "inclinometer: SCL3300", "OK", "scl3300-spi1", samples=self.n)]


# ---------------------------------------------------------------------------------------------
# camera: the pan-tilt-zoom inspection camera


def _jpegs(n: int, size: int, seed: int) -> list[bytes]:
    rng = random.Random(seed)
    return [b"\xff\xd8\xff\xe0" + rng.randbytes(size - 6) + b"\xff\xd9" for _ in range(n)]


class PtzCamera(Node):
    """PTZ inspection camera (1080p, 10x zoom, LED ring) over RTSP + a serial PTZ head:
    ``~/image/compressed`` JPEG ~30 KB at the ``frame_rate`` parameter (the executive sets 5 Hz in
    transit, 10 Hz inspecting), ``~/ptz_state`` 5 Hz, base_link->camera_link on ``/tf`` 5 Hz,
    ``~/capture`` (BasicTypes: a full-resolution still)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("ptz_camera", namespace=NS)
        self.fault = FaultFile(fault_dir, "ptz_camera")
        self.declare_parameter("frame_rate", 5.0)
        self.declare_parameter("jpeg_quality", 70)
        self.img = self.create_publisher(CompressedImage, "~/image/compressed", SENSOR)
        self.ptz = self.create_publisher(JointState, "~/ptz_state", RELIABLE)
        self.tf = self.create_publisher(TransformStamped, "/tf", RELIABLE)
        self.create_service(BasicTypes, "~/capture", self.capture)
        self.frames = _jpegs(4, 30000, 21)
        self.n = 0
        self.started = time.time()
        self.crash_after = random.uniform(2.0, 3.0)
        self.pan = self.tilt = 0.0
        self.rate = 5.0
        self.timer = self.create_timer(1 / self.rate, self.frame)
        self.add_on_set_parameters_callback(self.on_params)
        self.create_timer(0.2, self.poll_head)
        self.log = self.get_logger()
        self.log.info(
            "RTSP stream rtsp://10.0.3.2:554/main opened (1920x1080 MJPEG), PTZ head on /dev/ttyUSB0"
        )
        Diagnostics(self, self.diag)

    def on_params(self, params) -> SetParametersResult:
        for p in params:
            if p.name == "frame_rate":
                if not 1.0 <= p.value <= 15.0:
                    return SetParametersResult(successful=False, reason="frame_rate must be 1-15 Hz")
                if p.value != self.rate:
                    self.rate = float(p.value)
                    self.timer.cancel()
                    self.timer = self.create_timer(1 / self.rate, self.frame)
        return SetParametersResult(successful=True)

    def frame(self) -> None:
        self.n += 1
        msg = CompressedImage(header=header("camera_optical", time.time() - 0.04), format="jpeg")
        msg.data = self.frames[self.n % 4]
        self.img.publish(msg)

    def poll_head(self) -> None:
        reply = {"pan": self.pan, "tilt": self.tilt, "zoom": "1.0"}
        if self.fault.word == "crashloop" and time.time() - self.started > self.crash_after:
            reply["zoom"] = "3.5x"  # the head's new firmware answers the zoom with its unit
        zoom = float(reply["zoom"])  # ValueError: the driver ends
        _k, name, s = phase()
        if name == "inspect":
            self.pan = 0.6 * math.sin(s * 0.5)
            self.tilt = 0.15
        elif name == "survey":
            self.pan = math.pi * math.sin((s - 40.0) / 8.0 * math.pi)
            self.tilt = 0.4
        else:
            self.pan, self.tilt = 0.0, 0.0
        h = header("base_link")
        self.ptz.publish(
            JointState(
                header=h, name=["ptz_pan", "ptz_tilt", "ptz_zoom"], position=[self.pan, self.tilt, zoom]
            )
        )
        tf = TransformStamped(header=h, child_frame_id="camera_link")
        tf.transform.translation.x, tf.transform.translation.z = 0.32, 0.12
        tf.transform.rotation = quat(pitch=self.tilt, yaw=self.pan)
        self.tf.publish(tf)

    def capture(self, req: BasicTypes.Request, resp: BasicTypes.Response) -> BasicTypes.Response:
        k, _name, s = phase()
        time.sleep(0.25)  # the full-resolution still over RTSP
        resp.bool_value = True
        resp.string_value = f"/data/survey/MH14-MH15/seg{k:03d}_joint_{int(s)}.jpg"
        self.log.info(f"Still captured: {resp.string_value} (4056x3040)")
        return resp

    def diag(self):
        return [
            status(
                OK,
                "ptz_camera: stream",
                f"{self.rate:.0f} fps",
                "ptz-cam-IPC-0921",
                frames=self.n,
                led_ring="60 %",
            )
        ]


# ---------------------------------------------------------------------------------------------
# perception: the lifecycle-managed defect detector


DEFECTS = (
    "crack (circumferential)",
    "root intrusion",
    "joint displaced",
    "deposits (encrustation)",
    "lateral protruding",
)


class DefectDetector(LifecycleNode):
    """Defect detector (EN 13508-2 codes) on the inspection images and the ring profiles: activated
    by the executive for each inspection phase; publishes ``~/defects`` ONLY when it finds one."""

    def __init__(self) -> None:
        super().__init__("defect_detector", namespace=NS)
        self.subs = []
        self.pub = None
        self.frames = 0
        self.last_sonar = 0.0
        self.water_t = 0.0
        self.warned = 0.0
        self.found: set[tuple[int, int]] = set()
        self.get_logger().info("Loaded model crackseg-v4 (640x384, int8), EN 13508-2 code map")

    def on_configure(self, state) -> TransitionCallbackReturn:
        self.pub = self.create_lifecycle_publisher(String, "~/defects", RELIABLE)
        self.get_logger().info("Configuring: warm-up inference done")
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state) -> TransitionCallbackReturn:
        self.subs = [
            self.create_subscription(CompressedImage, "ptz_camera/image/compressed", self.on_image, SENSOR),
            self.create_subscription(LaserScan, "laser_profiler/profile", self.on_profile, SENSOR),
            self.create_subscription(Vector3Stamped, "laser_profiler/ovality", self.on_ovality, RELIABLE),
            self.create_subscription(LaserScan, "sonar_profiler/profile", self.on_sonar, SENSOR),
        ]
        self.last_sonar = time.time()
        self.get_logger().info("Activating: detecting on /tc/ptz_camera/image/compressed")
        return super().on_activate(state)

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        for s in self.subs:
            self.destroy_subscription(s)
        self.subs = []
        self.get_logger().info(f"Deactivating ({self.frames} frames processed)")
        return super().on_deactivate(state)

    def on_cleanup(self, state) -> TransitionCallbackReturn:
        return TransitionCallbackReturn.SUCCESS

    def _report(self, code: str, what: str, stamp, **extra) -> None:
        k, s = segment_of()
        d = {"segment": k, "at_s": round(s, 1), "code": code, "defect": what, "stamp": to_s(stamp), **extra}
        if self.pub is not None:
            self.pub.publish(String(data=json.dumps(d)))
        self.get_logger().info(f"Defect {code} ({what}) in segment {k} at {s:.1f} s")

    def on_image(self, msg: CompressedImage) -> None:
        self.frames += 1
        zlib.crc32(msg.data)  # the decode + inference (on the NPU: light on the CPU)
        k, s = segment_of()
        rng = random.Random(k * 7919)
        at = [int(rng.uniform(19, 39)) for _ in range(rng.choice((0, 1, 1, 2)))]
        for i, a in enumerate(at):
            if a <= s < a + 1 and (k, i) not in self.found:
                self.found.add((k, i))
                code = ("BAB", "BBA", "BAJ", "BBB", "BAG")[rng.randrange(5)]
                self._report(
                    code,
                    DEFECTS[("BAB", "BBA", "BAJ", "BBB", "BAG").index(code)],
                    msg.header.stamp,
                    confidence=round(rng.uniform(0.7, 0.97), 2),
                )

    def on_profile(self, msg: LaserScan) -> None:
        now = time.time()
        if not (msg.intensities and msg.intensities[270] < 50.0):
            self.water_t = 0.0
            return
        if not self.water_t:
            self.water_t = now
        if now - self.water_t > 2.0 and now - self.last_sonar > 2.0 and now - self.warned > 5.0:
            self.warned = now
            self.get_logger().warn(
                f"Water over the invert but no sonar profile for {now - self.last_sonar:.1f} s: "
                "below-water-line section not inspected"
            )

    def on_ovality(self, msg: Vector3Stamped) -> None:
        if msg.vector.x > 5.0:
            k, _ = segment_of()
            if (k, -1) not in self.found:
                self.found.add((k, -1))
                self._report("BAA", "deformation", msg.header.stamp, ovality_pct=round(msg.vector.x, 1))

    def on_sonar(self, msg: LaserScan) -> None:
        self.last_sonar = time.time()


# ---------------------------------------------------------------------------------------------
# localization: track odometry + IMU + inclinometer + tether length


class CrawlerLocalization(Node):
    """EKF-like fusion: track odometry (25 Hz) + IMU (50 Hz) + inclinometer -> ``/tc/odometry/filtered``
    and odom->base_link on ``/tf`` 20 Hz; the reel's paid-out tether length corrects the chainage:
    map->odom on ``/tf`` 1 Hz."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("crawler_localization", namespace=NS)
        self.fault = FaultFile(fault_dir, "crawler_localization")
        reliable = self.fault.word == "reliable"
        imu_qos = QoSProfile(
            depth=10, reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT
        )
        self.get_logger().info(
            f"Loaded crawler_localization.yaml (imu0 qos: {'reliable' if reliable else 'best_effort'}"
            ", odom0: tracks/odom, tether0: reel/payout, two_d_mode: false)"
        )
        self.pub = self.create_publisher(Odometry, "odometry/filtered", RELIABLE)
        self.tf = self.create_publisher(TransformStamped, "/tf", RELIABLE)
        self.create_subscription(Odometry, "tracks/odom", self.on_odom, RELIABLE)
        self.create_subscription(Imu, "imu/data", self.on_imu, imu_qos)
        self.create_subscription(Vector3Stamped, "inclinometer/tilt", self.on_tilt, RELIABLE)
        self.create_subscription(JointState, "reel/payout", self.on_payout, RELIABLE)
        self.v = self.w = 0.0
        self.roll = self.pitch = 0.0
        self.x = self.yaw = 0.0
        self.payout = None
        self.offset = 0.0
        self.last = time.time()
        self.n_imu = self.n_odom = 0
        self.win_t = time.time()
        self.create_timer(0.05, self.update)
        self.create_timer(1.0, self.correct)
        Diagnostics(self, self.diag)

    def on_odom(self, msg: Odometry) -> None:
        self.v, self.n_odom = msg.twist.twist.linear.x, self.n_odom + 1

    def on_imu(self, msg: Imu) -> None:
        self.w, self.n_imu = msg.angular_velocity.z, self.n_imu + 1
        q = msg.orientation
        self.roll = math.atan2(2 * (q.w * q.x + q.y * q.z), 1 - 2 * (q.x * q.x + q.y * q.y))

    def on_tilt(self, msg: Vector3Stamped) -> None:
        self.pitch = msg.vector.y

    def on_payout(self, msg: JointState) -> None:
        self.payout = msg.position[0]

    def update(self) -> None:
        now = time.time()
        dt, self.last = now - self.last, now
        self.yaw += self.w * dt
        self.x += self.v * math.cos(self.pitch) * dt
        h = header("odom", now)
        msg = Odometry(header=h, child_frame_id="base_link")
        msg.pose.pose.position.x = self.x
        msg.pose.pose.position.z = -self.x * math.sin(self.pitch)
        msg.pose.pose.orientation = quat(self.roll, self.pitch, self.yaw)
        msg.twist.twist.linear.x, msg.twist.twist.angular.z = self.v, self.w
        self.pub.publish(msg)
        tf = TransformStamped(header=h, child_frame_id="base_link")
        tf.transform.translation.x = self.x
        tf.transform.rotation = msg.pose.pose.orientation
        self.tf.publish(tf)

    def correct(self) -> None:
        if self.payout is not None:  # tether paid out minus the slack the reel keeps (0.5 m) and MH depth
            target = self.payout - 0.5 - 3.2
            self.offset += 0.2 * ((target - self.x) - self.offset) if target > 0 else 0.0
        tf = TransformStamped(header=header("map"), child_frame_id="odom")
        tf.transform.translation.x = 2.4 + self.offset  # MH-14's invert in the sewer map
        tf.transform.rotation.w = 1.0
        self.tf.publish(tf)

    def diag(self):
        now = time.time()
        span = max(now - self.win_t, 1e-3)
        imu_hz, odom_hz = self.n_imu / span, self.n_odom / span
        self.n_imu = self.n_odom = 0
        self.win_t = now

        def topic(name, hz, lo, hi):
            ok = lo <= hz <= hi
            msg = (
                "Desired frequency met"
                if ok
                else ("No events recorded." if hz == 0 else "Frequency too low.")
            )
            return status(
                OK if ok else WARN,
                f"crawler_localization: {name} topic status",
                msg,
                "none",
                frequency=round(hz, 1),
                expected=f"{lo}-{hi}",
            )

        return [
            topic("imu", imu_hz, 45, 55),
            topic("odometry", odom_hz, 22, 28),
            status(
                OK,
                "crawler_localization: chainage",
                f"{2.4 + self.offset + self.x:.2f} m from MH-14",
                "none",
                tether_correction=round(self.offset, 3),
            ),
        ]


# ---------------------------------------------------------------------------------------------
# mission: the inspection executive and the crawl controller (MultiThreadedExecutor, groups)


class CrawlController(Node):
    """In-pipe crawl controller: the ``~/crawl`` action (Fibonacci ``order`` = speed mm/s, runs until
    the phase ends or it is cancelled) -> ``/tc/cmd_vel/auto`` 10 Hz, steering against the roll so
    the crawler stays on the invert."""

    def __init__(self) -> None:
        super().__init__("crawl_controller", namespace=NS)
        self.pub = self.create_publisher(Twist, "cmd_vel/auto", COMMAND)
        self.roll = 0.0
        g = MutuallyExclusiveCallbackGroup()
        self.create_subscription(
            Vector3Stamped, "inclinometer/tilt", self.on_tilt, RELIABLE, callback_group=g
        )
        ActionServer(
            self,
            Fibonacci,
            "crawl_controller/crawl",
            self.crawl,
            callback_group=ReentrantCallbackGroup(),
            cancel_callback=lambda _g: CancelResponse.ACCEPT,
        )

    def on_tilt(self, msg: Vector3Stamped) -> None:
        self.roll = msg.vector.x

    def crawl(self, goal) -> Fibonacci.Result:
        v = goal.request.order / 1000.0
        k, name, _s = phase()
        self.get_logger().info(f"Crawl goal: {v:.3f} m/s ({name}, segment {k})")
        n = 0
        while rclpy.ok():
            if goal.is_cancel_requested:
                self.pub.publish(Twist())
                goal.canceled()
                self.get_logger().warn(f"Crawl goal cancelled after {n / 10:.1f} s")
                return Fibonacci.Result(sequence=[n])
            k2, now_name, _s = phase()
            if (k2, now_name) != (k, name):
                break
            tw = Twist()
            tw.linear.x, tw.angular.z = v, -0.5 * self.roll
            self.pub.publish(tw)
            n += 1
            if n % 10 == 0:
                goal.publish_feedback(Fibonacci.Feedback(sequence=[n // 10]))
            time.sleep(0.1)
        self.pub.publish(Twist())
        goal.succeed()
        return Fibonacci.Result(sequence=[n])


class InspectionExecutive(Node):
    """The inspection executive: runs every segment (transit, inspect, survey, reel sync) by the
    clock: the crawl goals, the camera's ``frame_rate`` parameter, the defect detector's lifecycle,
    the survey still (``/tc/ptz_camera/capture``), the tether length sync
    (``/tc/reel_controller/sync_length``); ``/tc/mission/mode`` and ``~/state`` latched; halts the
    crawler when the gas readings go stale (confined-space rule)."""

    def __init__(self) -> None:
        super().__init__("inspection_executive", namespace=NS)
        g_calls, g_watch = MutuallyExclusiveCallbackGroup(), MutuallyExclusiveCallbackGroup()
        self.crawl = ActionClient(self, Fibonacci, "crawl_controller/crawl", callback_group=g_calls)
        self.cam_params = self.create_client(
            SetParameters, "ptz_camera/set_parameters", callback_group=g_calls
        )
        self.capture = self.create_client(BasicTypes, "ptz_camera/capture", callback_group=g_calls)
        self.sync = self.create_client(BasicTypes, "reel_controller/sync_length", callback_group=g_calls)
        self.change = self.create_client(ChangeState, "defect_detector/change_state", callback_group=g_calls)
        self.get = self.create_client(GetState, "defect_detector/get_state", callback_group=g_calls)
        self.mode_pub = self.create_publisher(String, "mission/mode", LATCHED)
        self.state_pub = self.create_publisher(String, "~/state", LATCHED)
        self.create_subscription(
            String, "gas_monitor/readings", self.on_gas, RELIABLE, callback_group=g_watch
        )
        self.create_subscription(String, "gas_monitor/alarm", self.on_alarm, LATCHED, callback_group=g_watch)
        self.gas_t = time.time()
        self.gas_stale = False
        self.stale_logged = 0.0
        self.crawl_gh = None
        self.mode = ""
        self.log = self.get_logger()
        self._set("bringup", -1)
        self.create_timer(1.0, self.watchdog, callback_group=g_watch)
        Diagnostics(self, self.diag, group=g_watch)
        self.log.info("Inspection MH-14 -> MH-15 (DN600 VC, 62 m): job 2024-1187, operator on the surface")
        threading.Thread(target=on_shutdown_quiet(self.run), daemon=True).start()

    def on_gas(self, msg: String) -> None:
        self.gas_t = time.time()
        if self.gas_stale:
            self.gas_stale = False
            self.log.info("Gas readings back: crawler released")

    def on_alarm(self, msg: String) -> None:
        a = json.loads(msg.data)
        if a.get("level", "none") != "none":
            self.log.warn(f"Gas alarm {a['level']} ({a['gas']} {a['value']}): continuing, operator notified")

    def watchdog(self) -> None:
        age = time.time() - self.gas_t
        if age > 5.0:
            self.gas_stale = True
            if time.time() - self.stale_logged > 10.0:
                self.stale_logged = time.time()
                self.log.error(
                    f"Gas readings from /tc/gas_monitor/readings stale ({age:.1f} s): halting the "
                    "crawler (confined-space entry procedure)"
                )
            gh = self.crawl_gh
            if gh is not None:
                self.crawl_gh = None
                gh.cancel_goal_async()

    def _set(self, mode: str, k: int) -> None:
        self.mode = mode
        self.mode_pub.publish(String(data=mode))
        self.state_pub.publish(
            String(
                data=json.dumps(
                    {"segment": k, "phase": mode, "job": "2024-1187", "gas_ok": not self.gas_stale}
                )
            )
        )

    def _frame_rate(self, hz: float) -> None:
        if not self.cam_params.wait_for_service(timeout_sec=0.5):
            self.log.warn("ptz_camera/set_parameters not available: frame rate unchanged")
            return
        req = SetParameters.Request(parameters=[Parameter("frame_rate", value=hz).to_parameter_msg()])
        r = wait_future(self.cam_params.call_async(req), 1.0)
        if r is None or not r.results[0].successful:
            self.log.warn(f"Could not set ptz_camera frame_rate to {hz:.0f} Hz")

    def _transition(self, tid: int, label: str) -> bool:
        if not self.change.wait_for_service(timeout_sec=1.0):
            self.log.error(
                f"Failed to change state for node: defect_detector ({label}): service not available"
            )
            return False
        r = wait_future(self.change.call_async(ChangeState.Request(transition=Transition(id=tid))), 2.0)
        if r is None or not r.success:
            self.log.error(f"Failed to change state for node: defect_detector ({label})")
            return False
        return True

    def _detector_state(self) -> str:
        if not self.get.wait_for_service(timeout_sec=1.0):
            return "unknown"
        r = wait_future(self.get.call_async(GetState.Request()), 1.0)
        return r.current_state.label if r else "unknown"

    def _crawl(self, k: int, name: str) -> None:
        if self.gas_stale:
            self.log.error(f"Segment {k} {name}: crawl not started, gas readings stale")
            return
        if not self.crawl.wait_for_server(timeout_sec=1.0):
            self.log.error(f"Segment {k} {name}: crawl_controller/crawl not available")
            return
        gh = wait_future(self.crawl.send_goal_async(Fibonacci.Goal(order=SPEED_MM_S[name])), 1.0)
        if gh is None or not gh.accepted:
            self.log.error(f"Segment {k} {name}: crawl goal not accepted")
            return
        self.crawl_gh = gh

    def _capture(self, k: int) -> None:
        if not self.capture.wait_for_service(timeout_sec=1.0):
            self.log.error(f"Segment {k} survey: ptz_camera/capture not available")
            return
        r = wait_future(self.capture.call_async(BasicTypes.Request(bool_value=True)), 2.0)
        if r is None:
            self.log.error(f"Segment {k} survey: /tc/ptz_camera/capture did not answer within 2.0 s")

    def _sync(self, k: int) -> None:
        if not self.sync.wait_for_service(timeout_sec=1.0):
            self.log.error(f"Segment {k}: reel_controller/sync_length not available")
            return
        r = wait_future(self.sync.call_async(BasicTypes.Request(bool_value=True)), 2.0)
        if r is None:
            self.log.error(
                f"Segment {k}: tether length sync failed: /tc/reel_controller/sync_length did not "
                "answer within 2.0 s; chainage not corrected"
            )
        else:
            self.log.info(f"Segment {k}: tether length synced, {r.float64_value:.2f} m paid out")

    def _at(self, t: float) -> bool:
        wait = t - time.time()
        if wait > 0:
            time.sleep(wait)
        return rclpy.ok()

    def run(self) -> None:
        k, _ = segment_of()
        k = max(k + 1, 0)
        while rclpy.ok():
            t0 = segment_start(k)
            if not self._at(t0):
                return
            self.log.info(f"Segment {k}: transit")
            self._set("transit", k)
            self._frame_rate(FRAME_RATE["transit"])
            self._crawl(k, "transit")
            if not self._at(t0 + 17.0):
                return
            if self._detector_state() == "unconfigured":
                self._transition(Transition.TRANSITION_CONFIGURE, "configure")
            self._transition(Transition.TRANSITION_ACTIVATE, "activate")
            if not self._at(t0 + 18.0):
                return
            self.log.info(f"Segment {k}: inspect")
            self._set("inspect", k)
            self._frame_rate(FRAME_RATE["inspect"])
            self._crawl(k, "inspect")
            if not self._at(t0 + 40.0):
                return
            self.crawl_gh = None
            self.log.info(f"Segment {k}: survey at joint J{k + 1:02d}")
            self._set("survey", k)
            if self._detector_state() == "active":
                self._transition(Transition.TRANSITION_DEACTIVATE, "deactivate")
            if not self._at(t0 + 42.0):
                return
            self._capture(k)
            if not self._at(t0 + 48.0):
                return
            self._set("reel_sync", k)
            self._frame_rate(FRAME_RATE["reel_sync"])
            self._sync(k)
            k += 1

    def diag(self):
        return [
            status(
                ERROR if self.gas_stale else OK,
                "inspection_executive: mission",
                f"{self.mode}{' (halted: gas stale)' if self.gas_stale else ''}",
                "none",
            )
        ]


# ---------------------------------------------------------------------------------------------
# gas_monitor


class GasMonitor(Node):
    """Multi-gas head (H2S, CH4, O2) on Modbus RTU: ``~/readings`` 1 Hz; ``~/alarm`` latched on change
    (A1: H2S >= 5 ppm, CH4 >= 10 %LEL, O2 < 19.5 %)."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("gas_monitor", namespace=NS)
        self.fault = FaultFile(fault_dir, "gas_monitor")
        self.pub = self.create_publisher(String, "~/readings", RELIABLE)
        self.alarm_pub = self.create_publisher(String, "~/alarm", LATCHED)
        self.alarm = "none"
        self.alarm_pub.publish(String(data=json.dumps({"level": "none", "gas": "", "value": ""})))
        self.log = self.get_logger()
        self.log.info("Gas head on /dev/ttyUSB1 (Modbus RTU, slave 3): H2S, CH4, O2 cells warmed up")
        self.last = (0.0, 0.0, 0.0)
        self.create_timer(1.0, self.tick)
        Diagnostics(self, self.diag)

    def _read(self) -> tuple[float, float, float]:
        frame = [int(v * 100) for v in gas_levels()]
        if self.fault.word == "crash":
            frame = frame[:2]  # a truncated Modbus reply (O2 register missing)
        h2s, ch4, o2 = frame  # ValueError on the short frame: the driver ends
        return h2s / 100, ch4 / 100, o2 / 100

    def tick(self) -> None:
        h2s, ch4, o2 = self.last = self._read()
        self.pub.publish(
            String(
                data=json.dumps({"stamp": time.time(), "h2s_ppm": h2s, "ch4_pct_lel": ch4, "o2_pct_vol": o2})
            )
        )
        level = "A1" if h2s >= 5.0 or ch4 >= 10.0 or o2 < 19.5 else "none"
        if level != self.alarm:
            self.alarm = level
            self.alarm_pub.publish(
                String(data=json.dumps({"level": level, "gas": "H2S", "value": f"{h2s:.1f} ppm"}))
            )
            if level == "A1":
                self.log.warn(f"Alarm A1 raised: H2S {h2s:.1f} ppm (threshold 5.0 ppm)")
            else:
                self.log.info(f"Alarm cleared: H2S {h2s:.1f} ppm")

    def diag(self):
        h2s, ch4, o2 = self.last
        return [
            status(
                WARN if self.alarm != "none" else OK,
                "gas_monitor: gas head",
                "Alarm A1" if self.alarm != "none" else "OK",
                "gas-head-MX6-slave3",
                h2s_ppm=h2s,
                ch4_pct_lel=ch4,
                o2_pct_vol=o2,
            )
        ]


# ---------------------------------------------------------------------------------------------
# tether_a / tether_b: the hot-standby pair of surface-link modem bridges


class TetherModem(Node):
    """A VDSL2 modem bridge over one pair of the tether: when ACTIVE it publishes ``/tc/tether/link``
    2 Hz and relays the inspection video (``/tc/surface/image/compressed`` <= 3 Hz, transcoded ~12 KB)
    and the crawler odometry (``/tc/surface/odom`` 5 Hz) within the line's bandwidth. The primary (A)
    is active; the hot standby (B) watches A's link status and takes over when it is silent > 1.2 s,
    publishing nothing until then; A reclaims the link after a scheduled failover test."""

    def __init__(self, fault_dir: Path, name: str, primary: bool) -> None:
        super().__init__(name, namespace=NS)
        self.fault = FaultFile(fault_dir, name)
        self.primary = primary
        self.active = primary
        self.link = self.create_publisher(String, "tether/link", RELIABLE)
        self.img_pub = self.create_publisher(CompressedImage, "surface/image/compressed", SENSOR)
        self.odom_pub = self.create_publisher(Odometry, "surface/odom", RELIABLE)
        self.create_subscription(CompressedImage, "ptz_camera/image/compressed", self.on_image, SENSOR)
        self.create_subscription(Odometry, "odometry/filtered", self.on_odom, RELIABLE)
        self.create_subscription(String, "tether/link", self.on_link, RELIABLE)
        self.imgs: deque = deque(maxlen=12)
        self.sent: dict[int, object] = {}
        self.odoms: deque = deque(maxlen=40)
        self.peer_t = 0.0  # the other modem's last link status
        self.peer_active = False
        self.down = False
        self.down_t = 0.0
        self.dropped = 0
        self.testing = False
        self.reclaim_until = 0.0
        self.conflict_t = 0.0
        self.relayed = 0
        self.line = "A" if primary else "B"
        self.log = self.get_logger()
        self.log.info(
            f"VDSL2 line {self.line} in showtime: 38.2/12.1 Mbit/s, SNR margin 9.1 dB"
            + ("" if primary else "; hot standby")
        )
        self.create_timer(0.5, self.tick_link)
        self.create_timer(1 / 3, self.relay_image)
        self.create_timer(0.2, self.relay_odom)
        Diagnostics(self, self.diag)

    def on_image(self, msg: CompressedImage) -> None:
        self.imgs.append((time.time(), msg))

    def on_odom(self, msg: Odometry) -> None:
        self.odoms.append((time.time(), msg))

    def on_link(self, msg: String) -> None:
        s = json.loads(msg.data)
        if s["modem"] == self.get_name():
            return
        self.peer_t = time.time()
        self.peer_active = s["role"] == "active"
        if (
            self.primary
            and self.active
            and self.peer_active
            and time.time() > self.reclaim_until
            and time.time() - self.conflict_t > 5.0
        ):
            self.conflict_t = time.time()
            self.log.warn(
                f"Link arbitration conflict: {s['modem']} claims ACTIVE while this primary is "
                "active (both relaying to the surface)"
            )
        if not self.primary and self.active and s.get("reclaim"):
            self.active = False
            self.log.info("Primary reclaimed the surface link: back to hot standby")

    def _delay(self) -> float:
        return 0.35 if self.primary and self.fault.word == "lag" else 0.0

    def _pick(self, q: deque):
        """The newest message the line has delivered (received at least the interleaver delay ago),
        each message relayed once: None when there is nothing new."""
        cut = time.time() - self._delay()
        for t, m in reversed(q):
            if t <= cut:
                if m is self.sent.get(id(q)):
                    return None
                self.sent[id(q)] = m
                return m
        return None

    def tick_link(self) -> None:
        now = time.time()
        if self.primary:
            testing = failover_test()
            if testing and not self.testing:
                self.log.info(
                    "Scheduled failover test: releasing the surface link to tether_modem_b for 10 s"
                )
                self.active = False
            elif self.testing and not testing:
                self.active = True
                self.reclaim_until = now + 3.0
                self.log.info("Failover test done: primary reclaims the surface link")
            self.testing = testing
            down = line_dropout()
            if down != self.down and self.active:
                if down:
                    self.down_t, self.dropped = now, 0
                    self.log.warn("VDSL2 line A: loss of margin (SNR 1.2 dB), fast retrain")
                else:
                    self.log.info(
                        f"VDSL2 line A back in showtime after {now - self.down_t:.1f} s "
                        f"({self.dropped} frames dropped)"
                    )
            self.down = down
        else:
            timeout = 0.2 if self.fault.word == "splitbrain" else 1.2
            silent = now - self.peer_t
            if not self.active and self.peer_t > 0 and silent > timeout:
                self.active = True
                self.log.warn(
                    f"Primary link status silent for {silent:.2f} s (> {timeout:.1f} s): taking over "
                    "the surface link on line B"
                )
        if self.active:
            self.link.publish(
                String(
                    data=json.dumps(
                        {
                            "modem": self.get_name(),
                            "line": self.line,
                            "role": "active",
                            "stamp": now,
                            "state": "retrain" if self.down else "showtime",
                            "ds_mbps": 0.0 if self.down else 38.2,
                            "us_mbps": 0.0 if self.down else 12.1,
                            "reclaim": now < self.reclaim_until,
                        }
                    )
                )
            )

    def relay_image(self) -> None:
        if not self.active:
            return
        if self.down:
            self.dropped += 1
            return
        m = self._pick(self.imgs)
        if m is None:
            return
        out = CompressedImage(header=m.header, format="jpeg")
        out.data = m.data[:12000]  # transcoded to 640x360 for the line
        self.img_pub.publish(out)
        self.relayed += 1

    def relay_odom(self) -> None:
        if not self.active or self.down:
            return
        m = self._pick(self.odoms)
        if m is not None:
            self.odom_pub.publish(m)

    def diag(self):
        role = "active" if self.active else "hot standby"
        return [
            status(
                WARN if self.down else OK,
                f"{self.get_name()}: VDSL2 line {self.line}",
                f"{role}, {'retrain' if self.down else 'showtime'}",
                f"vdsl2-modem-{self.line}",
                relayed_frames=self.relayed,
                snr_margin_db=9.1,
            )
        ]


# ---------------------------------------------------------------------------------------------
# reel: the surface tether reel / winch controller (MultiThreadedExecutor, groups)


class ReelController(Node):
    """The surface winch (VFD + drum encoder): pays out tether in step with the crawler's relayed
    odometry (``/tc/surface/odom``), keeping 0.5 m of slack; ``/tc/reel/payout`` JointState 5 Hz
    (position = tether paid out m, effort = tension N); ``~/sync_length`` (BasicTypes) reads the drum
    encoder for the executive."""

    def __init__(self, fault_dir: Path) -> None:
        super().__init__("reel_controller", namespace=NS)
        self.fault = FaultFile(fault_dir, "reel_controller")
        g_ctl, g_srv = MutuallyExclusiveCallbackGroup(), MutuallyExclusiveCallbackGroup()
        self.pub = self.create_publisher(JointState, "reel/payout", RELIABLE)
        self.create_subscription(Odometry, "surface/odom", self.on_odom, RELIABLE, callback_group=g_ctl)
        self.create_service(BasicTypes, "~/sync_length", self.on_sync, callback_group=g_srv)
        self.payout = 3.7  # the manhole's depth + slack
        self.crawler_x = 0.0
        self.crawler_v = 0.0
        self.age = 0.0
        self.odom_t = 0.0
        self.tension = 45.0
        self.warned = 0.0
        self.slow_logged = False
        self.last = time.time()
        self.log = self.get_logger()
        self.log.info("Winch VFD on Modbus TCP 10.0.1.30:502, drum encoder homed: 3.70 m paid out")
        self.create_timer(0.2, self.tick, callback_group=g_ctl)
        Diagnostics(self, self.diag, group=g_ctl)

    def on_odom(self, msg: Odometry) -> None:
        self.odom_t = time.time()
        self.age = self.odom_t - to_s(msg.header.stamp)
        self.crawler_x = msg.pose.pose.position.x
        self.crawler_v = msg.twist.twist.linear.x

    def tick(self) -> None:
        now = time.time()
        dt, self.last = now - self.last, now
        target = 3.2 + self.crawler_x + 0.5
        step = max(-0.4 * dt, min(0.4 * dt, target - self.payout))
        self.payout += step
        lag_m = self.age * abs(self.crawler_v) if now - self.odom_t < 1.0 else 0.0
        self.tension = 45.0 + 300.0 * lag_m + random.gauss(0, 1.0)
        moving = abs(self.crawler_v) > 0.01 and now - self.odom_t < 1.0
        if moving and self.age > 0.3 and now - self.warned > 5.0:
            self.warned = now
            self.log.warn(
                f"Crawler telemetry {self.age:.2f} s old (limit 0.30 s): payout lagging the crawler "
                f"by {lag_m:.2f} m, tether tension {self.tension:.0f} N"
            )
        self.pub.publish(
            JointState(
                header=header("reel_drum"),
                name=["reel_drum"],
                position=[self.payout],
                velocity=[step / dt if dt > 0 else 0.0],
                effort=[self.tension],
            )
        )

    def on_sync(self, req: BasicTypes.Request, resp: BasicTypes.Response) -> BasicTypes.Response:
        if self.fault.word == "slow":
            if not self.slow_logged:
                self.slow_logged = True
                self.log.info(
                    "Drum encoder: absolute re-homing before each length read (encoder_homing: every_request)"
                )
            time.sleep(4.0)
        else:
            time.sleep(random.uniform(0.15, 0.35))  # the encoder's multi-turn read over SSI
        resp.bool_value = True
        resp.float64_value = self.payout
        return resp

    def diag(self):
        return [
            status(
                WARN if self.tension > 70 else OK,
                "reel_controller: winch",
                f"{self.payout:.2f} m paid out",
                "winch-vfd-10.0.1.30",
                tension_n=round(self.tension),
                telemetry_age_s=round(self.age, 3),
            )
        ]


# ---------------------------------------------------------------------------------------------
# recorder, web_ui, diagnostics, operator


RECORDED = (
    ("/tc/laser_profiler/profile", LaserScan, SENSOR),
    ("/tc/laser_profiler/ovality", Vector3Stamped, SENSOR),
    ("/tc/sonar_profiler/profile", LaserScan, SENSOR),
    ("/tc/odometry/filtered", Odometry, SENSOR),
    ("/tc/inclinometer/tilt", Vector3Stamped, SENSOR),
    ("/tc/gas_monitor/readings", String, SENSOR),
    ("/tc/gas_monitor/alarm", String, LATCHED),
    ("/tc/defect_detector/defects", String, SENSOR),
    ("/tc/mission/mode", String, LATCHED),
    ("/tc/inspection_executive/state", String, LATCHED),
    ("/tc/reel/payout", JointState, SENSOR),
    ("/tc/tether/link", String, SENSOR),
    ("/tc/surface/image/compressed", CompressedImage, SENSOR),
    ("/tc/cmd_vel", Twist, SENSOR),
    ("/diagnostics", DiagnosticArray, SENSOR),
    ("/tf", TransformStamped, SENSOR),
)


class Recorder(Node):
    """rosbag2 record-like: 16 topics serialized into 10 s chunks, zlib-compressed and appended to a
    bag file in a temp directory (split at 64 MB)."""

    def __init__(self, where: Path) -> None:
        super().__init__("recorder", namespace=NS)
        self.chunk: list[bytes] = []
        self.dir = Path(tempfile.mkdtemp(prefix="tc_bag_", dir=where))
        self.split = 0
        self.file = open(self.dir / "MH14-MH15_0.mcap", "wb")
        for topic, typ, qos in RECORDED:
            self.create_subscription(typ, topic, lambda b: self.chunk.append(b), qos, raw=True)
        self.get_logger().info(f"Recording {len(RECORDED)} topics to {self.dir} (zlib chunks, 10 s)")
        self.create_timer(10.0, self.flush)

    def flush(self) -> None:
        data, self.chunk = b"".join(self.chunk), []
        self.file.write(zlib.compress(data, 6))
        self.file.flush()
        if self.file.tell() > 64 << 20:
            self.file.close()
            os.unlink(self.file.name)
            self.split += 1
            self.file = open(self.dir / f"MH14-MH15_{self.split}.mcap", "wb")
            self.get_logger().info(f"Bag split: MH14-MH15_{self.split}.mcap")


UI_TOPICS = (
    ("/tc/surface/image/compressed", CompressedImage, SENSOR),
    ("/tc/surface/odom", Odometry, SENSOR),
    ("/diagnostics_agg", DiagnosticArray, RELIABLE),
    ("/tc/inspection_executive/state", String, LATCHED),
    ("/tc/gas_monitor/readings", String, RELIABLE),
    ("/tc/gas_monitor/alarm", String, LATCHED),
    ("/tc/defect_detector/defects", String, RELIABLE),
    ("/tc/reel/payout", JointState, SENSOR),
    ("/tc/tether/link", String, RELIABLE),
)
TABLET_TOPICS = (
    ("/tc/surface/image/compressed", CompressedImage, SENSOR),
    ("/tc/inspection_executive/state", String, LATCHED),
)


class WebUiBridge(Node):
    """rosbridge-like websocket server in the surface van: the operator's browser subscribed for good
    (9 topics), the site supervisor's tablet 30-70 s of every 120 s (2 topics), the operator's
    joystick -> ``/tc/cmd_vel/joy`` 10 Hz while nudging."""

    def __init__(self) -> None:
        super().__init__("web_ui_bridge", namespace=NS)
        self.joy = self.create_publisher(Twist, "cmd_vel/joy", COMMAND)
        self.log = self.get_logger()
        self.log.info("Rosbridge WebSocket server started on port 9090")
        self.log.info("Client 10.0.1.51 (operator console, Chrome) connected")
        self.subs = [self.create_subscription(t, n, lambda _b: None, q, raw=True) for n, t, q in UI_TOPICS]
        self.tablet = []
        self.nudging = False
        self.create_timer(1.0, self.tick)
        self.create_timer(0.1, self.tick_joy)

    def tick(self) -> None:
        e = elapsed() % 120.0
        want = 30.0 <= e < 70.0
        if want and not self.tablet:
            self.log.info("Client 10.0.1.77 (site supervisor, tablet) connected")
            self.tablet = [
                self.create_subscription(t, n, lambda _b: None, q, raw=True) for n, t, q in TABLET_TOPICS
            ]
        elif not want and self.tablet:
            for s in self.tablet:
                self.destroy_subscription(s)
            self.tablet = []
            self.log.info("Client 10.0.1.77 disconnected")

    def tick_joy(self) -> None:
        on = nudge()
        if on and not self.nudging:
            self.log.info("Operator joystick engaged: nudging forward 30 mm/s to centre the joint")
        self.nudging = on
        if on:
            tw = Twist()
            tw.linear.x = 0.03
            self.joy.publish(tw)


GROUPS = (
    ("track_driver", "Drive"),
    ("power_monitor", "Drive"),
    ("laser_profiler", "Sensors"),
    ("sonar_profiler", "Sensors"),
    ("inclinometer", "Sensors"),
    ("ptz_camera", "Sensors"),
    ("gas_monitor", "Safety"),
    ("crawler_localization", "Localization"),
    ("tether_modem", "Tether"),
    ("reel_controller", "Surface"),
    ("inspection_executive", "Mission"),
)


class DiagnosticAggregator(Node):
    """diagnostic_aggregator: ``/diagnostics`` -> ``/diagnostics_agg`` 1 Hz, STALE after 5 s."""

    def __init__(self) -> None:
        super().__init__("diagnostic_aggregator")
        self.last: dict[str, tuple[float, DiagnosticStatus]] = {}
        self.create_subscription(DiagnosticArray, "/diagnostics", self.on_diag, RELIABLE)
        self.pub = self.create_publisher(DiagnosticArray, "/diagnostics_agg", RELIABLE)
        self.create_timer(1.0, self.tick)

    def on_diag(self, msg: DiagnosticArray) -> None:
        now = time.time()
        for s in msg.status:
            self.last[s.name] = (now, s)

    def tick(self) -> None:
        now = time.time()
        out = []
        for name, (t, s) in sorted(self.last.items()):
            group = next((g for key, g in GROUPS if key in name), "Other")
            out.append(
                DiagnosticStatus(
                    level=STALE if now - t > 5 else s.level,
                    name=f"/Crawler/{group}/{name}",
                    message=s.message,
                    hardware_id=s.hardware_id,
                    values=s.values,
                )
            )
        self.pub.publish(DiagnosticArray(header=header(""), status=out))


class OperatorConsole(Node):
    """The inspection engineer's ``ros2 topic echo`` of the mission state, the gas and the defects."""

    def __init__(self) -> None:
        super().__init__("operator_console", namespace=NS)
        self.create_subscription(
            String, "inspection_executive/state", lambda m: print(m.data, flush=True), LATCHED
        )
        self.create_subscription(
            String, "gas_monitor/readings", lambda m: print(m.data, flush=True), RELIABLE
        )
        self.create_subscription(
            String, "defect_detector/defects", lambda m: print("DEFECT", m.data, flush=True), RELIABLE
        )


# ---------------------------------------------------------------------------------------------


def build(process: str, fault_dir: Path):
    """The process's executor, its nodes added."""
    if process == "crawler_base":
        b = Base()
        return single_threaded(TrackDriver(b), ImuDriver(fault_dir, b), CmdVelMux(), PowerMonitor(b))
    if process == "sensor_container":
        return single_threaded(LaserProfiler(fault_dir), SonarProfiler(fault_dir), Inclinometer())
    if process == "camera":
        return single_threaded(PtzCamera(fault_dir))
    if process == "perception":
        return single_threaded(DefectDetector())
    if process == "localization":
        return single_threaded(CrawlerLocalization(fault_dir))
    if process == "mission":
        ex = MultiThreadedExecutor(num_threads=3)
        for n in (InspectionExecutive(), CrawlController()):
            ex.add_node(n)
        return ex
    if process == "gas":
        return single_threaded(GasMonitor(fault_dir))
    if process == "tether_a":
        return single_threaded(TetherModem(fault_dir, "tether_modem_a", True))
    if process == "tether_b":
        return single_threaded(TetherModem(fault_dir, "tether_modem_b", False))
    if process == "reel":
        ex = MultiThreadedExecutor(num_threads=2)
        ex.add_node(ReelController(fault_dir))
        return ex
    if process == "recorder":
        return single_threaded(Recorder(fault_dir.parent))
    if process == "web_ui":
        return single_threaded(WebUiBridge())
    if process == "diagnostics":
        return single_threaded(DiagnosticAggregator())
    if process == "operator":
        return single_threaded(OperatorConsole())
    raise SystemExit(f"unknown process {process!r}")


def main(argv: list[str]) -> None:
    process, fault_dir = argv[0], Path(argv[1])
    run_for = float(argv[2]) if len(argv) > 2 else 0.0
    rclpy.init()
    ex = build(process, fault_dir)
    hooks = {}
    if process == "perception":
        hooks["cpu"] = lambda: (
            ex.get_nodes()[0]
            .get_logger()
            .warn(
                "Model reloaded by the config sync: crackseg-v4 at full resolution (1920x1080, fp32, NPU "
                "delegate off): inference on the CPU"
            )
        )
    spin(ex, fault_dir, process, run_for, hooks)


if __name__ == "__main__":
    main(sys.argv[1:])
