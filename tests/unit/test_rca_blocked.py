"""A stall of a single-threaded executor: which fellow's callback blocked it, from when each
one's next message was due (`siblings.blocked_first`)."""

from __future__ import annotations

import pytest

from stream_viz.model.graph import add_flow_edge, add_member, add_tree_edge, new_graph
from stream_viz.rca import RcaSettings, analyze
from stream_viz.rca.siblings import BEAT_ERROR, LATE_S, LINE_S, OUTPUT_PRIOR, blocked_first, ran_last
from stream_viz.records import Alert
from tests.unit.test_rca_containers import GROUND, pipeline

CAM, LIDAR, IMU = "node:/cam", "node:/lidar", "node:/imu"
IMAGE, SCAN, IMUT = "topic:/image", "topic:/scan", "topic:/imu"
BOX = "process:7"


def test_a_slow_node_due_as_the_executor_stopped_blocked_it_likelier_than_a_fast_one():
    # The 6 Hz camera's next frame was due at 10.125 and never came; the 100 Hz IMU published
    # until 10.115 (due 10.125 too), the 15 Hz lidar until 10.075 (due 10.142: it had not missed
    # a beat). The lidar does not fit (the IMU missed its beat 17 ms before the lidar's due).
    odds = blocked_first({"cam": (9.958, 10.125, 1 / 6), "imu": (10.115, 10.125, 0.01),
                          "lidar": (10.075, 10.142, 1 / 15)})
    hidden = (1 - OUTPUT_PRIOR) * (0.010 + LATE_S)  # another callback, between 10.115 and 10.125

    def fit(beat):
        return OUTPUT_PRIOR * (beat + LATE_S + BEAT_ERROR * beat) + hidden

    total = fit(1 / 6) + fit(0.01) + hidden
    assert odds["cam"] == pytest.approx(fit(1 / 6) / total)
    assert odds["imu"] == pytest.approx(fit(0.01) / total)
    assert odds["lidar"] == pytest.approx(hidden / total)
    assert odds["cam"] > 6 * odds["imu"] > 0


def test_two_nodes_of_one_beat_due_together_are_alike_and_one_node_says_nothing():
    odds = blocked_first({"a": (9.0, 10.0, 1.0), "b": (9.004, 10.004, 1.0)})
    assert odds["a"] == pytest.approx(0.5) and odds["b"] == pytest.approx(0.5)
    assert blocked_first({"a": (9.0, 10.0, 1.0)}) == {}


@pytest.fixture
def G():
    """A sensor container (process 7: cam, lidar, imu on one executor)."""
    g = new_graph()
    for m in (CAM, LIDAR, IMU, IMAGE, SCAN, IMUT, BOX):
        add_member(g, m)
    for node, topic in ((CAM, IMAGE), (LIDAR, SCAN), (IMU, IMUT)):
        add_flow_edge(g, node, topic, "pub")
        add_tree_edge(g, BOX, node)
    return g


def silent(topic, last, beat, t0=11.0, **data):
    """topic_rate's silence alerts: the newest message at ``last``, one every ``beat`` before."""
    data = {"since": last, "since_within": beat, **data}
    return [Alert(topic, "topic_rate", t0 + 5 * k, "error", "silent", data) for k in range(3)]


def rank(G, alerts):
    r = analyze(G, alerts, RcaSettings(), None)
    return {rc.member: rc for rc in r.root_causes}, [rc.member for rc in r.root_causes]


def test_the_node_whose_frame_was_due_as_its_container_stalled_ranks_first(G):
    # Before: the three tied (one executor, outputs silent together), each 1/3 likely first.
    alerts = silent(IMAGE, 9.958, 1 / 6) + silent(IMUT, 10.115, 0.01) + silent(SCAN, 10.075, 1 / 15)
    by, order = rank(G, alerts)
    assert order[0] == CAM
    assert by[CAM].score > by[IMU].score > by[LIDAR].score
    assert "indistinguishable_from" not in by[CAM].evidence
    assert by[CAM].evidence["blocked"] > 0.8
    assert by[LIDAR].evidence["upstream"] > by[IMU].evidence["upstream"] > 0  # excused by the camera


def test_of_fellows_in_step_the_one_that_published_first_blocked_them(G):
    # Three 10 Hz drivers in step: the executor runs them in the same order every round, the
    # camera first (its last message 2 ms before the IMU's): the IMU and the lidar cannot have
    # blocked it before it published.
    alerts = silent(IMAGE, 10.0, 0.1) + silent(IMUT, 10.002, 0.1) + silent(SCAN, 10.004, 0.1)
    by, order = rank(G, alerts)
    assert order[0] == CAM and "indistinguishable_from" not in by[CAM].evidence
    assert by[IMU].evidence["upstream"] > 0 and by[LIDAR].evidence["upstream"] > 0


