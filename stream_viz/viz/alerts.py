"""``/alerts``: the alerts as a TextLog with levels, and markers on the member's metric plot."""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np
import rerun as rr

from stream_viz.errors import ModelError
from stream_viz.records import SEVERITY_RANK, Alert
from stream_viz.viz import paths, style


def alert_text(alert: Alert) -> str:
    """Return the line shown in the alert log: ``[plugin] member: message``."""
    return f"[{alert.plugin}] {alert.member}: {alert.message}"


def marker_value(alert: Alert) -> float:
    """Return the y value of an alert's marker: ``data["value"]`` if numeric, else the severity rank 1–4."""
    value = alert.data.get("value") if alert.data else None
    if isinstance(value, int | float) and np.isfinite(value):
        return float(value)
    return float(SEVERITY_RANK.get(alert.severity, -1) + 1)


def log_alerts(rec: rr.RecordingStream, alerts: Sequence[Alert] | Iterable[Alert]) -> int:
    """Log alerts at ``/alerts`` (TextLog, one row per alert at its time ``t``) and as markers.

    Severities map to Rerun levels (info/warn/error/fatal -> INFO/WARN/ERROR/CRITICAL). Each
    alert also puts a cross at ``/metrics/<kind>/<member>/alerts``, in the member's metric plot.
    Returns the number of alerts logged.
    """
    alerts = sorted(alerts, key=lambda a: a.t)
    if not alerts:
        return 0
    times = np.array([a.t for a in alerts], dtype=float)
    rec.send_columns(
        paths.ALERTS,
        indexes=[rr.TimeColumn(paths.TIME, timestamp=times)],
        columns=rr.TextLog.columns(
            text=[alert_text(a) for a in alerts],
            level=[style.SEVERITY_LEVEL.get(a.severity, "INFO") for a in alerts],
            color=[style.SEVERITY_COLOR.get(a.severity, (0, 0, 0)) for a in alerts],
        ),
    )
    styled = style.styled(rec)
    by_member: dict[str, list[Alert]] = {}
    for a in alerts:
        by_member.setdefault(a.member, []).append(a)
    for member, group in sorted(by_member.items()):
        try:
            path = paths.metrics_path(member, paths.ALERT_MARKERS)
        except ModelError:  # a malformed member id: the text log above still has the alert
            continue
        if path not in styled:
            rec.log(path, rr.SeriesPoints(markers=["cross"], names=["alerts"], colors=[(230, 57, 53)],
                                          marker_sizes=[6.0]), static=True)
            styled.add(path)
        rec.send_columns(
            path,
            indexes=[rr.TimeColumn(paths.TIME, timestamp=np.array([a.t for a in group], dtype=float))],
            columns=rr.Scalars.columns(scalars=np.array([marker_value(a) for a in group])),
        )
    return len(alerts)
