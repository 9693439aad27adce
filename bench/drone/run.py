"""Run the drone robot (a quadrotor's companion computer) under the monitor: healthy run, injected faults.

``python -m bench.drone.run [--healthy S] [--warmup S] [--post S] [--faults a,b] [--out DIR]``

The quadrotor's processes (`bench.drone.robot`) under the in-process monitor, as every
hand-written robot runs (`bench.handwritten`: the runs, their scores, the files written). All
nodes are on wall time.

The stack. The flight-controller bridge (``/fmu/fc_bridge``, PX4 over micro XRCE-DDS) publishes
the FCU's IMU on ``/fmu/out/imu`` at 200 Hz and its odometry on ``/fmu/out/odometry`` at 100 Hz,
best effort, from its serial reader thread; ``/fmu/status`` at 1 Hz and on every change,
``/fmu/battery`` at 1 Hz; it takes ``/fmu/in/vehicle_command`` (ARM, OFFBOARD, LAND) and
``/fmu/in/trajectory_setpoint`` and simulates the vehicle (it follows the setpoints in OFFBOARD,
lands in AUTO_LAND and disarms, falls back to Hold when the setpoint stream stops 0.5 s). The
camera driver (``/camera/camera_driver``) publishes ``/camera/image_raw`` (320x240 mono8, 77 KB)
and ``/camera/camera_info`` at 30 Hz, best effort, from its capture thread. The rangefinder
(``/rangefinder/tfmini``) publishes ``/rangefinder/range`` at 30 Hz best effort stamped by the
device's own free-running clock, a constant 0.3 s behind the computer's (healthy; the height
synchronizer corrects it by a parameter). The VIO (``/vio/estimator``, its own process on a
multi-threaded executor): the image callback in a reentrant callback group (10-20 ms of CPU a
frame of wall time, mostly 10-13; the tracker is one lock, a frame that finds it busy is dropped:
under load ~20-30 % of the frames are, a WARN only when >= 80 % are), the IMU
pre-integration in a mutually exclusive group, its housekeeping (diagnostics, heartbeat) in a
third; ``/vio/odometry`` at 30 Hz stamped with the frame's stamp. The perception container (one
process, one single-threaded executor): ``/perception/obstacle_detector`` (every frame examined,
``/perception/obstacles`` at 10 Hz), ``/perception/height_sync`` (pairs each VIO odometry with the
rangefinder sample whose corrected stamp is within 20 ms: ``/perception/height_odometry`` ~30 Hz;
a WARN every 10 s after 5 s without a pair) and ``/perception/precision_landing``, a lifecycle node
configured at bring-up and activated only for a mission's last 20 s (it then subscribes to the
camera and the height odometry and publishes ``/perception/landing_target`` at 15 Hz). The mapper
(``/mapping/mapper``) takes VIO keyframes and the obstacle distances, runs a loop-closure
optimisation every 25-35 s that holds its only thread 1-2 s (a healthy CPU spike, and its
heartbeat then sometimes comes > 1 s late), and publishes ``/mapping/map`` latched (transient
local) only when the map changed (in flight; not on the ground). The flight process (a
multi-threaded executor): ``/mission/mission_manager`` serves ``/mission/execute`` (a survey:
ARM, OFFBOARD, four waypoints on ``/mission/waypoint``, the final 20 s approach with precision
landing active, LAND; feedback at 5 Hz only while a mission runs) and ``/control/offboard_controller``
streams ``/fmu/in/trajectory_setpoint`` at 20 Hz from its own thread, always. The safety process
(single-threaded): ``/safety/geofence`` (the VIO odometry: GPS-denied flight;
``/safety/geofence_status`` at 2 Hz),
``/safety/heartbeat_watchdog`` (``/heartbeat`` from the FCU bridge, camera, VIO, mapper, mission
manager, offboard controller and downlink at 1 Hz each; ``/safety/watchdog`` at 2 Hz; a WARN when
one is > 1 s late, an ERROR when silent 5 s), ``/safety/battery_monitor``. The telemetry downlink
(``/telemetry/downlink``) publishes ``/telemetry/summary`` at 10 Hz, throttled to 1 Hz for 10-20 s
episodes of low link quality (first after 30-90 s, then 40-120 s apart; a WARN at each start).
``/system/system_monitor`` and ``/system/diagnostic_aggregator`` (``/diagnostics`` with
diagnostic_updater names ``node: task`` from seven nodes -> ``/diagnostics_agg`` 1 Hz).

The ground station (``/ground_station/gcs``, the operator process) joins at 20 s, sends a mission
5 s after it connects (40-50 s long) and every 60-75 s after that, and is closed (exit 0) after
140 s, reopened 30 s later. So a mission runs from ~25 s to ~70 s and another from 85-100 s to
~130-150 s: at the injection (100 s) the ground station is connected and a mission is flying.

Load: ~145 % of one core when healthy (of the machine's two), measured with psutil over 60 s:
the VIO ~80 % (its multi-threaded executor dispatching 230 callbacks/s: rclpy's dispatch loop
re-yields a task until a worker thread takes the GIL; the image work itself ~35 %), perception
~15-18 %, the FCU bridge ~14 %, the mapper ~7 % (loop closure included), the rest 2-7 % each.
Above the ~70 % aimed at: each rclpy callback costs ~1 ms of CPU here, and the 200 Hz IMU into
a multi-threaded executor plus 30 frames/s of 10-20 ms cannot fit in it.

The faults, each with its true root cause (the target node):

- ``hang_vio``: the VIO back end's solver deadlocks inside the tracker lock: one image callback
  blocks for good; later frames find the tracker busy and are dropped (a WARN every 5 s); the IMU
  and housekeeping groups go on (heartbeat, diagnostics: tracking WARN). ``/vio/odometry`` stops,
  so does ``/perception/height_odometry`` (height_sync WARNs), the mapper gets no keyframes.
  Root cause /vio/estimator.
- ``hang_obstacle_detector``: the detector's inference call never returns; the perception
  container's single-threaded executor stops with it: ``/perception/obstacles``,
  ``/perception/height_odometry`` (and the landing target if active) stop; the offboard
  controller warns that collision prevention is inactive. Root cause /perception/obstacle_detector.
- ``crash_camera``: the camera driver process is SIGKILLed: the image and camera_info stop, the
  VIO odometry, obstacles, height odometry stop; the watchdog warns then errors on the camera's
  heartbeat. Root cause /camera/camera_driver.
- ``degrade_imu``: the FCU's serial link saturates: ``/fmu/out/imu`` drops to 120 Hz (60 %), the
  odometry stays at 100 Hz, nothing logged. Root cause /fmu/fc_bridge.
- ``slow_mission``: the mission manager's trajectory generation stalls on a terrain query: the
  running mission's feedback stops, it aborts after 10 s (an ERROR; LAND sent); new goals are
  answered 4 s late and abort the same way; the ground station logs the abort. Root cause
  /mission/mission_manager.
- ``skew_rangefinder``: a brown-out resets the rangefinder's clock: its stamps jump 2 s further
  behind (2.3 s in all). Its rate is unchanged; height_sync finds no pair within 20 ms:
  ``/perception/height_odometry`` stops and height_sync WARNs. Root cause /rangefinder/tfmini.
- ``qos_height_sync``: a config reload makes height_sync re-create its rangefinder subscription as
  RELIABLE against the best-effort publisher: it receives nothing, ``/perception/height_odometry``
  stops, it WARNs. Root cause /perception/height_sync.
- ``leak_mapper``: the mapper's keyframe cache is never trimmed: its process grows 3 MB/s.
  Root cause /mapping/mapper.
- ``cpu_telemetry``: a runaway log-compression thread in the telemetry process burns a core.
  Root cause /telemetry/downlink.
- ``errlog_geofence``: the fence file fails its checksum: the geofence logs an ERROR every
  second and goes on with its cached fence (its status unchanged). Root cause /safety/geofence.
- ``die_offboard``: the offboard controller's setpoint thread dies on an exception (a traceback
  on stderr, no ROS log; its heartbeat timer and subscriptions go on): ``/fmu/in/trajectory_setpoint``
  stops; PX4 (the bridge) WARNs "offboard control signal lost" and holds; the mission manager
  aborts the mission with an ERROR and sends LAND; the ground station logs the abort; later
  missions are refused OFFBOARD by the FCU (a WARN) and aborted. Root cause
  /control/offboard_controller.
"""

