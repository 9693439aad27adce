"""The robots ``stream-viz demo --robot NAME`` (and the evaluation) can start, by name."""

from __future__ import annotations

from typing import TYPE_CHECKING

from stream_viz.errors import DemoError

if TYPE_CHECKING:  # the CLI imports this module to parse arguments: keep it light
    from stream_viz.demo.topology import Topology

ROBOTS = ("demo", "amr")  # the first demo robot; the warehouse AMR (stream_viz/demo/amr)


def robot_topology(name: str) -> Topology:
    """The topology of robot ``name`` (DemoError naming the robots otherwise)."""
    if name == "demo":
        from stream_viz.demo.topology import DEMO

        return DEMO
    if name == "amr":
        from stream_viz.demo.amr.topology import AMR

        return AMR
    raise DemoError(f"unknown robot {name!r}; robots: {', '.join(ROBOTS)}")


def default_target(name: str, fault: str) -> str:
    """The node ``fault`` hits on robot ``name`` when no target is given."""
    if name == "amr":
        from stream_viz.demo.amr.topology import DEFAULT_TARGETS

        if fault not in DEFAULT_TARGETS:
            raise DemoError(f"unknown fault {fault!r}; the amr's faults: {', '.join(DEFAULT_TARGETS)}")
        return DEFAULT_TARGETS[fault]
    robot_topology(name)
    return "/lidar_driver"
