"""``stream-viz demo``: the simulated robot, a fault, the whole pipeline, and the viewer."""

from __future__ import annotations

import argparse
import os
import threading
import time
from pathlib import Path
from typing import Any

from stream_viz.config import load_config
from stream_viz.demo.robot import FaultSpec, Robot
from stream_viz.monitor import Monitor, install_stop_handlers

DEFAULT_RECORDING = Path("stream_viz_demo.rrd")


def default_viewer() -> str:
    """A native viewer where there is a screen; otherwise only the saved recording."""
    return "spawn" if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY") else "none"


def run_demo(args: argparse.Namespace) -> dict[str, Any]:
    """Start the robot, monitor it with a fault injected at ``--at`` s, print the diagnosis."""
    config = load_config(args.config)
    fault = FaultSpec(args.fault, args.target, args.at)  # validates fault and target first
    save = args.save or DEFAULT_RECORDING
    viewer = args.viewer or default_viewer()
    stop = threading.Event()
    install_stop_handlers(stop)
    with Robot(fault=fault) as robot:
        robot.start()
        mon = Monitor(config, db=args.db, save=save, report=args.report, viewer=viewer)
        try:
            mon.progress.say(f"demo robot up: {len(robot.node_pids())} nodes; "
                             f"{args.fault} of {args.target} at +{args.at:g} s")
            robot.wait_ready(timeout=20.0)
            deadline = time.monotonic() + args.duration

            def note_injection() -> None:
                if mon.injected is None:
                    mon.injected = robot.injected() or None

            mon.run(max(0.0, deadline - time.monotonic()), stop, on_tick=note_injection)
            note_injection()
        finally:
            report = mon.close()
    _print_diagnosis(report, save, mon)
    return report


def _print_diagnosis(report: dict[str, Any], save: Path, mon: Monitor) -> None:
    say = mon.progress.say
    inj = report.get("injected")
    if inj:
        say(f"injected: {inj['fault']} of {inj['target']}")
    causes = report["root_causes"]
    if not causes:
        say("no root cause found")
    for rank, rc in enumerate(causes[:5], 1):
        say(f"{rank}. {rc['member']}  score {rc['score']:.2f}  trajectory: {' <- '.join(rc['trajectory'])}")
    say(f"{len(report['alerts'])} alerts; alert database: {mon.db_path}")
    say(f"recording: {save}  (open with: rerun {save})")
