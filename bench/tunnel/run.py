"""Run the sewer / utility-tunnel inspection crawler under the monitor: healthy run, injected faults.

``python -m bench.tunnel.run [--healthy S] [--warmup S] [--post S] [--faults a,b] [--out DIR]
[--samples DIR] [--from-healthy RUN.sqlite]``

The robot's processes (`bench.tunnel.robot`) under the in-process monitor, as every hand-written
robot runs (`bench.handwritten`: the runs, their scores, the files written). ``tunnel`` is a tracked
sewer inspection crawler ("TC-3") lowered through manhole MH-14 into a DN600 vitrified-clay sewer
and inspecting towards MH-15 on a tether, with a surface van holding the tether reel / winch, the
operator's web UI and the recorder. The crawler: two brushless track motors on EtherCAT, a VN-100
IMU on a UART, an SCL3300 inclinometer, a tether power module (380 VDC -> 48 V), a laser ring
profiler hardware-triggered by track travel (pipe ovality), an imaging sonar profiler for the
flooded invert (on only while its transducer's wet switch is closed), a multi-gas head (H2S, CH4,
O2) on Modbus RTU, a pan-tilt-zoom inspection camera (RTSP + serial PTZ head), a lifecycle-managed
defect detector, an EKF-like localization fusing track odometry, IMU, inclinometer and the reel's
paid-out tether length, an inspection executive and a crawl controller, a twist_mux-like velocity
mux (the executive's commands and the surface operator's joystick), and a HOT-STANDBY PAIR of VDSL2
modem bridges (line A primary, line B standby) that relay the bandwidth-limited streams to the
surface. Laid out as a production ROS 2 Jazzy team lays it out: a single-threaded sensor component
container (laser profiler, sonar profiler, inclinometer on ONE SingleThreadedExecutor), the base
drivers on one SingleThreadedExecutor, the mission on a MultiThreadedExecutor (3 threads, callback
groups: executive calls / gas watchdog / the crawl action in a reentrant group), the reel on a
MultiThreadedExecutor (2 threads: control loop and the ``sync_length`` service in separate
groups). Everything is under ``/tc`` except ``/tf``, ``/diagnostics``, ``/diagnostics_agg``,
``/rosout``, ``/parameter_events`` and the infrastructure node ``/diagnostic_aggregator``. Wall
time everywhere.

The work cycle (`bench.tunnel.robot`: `phase`, `flooded`, `nudge`, `line_dropout`,
`failover_test`, `gas_levels`), shared by every process through the wall clock from ``TC_T0``,
which `TunnelRobot.start` sets to the robot's start. Bring-up 10 s, then one pipe segment every
56 s (segment k from 10 + 56 k s): transit 0-18 s (crawl 0.25 m/s, camera 5 Hz), inspect 18-40 s
(0.08 m/s, camera 10 Hz, the defect detector configured (first time) and activated at 17 s,
deactivated at 40 s), survey at the joint 40-48 s (stopped, PTZ 360-degree sweep, a still captured
through ``/tc/ptz_camera/capture`` at 42 s), reel sync 48-56 s (the executive calls
``/tc/reel_controller/sync_length`` at 48 s, 2 s timeout). Each phase change sets
``/tc/mission/mode`` and ``~/state`` (latched) and, through ``/tc/ptz_camera/set_parameters``, the
camera's ``frame_rate`` parameter (5 -> 10 -> 5 Hz: ``/parameter_events``). The sag in every
segment is flooded 26-44 s: the laser profile shows water over the invert and the sonar profiles.
At 44-47 s of segments 1, 4, 7, ... the surface operator nudges the crawler with the joystick (the
mux switches to ``joystick``). An H2S pocket at a lateral in segments 2, 6, 10, ...: gas alarm A1
(H2S >= 5 ppm) raised ~25 s and cleared ~31 s into the segment (WARNs from the gas monitor and the
executive, the crawl goes on). VDSL2 line A drops 1-3 s once in every 90 s window (seeded: ~76.7 s
for 1.5 s and ~121.6 s for 2.5 s in every run): modem A WARNs "loss of margin ... fast retrain",
relays nothing meanwhile, INFOs "back in showtime after N s (M frames dropped)"; no failover. A
scheduled hot-standby test at 150 s and then every 300 s: modem A releases the link for 10 s,
modem B WARNs "Primary link status silent ... taking over" and relays, A reclaims ("reclaim" in its
link status for 3 s) and B returns to hot standby. The site supervisor's tablet connects to the
web UI bridge 30-70 s of every 120 s (2 subscriptions created, then destroyed). The operator's
console joins at 50 s, exits with code 0 after 40 s and is started again 30 s later.

Substitutes (not installed here: tf2_msgs, diagnostic_updater, twist_mux, std_srvs, rosbridge,
any gas / modem / inspection message package): ``/tf`` carries geometry_msgs/TransformStamped, one
transform a message; the gas readings, the gas alarm, the tether link status, the defect reports,
the mission mode and the executive's state are std_msgs/String (JSON); the crawl action is
test_msgs/Fibonacci (``order`` = speed in mm/s); ``~/capture`` and ``~/sync_length`` are
test_msgs/BasicTypes (``string_value`` the still's path, ``float64_value`` the tether paid out);
the laser and sonar profiles are sensor_msgs/LaserScan (ring: 360 beams over 360 degrees, water in
the intensities; sonar: 200 beams over the invert); ovality and tilt are
geometry_msgs/Vector3Stamped (ovality %, min and max diameter; roll, pitch); the reel's payout is a
sensor_msgs/JointState (position = tether paid out m, effort = tension N); the mux, the relays, the
web bridge and the diagnostic updaters (a timer each, statuses ``node: task`` with a
``hardware_id``) are hand-written.

QoS: "sensor" best effort keep-last 5 (``/tc/imu/data``, both profiles, both camera streams),
"command" reliable keep-last 1 (``/tc/cmd_vel/auto``, ``/tc/cmd_vel/joy``, ``/tc/cmd_vel``),
"latched" reliable transient-local depth 1 (``/tc/mission/mode``, ``/tc/inspection_executive/state``,
``/tc/gas_monitor/alarm``, ``/tc/cmd_vel_mux/active``), reliable keep-last 10 for everything else.
The recorder and the web UI bridge subscribe best effort (raw) except to the latched topics.
Several publishers on one topic: ``/diagnostics`` (12 nodes), ``/tf`` (localization's odom->base_link
20 Hz and map->odom 1 Hz, the camera's base_link->camera_link 5 Hz), and the hot-standby pair's
``/tc/tether/link``, ``/tc/surface/image/compressed``, ``/tc/surface/odom`` (both modems have
publishers; only the active one publishes).

Processes -> nodes (14 processes, 20 nodes; the console comes and goes):

- ``crawler_base`` (ONE SingleThreadedExecutor): ``/tc/track_driver`` (``/tc/cmd_vel`` ->
  ``/tc/tracks/odom`` 25 Hz stamped 3 ms back, ``/tc/tracks/joint_states`` 10 Hz; 0.5 s command
  timeout, 0.25 m/s^2; diagnostics), ``/tc/imu_driver`` (``/tc/imu/data`` 50 Hz stamped 2 ms back),
  ``/tc/cmd_vel_mux`` (``/tc/cmd_vel/joy`` priority 100 over ``/tc/cmd_vel/auto`` priority 10 ->
  ``/tc/cmd_vel`` on each selected input; ``~/active`` latched; INFO "Input 'joystick' ... took
  over"), ``/tc/power_monitor`` (``/tc/power/state`` BatteryState 1 Hz; diagnostics every 2 s).
- ``sensor_container`` (component container, ONE SingleThreadedExecutor): ``/tc/laser_profiler``
  (``~/profile`` every 20 mm of travel from ``/tc/tracks/joint_states``: 12.5 Hz in transit, 4 Hz
  inspecting, NOTHING while stopped, stamped 10 ms back; ``~/ovality`` every 10 profiles, > 5 % in
  odd segments 30-33 s; diagnostics), ``/tc/sonar_profiler`` (``~/profile`` 5 Hz ONLY while flooded,
  stamped 50 ms back; INFO "Transducer submerged ..." / "Transducer dry ..."; diagnostics),
  ``/tc/inclinometer`` (``~/tilt`` 5 Hz; diagnostics every 2 s).
- ``camera``: ``/tc/ptz_camera`` (``~/image/compressed`` 30 KB JPEG at its ``frame_rate`` parameter,
  5 or 10 Hz, stamped 40 ms back; ``~/ptz_state`` and base_link->camera_link on ``/tf`` 5 Hz;
  ``~/capture`` ~0.25 s; diagnostics).
- ``perception``: ``/tc/defect_detector`` (lifecycle node, transitions from the executive; while
  active subscribes the camera, the laser profile and ovality, the sonar profile; ``~/defects``
  ONLY when it finds one: 0-2 seeded defects an inspection plus a deformation (BAA) in odd
  segments; INFO "Defect ..."; ``~/transition_event``).
- ``localization``: ``/tc/crawler_localization`` (tracks odometry, IMU best effort, inclinometer,
  ``/tc/reel/payout`` -> ``/tc/odometry/filtered`` and odom->base_link 20 Hz, map->odom 1 Hz;
  diagnostics "imu topic status" 45-55 Hz, "odometry topic status" 22-28 Hz, "chainage").
- ``mission`` (MultiThreadedExecutor, 3 threads, groups): ``/tc/inspection_executive`` (the cycle
  above from a thread; clients of ``/tc/crawl_controller/crawl``, ``/tc/ptz_camera/set_parameters``,
  ``/tc/ptz_camera/capture``, ``/tc/reel_controller/sync_length``,
  ``/tc/defect_detector/{get_state,change_state}``; gas watchdog 1 Hz: readings older than 5 s ->
  ERROR "Gas readings ... stale ...: halting the crawler", the crawl goal cancelled; diagnostics),
  ``/tc/crawl_controller`` (``~/crawl`` action -> ``/tc/cmd_vel/auto`` 10 Hz while a goal runs: 40 s
  of every 56, steering against the inclinometer's roll).
- ``gas``: ``/tc/gas_monitor`` (``~/readings`` 1 Hz; ``~/alarm`` latched on change; diagnostics).
- ``tether_a``: ``/tc/tether_modem_a`` (primary: ``/tc/tether/link`` 2 Hz; relays the camera ->
  ``/tc/surface/image/compressed`` 3 Hz, transcoded to 12 KB, header kept, ~120-170 ms after its
  stamp; ``/tc/odometry/filtered`` -> ``/tc/surface/odom`` 5 Hz, ~40-50 ms after its stamp; each
  message relayed once; diagnostics).
- ``tether_b``: ``/tc/tether_modem_b`` (hot standby: the same subscriptions; publishes on the three
  relay topics ONLY while it has taken over: the failover test; diagnostics always).
- ``reel`` (MultiThreadedExecutor, 2 threads, groups): ``/tc/reel_controller`` (``/tc/surface/odom``
  -> the drum keeps 0.5 m slack; ``/tc/reel/payout`` 5 Hz; ``~/sync_length`` 0.15-0.35 s; WARN
  "Crawler telemetry N s old ..." when the relayed odometry is > 0.3 s old while the crawler moves;
  diagnostics).
- ``recorder``: ``/tc/recorder`` (16 topics raw, a zlib-6 chunk every 10 s into a temp bag file;
  publishes nothing).
- ``web_ui``: ``/tc/web_ui_bridge`` (rosbridge-like: the operator's browser's 9 raw subscriptions
  for good, the tablet's 2 on and off; ``/tc/cmd_vel/joy`` 10 Hz while nudging; INFO "Operator
  joystick engaged ...").
- ``diagnostics``: ``/diagnostic_aggregator`` (``/diagnostics`` -> ``/diagnostics_agg`` 1 Hz,
  ``/Crawler/{Drive,Sensors,Safety,Localization,Tether,Surface,Mission,Other}/...``, STALE after 5 s).
- ``operator``: ``/tc/operator_console`` (echoes the executive's state, the gas readings and the
  defects to its stdout).

Healthy dynamics measured in the smoke test on the 2-core VM (rclpy probe subscribing every topic
best effort, 10-12 s windows in segments 0 and 1): ``/tc/imu/data`` 49.3 Hz, ``/tc/tracks/odom``
24.9 Hz, ``/tc/odometry/filtered`` 20 Hz, ``/tf`` ~26 msgs/s (2 publishers), ``/tc/tracks/joint_states``
10 Hz, ``/tc/ptz_camera/image/compressed`` 9.9 Hz inspecting, ``/tc/cmd_vel/auto`` and
``/tc/cmd_vel`` 9.9 Hz while crawling, ``/tc/laser_profiler/profile`` 4.0 Hz inspecting (0 when
stopped), ``/tc/laser_profiler/ovality`` 0.4 Hz inspecting, ``/tc/surface/image/compressed`` 3 Hz,
``/tc/surface/odom`` 5 Hz, ``/tc/reel/payout``, ``/tc/inclinometer/tilt``, ``/tc/ptz_camera/ptz_state``
5 Hz, ``/tc/sonar_profiler/profile`` 5 Hz while flooded, ``/tc/tether/link`` 2 Hz, ``/diagnostics``
~11.3 arrays/s (12 publishers), gas, power and ``/diagnostics_agg`` 1 Hz; the camera's 5 Hz in
transit and the profiler's 12.5 Hz in transit follow from the code, not probed. The first 170 s of a
healthy run log the cycle above, the two line dropouts, the H2S alarm in segment 2 and the failover
test at 150 s; no ERROR.

Load (psutil, sum over the 13 processes, operator, monitor and probe not running, 14-15 s
windows): 60 % of one core at 22-37 s (transit end, inspection start), 54 % at 68-82 s (transit,
inspection): crawler_base ~14 %, localization ~10 %, recorder ~8-9 %, sensor_container ~5-6 %,
each modem ~4 %, every other process 3 % or less. Within the 50-70 % aimed at, at the rates above
(the IMU at 50 Hz and the track odometry at 25 Hz are lower than a production crawler's 100-200 Hz
for that reason; the recorder does not record the raw camera, the IMU or the track odometry).

Faults checked by hand in the smoke test (fault files written at 86-90 s and 130 s; the crash loop
with a launch-like respawn loop, the restart by Ctrl-C and a new process 1.5 s later): all eleven
behave as described below (``rate`` 20 Hz, ``lag`` ~0.4 s, the sonar silent, the sync ERROR, the
detector's CPU ~60 %, the split brain 6 Hz / 10 Hz with two publishers, the web bridge +50 MB in
15 s, the container's three nodes silent, the gas ERROR and the cancelled crawl, the camera
restarting every ~4.3 s, both incompatible-QoS WARNs). One short runner run (``--healthy 30
--warmup 20 --post 15 --faults qos_crawler_localization``) ran end to end.

Fault files: the harness's `NamespacedRobot` names a node's fault file by its namespace and name,
``FAULT_DIR/tc.<node>`` (`bench.tunnel.robot.FaultFile`).

The faults (default injection 95 s after the start: segment 1, 11 s into its inspection, crawling at
0.08 m/s with the defect detector active since 83 s; the sag flooded 92-110 s, the survey 106-114 s
with the still at ~108 s, the joystick nudge 110-113 s, the tether sync at 114 s, segment 2's
transit from 122 s, line A's dropout at ~121.6 s), each with its root cause (the target node) and
what a user sees:

- ``hang_laser_profiler``: the ring profiler head loses its frame sync and the driver's resync calls
  a blocking ``read()`` with no timeout inside the single-threaded sensor container: WARN "Serial
  frame timeout on /dev/ttyTHS1 (no 0xAA55 sync word for 250 ms); re-synchronizing ..." once at
  the next 20 mm of travel, then the laser profile and ovality, the SONAR profile (the sag is
  flooded) and the INCLINOMETER all stop, their three diagnostics go STALE in the aggregator; the
  crawl controller steers on a frozen roll, the localization on a frozen pitch; the detector gets no
  profiles. Root cause /tc/laser_profiler (process sensor_container).
- ``crash_gas_monitor``: the gas head sends a truncated Modbus reply (the O2 register missing) and
  the driver's unpacking raises: a ValueError traceback on stderr only, the ``gas`` process exits
  with code 1 at once, its node still listed (as a C++ abort leaves it); nothing on /rosout from it.
  5 s later the executive ERRORs "Gas readings from /tc/gas_monitor/readings stale (5.x s): halting
  the crawler (confined-space entry procedure)" (again every 10 s), the crawl goal is cancelled
  (WARN "Crawl goal cancelled ..."): ``/tc/cmd_vel/auto`` and ``/tc/cmd_vel`` stop, the tracks stop,
  the laser profiler stops triggering, the reel stops paying out; the executive's diagnostics ERROR;
  at 122 s "Segment 2 transit: crawl not started, gas readings stale". Root cause /tc/gas_monitor
  (process gas).
- ``crashloop_ptz_camera``: the PTZ head's new firmware answers the zoom with its unit ("3.5x"): a
  ValueError traceback 2-3 s after each start (the driver's head poll), the ``camera`` process exits
  with code 1 and the launch file's respawn starts it again 1 s later: a restart every ~4.3 s (new
  pid, INFO "RTSP stream ... opened" each time), the camera stream in bursts at its default 5 Hz,
  ``/tc/surface/image/compressed`` in bursts, the detector's frames in bursts, the survey still fails
  when the camera is down (ERROR "Segment 1 survey: /tc/ptz_camera/capture did not answer within
  2.0 s" or "... not available"), the executive's frame-rate change may WARN. Root cause
  /tc/ptz_camera (process camera).
- ``rate_imu_driver``: UART framing errors make the VN-100 driver fall back to 230400 baud: WARN
  "UART framing errors on /dev/ttyTHS0 ...: async output rate reduced to 20 Hz" once,
  ``/tc/imu/data`` falls from 50 to 20 Hz; the localization's "imu topic status" WARNs "Frequency
  too low." in ``/diagnostics``. Root cause /tc/imu_driver (process crawler_base).
- ``lag_tether_modem_a``: line A retrains with a deeper interleaver (impulse-noise protection) and
  modem A says nothing: ``/tc/surface/image/compressed`` and ``/tc/surface/odom`` keep 3 and 5 Hz but
  arrive ~0.4 s after their stamps (were ~0.15 and ~0.05 s); the reel controller WARNs "Crawler
  telemetry 0.40 s old (limit 0.30 s): payout lagging the crawler by N m, tether tension N N"
  every 5 s while the crawler moves (until 106 s, again at the nudge and from 122 s). Root cause
  /tc/tether_modem_a (process tether_a).
- ``slow_reel_controller``: a new winch parameter makes the drum encoder re-home before each length
  read: INFO "Drum encoder: absolute re-homing before each length read (encoder_homing:
  every_request)" at the sync (114 s), ``sync_length`` takes 4 s, the executive ERRORs "Segment 1:
  tether length sync failed: /tc/reel_controller/sync_length did not answer within 2.0 s; chainage
  not corrected" (~116 s, and at every later sync); the reel's payout stays at 5 Hz (its own
  callback group). Root cause /tc/reel_controller (process reel).
- ``cpu_defect_detector``: the config sync reloads the detector's model at full resolution on the
  CPU: WARN "Model reloaded by the config sync: crackseg-v4 at full resolution ...: inference on
  the CPU" once and a core busy in the ``perception`` process (~60 % of a core measured beside the
  robot). Root cause /tc/defect_detector (process perception).
- ``leak_web_ui_bridge``: the browser's websocket send queue is never drained: the ``web_ui``
  process grows ~3 MB/s (measured 78 -> 130 MB in 15 s); nothing is logged; the bridge goes on.
  Root cause /tc/web_ui_bridge (process web_ui).
- ``qos_crawler_localization``: a redeployed crawler_localization.yaml and a restart of the
  ``localization`` process (new pid) make the EKF subscribe the IMU RELIABLE against the driver's
  best-effort publisher: INFO "Loaded crawler_localization.yaml (imu0 qos: reliable, ...)", then
  rclpy's incompatible-QoS WARNs on both sides (the imu_driver's and the localization's), no IMU in
  the filter (yaw frozen), "imu topic status" WARN "No events recorded."; ``/tc/odometry/filtered``
  and ``/tf`` go on at 20 Hz. Root cause /tc/crawler_localization (process localization).
- ``splitbrain_tether_modem_b``: modem B's heartbeat timeout is read as 0.2 s (a ms/s unit slip in
  its new config) while A's link status comes every 0.5 s: B WARNs "Primary link status silent for
  0.3x s (> 0.2 s): taking over the surface link on line B" once and relays beside A for good (a
  failover that should not have happened: both active): ``/tc/surface/image/compressed`` 6 Hz,
  ``/tc/surface/odom`` 10 Hz, ``/tc/tether/link`` 4 Hz, each from two publishers; modem A WARNs "Link
  arbitration conflict: tether_modem_b claims ACTIVE while this primary is active ..." every 5 s.
  Root cause /tc/tether_modem_b (process tether_b).
- ``stale_sonar_profiler``: the sonar transducer's wet switch sticks open: the driver believes it
  is dry and INFOs "Transducer dry (wet switch open): sonar profiling off, laser only" (at the
  injection, the sag being flooded since 92 s), ``/tc/sonar_profiler/profile`` stops, its diagnostics
  say "Dry: standby" (OK); the defect detector, seeing water over the invert in the laser profile,
  WARNs "Water over the invert but no sonar profile for N s: below-water-line section not
  inspected" every 5 s until it is deactivated at 106 s (and in every later sag). Root cause
  /tc/sonar_profiler (process sensor_container).
"""

