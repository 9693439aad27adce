"""Run the hand-written pick station under the monitor: a healthy run and injected faults.

``python -m bench.station.run [--healthy S] [--warmup S] [--post S] [--faults a,b] [--out DIR]``

The station's processes (`bench.station.robot`) under the in-process monitor, as every
hand-written robot runs (`bench.handwritten`: the runs, their scores, the files written). The
HMI joins 15 s after the start, exits cleanly (code 0) 45 s later and its launcher starts it
again 10 s after that. ``outside_load`` is a fault of the computer, not of the robot: CPU hogs
outside ROS (three a CPU); its root cause is the host member.
"""

from __future__ import annotations

import os
import subprocess
import sys

from bench.handwritten import HOST, Design, Robot, main

HOGS_PER_CPU = 3
DESIGN = Design(
    module="bench.station.robot",
    nodes={  # process -> its nodes (fully qualified)
        "arm_drivers": ("/arm/joint_state_broadcaster", "/arm/gripper_driver", "/arm/ft_sensor"),
        "perception": ("/station/camera", "/station/detector"),
        "planning": ("/arm/motion_planner",),
        "executive": ("/station/task_executive",),
        "monitoring": ("/station/diagnostic_aggregator",),
        "hmi": ("/station/hmi",),
    },
    faults={  # "outside": CPU hogs that are no part of the robot (the computer is the cause)
        "crash_perception": ("kill", "/station/camera", "perception"),
        "crash_arm": ("kill", "/arm/gripper_driver", "arm_drivers"),
        "hang_gripper": ("file:hang", "/arm/gripper_driver", "arm_drivers"),
        "degrade_ft": ("file:degrade", "/arm/ft_sensor", "arm_drivers"),
        "delay_camera": ("file:delay", "/station/camera", "perception"),
        "errlog_gripper": ("file:errlog", "/arm/gripper_driver", "arm_drivers"),
        "slow_detector": ("file:slow_service", "/station/detector", "perception"),
        "cpu_planning": ("cpu", "/arm/motion_planner", "planning"),
        "hang_aggregator": ("file:hang", "/station/diagnostic_aggregator", "monitoring"),
        "outside_load": ("outside", HOST, ""),
    },
    operator="hmi", join_s=15.0, run_s=45.0, again_s=10.0,  # joins before a fault at 30 s
)
NODES, FAULTS = DESIGN.nodes, DESIGN.faults


class Station(Robot):
    """The station; its ``outside_load`` starts CPU hogs outside the robot."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.hogs: list[subprocess.Popen] = []

    def inject(self, fault: str) -> None:
        if DESIGN.faults[fault][0] == "outside":  # each in a session of its own: autogroups share alike
            self.hogs = [subprocess.Popen([sys.executable, "-c", "while True: pass"], start_new_session=True)
                         for _ in range(HOGS_PER_CPU * (os.cpu_count() or 1))]
        else:
            super().inject(fault)

    def end(self) -> None:
        for p in self.hogs:
            p.kill()
            p.wait(5)
        super().end()


if __name__ == "__main__":
    sys.exit(main(None, __doc__, "station", Station, DESIGN, 30.0,
                  "s from the start to the injection (30: the executive at work, idle from ~50 s)"))
