"""Run the sim robot (a rover prototyped in simulation) under the monitor: a healthy run and injected faults.

``python -m bench.sim.run [--healthy S] [--warmup S] [--post S] [--faults a,b] [--out DIR]``

The rover's processes (`bench.sim.robot`) under the in-process monitor, as every hand-written
robot runs (`bench.handwritten`: the runs, their scores, the files written). The simulator
(``/gz_sim``) publishes ``/clock`` at 50 Hz of wall time (not 100: each /clock message wakes
every sim-time rclpy process, ~0.35 ms each), its real-time factor wandering between 0.6 and 1.0
as the physics load changes every 20-60 s; every other node runs on sim time (stamps from 0,
timers in sim time, so every wall-clock rate follows the RTF), except the bag recorder (``ros2
bag record`` without ``--use-sim-time``, as usual: it records ``/clock`` like any topic). The bridge
(``/ros_gz_bridge``, root namespace) brings the sensors out: ``/scan`` 10 Hz, ``/imu`` 200 Hz,
``/odom`` and ``/joint_states`` 50 Hz, ``/camera/image_raw`` (230 KB, best effort) and its
``camera_info`` 15 Hz, odom->base_link on ``/tf``; it drives the rover from ``/cmd_vel``.
Nav2 runs in one component container (single-threaded executor) under ``/sim``: its lifecycle
manager configures then activates the controller, smoother, planner, behavior, bt_navigator and
waypoint follower servers at start (bonds on ``/sim/bond``); the waypoint follower sends the
next patrol goal on ``/goal_pose`` 6 s (sim) after the previous one ended, the navigator
replans at 1 Hz through ``/sim/compute_path`` while a goal is active and the controller commands
``/cmd_vel_nav`` at 20 Hz only then. slam_toolbox (``/map`` every 5 s, map->odom at 20 Hz), the
robot_state_publisher, twist_mux (``/cmd_vel_teleop`` over ``/cmd_vel_nav`` into ``/cmd_vel``),
a system monitor and the diagnostic aggregator run at the root. Normal noise: the planner logs
every plan, the controller warns that its control loop missed its rate when the RTF dips, the
system monitor's GPU status is a standing WARN (software rendering), foxglove_bridge subscribes
to six topics only while its client is connected (from 10 s, 40 s of every 120 s).

The launcher (`SimRobot`) does what a developer's terminals do besides: ``ros2 bag record -a``
(``/rosbag2_recorder``, subscribing to each topic it discovers) from 20 s, stopped cleanly after
180 s and restarted 60 s later; the keyboard teleop joining at 90 s (bursts of 5-20 commands at
10 Hz every 10-60 s); a ``ros2 param set`` of the controller's speed (``/_ros2cli_<pid>``, exits
0) at 40 s and every 120 s after. rviz2 (the operator process) opens at 30 s, is closed (exit 0)
100 s later and reopened 40 s after that; it sends one 2D goal pose 15 s after each opening. The
faults are injected 100 s after the start: rviz is open, the recorder records, the teleop has
joined, a patrol goal is under way or about to be.

Load: ~55-65 % of one core when healthy with the recorder off and rviz closed, ~75-90 % with
both (the recorder's ~600 messages/s and /clock's wake-ups in 11 Python processes dominate).

The faults, each with its true root cause (the target node):

- ``crash_bridge``: the bridge process is SIGKILLed: every sensor topic, the odometry and
  odom->base_link stop; the rover no longer moves; the robot_state_publisher's wheel
  transforms stop with the joint states; the clock, SLAM's map->odom and nav go on.
  Root cause /ros_gz_bridge.
- ``slow_sim``: a pathological collision mesh drops the simulator's real-time factor to 0.2:
  ``/clock`` stays at 100 Hz but sim time crawls; every sim-time rate (sensors, tf, costmaps,
  cmd_vel, diagnostics) drops to 20-35 % of its usual wall-clock rate; the controller warns
  about its loop rate. Root cause /gz_sim.
- ``hang_controller``: the controller_server's odometry callback blocks forever on a mutex a
  dead plugin thread holds; the container's single-threaded executor stops with it: the
  local and global costmaps, ``/cmd_vel_nav``, the plans, the bonds, bt_navigator and the
  waypoint follower all stop. Root cause /sim/controller_server.
- ``stall_planner``: the planner's planning thread waits on a costmap lock never released:
  ``/sim/compute_path`` stops answering (the rest of the container goes on); bt_navigator logs
  an ERROR naming the service 5 s (sim) after its request and aborts the goal; later goals fail
  the same way, the rover stops navigating. Root cause /sim/planner_server.
- ``stale_slam``: slam_toolbox's transform thread stops taking new scan stamps: map->odom goes
  on at 20 Hz with a frozen stamp. Root cause /slam_toolbox.
- ``leak_slam``: slam_toolbox's pose graph is never trimmed: its process grows 3 MB/s.
  Root cause /slam_toolbox.
- ``cpu_recorder``: a runaway compression thread in the rosbag2 recorder burns a core.
  Root cause /rosbag2_recorder.
- ``qos_twist_mux``: a config reload makes twist_mux re-create its ``/cmd_vel_nav``
  subscription as TRANSIENT_LOCAL against the controller's VOLATILE publisher: it gets nothing,
  ``/cmd_vel`` carries only teleop bursts, the rover stops following its paths (goals are
  never reached). Root cause /twist_mux.
- ``degrade_imu``: a bad SDF reload halves the simulated IMU's update rate: ``/imu`` at 100 Hz
  of sim time, nothing logged; the other sensors go on. Root cause /ros_gz_bridge.
- ``errlog_controller``: the local costmap's obstacle layer rejects every scan: the
  controller_server logs an ERROR every second while it keeps driving. Root cause
  /sim/controller_server.
- ``crash_state_publisher``: the robot_state_publisher is SIGKILLed: the wheel transforms on
  ``/tf`` stop (``/tf_static`` and ``/robot_description`` were latched by it and are gone for
  late joiners). Root cause /robot_state_publisher.
"""

