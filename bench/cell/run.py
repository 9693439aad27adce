"""Run the cell robot (a pick-and-place work cell) under the monitor: healthy run, injected faults.

``python -m bench.cell.run [--healthy S] [--warmup S] [--post S] [--faults a,b] [--out DIR]``

The cell's processes (`bench.cell.robot`) under the in-process monitor, as every hand-written robot
runs (`bench.handwritten`: the runs, their scores, the files written). A production cell built with
ros2_control, MoveIt and a behaviour tree: a 6-axis arm with a two-finger gripper picks parts off a
conveyor under a depth camera, puts each in an inspection nest for a barcode check and goes home.
It runs on a HIL bench: the belt and its parts are a model (``/sim``) that the drivers sample as they
would sample their hardware. All nodes are on wall time. Every process runs one single-threaded
executor, rclpy's C++ EventsExecutor (``rclpy.experimental``, for CPU), except two that run rclpy's
MultiThreadedExecutor: the controller manager's (4 threads, as ``ros2_control_node`` does: the two
controllers' actions block in their execute callbacks, each in a reentrant group, while the control
loop completes them) and move_group's (3 threads: planning in its own mutually exclusive group, the
execute action in a reentrant one, the 1 Hz scene report in a third). No trajectory_msgs,
control_msgs nor tf2_msgs in this environment: ``/tf`` and ``/tf_static`` carry
geometry_msgs/TransformStamped (one transform a message), a joint trajectory is a
sensor_msgs/JointState (the waypoints' positions one after the other, ``effort`` their time from
start, ``frame_id`` its id), actions are test_msgs/Fibonacci, planning is nav_msgs/GetPlan, the pose
estimation a std_srvs/Trigger answering JSON, the light curtain a sensor_msgs/Range (inf = clear).
QoS: "sensor" best effort keep-last 5 (camera clouds and info, filtered cloud, light curtain, belt
encoder, gripper and trajectory controller states, inspection images, the sim's ground truth),
"command" reliable keep-last 1 (the belt drive), "reliable" keep-last 10 (/joint_states,
/diagnostics, detections, trajectories, belt speed and heartbeat, inspection results, cycle times),
"latched" reliable transient-local (/tf_static, /safety/state, /conveyor/parts_present,
/cell/bt_status, the planned path, /client_count).

The stack. HIL (process ``cell_sim``): ``/sim/cell_simulator``: the belt follows the PLC's drive
command (``/conveyor/drive``, ramped), a part is loaded at the infeed every 8-16 s when there is room,
parts stop against the stopper under the photo eye (1.0 m along the belt), the part there leaves the
belt once the gripper closes on it; ``/sim/ground_truth`` (PoseArray) 20 Hz. Process
``controller_manager`` (four nodes, one executor): ``/arm/controller_manager`` runs the hardware
interface's read/update/write loop at 250 Hz in its own thread (sub-ms jitter; its diagnostics count
cycles, overruns and the worst jitter) and disables the drives while ``/safety/state`` is not RUN;
``/arm/joint_state_broadcaster`` publishes ``/joint_states`` (7 joints) at 100 Hz from the loop;
``/arm/joint_trajectory_controller`` takes a trajectory on ``~/joint_trajectory`` and executes it on a
``~/follow_joint_trajectory`` goal, publishing ``~/controller_state`` at 50 Hz only while it executes
(silent while the arm waits: ~10 Hz on average); ``/arm/gripper_controller`` (``~/gripper_cmd``, the
target width; the fingers stall on a part at 40 mm, 20 N) publishes ``~/state`` at 20 Hz.
``/robot_state_publisher`` (process ``robot_state_publisher``): base_link -> tool0 and the finger on
``/tf`` for each joint state (200 messages/s) and the fixed frames on ``/tf_static`` once (latched).
Process ``move_group``: ``/arm/move_group`` serves ``/arm/move_group/plan`` (an RRTConnect-like
search with collision checks against the octomap: 0.2-0.8 s of real CPU for most plans, 1-2 s for
~15 %, 0.1 s for the free-space move home; ~6 % fail with a WARN "unable to solve the planning
problem"), latches the plan on ``~/display_planned_path``, and ``~/execute_trajectory`` sends the
trajectory and a goal to the trajectory controller; its private node ``/arm/move_group_private`` (as
MoveIt makes one, spun by its own EventsExecutor thread) keeps the current state from
``/joint_states`` and the octomap from ``/perception/points_filtered``; ``~/monitored_planning_scene``
1 Hz, a WARN every 10 s while the octomap is more than 2 s old. Perception: the depth camera
(``/perception/camera/camera_driver``, process ``camera``): ``/perception/camera/depth/points`` (1200
points over the pick zone) and ``.../camera_info`` at 15 Hz from its USB thread, stamped at exposure.
Process ``perception`` (three nodes on ONE single-threaded executor): ``/perception/object_detector``
(segments the cloud above the belt: ``/perception/detections`` only while a part is in view, ~15 Hz
then, silent otherwise), ``/perception/pose_estimator`` (``~/estimate``, on demand: an ICP refinement
of the newest detection against the newest cloud, 50-150 ms; it fails without a cloud younger than
1 s) and ``/perception/cloud_preprocessor`` (``/perception/points_filtered`` 15 Hz for the planning
scene). PLCs: ``/conveyor/plc_bridge`` (process ``conveyor``): ``speed`` a runtime parameter (0.2
m/s), ``~/run`` (SetBool), the belt stopped by the PLC when the photo eye sees a part;
``/conveyor/speed`` and ``/conveyor/drive`` 10 Hz, ``/conveyor/encoder`` 20 Hz, ``/conveyor/parts_present``
latched on change, ``/conveyor/heartbeat`` 2 Hz. ``/safety/safety_plc_bridge`` (process ``safety``):
``/safety/state`` latched (RUN), ``/safety/light_curtain`` 50 Hz from its polling thread; a tote
passes the curtain every 40-80 s with the curtain muted for 3 s (``frame_id`` muted; INFO logs).

The cell: ``/cell/task_orchestrator`` (process ``orchestrator``), the behaviour tree at 10 Hz:
WaitForPart -> Detect (a detection at the pick position within 3 s) -> EstimatePose (3 s timeout) ->
PlanPick (5 s timeout) -> ExecutePick -> Grasp -> RestartBelt -> PlanPlace -> ExecutePlace ->
InspectOn (the inspection station activated through its ``change_state``) -> Inspect -> Release ->
InspectOff (deactivated) -> PlanHome -> ExecuteHome; each motion step guarded by CellSafe (the light
curtain live, its stamps younger than 0.5 s, clear or muted); a failure is retried with a WARN
("... failed (...): retrying (n)"), from the third in a row with an ERROR; ``/cell/bt_status``
latched on each change, ``/cell/cycle_time``, ``~/get_status`` (Trigger). ``/cell/inspection_station``
(process ``inspection``), a lifecycle node configured by the tree at start-up: active (~1.6 s a
cycle) it streams ``/cell/inspection/image`` 10 Hz and gives its verdict on ``/cell/inspection/result``
(~3 % FAIL, a WARN). ``/diagnostic_aggregator`` (process ``diagnostics``): ``/diagnostics`` from ten
nodes (``node: task`` names, hardware ids) -> ``/diagnostics_agg`` and ``/diagnostics_toplevel_state``
1 Hz, STALE after 5 s. ``/cell/hand_eye_calibration`` (process ``calibration``): at boot it publishes
base_link -> camera_link on ``/tf_static`` (latched: gone with it) and exits with code 0 after ~4 s.
The recorder (``/rosbag2_recorder``, process ``recorder``, like ``ros2 bag record``): serialized
subscriptions to 14 topics (joint states, controller state, planned path, detections, encoder,
parts present, safety state and light curtain, BT status, inspection results, cycle times,
diagnostics_agg, /tf_static, /rosout) made as their publishers appear, a split every 60 s. Process
``rosbridge``: ``/rosbridge_websocket`` (one browser dashboard: subscribes to 14 topics, throttles
them to the client's rates, queues JSON drained 10 times a second; ``/client_count`` latched) and
``/rosapi`` (``/rosapi/topics``, ``/rosapi/nodes``, refreshed by the page every 5 s). The operator HMI
(``/cell/operator_hmi``, process ``hmi``) joins at 15 s, exits with code 0 after 60 s and is restarted
10 s later (connected ~15-75 s and ~85-145 s, ...): 5 s after each start it sets the belt's ``speed``
(0.15, 0.2 or 0.25 m/s) through ``/conveyor/plc_bridge/set_parameters`` (the bridge logs it), every
10 s it calls ``/cell/task_orchestrator/get_status``, and watches the BT status, the cycle times and
``/diagnostics_agg``.

Healthy dynamics: the first part at the photo eye ~7 s after the start, then a cycle of 12.5-15 s
(part at the eye -> home; measured 12.7-15.1 s, the first one up to ~20 s while the monitor
and the processes start) whenever a part waits, the belt restarted as soon as
the part is grasped; with parts every 8-16 s the cell sometimes waits for one (detections and the
belt's motion stop and start). Per cycle: three plans (CPU spikes of move_group to a whole core for
0.1-2 s), three trajectories (the controller state's bursts of 1.3-3.8 s), the inspection station
activated and deactivated, 7 INFO lines of the tree, the planner's and the controllers'. Now and
then: a failed plan (~6 %, a WARN from move_group and one from the tree), a rejected detection
(~5 %, a WARN), a missed grasp (~5 %, a WARN, the gripper reopened and the pose estimated again),
an inspection FAIL (~3 %, a WARN), the light curtain's muting every 40-80 s; the recorder's splits;
the HMI's sessions, each with its parameter change.

Load: ~58 % of one core when healthy (of the machine's two; 53 % and 64 % in two windows of 30 s
measured with psutil with the HMI connected, depending on how much of the window the arm moved):
move_group 12-18 % (its planning), the controller manager 12-18 % (the 250 Hz loop ~7 % and
rclpy's MultiThreadedExecutor while the actions block), the robot state publisher ~6 %, rosbridge
~5 %, the recorder ~4 %, the rest 0.3-2.7 % each; the monitor itself besides.

The faults (injected 90 s after the start: the HMI's second session connected, the cell mid-cycle
(its fifth to seventh part), so every stage of a cycle falls in the 30 s after the injection), each
with its true root cause (the target node):

- ``crash_camera``: the depth camera's process is SIGKILLed: ``/perception/camera/depth/points`` and
  its camera info stop; the detector publishes no detection, the preprocessor no filtered cloud,
  move_group WARNs every 10 s that its octomap is not updated, the camera's diagnostics go STALE; a
  cycle past its pose estimate finishes; the next part at the eye is never detected: the tree's
  Detect fails every 3 s (WARNs, then ERRORs "Detect failed n times in a row"), no plan, no
  trajectory, the belt stays stopped, the cycle time stops coming. Root cause
  /perception/camera/camera_driver.
- ``hang_detector``: the detector's clustering loops forever in its cloud callback (a cyclic
  union-find; no CPU); the perception container's single executor stops with it, so its siblings
  starve: ``/perception/detections`` and ``/perception/points_filtered`` stop and the pose estimator
  would answer nothing; the camera goes on at 15 Hz; move_group WARNs its octomap is old; the tree's
  Detect fails every 3 s (WARNs, then ERRORs) and the cell stands. Root cause
  /perception/object_detector.
- ``degrade_joint_states``: the broadcaster's realtime publisher no longer gets its lock on most
  cycles: ``/joint_states`` drops from 100 to 40 Hz and ``/tf`` from 200 to 80 messages/s with it;
  nothing logged; the control loop and the arm's motions are unchanged. Root cause
  /arm/joint_state_broadcaster.
- ``slow_move_group``: the octomap's collision cache is rebuilt on every query: every plan takes 8 s
  more; the tree's plan times out after 5 s (ERRORs "Timed out waiting for /arm/move_group/plan (5
  s) in PlanPick/PlanPlace/PlanHome", from the third "... failed n times in a row"), retried every
  ~6 s; move_group logs each late plan (~8.2-8.8 s) while the requests queue behind each other; no
  trajectory executes, the arm holds (with the part when it was carrying one). Root cause
  /arm/move_group.
- ``stale_light_curtain``: the safety bridge loses its time sync and stamps with the PLC's clock:
  ``/safety/light_curtain`` comes 2 s in the past, at 50 Hz still; the tree's CellSafe fails before
  its next motion step (an ERROR every 5 s "CellSafe failed before <step>: light curtain data 2.0 s
  old; holding"): the arm stops where it is, the belt stays stopped, no trajectory, no cycle time;
  when it holds before Release the inspection station stays active, its image stream going on.
  Root cause /safety/safety_plc_bridge.
- ``qos_pose_estimator``: a redeployed pose_estimator.yaml makes the estimator re-create its cloud
  subscription RELIABLE against the camera's best-effort publisher: it receives nothing (rclpy WARNs
  the incompatible QoS on both sides); each estimate fails ("no point cloud in the last 1.0 s", an
  ERROR from the estimator) and the tree goes back to Detect and tries again every ~1.3 s (WARNs,
  then ERRORs "EstimatePose failed n times in a row"); detections go on, the cell stands. Root
  cause /perception/pose_estimator.
- ``leak_rosbridge``: the websocket's send queue to a stalled browser tab is never drained: the
  rosbridge process grows 2.5 MB/s. Root cause /rosbridge_websocket.
- ``cpu_recorder``: the bag's compression thread spins (the demo's burner asked for a whole core;
  measured ~80 % of a core here, from ~4 %). Root cause /rosbag2_recorder.
- ``errlog_gripper``: one finger's CAN node fails its CRC: the gripper controller logs an ERROR every
  second ("CAN bus: CRC error on node 0x09 ... frame re-read") and goes on (its state, the grasps and
  ``/joint_states`` unchanged). Root cause /arm/gripper_controller.
- ``flaky_encoder``: the belt encoder's cable chafes: ``/conveyor/encoder`` drops out for 1-3 s every
  6-13 s (a WARN "Encoder signal lost" and an INFO "Encoder signal back" each time; ~11 Hz on
  average instead of 20), the bridge's diagnostics WARN while it is out; only the recorder consumes
  the encoder: the belt and the cycle go on. Root cause /conveyor/plc_bridge.
"""

