"""Run the shuttle robot (an Autoware-style campus shuttle) under the monitor: healthy run, injected faults.

``python -m bench.shuttle.run [--healthy S] [--warmup S] [--post S] [--faults a,b] [--out DIR]``

The shuttle's processes (`bench.shuttle.robot`) under the in-process monitor, as every hand-written
robot runs (`bench.handwritten`: the runs, their scores, the files written). All nodes are on wall
time, every process runs one single-threaded executor: rclpy's C++ EventsExecutor
(``rclpy.experimental``, adopted by the team for CPU; it has no guard conditions and no coroutine
callbacks, so service answers are polled from timers and each process applies a changed fault word
from a 1 Hz timer). QoS: "sensor" is best effort keep-last 5, "reliable" keep-last 10 (1 where only
the newest matters), "latched" reliable transient-local depth 1.

The world: a 620 m loop road (a 220 x 100 m rounded rectangle) with three stations (Depot 0 m,
Library 230 m, Clinic 420 m) and three signalised intersections (120, 360, 560 m; 45 s signal
cycles: green 28 s, amber 3 s, red 14 s).

The stack. Sensing: the lidar driver (``/sensing/lidar/top/lidar_driver``, process ``lidar``)
publishes ``/sensing/lidar/top/pointcloud_raw`` (PointCloud2, ~1900 points, 30 KB) at 10 Hz, sensor
QoS, from its packet thread, and drops a scan with a lost packet now and then (~0.6 %, silently).
The pointcloud preprocessor container (process ``pointcloud_container``, three nodes on ONE
single-threaded executor): ``/sensing/lidar/top/crop_box_filter`` (raw ->
``/sensing/lidar/top/pointcloud``), ``/sensing/lidar/top/ground_filter`` (->
``/sensing/lidar/top/no_ground/pointcloud``) and ``/sensing/lidar/top/voxel_grid_downsample_filter``
(the cropped cloud -> ``/sensing/lidar/top/downsampled/pointcloud``), all 10 Hz sensor QoS with the
scan's stamp. The camera (``/sensing/camera/camera0/camera_driver``, process ``camera``):
``image_raw`` (160x120 rgb8, 58 KB) and ``camera_info`` at 15 Hz, sensor QoS, from its capture
thread. The IMU (``/sensing/imu/imu_driver``, process ``imu``): ``/sensing/imu/imu_data`` 50 Hz
sensor QoS from its serial thread. The GNSS (process ``gnss``): ``/sensing/gnss/gnss_driver``
publishes ``/sensing/gnss/nav_sat_fix`` at 5 Hz sensor QoS (it loses its RTK fix every 40-90 s for
3-8 s: a WARN, then "RTK fix restored"); ``/sensing/gnss/gnss_poser`` ->
``/sensing/gnss/pose_with_covariance`` 5 Hz reliable. The vehicle (``/vehicle/vehicle_interface``,
process ``vehicle``, the CAN bridge and the simulated vehicle): ``/vehicle/status/velocity_status``
(TwistWithCovarianceStamped) at 50 Hz reliable from its CAN thread, ``/vehicle/status/control_mode``
and ``/vehicle/status/battery`` 1 Hz; it takes ``/control/command/control_cmd`` (best effort, depth
1) and brakes (an ERROR) when no command came for 1.0 s.

Localization: ``/localization/pose_estimator/ndt_scan_matcher`` (process ``ndt``) matches each
downsampled scan (5-15 ms of numpy) with the EKF's biased pose as its initial guess (a scan whose
newest guess is > 1 s older is skipped with a WARN) ->
``/localization/pose_estimator/pose_with_covariance`` 10 Hz reliable, stamped with the scan's stamp;
it is enabled by its ``ndt_align_srv`` (Trigger); its dynamic map update holds its thread 0.4-0.7 s
every 25-35 s (a healthy CPU spike, its output then comes late in a burst). Process
``localization``: ``/localization/pose_twist_fusion_filter/ekf_localizer`` (its prediction runs on
each 50 Hz velocity report; inputs the velocity report, the IMU, the NDT pose, ``/initialpose3d``)
publishes ``/localization/kinematic_state`` (Odometry, 50 Hz, reliable depth 1) and
``/localization/pose_twist_fusion_filter/biased_pose_with_covariance`` (10 Hz), both stamped with
the velocity report's stamp they were predicted from; it rejects an NDT pose older than 1 s (a
WARN). ``/localization/util/pose_initializer`` serves ``/localization/initialize`` (Trigger: the
request is accepted at once; then the GNSS pose, an ``ndt_align_srv`` call polled at 10 Hz,
``/initialpose3d``) and latches ``/localization/initialization_state``.

Perception: ``/perception/object_recognition/detection/tensorrt_yolox`` (process ``detector``)
infers every camera frame and publishes ``/perception/object_recognition/detection/rois0``
(PoseArray, reliable) only when something is in view: bursts of 2-6 s at ~13 Hz, then 3-15 s of
nothing. Process ``perception``:
``/perception/object_recognition/detection/clustering/euclidean_cluster`` (no-ground cloud ->
``.../clustering/clusters`` 10 Hz) and
``/perception/object_recognition/tracking/multi_object_tracker`` (an approximate-time synchronizer
of the clusters and the ROIs, slop 50 ms, a cluster set alone once the next set came ->
``/perception/object_recognition/objects`` 10 Hz with the clusters' stamp). Process
``traffic_light``: ``/perception/traffic_light_recognition/traffic_light_classifier``, a lifecycle
node configured at bring-up by the behavior planner and activated only within 70 m of an
intersection (then it subscribes the camera, the route and the biased pose and publishes
``/perception/traffic_light_recognition/traffic_signals`` at 7.5 Hz; deactivated past it: ~15-20 s
active per intersection, nothing the rest of the time).

Planning: ``/planning/mission_planning/mission_planner`` (process ``mission_planning``) serves
``/planning/mission_planning/set_route_points`` and ``/planning/mission_planning/plan_route``
(nav_msgs/GetPlan), publishes ``/planning/mission_planning/route`` (Path, latched) once per route
and ``/planning/mission_planning/state`` (UNSET/SET/ARRIVED, latched); it decides the arrival from
the biased pose. Process ``planning`` (one container):
``.../lane_driving/behavior_planning/behavior_path_planner`` (ego pose and speed from the 10 Hz
biased pose; 10 Hz while a route is set: ``.../behavior_planning/path``, 80 m, speed limits per
point, a stop at the goal and at a red/amber/unknown signal's stop line; it drives the classifier's
lifecycle; nothing published while no route is set or once arrived),
``/planning/scenario_planning/motion_velocity_smoother`` (``max_velocity`` a runtime parameter,
curvature and deceleration limits -> ``.../motion_velocity_smoother/trajectory``),
``/planning/planning_validator`` (-> ``/planning/scenario_planning/trajectory``, the previous one on
an invalid input).

Control (process ``control``): ``/control/trajectory_follower/controller_node_exe`` (30 Hz timer,
pure pursuit and a smooth stop before the first zero-speed point; zero commands when the trajectory
is > 1 s old) -> ``/control/trajectory_follower/control_cmd``; ``/control/vehicle_cmd_gate`` (the
remote operator's ``/external/selected/control_cmd`` while fresh, else the follower's in AUTONOMOUS,
each passed on as it comes: 30 Hz; else its own 10 Hz stop, or a comfortable-stop ramp during an
MRM) -> ``/control/command/control_cmd`` (best effort depth 1) and ``/control/current_gate_mode``
(latched, on change).

System (process ``system``): ``/system/topic_state_monitor`` (the cropped cloud, the NDT pose, the
objects, the trajectory only while a route is set; timeouts 1-2 s; statuses
``topic_state_monitor_<topic>: <component>_topic_status`` on ``/diagnostics`` 1 Hz),
``/system/component_state_monitor`` (``/diagnostics_agg`` ->
``/system/component_state_monitor/component/autonomous/<c>`` Bool 1 Hz for sensing, localization,
perception, planning), ``/system/emergency_handler`` (MRM: in AUTONOMOUS a component not ready
starts a comfortable stop, an ERROR; ``/system/fail_safe/mrm_state`` 5 Hz),
``/system/diagnostic_aggregator`` (``/diagnostics`` from eleven nodes with ``node: task`` names and
hardware ids -> ``/diagnostics_agg`` and ``/diagnostics_toplevel_state`` 1 Hz) and
``/system/system_monitor``. The recorder (``/rosbag2_recorder``, process ``recorder``, like ``ros2
bag record``): serialized subscriptions to 13 topics (route, states, trajectory, signals, MRM, gate
mode, ETA, vehicle status, battery, diagnostics_agg, /rosout ...) made as their publishers appear, a
split every 60 s. The AD API (process ``ad_api``): ``/default_ad_api/node/localization`` calls
``/localization/initialize`` once at startup; ``/default_ad_api/node/routing`` runs the timetable
(Depot -> Library -> Clinic -> Depot ...): the first route 3 s after initialization, then at each
arrival a 10-20 s dwell and the next route; while a route is set, ``plan_route`` every 10 s for the
ETA (``/api/routing/eta``); calls time out after 3 s (an ERROR); ``/api/routing/state`` and
``/api/operation_mode/state`` (AUTONOMOUS from the first route on) latched.

Healthy dynamics: the startup (initialization ~2-5 s, the first route ~6-9 s); legs of 190-230 m at
up to 4-5 m/s (3.8 m/s in the bends): 45-60 s of driving, up to 14 s more at a red light; stops at
stations for 10-20 s (the behavior planner, smoother and validator publish nothing then, the
follower commands zero, the traffic-light classifier is inactive away from intersections, the
trajectory's topic monitor is off); a new route latched every ~60-90 s; the traffic-light classifier
activated/deactivated around each intersection (its topic appears and stops); the GNSS WARNs on RTK
float episodes; the NDT's dynamic map update every ~30 s; a lidar scan dropped now and then; the
recorder's subscriptions appearing as their publishers do, its splits; now and then (a map update or
a process starting while the ECU is busy) an NDT pose comes > 1 s late and the EKF WARNs it ignored
it, or the NDT WARNs a skipped scan. The operator console (``/remote/operator_console``, process
``operator``) joins at 15 s, exits with code 0 after 65 s and is restarted 10 s later (so from ~90 s
to ~155 s, across the faults, and again at ~165 s): 6 s after each start it sets the smoother's
``max_velocity`` (4.0, 4.2 or 5.0 m/s) through
``/planning/scenario_planning/motion_velocity_smoother/set_parameters`` (the smoother logs the
change); at each station arrival while it is connected it takes remote control for 5 s
(``/external/selected/control_cmd`` 10 Hz zero commands; the gate logs AUTO -> REMOTE -> AUTO).

Load: ~55-60 % of one core when healthy (of the machine's two; 54 % and 60 % measured with psutil
over 60 s, from 38 s to 98 s of two healthy runs: NDT 8-11 % (its map updates included), control ~9
%, localization 7-9 %, planning 6-7 %, the pointcloud container ~4.5 %, the vehicle ~4 %, the rest
0.5-3 % each; the monitor itself ~7 % besides). With rclpy's SingleThreadedExecutor in every process
the same stack took 108-120 %: rclpy's Python dispatch costs ~1.3 ms a callback here, and the 50 Hz
IMU, velocity report and kinematic state, the 30 Hz control loop and the 10 Hz lidar pipeline are
~450 callbacks a second.

The faults (injected 100 s after the start: the console connected, the shuttle on its second leg or
dwelling at the Library), each with its true root cause (the target node):

- ``crash_lidar``: the lidar driver's process is SIGKILLed: ``pointcloud_raw`` stops and with it the
  container's three outputs, the NDT pose (the EKF WARNs "pose not updated", dead reckoning), the
  clusters and the objects (the behavior planner WARNs "no objects"); the topic state monitor ERRORs
  (sensing, localization, perception), the emergency handler starts an MRM (ERROR) and the gate
  brakes the shuttle to a stop; the lidar's diagnostics go stale. Root cause
  /sensing/lidar/top/lidar_driver.
- ``hang_ground_filter``: the ground filter's callback never returns; the container's single
  executor stops with it, so the crop box and downsample filters (its siblings) stop too: the same
  downstream effects as a lidar crash, but the lidar driver goes on publishing. Root cause
  /sensing/lidar/top/ground_filter.
- ``degrade_imu``: the IMU's UART overruns: ``/sensing/imu/imu_data`` drops to 20 Hz (40 %); nothing
  logged, the EKF's ``imu_hz`` diagnostic value falls. Root cause /sensing/imu/imu_driver.
- ``slow_ndt``: the NDT waits ~250 ms per scan for the map loader's lock and iterates 50 ms longer:
  its pose comes at ~3 Hz and ~0.5-1 s late (its scan queue of 5 fills); its diagnostics WARN
  (processing time), the EKF WARNs about (and rejects) poses older than 1 s. Root cause
  /localization/pose_estimator/ndt_scan_matcher.
- ``stale_ekf``: the EKF's output index into its state buffer goes wrong: kinematic_state and the
  biased pose are stamped 1.5 s in the past, rates unchanged; the NDT then skips every scan
  ("initial pose ... older than the scan", WARNs every 2 s): its pose stops, the EKF WARNs the pose
  is not updated, the topic state monitor ERRORs on localization and the emergency handler stops the
  shuttle (MRM). Root cause /localization/pose_twist_fusion_filter/ekf_localizer.
- ``slow_route``: the mission planner's routing graph cache is invalidated: every route call takes 5
  s (its single thread blocked, so its arrival check and pose subscription stall too); the AD API's
  ETA calls and any departure's ``set_route_points`` time out after 3 s (ERRORs every ~10 s,
  retries; a departure's route arrives late and the AD API WARNs it was set after all). Root cause
  /planning/mission_planning/mission_planner.
- ``qos_vehicle_cmd``: a reloaded interface config makes the CAN bridge re-create its command
  subscription RELIABLE against the gate's best-effort publisher: it receives nothing (rclpy WARNs
  the incompatible QoS on both sides, in the CAN bridge and in the gate), brakes with an ERROR
  "Control command timeout" and holds the shuttle (velocity 0; its diagnostics ERROR) while the
  whole stack goes on commanding. Root cause /vehicle/vehicle_interface.
- ``leak_tracker``: the tracker's history is never trimmed: the perception process grows 2.5 MB/s.
  Root cause /perception/object_recognition/tracking/multi_object_tracker.
- ``cpu_behavior``: a runaway thread in the behavior planner's process (the planning container)
  burns a core. Root cause
  /planning/scenario_planning/lane_driving/behavior_planning/behavior_path_planner.
- ``errlog_follower``: the steering angle sensor reports garbage: the trajectory follower logs an
  ERROR every second and goes on with its estimate (control unchanged). Root cause
  /control/trajectory_follower/controller_node_exe.
"""

