"""Component containers and executors (issue 16, item 2): several nodes in one process; the one
whose own outputs changed first or most ranks first, and the report says when they cannot be
told apart."""

from __future__ import annotations

import pytest

from stream_viz.model.graph import add_flow_edge, add_member, add_tree_edge, new_graph
from stream_viz.rca import RcaSettings, analyze
from stream_viz.rca.symptoms import IMPLIED_FELLOW
from stream_viz.records import Alert

CAM, LIDAR, IMU, DET, FUSE = "node:/cam", "node:/lidar", "node:/imu", "node:/det", "node:/fuse"
IMAGE, SCAN, IMUT = "topic:/image", "topic:/scan", "topic:/imu"
BOX = "process:7"
S = RcaSettings()
OUT = S.severity["error"] * S.charge  # a silent output, charged to its publisher


def al(member, plugin, t, severity="error", **data):
    return Alert(member, plugin, float(t), severity, f"{plugin} on {member}", data)


@pytest.fixture
def G():
    """A sensor container (process 7: cam, lidar, imu, one executor); det (process 8) subscribes
    to /image and /scan, fuse (process 9) to /imu."""
    g = new_graph()
    for m in (CAM, LIDAR, IMU, DET, FUSE, IMAGE, SCAN, IMUT, BOX, "process:8", "process:9"):
        add_member(g, m)
    for node, topic in ((CAM, IMAGE), (LIDAR, SCAN), (IMU, IMUT)):
        add_flow_edge(g, node, topic, "pub")
        add_tree_edge(g, BOX, node)
    add_flow_edge(g, IMAGE, DET, "sub")
    add_flow_edge(g, SCAN, DET, "sub")
    add_flow_edge(g, IMUT, FUSE, "sub")
    add_tree_edge(g, "process:8", DET)
    add_tree_edge(g, "process:9", FUSE)
    return g


def rank(G, alerts):
    r = analyze(G, alerts, RcaSettings(), None)
    return {rc.member: rc for rc in r.root_causes}, [rc.member for rc in r.root_causes]


def silent(topic, t0, n=3):
    return [al(topic, "topic_rate", t0 + 5 * k) for k in range(n)]


def test_the_node_whose_own_output_stopped_first_ranks_first(G):
    # cam's callback blocks at 10; the single executor starves lidar and imu, whose outputs are
    # seen to stop 4 s later. Before: all three were charged alike and tied.
    by, order = rank(G, silent(IMAGE, 10) + silent(SCAN, 14) + silent(IMUT, 14))
    assert order[0] == CAM
    assert by[CAM].evidence["process"] == BOX and "indistinguishable_from" not in by[CAM].evidence
    for sib in (LIDAR, IMU):
        assert by[sib].evidence["upstream"] == pytest.approx(OUT)  # excused by cam, which came first
        assert by[sib].evidence["hypothesis"] == pytest.approx(OUT * (1 - OUT))


def test_a_starved_container_whose_outputs_stop_together_is_named_indistinguishable(G):
    by, order = rank(G, silent(IMAGE, 10) + silent(SCAN, 10) + silent(IMUT, 11))
    assert set(order[:3]) == {CAM, LIDAR, IMU}
    for n in (CAM, LIDAR, IMU):
        assert by[n].evidence["process"] == BOX
        assert by[n].evidence["indistinguishable_from"] == sorted({CAM, LIDAR, IMU} - {n})
        assert by[n].evidence["hypothesis"] == pytest.approx(OUT)


def test_a_process_alert_goes_to_the_node_whose_own_outputs_changed(G):
    # A multi-threaded container: cam's busy callback raises the process's CPU; its siblings go
    # on publishing. Before: the process alert made all three equal candidates.
    cpu = [al(BOX, "process_resources", 9 + 5 * k, "warn") for k in range(3)]
    by, order = rank(G, cpu + silent(IMAGE, 12))
    assert order[0] == CAM
    for sib in (LIDAR, IMU):
        assert by[sib].evidence["upstream"] == pytest.approx(OUT)
        assert "indistinguishable_from" not in by[sib].evidence
    # The same, with the process alert delivered on each node (data names the process).
    per_node = [al(n, "process_resources", 9, "warn", process=BOX) for n in (CAM, LIDAR, IMU)]
    _, order = rank(G, per_node + silent(IMAGE, 12))
    assert order[0] == CAM


