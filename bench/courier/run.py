"""Run the sidewalk courier robot under the monitor: healthy run, injected faults.

``python -m bench.courier.run [--healthy S] [--warmup S] [--post S] [--faults a,b] [--out DIR]
[--samples DIR]``

The robot
=========
A six-wheeled sidewalk delivery robot ("courier", namespace ``/dlv``): locked cargo bay, LTE modem,
remote teleoperation by a human supervisor when it is stuck, GNSS + wheel odometry + IMU
localization, a camera and a 2D lidar for obstacles and crosswalks, a traffic-light (pedestrian
signal) detector used at crossings, a mission executive taking orders from a fleet cloud bridge,
a lifecycle-managed navigation stack, a velocity mux with a safety stop, a diagnostic aggregator,
a bag recorder and a remote-ops console that joins late and leaves. One module runs every process:
``python -m bench.courier.robot PROCESS FAULT_DIR [RUN_FOR]``. 16 processes, 29 nodes, real rclpy
nodes on wall time; everything under ``/dlv`` except /tf, /tf_static, /diagnostics,
/diagnostics_agg, /robot_description, /rosout, /parameter_events and two infrastructure nodes.

QoS names below: SENSOR = best effort, keep last 5, volatile (``qos_profile_sensor_data``);
RELIABLE = reliable, keep last 10, volatile; LATCHED = reliable, keep last 1, transient local;
TF = reliable, depth 100; TF_STATIC = reliable, depth 10, transient local.

Processes → nodes (executor)
----------------------------
- ``sensor_container`` (component container, ONE SingleThreadedExecutor: a blocked callback starves
  all four): /dlv/gnss_driver, /dlv/imu_driver, /dlv/wheel_odometry, /dlv/battery_monitor
- ``lidar`` (single): /dlv/lidar_driver
- ``camera_container`` (container, SingleThreadedExecutor, one callback group per node):
  /dlv/front_camera, /dlv/image_compressor
- ``uplink`` (single): /dlv/video_uplink
- ``perception`` (container, SingleThreadedExecutor): /dlv/obstacle_tracker, /dlv/crosswalk_detector
- ``traffic_light`` (single; joins late: "loads its TensorRT engine" 7–9 s before creating its
  node): /dlv/traffic_light_detector
- ``localization`` (container, SingleThreadedExecutor): /dlv/ekf_filter, /dlv/navsat_transform
- ``navigation`` (container, MultiThreadedExecutor with 3 threads and callback groups: the planner's
  service in its own mutually exclusive group, its publisher timer in another, the costmap's scan +
  timer in a third, the follower's subscriptions in a fourth, the action server in a reentrant
  group; all three are lifecycle nodes): /dlv/route_planner, /dlv/local_costmap, /dlv/path_follower
- ``executive`` (container, SingleThreadedExecutor, asynchronous clients only):
  /dlv/mission_executive, /dlv/lifecycle_manager
- ``safety`` (container, single): /dlv/velocity_mux, /dlv/safety_monitor
- ``motion`` (container, single): /dlv/motor_controller, /dlv/cargo_bay
- ``comms`` (container, single): /dlv/cellular_modem, /dlv/teleop_gateway
- ``cloud_bridge`` (single): /dlv/fleet_bridge
- ``infra`` (root infrastructure, single): /robot_state_publisher, /diagnostic_aggregator
- ``recorder`` (single): /dlv/data_recorder
- ``console`` (the operator: joins 30 s after the start, runs 60 s, exits with code 0, comes back
  25 s later, and so on): /dlv/remote_console

Topics (type, rate, QoS, publisher → subscribers, when)
-------------------------------------------------------
- /dlv/gnss/fix sensor_msgs/NavSatFix 5 Hz SENSOR, gnss_driver → navsat_transform, data_recorder;
  stamped 80–110 ms in the past (solution latency); status GBAS (RTK fixed) or SBAS (RTK float,
  under trees, larger covariance)
- /dlv/imu/data sensor_msgs/Imu 25 Hz SENSOR, imu_driver → ekf_filter; stamp 4 ms old; noise larger
  while moving
- /dlv/motor/joint_states sensor_msgs/JointState (6 wheels) 20 Hz SENSOR, motor_controller →
  wheel_odometry
- /dlv/wheel/odom nav_msgs/Odometry 20 Hz SENSOR, wheel_odometry (one per encoder update, stamped
  with the joint states' stamp) → ekf_filter
- /dlv/battery sensor_msgs/BatteryState 1 Hz RELIABLE, battery_monitor → data_recorder
- /dlv/scan sensor_msgs/LaserScan (360 beams) 10 Hz SENSOR, lidar_driver → local_costmap,
  safety_monitor, obstacle_tracker; stamped at the start of the revolution (100 ms old);
  pedestrians appear as close returns ahead
- /dlv/front_camera/image_raw sensor_msgs/Image 64×48 rgb8 (downscaled for the bench) 10 Hz SENSOR,
  front_camera → image_compressor, obstacle_tracker, crosswalk_detector, video_uplink,
  traffic_light_detector (only while a crosswalk is right ahead: it subscribes then, unsubscribes
  after); stamp 35 ms old (mid-exposure)
- /dlv/front_camera/camera_info sensor_msgs/CameraInfo 10 Hz SENSOR, front_camera
- /dlv/front_camera/image_raw/compressed sensor_msgs/CompressedImage 10 Hz SENSOR, image_compressor
  → remote_console: published ONLY while someone subscribes (image_transport's lazy publisher)
- /dlv/uplink/video sensor_msgs/CompressedImage SENSOR, video_uplink (stand-in for the WebRTC
  stream): 10 fps at HIGH, 5 at MEDIUM, 2 at LOW — the rate follows the modem's link quality
- /dlv/uplink/stats std_msgs/String (JSON: mode, fps, kbps) 1 Hz RELIABLE, video_uplink →
  teleop_gateway, remote_console
- /dlv/modem/link_quality std_msgs/Float32 1 Hz RELIABLE, cellular_modem → video_uplink
- /dlv/obstacles geometry_msgs/PoseArray RELIABLE, obstacle_tracker → path_follower: 10 Hz ONLY while
  something is within 5 m ahead (pedestrians), nothing otherwise; the tracker's CPU rises then
- /dlv/crosswalk geometry_msgs/PolygonStamped 5 Hz RELIABLE (every other camera frame; empty polygon:
  none in view), crosswalk_detector → traffic_light_detector, mission_executive
- /dlv/traffic_light std_msgs/String (JSON: state red/green, confidence, image stamp) RELIABLE,
  traffic_light_detector → mission_executive: ~10 Hz ONLY while waiting at a crossing
- /dlv/odometry/filtered nav_msgs/Odometry 10 Hz RELIABLE, ekf_filter → navsat_transform,
  path_follower, data_recorder
- /dlv/odometry/gps nav_msgs/Odometry 5 Hz RELIABLE (one per fresh fix), navsat_transform
- /tf geometry_msgs/TransformStamped TF: odom→base_link 10 Hz (ekf_filter), map→odom 5 Hz
  (navsat_transform, stamped 0.2 s in the FUTURE on purpose, like AMCL's transform_tolerance)
- /tf_static geometry_msgs/TransformStamped TF_STATIC, 5 messages once (robot_state_publisher) →
  data_recorder; /robot_description std_msgs/String LATCHED once
- /dlv/local_costmap/costmap nav_msgs/OccupancyGrid 40×40 2 Hz RELIABLE, local_costmap (while
  active) → path_follower
- /dlv/route nav_msgs/Path LATCHED, route_planner, once per planned route
- /dlv/route_progress std_msgs/Float32 2 Hz RELIABLE, route_planner (while active)
- /dlv/autonomy/cmd_vel geometry_msgs/Twist 10 Hz RELIABLE, path_follower → velocity_mux, ONLY while
  a route is followed (0.5 m/s while obstacles are tracked, 1.4 m/s otherwise)
- /dlv/teleop/cmd_vel geometry_msgs/Twist 10 Hz RELIABLE, teleop_gateway → velocity_mux, ONLY while
  the supervisor drives (the robot is stuck)
- /dlv/safety/stop std_msgs/Bool LATCHED, safety_monitor → velocity_mux, mission_executive,
  data_recorder: on change (obstacle closer than 0.6 m, or lidar silent 1 s)
- /dlv/cmd_vel geometry_msgs/TwistStamped 10 Hz RELIABLE, velocity_mux → motor_controller,
  data_recorder: always (zero when no input is fresh or the safety stop is set)
- /dlv/velocity_mux/active std_msgs/String LATCHED, on change (idle/autonomy/teleop/safety_stop)
- /dlv/mission/state std_msgs/String (JSON) LATCHED, mission_executive, on change →
  fleet_bridge, remote_console, data_recorder; /dlv/mission/assistance std_msgs/Bool LATCHED →
  teleop_gateway
- /dlv/fleet/order std_msgs/String (JSON) LATCHED, fleet_bridge, once per delivery round;
  /dlv/fleet/heartbeat std_msgs/Header 1 Hz RELIABLE → mission_executive
- /dlv/cargo_bay/state std_msgs/String LATCHED, cargo_bay, on change
- /diagnostics diagnostic_msgs/DiagnosticArray 1 Hz per hardware node RELIABLE (gnss_driver,
  imu_driver, battery_monitor, lidar_driver, front_camera, video_uplink, motor_controller,
  cargo_bay, cellular_modem), status names "node_name: task", hardware_id set
  → diagnostic_aggregator → /diagnostics_agg 1 Hz RELIABLE, paths such as
  "/Sensors/GNSS/gnss_driver: fix" plus group summaries (/Sensors, /Drive, /Comms, /Power,
  /Payload); a status not refreshed for 5 s becomes STALE → remote_console, data_recorder
- lifecycle transition_event topics of the three navigation nodes

Services, actions, parameters
-----------------------------
- /dlv/plan_route nav_msgs/srv/GetPlan (route_planner; mission_executive calls it at the start of
  every driving leg, 5 s timeout)
- /dlv/follow_route action, test_msgs/action/Fibonacci as a stand-in for nav2's FollowPath
  (order = waypoints, feedback = waypoints passed), path_follower; mission_executive sends a goal
  per leg and per crossing
- /dlv/cargo_bay/unlock std_srvs/srv/Trigger (cargo_bay; called at every drop-off, relocks in 7 s)
- /dlv/<route_planner|local_costmap|path_follower>/change_state and get_state (lifecycle_msgs):
  lifecycle_manager configures then activates them at start (≈5 s) and polls get_state every 2 s;
  /dlv/lifecycle_manager/is_active std_srvs/Trigger
- /dlv/velocity_mux parameters max_linear_speed (1.6) and max_angular_speed (1.0): the console
  sets max_linear_speed to 1.2 m/s 4 s after it joins and back to 1.6 m/s 6 s before it leaves
  (rcl_interfaces SetParameters; the mux logs each change)

Substitutes for missing message packages: tf2_msgs/TFMessage → one geometry_msgs/TransformStamped
per message on /tf and /tf_static; nav2_msgs FollowPath → test_msgs/action/Fibonacci; vision_msgs
detections → geometry_msgs/PoseArray (obstacles), geometry_msgs/PolygonStamped (crosswalk),
std_msgs/String JSON (traffic light); the WebRTC stream → sensor_msgs/CompressedImage;
diagnostic_updater → a small helper publishing DiagnosticArray; rosbag2 → a raw-subscription node.

Healthy dynamics: the world schedule
------------------------------------
Every process computes the same world from the wall clock (`robot.world`): 120 s delivery rounds,
each seeded from its index: idle at the hub 8–14 s (the fleet bridge posts the round's order),
driving 12–20 s, a crossing 7–12 s (red, then green for the last 3.5 s: the detector runs, the
executive sends a short crossing goal on WALK), driving 10–18 s, with probability 0.7 stuck 8–14 s
(the executive WARNs and requests assistance, the supervisor takes over after 2 s and the mux
switches to teleop), driving 6–12 s, delivering 8–12 s (cargo bay unlocked), then driving back
(with a second crossing when there is time). Pedestrians come into view in about two thirds of the
longer driving legs (3–7 s, sometimes closer than 0.6 m: a brief protective stop, INFO) and at the
start of every crossing. Under trees (1–2 × 6–15 s per round) the GNSS drops to RTK float (WARN, then
INFO when fixed again); in weak coverage (1–2 × 8–25 s per round) the modem WARNs "signal weak" and
the uplink steps down HIGH→MEDIUM→LOW (WARN) and back up after 5 s of good link (INFO). A 10-minute
run shows each of these several times. Other healthy log lines: the recorder's INFO every 60 s (bag
split), route plans, goals, mux source changes, the console's INFO while it is present.

Load at rest: 49–57 % of ONE core in total for the 15 always-on processes (psutil, sum of the
processes' CPU over 30 s windows, four windows, measured on the 2-core bench machine; the upper
end while driving with pedestrians in view); the busiest are navigation (~10 %, the
MultiThreadedExecutor), sensor_container and localization (~8 % each); ~1.5 % each for the quiet ones.

Faults (12), each with its root cause and what a user sees
-----------------------------------------------------------
- crash_fleet_bridge (file:crash → /dlv/fleet_bridge, cloud_bridge): a new cloud release sends an
  order without its drop-off block; the bridge's parser raises KeyError in its timer, the process
  prints the traceback and exits 1. /dlv/fleet/heartbeat stops; the executive WARNs "fleet bridge
  heartbeat lost" every 15 s and, from the next round, "no delivery order ... staying at the hub".
- hang_imu_driver (file:hang → /dlv/imu_driver, sensor_container): the IMU's serial bridge stops
  answering and the driver's read() never returns inside the single-threaded container: imu, gnss,
  wheel odometry and battery all stop (nothing logged by the container); ekf_filter WARNs no IMU /
  no wheel odometry, navsat_transform WARNs no GNSS fix, /diagnostics_agg marks the four STALE.
- hang_route_planner (file:hang → /dlv/route_planner, navigation): the planner's service callback
  blocks forever (tile cache lock); /dlv/route_progress and the rest of the container go on; every
  driving leg the executive ERRORs "plan_route did not answer within 5.0 s" and fails the leg, the
  fleet bridge WARNs the failed leg.
- degraded_lidar (file:degraded → /dlv/lidar_driver, lidar): a failing Ethernet link: /dlv/scan
  drops from 10 Hz to ~1.7 Hz; the driver WARNs incomplete revolutions every 15 s, its diagnostic
  WARNs; local_costmap WARNs its scan observation buffer is not updated in time.
- stale_gnss (file:stale → /dlv/gnss_driver, sensor_container): the receiver loses PPS time sync and
  stamps fixes ~4.5–4.8 s in the past while keeping 5 Hz; navsat_transform WARNs "GNSS fix is 4.7 s
  old; discarding it" and /dlv/odometry/gps stops.
- leak_recorder (leak → /dlv/data_recorder, recorder): its buffer grows ~3 MB/s, nothing logged.
- qos_safety_monitor (restart:qos → /dlv/safety_monitor, safety): a redeploy with a new parameter
  file makes its /dlv/scan subscription RELIABLE against the best-effort lidar: rclpy WARNs the
  incompatible QoS, nothing arrives; after 1 s the monitor ERRORs and asserts the protective stop,
  the mux WARNs and commands zero, the executive ERRORs "safety stop held for 10 s" and fails legs.
- deactivate_costmap (file:deactivate → /dlv/local_costmap, navigation): the costmap ERRORs that the
  sensor origin is out of map bounds and deactivates itself; its costmap stops, path_follower ERRORs
  "local costmap is ... old; aborting route", the executive fails legs, lifecycle_manager ERRORs
  every 10 s that the node is 'inactive'.
- crashloop_uplink (respawn:abort → /dlv/video_uplink, uplink): a broken encoder driver: 2–3 s after
  each start the pipeline logs FATAL and aborts (SIGABRT); launch respawns it 1 s later, forever;
  /dlv/uplink/* come and go, diagnostics of the encoder go stale, the teleop gateway WARNs the
  supervisor is driving blind while it drives.
- cpu_traffic_light (cpu → /dlv/traffic_light_detector, traffic_light): the GPU context fails; the
  detector WARNs it falls back to CPU inference and the process burns a core; at crossings its
  inference takes >1 s (WARN), its output drops to <1 Hz and the executive WARNs the detection is
  late / missing and holds at the crosswalk.
- error_motor_controller (file:error → /dlv/motor_controller, motion): a CAN error on the encoder
  bus: the controller ERRORs once, its diagnostic goes ERROR and /dlv/motor/joint_states stops while
  it still consumes /dlv/cmd_vel; wheel_odometry WARNs no encoder data, /dlv/wheel/odom stops,
  ekf_filter WARNs no wheel odometry.
- kill_perception (kill → /dlv/obstacle_tracker, perception): the OOM killer SIGKILLs the perception
  container (no log line): /dlv/crosswalk and /dlv/obstacles stop; the executive WARNs "no crosswalk
  detections", the traffic light detector never wakes up, the executive holds at crossings.
"""

