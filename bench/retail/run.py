"""Run the supermarket shelf-scanning robot under the monitor: healthy run, injected faults.

``python -m bench.retail.run [--healthy S] [--warmup S] [--post S] [--faults a,b] [--out DIR]
[--samples DIR] [--from-healthy RUN.sqlite]``

The robot's processes (`bench.retail.robot`) under the in-process monitor, as every hand-written
robot runs (`bench.handwritten`: the runs, their scores, the files written). ``rs`` is a
supermarket shelf-scanning inventory robot working store 0412 during opening hours: a tall mast with
three shelf cameras (low, middle, high bands, hardware-triggered together) whose frames are
stitched into one panorama, shelf-label OCR/barcode reading and an out-of-stock (gap) detector on
the panorama, an RFID reader that reads tagged merchandise while passing, a 3D lidar for
localization, shopper detection and a speed limiter near shoppers, a mission executive driving aisle
legs through a planner service and topping up its battery at a dock through a docking action, a
cloud uploader sending the results in batches over LTE, and a store associate's handheld app. Laid
out as a production ROS 2 Jazzy team lays it out: a single-threaded camera component container, a
multi-threaded perception container with callback groups, a lifecycle-managed lidar driver, a
Nav2-like navigation container, a safety process. Everything is under ``/rs`` except ``/tf``,
``/tf_static``, ``/diagnostics``, ``/diagnostics_agg``, ``/rosout``, ``/parameter_events`` and
the infrastructure node ``/diagnostic_aggregator``. Wall time everywhere.

The store: one schedule shared by every process through the wall clock
(`bench.retail.robot.shelf`, `bench.retail.robot.shopper`): the shelf segment (bay) in front of the
cameras changes every 3 s, 22 % of the bays have an out-of-stock gap, 50 % carry RFID tags; in 60 %
of the 30 s epochs a shopper stands 1.2-3.5 m from the robot for 4-10 s (the lidar sees them).
Whether the robot moves comes from its own odometry.

Substitutes (not installed here: vision_msgs, nav2_msgs, tf2_msgs, example_interfaces,
diagnostic_updater, message_filters): ``/tf`` and ``/tf_static`` carry geometry_msgs/TransformStamped,
one transform a message; the docking action (opennav_docking's DockRobot/UndockRobot) is
test_msgs/Fibonacci (``order`` 1 dock, 0 undock; feedback ``sequence[0]`` = cm to go; result
``sequence[0]`` 0 docked, 3 charger contacts fault, 5 canceled); the lifecycle manager's
ManageLifecycleNodes is std_srvs/SetBool (``true`` activate, ``false`` deactivate); the planner is
nav_msgs/GetPlan; gap detections (vision_msgs/Detection2DArray) and shoppers are
geometry_msgs/PoseArray; labels, RFID reads, the mission state, the uploader status and the mux's
active input are std_msgs/String (JSON or a word); the stitcher's ApproximateTime synchronizer is
written out in the node (3 inputs, queue 10, slop 0.015 s); the diagnostic updaters are a timer each
(statuses named ``node: task`` with a ``hardware_id``).

QoS: "sensor" best effort keep-last 5 (the three ``~/image_raw``, ``/rs/lidar/points``), "command"
reliable keep-last 1 (``/rs/cmd_vel_nav``, ``/rs/cmd_vel_dock``, ``/rs/cmd_vel_teleop``),
"reliable" keep-last 10 (``/rs/panorama``, labels, detections, shoppers, RFID reads, odometry,
``/rs/cmd_vel``, localization pose, plan, battery, uploader status, ``/tf``, ``/diagnostics``,
``/diagnostics_agg``), "latched" reliable transient-local depth 1 (``/rs/speed_limit``,
``/rs/mission_executive/state``, ``/rs/velocity_mux/active``, ``/rs/dock_server/charging``,
``/rs/robot_description``), ``/tf_static`` transient-local depth 100. Several publishers:
``/diagnostics`` (12 statuses from 11 nodes), ``/tf`` (base driver, localization).

Processes -> nodes (12 processes, 22 nodes; the handheld comes and goes):

- ``camera_container`` (component container, ONE SingleThreadedExecutor):
  ``/rs/shelf_cam_left``, ``/rs/shelf_cam_center``, ``/rs/shelf_cam_right`` (Basler ace2 on the
  trigger board's 5 Hz line: each ``~/image_raw`` 160x120 mono8 19 KB at 5 Hz, stamped with the
  trigger edge, the same stamp for the three; the bay, its gap and tag coded in the first pixels;
  diagnostics 1 Hz each "shelf_cam_X: ... topic status" with its serial number),
  ``/rs/image_stitcher`` (ApproximateTime over the three: ``/rs/panorama`` 480x120 57 KB at 5 Hz,
  stamped as the set, only when the three stamps lie within 0.015 s; unmatched images are dropped
  after 1 s with a WARN "Dropped N unmatched images: no set within slop 0.015 s (latest stamps
  ...)" at most every 5 s -- never in a healthy run; an audit archive of the panorama written to a
  USB SSD every 2 s).
- ``perception`` (component_container_mt: MultiThreadedExecutor, 2 threads; OCR, gap detection,
  odometry+diagnostics each a MutuallyExclusive group, the shopper detector a Reentrant group):
  ``/rs/label_reader`` (OCR + barcodes of the panorama once per new bay while the robot moves:
  ``~/labels`` JSON, ~0.3 Hz while scanning, 20-50 ms each; diagnostics "label_reader: Text
  recognition" on the GPU), ``/rs/gap_detector`` (``~/detections`` ONLY when a moving robot's new
  bay has a gap, INFO "Out-of-stock gap in bay N ..."; ~0.07 Hz, bursty), ``/rs/shopper_detector``
  (``/rs/lidar/points`` -> ``/rs/shoppers`` at the cloud's rate ONLY while a shopper is within 4 m;
  INFO "Person track N started/lost").
- ``lidar_driver``: ``/rs/lidar`` (lifecycle node, configured and activated by the lifecycle
  manager; ``/rs/lidar/points`` PointCloud2 9600 points x 16 B = 150 KB at 10 Hz best effort while
  active, stamped 50 ms before publishing; parameter ``rpm`` 600 (10 Hz; 300 -> 5 Hz, logged
  "Setting lidar_mode to 1024x5 (rpm 300); reinitializing sensor"); WARN "Window blockage detected
  ..." every 70-160 s; diagnostics "lidar: Ouster OS0-32 status" Streaming/Standby).
- ``base`` (SingleThreadedExecutor): ``/rs/base_driver`` (``/rs/cmd_vel`` in, 0.5 s timeout;
  ``/rs/odom`` and odom->base_link on ``/tf`` 20 Hz, still while idle; ``/rs/battery_state`` 1 Hz,
  charging while the mission state is ``charging``; diagnostics motor controller + battery),
  ``/rs/robot_state_publisher`` (``/rs/robot_description`` and 5 static transforms latched).
- ``navigation`` (component_container_mt: MultiThreadedExecutor, 3 threads): ``/rs/localization``
  (odometry + cloud in a MutuallyExclusive group -> ``/rs/localization/pose`` and map->odom on
  ``/tf`` at each cloud, 10 Hz; stops while the lidar is inactive; WARN "Scan match score 0.41 ..."
  every 60-150 s), ``/rs/planner`` (``/rs/planner/compute_path`` nav_msgs/GetPlan, 50-250 ms, its
  own MutuallyExclusive group), ``/rs/path_follower`` (``/rs/plan`` -> ``/rs/cmd_vel_nav`` 10 Hz for
  7 s, 0.5 m/s), ``/rs/lifecycle_manager`` (configures and activates the lidar at start, waiting for
  it; ``~/set_active`` SetBool; ``/rs/lidar/get_state`` every 2 s, ERROR "CRITICAL FAILURE: SERVER
  lidar IS DOWN ..." without an answer in 4 s; diagnostics 0.5 Hz).
- ``safety`` (SingleThreadedExecutor): ``/rs/speed_limiter`` (reads safety.yaml at start and logs
  it; ``/rs/lidar/points`` with the yaml's QoS (sensor_data), shoppers, mission state;
  ``/rs/speed_limit`` latched on change: 0.8 m/s, 0.3 with a shopper within 2.5 m (INFO "Shopper
  within 2.5 m ..."/"Zone clear ..."), 0.0 when no cloud for 0.5 s outside charging: WARN "No point
  cloud on /rs/lidar/points ...: safety field data stale, speed limited to 0.00 m/s" every 5 s (once
  at start, before the lidar is active); diagnostics), ``/rs/velocity_mux`` (teleop > docking >
  mission into ``/rs/cmd_vel`` at the input's rate, the mission's input clamped to the speed limit,
  one zero when its inputs stop; ``~/active`` latched, INFO "Switched to input 'X'").
- ``rfid``: ``/rs/rfid_reader`` (Impinj R700 over LLRP; while the robot moves past a tagged bay,
  ``/rs/rfid/reads`` at 20 Hz with 1-6 EPCs each -- bursts of up to 3 s, ~10 Hz on average while
  scanning; WARN "Antenna 3: reflected power ..." every 60-150 s while reading; diagnostics).
- ``docking`` (MultiThreadedExecutor, 3 threads, Reentrant action group): ``/rs/dock_server``
  (``/rs/dock_server/dock`` action: dock = 5 s backing onto the charger on ``/rs/cmd_vel_dock`` 10 Hz
  with feedback 10 Hz, then the contacts check, INFO "Docked: charging at 27.5 V / 6.2 A"; undock =
  2 s; feedback and ``/rs/cmd_vel_dock`` ONLY during goals; ``~/charging`` latched; diagnostics
  "dock_server: Charger contacts").
- ``mission`` (SingleThreadedExecutor, every call asynchronous; the mission a worker thread):
  ``/rs/mission_executive`` (waits for the planner and the dock, then a 40 s cycle from its start:
  three aisle legs at 0, 10, 20 s, each a ``compute_path`` call (5 s timeout) and a ``/rs/plan``;
  at 28 s the dock goal (15 s timeout), on success ``set_active false`` (the lidar goes inactive
  while charging), at 36 s ``set_active true`` and the undock goal; ``~/state`` latched on change:
  ``scanning:aisle_N``, ``docking``, ``charging``, ``undocking``, ``dock_failed``).
- ``cloud``: ``/rs/cloud_uploader`` JOINS LATE (waits 12 s for its LTE modem); keeps labels, gap
  detections and RFID reads; its uploader thread POSTs a batch every ``upload_period`` s (10,
  changed at runtime by the handheld, INFO "upload_period set to X s"), 0.3-0.9 s each, INFO
  "Uploaded batch N ..." and ``~/status``; WARN "Upload failed: HTTP 503 ...; retrying in 5 s"
  every 60-140 s; diagnostics "cloud_uploader: Upload link".
- ``diagnostics``: ``/diagnostic_aggregator`` (``/diagnostics`` -> ``/diagnostics_agg`` 1 Hz with
  paths ``/Shelfscanner/{Cameras,Sensors,Base,Safety,Perception,Navigation,Connectivity,Other}/...``,
  STALE after 5 s).
- ``handheld`` (the operator): ``/rs/associate_handheld``, a store associate's Zebra handheld app,
  joins at 35 s, exits with code 0 after 50 s and comes back 30 s later (connected ~35-85 s,
  ~115-165 s, ...): subscribes ``/diagnostics_agg``, the mission state and the gap detections
  (INFO "Gap alert ..."); 5 s after connecting sets the uploader's ``upload_period`` (5, 8 or 15 s);
  18-21 s after connecting nudges the robot back on ``/rs/cmd_vel_teleop`` 10 Hz (the mux switches
  to teleop).

Healthy dynamics (measured 15-75 s after the start, rclpy probe): cameras 5 Hz each, panorama
5 Hz, lidar 10 Hz, odometry 20 Hz, ``/tf`` ~30 msgs/s, localization pose 10 Hz (not while
charging), ``/diagnostics`` ~10.5 arrays/s, ``/diagnostics_agg`` and battery 1 Hz. Bursty or on
demand: RFID reads (~10 Hz averaged over a minute), labels (~0.3 Hz), gap detections (~0.07 Hz),
shoppers (~1.5 Hz averaged), ``/rs/cmd_vel_nav`` (21 s of each 40 s), ``/rs/cmd_vel_dock`` and the
dock feedback (7 s of each 40 s), plans (3 a cycle), teleop (the handheld), uploader status (one a
batch), latched states on change. Lifecycle transitions: the lidar configured+activated at start,
deactivated and activated at every charge (twice a cycle). Parameter changes: the uploader's
``upload_period`` (each handheld session). Late joiners: the uploader (12 s), the handheld.
Recurring WARNs: the lidar's window blockage, localization's scan match score, the RFID antenna,
the uploader's HTTP 503, the speed limiter's stale WARN at start.

Load at rest (psutil, 2-core VM, the monitor not running, the handheld not connected): 34-40 % of
one core in total in seven 15 s windows 15-75 s after the start over two starts, with and without an
rclpy probe subscribed to every topic (perception 10-11 %, navigation 10-12 %, base, safety, rfid
and camera_container 2-3 % each, every other process 1 % or less). Both multi-threaded containers
are exposed to rclpy's MultiThreadedExecutor re-queuing (ros2/rclpy#1452): in an earlier layout (4
threads, odometry at 30 Hz, a multi-threaded mission) they spiked to 30-78 % of a core for tens of
seconds; with this layout no spike was seen, but one may occur.

The faults (default injection 130 s after the start: the handheld's second session connected, the
mission in its fourth cycle: plans at ~132 and ~142 s, a dock goal at ~150 s), each with its true
root cause (the target node) and what a user sees:

- ``drift_shelf_cam_right``: the right camera's trigger input (opto-isolator) fails and the camera
  runs free: its stamps are 41 ms after the trigger edge; all three cameras keep 5 Hz, nothing is
  logged by the camera; the stitcher finds no set within its 15 ms slop: ``/rs/panorama`` stops,
  WARN "Dropped 75 unmatched images: no set within slop 0.015 s (latest stamps left ..., center
  ..., right ...)" every 5 s; no labels nor gap detections any more (RFID still reads). Root cause
  /rs/shelf_cam_right (process camera_container).
- ``hang_image_stitcher``: the stitcher's audit-archive write blocks forever on a hung USB SSD
  (task in D state) inside the single-threaded camera container: the three cameras' images and
  diagnostics and the panorama all stop (the four nodes stay in the graph), so labels and gaps
  stop too. Root cause /rs/image_stitcher (process camera_container).
- ``crash_gap_detector``: the nightly planogram push arrives truncated: INFO "Reloaded planogram
  ... (0 bays)" and the next panorama's facing lookup raises an uncaught ``IndexError``: the
  ``perception`` container exits with code 1 (traceback in its log); labels, gap detections and
  shoppers stop (the speed limiter no longer slows near shoppers). Root cause /rs/gap_detector
  (process perception).
- ``cpu_label_reader``: the OCR model's GPU plugin fails: WARN "[GPU] clWaitForEvents failed:
  CL_OUT_OF_RESOURCES; falling back to CPU inference ..." and inference on the CPU: one core busy in
  the perception process, OCR 6x slower, its diagnostics WARN "CPU fallback". Root cause
  /rs/label_reader (process perception).
- ``leak_cloud_uploader``: the uploader's retry queue keeps every batch: the ``cloud`` process
  grows ~3 MB/s; nothing is logged; uploads go on. Root cause /rs/cloud_uploader.
- ``hang_planner``: the costmap's update thread holds its mutex forever: ``compute_path`` never
  answers (its group is taken; the rest of the navigation container goes on); the mission ERRORs
  "Failed to plan to aisle N: service /rs/planner/compute_path did not answer within 5.0 s;
  skipping aisle" at each leg, the robot stops driving aisles (it still docks). Root cause
  /rs/planner (process navigation).
- ``abort_dock_server``: the charger contacts are faulted: each dock goal backs onto the dock (5 s
  of feedback and ``cmd_vel_dock``), then ERROR "Charger contacts not detected after docking
  (contact voltage 0.0 V, expected 27.5 V): aborting dock", its diagnostics ERROR; the mission
  ERRORs "Docking failed: goal aborted by /rs/dock_server (code 3); retrying in 3 s", then "Docking
  failed twice: ...; continuing the mission without charging" (state ``dock_failed``; the lidar
  stays active, the battery keeps draining). Root cause /rs/dock_server (process docking).
- ``param_lidar``: a technician runs ``ros2 param set /rs/lidar rpm 300`` (a short-lived CLI process
  and its hidden node ``/_ros2cli_<pid>``, `RetailRobot.inject`'s ``param:`` kind): the lidar logs
  "Setting lidar_mode to 1024x5 (rpm 300); reinitializing sensor" and ``/rs/lidar/points`` falls
  from 10 to 5 Hz; localization's pose and the shoppers follow at 5 Hz. Root cause /rs/lidar
  (process lidar_driver).
- ``qos_speed_limiter``: a redeployed safety.yaml and a restart of the ``safety`` process (both
  nodes leave and come back, new pid) make the speed limiter subscribe the cloud RELIABLE against
  the lidar's best-effort publisher: INFO "Loaded parameters ... (cloud_qos: reliable, depth 5
  ...)", rclpy's incompatible-QoS WARNs on both sides ("New publisher discovered ... offering
  incompatible QoS ..." in the speed limiter, "New subscription discovered ... requesting
  incompatible QoS ..." in the lidar); it receives nothing: "No point cloud on /rs/lidar/points
  since start: ... speed limited to 0.00 m/s" every 5 s, ``/rs/speed_limit`` latched 0, the mux
  clamps the mission to zero: the robot no longer moves (no RFID reads, labels nor gaps), though
  ``/rs/cmd_vel_nav`` and the cloud go on. Root cause /rs/speed_limiter (process safety).
- ``crashloop_rfid_reader``: the reader's firmware updates itself to 8.1.0 and rejects the
  driver's ROSpec: FATAL "LLRP: ERROR_MESSAGE from reader: M_FieldError (ROSpec 1: AntennaID 3 not
  supported) ..." and an uncaught RuntimeError (exit 1) 2-3 s after each start; the launch file's
  respawn starts it again 1 s later: a restart loop every ~4 s (new pid, its diagnostics gone and
  back, no RFID reads). Root cause /rs/rfid_reader (process rfid).
"""