def test_a_process_alert_alone_cannot_tell_its_nodes_apart(G):
    by, order = rank(G, [al(n, "process_resources", 9, "warn", process=BOX) for n in (CAM, LIDAR, IMU)])
    assert set(order) == {CAM, LIDAR, IMU}
    assert by[LIDAR].evidence["indistinguishable_from"] == [CAM, IMU]


def test_a_process_alert_naming_the_node_that_began_to_warn_tells_it_apart(G):
    # The container's CPU rose as lidar began to warn ("falling back to CPU"): process_resources
    # names lidar in the alert it gives each node (data ``names``); lidar ranks first, alone.
    busy = [al(n, "process_resources", 9 + 5 * k, "warn", process=BOX, names=[LIDAR])
            for n in (CAM, LIDAR, IMU) for k in range(3)]
    by, order = rank(G, busy)
    assert order[0] == LIDAR and "indistinguishable_from" not in by[LIDAR].evidence
    assert by[LIDAR].score > by[CAM].score == by[IMU].score
    for sib in (CAM, IMU):  # excused by the node named, as by a sibling whose own change came first
        assert by[sib].evidence["upstream"] > 0 and "indistinguishable_from" not in by[sib].evidence


def test_a_client_waiting_on_one_of_the_nodes_tells_it_apart(G):
    # The container burns CPU and arm, which calls lidar's service, logs a timeout: of nodes
    # that share the process's alert alone, the one a complaining client waits on ranks first.
    arm = "node:/arm"
    add_member(G, arm)
    add_flow_edge(G, arm, LIDAR, "send")
    busy = [al(n, "process_resources", 9, "warn", process=BOX) for n in (CAM, LIDAR, IMU)]
    by, order = rank(G, [*busy, al(arm, "rosout", 12)])
    assert order[0] == LIDAR and "indistinguishable_from" not in by[LIDAR].evidence
    assert by[LIDAR].evidence["awaited_by"] == [arm] and "awaited_by" not in by[CAM].evidence
    assert by[CAM].evidence["indistinguishable_from"] == [IMU]
    assert by[LIDAR].score > by[CAM].score
    # A stall starves every service of the executor alike: the complaint tells no fellow apart.
    by, _ = rank(G, silent(IMAGE, 10) + silent(SCAN, 10) + silent(IMUT, 11) + [al(arm, "rosout", 12)])
    assert by[LIDAR].evidence["indistinguishable_from"] == [CAM, IMU]


def test_an_own_error_log_tells_the_blocking_node_apart(G):
    # All outputs stop together, but cam also logs that its callback overran.
    alerts = [al(CAM, "rosout", 10, "warn", symptom="log"), *silent(IMAGE, 10), *silent(SCAN, 10),
              *silent(IMUT, 10)]
    by, order = rank(G, alerts)
    assert order[0] == CAM and "indistinguishable_from" not in by[CAM].evidence
    assert by[LIDAR].evidence["upstream"] == pytest.approx(OUT)


def with_cam_info(G):
    """cam also feeds lidar, inside the container: cam → /cam_info → lidar."""
    add_member(G, "topic:/cam_info")
    add_flow_edge(G, CAM, "topic:/cam_info", "pub")
    add_flow_edge(G, "topic:/cam_info", LIDAR, "sub")
    return G


def test_a_process_symptom_does_not_travel_along_the_data_flow_between_its_nodes(G):
    # A process alert on both, and cam feeds lidar: the CPU (or memory) they share is one symptom
    # of the process, not cam's output reaching lidar, so the data flow tells nothing apart.
    # Before: cam excused lidar and ranked first (on the AMR, a leak in a four-node container
    # ranked the two nodes fed by nobody in it first).
    with_cam_info(G)
    by, order = rank(G, [al(n, "process_resources", 9, "warn", process=BOX) for n in (CAM, LIDAR)])
    assert set(order) == {CAM, LIDAR} and by[CAM].score == by[LIDAR].score
    assert by[LIDAR].evidence["upstream"] == 0.0
    assert by[LIDAR].evidence["indistinguishable_from"] == [CAM]


