"""``stream-viz demo``: the simulated robot, a fault, the whole pipeline, and the viewer."""

from __future__ import annotations

import argparse
import os
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from stream_viz.commands.monitor import (
    add_outputs,
    add_samples,
    install_stop_handlers,
    linger,
    say_recording,
    serve_at,
)
from stream_viz.demo.faults import FAULTS
from stream_viz.demo.robots import ROBOTS

if TYPE_CHECKING:
    from stream_viz.monitor import Monitor

NAME = "demo"
HELP = "start a simulated robot, inject a fault, diagnose it, show it"
DEFAULT_RECORDING = Path("stream_viz_demo.rrd")


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--robot", choices=ROBOTS, default="demo",
                   help="which robot: the demo robot, or the warehouse AMR (see docs/demo.md)")
    p.add_argument("--fault", choices=(*FAULTS, "none"), default="crash",
                   help="what to inject ('none': a healthy run, to see what a calm robot looks like)")
    p.add_argument("--target", metavar="NODE", help="node to fault (default: the robot's usual one)")
    p.add_argument("--size", type=float, metavar="X",
                   help="how strong (degrade: fraction of messages kept, leak: MB/s, delay: ms, cpu: share "
                        "of a core, errlog: lines/s; default: the fault's usual size; docs/demo.md)")
    p.add_argument("--at", type=float, default=12.0, metavar="SECONDS",
                   help="inject this long after the robot is up")
    p.add_argument("--duration", type=float, default=30.0, metavar="SECONDS",
                   help="length of the run, from when the robot is up")
    p.add_argument("--domain", type=int, default=42, metavar="ID", help="ROS_DOMAIN_ID of the demo robot")
    add_outputs(p)
    add_samples(p)


def default_viewer() -> str:
    """A native viewer where there is a screen; otherwise only the saved recording."""
    return "spawn" if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY") else "none"


def demo_env(domain: int) -> dict[str, str]:
    """The environment of the demo: its own ROS domain, discovery on this machine only."""
    os.environ["ROS_DOMAIN_ID"] = str(domain)
    os.environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    return dict(os.environ)


def run(args: argparse.Namespace) -> int:
    """Start the robot, monitor it with a fault injected at ``--at`` s, print the diagnosis."""
    from stream_viz.config import load_config
    from stream_viz.demo.robot import FaultSpec, Robot
    from stream_viz.demo.robots import default_target, robot_topology
    from stream_viz.monitor import Monitor

    config = load_config(args.config)
    robot_name = args.robot
    fault = None if args.fault == "none" else \
        FaultSpec(args.fault, args.target or default_target(robot_name, args.fault), args.at, args.size)
    save = args.save or DEFAULT_RECORDING
    viewer = args.viewer or default_viewer()
    stop = threading.Event()
    install_stop_handlers(stop)
    env = demo_env(args.domain)
    robot = Robot(env=env, topology=robot_topology(robot_name))
    if fault is not None:
        robot.topology.check_fault(fault)
    # The monitor checks its outputs before any robot process starts: a bad path costs nothing.
    mon = Monitor(config, db=args.db, save=save, report=args.report, viewer=viewer, domain_id=args.domain,
                  serve_at=serve_at(args), group_by=args.group_by, samples=args.samples,
                  condensed=args.condensed)
    try:
        size = "" if fault is None or fault.size is None else f" (size {fault.size:g})"
        what = f"{fault.fault}{size} of {fault.target} {fault.at:g} s after it is up" if fault else "no fault"
        mon.progress.say(f"demo robot on ROS_DOMAIN_ID={args.domain}: "
                         f"{len(robot.topology.node_names())} nodes; {what}; {args.duration:g} s run")
        robot.start()
        robot.wait_ready(timeout=60.0)
        # The fault is armed once the robot is up, so the monitor always sees a healthy baseline
        # first, however slow start-up is on a loaded machine.
        if fault is not None:
            robot.inject(fault)
        end = time.monotonic() + args.duration

        def note_injection() -> None:
            if mon.injected is None:
                mon.injected = robot.injected() or None

        mon.run(max(0.0, end - time.monotonic()), stop, on_tick=note_injection)
        note_injection()
    finally:
        try:
            report = mon.close(keep_view=viewer == "serve")
        finally:
            robot.stop()
    print_diagnosis(report, mon)
    linger(mon, viewer)
    return 0


def print_diagnosis(report: dict[str, Any], mon: Monitor) -> None:
    """The injected fault, the top five root causes, where the outputs went."""
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
    if mon.recording_parts:
        say_recording(mon)
