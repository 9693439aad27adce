"""Run the hotel-lobby concierge robot under the monitor: healthy run, injected faults.

``python -m bench.concierge.run [--healthy S] [--warmup S] [--post S] [--faults a,b] [--out DIR]
[--samples DIR]``

The robot's processes (`bench.concierge.robot`) under the in-process monitor, as every hand-written
robot runs (`bench.handwritten`: the runs, their scores, the files written). ``cg`` is a humanoid
concierge robot in a hotel lobby: a wheeled base with a torso, two 6-DoF arms, a head with a camera
and a microphone array, a tablet on its chest. It greets guests, answers them by voice, waves and
points, guides them to the elevators, looks up bookings and encodes key cards through the hotel's
property-management system (PMS). Laid out as a production team lays out ROS 2 Jazzy: a
ros2_control-like controller manager, a head-perception component container, a Nav2-like
navigation container of lifecycle nodes, a speech pipeline, a behaviour-tree task executive, a
velocity mux behind a collision monitor. Everything is under ``/cg`` except ``/tf``, ``/tf_static``,
``/diagnostics``, ``/diagnostics_agg``, ``/diagnostics_toplevel_state``, ``/rosout``,
``/parameter_events``, the hotel's ``/hotel/*`` and the infrastructure nodes ``/hotel_pms_bridge``,
``/diagnostic_aggregator`` and ``/rosbag2_recorder``. Wall time everywhere.

Guests: one schedule shared by every process through the wall clock (`bench.concierge.robot.world`,
45 s epochs): in 85 % of the epochs a guest stands in front of the robot for 22-33 s; the camera
sees the face, the lidar sees legs at 0.9 m, the microphones hear 1-3 utterances 1.0-2.4 s long
8-11 s apart (hello, check in, directions, guide me to the elevators, late checkout, towels,
goodbye; the intent is coded in the audio chunks), 40 % of the guests touch the chest tablet.

Substitutes (not on PyPI here: tf2_msgs, control_msgs, trajectory_msgs, audio_common_msgs,
vision_msgs, nav2_msgs, example_interfaces, diagnostic_updater): ``/tf`` and ``/tf_static`` carry
geometry_msgs/TransformStamped, one transform a message; the arms' FollowJointTrajectory
(``order`` = duration in 0.1 s), Nav2's NavigateToPose (``order`` = place index: home, elevators,
restaurant, front_desk; result ``sequence[0]`` 0 succeeded, 2 no progress, 3 localization lost,
5 canceled, 6 navigator inactive) and the TTS ``say`` action (``order`` = phrase index) are
test_msgs/Fibonacci; the joint trajectory controller state is a sensor_msgs/JointState; audio chunks
are std_msgs/UInt8MultiArray (2048 bytes = 1024 S16LE samples at 16 kHz; byte 0 the energy, 1 the
spoken intent, 2-3 the utterance number); the PMS services and the speech recogniser's
``transcribe`` are test_msgs/BasicTypes; face detections and people are geometry_msgs/PoseArray;
an utterance end is a std_msgs/Header (``frame_id`` ``utt-<n>:<chunks>``, stamp = its start);
intents, task results, executive status, tablet pages and touches are std_msgs/String (JSON).

QoS: "sensor" best effort keep-last 5 (``/cg/scan``, ``/cg/imu/data``, the head camera's image,
camera info and lazy compressed stream), "command" reliable keep-last 1 (``/cg/cmd_vel_nav``,
``/cg/cmd_vel_teleop``), "reliable" keep-last 10 (joint states, odometry, the diff drive's
``cmd_vel``, audio, voice, utterances, faces, people, localization pose, plan, ``/diagnostics``,
``/diagnostics_agg``, ``/tf``, intents and results, ``/hotel/room_status``), "latched" reliable
transient-local depth 1 (``/cg/map``, ``/cg/robot_description``, ``/cg/audio/info``,
``/cg/speech/vad``, ``/cg/person_tracker/guest_present``, ``/cg/safety/stop``,
``/cg/velocity_mux/active``, ``/cg/tts/speaking``, ``/cg/task_executive/status``,
``/cg/dialogue_manager/state``, ``/cg/chest_tablet/page``), ``/tf_static`` transient-local depth
100 (robot state publisher, head camera). Lifecycle publishers (map, localization pose, cmd_vel_nav,
plan, VAD voice) publish only while their node is active. Several publishers: ``/diagnostics``
(10 nodes), ``/tf`` (diff drive, localization, robot state publisher), ``/tf_static`` (2).

Processes -> nodes (15 processes, 28 nodes; the console comes and goes):

- ``controller_manager`` (MultiThreadedExecutor, 4 threads; the update loop a thread of its own
  at 50 Hz, the controllers publishing from it as realtime publishers do):
  ``/cg/controller_manager`` (``~/list_controllers`` std_srvs/Trigger; diagnostics 1 Hz, one status
  per motor board with its ``hardware_id``: left/right arm boards and torso/head on EtherCAT, the
  base's Roboteq on CAN, plus "Controllers Activity"; a WARN "Overrun detected! ..." every 60-140
  s), ``/cg/joint_state_broadcaster`` (``/cg/joint_states`` 50 Hz, 17 joints),
  ``/cg/left_arm_controller`` and ``/cg/right_arm_controller`` (``~/follow_joint_trajectory``
  action in a reentrant group each, ``~/controller_state`` 10 Hz while active),
  ``/cg/diff_drive_controller`` (``~/cmd_vel`` TwistStamped, 0.5 s timeout; ``/cg/odom`` and
  odom->base_link on ``/tf`` 25 Hz, still while idle).
- ``head_container`` (component container, ONE SingleThreadedExecutor): ``/cg/head_camera``
  (``~/image_raw`` 64x48 rgb8 and ``~/camera_info`` 15 Hz stamped 30 ms before publishing;
  ``~/image_raw/compressed`` 5 Hz ONLY while someone subscribes = while the console is connected,
  INFO "Compressed stream started/stopped"; its optical frame on ``/tf_static``; diagnostics 1 Hz),
  ``/cg/face_detector`` (``~/faces`` ~15 Hz ONLY while a face is in view, stamped as the image),
  ``/cg/person_tracker`` (``/cg/people`` 5 Hz while tracking, ``~/guest_present`` latched on change,
  INFO "Track N started/lost"; a 3 s timer saving its re-identification gallery to the NAS).
- ``navigation`` (component_container_mt: MultiThreadedExecutor, 4 threads; the action server in
  a reentrant group, localization's subscriptions in a mutually exclusive group, the lifecycle
  manager's clients in a reentrant group, its bring-up and bond a thread): ``/cg/map_server``
  (lifecycle; latches ``/cg/map`` 200x150 at 0.1 m once active, ``~/map`` GetMap),
  ``/cg/localization`` (lifecycle; scan + odometry -> ``/cg/localization/pose`` 10 Hz while the base
  moves, 1 Hz still, map->odom on ``/tf`` with it; a scan older than 0.5 s is dropped with the
  "Message Filter dropping message ..." WARN every 2 s at most), ``/cg/navigator`` (lifecycle;
  ``/cg/navigate_to_pose``: a straight-line ``/cg/plan`` every 2 s, ``/cg/cmd_vel_nav`` 20 Hz only
  while driving; aborts with ERROR "Robot pose is X s old (localization): localization lost" after
  1.5 s without a pose, "Failed to make progress" without 0.2 m in 10 s; rejects goals with ERROR
  "Initial robot pose is not available" when the pose is 3 s old) and
  ``/cg/lifecycle_manager_navigation`` (configures then activates the three at start, then
  ``get_state`` every 2 s: WARN "Managed node 'X' reports state 'inactive', expected 'active'" on a
  change, ERROR "CRITICAL FAILURE: SERVER X IS DOWN ..." without an answer in 4 s; diagnostics
  "Nav2 Health" 0.5 Hz).
- ``base_sensors`` (SingleThreadedExecutor): ``/cg/base_lidar`` (``/cg/scan`` 270 beams 10 Hz,
  stamped 20 ms before publishing; a guest's legs at 0.9 m ahead; WARN "Contamination warning ..."
  every 60-150 s; diagnostics), ``/cg/imu`` (``/cg/imu/data`` 50 Hz; diagnostics; recorded by no
  one, a sink-less sensor topic).
- ``speech`` (SingleThreadedExecutor): ``/cg/audio_capture`` (``/cg/audio/raw`` 15.6 Hz steady,
  ``/cg/audio/info`` latched once, diagnostics), ``/cg/vad`` (lifecycle, configures and activates
  itself; while active and someone speaks: ``/cg/speech/voice`` chunks 15.6 Hz in bursts of 1-2.5
  s, ``/cg/speech/vad`` latched on change, ``/cg/speech/utterance`` once per utterance; the dialogue
  manager deactivates it while the robot speaks and reactivates it after: a normal
  deactivate/activate several times a minute).
- ``asr`` (MultiThreadedExecutor, reentrant group): ``/cg/speech_recognizer`` JOINS LATE (loads its
  model 8 s before creating its node); buffers ``/cg/speech/voice``, serves ``~/transcribe``
  (0.25-0.6 s per utterance); diagnostics.
- ``hri`` (SingleThreadedExecutor, every call asynchronous): ``/cg/dialogue_manager`` (on a guest:
  greets, publishes a "hello" intent; on each utterance: ``transcribe`` (5 s timeout, WARN), INFO
  "Heard '...' -> intent X" or WARN "Low ASR confidence ..."; ``/cg/dialogue/intent``, the TTS
  ``say`` goals one after another, the VAD's ``change_state`` around them, the tablet's ``page``
  parameter through ``/cg/chest_tablet/set_parameters``; ``~/state`` latched on change; WARN "No
  result from the task executive ..." after 60 s), ``/cg/chest_tablet`` (``~/page`` latched on each
  parameter change, ``/cg/tablet/touch`` 4 Hz bursts of 2 s while a guest touches it; parameters
  ``page``, ``brightness``).
- ``tts`` (MultiThreadedExecutor): ``/cg/tts`` (``~/say`` action; ``/cg/audio/tts_out`` 16 Hz ONLY
  while speaking, ``~/speaking`` latched, INFO "Saying: '...'"; parameters ``volume`` (set at runtime
  by the console, INFO "Volume set to X") and ``voice``; diagnostics).
- ``executive`` (MultiThreadedExecutor, reentrant group; the behaviour tree a worker thread):
  ``/cg/task_executive`` (intents -> tasks: hello/goodbye wave the right arm, directions point the
  left arm, guide = navigate to the elevators and back home, check in = ``/hotel/lookup_booking``
  (5 s timeout) + ``/hotel/encode_key`` (8 s) + a hand-over gesture, late checkout and towels =
  ``/hotel/request_service``; ERROR "X: service /hotel/X did not answer within N s", "goal rejected
  by ..."; ``~/status`` latched on change, ``~/bt_log`` per behaviour-tree node change,
  ``~/task_result`` per task).
- ``safety`` (SingleThreadedExecutor): ``/cg/collision_monitor`` (``/cg/scan`` best effort; STOP when
  the scan is 0.5 s old by arrival or by stamp or something is within 0.3 m: WARN "Protective stop:
  <why>", INFO when cleared; ``/cg/safety/stop`` latched on change; one "scan data stale" stop at
  start; diagnostics; logs its QoS from safety.yaml at start), ``/cg/velocity_mux`` (teleop over
  navigation into ``/cg/diff_drive_controller/cmd_vel`` at the input's rate, zero while stopped,
  one zero when its inputs stop; ``~/active`` latched).
- ``state_publisher``: ``/cg/robot_state_publisher`` (URDF and 6 static transforms latched; head and
  wrists on ``/tf`` 10 Hz from the 50 Hz joint states).
- ``pms_bridge`` (MultiThreadedExecutor, 4 threads, reentrant services): ``/hotel_pms_bridge``
  (``/hotel/lookup_booking``, ``/hotel/encode_key``, ``/hotel/request_service``, each a blocking
  REST call of 0.2-1.2 s, a WARN "PMS API rate limited (HTTP 429)" every 60-150 s; from its event
  stream thread ``/hotel/room_status`` 0.5 Hz and its diagnostics "Opera PMS link" 1 Hz).
- ``diagnostics``: ``/diagnostic_aggregator`` (``/diagnostics`` -> ``/diagnostics_agg`` 1 Hz with
  paths ``/Robot/{Motors,Sensors,Speech,Navigation,Safety,Hotel,Other}/...``, STALE after 5 s;
  ``/diagnostics_toplevel_state``).
- ``recorder``: ``/rosbag2_recorder`` (serialized subscriptions to 18 topics as they appear, INFO
  "Subscribed to topic ..."; drained by a writer thread at 10 Hz).
- ``console`` (the operator): ``/cg/teleop_console``, the front desk's console, joins at 30 s, exits
  with code 0 after 60 s and comes back 25 s later (connected ~30-90 s, ~115-175 s, ...):
  subscribes ``/diagnostics_agg``, the executive's status and the compressed camera stream (which
  starts the camera's lazy publisher); 4 s after connecting sets ``/cg/tts`` ``volume``; 20-23 s after
  connecting turns the robot in place on ``/cg/cmd_vel_teleop`` 10 Hz (the mux switches to teleop).

Healthy dynamics: steady joint states 50 Hz, IMU 50 Hz, odometry and its ``/tf`` 25 Hz, audio
15.6 Hz, camera 15 Hz, scan 10 Hz, controller states 10 Hz, robot state ``/tf`` 30 msgs/s,
diagnostics 1 Hz (~10 arrays/s). Bursty or on demand: faces and people (guest in view), voice chunks
and utterances (guest speaking, VAD active), TTS audio (robot speaking), intents, PMS calls (about
half the utterances), arm goals, ``cmd_vel_nav`` / ``cmd_vel`` / plan and the 10 Hz pose (guiding,
~30 s), teleop (console), tablet touches, the compressed stream (console), the VAD's lifecycle
transitions, parameter changes (tablet page per dialogue state, TTS volume). The robot idles most
of the time: base still, odometry constant, pose at 1 Hz.

Load at rest (psutil, 2-core VM, the monitor not running): 40 % of one core in total over 30 s
(45-75 s after the start, the robot idle: navigation 12 %, recorder 6 %, controller_manager 5 %,
base_sensors, state_publisher, head_container 3 % each, every other process 2 % or less); in 5 s
windows over 100 s 34-60 %, navigation's MultiThreadedExecutor varying most (7-34 %).

The faults (default injection 130 s after the start: the console's second session connected), each
with its true root cause (the target node) and what a user sees:

- ``crash_vad``: a frame counter overflows the VAD's ring buffer: an uncaught ``IndexError`` in its
  audio callback ends the ``speech`` process (Python traceback in its log, exit code 1); the
  audio capture goes with it: ``/cg/audio/raw``, voice, utterances and its diagnostics stop; the
  dialogue manager hears nothing more (its ``change_state`` calls find no server). Root cause
  /cg/vad (process speech).
- ``hang_person_tracker``: the tracker's gallery save blocks on a hard NFS mount whose server is
  gone, inside the single-threaded head container: the camera's image, camera info and diagnostics,
  faces and people all stop (the three nodes stay in the graph); ``guest_present`` stays latched at
  its last value, so the dialogue neither greets new guests nor notices them leave. Root cause
  /cg/person_tracker (process head_container).
- ``hang_hotel_pms_bridge``: the PMS's TLS session is half-open: every REST call blocks without a
  timeout; the three services never answer (after 4 calls all executor threads are taken) while
  ``/hotel/room_status`` and the bridge's diagnostics go on from its event thread. Seen only when a
  guest asks for something the PMS does: the executive ERRORs "lookup_booking: service
  /hotel/lookup_booking did not answer within 5.0 s" (or encode_key/request_service), the task
  fails, the robot says "please see the front desk". Root cause /hotel_pms_bridge.
- ``degrade_audio_capture``: ALSA overruns on the USB microphone array drop ~65 % of the chunks:
  ``/cg/audio/raw`` ~5.5 Hz instead of 15.6; WARN "overrun!!! (at least X ms long) on capture device
  hw:2,0, dropping frames" every 3 s; utterances are short, the recogniser's confidence low, the
  dialogue WARNs "Low ASR confidence ..." and asks guests to repeat. Root cause /cg/audio_capture
  (process speech).
- ``stale_base_lidar``: the lidar loses its PTP sync and stamps every scan 2.6 s in the past:
  ``/cg/scan`` stays at 10 Hz; the collision monitor WARNs "Protective stop: scan data stale" and
  latches STOP (the mux commands zero), localization drops every scan (the "Message Filter
  dropping message" WARN) and publishes no pose nor map->odom; a guide fails ("localization
  lost", or "Initial robot pose is not available" for a new goal). Root cause /cg/base_lidar
  (process base_sensors).
- ``leak_dialogue_manager``: the dialogue context is never trimmed: the ``hri`` process grows
  ~3 MB/s; nothing is logged; the dialogue goes on. Root cause /cg/dialogue_manager (process hri).
- ``qos_collision_monitor``: a redeployed safety.yaml and a restart of the ``safety`` process (both
  nodes leave and come back, new pid) make the collision monitor subscribe ``/cg/scan`` RELIABLE
  against the lidar's best-effort publisher: INFO "Loaded parameters ... (scan_qos: reliable ...)",
  rclpy's incompatible-QoS WARN; it receives nothing: a permanent "Protective stop: scan data stale",
  ``/cg/safety/stop`` latched true, the mux commands zero (a guide makes no progress). ``/cg/scan``
  goes on at 10 Hz. Root cause /cg/collision_monitor (process safety).
- ``deactivate_localization``: scan matching diverges: ERROR "Scan matching diverged ...;
  deactivating, relocalization required" and the node deactivates itself (still in the graph,
  answers its lifecycle services, state inactive): its pose and map->odom stop; the lifecycle
  manager WARNs "Managed node 'localization' reports state 'inactive' ...", its diagnostics go
  ERROR; the next guide is rejected ("Initial robot pose is not available"). Root cause
  /cg/localization (process navigation).
- ``crashloop_tts``: the audio output device is held by another process: the TTS node starts, logs
  its voice, and 2-3 s later FATAL "ALSA: snd_pcm_open(plughw:1,0) failed: Device or resource busy"
  and aborts (exit 134); the launch file's respawn starts it again 1 s later: a restart loop every
  ~3.5 s (new pid, ``~/speaking`` re-latched, its diagnostics gone and back); the dialogue's say goals
  fail or go unanswered, the VAD stays deactivated when a say never finishes. Root cause /cg/tts.
- ``cpu_speech_recognizer``: CUDA fails and the recogniser falls back to CPU inference: WARN "CUDA
  error ... falling back to CPU inference (slow)", one core busy in its process, transcriptions 5x
  slower (the dialogue's 5 s timeout fires now and then), its diagnostics WARN. Root cause
  /cg/speech_recognizer (process asr).
- ``error_left_arm_controller``: the left arm's elbow violates its state tolerance: the controller
  ERRORs "Aborted due to state tolerance violation ..." and the controller manager ERRORs
  "Deactivating following controllers as their update resulted in an error: [ left_arm_controller ]";
  its ``controller_state`` stops, its diagnostics WARN, later "point" gestures are rejected (WARN
  "Can't accept new action goals. Controller is not running." and the executive's ERROR). The
  rest of the controller manager goes on. Root cause /cg/left_arm_controller (process
  controller_manager).
- ``kill_task_executive``: the kernel's OOM killer SIGKILLs the executive (no log line): its
  latched status stays; intents go unanswered, no gesture, guide or PMS call happens; after 60 s the
  dialogue WARNs "No result from the task executive ...". Root cause /cg/task_executive.
"""

