"""Run the quadruped robot (a legged inspection robot) under the monitor: healthy run, injected faults.

``python -m bench.quadruped.run [--healthy S] [--warmup S] [--post S] [--faults a,b] [--out DIR]``

The robot's processes (`bench.quadruped.robot`) under the in-process monitor, as every hand-written
robot runs (`bench.handwritten`: the runs, their scores, the files written). An ANYmal/Spot-class
quadruped doing autonomous inspection rounds in a process plant, its stack as a production team lays
it out: a whole-body locomotion controller, a state estimator over the IMU and the legs, a lidar with
elevation mapping, nav2-style navigation (lifecycle nodes under a lifecycle manager with bonds, a
navigate_to_pose action, a twist mux), a docking server, a behaviour-tree mission executive and an
inspection payload (PTZ, thermal, gas, acoustic), with the platform's battery manager, diagnostics,
bag recorder, foxglove bridge and a remote operator station that comes and goes. Everything is under
``/quad`` except ``/tf``, ``/tf_static``, ``/diagnostics``, ``/diagnostics_agg``,
``/diagnostics_toplevel_state``, ``/rosout``, ``/diagnostic_aggregator``, ``/rosbag2_recorder`` and
``/foxglove_bridge``. All nodes are on wall time. The processes run rclpy's C++ EventsExecutor
(``rclpy.experimental``, for CPU), except the navigation container (rclpy's MultiThreadedExecutor, 5
threads, as nav2's ``component_container_mt``: the navigate_to_pose, follow_path and backup actions
block in their execute callbacks, each node's actions in a reentrant group, the BT navigator's
clients in another; the local costmap node spun by its own EventsExecutor thread, as nav2 does), the
docking server (MultiThreadedExecutor, 2 threads, its actions reentrant) and the inspection payload's
container (rclpy's SingleThreadedExecutor, one thread for its four nodes, as ``component_container``).
No tf2_msgs, nav2_msgs, trajectory_msgs nor control_msgs in this environment: ``/tf`` and
``/tf_static`` carry geometry_msgs/TransformStamped (one transform a message); every action is
test_msgs/Fibonacci (``order`` = the waypoint index, plan id, preset or cm to back up; the feedback's
``sequence`` the progress); the gait/contact state is a sensor_msgs/JointState (feet, contact flags,
the legs' body velocity vx, vy, wz, ``frame_id`` the gait); bond heartbeats std_msgs/Header
(``frame_id`` the managed node); the thermal capture a std_srvs/Trigger answering JSON; the gas
reading a std_msgs/Float32 (CH4, % LEL). QoS: "sensor" best effort keep-last 5 (IMU, lidar, gait
state, PTZ images, joystick), "command" reliable keep-last 1 (every cmd_vel), "reliable" keep-last 10
(joint states, odometry, elevation map, costmap, plan, bonds, diagnostics, gas, acoustic events,
battery, mission report), "latched" reliable transient-local (/tf_static, /quad/robot_description,
/quad/map, /quad/state_estimator/health, /quad/twist_mux/active, /quad/docking_server/state,
/quad/battery/status, /quad/mission/status).

The stack. Process ``locomotion``: ``/quad/locomotion_controller`` runs the whole-body control loop
at 400 Hz in its own thread (its diagnostics count cycles, overruns, jitter): it tracks
``/quad/cmd_vel`` (stands when no command came for 0.5 s or while the state estimate is not OK),
trots at 1.8 Hz when walking and publishes ``/quad/gait_state`` at 50 Hz walking, 10 Hz standing
(INFO "Gait: stand -> trot" and back at each start and stop; a WARN "Foot slip detected on XX"
about once a minute of walking); ``/quad/joint_state_broadcaster`` publishes ``/quad/joint_states``
(12 joints) at 100 Hz from the loop. ``/quad/imu_driver`` (process ``imu``): ``/quad/imu/data`` 200
Hz from its SPI thread, stamped at the sample (PTP time). Process ``state_estimation``:
``/quad/state_estimator`` updates on every IMU sample (rejecting samples whose stamp is more than
0.25 s off; INITIALIZING until the first one), takes the legs' velocity from the gait state,
publishes ``/quad/odom`` and odom -> base_link on ``/tf`` at 50 Hz and
``/quad/state_estimator/health`` latched (OK; DEGRADED after 0.5 s without a valid IMU sample: leg
odometry only, and the locomotion controller holds its stand);
``/quad/robot_state_publisher`` latches ``/quad/robot_description`` and the sensor mounts on
``/tf_static`` and publishes base_link -> each foot on ``/tf`` at 10 Hz from the joint states. The
lidar (``/quad/lidar/lidar_driver``, process ``lidar``): ``/quad/lidar/points`` (32 x 512 points,
262 KB) at 10 Hz, best effort, stamped at the scan (PTP); a WARN "Dropped n UDP packets" every ~35 s.
``/quad/elevation_mapping`` (process ``elevation_mapping``): every scan fused into a 6 x 6 m map;
every 5th scan the heavy update (smoothing, inpainting, traversability: a CPU burst of ~40 ms)
and ``~/elevation_map`` (OccupancyGrid, 2 Hz); a cloud more than 0.5 s old is dropped with tf2's
"Lookup would require extrapolation into the past" ERROR (1/s at most); a WARN every 5 s while the
map is not updated for 2 s. ``/quad/site_map_loader`` (process ``site_map_loader``) latches the
plant's 300 x 300 map on ``/quad/map`` and exits with code 0 after ~6 s.

Navigation (process ``navigation``, one container): ``/quad/lifecycle_manager_navigation``
configures then activates ``/quad/planner_server``, ``/quad/controller_server``,
``/quad/behavior_server`` and ``/quad/bt_navigator`` at start-up through their ``change_state``
services (nav2's INFO lines), then watches their bonds (a heartbeat each on ``/quad/bond`` every 1 s,
ERROR "Have not received a heartbeat from X" after 4 s) and answers ``~/is_active``. The planner
serves ``/quad/planner_server/compute_path`` (GetPlan; a wavefront over the inflated site map:
50-120 ms of CPU) and publishes each plan on ``/quad/plan``. The controller's ``/quad/follow_path``
action runs regulated pure pursuit at 20 Hz in its execute callback on ``/quad/cmd_vel_nav``, with
feedback at 5 Hz; it aborts when the elevation map (through its costmap node) is more than 2.5 s old
(ERROR "Elevation map is ... old: the local costmap is not current"), when it makes no progress
(0.25 m in 10 s) and, for ~6 % of the paths, on an obstacle crossing it (a WARN "Collision ahead");
``max_vel_x`` is a runtime parameter (0.5 m/s). ``/quad/local_costmap/local_costmap`` (the
controller's costmap node) keeps the pose from ``/quad/odom`` and the elevation map and publishes
``~/costmap`` at 1 Hz. ``/quad/bt_navigator`` serves ``/quad/navigate_to_pose``: compute the path
(4 s timeout, ERROR "Timed out waiting for /quad/planner_server/compute_path"), follow it, and on a
failure back up 0.2 m (``/quad/backup`` of the behaviour server, 2 s on ``/quad/cmd_vel_nav``) and
try again, 3 attempts; feedback at 5 Hz only while it navigates. ``/quad/twist_mux`` (process
``twist_mux``): ``/quad/cmd_vel_nav`` (priority 10), ``/quad/cmd_vel_dock`` (20) and
``/quad/cmd_vel_teleop`` (100, only while the operator's remote is connected) into ``/quad/cmd_vel``
(silent while the robot stands), the active input latched. ``/quad/docking_server`` (process
``docking``): ``~/undock_robot`` (backs off the charger for 4 s on ``/quad/cmd_vel_dock``, once, at
the start of the mission), ``~/dock_robot``, ``~/state`` latched (DOCKED -> UNDOCKED).

The mission: ``/quad/mission_executive`` (process ``mission``), a behaviour tree at 10 Hz:
WaitForNavigation (``is_active``) -> Undock, then for each of 4 waypoints: Navigate
(navigate_to_pose; a failure retried every 3 s, WARNs then ERRORs from the third) -> PtzOn (the PTZ
camera's ``change_state`` activate, 2 s timeout) -> PtzPreset (``move_to_preset``) -> Thermal
(``/quad/inspection/thermal_camera/capture``, 3 s timeout, one retry) -> GasCheck (a reading younger
than 3 s) -> Listen (3 s for acoustic events) -> PtzOff (deactivate) -> the next waypoint; a failed
inspection step is reported ("Inspection at X incomplete", an ERROR) and the round goes on;
``/quad/mission/status`` latched, ``/quad/mission/report`` per waypoint, ``~/get_status``. The
inspection payload (process ``inspection``, one SingleThreadedExecutor):
``/quad/inspection/ptz_camera`` (a lifecycle node configured at start-up, active only at a
waypoint: ``/quad/inspection/ptz/image/compressed`` ~46 KB JPEG at 10 Hz; ``~/move_to_preset`` a
blocking ~0.8 s VISCA exchange), ``/quad/inspection/thermal_camera`` (``~/capture``, 0.3-0.6 s in
its callback; ~4 % refused during flat-field correction, a WARN, retried by the mission),
``/quad/inspection/gas_sensor`` (its 1 Hz timer reads the serial line:
``/quad/inspection/gas/reading``) and ``/quad/inspection/acoustic_detector`` (5 Hz FFTs of its
microphone; ``/quad/inspection/acoustic/leak`` only when it hears a leak signature, every ~15 s on
average). ``/quad/battery_manager`` (process ``battery``): ``/quad/battery/state`` 1 Hz and
``/quad/battery/status`` latched (CHARGING on the dock, DISCHARGING after the undock).
``/diagnostic_aggregator`` (process ``diagnostics``): ``/diagnostics`` from 15 nodes (``node: task``
names, hardware ids) -> ``/diagnostics_agg`` and ``/diagnostics_toplevel_state`` 1 Hz, STALE after
5 s. ``/rosbag2_recorder`` (process ``recorder``): serialized subscriptions to 14 topics made as
their publishers appear, a split every 60 s. ``/foxglove_bridge`` (process ``foxglove_bridge``):
one web client's 10 topics (costmap, plan, elevation map, PTZ images, mission, battery,
diagnostics, /rosout, /tf_static, the description), throttled, a send queue drained 10 times a
second. The operator station (process ``operator``: ``/quad/operator_ui`` and ``/quad/teleop_joy``)
joins at 15 s, exits with code 0 after 60 s and is started again 10 s later (connected ~15-75 s and
~85-145 s, ...): ``/quad/joy`` at 20 Hz while connected (``/quad/cmd_vel_teleop`` exists, silent:
the dead-man button is not held), 5 s after each start the UI sets the controller's ``max_vel_x``
(0.45-0.6 m/s) through ``/quad/controller_server/set_parameters`` (the controller logs it), asks
``/quad/mission_executive/get_status`` every 10 s, watches the mission, battery, PTZ stream and
``/diagnostics_agg``.

Healthy dynamics (measured): navigation active ~5 s after the start, the undock at ~6 s (4 s), then
waypoint after waypoint: ~10 s walking (``/quad/cmd_vel`` and ``/quad/cmd_vel_nav`` at 20 Hz, the
gait state at 50 Hz, navigate_to_pose feedback) and ~5 s standing at the waypoint (cmd_vel silent,
gait state 10 Hz, the PTZ camera active and streaming 10 Hz, its lifecycle transitions, the thermal
capture, the gas check): a round of 4 waypoints in ~62 s, so about one waypoint every 15 s; on
average 44/27 gait states per 10 s window walking/standing, ~4 PTZ images/s. Steady:
``/quad/joint_states`` 100 Hz, ``/quad/imu/data`` 200 Hz, ``/quad/odom`` 50 Hz, ``/quad/lidar/points``
10 Hz, the elevation map 2 Hz, the gas reading 1 Hz. Now and then: a foot slip WARN, a dropped-UDP
WARN of the lidar, a collision abort with its backup recovery and replan (WARNs), a refused thermal
capture (a WARN and a retry), an acoustic leak candidate (a WARN of the mission), a hot spot flagged.

Load: ~60-65 % of one core when healthy, the monitor not counted (54-71 % in 10 s windows with
psutil over 30-100 s in four runs, the operator connected or not, of the machine's two cores): the
state estimation process 14-19 % (200 IMU callbacks/s, 100 joint states/s for the robot state
publisher, odometry and /tf at 50 Hz), the navigation container 9-13 %, locomotion 9-12 % (the
400 Hz loop), the IMU driver 7-9 %, the inspection container ~4 %, the
recorder ~3 %, elevation mapping ~2.5 % (bursty), the operator station ~1.7 % while connected, the
rest 0.3-1.5 % each; RSS ~80-97 MB a process.

The faults (injected 90 s after the start: the operator's second session connected, the robot in
its second round, walking or inspecting; a waypoint passes every ~15 s, so each stage of the mission
falls in the 30 s watched), each with its true root cause (the target node):

- ``crash_twist_mux``: the twist mux's process is SIGKILLed: ``/quad/cmd_vel`` stops (and
  ``/quad/twist_mux/active``'s latched value goes with it); the locomotion controller gets no command
  and holds its stand; the controller server keeps publishing ``/quad/cmd_vel_nav`` but the robot does
  not move: "Failed to make progress" 10 s into each path (an ERROR of the controller), the BT
  navigator's backup recovery (a WARN; the backup's commands go nowhere either) and replan, every
  ~13 s; the third failure (~35-40 s after the kill) aborts the navigation (an ERROR "navigation to X
  aborted") and the mission retries (WARNs, then ERRORs "Navigate failed n times in a row"); when
  the kill comes while the robot inspects, the inspection finishes first. The mux's diagnostics go
  STALE; the gait state stays at 10 Hz (standing). Root cause /quad/twist_mux.
- ``hang_gas_sensor``: the gas sensor's serial read blocks forever in its timer callback (the sensor
  stopped answering; no timeout): the inspection container's single executor stops with it, so its
  siblings starve: ``/quad/inspection/gas/reading`` stops, the PTZ stream (while active) stops, the
  acoustic detector's events and the four payload nodes' diagnostics stop (STALE, the operator UI
  WARNs an ERROR in the diagnostics); at the next waypoint the mission's PTZ activation times out
  (ERRORs "Timed out waiting for /quad/inspection/ptz_camera/change_state (2 s) in PtzOn at X",
  "Inspection at X incomplete", its deactivation's timeout after) and it walks on (mid-inspection,
  the preset, thermal capture or deactivation times out the same way); the robot goes on walking
  its round. Root cause /quad/inspection/gas_sensor.
- ``degrade_joint_states``: the broadcaster's realtime publisher gets its lock on fewer than half of
  the cycles: ``/quad/joint_states`` drops from 100 to ~45 Hz (measured 44-48 Hz); nothing logged;
  the control loop, the gait state, the odometry and the mission are unchanged (the robot state
  publisher's feet transforms use the newest joint state at 10 Hz). Root cause
  /quad/joint_state_broadcaster.
- ``slow_planner``: a bad parameter file makes the planner rebuild its global costmap at 1 cm for
  every request: every compute_path takes 8 s more; the BT navigator's 4 s timeout fires (ERRORs
  "Timed out waiting for /quad/planner_server/compute_path (4 s): ComputePathToPose failed"), the
  backup recovery runs, the late plans arrive (the planner WARNs "Planner loop missed its desired
  rate ... took 8.x s") for requests that were given up; after 3 attempts navigation aborts, the
  mission retries (WARNs then ERRORs): the robot stands at its waypoint, cmd_vel silent but for the
  backups. Root cause /quad/planner_server.
- ``stale_lidar``: the lidar loses its PTP master and stamps its scans with its own free-running
  clock, 2 s behind: ``/quad/lidar/points`` comes at 10 Hz still, 2 s in the past; elevation mapping
  drops every cloud (ERROR "Lookup would require extrapolation into the past ... point cloud dropped",
  1/s) and stops publishing its map (WARN "Elevation map not updated", its diagnostics WARN); the
  controller aborts its path (ERROR "Elevation map is n s old: the local costmap is not current"),
  the BT navigator's recoveries and replans fail the same way, the mission's navigation fails
  (WARNs then ERRORs): the robot stands. Root cause /quad/lidar/lidar_driver.
- ``qos_state_estimator``: a redeployed state_estimator.yaml makes the estimator re-create its IMU
  subscription RELIABLE against the driver's best-effort publisher: it receives nothing (rclpy
  reports the incompatible QoS); after 0.5 s the filter degrades (ERROR "Filter degraded: no valid IMU
  measurement for 0.5 s ... leg odometry only", health DEGRADED, diagnostics ERROR); the locomotion
  controller WARNs it holds its stand and ignores cmd_vel; the controller's progress check fails,
  the BT navigator recovers and fails, the mission's navigation fails (WARNs, ERRORs); the IMU topic
  goes on at 200 Hz. Root cause /quad/state_estimator.
- ``leak_foxglove_bridge``: the bridge's send buffer to a stalled browser tab is never drained: its
  process grows 3 MB/s (measured 82 -> 290 MB in 70 s). Root cause /foxglove_bridge.
- ``cpu_battery_manager``: the BMS's SMBus polling thread spins on a NAK without sleeping: the
  battery process takes ~70-80 % of a core (measured 66-80 %, from ~0.4 %); its topics go on at 1 Hz.
  Root cause /quad/battery_manager.
- ``errlog_acoustic_detector``: the acoustic detector's USB sound card overruns: an ERROR every
  0.4 s ("ALSA: capture overrun (xrun) on hw:2,0, recovering the stream"); its analysis, its events
  and its diagnostics go on. Root cause /quad/inspection/acoustic_detector.
- ``flaky_imu``: the IMU's harness chafes at the hip: ``/quad/imu/data`` drops out for 1-3 s every
  5-12 s (the driver WARNs "IMU timeout: no data-ready interrupt" and INFOs "IMU data back"; ~140
  Hz on average instead of 200, measured); during each dropout the estimator degrades (ERROR "Filter
  degraded ... no IMU sample") and recovers (INFO), the locomotion controller stops and walks on
  (WARN, INFO): the robot walks in fits and starts, navigation slower, now and then a progress
  failure and a recovery. Root cause /quad/imu_driver.
"""

