"""``stream-viz blueprint``: write the default Rerun layout as an ``.rbl`` file."""

from __future__ import annotations

import argparse
from pathlib import Path

NAME = "blueprint"
HELP = "write the default Rerun layout as an .rbl file"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("path", type=Path, metavar="FILE.rbl")


def run(args: argparse.Namespace) -> int:
    from stream_viz_blueprints.default import save_blueprint

    save_blueprint(args.path)
    print(f"wrote {args.path}")
    return 0
