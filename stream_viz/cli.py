"""The ``stream-viz`` command line: builds the parser from the command modules
(`stream_viz.commands`); the only place that turns errors into exit codes."""

from __future__ import annotations

import argparse
import sys

from stream_viz.commands import COMMANDS
from stream_viz.errors import StreamVizError


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog="stream-viz",
        description="A live visual debugger for ROS 2 robots: model, symptoms, root causes, in Rerun.",
    )
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in COMMANDS:
        c = sub.add_parser(command.NAME, help=command.HELP)
        command.add_arguments(c)
        c.set_defaults(func=command.run)
    return p


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
