"""Run the field robot (a tractor spraying a field) under the monitor: a healthy run and injected faults.

``python -m bench.field.run [--healthy S] [--warmup S] [--post S] [--faults a,b] [--out DIR]``

The tractor's processes (`bench.field.robot`) under the in-process monitor, as every
hand-written robot runs (`bench.handwritten`: the runs, their scores, the files written). Its
launcher (`FieldRobot`) does what a field engineer's launch and terminal do besides: the four
controller spawners at bring-up (the joint state broadcaster's at 1.5 s, the three others when
it has exited; each exits with code 0 within ~10 s), a developer's ``ros2 topic echo|hz`` every
60 s from 30 s on (``/_ros2cli_<pid>``, 10 s each, exit 0) and, once, at 120 s, a Ctrl-C of the
robot_state_publisher (after an URDF edit) relaunched 5 s later. The operator console joins
15 s after the start, exits cleanly (code 0) 50 s later and its launcher starts it again 15 s
after that. The faults are injected 50 s after the start: the console is open, the controllers
are active, the second row (started at 45-49 s, 8-20 s long) is under way.

The faults, each with its true root cause (the target node):

- ``crash_control``: the controller manager's process is SIGKILLed (a segfault in a hardware
  plugin): the joint states, the drive's odometry and odom->base_link, the boom and hitch
  states stop; the robot_state_publisher's transforms stop with the joint states, the EKF goes
  on from the IMU alone. Root cause /field/controller_manager.
- ``hang_imu``: the IMU driver's serial read blocks forever; the GNSS driver shares its
  single-threaded executor and stops too; the EKF goes on from the wheel odometry.
  Root cause /field/imu_driver.
- ``degrade_boom``: the boom ECU's CAN frames overrun and the boom controller skips every other
  update: ``/field/boom_controller/controller_state`` at 25 of its 50 Hz, no log; the other
  controllers of the manager go on. Root cause /field/boom_controller.
- ``lag_twist_mux``: the twist mux's output stalls behind a blocking write: every command to
  the drive controller 300 ms late (its stamp kept), the rate unchanged.
  Root cause /field/twist_mux.
- ``stall_prescription``: the farm bridge's prescription requests never complete:
  ``/field/farm_bridge/get_prescription`` stops answering; the sprayer controller logs an ERROR
  naming the service 5 s after each call (every 15 s). Root cause /field/farm_bridge.
- ``stuck_navigator``: the row navigator waits for an end-of-row mark it never sees: the
  ``navigate_row`` goal under way stops its feedback (at once, or 3 s into the next goal) and
  never finishes; the tractor keeps driving; the mission planner cancels the goal 60 s after
  sending it, with an ERROR. Root cause /field/row_navigator.
- ``leak_ekf``: the EKF's measurement history is never trimmed: 3 MB/s.
  Root cause /field/ekf_filter.
- ``cpu_weed_detector``: a runaway post-processing thread of the weed detector burns a core in
  the perception container (four nodes, multi-threaded). Root cause /field/weed_detector.
- ``errlog_gnss``: the GNSS driver logs an ERROR every second (RTCM3 CRC mismatch) while its
  fixes go on at 10 Hz. Root cause /field/gnss_driver.
- ``qos_row_detector``: a configuration change makes the row detector re-create its
  ``/field/lidar/points`` subscription as RELIABLE on the lidar's BEST_EFFORT publisher: it
  receives nothing, ``/field/row_detector/rows`` stops, the navigator steers on its last rows.
  Root cause /field/row_detector.
- ``stale_camera``: the camera driver's frame queue backs up: its images (and so the weed
  detections and the compressed stream, which keep the image's header) are stamped 1 s old,
  the rate unchanged. Root cause /field/camera_driver.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading

from bench.handwritten import ROOT, Design, NamespacedRobot, main

DESIGN = Design(
    module="bench.field.robot",
    nodes={  # process -> its nodes (fully qualified), in the order they start
        "control": ("/field/controller_manager", "/field/joint_state_broadcaster", "/field/drive_controller",
                    "/field/boom_controller", "/field/hitch_controller"),
        "state_publisher": ("/field/robot_state_publisher",),
        "sensors": ("/field/imu_driver", "/field/gnss_driver"),
        "lidar": ("/field/lidar_driver",),
        "perception": ("/field/camera_driver", "/field/image_republisher", "/field/weed_detector",
                       "/field/row_detector"),
        "localization": ("/field/ekf_filter",),
        "navigation": ("/field/row_navigator", "/field/twist_mux"),
        "mission": ("/field/mission_planner", "/field/farm_bridge"),
        "implement": ("/field/sprayer_controller",),
        "supervisor": ("/field/system_monitor",),
        "uplink": ("/field/telemetry_uplink",),
        "console": ("/field/operator_console",),
    },
    faults={
        "crash_control": ("kill", "/field/controller_manager", "control"),
        "hang_imu": ("file:hang", "/field/imu_driver", "sensors"),
        "degrade_boom": ("file:degrade", "/field/boom_controller", "control"),
        "lag_twist_mux": ("file:lag", "/field/twist_mux", "navigation"),
        "stall_prescription": ("file:stall", "/field/farm_bridge", "mission"),
        "stuck_navigator": ("file:stuck", "/field/row_navigator", "navigation"),
        "leak_ekf": ("leak", "/field/ekf_filter", "localization"),
        "cpu_weed_detector": ("cpu", "/field/weed_detector", "perception"),
        "errlog_gnss": ("file:errlog", "/field/gnss_driver", "sensors"),
        "qos_row_detector": ("file:reliable", "/field/row_detector", "perception"),
        "stale_camera": ("file:stale", "/field/camera_driver", "perception"),
    },
    operator="console", join_s=15.0, run_s=50.0, again_s=15.0,  # joins before the faults at 50 s
)
NODES, FAULTS = DESIGN.nodes, DESIGN.faults

SPAWNERS = ("drive_controller", "boom_controller", "hitch_controller")  # after joint_state_broadcaster
CLI = ("echo:/field/gnss/fix", "hz:/field/imu/data_raw", "echo:/diagnostics", "hz:/field/lidar/points",
       "hz:/field/joint_states")
RESTARTED = "state_publisher"  # Ctrl-C'd by the developer at RESTART_S, relaunched 5 s later
RESTART_S = 120.0


class FieldRobot(NamespacedRobot):
    """The tractor's launch, its spawners, a developer's CLI tools and the developer's manual
    restart of the robot_state_publisher. The short-lived processes are not the robot's (not in
    `Design.nodes`): they are kept apart in ``transient`` and ended with the robot."""

    def start(self) -> None:
        super().start()
        for job in (self._spawners, self._developer_cli, self._manual_restart):
            threading.Thread(target=job, daemon=True).start()

    def _transient(self, process: str) -> subprocess.Popen:
        log = open(self.logs / f"{process.replace(':', '_').replace('/', '_')}.log", "a")
        cmd = [sys.executable, "-m", self.design.module, process, str(self.fault_dir)]
        p = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, start_new_session=True, cwd=ROOT)
        self.transient.append(p)
        return p

    def _spawners(self) -> None:
        if self.stop.wait(1.5):
            return
        first = self._transient("spawner:joint_state_broadcaster")
        while first.poll() is None and not self.stop.wait(0.2):
            pass
        if not self.stop.is_set():
            for c in SPAWNERS:
                self._transient(f"spawner:{c}")

    def _developer_cli(self) -> None:
        i = 0
        wait = 30.0
        while not self.stop.wait(wait):
            self._transient(f"cli:{CLI[i % len(CLI)]}")
            i += 1
            wait = 60.0

    def _manual_restart(self) -> None:
        if self.stop.wait(RESTART_S):
            return
        p = self.procs[RESTARTED]
        if p.poll() is None:
            os.killpg(p.pid, signal.SIGINT)  # Ctrl-C in its terminal
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                return
        if not self.stop.wait(5.0):
            self.spawn(RESTARTED)



if __name__ == "__main__":
    sys.exit(main(None, __doc__, "field", FieldRobot, DESIGN, 50.0,
                  "s from the start to the injection (50: the console open, the second row under way)"))
