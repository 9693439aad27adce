"""Alert episodes: an ongoing symptom is one episode, stored as a few rows, not one per sample.

For each ``(member, plugin)``: an alert more than ``gap_s`` after the previous one opens a new
episode and is stored. While the episode goes on, an alert is stored again only when
``repeat_s`` have passed since the last stored one, or when its severity is higher than the
last stored one's (an escalation is never hidden). Every alert, stored or not, extends the
episode (``end``, ``count``, ``max_severity``).

A plugin that knows its symptom comes and goes (a topic that flaps, a node in a restart loop)
says how long it may pause and still be the same episode: ``episode_hold_s`` in the alert's
data; the longer of it and ``gap_s`` ends the episode.
"""

from __future__ import annotations

from dataclasses import dataclass

from stream_viz.records import SEVERITY_RANK, Alert


@dataclass
class Episode:
    """One ongoing or ended symptom of ``member`` found by ``plugin``."""

    member: str
    plugin: str
    start: float
    end: float
    count: int
    max_severity: str
    last_stored_t: float
    last_stored_severity: str
    id: int | None = None
    hold_s: float = 0.0  # the last alert's ``episode_hold_s``: a pause this long does not end it


class EpisodeTracker:
    """Decides which alerts become rows, and keeps the episodes up to date.

    Parameters
    ----------
    repeat_s : float
        Store an ongoing episode's alert at most once per this many seconds.
    gap_s : float
        A pause longer than this ends an episode.
    """

    def __init__(self, repeat_s: float = 5.0, gap_s: float = 3.0) -> None:
        self.repeat_s, self.gap_s = repeat_s, gap_s
        self.open: dict[tuple[str, str], Episode] = {}

    def offer(self, alert: Alert) -> tuple[bool, Episode, bool]:
        """Account ``alert``; return ``(store it?, its episode, episode is new?)``."""
        key = (alert.member, alert.plugin)
        ep = self.open.get(key)
        if ep is None or alert.t - ep.end > max(self.gap_s, ep.hold_s):
            ep = Episode(alert.member, alert.plugin, alert.t, alert.t, 1, alert.severity,
                         alert.t, alert.severity, hold_s=hold_of(alert))
            self.open[key] = ep
            return True, ep, True
        ep.hold_s = hold_of(alert)
        ep.end = max(ep.end, alert.t)
        ep.count += 1
        if SEVERITY_RANK[alert.severity] > SEVERITY_RANK[ep.max_severity]:
            ep.max_severity = alert.severity
        store = (alert.t - ep.last_stored_t >= self.repeat_s
                 or SEVERITY_RANK[alert.severity] > SEVERITY_RANK[ep.last_stored_severity])
        if store:
            ep.last_stored_t, ep.last_stored_severity = alert.t, alert.severity
        return store, ep, False


def hold_of(alert: Alert) -> float:
    """Return the alert's ``episode_hold_s`` (s; 0 when absent or not a finite number ≥ 0)."""
    hold = alert.data.get("episode_hold_s", 0.0)
    if isinstance(hold, bool) or not isinstance(hold, int | float) or not 0 <= hold < float("inf"):
        return 0.0
    return float(hold)
