"""The one severity scale: everything that orders, colours or weighs severities is keyed by it."""

from __future__ import annotations

from stream_viz.detect.episodes import EpisodeTracker
from stream_viz.rca.settings import RcaSettings
from stream_viz.records import SEVERITIES, SEVERITY_RANK, Alert
from stream_viz.viz import style
from stream_viz.viz.alerts import marker_value


def test_one_scale_least_to_most_severe():
    assert SEVERITIES == ("info", "warn", "error", "fatal")
    assert [SEVERITY_RANK[s] for s in SEVERITIES] == [0, 1, 2, 3]


def test_viewer_and_rca_are_keyed_by_the_scale():
    assert tuple(style.SEVERITY_COLOR) == tuple(style.SEVERITY_LEVEL) == SEVERITIES
    assert tuple(RcaSettings().severity) == SEVERITIES
    # An alert's marker without a value sits at its rank, 1 (info) to 4 (fatal); unknown at 0.
    assert [marker_value(Alert("node:/a", "p", 0.0, s, "")) for s in (*SEVERITIES, "odd")] == [1, 2, 3, 4, 0]


def test_episodes_escalate_along_the_scale():
    tracker = EpisodeTracker(repeat_s=60.0, gap_s=10.0)
    stored = [tracker.offer(Alert("node:/a", "p", t, s, ""))[0]
              for t, s in enumerate(("warn", "info", "error", "warn", "fatal"))]
    assert stored == [True, False, True, False, True]
