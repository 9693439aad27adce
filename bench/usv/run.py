"""Run the harbour patrol surface vessel (USV) under the monitor: healthy run, injected faults.

``python -m bench.usv.run [--healthy S] [--warmup S] [--post S] [--faults a,b] [--out DIR]
[--samples DIR] [--from-healthy RUN.sqlite]``

The robot's processes (`bench.usv.robot`) under the in-process monitor, as every hand-written robot
runs (`bench.handwritten`: the runs, their scores, the files written). ``usv`` is a 7 m autonomous
harbour patrol / survey boat working Kiel harbour: twin electric thrusters, an ArduPilot Rover
(frame BOAT) flight controller bridged by a mavros-like process (IMU and RTK GNSS relayed from the
FCU), a ros2_control-style thruster controller, a lifecycle-managed marine radar with an ARPA-like
tracker, an AIS receiver, a visible and a thermal camera with a vessel detector, a fused obstacle
map, COLREGs collision avoidance, a command mux (mission < avoidance < remote operator),
robot_localization-style navsat_transform + EKF, a mission executive that drives waypoint legs
through a route planner service and a leg action and puts the radar to standby in the marina's
no-transmit zone, a shore telemetry relay over an intermittent radio, a rosbag-like recorder and the
harbour master's shore console. Laid out as a production ROS 2 Jazzy team lays it out: a
single-threaded camera component container, a multi-threaded perception container with callback
groups, a controller manager with its realtime update thread, a lifecycle radar driver and its
lifecycle manager. Everything is under ``/usv`` except ``/tf``, ``/tf_static``, ``/diagnostics``,
``/diagnostics_agg``, ``/rosout``, ``/parameter_events`` and the infrastructure node
``/diagnostic_aggregator``. Wall time everywhere.

The sea: one schedule shared by every process through the wall clock (`bench.usv.robot.contacts`,
`bench.usv.robot.link_up`): four traffic slots of 45 s epochs; in 60 % of them a vessel passes for
10-25 s, from 1.5-2.8 km in to its closest point of approach (150-1100 m) and out again (~1 vessel
around on average, 0-4; within 600 m ~6 % of the time); each sends AIS at its own random rate
(Poisson, 0.5/0.33 Hz Class A, 0.1 Hz Class B). The shore radio is down for 3-6 s in 65 % of the
minutes.

Substitutes (not installed here: mavros_msgs, radar_msgs, marine_sensor_msgs, vision_msgs,
nav2_msgs, tf2_msgs, control_msgs, diagnostic_updater, rosbag2): ``/tf`` and ``/tf_static`` carry
geometry_msgs/TransformStamped, one transform a message; the radar's revolution is a
sensor_msgs/Image (1024 spokes x 128 range bins mono8, 128 KB); the mavros state, mode, AIS
messages, mission state, mux input and controller activity are std_msgs/String (JSON or a word);
``set_mode`` and ``set_transmit`` are std_srvs/SetBool; the route planner is nav_msgs/GetPlan; the
leg action (nav2 FollowWaypoints-like) is test_msgs/Fibonacci (``order`` = the leg's seconds;
feedback ``sequence[0]`` = metres to go; result ``sequence[0]`` 0 reached, 5 canceled); radar
tracks, detections and obstacles are geometry_msgs/PoseArray; the diagnostic updaters are a timer
each (statuses named ``node: task`` with a ``hardware_id``).

QoS: "sensor" best effort keep-last 5 (``/usv/mavros/imu/data``,
``/usv/mavros/global_position/raw/fix``, ``/usv/radar/scan``, both cameras'
``image_raw/compressed``, ``/usv/shore/camera/compressed``), "command" reliable keep-last 1
(``/usv/cmd_vel_mission``, ``/usv/cmd_vel_avoid``, ``/usv/cmd_vel_teleop``), "reliable" keep-last 10
(everything else: ``/usv/cmd_vel``, odometry, tracks, AIS, obstacles, thruster states, mavros
state and battery, shore relays, ``/tf``, ``/diagnostics``, ``/diagnostics_agg``), "latched" reliable
transient-local depth 1 (``/usv/mavros/mode``, ``/usv/mission_executive/state``,
``/usv/cmd_vel_mux/active``, ``/usv/controller_manager/activity``, ``/usv/robot_description``),
``/tf_static`` transient-local depth 100. Several publishers: ``/diagnostics`` (14 statuses from 11
nodes), ``/tf`` (the EKF's odom->base_link 20 Hz, the thermal camera's pan-tilt 4.5 Hz).

Processes -> nodes (13 processes, 26 nodes; the shore console comes and goes):

- ``autopilot_bridge`` (mavros-like, ONE SingleThreadedExecutor, the router and two plugins):
  ``/usv/mavros`` (FCU heartbeat 1 Hz -> ``/usv/mavros/state`` 1 Hz and ``/usv/mavros/battery`` 1 Hz;
  ``/usv/mavros/mode`` latched on change, HOLD at start, GUIDED/HOLD through ``/usv/mavros/set_mode``;
  INFO "FCU: Arming motors" 3 s after start; WARN "FCU: EKF3 IMU0 MAG0 ground mag anomaly ..." every
  80-170 s; diagnostics FCU connection + battery), ``/usv/mavros/imu`` (``/usv/mavros/imu/data`` Imu
  50 Hz, stamped 4 ms before publishing), ``/usv/mavros/global_position``
  (``/usv/mavros/global_position/raw/fix`` NavSatFix RTK fix 10 Hz, stamped 80 ms before publishing
  through the FCU's TIMESYNC).
- ``thruster_control`` (ros2_control_node-like: MultiThreadedExecutor 2 threads + the
  ``cm_update_loop`` thread at 50 Hz): ``/usv/controller_manager`` (loads and activates both
  controllers at start, ``~/activity`` latched; WARN "Overrun detected! ... missed its desired rate of
  50 Hz ..." every 90-200 s; diagnostics activity + hardware), ``/usv/thruster_state_broadcaster``
  (``/usv/thruster_states`` JointState 50 Hz from the loop), ``/usv/thrust_allocator``
  (``/usv/cmd_vel`` -> differential thrust, 0.5 s command timeout).
- ``radar_driver``: ``/usv/radar`` (lifecycle node, configured and activated by the lifecycle
  manager; ``/usv/radar/scan`` one 128 KB revolution every 2.5 s (24 rpm, 0.4 Hz) while active,
  stamped half a revolution back; ``~/transition_event``; parameter ``range_m`` 3000/1500 set by the
  mission each cycle, INFO "Range set to 1500 m (pulse short)"; WARN "Sea clutter high ..." every
  70-160 s; diagnostics Transmitting/Standby).
- ``ais``: ``/usv/ais_receiver`` (dAISy on /dev/ttyUSB1 polled at 10 Hz; ``/usv/ais/messages`` one per
  received report: irregular, ~0.2-0.8 Hz, rate changes as ships come and go, none when no ship;
  INFO "New AIS target MMSI ..."; WARN "NMEA checksum mismatch ..." every 60-150 s).
- ``camera_container`` (component container, ONE SingleThreadedExecutor): ``/usv/camera``
  (Blackfly S: ``/usv/camera/image_raw/compressed`` 37 KB JPEG at 10 Hz), ``/usv/thermal_camera``
  (Boson 640: ``/usv/thermal_camera/image_raw/compressed`` 14 KB at 9 Hz; ``/tf``
  ptu_base->thermal_optical_frame at 4.5 Hz; a flat field correction every 60-120 s, INFO "Running
  flat field correction (shutter)", 0.25 s blocking on its serial port). Diagnostics each.
- ``perception`` (component_container_mt: MultiThreadedExecutor, 2 threads, a MutuallyExclusive
  group each; a Python container: a crash ends it as Python does, ``ROBOT_PYTHON_EXIT=1``, its
  nodes deregistering): ``/usv/radar_tracker`` (scan -> ``/usv/radar/targets`` 0.4 Hz, none while
  the radar stands by; INFO "N radar tracks (was M)"), ``/usv/vessel_detector`` (YOLO on the GPU,
  10-20 ms a frame on every visible frame; ``/usv/vessel_detector/detections`` only when a ship is
  ahead within 1.2 km, ~0.2 Hz, bursty), ``/usv/obstacle_map`` (tracks + AIS + detections ->
  ``/usv/obstacles`` 2 Hz; WARN "No radar targets ... for N s: obstacle map from AIS and camera only"
  every 10 s when no tracks for 10 s outside the no-transmit zone -- never in a healthy run).
- ``localization`` (component container, ONE SingleThreadedExecutor): ``/usv/navsat_transform``
  (fix -> ``/usv/odometry/gps`` 10 Hz, stamped as the fix), ``/usv/ekf_filter_node`` (IMU + GNSS ->
  ``/usv/odometry/filtered`` and odom->base_link on ``/tf`` 20 Hz; diagnostics "imu topic status"
  (45-55 Hz expected) and "Filter"), ``/usv/robot_state_publisher`` (``/usv/robot_description`` and
  6 static transforms latched).
- ``guidance`` (MultiThreadedExecutor, 3 threads, groups): ``/usv/route_planner``
  (``/usv/route_planner/plan_route`` GetPlan on the ENC charts, 80-300 ms), ``/usv/waypoint_follower``
  (``/usv/waypoint_follower/follow_leg`` action: 12 s legs, ``/usv/cmd_vel_mission`` 10 Hz and
  feedback 2 Hz ONLY during legs), ``/usv/colregs_avoidance`` (``/usv/obstacles`` ->
  ``/usv/cmd_vel_avoid`` 10 Hz ONLY while a contact is within ``safe_range_m`` (600 m, changed at
  runtime by the shore console), INFO "Contact at N m bearing B deg: Rule 15 ...; altering course to
  starboard" / "Contact clear; resuming mission"), ``/usv/cmd_vel_mux`` (teleop > avoidance > mission
  into ``/usv/cmd_vel`` at the winning input's rate; ``~/active`` latched, INFO "Switched to input
  'X'").
- ``mission`` (MultiThreadedExecutor 2 threads; the mission and the bringup threads):
  ``/usv/mission_executive`` (a 60 s cycle from its start: three legs at 0, 15, 30 s, each a
  ``plan_route`` call (5 s timeout), ``~/route``, ``set_mode`` GUIDED and a 12 s leg goal; the radar's
  ``range_m`` 3000 before wp_1, 1500 before the inshore wp_3; at 45 s the marina's no-transmit zone:
  ``set_transmit false`` for 7 s then ``true``; ``~/state`` latched on change: ``transit:wp_N``,
  ``no_transmit_zone``, ``patrol``, ``holding``), ``/usv/lifecycle_manager`` (configures and activates
  the radar at start; ``~/set_transmit``; ``/usv/radar/get_state`` every 2 s; ERROR "CRITICAL
  FAILURE: SERVER radar IS DOWN ..." without an answer in 4 s; diagnostics 0.5 Hz, WARN when the
  radar's state is not the one it asked for).
- ``shore_link``: ``/usv/telemetry_relay`` (topic_tools throttle over the Silvus radio:
  ``/usv/odometry/filtered`` -> ``/usv/shore/odometry`` 2 Hz, ``/diagnostics_agg`` ->
  ``/usv/shore/diagnostics_agg`` 1 Hz, the visible camera -> ``/usv/shore/camera/compressed`` 1 Hz
  (subscribed with the QoS of its shore_relay.yaml, sensor_data); paused while the link is down:
  WARN "Radio link to shore lost ..." / INFO "... restored"; ``/usv/radio/link_quality`` 1 Hz, 0 while
  down; diagnostics).
- ``recorder``: ``/usv/rosbag_recorder`` JOINS LATE (15 s: the data disk is unlocked and mounted
  first); subscribes 10 topics (fix, filtered odometry, tracks, AIS, obstacles, ``/usv/cmd_vel``,
  thruster states, mission state, mavros state, ``/diagnostics``; not the IMU, which the FCU logs
  itself); INFO "Writing bag file ..." every 120 s; diagnostics 0.5 Hz.
- ``diagnostics``: ``/diagnostic_aggregator`` (``/diagnostics`` -> ``/diagnostics_agg`` 1 Hz with
  paths ``/USV/{Autopilot,Propulsion,Sensors,Perception,Localization,Mission,Communications,
  Logging,Other}/...``, STALE after 5 s).
- ``operator`` (the operator): ``/usv/operator_console``, the harbour master's shore console, joins at
  35 s, exits with code 0 after 50 s and comes back 30 s later (connected ~35-85 s, ~115-165 s, ...):
  subscribes the shore relays and the mission state; 5 s after connecting sets the avoidance's
  ``safe_range_m`` (500, 700 or 800 m); 20-23 s after connecting takes the helm on
  ``/usv/cmd_vel_teleop`` 10 Hz (the mux switches to teleop).

Healthy dynamics (measured 20-80 s after the start, rclpy probe, 30 s windows): IMU 50 Hz, thruster
states 50 Hz, ``/tf`` 24.5 msgs/s, filtered odometry 20 Hz, GNSS fix and ``/usv/odometry/gps`` 10 Hz,
visible camera 10 Hz, thermal 9 Hz, ``/diagnostics`` 10 arrays/s, obstacles 2 Hz, radar scan and
tracks 0.4 Hz (0 during the 7 s standby of each cycle), mavros state, battery, ``/diagnostics_agg``,
link quality 1 Hz; shore relays 2/1/1 Hz except during outages. Bursty or on demand: AIS (~0.2-0.8
Hz), detections (~0.2 Hz), ``/usv/cmd_vel_mission`` (36 s of each 60 s), ``/usv/cmd_vel_avoid`` (only
with a contact within range, ~6 % of the time), ``/usv/cmd_vel`` (follows its winning input),
teleop (3 s a console session), routes (3 a cycle), latched states on change. Lifecycle
transitions: the radar configured+activated at start, deactivated and activated every cycle.
Parameter changes: the radar's ``range_m`` (twice a cycle), the avoidance's ``safe_range_m`` (each
console session). Late joiners: the recorder (15 s), the console. Recurring WARNs: the FCU's mag
anomaly, the controller manager's overrun, the radar's sea clutter, the AIS checksum, the radio
link lost.

Load at rest (psutil, 2-core VM, the monitor not running, the console not connected): ~40 % of one
core in total over a 30 s window 15-45 s after the start (localization 7.5 %, recorder 6.6 %,
autopilot_bridge 5.6 %, perception and guidance 4.6 % each, thruster_control 4.2 %, shore_link
2.7 %, camera_container 1.7 %, every other process 1 % or less); a first layout with the recorder
on the IMU and the mission on the filtered odometry measured 48 %.

The faults (default injection 140 s after the start: the console's second session connected, the
mission in its third cycle, leg 2 starting ~2 s later, the next no-transmit zone at ~170 s), each
with its true root cause (the target node) and what a user sees:

- ``lag_global_position``: the FCU's TIMESYNC offset estimate runs away after a GNSS time jump: the
  fix keeps coming at 10 Hz but its stamps lag more and more (0.15 s more each second); nothing is
  logged by mavros; ``/usv/odometry/gps`` carries the same old stamps; ~7 s later the EKF WARNs
  "Measurement from /usv/odometry/gps is N s old, older than the history length (1.00 s); ignoring
  it" every 5 s, its "Filter" diagnostics WARN "GNSS not fused" and its position variance grows.
  Root cause /usv/mavros/global_position (process autopilot_bridge).
- ``rate_imu``: after an FCU parameter reset the imu plugin's SET_MESSAGE_INTERVAL is denied: WARN
  "IMU: SET_MESSAGE_INTERVAL for HIGHRES_IMU (20000 us) denied by FCU ..." once and
  ``/usv/mavros/imu/data`` falls from 50 to ~33 Hz (66 %); the EKF's imu topic status diagnostics
  WARN "Frequency too low". Root cause /usv/mavros/imu (process autopilot_bridge).
- ``hang_thermal_camera``: the Boson's flat field correction command gets no reply and its serial
  read has no timeout (blocked for good) inside the single-threaded camera container: INFO "Running
  flat field correction (shutter)" then both cameras' images, the pan-tilt ``/tf`` and their
  diagnostics stop (the two nodes stay in the graph; their diagnostics go STALE in the aggregator);
  downstream the detector and the shore camera relay fall silent. Root cause /usv/thermal_camera
  (process camera_container).
- ``crash_radar_tracker``: a pushed arpa.yaml has an empty clutter map section: INFO "Reloaded
  tracker config /opt/usv/config/arpa.yaml (clutter_map.cell_m: 0.0, ...)" and the same scan's
  callback raises an uncaught ``ZeroDivisionError``: the ``perception`` container exits with code
  1 (traceback in its log), its three nodes deregister; tracks, detections and ``/usv/obstacles``
  stop, so COLREGs avoidance no longer reacts. Root cause /usv/radar_tracker (process perception).
- ``cpu_vessel_detector``: TensorRT runs out of GPU memory: WARN "TensorRT: ... Error Code 1: Cuda
  Runtime (out of memory); falling back to ONNX Runtime CPUExecutionProvider (slow)", one core busy
  in the perception process, inference 5x slower, its diagnostics WARN "CPU fallback". Root cause
  /usv/vessel_detector (process perception).
- ``leak_rosbag_recorder``: the recorder's write cache is never flushed: the ``recorder`` process
  grows ~3 MB/s; nothing is logged; recording goes on. Root cause /usv/rosbag_recorder.
- ``slow_route_planner``: the ENC database's spatial index is rebuilt on every query: each
  ``plan_route`` takes 8-11 s; the mission ERRORs "Route planning to wp_N failed: service
  /usv/route_planner/plan_route did not answer within 5.0 s; holding station" at each leg, state
  ``holding``, mavros mode HOLD; no legs run (``/usv/cmd_vel_mission`` silent). Root cause
  /usv/route_planner (process guidance).
- ``zone_navsat_transform``: navsat_transform's UTM conversion flips zone at the datum: every
  ``/usv/odometry/gps`` is 400 km east; the EKF ERRORs "Rejecting /usv/odometry/gps: Mahalanobis
  distance ... exceeds threshold 25.0 (position jump 400012 m)" every 2 s, its diagnostics WARN "GNSS
  not fused", the variance grows; rates unchanged. Root cause /usv/navsat_transform (process
  localization).
- ``deactivate_radar``: a crew member types ``ros2 lifecycle set /usv/radar deactivate`` on the
  wrong terminal (a short-lived CLI process and its hidden node ``/_ros2cli_<pid>``,
  `UsvRobot.inject`'s ``lifecycle:`` kind): the radar logs "Transmit off: standby" at sea,
  ``/usv/radar/scan`` and the tracks stop, 10 s later the obstacle map WARNs "No radar targets on
  /usv/radar/targets for N s: obstacle map from AIS and camera only" every 10 s, the lifecycle
  manager's diagnostics WARN "radar inactive" (expected active); only the next no-transmit zone's
  exit reactivates it (the lifecycle manager skips the zone entry's deactivate, "radar already
  inactive"; with the default injection the zone entry comes ~27 s later, its exit ~34 s later).
  Root cause /usv/radar (process radar_driver).
- ``qos_telemetry_relay``: a redeployed shore_relay.yaml and a restart of the ``shore_link``
  process (new pid) make the relay subscribe the camera RELIABLE against its best-effort publisher:
  INFO "Loaded ... (camera qos: reliable, depth 5)", rclpy's incompatible-QoS WARNs on both sides
  ("New publisher discovered ... offering incompatible QoS" in the relay, "New subscription
  discovered ... requesting incompatible QoS" in the camera); ``/usv/shore/camera/compressed`` stops
  for good while odometry and diagnostics still reach shore. Root cause /usv/telemetry_relay
  (process shore_link).
- ``crashloop_ais_receiver``: a USB brownout re-enumerates the dAISy as /dev/ttyUSB2: FATAL "Serial
  read failed on /dev/ttyUSB1: device reports readiness to read but returned no data ..." and an
  uncaught OSError (exit 1) 1.5-2.5 s after each start; the launch file's respawn starts it again
  1 s later: a restart loop every ~3 s (new pid, its diagnostics gone and back, no AIS). Root cause
  /usv/ais_receiver (process ais).
"""

