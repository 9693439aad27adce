"""The ``stream-viz`` command line; the only place that turns errors into exit codes."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from stream_viz.demo.faults import FAULTS
from stream_viz.demo.robots import ROBOTS
from stream_viz.errors import StreamVizError


def _add_outputs(p: argparse.ArgumentParser) -> None:
    p.add_argument("--save", type=Path, metavar="FILE.rrd", help="also write the Rerun recording here")
    p.add_argument("--db", type=Path, metavar="FILE.sqlite", help="keep the alert database here")
    p.add_argument("--report", type=Path, metavar="FILE.json", help="write the JSON report here at the end")
    p.add_argument("--config", type=Path, metavar="FILE.toml", help="settings (plugins, watchlist, rca)")
    p.add_argument(
        "--viewer", default=None, metavar="spawn|serve|none|URL",
        help="spawn a native viewer, serve a web viewer on localhost, none, or a rerun+http:// URL",
    )


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="stream-viz",
        description="A live visual debugger for ROS 2 robots: model, symptoms, root causes, in Rerun.",
    )
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")

    s = sub.add_parser("snapshot", help="print the current model of the ROS 2 system on ROS_DOMAIN_ID")
    s.add_argument("--json", action="store_true", help="print JSON (members, edges) instead of text")
    s.add_argument("--settle", type=float, default=2.0, metavar="S", help="seconds to let discovery settle")
    s.set_defaults(func=_snapshot)

    m = sub.add_parser("monitor", help="attach to the running system, detect, diagnose, stream to Rerun")
    m.add_argument("--duration", type=float, metavar="SECONDS", help="stop after this long (else SIGINT)")
    _add_outputs(m)
    m.set_defaults(func=_monitor)

    d = sub.add_parser("demo", help="start a simulated robot, inject a fault, diagnose it, show it")
    d.add_argument("--robot", choices=ROBOTS, default="demo",
                   help="which robot: the demo robot, or the warehouse AMR (see docs/demo.md)")
    d.add_argument("--fault", choices=(*FAULTS, "none"), default="crash",
                   help="what to inject ('none': a healthy run, to see what a calm robot looks like)")
    d.add_argument("--target", metavar="NODE", help="node to fault (default: the robot's usual one)")
    d.add_argument("--at", type=float, default=12.0, metavar="SECONDS",
                   help="inject this long after the robot is up")
    d.add_argument("--duration", type=float, default=30.0, metavar="SECONDS",
                   help="length of the run, from when the robot is up")
    d.add_argument("--domain", type=int, default=42, metavar="ID", help="ROS_DOMAIN_ID of the demo robot")
    _add_outputs(d)
    d.set_defaults(func=_demo)

    a = sub.add_parser("analyze", help="rerun the root-cause analysis offline on a saved alert database")
    a.add_argument("--db", type=Path, required=True, metavar="FILE.sqlite")
    a.add_argument("--policy", choices=("downstream", "upstream", "both"))
    a.add_argument("--method", help="correlation method (see docs/rca.md)")
    a.add_argument("--config", type=Path, metavar="FILE.toml")
    a.add_argument("--report", type=Path, metavar="FILE.json")
    a.add_argument("--save", type=Path, metavar="FILE.rrd", help="write the diagnosis as a recording")
    a.set_defaults(func=_analyze)

    b = sub.add_parser("blueprint", help="write the default Rerun layout as an .rbl file")
    b.add_argument("path", type=Path, metavar="FILE.rbl")
    b.set_defaults(func=_blueprint)
    return p


def _snapshot(args: argparse.Namespace) -> int:
    from stream_viz.collect.snapshot import snapshot_main

    print(snapshot_main(json=args.json, settle_s=args.settle))
    return 0


def _monitor(args: argparse.Namespace) -> int:
    from stream_viz.monitor import run_monitor

    run_monitor(args)
    return 0


def _demo(args: argparse.Namespace) -> int:
    from stream_viz.demo_cmd import run_demo

    run_demo(args)
    return 0


def _analyze(args: argparse.Namespace) -> int:
    from stream_viz.analyze import run_analyze

    run_analyze(args)
    return 0


def _blueprint(args: argparse.Namespace) -> int:
    from stream_viz_blueprints.default import save_blueprint

    save_blueprint(args.path)
    print(f"wrote {args.path}")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except StreamVizError as exc:
        print(f"Error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())