from __future__ import annotations

import os
import sys

from bench.handwritten import Design, LaunchedRobot, main

for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

DESIGN = Design(
    module="bench.concierge.robot",
    nodes={
        "controller_manager": (
            "/cg/controller_manager",
            "/cg/joint_state_broadcaster",
            "/cg/left_arm_controller",
            "/cg/right_arm_controller",
            "/cg/diff_drive_controller",
        ),
        "head_container": ("/cg/head_camera", "/cg/face_detector", "/cg/person_tracker"),
        "navigation": (
            "/cg/map_server",
            "/cg/localization",
            "/cg/navigator",
            "/cg/lifecycle_manager_navigation",
        ),
        "base_sensors": ("/cg/base_lidar", "/cg/imu"),
        "speech": ("/cg/audio_capture", "/cg/vad"),
        "asr": ("/cg/speech_recognizer",),
        "hri": ("/cg/dialogue_manager", "/cg/chest_tablet"),
        "tts": ("/cg/tts",),
        "executive": ("/cg/task_executive",),
        "safety": ("/cg/collision_monitor", "/cg/velocity_mux"),
        "state_publisher": ("/cg/robot_state_publisher",),
        "pms_bridge": ("/hotel_pms_bridge",),
        "diagnostics": ("/diagnostic_aggregator",),
        "recorder": ("/rosbag2_recorder",),
        "console": ("/cg/teleop_console",),
    },
    faults={
        "crash_vad": ("file:crash", "/cg/vad", "speech"),
        "hang_person_tracker": ("file:hang", "/cg/person_tracker", "head_container"),
        "hang_hotel_pms_bridge": ("file:hang", "/hotel_pms_bridge", "pms_bridge"),
        "degrade_audio_capture": ("file:degrade", "/cg/audio_capture", "speech"),
        "stale_base_lidar": ("file:stale", "/cg/base_lidar", "base_sensors"),
        "leak_dialogue_manager": ("leak", "/cg/dialogue_manager", "hri"),
        "qos_collision_monitor": ("restart:reliable", "/cg/collision_monitor", "safety"),
        "deactivate_localization": ("file:deactivate", "/cg/localization", "navigation"),
        "crashloop_tts": ("respawn:crashloop", "/cg/tts", "tts"),
        "cpu_speech_recognizer": ("cpu", "/cg/speech_recognizer", "asr"),
        "error_left_arm_controller": ("file:error", "/cg/left_arm_controller", "controller_manager"),
        "kill_task_executive": ("kill", "/cg/task_executive", "executive"),
    },
    operator="console",
    join_s=30.0,
    run_s=60.0,
    again_s=25.0,
)
NODES, FAULTS = DESIGN.nodes, DESIGN.faults
if __name__ == "__main__":
    sys.exit(
        main(
            None,
            __doc__,
            "concierge",
            LaunchedRobot,
            DESIGN,
            130.0,
            "s from the start to the injection (130: the console's second session connected, a few "
            "guests served)",
        )
    )