from __future__ import annotations

import os
import subprocess
import sys

from bench.handwritten import ROOT, Design, LaunchedRobot, main

for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

DESIGN = Design(
    module="bench.usv.robot",
    nodes={
        "autopilot_bridge": ("/usv/mavros", "/usv/mavros/imu", "/usv/mavros/global_position"),
        "thruster_control": (
            "/usv/controller_manager",
            "/usv/thruster_state_broadcaster",
            "/usv/thrust_allocator",
        ),
        "radar_driver": ("/usv/radar",),
        "ais": ("/usv/ais_receiver",),
        "camera_container": ("/usv/camera", "/usv/thermal_camera"),
        "perception": ("/usv/radar_tracker", "/usv/vessel_detector", "/usv/obstacle_map"),
        "localization": ("/usv/navsat_transform", "/usv/ekf_filter_node", "/usv/robot_state_publisher"),
        "guidance": (
            "/usv/route_planner",
            "/usv/waypoint_follower",
            "/usv/colregs_avoidance",
            "/usv/cmd_vel_mux",
        ),
        "mission": ("/usv/mission_executive", "/usv/lifecycle_manager"),
        "shore_link": ("/usv/telemetry_relay",),
        "recorder": ("/usv/rosbag_recorder",),
        "diagnostics": ("/diagnostic_aggregator",),
        "operator": ("/usv/operator_console",),
    },
    faults={
        "lag_global_position": ("file:lag", "/usv/mavros/global_position", "autopilot_bridge"),
        "rate_imu": ("file:rate", "/usv/mavros/imu", "autopilot_bridge"),
        "hang_thermal_camera": ("file:hang", "/usv/thermal_camera", "camera_container"),
        "crash_radar_tracker": ("file:crash", "/usv/radar_tracker", "perception"),
        "cpu_vessel_detector": ("cpu", "/usv/vessel_detector", "perception"),
        "leak_rosbag_recorder": ("leak", "/usv/rosbag_recorder", "recorder"),
        "slow_route_planner": ("file:slow", "/usv/route_planner", "guidance"),
        "zone_navsat_transform": ("file:zone", "/usv/navsat_transform", "localization"),
        "deactivate_radar": ("lifecycle:deactivate", "/usv/radar", "radar_driver"),
        "qos_telemetry_relay": ("restart:reliable", "/usv/telemetry_relay", "shore_link"),
        "crashloop_ais_receiver": ("respawn:crashloop", "/usv/ais_receiver", "ais"),
    },
    operator="operator",
    join_s=35.0,
    run_s=50.0,
    again_s=30.0,
)
NODES, FAULTS = DESIGN.nodes, DESIGN.faults


class UsvRobot(LaunchedRobot):
    """`LaunchedRobot` plus ``lifecycle:<transition>``: a crew member's ``ros2 lifecycle set <target>
    <transition>``, a short-lived CLI process (its own hidden node) calling the target's
    ``change_state``."""

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
            "usv",
            UsvRobot,
            DESIGN,
            140.0,
            "s from the start to the injection (140: the console's second session connected, the "
            "mission in its third cycle, the next radar standby ~30 s later)",
        )
    )
