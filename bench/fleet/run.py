"""Run the simulated delivery fleet under the monitor: a healthy run and injected faults.

``python -m bench.fleet.run [--healthy S] [--warmup S] [--post S] [--faults a,b] [--out DIR]``

The fleet's processes (`bench.fleet.robot`) under the in-process monitor, as every hand-written
robot runs (`bench.handwritten`: the runs, their scores, the files written). The teleop joins
20 s after the start, exits cleanly (code 0) 40 s later and its launcher starts it again 15 s
after that.
"""

from __future__ import annotations

import sys

from bench.handwritten import Design, NamespacedRobot, main

DESIGN = Design(
    module="bench.fleet.robot",
    nodes={  # process -> its nodes (fully qualified), in the order they start
        "sim": ("/sim/world", "/sim/bridge", "/sim/map_server"),
        "r1_nav": ("/r1/localizer", "/r1/planner", "/r1/controller"),
        "r2_odom_filter": ("/r2/odom_filter",),
        "r2_localizer": ("/r2/localizer",),
        "r2_planner": ("/r2/planner",),
        "r2_controller": ("/r2/controller",),
        "dispatcher": ("/fleet/dispatcher",),
        "fleet": ("/fleet/manager", "/fleet/battery"),
        "tools": ("/tools/recorder", "/tools/diag"),
        "teleop": ("/r1/teleop",),
    },
    faults={
        "crash_r2_localizer": ("kill", "/r2/localizer", "r2_localizer"),
        "hang_r1_planner": ("file:hang", "/r1/planner", "r1_nav"),
        "degrade_r1_scan": ("file:degrade", "/sim/bridge", "sim"),
        "stale_r2_odom": ("file:stale", "/r2/odom_filter", "r2_odom_filter"),
        "slow_assign": ("file:slow_service", "/fleet/manager", "fleet"),
        "errlog_r1_controller": ("file:errlog", "/r1/controller", "r1_nav"),
        "leak_fleet": ("leak", "/fleet/manager", "fleet"),
        "stop_r1_tf": ("file:stop_tf", "/r1/localizer", "r1_nav"),
        "cpu_tools": ("cpu", "/tools/recorder", "tools"),
        "crash_sim": ("kill", "/sim/world", "sim"),
    },
    operator="teleop", join_s=20.0, run_s=40.0, again_s=15.0,  # joins before a fault at 40 s
)
NODES, FAULTS = DESIGN.nodes, DESIGN.faults


if __name__ == "__main__":
    sys.exit(main(None, __doc__, "fleet", NamespacedRobot, DESIGN, 40.0,
                  "s from the start to the injection (40: the teleop joined, goals under way)"))
