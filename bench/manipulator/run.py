"""Run the mobile manipulator (warehouse order picking) under the monitor: healthy run, injected faults.

``python -m bench.manipulator.run [--healthy S] [--warmup S] [--post S] [--faults a,b] [--out DIR]``

The robot's processes (`bench.manipulator.robot`) under the in-process monitor, as every hand-written
robot runs (`bench.handwritten`: the runs, their scores, the files written). A wheeled base with a
6-DOF arm, a parallel gripper, a wrist F/T sensor and a wrist RGB-D camera picking totes from shelves
and placing them at a packing station, its stack laid out as a production team lays out ros2_control,
MoveIt and an Open-RMF-style fleet adapter. Everything is under ``/mm`` except ``/tf``,
``/tf_static``, ``/diagnostics``, ``/diagnostics_agg``, ``/diagnostics_toplevel_state``, ``/rosout``,
``/parameter_events``, the fleet manager's ``/fleet_manager/task_orders`` and the infrastructure
nodes ``/fleet_manager``, ``/diagnostic_aggregator``, ``/rosbag2_recorder`` and
``/rosbridge_websocket``. Wall time everywhere. Every process spins one rclpy SingleThreadedExecutor
(the wheels' EventsExecutor hangs, and the MultiThreadedExecutor costs too much CPU in Python): the
action servers that wait (the JTC, the gripper, move_group's execution, the path follower) are
coroutines that yield to the executor; drivers and loops run in threads of their own.

Substitutes (no control_msgs, trajectory_msgs, tf2_msgs, moveit_msgs, controller_manager_msgs nor
rmf_fleet_msgs here): ``/tf`` and ``/tf_static`` carry geometry_msgs/TransformStamped, one transform a
message; a trajectory (the JTC's ``~/joint_trajectory``, servo's output), the JTC's
``~/controller_state`` and ``/mm/display_planned_path`` are sensor_msgs/JointState; every action is
test_msgs/Fibonacci (``order`` = the SRDF named pose's index for ``follow_joint_trajectory``, the plan
id for ``execute_trajectory``, the site's index for ``navigate_to_pose``, 0/1 = open/close for
``gripper_cmd``; feedback ``sequence`` = progress, result ``sequence[0]`` = error code); the
controller manager's load/configure/switch services and MoveIt's ``plan_kinematic_path`` /
``compute_cartesian_path`` are test_msgs/BasicTypes (``string_value`` the request, ``bool_value``
ok, ``int32_value`` the plan id, ``float64_value`` the planning time); ``list_controllers``,
``list_hardware_*`` are std_srvs/Trigger (JSON); fleet orders, robot and task states, the planning
scene, the URDF are std_msgs/String (JSON / XML); the bumpers std_msgs/UInt8 (a bit mask, bit 7 the
e-stop); the heartbeat std_msgs/Header (``frame_id`` = RUN / PROTECTIVE_STOP). QoS: "sensor" best
effort keep-last 5 (scan, images, camera info, point cloud, wrench, particle cloud), the MCU's
best-effort keep-last 1 (bumpers, sonars: rclc best-effort publishers), "command" reliable keep-last 1
(cmd_vel_nav, cmd_vel_teleop, the heartbeat), "reliable" keep-last 10 (joint states, odometry, the
DDC's cmd_vel, JTC state, battery, diagnostics, plans, detections, fleet states), "latched" reliable
transient-local (``/tf_static`` depth 100, ``/mm/robot_description``, ``/mm/map``,
``/mm/amcl_pose``, ``/mm/safety/state``, ``/mm/velocity_mux/active``,
``/mm/fleet_adapter/task_state``).

Processes -> nodes (16 processes, 29 nodes; the two spawners exit, the operator comes and goes):

- ``controller_manager`` (ros2_control_node): ``/mm/controller_manager`` and, once the spawners
  load them, one node per controller: ``/mm/joint_state_broadcaster`` (``/mm/joint_states``, 9
  joints, 30 Hz), ``/mm/diff_drive_controller`` (``~/cmd_vel`` TwistStamped with a 0.5 s timeout,
  ``~/odom`` 25 Hz and odom -> base_link on ``/tf`` 25 Hz), ``/mm/arm_controller`` (JTC:
  ``~/follow_joint_trajectory``, ``~/joint_trajectory``, ``~/controller_state`` at 25 Hz always,
  moving or not), ``/mm/gripper_controller`` (``~/gripper_cmd``; stalls on a tote's handle) and
  ``/mm/ft_sensor_broadcaster`` (``~/wrench`` 50 Hz, best effort). The update loop runs at 250 Hz in
  its own thread (simulated hardware: read -> each active controller at its update rate -> write);
  the ROS interfaces on the executor. Waits for ``/mm/robot_description``, then logs the resource
  manager's lines (loading, initialising, configuring, activating the four hardware components
  mm_base, mm_arm, mm_gripper, wrist_ft) and serves ``~/load_controller``,
  ``~/configure_controller``, ``~/switch_controller``, ``~/unload_controller``,
  ``~/list_controllers``, ``~/list_hardware_components``, ``~/list_hardware_interfaces``.
  Diagnostics "controller_manager: Controllers Activity", "... Hardware Components Activity",
  "... Controller Manager Activity" (hardware id ``mm_picker``). Healthy quirks: the WARN "Could not
  enable FIFO RT scheduling policy" at start; "Overrun detected! The controller manager missed its
  desired rate of 250 Hz. The loop took X ms (missed cycles : n)." when a cycle wakes more than 3
  cycles late (at most one per 5 s; ~9-10 per 100 s measured on the loaded 2-core VM).
- ``spawner_base`` (``/mm/spawner_joint_state_broadcaster``: joint_state_broadcaster,
  ft_sensor_broadcaster, diff_drive_controller) and ``spawner_arm`` (``/mm/spawner_arm_controller``:
  arm_controller, gripper_controller): wait for the manager's services, load, configure, switch, log
  "Loaded X" / "Configured and activated ..." and exit with code 0 within ~2 s of the start.
- ``robot_state_publisher``: ``/mm/robot_state_publisher`` latches ``/mm/robot_description`` (the
  URDF with its ros2_control tags) and 11 fixed frames on ``/tf_static``; from the joint states,
  9 transforms on ``/tf`` at its publish_frequency of 10 Hz; "got segment X" INFOs at start.
- ``micro_ros_agent``: the agent's serial link to the base MCU; the MCU's rclc nodes appear through
  it ~1.2 s after the start: ``/mm/mcu/battery`` (``~/state`` BatteryState 1 Hz, reliable),
  ``/mm/mcu/bumpers`` (``/mm/mcu/bumpers`` 20 Hz), ``/mm/mcu/sonar`` (``~/front``, ``~/rear`` Range
  10 Hz each), all from one MCU executor thread (a 20 Hz tick) over the simulated serial line drained
  by the agent's reader thread. The agent logs to stdout only (its Micro XRCE-DDS lines; no rosout).
  Healthy quirk: every 40-120 s a serial framing error (an "error | SerialAgentLinux.cpp |
  recv_message | serial framing error" line) and a 0.1-0.4 s gap on all three nodes' topics. Now and
  then (every 90-240 s) someone walks past the front sonar (0.22 m for 0.8-2 s).
- ``lidar``: ``/mm/lidar/lidar_driver``, ``/mm/scan`` (LaserScan, 720 beams) at 10 Hz, best effort,
  stamped at the scan's first beam (PTP); a WARN "Received incomplete scan packet ... frame skipped"
  every 60-150 s (one scan missing); diagnostics "lidar_driver: /mm/scan topic status".
- ``perception`` (one component container): ``/mm/camera/camera_driver`` (RealSense-like:
  ``/mm/camera/color/image_raw`` rgb8 424x240 and ``/mm/camera/color/camera_info`` at 15 Hz,
  ``/mm/camera/depth/color/points`` 5 Hz, best effort, stamped at exposure; the "Hardware
  Notification: Right MIPI error" WARN at start; frequency diagnostics),
  ``/mm/camera/compressed_republisher`` (image_transport lazy: subscribes the raw stream and
  publishes ``/mm/camera/color/image_raw/compressed`` only while someone subscribes the compressed
  topic, i.e. while the operator UI is connected) and ``/mm/tote_detector`` (its ``~/enable``
  SetBool; while enabled by the fleet adapter at a shelf it subscribes the raw images, infers on
  every other one, drops images older than 0.5 s, and publishes ``~/detections`` (PoseArray stamped
  as the image) only while a tote is in view: bursts of ~7 Hz for a second or two per pick; ~10 %
  of looks a WARN "Barcode unreadable on tote candidate (glare): retrying").
- ``move_group`` (move_group and servo composed): ``/mm/move_group`` serves
  ``/mm/plan_kinematic_path`` (OMPL, 0.2-1.0 s of CPU, sometimes 1.5 s, blocking its executor),
  ``/mm/compute_cartesian_path`` (30 ms) and the ``/mm/execute_trajectory`` action (sends the JTC
  its ``follow_joint_trajectory``); its planning-scene monitor subscribes ``/mm/joint_states`` and
  the depth cloud (an octomap update of 3 ms each; clouds older than 1 s dropped with a tf
  extrapolation WARN) and publishes ``~/monitored_planning_scene`` at 1 Hz; MoveIt's INFO lines per
  plan and execution. ``/mm/servo_node`` (MoveIt Servo; shares move_group's planning scene monitor)
  is paused until ``~/pause_servo`` false, then publishes ``/mm/arm_controller/joint_trajectory`` at
  25 Hz and ``~/status`` at 6 Hz from ``~/delta_twist_cmds``.
- ``navigation`` (one container): ``/mm/map_server`` latches ``/mm/map`` (400 x 240 at 5 cm) and
  serves ``~/map``; ``/mm/amcl`` takes the DDC's odometry and every scan: ``/mm/amcl_pose`` 10 Hz
  (latched), map -> odom on ``/tf`` 10 Hz (post-dated by the 0.5 s transform tolerance),
  ``/mm/particle_cloud`` 2 Hz; a scan older than its odometry buffer (~2 s) is dropped with the
  message filter's WARN; 5 s without a scan, the "No laser scan received" WARN every 5 s.
  ``/mm/path_follower`` serves ``/mm/navigate_to_pose``: a straight-line ``/mm/plan``, then pure
  pursuit at 20 Hz on ``/mm/cmd_vel_nav`` (feedback 5 Hz); aborts when the pose is more than 1 s old
  ("localization lost") or without 0.2 m of progress in 10 s ("Failed to make progress").
- ``safety``: ``/mm/safety_controller`` (bumpers, both sonars, the e-stop bit -> RUN /
  PROTECTIVE_STOP with a WARN "Protective stop: <reasons>" and an INFO when cleared; stale inputs
  (0.5 s) or an obstacle closer than 0.3 m stop the base; ``/mm/safety/heartbeat`` 20 Hz,
  ``/mm/safety/state`` latched) and ``/mm/velocity_mux`` (teleop ``/mm/cmd_vel_teleop`` over
  navigation ``/mm/cmd_vel_nav``, limited in speed and acceleration, zero while the heartbeat says
  stop or is lost, into ``/mm/diff_drive_controller/cmd_vel``, silent while the inputs are;
  ``~/active`` latched; ``max_linear_vel`` a runtime parameter it logs).
- ``fleet_adapter``: ``/mm/fleet_adapter``, the task state machine in a worker thread: navigate to
  the shelf -> enable the detector -> plan+execute ``look`` -> wait ≤ 3 s for a fresh detection ->
  ``pre_pick`` (OMPL), ``pick`` (Cartesian), close the gripper, ``lift`` (Cartesian), ``stow`` (OMPL)
  -> navigate to ``pack_1`` -> ``pre_place``, ``place``, open, ``stow``. Planning timeout 5 s;
  a failure is an ERROR "[task] Task failed in phase 'X': <why>", a failed task state, and a stow
  attempt. ``~/robot_state`` 1 Hz (JSON), ``~/task_state`` latched on change; subscribes the pose,
  battery, safety state, detections and the orders.
- ``fleet_manager``: ``/fleet_manager`` sends ``/fleet_manager/task_orders`` 4-12 s after the robot
  reports idle, re-queues a failed order (WARN) and marks the robot lost after 5 s without its state
  (ERROR).
- ``diagnostics``: ``/diagnostic_aggregator``, ``/diagnostics`` (8 producers, ~7 arrays/s) ->
  ``/diagnostics_agg`` (Base, Sensors, Perception, Fleet, Other) and ``/diagnostics_toplevel_state``
  at 1 Hz, STALE after 5 s.
- ``recorder``: ``/rosbag2_recorder``, serialized subscriptions to 20 topics as their publishers
  appear, drained by its writer thread at 10 Hz (its node is not spun: its parameter services do not
  answer), "Writing to a new bag file" every 60 s.
- ``rosbridge``: ``/rosbridge_websocket`` with the warehouse dashboard connected: 8 subscriptions
  (robot and task state, battery, safety state, map, plan, ``/diagnostics_agg``, the pose throttled
  to 2 Hz), a send queue drained 10 times a second.
- ``operator``: ``/mm/operator_ui`` joins at 20 s, exits with code 0 after 80 s and is started again
  15 s later (connected ~20-100 s, ~115-195 s, ...): subscribes the compressed camera stream (which
  starts the lazy republisher), the robot state, safety state and ``/diagnostics_agg``; holds a silent
  ``/mm/cmd_vel_teleop`` publisher (the dead-man button not held); 5 s after connecting sets the
  velocity mux's ``max_linear_vel`` (0.55-0.7) through ``/mm/velocity_mux/set_parameters``; once a
  session, 20 s or more after connecting and while the base drives, a 6 s wrist-camera look-around by
  teleop (unpauses servo, ``/mm/servo_node/delta_twist_cmds`` at 20 Hz, pauses it again).

Healthy dynamics (measured in 60-125 s smoke runs): the spawners done ~1-2 s after the start; the
first order at ~10 s; a pick-and-place task takes ~55-60 s (two legs of 10-20 s driving at up to
0.7 m/s with ``cmd_vel_nav`` and the DDC's ``cmd_vel`` at 20 Hz, the base standing at the shelf and
at the station for ~12-15 s each with the arm moving through its plans, ~5 OMPL plans a task), then
4-12 s idle (arm stowed, the JTC state still at 25 Hz, command topics silent). Steady: joint states
30 Hz, wrench 50 Hz, odometry 25 Hz, JTC state 25 Hz, ``/tf`` ~125 msgs/s, scan 10 Hz, raw image and
camera info 15 Hz, cloud 5 Hz, pose 10 Hz, heartbeat 20 Hz, bumpers 20 Hz, sonars 10 Hz each,
battery, robot state and aggregated diagnostics 1 Hz. Bursty: detections, the compressed stream
(operator only), servo output (one 6 s jog a session), plans, ``cmd_vel``.

Load (psutil, 5 s windows, the monitor not running, no probe subscriptions, 2-core VM): ~80-120 %
of one core in total, i.e. MORE than the 60 % aimed at (Python rclpy costs ~0.5-1 ms a callback):
controller_manager 12-22 %, move_group 10-30 % (planning bursts), navigation 10-18 %, safety 10-17 %,
perception 7-15 % (the compressed stream while the operator is connected), robot_state_publisher
6-11 %, fleet_adapter 3-5 %, recorder, rosbridge, operator 3-5 % each, the rest 1-2 %.

The faults (injected 120 s after the start: the operator's second session connected, the robot in its
second task), each with its true root cause (the target node):

- ``crash_fleet_adapter``: the fleet adapter's process is SIGKILLed: robot and task states stop;
  the fleet manager ERRORs "Robot mm_01: no state for 5 s, marking it lost" and dispatches nothing;
  an action under way finishes (the path follower drives on to its goal, the JTC completes), then
  the robot idles: the arm stowed or wherever it stopped, the base still, the detector left as it
  was. Root cause /mm/fleet_adapter.
- ``hang_mcu_sonar``: the MCU's sonar callback waits on its echo pin without a timeout: the MCU's
  single rclc executor never returns, so ``/mm/mcu/sonar/*``, ``/mm/mcu/bumpers`` and
  ``/mm/mcu/battery/state`` all stop while the three nodes stay in the graph (the agent itself is
  fine, silent); the safety controller goes to PROTECTIVE_STOP (WARN "bumper data stale ...,
  sonar data stale ..."), the mux commands zero, the path follower fails to make progress (ERROR),
  the fleet adapter fails the task (ERROR), the fleet manager re-queues it (WARN), over and over.
  Root cause /mm/mcu/sonar.
- ``degrade_lidar``: the lidar's UDP frames overflow the socket buffer: ``/mm/scan`` drops from 10
  to ~4 Hz (measured 4.0-4.2); its frequency diagnostics WARN; AMCL's pose at ~4 Hz; navigation
  still works. Root cause /mm/lidar/lidar_driver.
- ``slow_move_group``: a redeployed OMPL config (longest_valid_segment_fraction 5e-5) makes every
  plan 6-9 s of CPU more (measured 10.8-15 s under load, queued behind each other on move_group's
  executor): the fleet adapter's 5 s planning timeout fires (ERROR "Task failed in phase 'pick':
  planning to 'look' timed out after 5.0 s", WARN "Could not stow the arm"), the fleet manager
  re-queues (WARN), the late plans finish ("Solution found in 10.8 seconds", WARN "Planning took
  10.83 s"); move_group's process burns CPU. Root cause /mm/move_group.
- ``stale_lidar``: the lidar loses its PTP master and stamps its scans with its free-running clock
  2.5 s behind: ``/mm/scan`` stays at 10 Hz; AMCL drops every scan (WARN "Message Filter dropping
  message ... earlier than all the data in the transform cache") and its pose stops (the latched one
  ages); the path follower aborts ("Robot pose is X s old ... localization lost", ERROR), the fleet
  adapter fails the task, the manager re-queues, and again. Root cause /mm/lidar/lidar_driver.
- ``qos_safety_controller``: a redeployed safety.yaml makes the safety controller re-create its
  sonar subscriptions RELIABLE against the MCU's best-effort publishers: it receives nothing (rclpy's
  incompatible-QoS WARNs); 0.5 s later PROTECTIVE_STOP "sonar data stale", the base stops, navigation
  fails (ERRORs), tasks fail and are re-queued; the sonar topics go on at 10 Hz. Root cause
  /mm/safety_controller.
- ``leak_rosbag2_recorder``: the recorder's write cache to a stalled disk is never flushed: its
  process grows 3 MB/s (measured 83 -> 201 MB in 40 s). Root cause /rosbag2_recorder.
- ``cpu_rosbridge``: a client's subscription makes rosbridge's encoder spin: the bridge's process
  takes ~50-70 % of a core (measured, from ~3 %); its sends go on. Root cause /rosbridge_websocket.
- ``errlog_ft_sensor_broadcaster``: the wrist F/T sensor's status word reports gauge saturation on
  force.z: the broadcaster logs an ERROR every 1-2 s ("Sensor 'wrist_ft': status word 0x20000000
  (gauge saturation on force.z), reading discarded; publishing the last valid wrench") and publishes
  the last valid wrench at 50 Hz; picks go on. Root cause /mm/ft_sensor_broadcaster (inside the
  controller manager's process).
- ``flaky_mcu_bumpers``: the bumpers' I/O expander NAKs on I2C: ``/mm/mcu/bumpers`` drops out for
  1-3 s every 5-12 s (the MCU node's timer returns without a frame; the sonars and battery go on);
  each dropout puts the safety controller in PROTECTIVE_STOP (WARN "bumper data stale") and clears
  it (INFO): the base drives in fits and starts, now and then a progress failure and a failed,
  re-queued task. Root cause /mm/mcu/bumpers.
"""