def test_fellows_due_alike_stay_tied(G):
    # Three 10 Hz outputs whose last messages came together: nothing tells which one blocked.
    alerts = silent(IMAGE, 10.0, 0.1) + silent(IMUT, 10.0, 0.1) + silent(SCAN, 10.0, 0.1)
    by, order = rank(G, alerts)
    box = {CAM, LIDAR, IMU}
    assert set(order) == box and len({by[n].score for n in box}) == 1
    for n in box:
        assert by[n].evidence["indistinguishable_from"] == sorted(box - {n})


def test_a_slow_node_whose_silence_is_noticed_later_is_still_a_fellow_of_the_stall(G):
    # The 2 Hz camera blocks at its due, 10.5; the 100 Hz IMU's silence is noticed at 11, the
    # camera's only at 14 (a slow topic takes longer to be called silent). Before: the IMU,
    # noticed first, excused the camera and ranked first.
    alerts = silent(IMAGE, 10.0, 0.5, t0=14.0) + silent(IMUT, 10.495, 0.01, t0=11.0)
    by, order = rank(G, alerts)
    assert order[0] == CAM and by[CAM].evidence["blocked"] > 0.9
    assert by[IMU].evidence["upstream"] > 0


def test_a_filter_that_never_answered_its_input_blocked_the_pipeline():
    # A filter container (process 2, one executor): crop → /cropped → ground and voxel, each 10 Hz,
    # one output per input; the raw scan comes from outside and goes on. The crop's last cloud
    # came at 10.017, after the ground's and the voxel's last outputs: each was due then (not a
    # beat after its own last output), the ground first in their round (9.917 before 9.918).
    # topic_rate said the crop's executor stopped while its input arrived: one stall.
    alerts = (silent("topic:/cropped", 10.017, 0.1, executor_stopped=True)
              + silent("topic:/no_ground", 9.917, 0.1) + silent("topic:/down", 9.918, 0.1))
    by, order = rank(pipeline(), alerts)
    assert order[0] == GROUND and by[GROUND].evidence["blocked"] > 0.9
    assert "indistinguishable_from" not in by[GROUND].evidence


def test_an_input_whose_callback_publishes_nothing_may_be_where_it_blocked():
    # A merger republishes the 10 Hz /raw and reads the 30 Hz /imu; its IMU callback blocks. All
    # three last published at 10.0; the IMU's next was due first (10.033). Without its inputs the
    # IMU would be the blocker (3.4 times the others); the IMU message that arrived last (10.0) is
    # a callback of the merger's that may have blocked there, weighed as the IMU's due.
    dues = {"imu": (10.0, 10.0 + 1 / 30, 1 / 30), "driver": (10.0, 10.1, 0.1), "merger": (10.0, 10.1, 0.1)}
    alone = blocked_first(dues)
    assert alone["imu"] > 3 * alone["merger"] and alone["merger"] == pytest.approx(alone["driver"])
    odds = blocked_first(dues, {"merger": [(10.0, 1 / 30)]})
    assert odds["merger"] == pytest.approx(odds["imu"]) and odds["imu"] > 3 * odds["driver"]
    late = blocked_first(dues, {"merger": [(9.9, 1 / 30)]})  # an older arrival: it was answered
    assert late == pytest.approx(alone)


def test_the_one_that_logged_after_every_message_of_the_stall_ran_last():
    dues = {"cam": (10.0, 10.1, 0.1), "thermal": (9.98, 10.09, 1 / 9)}
    assert ran_last(dues, {"thermal": 10.03, "cam": 4.0}) == "thermal"  # after 10.0, by 10.09
    assert ran_last(dues, {"thermal": 10.0 - LINE_S + 0.001}) == "thermal"  # stamps a little off
    assert ran_last(dues, {"thermal": 9.9}) is None  # before the cam's last frame: others ran since
    assert ran_last(dues, {"thermal": 10.2}) is None  # after the first due: it was running then
    assert ran_last(dues, {"thermal": 10.03, "cam": 10.04}) is None  # two: nothing told
    assert ran_last({"cam": (10.0, 10.1, 0.1)}, {"cam": 10.03}) is None  # one node is no stall


def test_a_fellow_that_announced_the_call_that_blocked_ranks_first_where_the_timing_would_not(G):
    # Camera, IMU and lidar in step at 10 Hz, the camera first in their round: by the timing it
    # blocked them. The lidar logged
    # "Running a self-test" at 10.01, after the last message of them all (10.004): it ran last.
    alerts = (silent(IMAGE, 10.0, 0.1) + silent(IMUT, 10.002, 0.1)
              + silent(SCAN, 10.004, 0.1, logged_at=10.01))
    by, order = rank(G, alerts)
    assert order[0] == LIDAR and by[LIDAR].evidence["blocked"] == 1.0
    assert by[CAM].evidence["blocked"] == 0.0 and by[CAM].evidence["upstream"] > 0
    # Its line before the camera's last frame says nothing: the camera first, as without it.
    early = silent(IMAGE, 10.0, 0.1) + silent(IMUT, 10.002, 0.1) + silent(SCAN, 10.004, 0.1, logged_at=9.9)
    assert rank(G, early)[1][0] == CAM
