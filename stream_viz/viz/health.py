"""``/health/<kind>/<name>``: each alerted or vanished member's health over time, as a coloured lane.

A member's state at time t is ``gone`` while it has vanished, else the worst severity of its
alerts in the last ``hold_s`` seconds, else ``ok``. An ongoing symptom is stored (and shown) as
an alert every few seconds (detect/episodes.py, ``repeat_s`` 5 s), so a hold of 15 s keeps the
lane coloured while the symptom lasts and turns it back to ``ok`` soon after it ends. Members
that never had an alert get no lane: a hundred green lanes would hide the few that matter.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable, Sequence

import numpy as np
import rerun as rr

from stream_viz.errors import ModelError
from stream_viz.records import SEVERITIES, SEVERITY_RANK, Alert
from stream_viz.viz import paths, style

HOLD_S = 15.0
OK, GONE = "ok", "gone"
STATES = (OK, *SEVERITIES, GONE)
STATE_COLOR = {OK: (76, 175, 80), **style.SEVERITY_COLOR, GONE: style.GONE_COLOR}

Change = tuple[float, str]


class HealthLanes:
    """The state of each member with a lane, turned into state changes as alerts and time arrive.

    Feed alerts in time order (`alerts`), the gone set (`gone`) and the clock (`tick`); each
    returns ``member -> [(t, state), …]``, only the changes, in time order.
    """

    def __init__(self, hold_s: float = HOLD_S) -> None:
        self.hold_s = hold_s
        self.window: dict[str, deque[tuple[float, str]]] = {}  # recent alerts (t, severity)
        self.state: dict[str, str] = {}
        self.gone: set[str] = set()

    def _worst(self, member: str) -> str:
        if member in self.gone:
            return GONE
        recent = self.window.get(member)
        if not recent:
            return OK
        return max((sev for _, sev in recent), key=lambda s: SEVERITY_RANK.get(s, -1))

    def _emit(self, out: dict[str, list[Change]], member: str, t: float) -> None:
        state = self._worst(member)
        if self.state.get(member) != state:
            self.state[member] = state
            out.setdefault(member, []).append((t, state))

    def _expire(self, out: dict[str, list[Change]], until: float) -> None:
        # Alerts leave the window hold_s after they arrived; the state may drop at that moment.
        for member, recent in self.window.items():
            while recent and recent[0][0] + self.hold_s <= until:
                t_end = recent[0][0] + self.hold_s
                while recent and recent[0][0] + self.hold_s <= t_end:
                    recent.popleft()
                self._emit(out, member, t_end)

    def alerts(self, alerts: Iterable[Alert]) -> dict[str, list[Change]]:
        """Take alerts (sorted by time); return the state changes they and the elapsed time make."""
        out: dict[str, list[Change]] = {}
        for a in sorted(alerts, key=lambda a: a.t):
            self._expire(out, a.t)
            self.window.setdefault(a.member, deque()).append((a.t, a.severity))
            self._emit(out, a.member, a.t)
        return out

    def tick(self, t: float) -> dict[str, list[Change]]:
        """Return the changes of alerts growing older than ``hold_s`` up to time ``t``."""
        out: dict[str, list[Change]] = {}
        self._expire(out, t)
        return out

    def set_gone(self, t: float, gone: Iterable[str]) -> dict[str, list[Change]]:
        """Take the members vanished at ``t``; return the changes (gone, or back)."""
        out = self.tick(t)
        gone = set(gone)
        changed, self.gone = gone ^ self.gone, gone
        for member in sorted(changed):
            self._emit(out, member, t)
        return out


def merge(*changes: dict[str, list[Change]]) -> dict[str, list[Change]]:
    """Return the changes of several calls as one ``member -> changes`` (each in time order)."""
    out: dict[str, list[Change]] = {}
    for c in changes:
        for member, ch in c.items():
            out.setdefault(member, []).extend(ch)
    return out


class FileEvents:
    """Alerts and lane changes gathered for the file until they are written together
    (`Recorder` ``file_events_s``): one chunk per entity for the lot, not one per sample."""

    def __init__(self) -> None:
        self.alerts: list[Alert] = []
        self.lanes: dict[str, list[Change]] = {}
        self.first_t: float | None = None  # the time of the first pending event

    def add(self, alerts: Iterable[Alert], lanes: dict[str, list[Change]]) -> None:
        alerts = list(alerts)
        times = [a.t for a in alerts] + [t for ch in lanes.values() for t, _ in ch]
        if not times:
            return
        self.alerts.extend(alerts)
        self.lanes = merge(self.lanes, lanes)
        self.first_t = min(times) if self.first_t is None else min(self.first_t, *times)

    def take(self) -> tuple[list[Alert], dict[str, list[Change]]]:
        """Return the pending alerts (in time order) and lane changes, and forget them."""
        out = sorted(self.alerts, key=lambda a: a.t), self.lanes
        self.alerts, self.lanes, self.first_t = [], {}, None
        return out


def log_health(rec: rr.RecordingStream, changes: dict[str, Sequence[Change]]) -> int:
    """Log state changes at ``/health/<kind>/<name>`` (``StateChange`` on ``time``); return #changes.

    Each lane gets its static ``StateConfiguration`` once (the states' colours and order).
    """
    styled = style.styled(rec)
    n = 0
    for member, ch in sorted(changes.items()):
        if not ch:
            continue
        try:
            path = paths.health_path(member)
        except ModelError:  # a malformed id: the alert log still has it
            continue
        if path not in styled:
            rec.log(path, rr.StateConfiguration(values=list(STATES),
                                                colors=[STATE_COLOR[s] for s in STATES]), static=True)
            styled.add(path)
        rec.send_columns(
            path, indexes=[rr.TimeColumn(paths.TIME, timestamp=np.array([t for t, _ in ch], dtype=float))],
            columns=rr.StateChange.columns(state=[s for _, s in ch]))
        n += len(ch)
    return n