from __future__ import annotations

import subprocess
import sys
import threading

from bench.handwritten import ROOT, Design, Robot, main

DESIGN = Design(
    module="bench.sim.robot",
    nodes={  # process -> its nodes (fully qualified), in the order they start
        "gz_sim": ("/gz_sim",),
        "bridge": ("/ros_gz_bridge",),
        "state_publisher": ("/robot_state_publisher",),
        "navigation": ("/sim/controller_server", "/sim/smoother_server", "/sim/planner_server",
                       "/sim/behavior_server", "/sim/bt_navigator", "/sim/waypoint_follower",
                       "/sim/lifecycle_manager_navigation"),
        "slam": ("/slam_toolbox",),
        "mux": ("/twist_mux",),
        "system_monitor": ("/system_monitor",),
        "diagnostics": ("/diagnostic_aggregator",),
        "foxglove": ("/foxglove_bridge",),
        "recorder": ("/rosbag2_recorder",),
        "teleop": ("/teleop_twist_keyboard",),
        "rviz": ("/rviz2",),
    },
    faults={
        "crash_bridge": ("kill", "/ros_gz_bridge", "bridge"),
        "slow_sim": ("file:slow", "/gz_sim", "gz_sim"),
        "hang_controller": ("file:hang", "/sim/controller_server", "navigation"),
        "stall_planner": ("file:stall", "/sim/planner_server", "navigation"),
        "stale_slam": ("file:stale", "/slam_toolbox", "slam"),
        "leak_slam": ("leak", "/slam_toolbox", "slam"),
        "cpu_recorder": ("cpu", "/rosbag2_recorder", "recorder"),
        "qos_twist_mux": ("file:qos", "/twist_mux", "mux"),
        "degrade_imu": ("file:degrade", "/ros_gz_bridge", "bridge"),
        "errlog_controller": ("file:errlog", "/sim/controller_server", "navigation"),
        "crash_state_publisher": ("kill", "/robot_state_publisher", "state_publisher"),
    },
    operator="rviz", join_s=30.0, run_s=100.0, again_s=40.0,  # open over the faults at 100 s
)
NODES, FAULTS = DESIGN.nodes, DESIGN.faults

LATE = ("recorder", "teleop")  # started by their own threads, not at bring-up
RECORD_AT, RECORD_S, RECORD_AGAIN = 20.0, 180.0, 60.0
TELEOP_AT = 90.0
PARAM_AT, PARAM_EVERY = 40.0, 120.0


class SimRobot(Robot):
    """The simulation's launch plus a developer's terminals: the bag recorder (started late,
    stopped and restarted), the keyboard teleop (joins late) and ``ros2 param set`` now and then.
    The ``ros2 param`` processes are not the robot's (not in `Design.nodes`): kept apart in
    ``transient`` and ended with the robot."""

    def start(self) -> None:
        for process in self.design.nodes:
            if process != self.design.operator and process not in LATE:
                self.spawn(process)
        for job in (self._operator, self._recorder, self._teleop, self._param_set):
            threading.Thread(target=job, daemon=True).start()

    def _recorder(self) -> None:
        wait = RECORD_AT
        while not self.stop.wait(wait):
            p = self.spawn("recorder", RECORD_S)
            while p.poll() is None and not self.stop.wait(0.5):
                pass
            wait = RECORD_AGAIN

    def _teleop(self) -> None:
        if not self.stop.wait(TELEOP_AT):
            self.spawn("teleop")

    def _param_set(self) -> None:
        wait = PARAM_AT
        while not self.stop.wait(wait):
            log = open(self.logs / "param_set.log", "a")
            cmd = [sys.executable, "-m", self.design.module, "param_set", str(self.fault_dir)]
            self.transient.append(subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT,
                                                   start_new_session=True, cwd=ROOT))
            wait = PARAM_EVERY



if __name__ == "__main__":
    sys.exit(main(None, __doc__, "sim", SimRobot, DESIGN, 100.0,
                  "s from the start to the injection (100: rviz open, the recorder on, the teleop joined)"))