from __future__ import annotations

import os
import sys

from bench.handwritten import Design, NamespacedRobot, main

# the launch file's environment for every process: numpy's BLAS single-threaded (its worker threads
# would spin on the ECU's two cores)
for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

DESIGN = Design(
    module="bench.shuttle.robot",
    nodes={  # process -> its nodes (fully qualified), in the order they start
        "vehicle": ("/vehicle/vehicle_interface",),
        "imu": ("/sensing/imu/imu_driver",),
        "gnss": ("/sensing/gnss/gnss_driver", "/sensing/gnss/gnss_poser"),
        "lidar": ("/sensing/lidar/top/lidar_driver",),
        "camera": ("/sensing/camera/camera0/camera_driver",),
        "pointcloud_container": ("/sensing/lidar/top/crop_box_filter", "/sensing/lidar/top/ground_filter",
                                 "/sensing/lidar/top/voxel_grid_downsample_filter"),
        "ndt": ("/localization/pose_estimator/ndt_scan_matcher",),
        "localization": ("/localization/pose_twist_fusion_filter/ekf_localizer",
                         "/localization/util/pose_initializer"),
        "detector": ("/perception/object_recognition/detection/tensorrt_yolox",),
        "perception": ("/perception/object_recognition/detection/clustering/euclidean_cluster",
                       "/perception/object_recognition/tracking/multi_object_tracker"),
        "traffic_light": ("/perception/traffic_light_recognition/traffic_light_classifier",),
        "mission_planning": ("/planning/mission_planning/mission_planner",),
        "planning": ("/planning/scenario_planning/lane_driving/behavior_planning/behavior_path_planner",
                     "/planning/scenario_planning/motion_velocity_smoother", "/planning/planning_validator"),
        "control": ("/control/trajectory_follower/controller_node_exe", "/control/vehicle_cmd_gate"),
        "system": ("/system/topic_state_monitor", "/system/component_state_monitor",
                   "/system/emergency_handler", "/system/diagnostic_aggregator", "/system/system_monitor"),
        "recorder": ("/rosbag2_recorder",),
        "ad_api": ("/default_ad_api/node/localization", "/default_ad_api/node/routing"),
        "operator": ("/remote/operator_console",),
    },
    faults={
        "crash_lidar": ("kill", "/sensing/lidar/top/lidar_driver", "lidar"),
        "hang_ground_filter": ("file:hang", "/sensing/lidar/top/ground_filter", "pointcloud_container"),
        "degrade_imu": ("file:degrade", "/sensing/imu/imu_driver", "imu"),
        "slow_ndt": ("file:slow", "/localization/pose_estimator/ndt_scan_matcher", "ndt"),
        "stale_ekf": ("file:stale", "/localization/pose_twist_fusion_filter/ekf_localizer", "localization"),
        "slow_route": ("file:slow", "/planning/mission_planning/mission_planner", "mission_planning"),
        "qos_vehicle_cmd": ("file:reliable", "/vehicle/vehicle_interface", "vehicle"),
        "leak_tracker": ("leak", "/perception/object_recognition/tracking/multi_object_tracker",
                         "perception"),
        "cpu_behavior": ("cpu",
                         "/planning/scenario_planning/lane_driving/behavior_planning/behavior_path_planner",
                         "planning"),
        "errlog_follower": ("file:errlog", "/control/trajectory_follower/controller_node_exe", "control"),
    },
    operator="operator", join_s=15.0, run_s=65.0, again_s=10.0,  # connected from ~90 s to ~155 s
)
NODES, FAULTS = DESIGN.nodes, DESIGN.faults


if __name__ == "__main__":
    sys.exit(main(None, __doc__, "shuttle", NamespacedRobot, DESIGN, 100.0,
                  "s from the start to the injection (100: the console connected, the second leg under way)"))
