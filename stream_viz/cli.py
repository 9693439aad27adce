"""The ``stream-viz`` command line; the only place that turns errors into exit codes."""

from __future__ import annotations

import argparse
import sys

from stream_viz.errors import StreamVizError


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="stream-viz", description=__doc__)
    p.add_subparsers(dest="command", required=True)
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except StreamVizError as exc:
        print(f"Error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
