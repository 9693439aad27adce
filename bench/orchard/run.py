"""Run the apple-harvesting orchard robot under the monitor: healthy run, injected faults.

``python -m bench.orchard.run [--healthy S] [--warmup S] [--post S] [--faults a,b] [--out DIR]
[--samples DIR] [--from-healthy RUN.sqlite]``

The robot's processes (`bench.orchard.robot`) under the in-process monitor, as every hand-written
robot runs (`bench.handwritten`: the runs, their scores, the files written). ``orchard`` is a
tracked apple harvester working a trellised Gala block (Wenatchee valley, 4 m row spacing): a
rubber-track base on CAN (track controller, vacuum blower, IMU), an RTK GNSS receiver with an NTRIP
client on the farm Wi-Fi, a lifecycle-managed SICK TiM781 looking at the canopy walls for row
centering, two ZED X stereo cameras (one per canopy side), an apple detector, a stereo fruit
localizer/tracker and a canopy segmenter, robot_localization-style EKF + navsat_transform, a row
follower, a headland path tracker and planner, a twist_mux-like velocity mux, two vacuum-tube
picking arms under a ros2_control-like controller manager, a MoveIt-like grasp planner, a mission
executive that drives the rows on a timetable, a harvest coordinator that runs both arms through
each bay's pick window, a lifecycle manager, a bridge to the farm server, a bin logger that joins
late and the crew lead's tablet that comes and goes. Laid out as a production ROS 2 Jazzy team lays
it out: a single-threaded stereo camera component container, a multi-threaded perception container
with callback groups, a localization container, a controller manager with its realtime update
thread, a lifecycle lidar driver and its lifecycle manager. Everything is under ``/orchard`` except
``/tf``, ``/tf_static``, ``/diagnostics``, ``/diagnostics_agg``, ``/rosout``, ``/parameter_events``
and the infrastructure node ``/diagnostic_aggregator``. Wall time everywhere.

The orchard: one schedule shared by every process through the wall clock (`bench.orchard.robot`:
`where`, `fruit`, `shaded`, `link_up`), from ``ORCHARD_T0``, which `OrchardRobot.start` sets to the
robot's start (every process of a run, and every restart of one, agrees). Bring-up takes 10 s, then
a row every 90 s (row 0 from 10 s, row 1 from 100 s, row 2 from 190 s, ...); within a row (phase
from its start): 0-2 s entering, then four bays: drive 2.5 m in 5 s at 0.5 m/s and stop 11 s for the
pick window (drives at 2-7, 18-23, 34-39, 50-55 s; pick windows 7-18, 23-34, 39-50, 55-66 s); at
66 s the row end (``~/row_end`` event, the canopy lidar deactivated, the headland turn planned); the
headland turn 68-86 s; the lidar reactivated at 88 s. Apples within reach of each arm at a bay: none
in 15 % of the bay sides, else 2-6 (seeded by row, bay, side); each arm takes one every ~2.6 s, so
detections come for the first 3-17 s of a pick window on each side and stop when the side is
picked. In 30 % of the bays the coordinator creeps the base forward 2 s (fruit beyond reach). In
35 % of the bays dense canopy over the antenna makes the RTK solution float. The farm Wi-Fi (mesh AP
at the row ends) is down 4-10 s in 55 % of the wall-clock minutes (~7 % of the time): no NTRIP
corrections (RTK float once they are 5 s old), no farm server.

Substitutes (not installed here: vision_msgs, trajectory_msgs, control_msgs, moveit_msgs,
nav2_msgs, rtcm_msgs, tf2_msgs, diagnostic_updater): ``/tf`` and ``/tf_static`` carry
geometry_msgs/TransformStamped, one transform a message; detections (vision_msgs/Detection2DArray)
are geometry_msgs/PoseArray in pixels (x, y the box centre, z its size, orientation.w the score)
stamped with their image; fruit tracks are geometry_msgs/PoseArray in base_link; RTCM corrections
are std_msgs/UInt8MultiArray; the grasp planner (MoveIt's GetMotionPlan) and the headland planner
are nav_msgs/GetPlan; the row, headland path and both arms' pick trajectory actions (nav2
FollowPath-like, control_msgs FollowJointTrajectory) are test_msgs/Fibonacci (``follow_row``:
``order`` = the row, feedback ``[bay, 0 driving / 1 stopped, cm]``; ``follow_path``: ``order`` =
the turn's seconds; ``follow_joint_trajectory``: ``order`` = the trajectory's waypoints, feedback
the tube's extension in cm, result 0 or -4 aborted); the arm controllers' ``~/controller_state``
(JointTrajectoryControllerState) is sensor_msgs/JointState; the mission state, the mux's active
input, the controller manager's activity, the RTK status, pick events and the bin fill are
std_msgs/String (a word or JSON); the diagnostic updaters are a timer each (statuses named ``node:
task`` with a ``hardware_id``).

QoS: "sensor" best effort keep-last 5 (``/orchard/imu/data``, ``/orchard/canopy_lidar/scan``, both
cameras' ``image_rect_color/compressed`` and ``camera_info``), "command" reliable keep-last 1
(``/orchard/cmd_vel_nav``, ``/orchard/cmd_vel_harvest``, ``/orchard/cmd_vel_teleop``), "reliable"
keep-last 10 (everything else: ``/orchard/cmd_vel``, the fix, odometry, detections, fruits, joint
states, controller states, pressures, picks, ``/tf``, ``/diagnostics``, ``/diagnostics_agg``),
"latched" reliable transient-local depth 1 (``/orchard/mission_executive/state``,
``/orchard/cmd_vel_mux/active``, ``/orchard/controller_manager/activity``,
``/orchard/gnss_driver/rtk_status``, ``/orchard/bin_logger/bin_fill``,
``/orchard/robot_description``), ``/tf_static`` transient-local depth 100. Several publishers on
one topic: ``/diagnostics`` (20 statuses from 17 nodes), ``/tf`` (the EKF's odom->base_link 20 Hz,
robot_state_publisher's two tube ends 5 Hz each), ``/orchard/cmd_vel_nav`` (row follower, path
tracker).

Processes -> nodes (14 processes, 30 nodes; the tablet comes and goes):

- ``base_driver`` (the base's CAN bridge, ONE SingleThreadedExecutor): ``/orchard/track_controller``
  (``/orchard/cmd_vel`` -> ``/orchard/odometry/wheel`` 20 Hz, 0.5 s command timeout;
  ``/orchard/battery`` 1 Hz; WARN "Left track motor channel temperature ... derating" every 100-220 s;
  diagnostics motor drivers + battery), ``/orchard/vacuum_pump`` (``~/enable`` SetBool, called at
  each pick window's start and end, INFO "Blower on ..."/"Blower off"; ``~/pressure`` FluidPressure
  5 Hz), ``/orchard/imu_driver`` (Xsens MTi-630: ``/orchard/imu/data`` 50 Hz, stamped 3 ms back).
- ``gnss`` (Python: a crash ends it as Python does, ``ROBOT_PYTHON_EXIT=1``, its nodes
  deregistering; ONE SingleThreadedExecutor): ``/orchard/gnss_driver`` (ZED-F9P: ``/orchard/fix``
  NavSatFix 10 Hz stamped 60 ms back; ``~/rtk_status`` latched on change, INFO "RTK fixed ..." /
  WARN "RTK float: carrier solution lost (canopy multipath, ...)" or "(correction age N s ...)"),
  ``/orchard/ntrip_client`` (``~/rtcm`` 1 Hz while the Wi-Fi is up; WARN "Lost connection to ...:
  [Errno 113] No route to host; reconnecting every 2 s" / INFO "Connected: ICY 200 OK ...").
- ``canopy_lidar``: ``/orchard/canopy_lidar`` (lifecycle node, configured and activated by the
  lifecycle manager at bring-up; ``~/scan`` LaserScan 811 beams (6.5 KB) at 15 Hz while active,
  stamped at the scan's start; ``~/transition_event``; INFO "Laser emission on ..." / "Laser emission
  off (standby)"; deactivated at every row end, activated before every row).
- ``stereo_container`` (component container, ONE SingleThreadedExecutor): ``/orchard/left_camera``,
  ``/orchard/right_camera`` (ZED X on GMSL2: ``~/image_rect_color/compressed`` 22-28 KB JPEG and
  ``~/camera_info`` at 8 Hz each, stamped at mid-exposure 35 ms back; WARN "Auto exposure: sun in
  field of view ..." every 120-260 s each; diagnostics each).
- ``perception`` (component_container_mt: MultiThreadedExecutor, 3 threads, a MutuallyExclusive
  group per node; Python, ``ROBOT_PYTHON_EXIT=1``): ``/orchard/fruit_detector`` (TensorRT YOLO;
  ``~/enable`` SetBool from the harvest coordinator; while enabled infers on both cameras' frames
  and publishes ``~/detections`` only for a side with apples in view: ~8 Hz per side during the first
  seconds of pick windows, nothing otherwise -- bursty; WARN "Detector enabled but no frames on ..."
  when enabled without frames for 2 s), ``/orchard/fruit_localizer`` (detections + camera_info ->
  ``~/fruits`` PoseArray in base_link at the detections' rate; WARN "Dropping N detections from
  X_camera: image stamp N s old (max_age 0.50 s) ..." for stale detections -- never in a healthy
  run), ``/orchard/canopy_segmenter`` (every 4th frame of both cameras -> ``~/canopy_density``
  OccupancyGrid 40x40 2 Hz).
- ``localization`` (component container, ONE SingleThreadedExecutor): ``/orchard/navsat_transform``
  (fix -> ``/orchard/odometry/gps`` 10 Hz, stamped as the fix), ``/orchard/ekf_filter_node`` (wheel
  odometry + IMU + GNSS -> ``/orchard/odometry/filtered`` and odom->base_link on ``/tf`` 20 Hz; WARN
  "No /orchard/odometry/gps measurement for N s ..." after 2 s without; diagnostics "imu topic
  status" (45-55 Hz expected) and "Filter"), ``/orchard/robot_state_publisher``
  (``/orchard/robot_description`` and 7 static transforms latched; joint states -> both tube ends on
  ``/tf`` 5 Hz each).
- ``navigation`` (MultiThreadedExecutor, 4 threads, groups): ``/orchard/row_follower``
  (``~/follow_row`` action: the row's four bays; ``/orchard/cmd_vel_nav`` 10 Hz ONLY while driving
  between bays (20 s of each 90), a zero twist at each stop; centering on the canopy scan; WARN "No
  scan on /orchard/canopy_lidar/scan for N s: row centering on GNSS/odometry only, speed limited to
  0.25 m/s" when driving blind -- never in a healthy run; subscribes the filtered odometry),
  ``/orchard/path_tracker`` (``~/follow_path`` action: the headland turn, ``/orchard/cmd_vel_nav``
  10 Hz for 18 s), ``/orchard/headland_planner`` (``~/plan_turn`` GetPlan, 50-150 ms, once a row),
  ``/orchard/cmd_vel_mux`` (teleop 100 > harvest creep 50 > navigation 10 into ``/orchard/cmd_vel``
  at the winning input's rate; ``~/active`` latched on change).
- ``arms`` (ros2_control_node-like, C++: a crash leaves its nodes listed; MultiThreadedExecutor 4
  threads + the ``cm_update_loop`` thread at 50 Hz): ``/orchard/controller_manager`` (loads and
  activates the three controllers at start, ``~/activity`` latched; WARN "Overrun detected! ..."
  every 90-220 s; diagnostics), ``/orchard/joint_state_broadcaster`` (``/orchard/joint_states``
  8 joints, 25 Hz from the loop: its publish_rate), ``/orchard/left_arm_controller``,
  ``/orchard/right_arm_controller`` (``~/follow_joint_trajectory`` action, a 2.2 s pick trajectory;
  ``~/controller_state`` 25 Hz ONLY while a trajectory runs; feedback 5 Hz).
- ``arm_planning`` (move_group-like, ONE SingleThreadedExecutor): ``/orchard/grasp_planner``
  (``~/plan_grasp`` GetPlan per apple, 40-150 ms, INFO "Solution found in 0.087 seconds; 8 waypoints
  ..." each; diagnostics).
- ``mission`` (MultiThreadedExecutor 4 threads, groups; the timetable, bring-up and per-arm worker
  threads): ``/orchard/mission_executive`` (the row timetable above: ``follow_row`` goal at 2 s,
  ``~/state`` latched on change from its feedback: ``row_N:entering``, ``row_N:driving_to_bay_K``,
  ``row_N:picking_bay_K``, ``row_N:row_end``, ``headland_turn:N->N+1``, ``holding``; ``~/row_end``
  PoseStamped once a row; ``plan_turn`` with a 3 s timeout; ``follow_path``; the lifecycle manager's
  ``set_canopy_sensing`` off at the row end and on at 88 s), ``/orchard/harvest_coordinator`` (on
  ``picking_bay_K``: vacuum on, detector on, one worker per arm: a fresh target from
  ``/orchard/fruit_localizer/fruits`` -> ``plan_grasp`` (1.5 s timeout) -> a pick goal -> ``~/picked``
  JSON per apple (~16 a bay, bursty); creep ``/orchard/cmd_vel_harvest`` 10 Hz for 2 s in 30 % of
  the bays; detector and vacuum off when the robot moves on; INFO "Row N: M apples picked, K attempts
  failed" at each row end; WARN "Row N bay K: no fruit targets ... within 4.0 s of stopping" when a
  bay has no apples on either side (~2 % of the bays); parameter ``min_fruit_diameter_mm`` set by the
  tablet), ``/orchard/lifecycle_manager`` (configures and activates the lidar at bring-up, nav2-like
  INFO "Configuring canopy_lidar" ... "Managed nodes are active"; ``~/set_canopy_sensing``; INFO
  "canopy_lidar already inactive/active" when asked for the state it has; ``canopy_lidar/get_state``
  every 2 s as its bond, ERROR "CRITICAL FAILURE: SERVER canopy_lidar IS DOWN ..." without an
  answer for 4 s; diagnostics 0.5 Hz, WARN "canopy_lidar inactive (expected active)" when the lidar
  is not in the state it set).
- ``farm_link``: ``/orchard/farm_bridge`` (farm_bridge.yaml: ``/orchard/odometry/filtered``
  reliable/volatile -> ``/orchard/farm/robot_pose`` 1 Hz while the link is up; picks ->
  ``/orchard/farm/harvest_events``, buffered while down; ``/orchard/wifi/link_quality`` 1 Hz, 0 while
  down; WARN "Wi-Fi link to farm server lost ..." / INFO "... restored ...; flushing N buffered
  events"; WARN "No pose on /orchard/odometry/filtered for N s ..." after 5 s without one).
- ``bin_logger``: ``/orchard/bin_logger`` JOINS LATE (its process starts with the others, its node
  20 s later, once the bin scale's USB serial is up): picks + fix (10 Hz, geotags) + row ends;
  ``~/bin_fill`` latched on every apple; INFO "Bin B-0xxx: N apples ..." at each row end.
- ``diagnostics``: ``/diagnostic_aggregator`` (``/diagnostics`` -> ``/diagnostics_agg`` 1 Hz with
  paths ``/Orchard/{Drive,Sensors,Perception,Localization,Navigation,Arms,Harvest,Communications,
  Logging,Other}/...``, STALE after 5 s).
- ``operator``: ``/orchard/operator_tablet``, the crew lead's tablet, joins at 35 s, exits with
  code 0 after 50 s and comes back 30 s later (connected ~35-85 s, ~115-165 s, ...): subscribes the
  mission state, the bin fill, ``/diagnostics_agg`` and the left camera (live view); 5 s after
  connecting sets the coordinator's ``min_fruit_diameter_mm`` (65, 70 or 75) through
  ``set_parameters``; 20-23 s after connecting nudges the robot on ``/orchard/cmd_vel_teleop`` 10 Hz
  (the mux switches to teleop).

Healthy dynamics (smoke test on the 2-core VM, rclpy probe, 15 s windows, 30-180 s after the start):
IMU 50 Hz, joint states 25 Hz, ``/tf`` 30 msgs/s, filtered and wheel odometry 20 Hz, canopy scan 15
Hz (none 66-88 s of each row), both cameras 8 Hz (images and camera_info), fix and
``/orchard/odometry/gps`` 10 Hz, vacuum pressure 5 Hz, ``/diagnostics`` ~15-16 arrays/s, canopy
density 2 Hz, battery, link quality, ``/diagnostics_agg``, RTCM (while the link is up), farm pose 1
Hz. Bursty or on demand: detections and fruits (~9-12 msgs/s over a window with a pick window in it,
0 otherwise), ``~/picked`` and the bin fill (one per apple, ~25-30 apples a row), both
``~/controller_state`` (25 Hz during picks; 11-18 msgs/s over a pick window), ``/orchard/cmd_vel_nav``
(10 Hz while driving: ~3 msgs/s over an in-row window, 8 over a turn), ``/orchard/cmd_vel_harvest``
(2 s in 30 % of the bays), ``/orchard/cmd_vel`` (follows its winning input), teleop (3 s a tablet
session), the row-end event (once a row), grasp plans (one per apple), the turn plan (once a row),
latched states on change. Lifecycle transitions: the lidar configured+activated at bring-up,
deactivated and activated every row. Service calls: ``enable`` of detector and vacuum twice a bay,
``plan_grasp`` per apple, ``plan_turn`` and ``set_canopy_sensing`` each row, ``get_state`` every 2 s.
Late joiners: the bin logger (20 s), the tablet. Recurring WARNs: RTK float under the canopy, the
Wi-Fi and NTRIP outages, the camera auto exposure, the track motor temperature, the controller
manager's overrun.

Load (psutil, 2-core VM, no monitor and no probe attached, another job on the machine): ~45-50 % of
one core in total between pick windows (localization 13-15 %, base_driver 9-10 %, navigation 4-7 %,
perception 4-6 %, mission 3-6 %, farm_link 2.3 %, arms 2-2.5 %, stereo_container 2 %, every other
process 1.7 % or less); 55-75 % in 15 s windows holding a pick window (perception 13-29 %: the
detector subscribes the cameras only while enabled, the localizer and the coordinator work). Above
the ~40 % aimed for.

The faults (default injection 140 s after the start: the tablet's second session connected, row 1's
third pick window 1 s old with 4 apples a side, the row end at 166 s, the lidar back at 188 s), each
with its true root cause (the target node) and what a user sees:

- ``hang_left_camera``: the left ZED X's GMSL2 link drops a frame and the driver's grab, called with
  no timeout, waits for good in the single-threaded stereo container: WARN "Frame grab timed out
  after 200 ms (GMSL2 link 0: 37 CRC errors); re-arming capture" once, then both cameras' images,
  camera_info and diagnostics stop (both nodes stay in the graph; their diagnostics go STALE in the
  aggregator); the segmenter's canopy density stops; in pick windows the detector WARNs "Detector
  enabled but no frames on /orchard/{left,right}_camera/... for N s", no detections, no fruit, no
  picks; the tablet's live view freezes. Root cause /orchard/left_camera (process
  stereo_container).
- ``hang_fruit_localizer``: a track reaching max_misses is pruned inline while the tracker's
  (non-reentrant) lock is held: the detections callback deadlocks at the next detections; nothing is
  logged; in the multi-threaded perception container the localizer's group never runs again (its
  diagnostics go STALE) while the detector and segmenter go on: detections still flow in pick
  windows but ``/orchard/fruit_localizer/fruits`` stops, the arms stand idle, ``~/picked`` and the
  bin fill stop, the coordinator WARNs "Row N bay K: no fruit targets ..." at each bay. Root cause
  /orchard/fruit_localizer (process perception).
- ``lag_right_camera``: the right camera loses PTP sync to the Orin's grandmaster and free-runs: its
  stamps fall behind by 0.1 s more every second; the camera logs nothing; images still come at 8 Hz;
  ~5 s later the localizer WARNs "Dropping N detections from right_camera: image stamp N s old
  (max_age 0.50 s); check camera time sync" during pick windows, the right arm stops picking (the
  left goes on). Root cause /orchard/right_camera (process stereo_container).
- ``rate_imu_driver``: the MTi resets after a brownout and its 921600 baud is not acknowledged: WARN
  "Device reset detected (wake-up message); baudrate 921600 not acknowledged, reconnected at 115200:
  output limited to 33 Hz" once and ``/orchard/imu/data`` falls from 50 to 33 Hz (66 %); the EKF's
  "imu topic status" diagnostics WARN "Frequency too low." Root cause /orchard/imu_driver (process
  base_driver).
- ``crash_right_arm_controller``: the right arm's joint limits are reloaded from a corrupted
  right_arm_limits.yaml (tube_extension max_velocity 0.0): INFO "Reloaded joint limits from
  /opt/orchard/config/right_arm_limits.yaml (tube_extension: max_velocity 0.0, ...)" and at the
  right arm's next trajectory sample the spline scaling divides by it on the realtime thread: a
  ZeroDivisionError traceback, "terminate called after throwing an instance of
  'std::runtime_error'", the ``arms`` process exits (code 134) -- controller manager, joint state
  broadcaster and both arm controllers at once, still listed (C++); ``/orchard/joint_states``, the
  tube-end ``/tf`` and controller states stop; the coordinator ERRORs "X arm pick trajectory did not
  finish ..." and "Action server /orchard/{left,right}_arm_controller/follow_joint_trajectory not
  available ..."; no more picks. Root cause /orchard/right_arm_controller (process arms).
- ``slow_grasp_planner``: the collision octomap is never cleared between bays (octomap.yaml pushed
  with ``clear_after_bay: false``): WARN "Octomap has 1843221 occupied voxels (limit 250000) ..."
  once, then every plan takes 3.5-5 s ("Solution found in 4.2 seconds ..."), requests queue up in the
  single-threaded planner, its diagnostics come late and WARN "Planning slow"; the coordinator ERRORs
  "Grasp planning for X apple (row N, bay K) failed: /orchard/grasp_planner/plan_grasp did not
  answer within 1.50 s; skipping apple" and WARNs "X arm paused for the rest of bay K: 3 planning
  failures"; no picks. Root cause /orchard/grasp_planner (process arm_planning).
- ``cpu_canopy_segmenter``: a new canopy_lab.yaml makes SLIC never converge: WARN "SLIC superpixels
  did not converge after 10 iterations (lab_threshold 0.0); retrying with max_iterations unbounded"
  once and one core busy in the perception container (its GIL shared with the detector and the
  localizer: their callbacks run late). Root cause /orchard/canopy_segmenter (process perception).
- ``leak_bin_logger``: the logger's geotag track cache is never trimmed: the ``bin_logger`` process
  grows ~3 MB/s; nothing is logged; logging goes on. Root cause /orchard/bin_logger.
- ``deactivate_canopy_lidar``: a crew member types ``ros2 lifecycle set /orchard/canopy_lidar
  deactivate`` on the wrong robot's terminal (a short-lived CLI process and its hidden node
  ``/_ros2cli_<pid>``, `OrchardRobot.inject`'s ``lifecycle:`` kind): the lidar logs "Laser emission
  off (standby)" mid-row, ``/orchard/canopy_lidar/scan`` stops, the lifecycle manager's diagnostics
  WARN "canopy_lidar inactive (expected active)", at the next drive (150 s with the default
  injection) the row follower WARNs "No scan on /orchard/canopy_lidar/scan ... speed limited to 0.25
  m/s"; at the row end the manager logs "canopy_lidar already inactive"; only the activation before
  the next row (188 s) brings it back. Root cause /orchard/canopy_lidar (process canopy_lidar).
- ``qos_farm_bridge``: a redeployed farm_bridge.yaml and a restart of the ``farm_link`` process (new
  pid) make the bridge subscribe the filtered odometry transient-local (depth 1) against the EKF's
  volatile publisher: INFO "Loaded ... (pose qos: reliable/transient_local, depth 1; ...)", rclpy's
  incompatible-QoS WARNs on both sides ("New publisher discovered ... offering incompatible QoS" in
  the bridge, "New subscription discovered ... requesting incompatible QoS" in the EKF);
  ``/orchard/farm/robot_pose`` stops for good and the bridge WARNs "No pose on
  /orchard/odometry/filtered for N s ..." every 10 s while link quality and harvest events still
  flow. Root cause /orchard/farm_bridge (process farm_link).
- ``crashloop_ntrip_client``: the farm rotated the NTRIP caster's credentials: the caster answers
  "HTTP/1.1 401 Unauthorized" and the client's response parser has no branch for it: an uncaught
  KeyError 1.5-2.5 s after each start (after INFO "Connecting to NTRIP caster ..."), the ``gnss``
  process exits with code 1 (Python: both its nodes deregister) and the launch file's respawn starts
  it again 1 s later: a restart loop every ~3-4 s (new pid); the fix comes in short bursts ("3D fix
  ... waiting for RTCM corrections", never RTK), the EKF WARNs "No /orchard/odometry/gps measurement
  for N s ...", the bin logger's geotags stop. Root cause /orchard/ntrip_client (process gnss).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time

from bench.handwritten import ROOT, Design, LaunchedRobot, main

for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

DESIGN = Design(
    module="bench.orchard.robot",
    nodes={
        "base_driver": ("/orchard/track_controller", "/orchard/vacuum_pump", "/orchard/imu_driver"),
        "gnss": ("/orchard/gnss_driver", "/orchard/ntrip_client"),
        "canopy_lidar": ("/orchard/canopy_lidar",),
        "stereo_container": ("/orchard/left_camera", "/orchard/right_camera"),
        "perception": ("/orchard/fruit_detector", "/orchard/fruit_localizer", "/orchard/canopy_segmenter"),
        "localization": (
            "/orchard/navsat_transform",
            "/orchard/ekf_filter_node",
            "/orchard/robot_state_publisher",
        ),
        "navigation": (
            "/orchard/row_follower",
            "/orchard/path_tracker",
            "/orchard/headland_planner",
            "/orchard/cmd_vel_mux",
        ),
        "arms": (
            "/orchard/controller_manager",
            "/orchard/joint_state_broadcaster",
            "/orchard/left_arm_controller",
            "/orchard/right_arm_controller",
        ),
        "arm_planning": ("/orchard/grasp_planner",),
        "mission": (
            "/orchard/mission_executive",
            "/orchard/harvest_coordinator",
            "/orchard/lifecycle_manager",
        ),
        "farm_link": ("/orchard/farm_bridge",),
        "bin_logger": ("/orchard/bin_logger",),
        "diagnostics": ("/diagnostic_aggregator",),
        "operator": ("/orchard/operator_tablet",),
    },
    faults={
        "hang_left_camera": ("file:hang", "/orchard/left_camera", "stereo_container"),
        "hang_fruit_localizer": ("file:hang", "/orchard/fruit_localizer", "perception"),
        "lag_right_camera": ("file:lag", "/orchard/right_camera", "stereo_container"),
        "rate_imu_driver": ("file:rate", "/orchard/imu_driver", "base_driver"),
        "crash_right_arm_controller": ("file:crash", "/orchard/right_arm_controller", "arms"),
        "slow_grasp_planner": ("file:slow", "/orchard/grasp_planner", "arm_planning"),
        "cpu_canopy_segmenter": ("cpu", "/orchard/canopy_segmenter", "perception"),
        "leak_bin_logger": ("leak", "/orchard/bin_logger", "bin_logger"),
        "deactivate_canopy_lidar": ("lifecycle:deactivate", "/orchard/canopy_lidar", "canopy_lidar"),
        "qos_farm_bridge": ("restart:transient_local", "/orchard/farm_bridge", "farm_link"),
        "crashloop_ntrip_client": ("respawn:crashloop", "/orchard/ntrip_client", "gnss"),
    },
    operator="operator",
    join_s=35.0,
    run_s=50.0,
    again_s=30.0,
)
NODES, FAULTS = DESIGN.nodes, DESIGN.faults


class OrchardRobot(LaunchedRobot):
    """`LaunchedRobot` that starts the orchard's day (``ORCHARD_T0``) with the robot, plus
    ``lifecycle:<transition>``: a crew member's ``ros2 lifecycle set <target> <transition>``, a
    short-lived CLI process (its own hidden node) calling the target's ``change_state``."""

    def start(self) -> None:
        os.environ["ORCHARD_T0"] = repr(time.time())  # inherited by every process of this run
        super().start()

    def inject(self, fault: str) -> None:
        how, target, _process = self.design.faults[fault]
        if not how.startswith("lifecycle:"):
            super().inject(fault)
            return
        log = open(self.logs / "ros2_lifecycle_set.log", "a")
        cmd = [
            sys.executable,
            "-m",
            self.design.module,
            "lifecycle_set",
            str(self.fault_dir),
            "0",
            target,
            how.removeprefix("lifecycle:"),
        ]
        self.transient.append(
            subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, start_new_session=True, cwd=ROOT)
        )


if __name__ == "__main__":
    sys.exit(
        main(
            None,
            __doc__,
            "orchard",
            OrchardRobot,
            DESIGN,
            140.0,
            "s from the start to the injection (140: the tablet's second session connected, row 1's "
            "third pick window 1 s old, the row end and the lidar's standby 26 s later)",
        )
    )
