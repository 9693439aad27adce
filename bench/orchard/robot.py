"""The apple-harvesting orchard robot's processes (`bench.orchard.run` documents the robot).

``python -m bench.orchard.robot PROCESS FAULT_DIR [RUN_FOR]`` runs one process until Ctrl-C (or
``RUN_FOR`` s); ``python -m bench.orchard.robot lifecycle_set FAULT_DIR 0 NODE TRANSITION`` is a
crew member's ``ros2 lifecycle set NODE TRANSITION``.

The orchard is one schedule every process reads from the wall clock: the robot's day starts at
``ORCHARD_T0`` (set by the runner when it starts the robot; a process started by hand uses its own
start), bring-up takes ``BRINGUP_S``, then every ``CYCLE_S`` one row: four bays (drive 5 s, stop 11 s
to pick), the row end, the headland turn. Fruit per bay, canopy shading of the GNSS antenna and the
farm Wi-Fi's outages are seeded from the row, the bay or the wall-clock minute, so every process
that needs them agrees without talking.
"""

from __future__ import annotations

import array
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
from nav_msgs.msg import OccupancyGrid, Odometry
from nav_msgs.msg import Path as PathMsg
from nav_msgs.srv import GetPlan
from rcl_interfaces.msg import Parameter as ParameterMsg
from rcl_interfaces.msg import ParameterType, ParameterValue, SetParametersResult
from rcl_interfaces.srv import SetParameters
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import (
    BatteryState,
    CameraInfo,
    CompressedImage,
    FluidPressure,
    Imu,
    JointState,
    LaserScan,
    NavSatFix,
    NavSatStatus,
)
from std_msgs.msg import Float32, String, UInt8MultiArray
from std_srvs.srv import SetBool
from test_msgs.action import Fibonacci

from bench.robot_process import (
    PYTHON_EXIT,
    header,
    on_shutdown_quiet,
    single_threaded,
    spin,
    status,
    to_s,
    wait_future,
)

OK, WARN, STALE = DiagnosticStatus.OK, DiagnosticStatus.WARN, DiagnosticStatus.STALE
NS = "/orchard"

# QoS as the team's launch files set them.
SENSOR = QoSProfile(depth=5, reliability=ReliabilityPolicy.BEST_EFFORT)
RELIABLE = QoSProfile(depth=10)
COMMAND = QoSProfile(depth=1)
LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
TF_STATIC = QoSProfile(depth=100, durability=DurabilityPolicy.TRANSIENT_LOCAL)

# ---------------------------------------------------------------------------------------------
# The orchard: one schedule through the wall clock.

T0 = float(os.environ.get("ORCHARD_T0", time.time()))
BRINGUP_S = 10.0
CYCLE_S = 90.0
BAYS = 4
DRIVE_S, DWELL_S = 5.0, 11.0
BAY_S = DRIVE_S + DWELL_S
ROW_START_S = 2.0  # the row follower's goal, after the row entry
ROW_END_S = ROW_START_S + BAYS * BAY_S  # 66
TURN_START_S, TURN_S = 68.0, 18.0
ACTIVATE_S = 88.0  # the canopy lidar back on before the next row
BAY_SPACING_M = 2.5
ROW_SPACING_M = 4.0
PICK_CYCLE_S = 2.6  # one apple per arm every 2.6 s


def rnd(*key) -> random.Random:
    """A generator seeded by ``key``: the same in every process."""
    return random.Random("/".join(str(k) for k in key))


