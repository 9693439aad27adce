"""Run the hospital delivery robot under the monitor: healthy run, injected faults.

``python -m bench.hospital.run [--healthy S] [--warmup S] [--post S] [--faults a,b] [--out DIR]``

The robot's processes (`bench.hospital.robot`) under the in-process monitor, as every hand-written
robot runs (`bench.handwritten`: the runs, their scores, the files written). ``hd_01`` is a hospital
delivery robot, one member of a fleet, carrying medicine and lab samples in four locked drawers from
a floor's meds room to the wards (floors 3-5, the elevator between them), laid out as a production
team lays out Nav2 (lifecycle nodes in a component container), its sensor drivers composed into one
container, a base controller, a safety PLC bridge, a velocity mux, a mission executor talking to an
Open-RMF-like fleet server and to the building's door/elevator gateway. Everything is under ``/hd``
except ``/tf``, ``/tf_static``, ``/diagnostics``, ``/diagnostics_agg``,
``/diagnostics_toplevel_state``, ``/rosout``, ``/parameter_events``, the fleet's ``/fleet/*`` and
the building's ``/building/*`` and the infrastructure nodes ``/fleet_server``, ``/building_gateway``,
``/diagnostic_aggregator`` and ``/rosbag2_recorder``. Wall time everywhere.

Executors: ``nav_container`` spins one MultiThreadedExecutor (8 threads): every lifecycle node's own
callbacks (timers, subscriptions, its lifecycle services) share its mutually exclusive default group;
the action servers (follow_path, backup, navigate_to_pose) run in a reentrant group per node, the
navigator's and the lifecycle manager's clients in a reentrant group. ``sensor_container`` spins
one SingleThreadedExecutor for its three drivers (a blocking callback in one starves the others).
``building_gateway`` spins a MultiThreadedExecutor (4 threads) whose reentrant service callbacks
block until the BMS link thread completes their request. Every other process spins one
SingleThreadedExecutor; the mission executor's state machine, the gateway's BMS link and status
relay, the recorder's writer and the lifecycle manager's bring-up are threads of their own.

Substitutes (no tf2_msgs, nav2_msgs, rmf_* nor diagnostic_updater here): ``/tf`` and ``/tf_static``
carry geometry_msgs/TransformStamped, one transform a message; the Nav2 actions
``/hd/navigate_to_pose`` (order = the place's index: meds_room, elevator_lobby, ward_a, ward_b, lab,
dock), ``/hd/follow_path`` and ``/hd/backup`` (order = cm) are test_msgs/Fibonacci (feedback
``sequence[0]`` = distance remaining in cm, result ``sequence[0]`` = 0 succeeded, 1 planner did not
answer, 2 no progress, 3 localization lost, 4 no plan, 5 canceled, 6 controller unavailable); the
planner's ``/hd/compute_path_to_pose`` is nav_msgs/GetPlan; ``/building/door/open``,
``/building/elevator/request``, ``/hd/drawer_controller/open_drawer`` and
``/fleet_server/report_incident`` are test_msgs/BasicTypes; orders, robot/mission states, keypad
events, drawer, door and elevator states are std_msgs/String (JSON); the particle cloud a
geometry_msgs/PoseArray; the safety heartbeat a std_msgs/Header (``frame_id`` RUN / STOP).

QoS: "sensor" best effort keep-last 5 (``/hd/scan``, depth image, camera info, points, the lazy
compressed color stream, ``/hd/imu/data``, ``/hd/particle_cloud``), "command" reliable keep-last 1
(``/hd/cmd_vel_nav``, ``/hd/cmd_vel_teleop``, ``/hd/safety/heartbeat``), "reliable" keep-last 10
(odometry, ``/hd/cmd_vel``, joint states, battery, plan, ``/diagnostics``, ``/diagnostics_agg``,
fleet orders and states, keypad, elevator status, robot state), "latched" reliable transient-local
depth 1 (``/hd/map``, ``/hd/amcl_pose``, ``/hd/robot_description``, ``/hd/safety/state``,
``/hd/cmd_vel_mux/active``, ``/hd/mission_executor/status``, ``/hd/drawer_controller/state``,
``/hd/hmi/touchscreen/page``, ``/hd/remote_teleop/session``, ``/building/doors/state``,
``/hd/base/estop``) and ``/tf_static`` (depth 100). Lifecycle topics (map, amcl's pose, tf and
particle cloud, plan, cmd_vel_nav) are lifecycle publishers: they publish only while their node is
active. Several publishers: ``/diagnostics`` (11 nodes), ``/tf`` (base controller, amcl, robot state
publisher), ``/hd/cmd_vel_nav`` (controller and behaviour servers).

Processes -> nodes (14 processes, 25 nodes; the tablet comes and goes):

- ``nav_container`` (component_container_mt): ``/hd/map_server`` (lifecycle; latches ``/hd/map``
  260 x 220 at 5 cm once active, serves ``~/map``; every 20 s re-reads its keep-out zones, 0.2-0.4 s
  blocking its own group), ``/hd/amcl`` (lifecycle; subscribes the scan and odometry; publishes
  ``/hd/amcl_pose`` at 5 Hz while the robot moves and 1 Hz while still, stamped as the scan, map->odom
  on ``/tf`` post-dated 0.5 s, ``/hd/particle_cloud`` 1 Hz; a scan older than 1 s is dropped with the
  message filter's WARN (every 2 s at most); 5 s without a scan, the "No laser scan received" WARN
  every 5 s; logs the "AMCL cannot publish a pose..." WARN once at activation, then its initial pose),
  ``/hd/planner_server`` (lifecycle; ``/hd/compute_path_to_pose`` 20-80 ms, each plan published on
  ``/hd/plan``; a 1 Hz global-costmap update timer), ``/hd/controller_server`` (lifecycle;
  ``/hd/follow_path``: pure pursuit at 20 Hz on ``/hd/cmd_vel_nav`` only while following, feedback
  2 Hz; aborts "Robot pose is X s old (amcl): localization lost" after 1.5 s without a pose, "Failed
  to make progress" without 0.2 m in 8 s; subscribes the depth points for its local costmap, WARN on
  clouds older than 1 s), ``/hd/behavior_server`` (lifecycle; ``/hd/backup``, idle unless a recovery
  runs), ``/hd/bt_navigator`` (lifecycle; ``/hd/navigate_to_pose``: plan, follow, re-plan every 1 s,
  planner timeout 2 s -> ERROR "compute_path_to_pose: planner server did not respond within 2.0 s",
  one backup recovery on a progress failure) and ``/hd/lifecycle_manager_navigation`` (plain node:
  configures then activates the six through their ``~/change_state`` at start, then polls every
  ``~/get_state`` every 2 s, its bond: no answer for 4 s -> ERROR "CRITICAL FAILURE: SERVER X IS DOWN
  after not receiving a heartbeat for 4000 ms.", a state other than active -> WARN once; diagnostics
  "lifecycle_manager_navigation: Nav2 Health" 0.5 Hz).
- ``sensor_container`` (component_container, single-threaded): ``/hd/front_lidar`` (``/hd/scan``
  LaserScan 360 beams 15 Hz, stamped at the first beam, 20 ms before publishing; every 60-150 s a WARN
  "Received incomplete scan packet ... frame skipped" and one scan missing; every 60-150 s someone
  walks in front for ~1 s (0.3 m); frequency diagnostics), ``/hd/depth_camera`` (logs an ERROR
  "Failed to open /dev/video4 ..." at start and opens 1.5 s later; ``~/depth/image_rect_raw`` 16UC1
  160x120 and ``~/depth/camera_info`` 6 Hz, ``~/depth/points`` 40x30 3 Hz stamped at exposure;
  ``~/color/image_raw/compressed`` 5 Hz ONLY while someone subscribes it, i.e. while the tablet is
  connected) and ``/hd/imu`` (``/hd/imu/data`` 100 Hz; frequency diagnostics).
- ``base``: ``/hd/base_controller`` (``/hd/cmd_vel`` with a 0.5 s timeout -> ``/hd/odom`` and
  odom->base_link on ``/tf`` 20 Hz, ``/hd/joint_states`` 10 Hz, ``/hd/base/estop`` latched; subscribes
  the IMU at 100 Hz: WARN every 5 s when its rate is below 60 Hz or it is silent),
  ``/hd/battery_monitor`` (``/hd/battery_state`` 1 Hz, diagnostics) and ``/hd/motor_driver``
  (diagnostics "motor_driver: Left wheel motor" / "Right wheel motor", hardware_id
  ``roboteq-sbl2360:/dev/ttyACM0``, 1 Hz).
- ``robot_state_publisher``: ``/hd/robot_state_publisher`` (5 static transforms and the URDF latched;
  the wheels' transforms on ``/tf`` from each joint state, 20 msgs/s).
- ``safety``: ``/hd/safety_monitor`` (scan best effort, e-stop; STOP when something is within 0.35 m
  ahead, the scan is 0.5 s stale or the e-stop is pressed: WARN "Protective stop: <reasons>", INFO
  when cleared; ``/hd/safety/heartbeat`` 10 Hz, ``/hd/safety/state`` latched on change; diagnostics
  1 Hz; a "scan data stale" stop at start until the lidar's first scan) and ``/hd/cmd_vel_mux``
  (teleop over navigation into ``/hd/cmd_vel`` at the inputs' rate, capped by its ``speed_limit``
  parameter, zero while the heartbeat says STOP or is 0.3 s old; one zero and silence 0.5 s after
  its input stops; ``~/active`` latched; INFO on each speed limit change).
- ``teleop``: ``/hd/remote_teleop``: the remote-assistance bridge; publishes ``/hd/cmd_vel_teleop``
  (10 Hz) only while a remote operator drives: 4-8 s after the mission reports FAILED, 5 s of
  backing up and turning; ``~/session`` latched.
- ``mission``: ``/hd/mission_executor``, the delivery state machine in a worker thread: navigate to
  the floor's meds room -> unlock the order's drawer, 3-5 s of loading, lock -> open the meds room
  door -> (another floor) navigate to the elevator lobby, ``/building/elevator/request`` (5-25 s,
  timeout 40 s) -> open the ward's door (1-2 s, now and then 3 s with a WARN "slow to open"; timeout
  8 s) -> navigate to the ward -> wait for the nurse's PIN (45 s) -> unlock, 2.5-4 s, lock ->
  delivered. Before each leg it sets the mux's ``speed_limit`` to 0.8 (corridor) and within 3 m of a
  ward to 0.45 (quiet zone) through ``/hd/cmd_vel_mux/set_parameters``. ``~/status`` latched on
  change, ``~/robot_state`` 1 Hz; INFO per step; a failure is an ERROR "[ord-N] Order failed in
  phase 'X': <why>", a FAILED status for 2 s and ``/fleet_server/report_incident``. Service
  introspection (metadata) on its elevator client.
- ``drawers``: ``/hd/drawer_controller`` (``~/open_drawer``, ``~/state`` latched on events only,
  diagnostics 1 Hz).
- ``hmi``: ``/hd/hmi/touchscreen``, the robot's screen: publishes ``/hd/hmi/keypad`` only when the
  nurse types (3-9 s after the robot starts waiting: four digits at 2-5 Hz and "enter"; one time in
  ten a wrong PIN first, then the mission's WARN "Wrong PIN ..."); ``~/page`` latched; parameter
  ``announce_volume``.
- ``building_gateway``: ``/building_gateway`` serves ``/building/door/open`` and
  ``/building/elevator/request`` (service introspection with contents on the elevator: its
  ``_service_event`` topic), each call blocking until the BMS link thread completes it;
  ``/building/elevator/status`` 2 Hz and its diagnostics ("building_gateway: BMS link") from a relay
  thread, ``/building/doors/state`` latched on events.
- ``fleet_server``: ``/fleet_server`` sends ``/fleet/orders`` 4-8 s after the robot first reports
  idle and 5-20 s after each order ends, re-queues a failed order (WARN) and re-sends it, logs the
  robot's incident reports (WARN), marks the robot lost after 5 s without its state (ERROR);
  ``/fleet/fleet_state`` 1 Hz.
- ``diagnostics``: ``/diagnostic_aggregator``: ``/diagnostics`` (~11 arrays/s) -> ``/diagnostics_agg``
  (Base, Sensors, Navigation, Safety, Payload, Building, Other) and ``/diagnostics_toplevel_state``
  1 Hz, STALE after 5 s.
- ``recorder``: ``/rosbag2_recorder``: serialized subscriptions to 19 topics as they appear (scan,
  odometry, ``/tf``, ``/tf_static``, cmd_vel, pose, plan, battery, ``/diagnostics``, states, orders,
  keypad, building topics, the map), drained by its writer thread at 10 Hz; "Writing to a new bag
  file" every 60 s.
- ``tablet`` (the operator): ``/hd/ward_tablet``, the nurse station's tablet app, joins at 25 s, exits
  with code 0 after 70 s and comes back 20 s later (connected ~25-95 s, ~115-185 s, ...): subscribes
  the compressed color stream (which starts the camera's lazy publisher: INFO "Color stream started"),
  the mission status, battery and ``/diagnostics_agg``; 3 s after connecting sets the touchscreen's
  ``announce_volume`` through ``/hd/hmi/touchscreen/set_parameters``.

Healthy dynamics (measured in 90-100 s smoke runs): the navigation servers active ~1 s after the
start; the first order at ~10 s; a delivery takes ~44-45 s on the same floor (measured) and ~60-80 s with the
elevator (legs of 6-11 m at up to 0.8 m/s, 0.45 in the quiet zones), then 5-20 s idle (the base
still, command topics silent, amcl's pose at 1 Hz). Steady: IMU 100 Hz, odometry and odom->base_link
20 Hz, scan 15 Hz, joint states 10 Hz, heartbeat 10 Hz, depth image/info 6 Hz, points 3 Hz, battery,
robot state, diagnostics and aggregated diagnostics 1 Hz. Bursty: cmd_vel_nav / cmd_vel (20 Hz while
driving), plans (1 Hz while driving), amcl pose (5 Hz moving, 1 Hz still), keypad, door and elevator
calls, drawer states, mission status, the compressed color stream (tablet only), teleop (after a
failure only).

Load (psutil, 10 s windows, the monitor not running, 2-core VM): ~53-72 % of one core in total
(mean ~60 %):
nav_container 17-24 %, sensor_container ~10 %, base 11-13 %, recorder 7-9 %, safety 4-6 %, every
other process about 1 %.

The faults (injected 120 s after the start: the tablet's second session connected, the robot in its
second or third delivery), each with its true root cause (the target node):

- ``crash_mission_executor``: the mission process is SIGKILLed: its robot state stops; the fleet
  server ERRORs "Robot hd_01: no state for 5.0 s, marking it lost" and dispatches nothing more; a
  navigation goal under way finishes (the navigator drives on to its goal), then the robot stands;
  the mission status stays latched at its last value. Root cause /hd/mission_executor.
- ``hang_depth_camera``: the camera's UVC read blocks without a timeout inside the single-threaded
  sensor container: ``/hd/depth_camera/*``, ``/hd/scan`` and ``/hd/imu/data`` all stop (the three
  nodes stay in the graph); the safety monitor stops the base ("scan data stale"), amcl WARNs "No
  laser scan received" every 5 s and publishes no pose, the base WARNs "IMU timeout", navigation
  fails (localization lost / no progress, ERRORs), the mission fails its order (ERROR), the fleet
  re-queues it (WARN), remote teleop drives briefly, again and again. Root cause /hd/depth_camera.
- ``hang_planner_server``: the planner's global-costmap timer deadlocks on its mutex inside the
  multi-threaded nav container: its group never runs again, so ``/hd/compute_path_to_pose`` and its
  ``get_state`` go unanswered, while amcl, the controller, the map server and the navigator go on
  (their groups are free). The lifecycle manager ERRORs "CRITICAL FAILURE: SERVER planner_server IS
  DOWN ..." ~5 s later; the navigator's next (re-)plan times out (ERROR "compute_path_to_pose: planner
  server did not respond within 2.0 s"), the goal is aborted, the mission fails its order ("planner
  did not answer"), the fleet re-queues it, remote teleop drives, and every later order fails at its
  first plan; ``/hd/plan`` stops. Root cause /hd/planner_server.
- ``hang_building_gateway``: the gateway's OPC-UA session to the BMS is half-open: its link thread
  blocks and no door or elevator request completes; the service callbacks wait forever (after 4
  calls the executor's threads are all taken); ``/building/elevator/status`` and the gateway's
  diagnostics go on at their rates from the relay thread (the topics look healthy, the elevator's
  ``_service_event`` shows requests without responses). The mission's next door call times out after
  8 s (an elevator ride under way after 40 s): ERROR "Order failed in phase 'X': service
  /building/door/open did not answer within 8.0 s (door '...')", the fleet re-queues, every later
  order fails the same way. Root cause /building_gateway.
- ``degrade_imu``: the IMU's serial link drops 60 % of its frames: ``/hd/imu/data`` at ~40 Hz
  (measured 35-44) instead of 100; its frequency diagnostics WARN; the base controller WARNs "IMU rate
  40.0 Hz below 60 Hz ... yaw fused from wheel odometry only" every 5 s; deliveries go on. Root cause
  /hd/imu.
- ``stale_front_lidar``: the lidar loses its time sync and stamps its scans with its free-running
  clock 2 s behind: ``/hd/scan`` stays at 15 Hz (the safety monitor is content); amcl drops every
  scan (WARN "Message Filter dropping message ... earlier than all the data in the transform cache")
  and publishes no pose nor map->odom; the controller aborts "localization lost" (ERROR), the mission
  fails its order and every later one, the fleet re-queues them. Root cause /hd/front_lidar.
- ``qos_safety_monitor``: a redeployed safety.yaml makes the safety monitor re-create its scan
  subscription RELIABLE against the lidar's best-effort publisher (INFO "Parameters reloaded ...";
  rclpy's incompatible-QoS WARN): it receives nothing; 0.5 s later a protective stop "scan data
  stale", the heartbeat says STOP, the mux commands zero, the controller fails to make progress
  (ERROR, one backup recovery that goes nowhere), the mission fails (ERROR), the fleet re-queues;
  ``/hd/scan`` goes on at 15 Hz. Root cause /hd/safety_monitor.
- ``leak_rosbag2_recorder``: the recorder's write cache is never flushed: its process grows ~3 MB/s
  (measured 83 -> 230 MB in 50 s); recording goes on. Root cause /rosbag2_recorder.
- ``crashloop_drawer_controller``: a corrupt locker calibration table: the drawer controller starts,
  homes, publishes its latched state, and ~3 s later logs FATAL "Compartment 3 lock feedback out of
  range ... aborting" and exits (code 134); the launch file's respawn starts it again 1 s later: a
  restart loop every ~5 s (new pid each time; ``~/state`` re-latched, its diagnostics going STALE
  and back); a mission that calls ``~/open_drawer`` while it is down fails ("service ... not
  available" or no answer). Root cause /hd/drawer_controller.
- ``deactivate_amcl``: amcl's watchdog deactivates it (a misread laser model config): it stays in the
  graph and answers its lifecycle services (state inactive), but its pose, map->odom and particle
  cloud stop (the latched pose ages); the lifecycle manager WARNs "Managed node amcl reports state
  'inactive', expected 'active'"; the controller aborts "localization lost" (ERROR), the navigator
  rejects every later goal (pose stale), the mission fails each order (ERROR), the fleet re-queues
  them (WARN). Root cause /hd/amcl.
"""