from __future__ import annotations

import os
import subprocess
import sys

from bench.handwritten import ROOT, Design, LaunchedRobot, main

for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

DESIGN = Design(
    module="bench.retail.robot",
    nodes={
        "camera_container": ("/rs/shelf_cam_left", "/rs/shelf_cam_center", "/rs/shelf_cam_right",
                             "/rs/image_stitcher"),
        "perception": ("/rs/label_reader", "/rs/gap_detector", "/rs/shopper_detector"),
        "lidar_driver": ("/rs/lidar",),
        "base": ("/rs/base_driver", "/rs/robot_state_publisher"),
        "navigation": ("/rs/localization", "/rs/planner", "/rs/path_follower", "/rs/lifecycle_manager"),
        "safety": ("/rs/speed_limiter", "/rs/velocity_mux"),
        "rfid": ("/rs/rfid_reader",),
        "docking": ("/rs/dock_server",),
        "mission": ("/rs/mission_executive",),
        "cloud": ("/rs/cloud_uploader",),
        "diagnostics": ("/diagnostic_aggregator",),
        "handheld": ("/rs/associate_handheld",),
    },
    faults={
        "drift_shelf_cam_right": ("file:drift", "/rs/shelf_cam_right", "camera_container"),
        "hang_image_stitcher": ("file:hang", "/rs/image_stitcher", "camera_container"),
        "crash_gap_detector": ("file:crash", "/rs/gap_detector", "perception"),
        "cpu_label_reader": ("cpu", "/rs/label_reader", "perception"),
        "leak_cloud_uploader": ("leak", "/rs/cloud_uploader", "cloud"),
        "hang_planner": ("file:hang", "/rs/planner", "navigation"),
        "abort_dock_server": ("file:abort", "/rs/dock_server", "docking"),
        "param_lidar": ("param:rpm=300", "/rs/lidar", "lidar_driver"),
        "qos_speed_limiter": ("restart:reliable", "/rs/speed_limiter", "safety"),
        "crashloop_rfid_reader": ("respawn:crashloop", "/rs/rfid_reader", "rfid"),
    },
    operator="handheld",
    join_s=35.0,
    run_s=50.0,
    again_s=30.0,
)
NODES, FAULTS = DESIGN.nodes, DESIGN.faults


class RetailRobot(LaunchedRobot):
    """`LaunchedRobot` plus ``param:<name>=<value>``: a technician's ``ros2 param set <target> <name>
    <value>``, a short-lived CLI process (its own hidden node) calling the target's ``set_parameters``."""

    def inject(self, fault: str) -> None:
        how, target, _process = self.design.faults[fault]
        if not how.startswith("param:"):
            super().inject(fault)
            return
        name, _, value = how.removeprefix("param:").partition("=")
        log = open(self.logs / "ros2_param_set.log", "a")
        cmd = [sys.executable, "-m", self.design.module, "param_set", str(self.fault_dir), "0",
               target, name, value]
        self.transient.append(subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT,
                                               start_new_session=True, cwd=ROOT))


if __name__ == "__main__":
    sys.exit(
        main(
            None,
            __doc__,
            "retail",
            RetailRobot,
            DESIGN,
            130.0,
            "s from the start to the injection (130: the handheld's second session connected, the "
            "mission's third top-up charge due ~20 s later)",
        )
    )
