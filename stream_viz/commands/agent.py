"""``stream-viz agent``: publish this computer's ROS processes for a monitor on another one."""

from __future__ import annotations

import argparse
import threading
import time

NAME = "agent"
HELP = "on each computer of the robot: publish its ROS processes for the monitor (no other traffic)"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--period", type=float, default=1.0, metavar="SECONDS",
                   help="the sampling period (the monitor's [monitor] period)")
    p.add_argument("--host", default=None, metavar="NAME",
                   help="the name this computer goes by (default: its host name)")
    p.add_argument("--duration", type=float, metavar="SECONDS", help="stop after this long (else SIGINT)")


def run(args: argparse.Namespace) -> int:
    """Sample and publish every --period until --duration passed or SIGINT/SIGTERM."""
    import os

    from stream_viz.collect.agent import Agent
    from stream_viz.commands.monitor import install_stop_handlers
    from stream_viz.errors import ConfigError

    if args.period <= 0:
        raise ConfigError(f"--period must be > 0 (got {args.period})")
    stop = threading.Event()
    install_stop_handlers(stop)
    domain = int(os.environ.get("ROS_DOMAIN_ID", "0") or 0)
    end = None if args.duration is None else time.monotonic() + args.duration
    with Agent(domain, args.period, args.host) as agent:
        print(f"agent on host {agent.host} (Fast DDS host id {agent.host_id:04x}), domain {domain}",
              flush=True)
        if agent.exits is not None and agent.exits.reason:  # a clean exit(0) then looks like a crash
            print(f"exit codes not read: {agent.exits.reason}", flush=True)
        due = time.monotonic()
        while not stop.is_set() and (end is None or time.monotonic() < end):
            agent.step()
            due += args.period
            stop.wait(max(0.0, due - time.monotonic()))
    return 0
