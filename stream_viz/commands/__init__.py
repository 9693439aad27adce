"""The ``stream-viz`` commands, one module each: its name, help line, ``add_arguments(parser)``
and ``run(args) -> exit code``. `stream_viz.cli` builds the parser from `COMMANDS`.

A command module imports what its ``run`` needs inside ``run``: parsing (``--help``, the README
test) must not load rclpy or Rerun.
"""

from __future__ import annotations

from stream_viz.commands import agent, analyze, blueprint, demo, monitor, replay, snapshot

COMMANDS = (snapshot, monitor, demo, replay, analyze, blueprint, agent)

__all__ = ["COMMANDS"]