def test_a_named_node_ranks_first_though_a_sibling_feeds_it(G):
    # The same, lidar named by the process's alerts (it began to warn as the CPU rose): cam, which
    # feeds it, explains no symptom of lidar's, which are the process's, through the data flow.
    # Before: cam's trajectory covered lidar's alert and cam ranked first (the blind retail robot's
    # gap detector over its label reader, through a handheld, the mux, the base and the odometry).
    with_cam_info(G)
    busy = [al(n, "process_resources", 9, "warn", process=BOX, names=[LIDAR]) for n in (CAM, LIDAR)]
    by, order = rank(G, busy)
    assert order[0] == LIDAR and by[CAM].evidence["explains"] == 1, by[CAM].evidence
    assert by[LIDAR].score > by[CAM].score


def test_a_named_node_ranks_first_though_a_sibling_feeds_a_third_whose_alert_came_first(G):
    # cam feeds lidar, imu is named by the process's alerts (it began to warn as the CPU rose);
    # lidar's alert is the first of the run. Its share is the process's: no start of cam's
    # trajectory, which would lend cam the pair's co-occurrence and time lag. Before: cam tied
    # imu (the blind USV's radar tracker, feeding its obstacle map, beside the named detector).
    with_cam_info(G)
    busy = [al(n, "process_resources", 9, "warn", process=BOX, names=[IMU]) for n in (LIDAR, CAM, IMU)]
    by, order = rank(G, busy)
    assert order[0] == IMU and by[IMU].score > by[CAM].score, [(m, by[m].score) for m in order]
    assert by[CAM].trajectory == [CAM] and by[CAM].evidence.get("cooccurrence") is None


def test_a_fellows_own_changed_output_still_excuses_the_node_it_feeds(G):
    # The same, but cam's own output changed too: that does travel, and tells them apart.
    with_cam_info(G)
    alerts = [al(n, "process_resources", 9, "warn", process=BOX) for n in (CAM, LIDAR)]
    by, order = rank(G, alerts + silent("topic:/cam_info", 9))
    assert order[0] == CAM and by[LIDAR].evidence["upstream"] > 0
    assert all("indistinguishable_from" not in by[n].evidence for n in (CAM, LIDAR))


def test_nodes_in_separate_processes_are_not_siblings(G):
    by, _ = rank(G, [*silent(IMAGE, 10), al(DET, "rosout", 20)])
    assert "process" not in by[CAM].evidence and "process" not in by[DET].evidence


def test_a_shared_topic_charges_each_publisher_from_when_it_was_named(G):
    # The three drivers publish /diagnostics too. The camera stops first (its own stop named at
    # 10, its image silent at 11); the lidar's and imu's diagnostics are named stopped at 15 only.
    # Before: each was charged from the topic's first alert (10), and the three tied.
    add_member(G, "topic:/diagnostics")
    for n in (CAM, LIDAR, IMU):
        add_flow_edge(G, n, "topic:/diagnostics", "pub")
    diag = [al("topic:/diagnostics", "topic_rate", 10, "warn", publishers=[CAM]),
            al("topic:/diagnostics", "topic_rate", 15, "warn", publishers=[CAM, LIDAR, IMU])]
    by, order = rank(G, diag + silent(IMAGE, 11))
    assert order[0] == CAM and "indistinguishable_from" not in by[CAM].evidence
    assert by[LIDAR].evidence["upstream"] > 0 and by[IMU].evidence["upstream"] > 0  # excused by the camera


MERGE, MERGED = "node:/merger", "topic:/merged"


def with_merger(G):
    """A scan merger in the sensor container: /scan → merger → /merged → det."""
    for m in (MERGE, MERGED):
        add_member(G, m)
    add_tree_edge(G, BOX, MERGE)
    add_flow_edge(G, SCAN, MERGE, "sub")
    add_flow_edge(G, MERGE, MERGED, "pub")
    add_flow_edge(G, MERGED, DET, "sub")
    return G


def test_a_hung_merger_ties_with_the_drivers_its_executor_starves(G):
    # The merger's callback blocks; the single executor starves the lidar, imu and cam drivers:
    # every output of the container stops in one sample, and the aggregator calls the lidar
    # stale. The data flow (lidar feeds the merger) explains nothing here: imu and cam, which feed
    # nobody in the container, stopped too. Before: the merger was excused by its input.
    with_merger(G)
    stale = [al(LIDAR, "diagnostics", 11, "warn")]
    by, order = rank(G, silent(IMAGE, 10) + silent(SCAN, 10) + silent(IMUT, 10) + silent(MERGED, 10) + stale)
    box = {CAM, LIDAR, IMU, MERGE}
    assert set(order[:4]) == box
    assert len({by[n].score for n in box}) == 1  # a tie, scored alike
    for n in box:
        assert by[n].evidence["process"] == BOX
        assert by[n].evidence["indistinguishable_from"] == sorted(box - {n})
    assert by[MERGE].evidence["upstream"] == 0.0


