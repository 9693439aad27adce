"""``stream-viz monitor``: attach to the system on ROS_DOMAIN_ID until --duration or a signal.

Also the command-line pieces ``demo`` shares: the output options, the stop signals, the
served viewer kept up at the end, where the recording went.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
from pathlib import Path
from typing import TYPE_CHECKING

from stream_viz.viz.layout_groups import GROUPINGS
from stream_viz.viz.serve import DEFAULT_BIND, DEFAULT_GRPC_PORT, DEFAULT_WEB_PORT, ServeAt

if TYPE_CHECKING:
    from stream_viz.monitor import Monitor

NAME = "monitor"
HELP = "attach to the running system, detect, diagnose, stream to Rerun"


def add_outputs(p: argparse.ArgumentParser) -> None:
    """The options of a live run's outputs (``monitor`` and ``demo``)."""
    p.add_argument("--save", type=Path, metavar="FILE.rrd", help="also write the Rerun recording here")
    p.add_argument("--db", type=Path, metavar="FILE.sqlite", help="keep the alert database here")
    p.add_argument("--report", type=Path, metavar="FILE.json", help="write the JSON report here at the end")
    p.add_argument("--config", type=Path, metavar="FILE.toml", help="settings (plugins, watchlist, rca)")
    p.add_argument(
        "--viewer", default=None, metavar="spawn|serve|none|URL",
        help="spawn a native viewer, serve a web viewer on localhost, none, or a rerun+http:// URL",
    )
    p.add_argument(
        "--serve-bind", default=DEFAULT_BIND, metavar="ADDR",
        help="with --viewer serve: the address the page and its data listen on (127.0.0.1: this "
             "machine only; 0.0.0.0: every interface, no authentication)",
    )
    p.add_argument("--web-port", type=int, default=DEFAULT_WEB_PORT, metavar="PORT",
                   help="with --viewer serve: the web page's port")
    p.add_argument("--grpc-port", type=int, default=DEFAULT_GRPC_PORT, metavar="PORT",
                   help="with --viewer serve: the port the page reads the data from")
    p.add_argument("--group-by", choices=GROUPINGS, default="namespace",
                   help="the system graph's boxes: per namespace (default), per process, or none")
    p.add_argument("--condensed", choices=("auto", "on", "off"), default=None,
                   help="the condensed system graph (groups as one disc, the diagnosis in full): auto "
                        "above [monitor] condense_above members (300; the default), on, or off")


def add_healthy(p: argparse.ArgumentParser) -> None:
    """``--healthy``: start from what an earlier healthy run of the same robot showed."""
    p.add_argument("--healthy", type=Path, metavar="RUN.sqlite",
                   help="the database (--db) of an earlier run of this robot you know was healthy: "
                        "what it showed as normal (a rate its links step down to) is not alerted on")


def add_samples(p: argparse.ArgumentParser) -> None:
    """``--samples``: a live run also writes what it collected, for ``stream-viz replay``."""
    p.add_argument("--samples", type=Path, metavar="FILE.jsonl.gz",
                   help="also write every sample collected here (replay it with stream-viz replay)")


def serve_at(args: argparse.Namespace) -> ServeAt:
    """Where ``--viewer serve`` listens, from the command line."""
    return ServeAt(args.serve_bind, args.web_port, args.grpc_port)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--duration", type=float, metavar="SECONDS", help="stop after this long (else SIGINT)")
    add_outputs(p)
    add_samples(p)
    add_healthy(p)


def run(args: argparse.Namespace) -> int:
    """Monitor until ``--duration`` passed or SIGINT/SIGTERM; write the outputs asked for."""
    from stream_viz.config import load_config
    from stream_viz.monitor import Monitor

    config = load_config(args.config)
    stop = threading.Event()
    install_stop_handlers(stop)
    viewer = args.viewer or "none"
    mon = Monitor(config, db=args.db, save=args.save, report=args.report, viewer=viewer,
                  serve_at=serve_at(args), group_by=args.group_by, samples=args.samples,
                  condensed=args.condensed, healthy=args.healthy)
    mon.progress.say(f"alert database: {mon.db_path}")
    try:
        mon.run(args.duration, stop)
    finally:
        mon.close(keep_view=viewer == "serve")
    say_healthy(mon)
    if args.save:
        say_recording(mon)
    if args.report:
        mon.progress.say(f"report: {args.report}")
    linger(mon, viewer)
    return 0


def install_stop_handlers(stop: threading.Event) -> None:
    """SIGINT and SIGTERM end the run cleanly (the report is written, exit code 0)."""

    def handler(signum, frame) -> None:
        stop.set()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)


def linger(mon: Monitor, viewer: str) -> None:
    """A served web viewer dies with this process: on a terminal, keep it up until Ctrl-C."""
    try:
        if viewer == "serve" and sys.stdin.isatty():
            done = threading.Event()
            install_stop_handlers(done)
            mon.progress.say(f"the web viewer keeps serving at {mon.view.url} — Ctrl-C to exit")
            done.wait()
    finally:
        mon.view.close()


def say_healthy(mon: Monitor) -> None:
    """Tell how a later run starts from this one: its database holds what the run learned."""
    mon.progress.say(f"if this run was the robot's normal, its alerts included, start the next "
                     f"from it: --healthy {mon.db_path}")


def say_recording(mon: Monitor) -> None:
    """Tell where the recording went (all its file parts) and how to open it."""
    parts = mon.recording_parts
    files = " ".join(str(p) for p in parts)
    more = f" in {len(parts)} parts" if len(parts) > 1 else ""
    mon.progress.say(f"recording{more}: {files}  (open with: rerun {files})")