from __future__ import annotations

import os
import sys

from bench.handwritten import Design, NamespacedRobot, main

# the launch file's environment for every process: numpy's BLAS single-threaded (its worker threads
# would spin on the cell PC's two cores)
for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

DESIGN = Design(
    module="bench.cell.robot",
    nodes={  # process -> its nodes (fully qualified), in the order they start
        "cell_sim": ("/sim/cell_simulator",),
        "calibration": ("/cell/hand_eye_calibration",),
        "controller_manager": ("/arm/controller_manager", "/arm/joint_state_broadcaster",
                               "/arm/joint_trajectory_controller", "/arm/gripper_controller"),
        "robot_state_publisher": ("/robot_state_publisher",),
        "move_group": ("/arm/move_group", "/arm/move_group_private"),
        "camera": ("/perception/camera/camera_driver",),
        "perception": ("/perception/object_detector", "/perception/pose_estimator",
                       "/perception/cloud_preprocessor"),
        "conveyor": ("/conveyor/plc_bridge",),
        "safety": ("/safety/safety_plc_bridge",),
        "orchestrator": ("/cell/task_orchestrator",),
        "inspection": ("/cell/inspection_station",),
        "diagnostics": ("/diagnostic_aggregator",),
        "recorder": ("/rosbag2_recorder",),
        "rosbridge": ("/rosbridge_websocket", "/rosapi"),
        "hmi": ("/cell/operator_hmi",),
    },
    faults={
        "crash_camera": ("kill", "/perception/camera/camera_driver", "camera"),
        "hang_detector": ("file:hang", "/perception/object_detector", "perception"),
        "degrade_joint_states": ("file:degrade", "/arm/joint_state_broadcaster", "controller_manager"),
        "slow_move_group": ("file:slow", "/arm/move_group", "move_group"),
        "stale_light_curtain": ("file:stale", "/safety/safety_plc_bridge", "safety"),
        "qos_pose_estimator": ("file:reliable", "/perception/pose_estimator", "perception"),
        "leak_rosbridge": ("leak", "/rosbridge_websocket", "rosbridge"),
        "cpu_recorder": ("cpu", "/rosbag2_recorder", "recorder"),
        "errlog_gripper": ("file:errlog", "/arm/gripper_controller", "controller_manager"),
        "flaky_encoder": ("file:flaky", "/conveyor/plc_bridge", "conveyor"),
    },
    operator="hmi", join_s=15.0, run_s=60.0, again_s=10.0,  # connected 15-75 s and from ~85 s to ~145 s
)
NODES, FAULTS = DESIGN.nodes, DESIGN.faults


if __name__ == "__main__":
    sys.exit(main(None, __doc__, "cell", NamespacedRobot, DESIGN, 90.0,
                  "s from the start to the injection (90: the HMI's second session connected, the cell "
                  "mid-cycle)"))