def test_one_driver_stopping_still_excuses_the_merger_it_feeds(G):
    # Only the lidar's output and the merger's stop (the imu and cam publish on): no stall of
    # the executor, so the data flow tells them apart as before.
    with_merger(G)
    by, order = rank(G, silent(SCAN, 10) + silent(MERGED, 10))
    assert order[0] == LIDAR
    assert by[MERGE].evidence["upstream"] > 0
    assert "indistinguishable_from" not in by[LIDAR].evidence


def died(t, nodes=(CAM, LIDAR, IMU)):
    """member_gone's alerts for a process seen to die: one per hosted node, for the process."""
    return [al(n, "member_gone", t, symptom="exit", process=BOX) for n in nodes]


def test_the_nodes_of_a_crashed_container_tie_however_late_their_silence_shows(G):
    # The container dies at 10; its outputs' silence is noticed at 11, 12 and 15 (slower topics
    # take longer). Before: the node whose topic was quickest to look silent ranked first.
    by, order = rank(G, died(10) + silent(IMAGE, 11) + silent(SCAN, 12) + silent(IMUT, 15))
    box = {CAM, LIDAR, IMU}
    assert set(order[:3]) == box and len({by[n].score for n in box}) == 1
    for n in box:
        assert by[n].evidence["indistinguishable_from"] == sorted(box - {n})


def test_the_last_words_before_a_crash_tell_the_crashed_node_apart(G):
    # The lidar logged an error at 9, then the container died: the lidar ranks first.
    alerts = [al(LIDAR, "rosout", 9, symptom="log"), *died(10), *silent(IMAGE, 11), *silent(SCAN, 11),
              *silent(IMUT, 12)]
    by, order = rank(G, alerts)
    assert order[0] == LIDAR and "indistinguishable_from" not in by[LIDAR].evidence
    assert by[CAM].evidence["upstream"] > 0 and by[IMU].evidence["upstream"] > 0  # excused by the lidar


def test_the_node_that_logged_last_as_its_process_died_ranks_first(G):
    # No warning before the crash; the lidar logged last (an INFO line, the collector's
    # last_words in the exit) as the container died: the crash is its own, the others excused.
    said = {"node": LIDAR, "t": 9.8, "text": "Reloaded calibration (0 beams)"}
    quiet = [*silent(IMAGE, 11), *silent(SCAN, 11), *silent(IMUT, 12)]
    gone = [al(n, "member_gone", 10, symptom="exit", process=BOX, last_words=said) for n in (CAM, LIDAR, IMU)]
    by, order = rank(G, gone + quiet)
    assert order[0] == LIDAR and "indistinguishable_from" not in by[LIDAR].evidence
    assert by[LIDAR].score > max(by[CAM].score, by[IMU].score)
    # without last words, they tie
    by, order = rank(G, died(10) + quiet)
    assert len({by[n].score for n in (CAM, LIDAR, IMU)}) == 1


def test_last_words_tell_apart_nodes_that_left_with_their_process(G):
    # A Python container's exception: rclpy destroyed the nodes on the way out, so their topics
    # lost their publishers and no silence follows; the crash alerts are all each node has.
    said = {"node": LIDAR, "t": 9.8, "text": "Reloaded calibration (0 beams)"}
    gone = [al(n, "member_gone", 12, symptom="exit", process=BOX, last_words=said, after_goodbye=True)
            for n in (CAM, LIDAR, IMU)]
    by, order = rank(G, gone)
    assert order[0] == LIDAR and "indistinguishable_from" not in by[LIDAR].evidence
    assert by[LIDAR].score > max(by[CAM].score, by[IMU].score)
    by, order = rank(G, [al(n, "member_gone", 12, symptom="exit", process=BOX) for n in (CAM, LIDAR, IMU)])
    assert len({by[n].score for n in (CAM, LIDAR, IMU)}) == 1


CROP, GROUND, VOXEL = "node:/crop", "node:/ground", "node:/voxel"


