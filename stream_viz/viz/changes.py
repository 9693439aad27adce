"""``/changes``: what was changed in the running system (parameters set at run time), as a TextLog.

A symptom that follows a change is read differently from one that comes out of the blue ("the
camera slowed down: someone set its fps"), so the changes stand on the same timeline as the
alerts and in the same log panel (the blueprint's *Alerts* view shows both).
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import rerun as rr

from stream_viz.records import Event
from stream_viz.viz import paths

CHANGE_KINDS = ("param",)  # the collector's events that are changes of configuration


def change_text(event: Event) -> str:
    """Return the line shown in the log: ``[param] node:/camera: parameters of /camera: fps = 5.0``."""
    return f"[{event.kind}] {event.member}: {event.text}"


def log_changes(rec: rr.RecordingStream, events: Iterable[Event]) -> int:
    """Log the change events among ``events`` at ``/changes`` (TextLog, level INFO, at each
    event's time); return how many."""
    changes = sorted((e for e in events if e.kind in CHANGE_KINDS), key=lambda e: e.t)
    if not changes:
        return 0
    rec.send_columns(
        paths.CHANGES,
        indexes=[rr.TimeColumn(paths.TIME, timestamp=np.array([e.t for e in changes], dtype=float))],
        columns=rr.TextLog.columns(text=[change_text(e) for e in changes], level=["INFO"] * len(changes)),
    )
    return len(changes)
