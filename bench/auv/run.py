"""Run the AUV robot (a survey AUV's companion computer) under the monitor: healthy run, injected faults.

``python -m bench.auv.run [--healthy S] [--warmup S] [--post S] [--faults a,b] [--out DIR]``

The AUV's processes (`bench.auv.robot`) under the in-process monitor, as every hand-written robot
runs (`bench.handwritten`: the runs, their scores, the files written). The vehicle is on a HIL bench
(its drivers sample a vehicle model's ground truth as they would sample their hardware) with a
fibre-optic micro-tether to the topside during trials. All nodes are on wall time. Every process runs
one single-threaded executor, rclpy's C++ EventsExecutor (``rclpy.experimental``, adopted for CPU: no
guard conditions, so service answers are polled from timers and a changed fault word is applied from
a 1 Hz timer), except the mission process: a MultiThreadedExecutor (4 threads) whose behaviour
actions block in their execute callbacks (a reentrant group), beside the setpoint timer and the
odometry subscription (their own mutually exclusive group) and the executive (another). QoS: "sensor"
is best effort keep-last 5 (every driver's stream, the odometry, the thruster states), "command"
reliable keep-last 1 (setpoint, wrench, thruster commands), "reliable" keep-last 10 (USBL fixes,
battery, diagnostics, telemetry), "latched" reliable transient-local depth 1 (navigation and mission
states, the leak state, the current survey line).

The world: a 60 x 110 m survey box in 25-35 m of water (a sloping sandy bottom, a steep rocky ridge
across it at x ~ 25 m that rises 9 m); the launch point 15 m south of it; a 0.05 m/s tidal current.

The stack. HIL (process ``sim``): ``/sim/vehicle_simulator`` (4-DOF model, thrust from the ESCs'
reported rpm, slightly positively buoyant) publishes ``/sim/ground_truth`` (Odometry) at 20 Hz.
Sensors: the AHRS (``/sensors/ahrs/ahrs_driver``, process ``ahrs``) ``/sensors/ahrs/imu`` 50 Hz from
its serial thread; the DVL (``/sensors/dvl/dvl_driver``, process ``dvl``) ``/sensors/dvl/twist``
(TwistWithCovarianceStamped) and ``/sensors/dvl/altitude`` (Range) at 8 Hz: no bottom lock within 3 m
of the surface, beyond 40 m altitude, on ~70 % of the pings over the ridge and in 1-4 s dropouts every
30-70 s (then covariance[0] = -1 and range = inf; a WARN "Bottom lock lost" once the loss held 1 s, an
INFO when regained); the pressure sensor (``/sensors/depth/pressure_driver``, process ``depth``)
``/sensors/depth/pressure`` (FluidPressure) 20 Hz. Process ``positioning``: ``/sensors/gps/gps_driver``
(``/sensors/gps/fix``: 5 Hz with a fix only while surfaced, 2-5 s after breaking the surface; 1 Hz
NO_FIX while submerged) and ``/sensors/usbl/usbl_receiver`` (``/sensors/usbl/fix``, reliable, an
aperiodic fix every 2-6 s while deeper than 2 m, stamped with the interrogation time 0.2-0.6 s before
it arrives; ~6 % multipath outliers 20-40 m off). Payload drivers (process ``payload_drivers``):
``/payload/multibeam/multibeam_driver``, a lifecycle node (configured at preflight, activated by the
executive for each survey block, deactivated before surfacing; active, ``/payload/multibeam/points``,
256 beams, at 350/range Hz up to 10 Hz, the range 3 x altitude + 10 m: ~6-10 Hz) and
``/payload/camera/camera_driver`` (``/payload/camera/image_raw`` 320x240 mono 4 Hz only while the DVL
altitude is below 9 m: on over the ridge, off elsewhere). The payload container (process
``payload_container``, three nodes on ONE single-threaded executor):
``/payload/multibeam/bathymetry_processor`` (each ping georeferenced with ``/nav/odometry`` ->
``/payload/multibeam/bathymetry``, the ping's stamp), ``/payload/camera/image_enhancer`` (every other
frame -> ``/payload/camera/image_enhanced`` 2 Hz) and ``/payload/coverage_monitor`` (``/payload/coverage``
Float32 1 Hz, its diagnostics).

Navigation (process ``navigation``): ``/nav/navsat_transform`` (valid fixes -> ``/nav/gps_pose``) and
``/nav/ekf_filter``: it predicts on each AHRS message with the DVL's velocity (a decaying velocity
model while it has no lock), depth from the pressure, position corrected by the USBL fixes (gated at
12 m: an outlier is rejected with a WARN) and by the GPS when surfaced; ``/nav/odometry`` at 25 Hz
(every other AHRS message) stamped with that AHRS message's stamp; ``/nav/status`` latched
(WAITING_FOR_GPS -> OK; DEAD_RECKONING, a WARN, after 3 s without DVL lock below 3 m); a DVL velocity
older than 1 s is rejected (a WARN every 5 s); an ERROR every ~6 s when the AHRS is silent for 1 s.
Control (process ``control``): ``/control/depth_heading_controller`` (20 Hz timer: line-of-sight
heading, depth and speed loops towards ``/control/setpoint``; ``cruise_speed`` a runtime parameter;
zero wrench and an ERROR when the odometry is > 1 s old) -> ``/control/wrench`` ->
``/control/thruster_allocator`` -> ``/control/thrusters/command`` (JointState rpm, 20 Hz). Process
``thrusters``: ``/control/thruster_driver``, the ESC bridge: its RS-485 thread writes the newest
command at 20 Hz and publishes ``/control/thrusters/state`` (rpm, current); watchdog: no command for
0.5 s stops the thrusters (an ERROR).

Mission: ``/mission/survey_planner`` (process ``planner``) serves ``/mission/survey_planner/plan_line``
(GetPlan, 0.1-0.3 s: a survey line's 7 waypoints at 10 m altitude). Process ``mission`` (the
MultiThreadedExecutor): ``/mission/behavior_server`` serves the actions ``/mission/dive``,
``/mission/follow_line``, ``/mission/surface``, ``/mission/go_home`` (test_msgs/Fibonacci; feedback
the percent done at 5 Hz) and steers the controller with ``/control/setpoint`` (5 Hz);
``/mission/mission_executive``, a state machine at 2 Hz: PREFLIGHT (the leak detector's self test
``/auv/leak_detector/self_test``, the multibeam configured through its ``change_state``, the EKF
initialized from GPS) -> DIVE -> SURVEY (multibeam activated; per line the planner's plan, 4 s
timeout, latched on ``/mission/current_line``, then a ``follow_line`` goal) -> after 3 lines SURFACE
(multibeam deactivated) -> GPS_FIX (20 s on the surface) -> DIVE ... (12 lines) -> GO_HOME ->
COMPLETE; ``/mission/state`` latched; it serves ``/mission/report`` (Trigger) for the topside.
Health (process ``health``): ``/auv/battery_monitor`` (``/auv/battery`` 1 Hz, current from the
thrusters'), ``/auv/leak_detector`` (``/auv/leak`` latched), ``/auv/diagnostic_aggregator``
(``/diagnostics`` from fifteen nodes with ``node: task`` names and hardware ids -> ``/diagnostics_agg``
and ``/diagnostics_toplevel_state`` 1 Hz, STALE after 5 s). Comms (process ``comms``):
``/comms/acoustic_modem`` (a status packet on ``/comms/modem/tx`` every 5 s while submerged, the
topside's pings on ``/comms/modem/rx`` every 8-15 s, 15 % of them lost with a WARN; silent on the
surface) and ``/comms/telemetry_bridge`` (subscribes to eleven topics, a 1 Hz JSON digest on
``/comms/telemetry`` for the topside). The recorder (``/rosbag2_recorder``, process ``recorder``, like
``ros2 bag record``): serialized subscriptions to 15 topics (odometry, USBL, GPS, DVL, bathymetry,
states, setpoint, battery, modem, diagnostics_agg, /rosout) made as their publishers appear, a split
every 60 s.

Healthy dynamics: GPS fix and EKF initialization 2-5 s after the start, the dive at once (~27 s to
21 m), the survey block from ~31 s: line 0 (~31-108 s: 18 m of transit and 60 m at ~1 m/s), line 1
(~108-185 s), line 2 (to ~250 s), surfacing at ~250 s (~42 s up: the multibeam deactivated, its
topic silent; the DVL loses lock near the surface, the modem falls silent, the GPS gets its fix and
goes 1 -> 5 Hz), 20 s of GPS fix, the next dive at ~312 s ... Along the way: the multibeam's ping
rate following the altitude; the camera switched on and off over the ridge (its two topics appear
and stop); DVL lock dropouts (WARNs, invalid velocities; a dropout over 3 s puts the EKF in
DEAD_RECKONING, a WARN, for a few seconds) and, over the ridge, intermittent lock; USBL fixes every
2-6 s and now and then an outlier the EKF rejects (a WARN); acoustic packets lost (WARNs); a new
line latched every ~75 s with its planning call and action; the recorder's subscriptions appearing
as their publishers do, its splits. The operator console (``/topside/operator_console``, process
``operator``) joins at 12 s, exits with code 0 after 60 s and is restarted 10 s later (so from ~82 s
to ~142 s, across the faults, and again at ~152 s): 5 s after each start it sets the controller's
``cruise_speed`` (0.9, 1.0 or 1.2 m/s) through ``/control/depth_heading_controller/set_parameters``
(the controller logs the change); every 10 s it calls ``/mission/report``.

Load: ~55 % of one core when healthy (of the machine's two; 51 % without the operator and 54 % with
it, measured with psutil over 30 s in the survey: the mission process ~14 % (the MultiThreadedExecutor
is rclpy's Python executor: its 25 Hz odometry subscription and action feedback dominate), navigation
and control ~4.5 % each, the AHRS and comms ~3.8 %, the rest 0.3-3 % each; the monitor itself besides).

The faults (injected 90 s after the start: the console connected, line 0 of the first survey block
near its end, so line 1's planning call and its action fall in the 30 s after the injection; the
multibeam active, the DVL locked), each with its true root cause (the target node):

- ``crash_thrusters``: the ESC bridge's process is SIGKILLed: ``/control/thrusters/state`` stops, the
  vehicle model gets no thrust and the vehicle (positively buoyant) coasts to a stop and drifts up
  (~11 m in 50 s); the controller's depth loop goes to its limit, the controller and allocator go on
  commanding at 20 Hz into nothing, the battery monitor's current drops to the hotel load, the
  thruster driver's diagnostics go STALE in the aggregator; the follow_line action makes no progress
  (its feedback frozen). Root cause /control/thruster_driver.
- ``hang_bathymetry``: the bathymetry processor's ray tracing never returns; the payload container's
  single executor stops with it, so the image enhancer and the coverage monitor (its siblings) stop
  too: ``bathymetry``, ``image_enhanced`` (when the camera is on) and ``/payload/coverage`` stop, the
  coverage monitor's diagnostics go STALE, the executive's report shows the coverage frozen; the
  multibeam driver goes on pinging. Root cause /payload/multibeam/bathymetry_processor.
- ``degrade_depth``: the pressure sensor's I2C bus stretches its clock: ``/sensors/depth/pressure``
  drops from 20 Hz to 6 Hz; nothing logged, the EKF's ``depth_hz`` diagnostic value falls; depth
  control goes on. Root cause /sensors/depth/pressure_driver.
- ``slow_survey_planner``: the planner's terrain tile cache thrashes: every plan takes 6 s more; the
  executive's plan for line 1 times out after 4 s (an ERROR "Timed out waiting for
  /mission/survey_planner/plan_line", retried 2 s later: an ERROR every ~7 s while the vehicle holds
  at the end of line 0), the planner's late answers (it logs each plan) are dropped; no new
  ``/mission/current_line`` nor ``follow_line`` goal, the setpoint stays on the last waypoint.
  Root cause /mission/survey_planner.
- ``stale_dvl``: the DVL driver's time sync resets and it stamps with the DVL's own clock: its twist and
  altitude come 2.5 s in the past, rates unchanged; the EKF rejects every DVL velocity (a WARN every 5
  s), goes DEAD_RECKONING (a WARN, ``/nav/status`` changes) and its uncertainty grows; the USBL fixes
  keep it near the truth. Root cause /sensors/dvl/dvl_driver.
- ``qos_ekf_imu``: a reloaded ekf.yaml makes the EKF re-create its AHRS subscription RELIABLE against
  the driver's best-effort publisher: it receives nothing (rclpy WARNs the incompatible QoS on both
  sides), stops predicting and publishing ``/nav/odometry`` (ERRORs "No AHRS data"); the controller
  zeroes its thrust ("Navigation timeout", an ERROR), the thrusters idle, the vehicle drifts up; the
  bathymetry is georeferenced with the last pose; the modem and the telemetry report a frozen
  position. Root cause /nav/ekf_filter.
- ``leak_telemetry``: the telemetry bridge's outbound queue is never drained: the comms process grows
  2.5 MB/s. Root cause /comms/telemetry_bridge.
- ``cpu_multibeam``: a runaway beamforming thread in the multibeam driver's process burns CPU (the
  demo's burner asked for a whole core; measured ~30 % of a core here, from ~3 %, as it contends for
  the GIL with the sonar thread).
  Root cause /payload/multibeam/multibeam_driver.
- ``errlog_battery``: the BMS's SMBus fails its CRC on one cell: the battery monitor logs an ERROR every
  second and goes on reporting from the pack estimate (``/auv/battery`` unchanged). Root cause
  /auv/battery_monitor.
- ``bias_ahrs``: the AHRS's hard-iron calibration is corrupted: its heading walks away at 1.5 deg/s,
  rates unchanged, nothing logged by the driver; the controller steers the vehicle off its line on the
  wrong heading while the EKF, dead-reckoning on that heading, believes it on the line; from ~30 s
  after the injection every USBL fix is rejected (WARNs "USBL fix rejected: innovation ... beyond the
  gate", 12 m growing to ~60 m), the vehicle leaves the survey box (measured: 45 m off after 60 s) and,
  its depth targets meant for where it believes it is, comes down to ~0.5 m above the seafloor; the
  bathymetry is misplaced. Root cause /sensors/ahrs/ahrs_driver.
"""