from __future__ import annotations

import os
import sys

from bench.handwritten import Design, LaunchedRobot, main

for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

DESIGN = Design(
    module="bench.hospital.robot",
    nodes={
        "nav_container": (
            "/hd/map_server",
            "/hd/amcl",
            "/hd/planner_server",
            "/hd/controller_server",
            "/hd/behavior_server",
            "/hd/bt_navigator",
            "/hd/lifecycle_manager_navigation",
        ),
        "sensor_container": ("/hd/front_lidar", "/hd/depth_camera", "/hd/imu"),
        "base": ("/hd/base_controller", "/hd/battery_monitor", "/hd/motor_driver"),
        "robot_state_publisher": ("/hd/robot_state_publisher",),
        "safety": ("/hd/safety_monitor", "/hd/cmd_vel_mux"),
        "teleop": ("/hd/remote_teleop",),
        "mission": ("/hd/mission_executor",),
        "drawers": ("/hd/drawer_controller",),
        "hmi": ("/hd/hmi/touchscreen",),
        "building_gateway": ("/building_gateway",),
        "fleet_server": ("/fleet_server",),
        "diagnostics": ("/diagnostic_aggregator",),
        "recorder": ("/rosbag2_recorder",),
        "tablet": ("/hd/ward_tablet",),
    },
    faults={
        "crash_mission_executor": ("kill", "/hd/mission_executor", "mission"),
        "hang_depth_camera": ("file:hang", "/hd/depth_camera", "sensor_container"),
        "hang_planner_server": ("file:hang", "/hd/planner_server", "nav_container"),
        "hang_building_gateway": ("file:hang", "/building_gateway", "building_gateway"),
        "degrade_imu": ("file:degrade", "/hd/imu", "sensor_container"),
        "stale_front_lidar": ("file:stale", "/hd/front_lidar", "sensor_container"),
        "qos_safety_monitor": ("file:reliable", "/hd/safety_monitor", "safety"),
        "leak_rosbag2_recorder": ("leak", "/rosbag2_recorder", "recorder"),
        "crashloop_drawer_controller": ("respawn:crashloop", "/hd/drawer_controller", "drawers"),
        "deactivate_amcl": ("file:deactivate", "/hd/amcl", "nav_container"),
    },
    operator="tablet",
    join_s=25.0,
    run_s=70.0,
    again_s=20.0,
)
NODES, FAULTS = DESIGN.nodes, DESIGN.faults
if __name__ == "__main__":
    sys.exit(
        main(
            None,
            __doc__,
            "hospital",
            LaunchedRobot,
            DESIGN,
            120.0,
            "s from the start to the injection (120: the tablet's second session connected, the robot "
            "in its second or third delivery)",
        )
    )
