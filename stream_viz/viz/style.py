"""Colours and sizes: what tells member kinds, states and severities apart in the viewer."""

from __future__ import annotations

import weakref
from typing import Any

from stream_viz.records import SEVERITIES

# RGB; active members (ROS nodes) are big blue discs, distributors smaller and warm/green.
KIND_COLOR = {
    "node": (66, 133, 244),
    "topic": (245, 166, 35),
    "service": (52, 168, 83),
    "action": (171, 71, 188),
    "process": (0, 150, 136),
    "host": (96, 125, 139),
    "root": (120, 120, 120),
}
KIND_RADIUS = {"node": 16.0, "topic": 9.0, "service": 8.0, "action": 9.0,
               "process": 12.0, "host": 14.0, "root": 10.0}
GONE_COLOR = (150, 150, 150)
GONE_SUFFIX = " (gone)"

# Per severity of the one scale, least to most severe (info, warn, error, fatal).
SEVERITY_COLOR = dict(zip(SEVERITIES, ((120, 180, 255), (255, 200, 0), (230, 57, 53), (150, 0, 20)),
                          strict=True))
# Rerun's TextLog levels (the viewer colours and filters by these).
SEVERITY_LEVEL = dict(zip(SEVERITIES, ("INFO", "WARN", "ERROR", "CRITICAL"), strict=True))

# RCA overlays, drawn over /system at the same positions.
SUBGRAPH_COLOR = (230, 57, 53)  # members of G_j
WATCH_COLOR = (255, 215, 0)  # W_j not (yet) in G_j
ALERT_COLOR = (150, 0, 20)  # the member whose alert grew G_j at this iteration
TRAJECTORY_COLOR = (200, 0, 200)
ROOT_CAUSE_COLOR = (0, 220, 255)
OVERLAY_RADIUS = 26.0  # overlay discs, in scene units (a label box is ~100 units wide)


def rgb_for_index(i: int) -> tuple[int, int, int]:
    """Return a distinct colour for series ``i`` (a small qualitative palette, cycled)."""
    palette = [(31, 119, 180), (255, 127, 14), (44, 160, 44), (214, 39, 40), (148, 103, 189),
               (140, 86, 75), (227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207)]
    return palette[i % len(palette)]


# Entities whose static style (SeriesLines / SeriesPoints) a recording stream has logged: static
# data is logged once per entity, and again after `forget_styled` (a new file part starts empty).
_styled: weakref.WeakKeyDictionary[Any, set[str]] = weakref.WeakKeyDictionary()


def styled(rec: Any) -> set[str]:
    """Return the entity paths ``rec`` has logged a static style for (add a path after logging)."""
    return _styled.setdefault(rec, set())


def forget_styled(rec: Any) -> None:
    """Make ``rec`` log its static styles again (its new sink has none of them)."""
    _styled.pop(rec, None)