def where(t: float | None = None) -> tuple[str, int, int, float]:
    """(segment, row, bay, s into the segment) at ``t``: segment bringup, entering, driving, picking,
    row_end, turn, aligning."""
    t = time.time() if t is None else t
    s = t - T0 - BRINGUP_S
    if s < 0:
        return "bringup", -1, -1, t - T0
    row, ph = int(s // CYCLE_S), s % CYCLE_S
    if ph < ROW_START_S:
        return "entering", row, -1, ph
    if ph < ROW_END_S:
        bay, b = int((ph - ROW_START_S) // BAY_S), (ph - ROW_START_S) % BAY_S
        return ("driving", row, bay, b) if b < DRIVE_S else ("picking", row, bay, b - DRIVE_S)
    if ph < TURN_START_S:
        return "row_end", row, -1, ph - ROW_END_S
    if ph < TURN_START_S + TURN_S:
        return "turn", row, -1, ph - TURN_START_S
    return "aligning", row, -1, ph - TURN_START_S - TURN_S


def row_start_time(row: int) -> float:
    return T0 + BRINGUP_S + row * CYCLE_S


def fruit(row: int, bay: int, side: str) -> int:
    """Apples within reach of one arm at a bay when the robot stops."""
    r = rnd("fruit", row, bay, side)
    return 0 if r.random() < 0.15 else r.randint(2, 6)


def visible(row: int, bay: int, side: str, into: float) -> int:
    """Apples one side's camera sees ``into`` s after the stop: the arm takes one every cycle."""
    return max(0, fruit(row, bay, side) - int(max(0.0, into - 1.0) // PICK_CYCLE_S))


def needs_creep(row: int, bay: int) -> bool:
    return rnd("creep", row, bay).random() < 0.3


def shaded(row: int, bay: int) -> bool:
    """Dense canopy over the antenna at this bay (multipath, RTK float)."""
    return rnd("canopy", row, bay).random() < 0.35


def link_up(t: float | None = None) -> bool:
    """The farm Wi-Fi (mesh AP at the row ends): down 4-10 s in 55 % of the wall-clock minutes."""
    t = time.time() if t is None else t
    r = rnd("wifi", int(t // 60))
    if r.random() < 0.55:
        start, dur = r.uniform(5, 45), r.uniform(4, 10)
        return not (start <= t % 60 < start + dur)
    return True


def pose_at(t: float | None = None) -> tuple[float, float, float]:
    """(x, y, yaw) of base_link in the orchard's map frame (rows along x, every other row back)."""
    seg, row, bay, into = where(t)
    if row < 0:
        return 0.0, 0.0, 0.0
    y0 = row * ROW_SPACING_M
    fwd = row % 2 == 0
    if seg in ("entering",):
        d = 0.0
    elif seg == "driving":
        d = bay * BAY_SPACING_M + BAY_SPACING_M * into / DRIVE_S
    elif seg == "picking":
        d = (bay + 1) * BAY_SPACING_M
    else:
        d = BAYS * BAY_SPACING_M
    if seg in ("turn", "aligning"):
        a = math.pi * min(1.0, into / TURN_S) if seg == "turn" else math.pi
        cx, r = (BAYS * BAY_SPACING_M + 2.0) if fwd else -2.0, ROW_SPACING_M / 2
        x = cx + (r * math.sin(a) if fwd else -r * math.sin(a))
        y = y0 + r - r * math.cos(a)
        return x, y, (0.0 if fwd else math.pi) + a
    x = d if fwd else BAYS * BAY_SPACING_M - d
    return x, y0, 0.0 if fwd else math.pi


def quat(yaw: float) -> Quaternion:
    return Quaternion(z=math.sin(yaw / 2), w=math.cos(yaw / 2))


# ---------------------------------------------------------------------------------------------
# What every process shares.


class Faults:
    """The fault files of a process's nodes (``FAULT_DIR/orchard.<node>``), polled every 0.5 s."""

    def __init__(self, fault_dir: Path) -> None:
        self.dir = fault_dir
        self.now: dict[str, str] = {}
        threading.Thread(target=self._poll, daemon=True).start()
        self._read()

    def _read(self) -> None:
        try:
            for f in self.dir.glob("orchard.*"):
                self.now[f.name.removeprefix("orchard.")] = f.read_text().strip()
        except OSError:
            pass

    def _poll(self) -> None:
        while True:
            time.sleep(0.5)
            self._read()

    def get(self, node: str) -> str | None:
        return self.now.get(node)


class Diag:
    """A node's diagnostic_updater: its tasks' statuses on /diagnostics every ``period`` s."""

    def __init__(self, node: Node, fill, period: float = 1.0, group=None) -> None:
        self.node, self.fill = node, fill
        self.pub = node.create_publisher(DiagnosticArray, "/diagnostics", RELIABLE)
        node.create_timer(period, self._publish, callback_group=group)

    def _publish(self) -> None:
        self.pub.publish(DiagnosticArray(header=header(""), status=list(self.fill())))


def every(lo: float, hi: float):
    """A recurring event every lo..hi s: call ``due()`` -> True when it fires."""
    nxt = [time.time() + random.uniform(lo, hi)]

    def due() -> bool:
        if time.time() >= nxt[0]:
            nxt[0] = time.time() + random.uniform(lo, hi)
            return True
        return False

    return due


def hang_forever() -> None:
    """A blocking call that never returns (a read without a timeout, a lock never released)."""
    threading.Event().wait()


# ---------------------------------------------------------------------------------------------
# base_driver: the tracked base's CAN bridge (tracks, vacuum pump) and the IMU.


class TrackController(Node):
    """Differential drive of the two rubber tracks (Roboteq SBL2360 on can0), battery from the BMS."""

    def __init__(self) -> None:
        super().__init__("track_controller", namespace=NS)
        self.cmd, self.cmd_t = Twist(), 0.0
        self.x = self.y = self.yaw = 0.0
        self.v = self.w = 0.0
        self.last = time.time()
        self.soc = 0.86 - ((time.time() - T0) / 3600.0) * 0.08
        self.timed_out = True
        self.create_subscription(Twist, "cmd_vel", self.on_cmd, RELIABLE)
        self.odom = self.create_publisher(Odometry, "odometry/wheel", RELIABLE)
        self.batt = self.create_publisher(BatteryState, "battery", RELIABLE)
        self.create_timer(1 / 20, self.update)
        self.create_timer(1.0, self.battery)
        self.hot = every(100, 220)
        self.temp = 48.0
        Diag(self, self.diag)
        self.get_logger().info(
            "CAN interface can0 up at 500 kbit/s; Roboteq SBL2360 node 1 (fw 2.1a) left/right channels ready"
        )
        self.get_logger().info("Track gauge 1.45 m, sprocket radius 0.19 m, cmd_vel timeout 0.50 s")

    def on_cmd(self, msg: Twist) -> None:
        self.cmd, self.cmd_t = msg, time.time()

    def update(self) -> None:
        now = time.time()
        dt, self.last = now - self.last, now
        if now - self.cmd_t > 0.5:
            self.v = self.w = 0.0
            self.timed_out = True
        else:
            self.v, self.w = self.cmd.linear.x, self.cmd.angular.z
            self.timed_out = False
        self.yaw += self.w * dt
        self.x += self.v * math.cos(self.yaw) * dt
        self.y += self.v * math.sin(self.yaw) * dt
        m = Odometry(header=header("odom", now - 0.004), child_frame_id="base_link")
        m.pose.pose.position.x, m.pose.pose.position.y = self.x, self.y
        m.pose.pose.orientation = quat(self.yaw)
        m.twist.twist.linear.x, m.twist.twist.angular.z = self.v, self.w
        m.twist.covariance[0] = m.twist.covariance[35] = 0.01
        self.odom.publish(m)

    def battery(self) -> None:
        self.soc = max(0.2, self.soc - 0.08 / 3600)
        self.temp = 48.0 + 4 * math.sin(time.time() / 300)
        if self.hot():
            self.get_logger().warning(
                f"Left track motor channel temperature {71 + random.random() * 3:.1f} C "
                "(warning above 70 C); derating to 80 %"
            )
        self.batt.publish(
            BatteryState(
                header=header("base_link"),
                voltage=51.2 + 3 * self.soc,
                current=-18.0 - 6 * abs(self.v),
                percentage=self.soc,
                power_supply_status=BatteryState.POWER_SUPPLY_STATUS_DISCHARGING,
                power_supply_technology=BatteryState.POWER_SUPPLY_TECHNOLOGY_LIFE,
                present=True,
            )
        )

    def diag(self):
        yield status(
            OK,
            "track_controller: Motor drivers",
            "Timeout, stopped" if self.timed_out else "Running",
            "roboteq-sbl2360-can0-1",
            left_temp_c=f"{self.temp:.1f}",
            right_temp_c=f"{self.temp - 1.2:.1f}",
            cmd_timeout_s=0.5,
        )
        yield status(
            OK if self.soc > 0.25 else WARN,
            "track_controller: Battery",
            f"{self.soc * 100:.0f} %",
            "orion-bms2-can0-10",
            soc=f"{self.soc:.3f}",
        )


class VacuumPump(Node):
    """The shared vacuum blower feeding both picking tubes (on can0), switched per bay."""

    def __init__(self) -> None:
        super().__init__("vacuum_pump", namespace=NS)
        self.on = False
        self.p = 101.3
        self.pub = self.create_publisher(FluidPressure, "~/pressure", RELIABLE)
        self.create_service(SetBool, "~/enable", self.enable)
        self.create_timer(0.2, self.tick)
        Diag(self, self.diag)
        self.get_logger().info("Becker blower VFD on can0 node 5; manifold sensor 0-110 kPa")

    def enable(self, req, res):
        if req.data != self.on:
            self.on = req.data
            self.get_logger().info("Blower on (setpoint 76 kPa abs)" if self.on else "Blower off")
        res.success, res.message = True, "on" if self.on else "off"
        return res

    def tick(self) -> None:
        goal = 76.0 if self.on else 101.3
        self.p += (goal - self.p) * 0.25 + random.gauss(0, 0.15)
        self.pub.publish(
            FluidPressure(header=header("vacuum_manifold"), fluid_pressure=self.p * 1000, variance=0.04)
        )

    def diag(self):
        yield status(
            OK,
            "vacuum_pump: Blower",
            "Running" if self.on else "Idle",
            "becker-vtlf250-can0-5",
            manifold_kpa=f"{self.p:.1f}",
        )


class ImuDriver(Node):
    """Xsens MTi-630 on /dev/ttyUSB0, 50 Hz."""

    def __init__(self, faults: Faults) -> None:
        super().__init__("imu_driver", namespace=NS)
        self.faults = faults
        self.pub = self.create_publisher(Imu, "imu/data", SENSOR)
        self.rate = 50.0
        self.timer = self.create_timer(1 / self.rate, self.tick)
        self.n = 0
        Diag(self, self.diag)
        self.get_logger().info("Opened /dev/ttyUSB0 at 921600 baud: MTi-630 (SN 03882114, fw 1.12.0)")
        self.get_logger().info("Output configuration: EulerAngles, Acceleration, RateOfTurn at 50 Hz")

    def tick(self) -> None:
        if self.rate == 50.0 and self.faults.get("imu_driver") == "rate":
            self.get_logger().warning(
                "Device reset detected (wake-up message); baudrate 921600 not "
                "acknowledged, reconnected at 115200: output limited to 33 Hz"
            )
            self.timer.cancel()
            self.rate = 33.0
            self.timer = self.create_timer(1 / self.rate, self.tick)
        t = time.time()
        _, _, yaw = pose_at(t)
        m = Imu(header=header("imu_link", t - 0.003))
        m.orientation = quat(yaw + random.gauss(0, 0.002))
        m.angular_velocity.z = random.gauss(0, 0.01)
        m.linear_acceleration.x = random.gauss(0, 0.05)
        m.linear_acceleration.z = 9.81 + random.gauss(0, 0.05)
        m.orientation_covariance[0] = m.orientation_covariance[4] = m.orientation_covariance[8] = 0.0004
        self.pub.publish(m)
        self.n += 1

    def diag(self):
        yield status(
            OK, "imu_driver: IMU", "Streaming", "xsens-mti630-03882114", rate_hz=self.rate, packets=self.n
        )


def base_driver(faults: Faults):
    return single_threaded(TrackController(), VacuumPump(), ImuDriver(faults)), {}


# ---------------------------------------------------------------------------------------------
# gnss: u-blox ZED-F9P driver and its NTRIP client (corrections over the farm Wi-Fi).

LAT0, LON0 = 47.42351, -120.31024  # the block's datum, Wenatchee valley


class GnssDriver(Node):
    def __init__(self) -> None:
        super().__init__("gnss_driver", namespace=NS)
        self.fix = self.create_publisher(NavSatFix, "fix", RELIABLE)
        self.rtk = self.create_publisher(String, "~/rtk_status", LATCHED)
        self.create_subscription(UInt8MultiArray, "ntrip_client/rtcm", self.on_rtcm, RELIABLE)
        self.last_rtcm = 0.0  # none yet
        self.started = time.time()
        self.state = ""
        self.create_timer(0.1, self.tick)
        Diag(self, self.diag)
        self.get_logger().info(
            "u-blox ZED-F9P HPG 1.32 on /dev/ttyACM0; UBX-NAV-PVT 10 Hz, dynamic model AGRICULTURAL"
        )

    def on_rtcm(self, msg) -> None:
        self.last_rtcm = time.time()

    def tick(self) -> None:
        t = time.time()
        seg, row, bay, _ = where(t)
        waiting = self.last_rtcm == 0.0
        age = t - (self.last_rtcm or self.started)
        under = seg in ("driving", "picking") and shaded(row, bay)
        if waiting:
            state = "3D_FIX"
        else:
            state = "3D_FIX" if age > 60 else ("RTK_FLOAT" if under or age > 5 else "RTK_FIXED")
        if state != self.state:
            sv = random.randint(12, 16) if under else random.randint(19, 26)
            if state == "RTK_FIXED":
                self.get_logger().info(
                    f"RTK fixed (carrier solution fixed, {sv} SV, correction age {age:.1f} s)"
                )
            elif state == "RTK_FLOAT":
                why = "canopy multipath" if under else f"correction age {age:.0f} s"
                self.get_logger().warning(f"RTK float: carrier solution lost ({why}, {sv} SV)")
            elif waiting:
                self.get_logger().info(f"3D fix ({sv} SV); waiting for RTCM corrections")
            else:
                self.get_logger().warning(f"No RTCM corrections for {age:.0f} s: 3D fix only")
            self.state = state
            self.rtk.publish(String(data=state))
        x, y, _ = pose_at(t)
        sd = {"RTK_FIXED": 0.015, "RTK_FLOAT": 0.25, "3D_FIX": 1.2}[state]
        m = NavSatFix(header=header("gnss_antenna", t - 0.06))
        m.status = NavSatStatus(
            status=NavSatStatus.STATUS_GBAS_FIX if state != "3D_FIX" else NavSatStatus.STATUS_FIX,
            service=NavSatStatus.SERVICE_GPS | NavSatStatus.SERVICE_GALILEO,
        )
        m.latitude = LAT0 + (y + random.gauss(0, sd)) / 111_132.0
        m.longitude = LON0 + (x + random.gauss(0, sd)) / (111_320.0 * math.cos(math.radians(LAT0)))
        m.altitude = 238.4 + random.gauss(0, sd * 2)
        m.position_covariance[0] = m.position_covariance[4] = sd * sd
        m.position_covariance[8] = 4 * sd * sd
        m.position_covariance_type = NavSatFix.COVARIANCE_TYPE_DIAGONAL_KNOWN
        self.fix.publish(m)

    def diag(self):
        lvl = OK if self.state == "RTK_FIXED" else WARN
        yield status(
            lvl,
            "gnss_driver: fix",
            self.state or "no fix",
            "ublox-zedf9p-ttyACM0",
            correction_age_s=f"{time.time() - (self.last_rtcm or self.started):.1f}",
        )


class NtripClient(Node):
    CASTER = "ntrip.wenatchee-farm.local:2101/ORCH_BASE"

    def __init__(self, faults: Faults) -> None:
        super().__init__("ntrip_client", namespace=NS)
        self.faults = faults
        self.pub = self.create_publisher(UInt8MultiArray, "~/rtcm", RELIABLE)
        self.connected = False
        self.started = time.time()
        self.connect_at = self.started + random.uniform(1.5, 2.5)
        self.frames = [array.array("B", os.urandom(random.randint(420, 620))) for _ in range(8)]
        self.create_timer(1.0, self.tick)
        Diag(self, self.diag)
        self.get_logger().info(f"Connecting to NTRIP caster {self.CASTER} over wlan0")

    def tick(self) -> None:
        t = time.time()
        if not self.connected:
            if t < self.connect_at or not link_up(t):
                return
            if self.faults.get("ntrip_client") == "crashloop":
                # the caster's new credentials: the response parser has no branch for it
                status_line = "HTTP/1.1 401 Unauthorized"
                code = {"ICY 200 OK": 200, "HTTP/1.1 200 OK": 200}[status_line]
                self.get_logger().info(f"Caster replied {code}")
            self.connected = True
            self.get_logger().info("Connected: ICY 200 OK; streaming RTCM3 1005 1077 1087 1097 1127 1230")
        if not link_up(t):
            self.connected = False
            self.connect_at = t
            self.get_logger().warning(
                f"Lost connection to {self.CASTER}: [Errno 113] No route to host; reconnecting every 2 s"
            )
            return
        msg = UInt8MultiArray()
        msg.data = self.frames[int(t) % len(self.frames)]
        self.pub.publish(msg)

    def diag(self):
        yield status(
            OK if self.connected else WARN,
            "ntrip_client: NTRIP",
            "Streaming corrections" if self.connected else "Disconnected",
            "ntrip://" + self.CASTER,
        )


def gnss(faults: Faults):
    os.environ[PYTHON_EXIT] = "1"  # the Python NTRIP client and driver wrapper: Python's exit
    return single_threaded(GnssDriver(), NtripClient(faults)), {}


# ---------------------------------------------------------------------------------------------
# canopy_lidar: a lifecycle-managed SICK TiM781 looking at the canopy walls (row centering).


class CanopyLidar(LifecycleNode):
    BEAMS = 811

    def __init__(self) -> None:
        super().__init__("canopy_lidar", namespace=NS)
        self.pub = None
        self.timer = None
        self.active = False
        self.n = 0
        self.scans = []
        Diag(self, self.diag)
        self.get_logger().info("Lifecycle node canopy_lidar created (unconfigured)")

    def on_configure(self, state) -> TransitionCallbackReturn:
        self.get_logger().info(
            "Connected to SICK TiM781 at 192.168.1.11:2112 (fw V2.10): 270 deg, 0.333 deg, 15 Hz"
        )
        self.pub = self.create_lifecycle_publisher(LaserScan, "~/scan", SENSOR)
        for k in range(6):
            a = [
                2.2 / max(0.2, abs(math.sin(-2.356 + i * 0.005818))) + 0.1 * math.sin(i * 0.3 + k)
                for i in range(self.BEAMS)
            ]
            self.scans.append(
                (
                    array.array("f", [min(25.0, v) for v in a]),
                    array.array("f", [800.0 + 50 * math.sin(i * 0.1 + k) for i in range(self.BEAMS)]),
                )
            )
        self.timer = self.create_timer(1 / 15, self.tick)
        return super().on_configure(state)

    def on_activate(self, state) -> TransitionCallbackReturn:
        self.active = True
        self.get_logger().info("Laser emission on; publishing /orchard/canopy_lidar/scan")
        return super().on_activate(state)

    def on_deactivate(self, state) -> TransitionCallbackReturn:
        self.active = False
        self.get_logger().info("Laser emission off (standby)")
        return super().on_deactivate(state)

    def on_cleanup(self, state) -> TransitionCallbackReturn:
        if self.timer:
            self.destroy_timer(self.timer)
            self.timer = None
        return super().on_cleanup(state)

    def tick(self) -> None:
        if not self.active:
            return
        t = time.time()
        r, i = self.scans[self.n % len(self.scans)]
        self.n += 1
        m = LaserScan(
            header=header("canopy_lidar", t - 1 / 15),
            angle_min=-2.356,
            angle_max=2.356,
            angle_increment=0.005818,
            time_increment=1 / 15 / 1080,
            scan_time=1 / 15,
            range_min=0.05,
            range_max=25.0,
        )
        m.ranges, m.intensities = r, i
        self.pub.publish(m)

    def diag(self):
        yield status(
            OK,
            "canopy_lidar: Scan",
            "Transmitting" if self.active else "Standby",
            "sick-tim781-192.168.1.11",
            scans=self.n,
        )


def canopy_lidar(faults: Faults):
    return single_threaded(CanopyLidar()), {}


# ---------------------------------------------------------------------------------------------
# stereo_container: both ZED X stereo cameras (GMSL2 on the Orin), one component container,
# ONE SingleThreadedExecutor.


class StereoCamera(Node):
    def __init__(self, side: str, serial: str, faults: Faults) -> None:
        super().__init__(f"{side}_camera", namespace=NS)
        self.side, self.serial, self.faults = side, serial, faults
        self.frame = f"{side}_camera_optical_frame"
        self.img = self.create_publisher(CompressedImage, "~/image_rect_color/compressed", SENSOR)
        self.info = self.create_publisher(CameraInfo, "~/camera_info", SENSOR)
        self.jpegs = [array.array("B", os.urandom(random.randint(13_000, 17_000))) for _ in range(4)]
        self.n = 0
        self.lag0 = None
        self.glare = every(120, 260)
        self.create_timer(1 / 8, self.grab)
        Diag(self, self.diag)
        self.get_logger().info(
            f"ZED X SN {serial} opened on GMSL2 port {0 if side == 'left' else 1}: "
            "HD1200 @ 15 fps, publishing rectified color 960x600 at 8 Hz (grab_frame_rate)"
        )

    def grab(self) -> None:
        t = time.time()
        fault = self.faults.get(self.name_)
        if fault == "hang":
            self.get_logger().warning(
                f"Frame grab timed out after 200 ms (GMSL2 link {self.port}: 37 CRC "
                "errors); re-arming capture"
            )
            hang_forever()  # sl::Camera::grab() waits for a frame that never comes
        if fault == "lag" and self.lag0 is None:
            self.lag0 = t
        # capture is exposure-centered; host stamping through the PTP-synced clock
        st = t - 0.035 - (0.1 * (t - self.lag0) if self.lag0 else 0.0)
        if self.glare():
            self.get_logger().warning(
                "Auto exposure: sun in field of view, 18 % saturated pixels; exposure clamped to 2.0 ms"
            )
        h = header(self.frame, st)
        self.img.publish(
            CompressedImage(header=h, format="bgr8; jpeg compressed bgr8", data=self.jpegs[self.n % 4])
        )
        ci = CameraInfo(header=h, height=600, width=960, distortion_model="plumb_bob")
        ci.k = [533.7, 0.0, 479.1, 0.0, 533.6, 300.9, 0.0, 0.0, 1.0]
        ci.p = [
            533.7,
            0.0,
            479.1,
            -64.1 if self.side == "right" else 0.0,
            0.0,
            533.6,
            300.9,
            0.0,
            0.0,
            0.0,
            1.0,
            0.0,
        ]
        self.info.publish(ci)
        self.n += 1

    @property
    def name_(self) -> str:
        return f"{self.side}_camera"

    @property
    def port(self) -> int:
        return 0 if self.side == "left" else 1

    def diag(self):
        yield status(
            OK, f"{self.name_}: Capture", "Streaming", f"zedx-{self.serial}", frames=self.n, rate_hz=8.0
        )


def stereo_container(faults: Faults):
    return single_threaded(
        StereoCamera("left", "41238817", faults), StereoCamera("right", "41239052", faults)
    ), {}


# ---------------------------------------------------------------------------------------------
# perception: component_container_mt (Python): MultiThreadedExecutor, 3 threads, one
# MutuallyExclusive group per node.


class FruitDetector(Node):
    """YOLOv8 apple detector (TensorRT on the Orin GPU), enabled per bay by the harvest coordinator."""

    def __init__(self) -> None:
        super().__init__("fruit_detector", namespace=NS)
        g = MutuallyExclusiveCallbackGroup()
        self.enabled = False
        self.enabled_at = 0.0
        self.last_img = {"left": 0.0, "right": 0.0}
        self.lat_ms = 0.0
        self.frames = 0
        self.pub = self.create_publisher(PoseArray, "~/detections", RELIABLE)
        self.group = g
        self.subs: list = []  # the cameras, subscribed only while enabled (saves the GMSL/DDS copies)
        self.create_service(SetBool, "~/enable", self.enable, callback_group=g)
        self.create_timer(1.0, self.watch, callback_group=g)
        Diag(self, self.diag, group=g)
        self.get_logger().info(
            "Loaded TensorRT engine /opt/orchard/models/yolov8s-apple-v3.engine "
            "(FP16, 640x640, conf 0.45, iou 0.50)"
        )

    def enable(self, req, res):
        if req.data and not self.subs:
            self.last_img = {"left": time.time(), "right": time.time()}
            self.subs = [
                self.create_subscription(
                    CompressedImage,
                    f"{side}_camera/image_rect_color/compressed",
                    lambda m, s=side: self.on_image(s, m),
                    SENSOR,
                    callback_group=self.group,
                )
                for side in ("left", "right")
            ]
        elif not req.data and self.subs:
            for sub in self.subs:
                self.destroy_subscription(sub)
            self.subs = []
        self.enabled = req.data
        self.enabled_at = time.time()
        res.success = True
        return res

    def on_image(self, side: str, msg: CompressedImage) -> None:
        t = time.time()
        self.last_img[side] = t
        if not self.enabled:
            return
        s = 0
        for k in range(0, len(msg.data), 4096):  # decode + letterbox stand-in
            s += msg.data[k]
        self.frames += 1
        seg, row, bay, into = where(t)  # what is in front of the camera now
        n = visible(row, bay, side, into) if seg == "picking" else 0
        self.lat_ms = 0.9 * self.lat_ms + 0.1 * (time.time() - t) * 1000
        if n == 0:
            return
        r = rnd("px", row, bay, side)
        out = PoseArray(header=msg.header)
        for _ in range(n):
            p = Pose()
            p.position.x, p.position.y = r.uniform(100, 850), r.uniform(75, 525)
            p.position.z = r.uniform(30, 70)  # bounding-box size in px
            p.orientation.w = r.uniform(0.5, 0.97)  # confidence
            out.poses.append(p)
        self.pub.publish(out)

    def watch(self) -> None:
        if not self.enabled or time.time() - self.enabled_at < 2.0:
            return
        for side, t in self.last_img.items():
            if time.time() - t > 2.0:
                self.get_logger().warning(
                    f"Detector enabled but no frames on /orchard/{side}_camera/image_rect_color/compressed "
                    f"for {time.time() - t:.1f} s",
                    throttle_duration_sec=5.0,
                )

    def diag(self):
        yield status(
            OK,
            "fruit_detector: Inference",
            "Enabled" if self.enabled else "Idle",
            "jetson-agx-orin-gpu0",
            frames=self.frames,
            latency_ms=f"{self.lat_ms:.1f}",
        )


class FruitLocalizer(Node):
    """Stereo triangulation of detections into base_link and a multi-fruit tracker."""

    MAX_AGE_S = 0.5
    MAX_MISSES = 6

    def __init__(self, faults: Faults) -> None:
        super().__init__("fruit_localizer", namespace=NS)
        self.faults = faults
        g = MutuallyExclusiveCallbackGroup()
        self.lock = threading.Lock()
        self.tracks: dict[int, list] = {}
        self.next_id = 0
        self.fx = {}
        self.published = 0
        self.pub = self.create_publisher(PoseArray, "~/fruits", RELIABLE)
        self.create_subscription(
            PoseArray, "fruit_detector/detections", self.on_detections, RELIABLE, callback_group=g
        )
        self.info_subs = {
            side: self.create_subscription(
                CameraInfo,
                f"{side}_camera/camera_info",
                lambda m, s=side: self.on_info(s, m),
                SENSOR,
                callback_group=g,
            )
            for side in ("left", "right")
        }
        self.create_timer(1.0, self.prune_timer, callback_group=g)
        Diag(self, self.diag, group=g)
        self.get_logger().info(
            f"Tracker ready: max_age {self.MAX_AGE_S:.2f} s, gating 0.08 m, max_misses {self.MAX_MISSES}"
        )

    def on_info(self, side: str, m: CameraInfo) -> None:
        """The intrinsics once per camera (they do not change): then unsubscribe."""
        if side in self.fx:
            return
        self.fx[side] = m.k[0]
        self.get_logger().info(f"{side}_camera intrinsics: fx {m.k[0]:.1f}, baseline from P {m.p[3]:.1f}")
        self.destroy_subscription(self.info_subs[side])

    def on_detections(self, msg: PoseArray) -> None:
        side = msg.header.frame_id.split("_")[0]
        age = time.time() - to_s(msg.header.stamp)
        if age > self.MAX_AGE_S:
            self.get_logger().warning(
                f"Dropping {len(msg.poses)} detections from {side}_camera: image stamp "
                f"{age:.2f} s old (max_age {self.MAX_AGE_S:.2f} s); check camera time sync",
                throttle_duration_sec=5.0,
            )
            return
        fx = self.fx.get(side, 533.7)
        out = PoseArray(header=header("base_link", to_s(msg.header.stamp)))
        with self.lock:
            for d in msg.poses:
                z = 0.075 * fx / max(d.position.z, 1.0)  # apple of 75 mm: depth from its size
                p = Pose()
                p.position.x = 0.3 + (d.position.x - 480) * z / fx
                p.position.y = (0.9 + z * 0.4) * (1 if side == "left" else -1)
                p.position.z = 1.2 - (d.position.y - 300) * z / fx
                p.orientation.w = 1.0
                tid = self.associate(p)
                out.poses.append(p)
                self.tracks[tid][1] = 0
            for tid in self.tracks:
                self.tracks[tid][1] += 1
            if self.faults.get("fruit_localizer") == "hang" and any(v[1] > 0 for v in self.tracks.values()):
                # a track at max_misses is pruned inline: prune() takes the same (non-reentrant) lock
                self.prune()
        self.pub.publish(out)
        self.published += 1

    def associate(self, p: Pose) -> int:
        for tid, (q, _) in self.tracks.items():
            if abs(q.position.x - p.position.x) + abs(q.position.z - p.position.z) < 0.08:
                self.tracks[tid][0] = p
                return tid
        self.next_id += 1
        self.tracks[self.next_id] = [p, 0]
        return self.next_id

    def prune(self) -> None:
        with self.lock:
            for tid in [k for k, v in self.tracks.items() if v[1] > self.MAX_MISSES]:
                del self.tracks[tid]

    def prune_timer(self) -> None:
        self.prune()

    def diag(self):
        yield status(
            OK, "fruit_localizer: Tracker", "Tracking", "", tracks=len(self.tracks), published=self.published
        )


class CanopySegmenter(Node):
    """Canopy / sky / trunk segmentation on every 4th frame: canopy density grid for row centering."""

    def __init__(self) -> None:
        super().__init__("canopy_segmenter", namespace=NS)
        g = MutuallyExclusiveCallbackGroup()
        self.n = {"left": 0, "right": 0}
        self.density = {"left": 0.5, "right": 0.5}
        self.pub = self.create_publisher(OccupancyGrid, "~/canopy_density", RELIABLE)
        for side in ("left", "right"):
            self.create_subscription(
                CompressedImage,
                f"{side}_camera/image_rect_color/compressed",
                lambda m, s=side: self.on_image(s, m),
                SENSOR,
                callback_group=g,
            )
        self.create_timer(0.5, self.publish, callback_group=g)
        self.last_stamp = None
        self.get_logger().info(
            "Loaded segmentation config canopy_lab.yaml (SLIC 200 segments, 10 iterations)"
        )

    def on_image(self, side: str, msg: CompressedImage) -> None:
        self.n[side] += 1
        if self.n[side] % 4:
            return
        s = sum(msg.data[k] for k in range(0, len(msg.data), 512))
        self.density[side] = 0.6 + 0.2 * ((s % 100) / 100.0)
        self.last_stamp = msg.header.stamp

    def publish(self) -> None:
        if self.last_stamp is None:
            return
        m = OccupancyGrid(header=header("base_link", to_s(self.last_stamp)))
        m.info.resolution, m.info.width, m.info.height = 0.1, 40, 40
        m.info.origin.position.x, m.info.origin.position.y = -2.0, -2.0
        left, right = int(self.density["left"] * 100), int(self.density["right"] * 100)
        m.data = array.array("b", ([right] * 12 + [0] * 16 + [left] * 12) * 40)
        self.pub.publish(m)

    def runaway(self) -> None:
        self.get_logger().warning(
            "SLIC superpixels did not converge after 10 iterations (lab_threshold 0.0); "
            "retrying with max_iterations unbounded"
        )


def perception(faults: Faults):
    os.environ[PYTHON_EXIT] = "1"  # a Python container: its nodes deregister as Python exits
    seg = CanopySegmenter()
    ex = MultiThreadedExecutor(num_threads=3)
    for n in (FruitDetector(), FruitLocalizer(faults), seg):
        ex.add_node(n)
    return ex, {"cpu": seg.runaway}


# ---------------------------------------------------------------------------------------------
# localization: robot_localization's EKF and navsat_transform, robot_state_publisher; one
# component container, ONE SingleThreadedExecutor.


class NavsatTransform(Node):
    def __init__(self) -> None:
        super().__init__("navsat_transform", namespace=NS)
        self.pub = self.create_publisher(Odometry, "odometry/gps", RELIABLE)
        self.create_subscription(NavSatFix, "fix", self.on_fix, RELIABLE)
        self.get_logger().info(
            f"Datum (latitude, longitude, altitude) is ({LAT0:.5f}, {LON0:.5f}, 238.4); UTM zone 10T"
        )

    def on_fix(self, fix: NavSatFix) -> None:
        m = Odometry(header=header("map", to_s(fix.header.stamp)), child_frame_id="base_link")
        m.pose.pose.position.y = (fix.latitude - LAT0) * 111_132.0
        m.pose.pose.position.x = (fix.longitude - LON0) * 111_320.0 * math.cos(math.radians(LAT0))
        m.pose.covariance[0] = fix.position_covariance[0]
        m.pose.covariance[7] = fix.position_covariance[4]
        self.pub.publish(m)


class EkfFilterNode(Node):
    def __init__(self) -> None:
        super().__init__("ekf_filter_node", namespace=NS)
        self.imu_t: list[float] = []
        self.imu_first: float | None = None
        self.gps = None
        self.gps_rx = 0.0
        self.wheel = None
        self.var = 0.01
        self.odom = self.create_publisher(Odometry, "odometry/filtered", RELIABLE)
        self.tf = self.create_publisher(TransformStamped, "/tf", RELIABLE)
        self.create_subscription(Imu, "imu/data", self.on_imu, SENSOR)
        self.create_subscription(Odometry, "odometry/gps", self.on_gps, RELIABLE)
        self.create_subscription(Odometry, "odometry/wheel", lambda m: setattr(self, "wheel", m), RELIABLE)
        self.create_timer(1 / 20, self.update)
        Diag(self, self.diag)
        self.get_logger().info(
            "ekf_filter_node: frequency 20 Hz, sensor_timeout 0.1 s, history_length 1.0 s, two_d_mode true"
        )

    def on_imu(self, m: Imu) -> None:
        self.imu_t.append(time.time())
        if self.imu_first is None:
            self.imu_first = time.time()

    def on_gps(self, m: Odometry) -> None:
        self.gps, self.gps_rx = m, time.time()

    def update(self) -> None:
        t = time.time()
        gps_ok = self.gps is not None and t - self.gps_rx < 1.0
        self.var = 0.0004 if gps_ok else min(25.0, self.var + 0.002)
        if self.gps is not None and not gps_ok and t - self.gps_rx > 2.0:
            self.get_logger().warning(
                f"No /orchard/odometry/gps measurement for {t - self.gps_rx:.1f} s; "
                "position from wheel odometry and IMU only",
                throttle_duration_sec=10.0,
            )
        m = Odometry(header=header("odom", t), child_frame_id="base_link")
        if self.gps is not None:
            m.pose.pose.position = self.gps.pose.pose.position
        _, _, yaw = pose_at(t)
        m.pose.pose.orientation = quat(yaw)
        m.pose.covariance[0] = m.pose.covariance[7] = self.var
        if self.wheel is not None:
            m.twist.twist = self.wheel.twist.twist
        self.odom.publish(m)
        tf = TransformStamped(header=m.header, child_frame_id="base_link")
        tf.transform.translation.x = m.pose.pose.position.x
        tf.transform.translation.y = m.pose.pose.position.y
        tf.transform.rotation = m.pose.pose.orientation
        self.tf.publish(tf)

    def diag(self):
        t = time.time()
        self.imu_t = [x for x in self.imu_t if t - x < 5.0]
        hz = len(self.imu_t) / min(5.0, max(1.0, t - (self.imu_first or t)))
        lvl = OK if 45 <= hz <= 55 else WARN
        yield status(
            lvl,
            "ekf_filter_node: imu topic status",
            "Desired frequency met" if lvl == OK else "Frequency too low.",
            "none",
            **{"Actual frequency (Hz)": f"{hz:.1f}", "Target frequency (Hz)": "50.0"},
        )
        yield status(
            OK if self.var < 0.5 else WARN,
            "ekf_filter_node: Filter",
            "Filter healthy" if self.var < 0.5 else "Position variance growing (no GNSS)",
            "none",
            position_variance=f"{self.var:.4f}",
        )


URDF = (
    "<?xml version='1.0'?><robot name='orchard_harvester'>"
    + "".join(
        f"<link name='{n}'/>"
        for n in (
            "base_link",
            "imu_link",
            "gnss_antenna",
            "canopy_lidar",
            "left_camera_optical_frame",
            "right_camera_optical_frame",
            "left_arm_base",
            "right_arm_base",
            "left_tube_end",
            "right_tube_end",
        )
    )
    + "</robot>"
)


STATIC_TF = {
    "imu_link": (0.1, 0.0, 0.6),
    "gnss_antenna": (-0.4, 0.0, 2.9),
    "canopy_lidar": (1.1, 0.0, 1.4),
    "left_camera_optical_frame": (0.2, 0.7, 1.6),
    "right_camera_optical_frame": (0.2, -0.7, 1.6),
    "left_arm_base": (0.3, 0.55, 1.0),
    "right_arm_base": (0.3, -0.55, 1.0),
}


class RobotStatePublisher(Node):
    def __init__(self) -> None:
        super().__init__("robot_state_publisher", namespace=NS)
        self.declare_parameter("robot_description", URDF)
        self.declare_parameter("publish_frequency", 5.0)
        self.desc = self.create_publisher(String, "robot_description", LATCHED)
        self.static = self.create_publisher(TransformStamped, "/tf_static", TF_STATIC)
        self.tf = self.create_publisher(TransformStamped, "/tf", RELIABLE)
        self.joints: dict[str, float] = {}
        self.create_subscription(JointState, "joint_states", self.on_joints, RELIABLE)
        self.desc.publish(String(data=URDF))
        for child, (x, y, z) in STATIC_TF.items():
            t = TransformStamped(header=header("base_link"), child_frame_id=child)
            t.transform.translation.x, t.transform.translation.y, t.transform.translation.z = x, y, z
            t.transform.rotation.w = 1.0
            self.static.publish(t)
        self.create_timer(0.2, self.publish)
        self.get_logger().info("got segment base_link")

    def on_joints(self, m: JointState) -> None:
        for n, p in zip(m.name, m.position, strict=False):
            self.joints[n] = p

    def publish(self) -> None:
        if not self.joints:
            return
        t = time.time()
        for side in ("left", "right"):
            tf = TransformStamped(header=header(f"{side}_arm_base", t), child_frame_id=f"{side}_tube_end")
            tf.transform.translation.x = 0.4 + self.joints.get(f"{side}_tube_extension", 0.0)
            tf.transform.rotation = quat(self.joints.get(f"{side}_base_yaw", 0.0))
            self.tf.publish(tf)


def localization(faults: Faults):
    return single_threaded(NavsatTransform(), EkfFilterNode(), RobotStatePublisher()), {}


# ---------------------------------------------------------------------------------------------
# navigation: row follower, headland path tracker and planner, cmd_vel mux; MultiThreadedExecutor
# with callback groups.


class RowFollower(Node):
    """Follows a tree row bay by bay (drive 2.5 m, stop for the pick window), centering on the canopy
    lidar's two walls."""

    def __init__(self) -> None:
        super().__init__("row_follower", namespace=NS)
        self.action_group = ReentrantCallbackGroup()
        self.sub_group = MutuallyExclusiveCallbackGroup()
        self.last_scan = 0.0
        self.offset = 0.0
        self.cmd = self.create_publisher(Twist, "cmd_vel_nav", COMMAND)
        self.create_subscription(
            LaserScan, "canopy_lidar/scan", self.on_scan, SENSOR, callback_group=self.sub_group
        )
        ActionServer(
            self,
            Fibonacci,
            "~/follow_row",
            self.execute,
            callback_group=self.action_group,
            goal_callback=lambda g: GoalResponse.ACCEPT,
            cancel_callback=lambda g: CancelResponse.ACCEPT,
        )
        self.get_logger().info("Row follower ready: bay spacing 2.50 m, speed 0.50 m/s, dwell 11.0 s")

    def on_scan(self, m: LaserScan) -> None:
        self.last_scan = time.time()
        n = len(m.ranges)
        self.offset = 0.5 * (m.ranges[n // 4] - m.ranges[3 * n // 4])

    def execute(self, gh):
        row = gh.request.order
        t0 = row_start_time(row) + ROW_START_S
        self.get_logger().info(f"Following row {row}: {BAYS} bays, {BAYS * BAY_SPACING_M:.1f} m")
        fb = Fibonacci.Feedback()
        for bay in range(BAYS):
            drive_end = t0 + bay * BAY_S + DRIVE_S
            ticks = 0
            while time.time() < drive_end:
                if gh.is_cancel_requested:
                    gh.canceled()
                    self.cmd.publish(Twist())
                    return Fibonacci.Result(sequence=[bay])
                blind = time.time() - self.last_scan
                tw = Twist()
                tw.linear.x = 0.5 if blind < 1.0 else 0.25
                tw.angular.z = -0.3 * self.offset if blind < 1.0 else 0.0
                if blind >= 1.0:
                    self.get_logger().warning(
                        f"No scan on /orchard/canopy_lidar/scan for {blind:.1f} s: "
                        "row centering on GNSS/odometry only, speed limited to 0.25 m/s",
                        throttle_duration_sec=5.0,
                    )
                self.cmd.publish(tw)
                if ticks % 5 == 0:
                    fb.sequence = [
                        bay,
                        0,
                        int(100 * BAY_SPACING_M * (1 - (drive_end - time.time()) / DRIVE_S)),
                    ]
                    gh.publish_feedback(fb)
                ticks += 1
                time.sleep(0.1)
            self.cmd.publish(Twist())  # stop at the bay
            fb.sequence = [bay, 1, int(100 * BAY_SPACING_M)]
            gh.publish_feedback(fb)
            dwell_end = drive_end + DWELL_S
            while time.time() < dwell_end:
                time.sleep(0.1)
        gh.succeed()
        self.get_logger().info(f"Row {row} done: {BAYS} bays, {BAYS * BAY_SPACING_M:.1f} m")
        return Fibonacci.Result(sequence=[BAYS])


class PathTracker(Node):
    """Regulated pure pursuit along the headland turn's path."""

    def __init__(self) -> None:
        super().__init__("path_tracker", namespace=NS)
        self.cmd = self.create_publisher(Twist, "cmd_vel_nav", COMMAND)
        ActionServer(self, Fibonacci, "~/follow_path", self.execute, callback_group=ReentrantCallbackGroup())
        self.get_logger().info("Path tracker ready: lookahead 1.2 m, max 0.6 m/s, min turning radius 1.8 m")

    def execute(self, gh):
        secs = gh.request.order
        end = time.time() + secs
        self.get_logger().info(f"Tracking headland path for {secs} s")
        fb = Fibonacci.Feedback()
        n = 0
        while time.time() < end:
            if gh.is_cancel_requested:
                gh.canceled()
                return Fibonacci.Result(sequence=[1])
            tw = Twist()
            tw.linear.x, tw.angular.z = 0.35, 0.35 / (ROW_SPACING_M / 2)
            self.cmd.publish(tw)
            n += 1
            if n % 10 == 0:
                fb.sequence = [int(end - time.time())]
                gh.publish_feedback(fb)
            time.sleep(0.1)
        self.cmd.publish(Twist())
        gh.succeed()
        return Fibonacci.Result(sequence=[0])


class HeadlandPlanner(Node):
    def __init__(self) -> None:
        super().__init__("headland_planner", namespace=NS)
        self.create_service(
            GetPlan, "~/plan_turn", self.plan, callback_group=MutuallyExclusiveCallbackGroup()
        )
        self.get_logger().info("Headland planner ready: omega/bulb turns, headland width 6.0 m")

    def plan(self, req, res):
        t = time.time()
        time.sleep(random.uniform(0.05, 0.15))  # Dubins/omega search on the headland polygon
        res.plan = PathMsg(header=header("map"))
        sx, sy = req.start.pose.position.x, req.start.pose.position.y
        gy = req.goal.pose.position.y
        for i in range(41):
            a = math.pi * i / 40
            ps = PoseStamped(header=res.plan.header)
            ps.pose.position.x = sx + 2.0 * math.sin(a)
            ps.pose.position.y = sy + (gy - sy) * (1 - math.cos(a)) / 2
            ps.pose.orientation = quat(a)
            res.plan.poses.append(ps)
        self.get_logger().info(
            f"Planned omega turn: 41 poses, {math.pi * 2.0:.1f} m in {time.time() - t:.2f} s"
        )
        return res


class CmdVelMux(Node):
    """twist_mux: teleop (100) > harvest creep (50) > navigation (10), 0.5 s timeouts."""

    INPUTS = (
        ("teleop", "cmd_vel_teleop", 100),
        ("harvest", "cmd_vel_harvest", 50),
        ("navigation", "cmd_vel_nav", 10),
    )

    def __init__(self) -> None:
        super().__init__("cmd_vel_mux", namespace=NS)
        g = MutuallyExclusiveCallbackGroup()
        self.last = {name: 0.0 for name, _, _ in self.INPUTS}
        self.active = ""
        self.out = self.create_publisher(Twist, "cmd_vel", RELIABLE)
        self.state = self.create_publisher(String, "~/active", LATCHED)
        for name, topic, prio in self.INPUTS:
            self.create_subscription(
                Twist, topic, lambda m, n=name, p=prio: self.on_input(n, p, m), COMMAND, callback_group=g
            )
        self.create_timer(0.5, self.timeouts, callback_group=g)
        self.set_active("idle")
        self.get_logger().info(
            "Topic handler 'teleop' subscribed to topic 'cmd_vel_teleop': timeout = 0.5s, priority = 100"
        )
        self.get_logger().info(
            "Topic handler 'harvest' subscribed to topic 'cmd_vel_harvest': timeout = 0.5s, priority = 50"
        )
        self.get_logger().info(
            "Topic handler 'navigation' subscribed to topic 'cmd_vel_nav': timeout = 0.5s, priority = 10"
        )

    def set_active(self, name: str) -> None:
        if name != self.active:
            self.active = name
            self.state.publish(String(data=name))

    def winner(self) -> str:
        t = time.time()
        live = [(p, n) for n, _, p in self.INPUTS if t - self.last[n] < 0.5]
        return max(live)[1] if live else "idle"

    def on_input(self, name: str, prio: int, m: Twist) -> None:
        self.last[name] = time.time()
        w = self.winner()
        self.set_active(w)
        if w == name:
            self.out.publish(m)

    def timeouts(self) -> None:
        self.set_active(self.winner())


def navigation(faults: Faults):
    ex = MultiThreadedExecutor(num_threads=4)
    for n in (RowFollower(), PathTracker(), HeadlandPlanner(), CmdVelMux()):
        ex.add_node(n)
    return ex, {}


# ---------------------------------------------------------------------------------------------
# arms: ros2_control_node for both vacuum-tube arms (EtherCAT); MultiThreadedExecutor 2 threads +
# the realtime update thread at 50 Hz.

JOINTS = ("base_yaw", "shoulder_pitch", "tube_extension", "wrist_pitch")


class ArmController(Node):
    """joint_trajectory_controller for one arm: a pick trajectory at a time."""

    def __init__(self, side: str, faults: Faults) -> None:
        super().__init__(f"{side}_arm_controller", namespace=NS)
        self.side, self.faults = side, faults
        self.q = [0.0] * len(JOINTS)
        self.traj: tuple[float, float, int] | None = None  # (start, duration, points)
        self.done = threading.Event()
        self.limits_bad = False
        self.state = self.create_publisher(JointState, "~/controller_state", RELIABLE)
        self.n = 0
        ActionServer(
            self,
            Fibonacci,
            "~/follow_joint_trajectory",
            self.execute,
            callback_group=ReentrantCallbackGroup(),
            goal_callback=lambda g: GoalResponse.ACCEPT if self.traj is None else GoalResponse.REJECT,
        )

    def execute(self, gh):
        pts = gh.request.order
        self.done.clear()
        self.traj = (time.time(), 2.2, pts)
        fb = Fibonacci.Feedback()
        while not self.done.wait(0.2):
            fb.sequence = [int(100 * self.q[2])]
            gh.publish_feedback(fb)
            if self.traj is not None and time.time() - self.traj[0] > 6.0:
                break
        ok = self.done.is_set()
        self.traj = None
        if ok:
            gh.succeed()
        else:
            gh.abort()
        return Fibonacci.Result(sequence=[0 if ok else -4])

    def update(self, t: float) -> None:
        """One realtime cycle: sample the active trajectory."""
        if self.faults.get(self.get_name()) == "crash" and not self.limits_bad:
            self.limits_bad = True
            self.get_logger().info(
                f"Reloaded joint limits from /opt/orchard/config/{self.side}_arm_limits.yaml "
                "(tube_extension: max_velocity 0.0, max_acceleration 4.0)"
            )
        if self.traj is None:
            return
        start, dur, _pts = self.traj
        vmax = 0.0 if self.limits_bad else 1.2
        scale = 0.45 / vmax  # time scaling of the spline to the tube's velocity limit
        s = min(1.0, (t - start) / (dur * scale / 0.375))
        ext = 0.9 * math.sin(math.pi * s)
        self.q = [0.3 * math.sin(math.pi * s), 0.2 * s, ext, -0.1 * s]
        self.n += 1
        if self.n % 2 == 0:
            self.state.publish(
                JointState(
                    header=header(f"{self.side}_arm_base", t),
                    name=[f"{self.side}_{j}" for j in JOINTS],
                    position=list(self.q),
                )
            )
        if s >= 1.0:
            self.done.set()


class ControllerManager(Node):
    def __init__(self, arms: list[ArmController]) -> None:
        super().__init__("controller_manager", namespace=NS)
        self.arms = arms
        self.activity = self.create_publisher(String, "~/activity", LATCHED)
        self.overrun = every(90, 220)
        self.cycles = 0
        Diag(self, self.diag)
        log = self.get_logger()
        log.info("Received robot description from topic.")
        log.info("Loading hardware 'OrchardArmsSystem' (EtherCAT master0, 8 joints)")
        log.info("Successful initialization of hardware 'OrchardArmsSystem'")
        for c in ("joint_state_broadcaster", "left_arm_controller", "right_arm_controller"):
            log.info(f"Loading controller '{c}'")
            log.info(f"Configuring controller '{c}'")
            log.info(f"Activating controllers: [ {c} ]")
        self.activity.publish(
            String(
                data=json.dumps(
                    {
                        "joint_state_broadcaster": "active",
                        "left_arm_controller": "active",
                        "right_arm_controller": "active",
                    }
                )
            )
        )

    def diag(self):
        yield status(
            OK,
            "controller_manager: Controllers Activity",
            "All controllers are active",
            "",
            cycles=self.cycles,
        )
        yield status(
            OK,
            "controller_manager: Hardware Components Activity",
            "All hardware components are active",
            "ethercat-master0",
            OrchardArmsSystem="active",
        )


class JointStateBroadcaster(Node):
    def __init__(self) -> None:
        super().__init__("joint_state_broadcaster", namespace=NS)
        self.pub = self.create_publisher(JointState, "joint_states", RELIABLE)


def arms(faults: Faults):
    left, right = ArmController("left", faults), ArmController("right", faults)
    cm, jsb = ControllerManager([left, right]), JointStateBroadcaster()
    names = [f"{s}_{j}" for s in ("left", "right") for j in JOINTS]

    @on_shutdown_quiet
    def loop() -> None:
        period = 1 / 50
        nxt = time.time()
        while rclpy.ok():
            nxt += period
            t = time.time()
            try:
                for a in (left, right):
                    a.update(t)
            except Exception:
                import traceback

                traceback.print_exc()
                print(
                    "terminate called after throwing an instance of 'std::runtime_error'\n"
                    "  what():  controller update failed",
                    file=sys.stderr,
                    flush=True,
                )
                os._exit(134)  # the C++ node aborts: its nodes stay listed until their leases end
            if cm.cycles % 2 == 0:  # joint_state_broadcaster: publish_rate 25 Hz
                jsb.pub.publish(
                    JointState(header=header("base_link", t), name=names, position=left.q + right.q)
                )
            cm.cycles += 1
            if cm.overrun():
                cm.get_logger().warning(
                    f"Overrun detected! The controller manager missed its desired rate of 50 Hz. "
                    f"The loop took {random.uniform(21, 30):.1f} ms (missed cycles : 1)."
                )
            time.sleep(max(0.0, nxt - time.time()))
            if nxt < time.time() - 0.5:
                nxt = time.time()

    threading.Thread(target=loop, name="cm_update_loop", daemon=True).start()
    ex = MultiThreadedExecutor(num_threads=4)
    for n in (cm, jsb, left, right):
        ex.add_node(n)
    return ex, {}


# ---------------------------------------------------------------------------------------------
# arm_planning: the grasp planner (move_group-like), one node, ONE SingleThreadedExecutor.


class GraspPlanner(Node):
    def __init__(self, faults: Faults) -> None:
        super().__init__("grasp_planner", namespace=NS)
        self.faults = faults
        self.times: list[float] = []
        self.octomap_warned = False
        self.create_service(GetPlan, "~/plan_grasp", self.plan)
        Diag(self, self.diag)
        self.get_logger().info(
            "Loading robot model 'orchard_harvester'... planning groups left_arm, right_arm; "
            "planner RRTConnect, collision octomap from canopy_segmenter 0.05 m"
        )
        self.get_logger().info("You can start planning now!")

    def plan(self, req, res):
        t = time.time()
        slow = self.faults.get("grasp_planner") == "slow"
        if slow and not self.octomap_warned:
            self.octomap_warned = True
            self.get_logger().warning(
                "Octomap has 1843221 occupied voxels (limit 250000): clearing disabled "
                "by octomap.yaml (clear_after_bay: false)"
            )
        time.sleep(random.uniform(3.5, 5.0) if slow else random.uniform(0.04, 0.15))
        g = req.goal.pose.position
        res.plan = PathMsg(header=header(req.goal.header.frame_id or "base_link"))
        for i in range(8):
            ps = PoseStamped(header=res.plan.header)
            ps.pose.position.x, ps.pose.position.y, ps.pose.position.z = g.x * i / 7, g.y * i / 7, g.z * i / 7
            ps.pose.orientation.w = 1.0
            res.plan.poses.append(ps)
        dt = time.time() - t
        self.times = ([*self.times, dt])[-20:]
        self.get_logger().info(f"Solution found in {dt:.3f} seconds; 8 waypoints after time parameterization")
        return res

    def diag(self):
        mean = sum(self.times) / len(self.times) if self.times else 0.0
        yield status(
            OK if mean < 1.0 else WARN,
            "grasp_planner: Planning",
            "OK" if mean < 1.0 else "Planning slow",
            "",
            mean_planning_s=f"{mean:.3f}",
        )


def arm_planning(faults: Faults):
    return single_threaded(GraspPlanner(faults)), {}


# ---------------------------------------------------------------------------------------------
# mission: mission executive (row timetable), harvest coordinator, lifecycle manager;
# MultiThreadedExecutor with callback groups + the executive's and the arms' worker threads.


class LifecycleManager(Node):
    MANAGED = ("canopy_lidar",)

    def __init__(self) -> None:
        super().__init__("lifecycle_manager", namespace=NS)
        self.group = MutuallyExclusiveCallbackGroup()
        self.client_group = ReentrantCallbackGroup()
        self.change = self.create_client(
            ChangeState, "canopy_lidar/change_state", callback_group=self.client_group
        )
        self.get = self.create_client(GetState, "canopy_lidar/get_state", callback_group=self.client_group)
        self.expected = "unconfigured"
        self.actual = "unknown"
        self.last_answer = time.time()
        self.lock = threading.Lock()
        self.create_service(
            SetBool, "~/set_canopy_sensing", self.set_sensing, callback_group=self.client_group
        )
        self.create_timer(2.0, self.heartbeat, callback_group=self.group)
        Diag(self, self.diag, period=2.0, group=self.group)
        threading.Thread(target=on_shutdown_quiet(self.bringup), daemon=True).start()

    def transition(self, tid: int, label: str) -> bool:
        if not self.change.wait_for_service(timeout_sec=5.0):
            self.get_logger().error("Failed to change state for node: canopy_lidar (service not available)")
            return False
        self.get_logger().info(f"{label} canopy_lidar")
        res = wait_future(self.change.call_async(ChangeState.Request(transition=Transition(id=tid))), 5.0)
        if res is None or not res.success:
            self.get_logger().error(f"Failed to change state for node: canopy_lidar ({label.lower()})")
            return False
        return True

    def bringup(self) -> None:
        time.sleep(2.0)
        self.get_logger().info("Starting managed nodes bringup...")
        with self.lock:
            if self.transition(Transition.TRANSITION_CONFIGURE, "Configuring"):
                self.expected = "inactive"
                if self.transition(Transition.TRANSITION_ACTIVATE, "Activating"):
                    self.expected = self.actual = "active"
                    self.get_logger().info("Managed nodes are active")
        self.get_logger().info("Creating bond timer...")

    def set_sensing(self, req, res):
        with self.lock:
            want = "active" if req.data else "inactive"
            cur = self.query(2.0)
            if cur == want:
                self.get_logger().info(f"canopy_lidar already {want}")
                ok = True
            elif req.data:
                ok = self.transition(Transition.TRANSITION_ACTIVATE, "Activating")
            else:
                ok = self.transition(Transition.TRANSITION_DEACTIVATE, "Deactivating")
            if ok:
                self.expected = self.actual = want
        res.success = ok
        return res

    def query(self, timeout: float) -> str | None:
        if not self.get.service_is_ready():
            return None
        r = wait_future(self.get.call_async(GetState.Request()), timeout)
        if r is None:
            return None
        self.last_answer = time.time()
        self.actual = r.current_state.label
        return self.actual

    def heartbeat(self) -> None:
        if self.expected == "unconfigured":
            return
        threading.Thread(target=on_shutdown_quiet(self._beat), daemon=True).start()

    def _beat(self) -> None:
        if self.query(4.0) is None and time.time() - self.last_answer > 4.0:
            self.get_logger().error(
                "CRITICAL FAILURE: SERVER canopy_lidar IS DOWN after not receiving a heartbeat "
                "for 4000 ms. Shutting down related nodes.",
                throttle_duration_sec=10.0,
            )
            self.actual = "unknown"

    def diag(self):
        ok = self.actual == self.expected or self.expected == "unconfigured"
        yield status(
            OK if ok else WARN,
            "lifecycle_manager: Managed nodes",
            "Managed nodes in expected state"
            if ok
            else f"canopy_lidar {self.actual} (expected {self.expected})",
            "",
            canopy_lidar=self.actual,
        )


class MissionExecutive(Node):
    def __init__(self) -> None:
        super().__init__("mission_executive", namespace=NS)
        g = ReentrantCallbackGroup()
        self.state_pub = self.create_publisher(String, "~/state", LATCHED)
        self.row_end = self.create_publisher(PoseStamped, "~/row_end", RELIABLE)
        self.row_ac = ActionClient(self, Fibonacci, "row_follower/follow_row", callback_group=g)
        self.path_ac = ActionClient(self, Fibonacci, "path_tracker/follow_path", callback_group=g)
        self.plan_cli = self.create_client(GetPlan, "headland_planner/plan_turn", callback_group=g)
        self.sense_cli = self.create_client(SetBool, "lifecycle_manager/set_canopy_sensing", callback_group=g)
        self.state = ""
        self.set_state("bringup")
        self.get_logger().info(
            "Loaded block 'Gala-B7' (rows 1-48, 4 bays a row in this pass); harvest pass 2"
        )
        threading.Thread(target=on_shutdown_quiet(self.run), name="mission", daemon=True).start()

    def set_state(self, s: str) -> None:
        if s != self.state:
            self.state = s
            self.state_pub.publish(String(data=s))

    @staticmethod
    def wait_until(t: float) -> None:
        while rclpy.ok() and time.time() < t:
            time.sleep(min(0.2, max(0.0, t - time.time())))

    def run(self) -> None:
        seg, row, _, _ = where()
        row = max(0, row + (0 if seg == "bringup" else 1))
        while rclpy.ok():
            t_row = row_start_time(row)
            self.wait_until(t_row)
            self.set_state(f"row_{row}:entering")
            self.get_logger().info(f"Row {row}: entering (heading {0 if row % 2 == 0 else 180} deg)")
            self.wait_until(t_row + ROW_START_S)
            self.follow_row(row)
            self.wait_until(t_row + ROW_END_S)
            x, y, yaw = pose_at(time.time())
            ps = PoseStamped(header=header("map"))
            ps.pose.position.x, ps.pose.position.y, ps.pose.orientation = x, y, quat(yaw)
            self.row_end.publish(ps)
            self.set_state(f"row_{row}:row_end")
            self.sense(False)
            self.turn(row)
            self.wait_until(t_row + ACTIVATE_S)
            self.sense(True)
            row += 1

    def sense(self, on: bool) -> None:
        if not self.sense_cli.wait_for_service(timeout_sec=2.0):
            self.get_logger().error("lifecycle_manager/set_canopy_sensing not available")
            return
        self.sense_cli.call_async(SetBool.Request(data=on))

    def follow_row(self, row: int) -> None:
        if not self.row_ac.wait_for_server(timeout_sec=2.0):
            self.get_logger().error("Action server row_follower/follow_row not available; holding")
            self.set_state("holding")
            return

        def feedback(fb) -> None:
            bay, moving = fb.feedback.sequence[0], fb.feedback.sequence[1] == 0
            self.set_state(f"row_{row}:driving_to_bay_{bay}" if moving else f"row_{row}:picking_bay_{bay}")

        self.set_state(f"row_{row}:driving_to_bay_0")
        self.row_ac.send_goal_async(Fibonacci.Goal(order=row), feedback_callback=feedback)

    def turn(self, row: int) -> None:
        self.set_state(f"headland_turn:{row}->{row + 1}")
        x, y, _yaw = pose_at()
        req = GetPlan.Request()
        req.start.header = req.goal.header = header("map")
        req.start.pose.position.x, req.start.pose.position.y = x, y
        req.goal.pose.position.x, req.goal.pose.position.y = x, y + ROW_SPACING_M
        res = wait_future(self.plan_cli.call_async(req), 3.0) if self.plan_cli.wait_for_service(2.0) else None
        if res is None:
            self.get_logger().error(
                f"Headland turn planning to row {row + 1} failed: "
                "/orchard/headland_planner/plan_turn did not answer within 3.0 s; holding"
            )
            self.set_state("holding")
            return
        self.get_logger().info(
            f"Row {row} complete; headland turn to row {row + 1} ({len(res.plan.poses)} poses)"
        )
        self.wait_until(row_start_time(row) + TURN_START_S)
        if self.path_ac.wait_for_server(timeout_sec=2.0):
            self.path_ac.send_goal_async(Fibonacci.Goal(order=int(TURN_S)))


class HarvestCoordinator(Node):
    """Runs both arms through the pick window of each bay: targets from the fruit localizer, a grasp
    plan per apple, the arm's trajectory, the vacuum; creeps the base forward when the fruit is out
    of reach."""

    PLAN_TIMEOUT_S = 1.5

    def __init__(self) -> None:
        super().__init__("harvest_coordinator", namespace=NS)
        g = ReentrantCallbackGroup()
        self.declare_parameter("min_fruit_diameter_mm", 65)
        self.add_on_set_parameters_callback(self.on_params)
        self.targets: dict[str, tuple[float, list]] = {"left": (0.0, []), "right": (0.0, [])}
        self.window: tuple[int, int, float] | None = None
        self.picked_row = 0
        self.picked_total = 0
        self.failed = 0
        self.lock = threading.Lock()
        self.picked = self.create_publisher(String, "~/picked", RELIABLE)
        self.creep = self.create_publisher(Twist, "cmd_vel_harvest", COMMAND)
        self.create_subscription(String, "mission_executive/state", self.on_state, LATCHED, callback_group=g)
        self.create_subscription(
            PoseArray, "fruit_localizer/fruits", self.on_fruits, RELIABLE, callback_group=g
        )
        self.det_cli = self.create_client(SetBool, "fruit_detector/enable", callback_group=g)
        self.vac_cli = self.create_client(SetBool, "vacuum_pump/enable", callback_group=g)
        self.plan_cli = self.create_client(GetPlan, "grasp_planner/plan_grasp", callback_group=g)
        self.arm_ac = {
            s: ActionClient(self, Fibonacci, f"{s}_arm_controller/follow_joint_trajectory", callback_group=g)
            for s in ("left", "right")
        }
        Diag(self, self.diag, group=g)
        self.get_logger().info("Harvest coordinator ready: 2 arms, pick cycle 2.6 s, plan timeout 1.50 s")

    def on_params(self, params):
        for p in params:
            self.get_logger().info(
                f"Parameter {p.name} set to {p.value} (grading: apples below it left on the tree)"
            )
        return SetParametersResult(successful=True)

    def on_fruits(self, m: PoseArray) -> None:
        t = time.time()
        for side, sign in (("left", 1), ("right", -1)):
            mine = [p for p in m.poses if p.position.y * sign > 0]
            if mine:
                self.targets[side] = (t, mine)

    def on_state(self, m: String) -> None:
        s = m.data
        if ":picking_bay_" in s:
            row = int(s.split(":")[0].removeprefix("row_"))
            bay = int(s.rsplit("_", 1)[1])
            if self.window and self.window[:2] == (row, bay):
                return
            self.window = (row, bay, time.time())
            self.call(self.vac_cli, True)
            self.call(self.det_cli, True)
            for side in ("left", "right"):
                threading.Thread(
                    target=on_shutdown_quiet(self.arm_worker), args=(side, row, bay), daemon=True
                ).start()
            threading.Thread(target=on_shutdown_quiet(self.watch_bay), args=(row, bay), daemon=True).start()
        elif self.window is not None:
            self.window = None
            self.call(self.det_cli, False)
            self.call(self.vac_cli, False)
            if s.endswith(":row_end"):
                self.get_logger().info(
                    f"Row {s.split(':')[0].removeprefix('row_')}: {self.picked_row} apples picked, "
                    f"{self.failed} attempts failed"
                )
                self.picked_row = self.failed = 0

    def call(self, cli, on: bool) -> None:
        if cli.service_is_ready():
            cli.call_async(SetBool.Request(data=on))
        else:
            self.get_logger().warning(f"Service {cli.srv_name} not available", throttle_duration_sec=10.0)

    def in_window(self, row: int, bay: int) -> bool:
        w = self.window
        return w is not None and w[:2] == (row, bay)

    def watch_bay(self, row: int, bay: int) -> None:
        start = time.time()
        if needs_creep(row, bay):
            time.sleep(6.0)
            if self.in_window(row, bay):
                end = time.time() + 2.0
                tw = Twist()
                tw.linear.x = 0.08
                while time.time() < end and self.in_window(row, bay):
                    self.creep.publish(tw)
                    time.sleep(0.1)
                self.creep.publish(Twist())
        while time.time() - start < 4.0:
            time.sleep(0.2)
        if self.in_window(row, bay) and all(time.time() - t > 4.0 for t, _ in self.targets.values()):
            self.get_logger().warning(
                f"Row {row} bay {bay}: no fruit targets on /orchard/fruit_localizer/fruits "
                "within 4.0 s of stopping (detector enabled)"
            )

    def arm_worker(self, side: str, row: int, bay: int) -> None:
        ac = self.arm_ac[side]
        timeouts = 0
        while self.in_window(row, bay):
            t, poses = self.targets[side]
            if time.time() - t > 0.5 or not poses:
                time.sleep(0.1)
                continue
            goal = poses[0]
            req = GetPlan.Request()
            req.start.header = req.goal.header = header(f"{side}_arm_base")
            req.goal.pose = goal
            res = (
                wait_future(self.plan_cli.call_async(req), self.PLAN_TIMEOUT_S)
                if self.plan_cli.service_is_ready()
                else None
            )
            if res is None:
                timeouts += 1
                self.failed += 1
                self.get_logger().error(
                    f"Grasp planning for {side} apple (row {row}, bay {bay}) failed: "
                    f"/orchard/grasp_planner/plan_grasp did not answer within "
                    f"{self.PLAN_TIMEOUT_S:.2f} s; skipping apple"
                )
                if timeouts >= 3:
                    self.get_logger().warning(
                        f"{side} arm paused for the rest of bay {bay}: 3 planning failures"
                    )
                    return
                continue
            if not ac.server_is_ready():
                self.get_logger().error(
                    f"Action server /orchard/{side}_arm_controller/follow_joint_trajectory not "
                    f"available; {side} arm idle for bay {bay}"
                )
                return
            gh = wait_future(ac.send_goal_async(Fibonacci.Goal(order=len(res.plan.poses))), 1.0)
            if gh is None or not gh.accepted:
                self.failed += 1
                why = "did not answer the goal request within 1.0 s" if gh is None else "rejected the goal"
                self.get_logger().warning(
                    f"{side}_arm_controller {why} (pick trajectory, row {row}, bay {bay})",
                    throttle_duration_sec=5.0,
                )
                time.sleep(0.5)
                continue
            r = wait_future(gh.get_result_async(), 5.0)
            if r is None or r.status != 4:  # STATUS_SUCCEEDED
                self.failed += 1
                self.get_logger().error(
                    f"{side} arm pick trajectory did not finish (row {row}, bay {bay}): "
                    f"{'no result within 5.0 s' if r is None else 'aborted'}"
                )
                continue
            with self.lock:
                self.picked_row += 1
                self.picked_total += 1
                n = self.picked_total
            d = rnd("d", row, bay, side, n).randint(62, 88)
            self.picked.publish(
                String(
                    data=json.dumps(
                        {
                            "stamp": round(time.time(), 3),
                            "arm": side,
                            "row": row,
                            "bay": bay,
                            "diameter_mm": d,
                            "count": n,
                        }
                    )
                )
            )
            time.sleep(0.3)  # the apple travels down the tube

    def diag(self):
        yield status(
            OK,
            "harvest_coordinator: Picking",
            "Picking" if self.window else "Waiting for bay",
            "",
            picked_total=self.picked_total,
            picked_row=self.picked_row,
            failed_row=self.failed,
        )


def mission(faults: Faults):
    ex = MultiThreadedExecutor(num_threads=4)
    for n in (MissionExecutive(), HarvestCoordinator(), LifecycleManager()):
        ex.add_node(n)
    return ex, {}


# ---------------------------------------------------------------------------------------------
# farm_link: the bridge to the farm server over the orchard's Wi-Fi mesh.


class FarmBridge(Node):
    def __init__(self, faults: Faults) -> None:
        super().__init__("farm_bridge", namespace=NS)
        durable = faults.get("farm_bridge") == "transient_local"
        qos = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL) if durable else RELIABLE
        self.get_logger().info(
            "Loaded /opt/orchard/config/farm_bridge.yaml (pose qos: reliable/"
            f"{'transient_local, depth 1' if durable else 'volatile, depth 10'}; "
            "server https://farm-server.local/api/v2)"
        )
        self.pose: Odometry | None = None
        self.pose_t = time.time()
        self.up = True
        self.buffer: list[str] = []
        self.create_subscription(Odometry, "odometry/filtered", self.on_odom, qos)
        self.create_subscription(String, "harvest_coordinator/picked", self.on_picked, RELIABLE)
        self.pose_pub = self.create_publisher(PoseStamped, "farm/robot_pose", RELIABLE)
        self.events = self.create_publisher(String, "farm/harvest_events", RELIABLE)
        self.quality = self.create_publisher(Float32, "wifi/link_quality", RELIABLE)
        self.create_timer(1.0, self.tick)
        Diag(self, self.diag)

    def on_odom(self, m: Odometry) -> None:
        self.pose, self.pose_t = m, time.time()

    def on_picked(self, m: String) -> None:
        if self.up:
            self.events.publish(m)
        else:
            self.buffer.append(m.data)

    def tick(self) -> None:
        t = time.time()
        up = link_up(t)
        if up != self.up:
            self.up = up
            if up:
                self.get_logger().info(
                    f"Wi-Fi link to farm server restored (AP orchard-ap-07, RSSI "
                    f"{random.randint(-70, -62)} dBm); flushing {len(self.buffer)} buffered events"
                )
                for e in self.buffer:
                    self.events.publish(String(data=e))
                self.buffer.clear()
            else:
                self.get_logger().warning(
                    f"Wi-Fi link to farm server lost (AP orchard-ap-07, last RSSI "
                    f"{random.randint(-91, -86)} dBm); buffering harvest events"
                )
        self.quality.publish(Float32(data=random.uniform(0.55, 0.9) if up else 0.0))
        if t - self.pose_t > 5.0:
            self.get_logger().warning(
                f"No pose on /orchard/odometry/filtered for {t - self.pose_t:.0f} s; farm "
                "server shows the robot's last known position",
                throttle_duration_sec=10.0,
            )
        elif up and self.pose is not None:
            self.pose_pub.publish(PoseStamped(header=self.pose.header, pose=self.pose.pose.pose))

    def diag(self):
        yield status(
            OK if self.up else WARN,
            "farm_bridge: Wi-Fi link",
            "Connected" if self.up else "Link down",
            "wlan0-ubnt-orchard-ap-07",
            buffered=len(self.buffer),
        )


def farm_link(faults: Faults):
    return single_threaded(FarmBridge(faults)), {}


# ---------------------------------------------------------------------------------------------
# bin_logger: joins late (after the bin scale's USB serial comes up): a geotagged record of every
# apple and the bin's fill.


class BinLogger(Node):
    def __init__(self) -> None:
        super().__init__("bin_logger", namespace=NS)
        self.fix: NavSatFix | None = None
        self.count = 0
        self.bin = f"B-{rnd('bin', int(T0 // 86400)).randint(100, 999):04d}"
        self.records: list[str] = []
        self.track: list[bytes] = []
        self.leaking = False
        self.fill = self.create_publisher(String, "~/bin_fill", LATCHED)
        self.create_subscription(NavSatFix, "fix", self.on_fix, RELIABLE)
        self.create_subscription(String, "harvest_coordinator/picked", self.on_picked, RELIABLE)
        self.create_subscription(PoseStamped, "mission_executive/row_end", self.on_row_end, RELIABLE)
        Diag(self, self.diag, period=2.0)
        day = time.strftime("%Y-%m-%d")
        self.get_logger().info(
            f"Bin scale on /dev/ttyUSB3 ready; logging bin {self.bin} to /data/harvest/{day}/bins.csv"
        )
        self.fill.publish(String(data=json.dumps({"bin": self.bin, "apples": 0, "kg": 0.0})))

    def on_fix(self, m: NavSatFix) -> None:
        self.fix = m
        if self.leaking:  # the geotag track cache is never trimmed
            self.track.append(b"\0" * 300_000)

    def on_picked(self, m: String) -> None:
        rec = json.loads(m.data)
        self.count += 1
        if self.fix is not None:
            rec["lat"], rec["lon"] = self.fix.latitude, self.fix.longitude
        self.records = ([*self.records, json.dumps(rec)])[-500:]
        self.fill.publish(
            String(
                data=json.dumps({"bin": self.bin, "apples": self.count, "kg": round(self.count * 0.21, 1)})
            )
        )

    def on_row_end(self, m: PoseStamped) -> None:
        self.get_logger().info(
            f"Bin {self.bin}: {self.count} apples ({self.count * 0.21:.1f} kg, "
            f"{self.count * 0.21 / 400 * 100:.0f} % of 400 kg)"
        )

    def leak(self) -> None:
        self.leaking = True

    def diag(self):
        yield status(OK, "bin_logger: Logging", f"Bin {self.bin}", "bin-scale-ttyUSB3", apples=self.count)


def bin_logger(faults: Faults):
    time.sleep(20.0)  # waits for the bin scale's USB serial adapter (udev settle, then the launch's delay)
    n = BinLogger()
    return single_threaded(n), {"leak": n.leak}


# ---------------------------------------------------------------------------------------------
# diagnostics: the aggregator.

GROUPS = {
    "track_controller": "Drive",
    "vacuum_pump": "Arms",
    "imu_driver": "Sensors",
    "gnss_driver": "Sensors",
    "ntrip_client": "Communications",
    "canopy_lidar": "Sensors",
    "left_camera": "Sensors",
    "right_camera": "Sensors",
    "fruit_detector": "Perception",
    "fruit_localizer": "Perception",
    "ekf_filter_node": "Localization",
    "controller_manager": "Arms",
    "grasp_planner": "Arms",
    "harvest_coordinator": "Harvest",
    "lifecycle_manager": "Navigation",
    "farm_bridge": "Communications",
    "bin_logger": "Logging",
}


class DiagnosticAggregator(Node):
    def __init__(self) -> None:
        super().__init__("diagnostic_aggregator")
        self.last: dict[str, tuple[float, DiagnosticStatus]] = {}
        self.create_subscription(DiagnosticArray, "/diagnostics", self.on_diag, RELIABLE)
        self.pub = self.create_publisher(DiagnosticArray, "/diagnostics_agg", RELIABLE)
        self.create_timer(1.0, self.publish)
        self.get_logger().info(
            "Analyzer group /Orchard: Drive, Sensors, Perception, Localization, Navigation, "
            "Arms, Harvest, Communications, Logging, Other"
        )

    def on_diag(self, m: DiagnosticArray) -> None:
        t = time.time()
        for s in m.status:
            self.last[s.name] = (t, s)

    def publish(self) -> None:
        t = time.time()
        out, worst = [], {}
        for name, (rx, s) in sorted(self.last.items()):
            grp = GROUPS.get(name.split(":")[0], "Other")
            st = DiagnosticStatus(
                level=s.level,
                name=f"/Orchard/{grp}/{name}",
                message=s.message,
                hardware_id=s.hardware_id,
                values=s.values,
            )
            if t - rx > 5.0:
                st.level, st.message = STALE, "Stale"
            out.append(st)
            lvl = 3 if st.level == STALE else int.from_bytes(st.level, "little")
            worst[grp] = max(worst.get(grp, 0), lvl)
        for grp, lvl in worst.items():
            out.append(status(bytes([lvl]), f"/Orchard/{grp}", ["OK", "Warning", "Error", "Stale"][lvl], ""))
        top = max(worst.values(), default=0)
        out.append(status(bytes([top]), "/Orchard", ["OK", "Warning", "Error", "Stale"][top], ""))
        self.pub.publish(DiagnosticArray(header=header(""), status=out))


def diagnostics(faults: Faults):
    return single_threaded(DiagnosticAggregator()), {}


# ---------------------------------------------------------------------------------------------
# operator: the crew lead's tablet (joins, leaves, comes back).


class OperatorTablet(Node):
    def __init__(self) -> None:
        super().__init__("operator_tablet", namespace=NS)
        self.t0 = time.time()
        self.frames = 0
        self.create_subscription(String, "mission_executive/state", self.on_state, LATCHED)
        self.create_subscription(String, "bin_logger/bin_fill", lambda m: None, LATCHED)
        self.create_subscription(DiagnosticArray, "/diagnostics_agg", lambda m: None, RELIABLE)
        self.create_subscription(
            CompressedImage, "left_camera/image_rect_color/compressed", self.on_frame, SENSOR
        )
        self.teleop = self.create_publisher(Twist, "cmd_vel_teleop", COMMAND)
        self.params = self.create_client(SetParameters, "harvest_coordinator/set_parameters")
        self.step = 0
        self.create_timer(0.1, self.tick)
        self.get_logger().info("Tablet connected (crew lead); live view left_camera")

    def on_state(self, m: String) -> None:
        self.state = m.data

    def on_frame(self, m) -> None:
        self.frames += 1

    def tick(self) -> None:
        e = time.time() - self.t0
        if self.step == 0 and e > 5.0:
            self.step = 1
            mm = random.choice((65, 70, 75))
            if self.params.service_is_ready():
                p = ParameterMsg(
                    name="min_fruit_diameter_mm",
                    value=ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=mm),
                )
                self.params.call_async(SetParameters.Request(parameters=[p]))
                self.get_logger().info(f"Grading set to {mm} mm")
        elif self.step == 1 and e > 20.0:
            if e < 23.0:
                tw = Twist()
                tw.linear.x = 0.15
                self.teleop.publish(tw)
            else:
                self.step = 2
                self.teleop.publish(Twist())


# ---------------------------------------------------------------------------------------------
# a crew member's `ros2 lifecycle set NODE TRANSITION`.


def lifecycle_set(target: str, transition: str) -> int:
    n = Node(f"_ros2cli_{os.getpid()}")
    cli = n.create_client(ChangeState, f"{target}/change_state")
    ids = {
        "configure": Transition.TRANSITION_CONFIGURE,
        "activate": Transition.TRANSITION_ACTIVATE,
        "deactivate": Transition.TRANSITION_DEACTIVATE,
        "cleanup": Transition.TRANSITION_CLEANUP,
    }
    if not cli.wait_for_service(timeout_sec=5.0):
        print(f"Node not found: {target}", flush=True)
        return 1
    fut = cli.call_async(ChangeState.Request(transition=Transition(id=ids[transition])))
    rclpy.spin_until_future_complete(n, fut, timeout_sec=5.0)
    ok = fut.done() and fut.result().success
    print("Transitioning successful" if ok else "Transitioning failed", flush=True)
    n.destroy_node()
    return 0 if ok else 1


PROCESSES = {
    "base_driver": base_driver,
    "gnss": gnss,
    "canopy_lidar": canopy_lidar,
    "stereo_container": stereo_container,
    "perception": perception,
    "localization": localization,
    "navigation": navigation,
    "arms": arms,
    "arm_planning": arm_planning,
    "mission": mission,
    "farm_link": farm_link,
    "bin_logger": bin_logger,
    "diagnostics": diagnostics,
    "operator": lambda faults: (single_threaded(OperatorTablet()), {}),
}


def main(argv: list[str]) -> None:
    process, fault_dir = argv[1], Path(argv[2])
    run_for = float(argv[3]) if len(argv) > 3 else 0.0
    rclpy.init()
    if process == "lifecycle_set":
        code = lifecycle_set(argv[4], argv[5])
        rclpy.try_shutdown()
        sys.exit(code)
    ex, hooks = PROCESSES[process](Faults(fault_dir))
    spin(ex, fault_dir, process, run_for, hooks)


if __name__ == "__main__":
    main(sys.argv)