from __future__ import annotations

import os
import sys

from bench.handwritten import Design, NamespacedRobot, main

# the launch file's environment for every process: numpy's BLAS single-threaded (its worker threads
# would spin on the robot's two cores)
for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

DESIGN = Design(
    module="bench.quadruped.robot",
    nodes={  # process -> its nodes (fully qualified), in the order they start
        "site_map_loader": ("/quad/site_map_loader",),
        "locomotion": ("/quad/locomotion_controller", "/quad/joint_state_broadcaster"),
        "imu": ("/quad/imu_driver",),
        "state_estimation": ("/quad/state_estimator", "/quad/robot_state_publisher"),
        "lidar": ("/quad/lidar/lidar_driver",),
        "elevation_mapping": ("/quad/elevation_mapping",),
        "navigation": ("/quad/planner_server", "/quad/controller_server",
                       "/quad/local_costmap/local_costmap", "/quad/behavior_server",
                       "/quad/bt_navigator", "/quad/lifecycle_manager_navigation"),
        "twist_mux": ("/quad/twist_mux",),
        "docking": ("/quad/docking_server",),
        "mission": ("/quad/mission_executive",),
        "inspection": ("/quad/inspection/ptz_camera", "/quad/inspection/thermal_camera",
                       "/quad/inspection/gas_sensor", "/quad/inspection/acoustic_detector"),
        "battery": ("/quad/battery_manager",),
        "diagnostics": ("/diagnostic_aggregator",),
        "recorder": ("/rosbag2_recorder",),
        "foxglove_bridge": ("/foxglove_bridge",),
        "operator": ("/quad/operator_ui", "/quad/teleop_joy"),
    },
    faults={
        "crash_twist_mux": ("kill", "/quad/twist_mux", "twist_mux"),
        "hang_gas_sensor": ("file:hang", "/quad/inspection/gas_sensor", "inspection"),
        "degrade_joint_states": ("file:degrade", "/quad/joint_state_broadcaster", "locomotion"),
        "slow_planner": ("file:slow", "/quad/planner_server", "navigation"),
        "stale_lidar": ("file:stale", "/quad/lidar/lidar_driver", "lidar"),
        "qos_state_estimator": ("file:reliable", "/quad/state_estimator", "state_estimation"),
        "leak_foxglove_bridge": ("leak", "/foxglove_bridge", "foxglove_bridge"),
        "cpu_battery_manager": ("cpu", "/quad/battery_manager", "battery"),
        "errlog_acoustic_detector": ("file:errlog", "/quad/inspection/acoustic_detector", "inspection"),
        "flaky_imu": ("file:flaky", "/quad/imu_driver", "imu"),
    },
    operator="operator", join_s=15.0, run_s=60.0, again_s=10.0,  # connected 15-75 s and from ~85 s to ~145 s
)
NODES, FAULTS = DESIGN.nodes, DESIGN.faults


if __name__ == "__main__":
    sys.exit(main(None, __doc__, "quadruped", NamespacedRobot, DESIGN, 90.0,
                  "s from the start to the injection (90: the operator's second session connected, the robot "
                  "mid-round)"))