from __future__ import annotations

import os
import sys

from bench.handwritten import Design, NamespacedRobot, main

for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

DESIGN = Design(
    module="bench.manipulator.robot",
    nodes={
        "robot_state_publisher": ("/mm/robot_state_publisher",),
        "controller_manager": (
            "/mm/controller_manager",
            "/mm/joint_state_broadcaster",
            "/mm/diff_drive_controller",
            "/mm/arm_controller",
            "/mm/gripper_controller",
            "/mm/ft_sensor_broadcaster",
        ),
        "spawner_base": ("/mm/spawner_joint_state_broadcaster",),
        "spawner_arm": ("/mm/spawner_arm_controller",),
        "micro_ros_agent": ("/mm/mcu/battery", "/mm/mcu/bumpers", "/mm/mcu/sonar"),
        "lidar": ("/mm/lidar/lidar_driver",),
        "perception": ("/mm/camera/camera_driver", "/mm/camera/compressed_republisher", "/mm/tote_detector"),
        "move_group": ("/mm/move_group", "/mm/servo_node"),
        "navigation": ("/mm/map_server", "/mm/amcl", "/mm/path_follower"),
        "safety": ("/mm/safety_controller", "/mm/velocity_mux"),
        "fleet_adapter": ("/mm/fleet_adapter",),
        "fleet_manager": ("/fleet_manager",),
        "diagnostics": ("/diagnostic_aggregator",),
        "recorder": ("/rosbag2_recorder",),
        "rosbridge": ("/rosbridge_websocket",),
        "operator": ("/mm/operator_ui",),
    },
    faults={
        "crash_fleet_adapter": ("kill", "/mm/fleet_adapter", "fleet_adapter"),
        "hang_mcu_sonar": ("file:hang", "/mm/mcu/sonar", "micro_ros_agent"),
        "degrade_lidar": ("file:degrade", "/mm/lidar/lidar_driver", "lidar"),
        "slow_move_group": ("file:slow", "/mm/move_group", "move_group"),
        "stale_lidar": ("file:stale", "/mm/lidar/lidar_driver", "lidar"),
        "qos_safety_controller": ("file:reliable", "/mm/safety_controller", "safety"),
        "leak_rosbag2_recorder": ("leak", "/rosbag2_recorder", "recorder"),
        "cpu_rosbridge": ("cpu", "/rosbridge_websocket", "rosbridge"),
        "errlog_ft_sensor_broadcaster": ("file:errlog", "/mm/ft_sensor_broadcaster", "controller_manager"),
        "flaky_mcu_bumpers": ("file:flaky", "/mm/mcu/bumpers", "micro_ros_agent"),
    },
    operator="operator",
    join_s=20.0,
    run_s=80.0,
    again_s=15.0,
)
NODES, FAULTS = DESIGN.nodes, DESIGN.faults

if __name__ == "__main__":
    sys.exit(
        main(
            None,
            __doc__,
            "manipulator",
            NamespacedRobot,
            DESIGN,
            120.0,
            "s from the start to the injection (120: the operator's second session connected, the robot "
            "in its second task)",
        )
    )