from __future__ import annotations

import os
import sys

from bench.handwritten import Design, NamespacedRobot, main

# the launch file's environment for every process: numpy's BLAS single-threaded (its worker threads
# would spin on the companion computer's two cores)
for var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")

DESIGN = Design(
    module="bench.auv.robot",
    nodes={  # process -> its nodes (fully qualified), in the order they start
        "sim": ("/sim/vehicle_simulator",),
        "ahrs": ("/sensors/ahrs/ahrs_driver",),
        "dvl": ("/sensors/dvl/dvl_driver",),
        "depth": ("/sensors/depth/pressure_driver",),
        "positioning": ("/sensors/gps/gps_driver", "/sensors/usbl/usbl_receiver"),
        "payload_drivers": ("/payload/multibeam/multibeam_driver", "/payload/camera/camera_driver"),
        "payload_container": ("/payload/multibeam/bathymetry_processor", "/payload/camera/image_enhancer",
                              "/payload/coverage_monitor"),
        "navigation": ("/nav/ekf_filter", "/nav/navsat_transform"),
        "control": ("/control/depth_heading_controller", "/control/thruster_allocator"),
        "thrusters": ("/control/thruster_driver",),
        "planner": ("/mission/survey_planner",),
        "mission": ("/mission/mission_executive", "/mission/behavior_server"),
        "health": ("/auv/battery_monitor", "/auv/leak_detector", "/auv/diagnostic_aggregator"),
        "comms": ("/comms/acoustic_modem", "/comms/telemetry_bridge"),
        "recorder": ("/rosbag2_recorder",),
        "operator": ("/topside/operator_console",),
    },
    faults={
        "crash_thrusters": ("kill", "/control/thruster_driver", "thrusters"),
        "hang_bathymetry": ("file:hang", "/payload/multibeam/bathymetry_processor", "payload_container"),
        "degrade_depth": ("file:degrade", "/sensors/depth/pressure_driver", "depth"),
        "slow_survey_planner": ("file:slow", "/mission/survey_planner", "planner"),
        "stale_dvl": ("file:stale", "/sensors/dvl/dvl_driver", "dvl"),
        "qos_ekf_imu": ("file:reliable", "/nav/ekf_filter", "navigation"),
        "leak_telemetry": ("leak", "/comms/telemetry_bridge", "comms"),
        "cpu_multibeam": ("cpu", "/payload/multibeam/multibeam_driver", "payload_drivers"),
        "errlog_battery": ("file:errlog", "/auv/battery_monitor", "health"),
        "bias_ahrs": ("file:bias", "/sensors/ahrs/ahrs_driver", "ahrs"),
    },
    operator="operator", join_s=12.0, run_s=60.0, again_s=10.0,  # connected from ~82 s to ~142 s
)
NODES, FAULTS = DESIGN.nodes, DESIGN.faults


if __name__ == "__main__":
    sys.exit(main(None, __doc__, "auv", NamespacedRobot, DESIGN, 90.0,
                  "s from the start to the injection (90: the console connected, line 0 of the first "
                  "survey block near its end)"))