from __future__ import annotations

import sys

from bench.handwritten import Design, NamespacedRobot, main

DESIGN = Design(
    module="bench.drone.robot",
    nodes={  # process -> its nodes (fully qualified), in the order they start
        "fmu": ("/fmu/fc_bridge",),
        "camera": ("/camera/camera_driver",),
        "rangefinder": ("/rangefinder/tfmini",),
        "vio": ("/vio/estimator",),
        "perception": ("/perception/obstacle_detector", "/perception/height_sync",
                       "/perception/precision_landing"),
        "mapping": ("/mapping/mapper",),
        "flight": ("/mission/mission_manager", "/control/offboard_controller"),
        "safety": ("/safety/geofence", "/safety/heartbeat_watchdog", "/safety/battery_monitor"),
        "telemetry": ("/telemetry/downlink",),
        "system": ("/system/system_monitor", "/system/diagnostic_aggregator"),
        "ground_station": ("/ground_station/gcs",),
    },
    faults={
        "hang_vio": ("file:hang", "/vio/estimator", "vio"),
        "hang_obstacle_detector": ("file:hang", "/perception/obstacle_detector", "perception"),
        "crash_camera": ("kill", "/camera/camera_driver", "camera"),
        "degrade_imu": ("file:degrade", "/fmu/fc_bridge", "fmu"),
        "slow_mission": ("file:slow", "/mission/mission_manager", "flight"),
        "skew_rangefinder": ("file:skew", "/rangefinder/tfmini", "rangefinder"),
        "qos_height_sync": ("file:reliable", "/perception/height_sync", "perception"),
        "leak_mapper": ("leak", "/mapping/mapper", "mapping"),
        "cpu_telemetry": ("cpu", "/telemetry/downlink", "telemetry"),
        "errlog_geofence": ("file:errlog", "/safety/geofence", "safety"),
        "die_offboard": ("file:die", "/control/offboard_controller", "flight"),
    },
    operator="ground_station", join_s=20.0, run_s=140.0, again_s=30.0,  # connected over the faults
)
NODES, FAULTS = DESIGN.nodes, DESIGN.faults


if __name__ == "__main__":
    sys.exit(main(None, __doc__, "drone", NamespacedRobot, DESIGN, 100.0,
                  "s from the start to the injection (100: the ground station connected, a mission flying)"))
