"""``stream-viz snapshot``: print the model of the ROS 2 system on ROS_DOMAIN_ID once."""

from __future__ import annotations

import argparse

NAME = "snapshot"
HELP = "print the current model of the ROS 2 system on ROS_DOMAIN_ID"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--json", action="store_true", help="print JSON (members, edges) instead of text")
    p.add_argument("--settle", type=float, default=2.0, metavar="S",
                   help="seconds to let discovery settle (up to 4 s more while nodes still appear)")


def run(args: argparse.Namespace) -> int:
    from stream_viz.collect.snapshot import snapshot_main

    print(snapshot_main(json=args.json, settle_s=args.settle))
    return 0