def pipeline():
    """A lidar driver (process 1) feeding a filter container (process 2): crop → /cropped → ground
    → /no_ground, crop → /cropped → voxel → /down."""
    g = new_graph()
    for m in ("node:/driver", "topic:/raw", CROP, "topic:/cropped", GROUND, "topic:/no_ground", VOXEL,
              "topic:/down", "process:1", "process:2"):
        add_member(g, m)
    add_tree_edge(g, "process:1", "node:/driver")
    for n in (CROP, GROUND, VOXEL):
        add_tree_edge(g, "process:2", n)
    flow = (("node:/driver", "topic:/raw", (CROP,)), (CROP, "topic:/cropped", (GROUND, VOXEL)),
            (GROUND, "topic:/no_ground", ()), (VOXEL, "topic:/down", ()))
    for pub, topic, subs in flow:
        add_flow_edge(g, pub, topic, "pub")
        for sub in subs:
            add_flow_edge(g, topic, sub, "sub")
    return g


def test_a_pipeline_in_one_container_whose_executor_stopped_ties_its_filters():
    # A lidar driver (process 1) feeds a filter container (process 2, one executor): crop → /cropped
    # → ground → /no_ground, crop → /cropped → voxel → /down. The raw scan goes on; all three
    # outputs stop at once. Only the crop filter is fed from outside the container, so the data
    # flow alone blames it; the crop output's alert saying its executor stopped while its input
    # arrived makes it one stall: the three tie (the ground filter had hung).
    g, crop, ground, voxel = pipeline(), CROP, GROUND, VOXEL
    others = silent("topic:/no_ground", 10) + silent("topic:/down", 10)
    by, order = rank(g, silent("topic:/cropped", 10) + others)
    assert order[0] == crop and "indistinguishable_from" not in by[crop].evidence
    stopped = [al("topic:/cropped", "topic_rate", 10 + 5 * k, executor_stopped=True) for k in range(3)]
    by, order = rank(g, stopped + others)
    assert set(order[:3]) == {crop, ground, voxel}
    for n in (crop, ground, voxel):
        assert by[n].evidence["indistinguishable_from"] == sorted({crop, ground, voxel} - {n})


DRIVER, POINTS, COSTMAP, CONTROL, CMD = (
    "node:/lidar_driver", "topic:/points", "node:/local_costmap", "node:/controller", "topic:/cmd")


def costmap_graph(same_process: bool):
    """driver (process 1) → /points → costmap; controller → /cmd. The controller reads the
    costmap in memory when both are in process 5 (nav2's controller server and its costmap)."""
    g = new_graph()
    for m in (DRIVER, POINTS, COSTMAP, CONTROL, CMD, "process:1", "process:5", "process:6"):
        add_member(g, m)
    add_flow_edge(g, DRIVER, POINTS, "pub")
    add_flow_edge(g, POINTS, COSTMAP, "sub")
    add_flow_edge(g, CONTROL, CMD, "pub")
    add_tree_edge(g, "process:1", DRIVER)
    add_tree_edge(g, "process:5", CONTROL)
    add_tree_edge(g, "process:5" if same_process else "process:6", COSTMAP)
    return g


def test_a_node_is_excused_by_what_its_silent_sibling_reads():
    # The lidar's clouds go stale; the controller logs that its costmap is old. The costmap node
    # raised nothing: what it reads is the controller's input, through memory. Before: the
    # controller ranked first (the quadruped's stale lidar).
    from stream_viz.rca.symptoms import SILENT_DECAY

    alerts = [*(al(POINTS, "message_age", t) for t in (10, 15, 20)),
              *(al(CONTROL, "rosout", t, symptom="log") for t in (12, 17, 22))]
    by, order = rank(costmap_graph(same_process=True), alerts)
    assert order[0] == DRIVER
    assert by[CONTROL].evidence["upstream"] == pytest.approx(S.severity["error"] * SILENT_DECAY)
    # In its own process the costmap is no input of the controller's: nothing excuses it.
    by, order = rank(costmap_graph(same_process=False), alerts)
    assert order[0] == CONTROL and by[CONTROL].evidence["upstream"] == 0.0


PLANNER, BT, MANAGER = "node:/planner", "node:/bt_navigator", "node:/lifecycle_manager"


