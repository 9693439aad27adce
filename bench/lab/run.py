"""Run the lab's mobile manipulator under the monitor: a healthy run and injected faults.

``python -m bench.lab.run [--healthy S] [--warmup S] [--post S] [--faults a,b] [--out DIR]``

The lab robot's processes (`bench.lab.robot`) under the in-process monitor, as every
hand-written robot runs (`bench.handwritten`: the runs, their scores, the files written). The
operator console joins 15 s after the start, exits cleanly (code 0) 50 s later and its launcher
starts it again 15 s after that.

The faults, each with its true root cause (the target node):

- ``crash_slam``: the SLAM mapper's process is SIGKILLed (an out-of-memory kill, as its map
  grows); /lab/map stops, the coverage planner goes on planning over its last map.
  Root cause /lab/slam_mapper.
- ``hang_depth_camera``: the depth camera's driver blocks forever in a device read; it shares the
  perception container's single thread, so the colour camera and the detector stop too and the
  lifecycle manager loses its heartbeat. Root cause /lab/depth_camera.
- ``leak_coverage``: the coverage planner leaks 2 MB/s (a cache of wavefronts never cleared).
  Root cause /lab/coverage_planner.
- ``degrade_imu``: the IMU's USB link loses 3 frames in 10: /lab/imu at 70 % of its 200 Hz, no
  log. Root cause /lab/imu_driver.
- ``stall_grasp_service``: the grasp planner's inference requests never return: /lab/plan_grasp
  stops answering (the call in flight too); the task manager times out after 12 s and logs an
  ERROR naming the service. Root cause /lab/grasp_planner.
- ``block_left_arm``: the left arm controller's hardware read blocks forever: its hardware
  group (/arm/left/joint_states, joint commands) stops, its diagnostics group goes on reporting
  OK, and the right arm controller beside it in the multi-threaded process goes on.
  Root cause /arm/left/controller.
- ``stop_log_player``: the log player's reader dies: /lab/mocap/pose stops for good (not the
  2 s pause between loops), nothing logged. Root cause /lab/log_player.
- ``errlog_lidar``: the lidar driver logs an ERROR every second (packet checksum mismatch) while
  its scans go on. Root cause /lab/lidar_driver.
- ``cpu_arms``: a thread of the right arm controller (a trajectory smoother stuck in a loop)
  burns a core in the two-controller multi-threaded process. Root cause /arm/right/controller.
- ``crash_lidar``: the lidar driver's process is SIGKILLed: /lab/scan stops, the mapper stops
  adding keyframes. Root cause /lab/lidar_driver.
"""

from __future__ import annotations

import sys

from bench.handwritten import Design, NamespacedRobot, main

DESIGN = Design(
    module="bench.lab.robot",
    nodes={  # process -> its nodes (fully qualified), in the order they start
        "base": ("/lab/imu_driver", "/lab/base_controller"),
        "lidar": ("/lab/lidar_driver",),
        "perception": ("/lab/depth_camera", "/lab/rgb_camera", "/lab/object_detector"),
        "slam": ("/lab/slam_mapper",),
        "coverage": ("/lab/coverage_planner",),
        "arms": ("/arm/left/controller", "/arm/right/controller"),
        "grasping": ("/lab/grasp_planner",),
        "executive": ("/lab/lifecycle_manager", "/lab/task_manager", "/lab/navigator"),
        "tools": ("/lab/log_player", "/lab/disk_monitor"),
        "teleop": ("/lab/joystick",),
        "console": ("/lab/console",),
    },
    faults={
        "crash_slam": ("kill", "/lab/slam_mapper", "slam"),
        "hang_depth_camera": ("file:hang", "/lab/depth_camera", "perception"),
        "leak_coverage": ("leak", "/lab/coverage_planner", "coverage"),
        "degrade_imu": ("file:degrade", "/lab/imu_driver", "base"),
        "stall_grasp_service": ("file:stall", "/lab/grasp_planner", "grasping"),
        "block_left_arm": ("file:block_state", "/arm/left/controller", "arms"),
        "stop_log_player": ("file:stop", "/lab/log_player", "tools"),
        "errlog_lidar": ("file:errlog", "/lab/lidar_driver", "lidar"),
        "cpu_arms": ("cpu", "/arm/right/controller", "arms"),
        "crash_lidar": ("kill", "/lab/lidar_driver", "lidar"),
    },
    operator="console", join_s=15.0, run_s=50.0, again_s=15.0,  # joins before a fault at 40 s
)
NODES, FAULTS = DESIGN.nodes, DESIGN.faults


if __name__ == "__main__":
    sys.exit(main(None, __doc__, "lab", NamespacedRobot, DESIGN, 40.0,
                  "s from the start to the injection (40: the console joined, the first grasp planned)"))