from __future__ import annotations

import os
import sys
import time

from bench.handwritten import Design, LaunchedRobot, main

for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

DESIGN = Design(
    module="bench.tunnel.robot",
    nodes={
        "crawler_base": ("/tc/track_driver", "/tc/imu_driver", "/tc/cmd_vel_mux", "/tc/power_monitor"),
        "sensor_container": ("/tc/laser_profiler", "/tc/sonar_profiler", "/tc/inclinometer"),
        "camera": ("/tc/ptz_camera",),
        "perception": ("/tc/defect_detector",),
        "localization": ("/tc/crawler_localization",),
        "mission": ("/tc/inspection_executive", "/tc/crawl_controller"),
        "gas": ("/tc/gas_monitor",),
        "tether_a": ("/tc/tether_modem_a",),
        "tether_b": ("/tc/tether_modem_b",),
        "reel": ("/tc/reel_controller",),
        "recorder": ("/tc/recorder",),
        "web_ui": ("/tc/web_ui_bridge",),
        "diagnostics": ("/diagnostic_aggregator",),
        "operator": ("/tc/operator_console",),
    },
    faults={
        "hang_laser_profiler": ("file:hang", "/tc/laser_profiler", "sensor_container"),
        "crash_gas_monitor": ("file:crash", "/tc/gas_monitor", "gas"),
        "crashloop_ptz_camera": ("respawn:crashloop", "/tc/ptz_camera", "camera"),
        "rate_imu_driver": ("file:rate", "/tc/imu_driver", "crawler_base"),
        "lag_tether_modem_a": ("file:lag", "/tc/tether_modem_a", "tether_a"),
        "slow_reel_controller": ("file:slow", "/tc/reel_controller", "reel"),
        "cpu_defect_detector": ("cpu", "/tc/defect_detector", "perception"),
        "leak_web_ui_bridge": ("leak", "/tc/web_ui_bridge", "web_ui"),
        "qos_crawler_localization": ("restart:reliable", "/tc/crawler_localization", "localization"),
        "splitbrain_tether_modem_b": ("file:splitbrain", "/tc/tether_modem_b", "tether_b"),
        "stale_sonar_profiler": ("file:stuck", "/tc/sonar_profiler", "sensor_container"),
    },
    operator="operator",
    join_s=50.0,
    run_s=40.0,
    again_s=30.0,
)
NODES, FAULTS = DESIGN.nodes, DESIGN.faults


class TunnelRobot(LaunchedRobot):
    """`LaunchedRobot` that starts the inspection cycle (``TC_T0``) with the robot."""

    def start(self) -> None:
        os.environ["TC_T0"] = repr(time.time())  # inherited by every process of this run
        super().start()


if __name__ == "__main__":
    sys.exit(
        main(
            None,
            __doc__,
            "tunnel",
            TunnelRobot,
            DESIGN,
            95.0,
            "s from the start to the injection (95: segment 1 inspecting, 11 s into its inspection; the "
            "flooded sag 92-110 s, the survey 106-114 s, the tether sync at 114 s)",
        )
    )