def test_a_complaint_charged_to_a_server_never_excuses_it_round_its_siblings():
    # One container: bt_navigator calls the planner; the lifecycle manager calls bt_navigator
    # (send edges: client → server). The slow planner's only symptom is bt_navigator's complaint
    # naming it; walking its silent sibling, the manager, leads back to bt_navigator, whose
    # complaint is the planner's own evidence, not its cause.
    g = new_graph()
    for m in ("process:5", PLANNER, BT, MANAGER):
        add_member(g, m)
    for m in (PLANNER, BT, MANAGER):
        add_tree_edge(g, "process:5", m)
    add_flow_edge(g, BT, PLANNER, "send")
    add_flow_edge(g, MANAGER, BT, "send")
    alerts = [a for t in (10, 17, 24) for a in (
        al(BT, "rosout", t, symptom="log"), al(BT, "services", t, server=PLANNER.removeprefix("node:")))]
    by, order = rank(g, alerts)
    assert order[0] == PLANNER
    assert BT in by[PLANNER].evidence["symptoms"]


def test_a_topic_of_the_complaining_client_never_excuses_the_server_round_its_siblings():
    # The same, but the way back is a topic: the mission (process 6) calls the planner and
    # publishes its state, which a mux (process 7) reads; the planner's silent sibling reads the
    # mux's output. The mission's complaint naming the planner is the planner's evidence; through
    # that topic it excused it (the blind USV's slow route planner ranked second to the mission
    # executive that complained of it).
    g = new_graph()
    mission, sibling, mux = "node:/mission", "node:/follower", "node:/mux"
    state, cmd = "topic:/mission/state", "topic:/cmd"
    for m in ("process:5", "process:6", "process:7", PLANNER, sibling, mission, mux, state, cmd):
        add_member(g, m)
    add_tree_edge(g, "process:5", PLANNER)
    add_tree_edge(g, "process:5", sibling)
    add_tree_edge(g, "process:6", mission)
    add_tree_edge(g, "process:7", mux)
    add_flow_edge(g, mission, PLANNER, "send")
    add_flow_edge(g, mission, state, "pub")
    add_flow_edge(g, state, mux, "sub")
    add_flow_edge(g, mux, cmd, "pub")
    add_flow_edge(g, cmd, sibling, "sub")
    server = PLANNER.removeprefix("node:")
    alerts = [a for t in (10, 17, 24)
              for a in (al(mission, "rosout", t, symptom="log"), al(mission, "services", t, server=server))]
    by, order = rank(g, alerts)
    assert order[0] == PLANNER and by[PLANNER].evidence["upstream"] == 0.0, by[PLANNER].evidence


def test_a_node_killed_by_a_signal_is_not_excused_by_its_inputs(G):
    # /imu stops at 10; fuse, which reads it, dies at 12. A crash (an exception, an abort) may
    # be what the stopped input did to it; a kill (SIGKILL: a person, a supervisor, the OOM
    # killer) is not: nothing upstream excuses it, and it is a root cause of its own beside the imu.
    def fuse_died(killed):
        return [al(FUSE, "member_gone", 12, symptom="exit", process="process:9", killed=killed)]

    crashed, _ = rank(G, silent(IMUT, 10) + fuse_died(False))
    assert crashed[FUSE].evidence["upstream"] == S.severity["error"]
    by, order = rank(G, silent(IMUT, 10) + fuse_died(True))
    assert by[FUSE].evidence["upstream"] == 0.0
    assert by[FUSE].evidence["hypothesis"] == S.severity["error"] > by[IMU].evidence["hypothesis"]
    assert order == [IMU, FUSE] and by[FUSE].score > 4 * crashed[FUSE].score


def test_a_silent_output_whose_executor_went_idle_makes_its_quiet_fellows_candidates(G):
    # cam's output stops with the container's one executor idle: a callback of lidar or imu (one
    # that publishes nothing, or only on demand) may have blocked it. Their outputs show nothing.
    by, order = rank(G, [al(IMAGE, "topic_rate", 10 + 5 * k, executor_idle=True) for k in range(3)])
    assert order[0] == CAM
    assert sorted(order[1:]) == [IMU, LIDAR]
    implied = OUT * S.charge * IMPLIED_FELLOW  # a fellow's share of cam's own change
    for fellow in (IMU, LIDAR):
        assert by[fellow].evidence["charged"] == pytest.approx(implied)
        assert by[fellow].evidence["upstream"] == 0.0  # nothing that stopped with them excuses them
    assert by[CAM].evidence["upstream"] == 0.0  # a suspicion excuses nobody
    # Its executor still running (a sensor gone quiet on its own): no suspect beside it.
    _, order = rank(G, silent(IMAGE, 10))
    assert order == [CAM]