from __future__ import annotations

import os
import sys

from bench.handwritten import Design, LaunchedRobot, main

for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

DESIGN = Design(
    module="bench.courier.robot",
    nodes={
        "sensor_container": ("/dlv/gnss_driver", "/dlv/imu_driver", "/dlv/wheel_odometry",
                             "/dlv/battery_monitor"),
        "lidar": ("/dlv/lidar_driver",),
        "camera_container": ("/dlv/front_camera", "/dlv/image_compressor"),
        "uplink": ("/dlv/video_uplink",),
        "perception": ("/dlv/obstacle_tracker", "/dlv/crosswalk_detector"),
        "traffic_light": ("/dlv/traffic_light_detector",),
        "localization": ("/dlv/ekf_filter", "/dlv/navsat_transform"),
        "navigation": ("/dlv/route_planner", "/dlv/local_costmap", "/dlv/path_follower"),
        "executive": ("/dlv/mission_executive", "/dlv/lifecycle_manager"),
        "safety": ("/dlv/velocity_mux", "/dlv/safety_monitor"),
        "motion": ("/dlv/motor_controller", "/dlv/cargo_bay"),
        "comms": ("/dlv/cellular_modem", "/dlv/teleop_gateway"),
        "cloud_bridge": ("/dlv/fleet_bridge",),
        "infra": ("/robot_state_publisher", "/diagnostic_aggregator"),
        "recorder": ("/dlv/data_recorder",),
        "console": ("/dlv/remote_console",),
    },
    faults={
        "crash_fleet_bridge": ("file:crash", "/dlv/fleet_bridge", "cloud_bridge"),
        "hang_imu_driver": ("file:hang", "/dlv/imu_driver", "sensor_container"),
        "hang_route_planner": ("file:hang", "/dlv/route_planner", "navigation"),
        "degraded_lidar": ("file:degraded", "/dlv/lidar_driver", "lidar"),
        "stale_gnss": ("file:stale", "/dlv/gnss_driver", "sensor_container"),
        "leak_recorder": ("leak", "/dlv/data_recorder", "recorder"),
        "qos_safety_monitor": ("restart:qos", "/dlv/safety_monitor", "safety"),
        "deactivate_costmap": ("file:deactivate", "/dlv/local_costmap", "navigation"),
        "crashloop_uplink": ("respawn:abort", "/dlv/video_uplink", "uplink"),
        "cpu_traffic_light": ("cpu", "/dlv/traffic_light_detector", "traffic_light"),
        "error_motor_controller": ("file:error", "/dlv/motor_controller", "motion"),
        "kill_perception": ("kill", "/dlv/obstacle_tracker", "perception"),
    },
    operator="console",
    join_s=30.0, run_s=60.0, again_s=25.0,
)
NODES, FAULTS = DESIGN.nodes, DESIGN.faults

if __name__ == "__main__":
    sys.exit(main(None, __doc__, "courier", LaunchedRobot, DESIGN, 130.0,
                  "s from the start to the injection (130: past the lifecycle bring-up, the traffic "
                  "light model load, the console's first visit and at least one full delivery round)"))
