"""Evidence from real robots on literal data: CDR stamps, QoS rules, diagnostics mapping, service
calls, log names, and the plugins that turn them into symptoms (issue 16 items 3, 4, 5, 6, 8)."""

from __future__ import annotations

import itertools
import struct

import pytest
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rcl_interfaces.msg import Log, Parameter, ParameterEvent, ParameterValue
from rclpy.duration import Duration
from rclpy.qos import (
    DurabilityPolicy,
    LivelinessPolicy,
    QoSProfile,
    ReliabilityPolicy,
    qos_check_compatible,
)
from rclpy.serialization import serialize_message
from sensor_msgs.msg import Imu
from std_msgs.msg import Header, String
from std_srvs.srv import Trigger

from stream_viz.collect.cdr import (
    REQUEST_RECEIVED,
    REQUEST_SENT,
    RESPONSE_RECEIVED,
    RESPONSE_SENT,
    has_header,
    header_stamp_ns,
    is_service_event,
    service_event_info,
)
from stream_viz.collect.diagnostics import DiagnosticsReader, aggregator_groups, map_status
from stream_viz.collect.naming import NodeNames, named_in_text, recently_left
from stream_viz.collect.params import param_event
from stream_viz.collect.rosgraph import INFINITE_NS, qos_dict
from stream_viz.collect.services import ServiceCalls, party
from stream_viz.collect.topics import log_event
from stream_viz.collect.window import TopicWindow, window_metrics
from stream_viz.model.graph import add_flow_edge, add_member, add_tree_edge, new_graph
from stream_viz.model.qos import compatibility
from stream_viz.model.theta import make_theta
from stream_viz.rca import RcaSettings, analyze
from stream_viz.records import Alert, Event
from tests.unit.test_plugins import drive, model

S = 1_000_000_000

# --------------------------------------------------------------------------- CDR stamps


def rmw_reason(level: str, reasons: list[str]) -> str:
    """``reasons`` as rmw writes them (``"ERROR: …;WARNING: …;"``), to compare with rclpy's check."""
    return "".join(f"{level.upper()}: {r};" for r in reasons) if level != "ok" else ""


def test_header_stamp_read_from_the_serialized_bytes():
    m = Imu()
    m.header.stamp.sec, m.header.stamp.nanosec, m.header.frame_id = 1_700_000_000, 250_000_000, "imu"
    assert header_stamp_ns(serialize_message(m)) == 1_700_000_000 * S + 250_000_000
    h = Header()
    h.stamp.sec, h.stamp.nanosec = 7, 9
    assert header_stamp_ns(serialize_message(h)) == 7 * S + 9  # a Header alone begins with its stamp
    # Big endian, and XCDR2 little endian: the same two fields at the same place.
    assert header_stamp_ns(b"\x00\x00\x00\x00" + struct.pack(">iI", 5, 6) + b"\x00") == 5 * S + 6
    assert header_stamp_ns(b"\x00\x07\x00\x00" + struct.pack("<iI", 5, 6)) == 5 * S + 6
    # An unset stamp says nothing; too short or another encapsulation: not read.
    assert header_stamp_ns(serialize_message(Imu())) is None
    assert header_stamp_ns(b"\x00\x01\x00\x00\x01\x00") is None
    assert header_stamp_ns(b"\x00\x03\x00\x00" + struct.pack("<iI", 5, 6)) is None


def test_which_types_begin_with_a_header():
    assert has_header(Imu) and has_header(DiagnosticArray)
    assert not has_header(String) and not has_header(Header) and not has_header(Trigger.Event)
    assert is_service_event(Trigger.Event) and not is_service_event(Imu)


def test_service_event_info_read_from_the_serialized_bytes():
    e = Trigger.Event()
    e.info.event_type, e.info.stamp.sec, e.info.stamp.nanosec = RESPONSE_SENT, 77, 99
    e.info.client_gid, e.info.sequence_number = list(range(1, 17)), 123_456_789_012
    assert service_event_info(serialize_message(e)) == (RESPONSE_SENT, 77 * S + 99, bytes(range(1, 17)),
                                                        123_456_789_012)
    # XCDR2: the int64 sequence number aligned to 4, right after the gid.
    raw = (b"\x00\x07\x00\x00" + bytes([1, 0, 0, 0]) + struct.pack("<iI", 3, 4) + bytes(16)
           + struct.pack("<q", 42))
    assert service_event_info(raw) == (REQUEST_RECEIVED, 3 * S + 4, bytes(16), 42)
    assert service_event_info(raw[:30]) is None


def test_window_stamp_age_is_the_mean_of_the_messages_that_have_one():
    w = TopicWindow()
    recs = [(1 * S, 1 * S, 10, 1, b"a" * 16, 300_000_000), (2 * S, 2 * S, 10, 2, b"a" * 16, None),
            (3 * S, 3 * S, 10, 3, b"b" * 16, 100_000_000)]
    for r in recs:
        w.add(*r)
    m = w.metrics(3 * S, 0, 3 * S, 2)
    assert m["stamp_age_ms"] == pytest.approx(200.0)
    assert window_metrics(recs, 3 * S, 0, 3 * S, 2)["stamp_age_ms"] == pytest.approx(200.0)
    assert w.publisher_rates(3 * S, 0, 3 * S) == {b"a" * 16: 2 / 3, b"b" * 16: 1 / 3}
    assert w.publisher_ages() == {b"a" * 16: 300.0, b"b" * 16: 100.0}  # whose stamps are late
    w.expire(2 * S)
    assert w.metrics(3 * S, 0, 3 * S, 2)["stamp_age_ms"] == pytest.approx(100.0)
    assert w.publisher_rates(3 * S, 0, 3 * S) == {b"a" * 16: 1 / 3, b"b" * 16: 1 / 3}
    assert w.publisher_ages() == {b"b" * 16: 100.0}  # a's one aged record expired
    assert "stamp_age_ms" not in window_metrics([(1 * S, 1 * S, 1, 1, None, None)], 2 * S, 0, 2 * S, 1)


# --------------------------------------------------------------------------- QoS rules


def Q(rel="reliable", dur="volatile", deadline=INFINITE_NS, liv="automatic", lease=INFINITE_NS):
    return {"reliability": rel, "durability": dur, "history": "unknown", "depth": None,
            "deadline_ns": deadline, "liveliness": liv, "liveliness_lease_ns": lease}


@pytest.mark.parametrize(("pub", "sub", "want"), [
    # each of rmw's rules (qos_profile_check_compatible), in its words
    (Q(rel="best_effort"), Q(), ("error", ["Best effort publisher and reliable subscription"])),
    (Q(), Q(rel="best_effort"), ("ok", [])),
    (Q(), Q(dur="transient_local"), ("error", ["Volatile publisher and transient local subscription"])),
    (Q(dur="transient_local"), Q(), ("ok", [])),
    (Q(deadline=0), Q(deadline=S), ("error", ["Subscription has a deadline, but publisher does not"])),
    (Q(deadline=2 * S), Q(deadline=S), ("error", ["Subscription deadline is less than publisher deadline"])),
    (Q(), Q(deadline=S), ("error", ["Subscription deadline is less than publisher deadline"])),  # none set: ∞
    (Q(deadline=S), Q(deadline=2 * S), ("ok", [])),
    (Q(), Q(liv="manual_by_topic"),
     ("error", ["Publisher's liveliness is automatic and subscription's is manual by topic"])),
    (Q(liv="manual_by_topic"), Q(), ("ok", [])),
    (Q(lease=0), Q(lease=S),
     ("error", ["Subscription has a liveliness lease duration, but publisher does not"])),
    (Q(lease=2 * S), Q(lease=S),
     ("error", ["Subscription liveliness lease duration is less than publisher"])),
    (Q(rel="best_effort", dur="volatile"), Q(dur="transient_local"),
     ("error", ["Best effort publisher and reliable subscription",
                "Volatile publisher and transient local subscription"])),
    # warnings: a policy rmw cannot judge, only without errors
    (Q(rel="unknown"), Q(), ("warning", ["Reliable subscription, but publisher is unknown"])),
    (Q(rel="system_default"), Q(rel="unknown"),
     ("warning", ["Publisher reliability is system_default and subscription reliability is unknown"])),
    (Q(rel="unknown"), Q(dur="transient_local"),
     ("error", ["Volatile publisher and transient local subscription"])),
    # an older model without durations: those rules are not checked
    ({"reliability": "reliable", "durability": "volatile"}, {"reliability": "reliable", "deadline_ns": S},
     ("ok", [])),
])
def test_qos_rules_as_ros2doctor_states_them(pub, sub, want):
    assert compatibility(pub, sub) == want


def _profiles():
    rel = (ReliabilityPolicy.RELIABLE, ReliabilityPolicy.BEST_EFFORT, ReliabilityPolicy.SYSTEM_DEFAULT)
    dur = (DurabilityPolicy.VOLATILE, DurabilityPolicy.TRANSIENT_LOCAL, DurabilityPolicy.UNKNOWN)
    liv = (LivelinessPolicy.AUTOMATIC, LivelinessPolicy.MANUAL_BY_TOPIC, LivelinessPolicy.SYSTEM_DEFAULT)
    dl = (Duration(), Duration(seconds=1), Duration(seconds=2))
    for r, d, lv, deadline, lease in itertools.product(rel, dur, liv, dl, dl[:2]):
        yield QoSProfile(depth=10, reliability=r, durability=d, liveliness=lv, deadline=deadline,
                         liveliness_lease_duration=lease)


def test_qos_rules_agree_with_rclpy_qos_check_compatible_on_every_pair():
    """The collector's dict of each profile, judged by our rules, equals what rmw says."""
    profiles = list(_profiles())
    for pub, sub in itertools.product(profiles, profiles):
        level, reasons = compatibility(qos_dict(pub), qos_dict(sub))
        want_level, want_reason = qos_check_compatible(pub, sub)
        assert (level, rmw_reason(level, reasons)) == (want_level.name.lower(), want_reason), (pub, sub)


def _qos_model(pub_qos, sub_qos, extra_pub=None):
    G = model()
    qos = [{"node": "/camera", "role": "pub", **pub_qos}, {"node": "/detector", "role": "sub", **sub_qos}]
    if extra_pub is not None:
        add_member(G, "node:/replay")
        add_flow_edge(G, "node:/replay", "topic:/img", "pub")
        qos.append({"node": "/replay", "role": "pub", **extra_pub})
    G.nodes["topic:/img"]["qos"] = qos
    return G


def test_qos_compat_alerts_on_the_subscriber_with_the_reason():
    G = _qos_model(Q(rel="best_effort"), Q())
    ps = drive_alerts("qos_compat", [(1.0, G, [])])
    assert [(a.member, a.severity) for a in ps] == [("node:/detector", "error")]
    a = ps[0]
    assert a.data["reasons"] == ["node:/camera: Best effort publisher and reliable subscription"]
    assert a.data["receives_nothing"] is True and a.data["publishers"] == ["node:/camera"]
    assert "receives nothing" in a.message
    # matched by one of two publishers: it still receives, from that one
    G2 = _qos_model(Q(rel="best_effort"), Q(), extra_pub=Q())
    (a2,) = drive_alerts("qos_compat", [(1.0, G2, [])])
    assert (a2.member, a2.severity, a2.data["receives_nothing"]) == ("node:/detector", "warn", False)
    # compatible, and a deadline mismatch on the same shape
    assert drive("qos_compat", [(float(t), _qos_model(Q(), Q()), []) for t in range(5)]) == []
    (a3,) = drive_alerts("qos_compat", [(1.0, _qos_model(Q(), Q(deadline=S // 10)), [])])
    assert "deadline" in a3.message and a3.severity == "error"
    assert drive("qos_compat", [(1.0, G, [])], settings={"ignore_topics": ["/img"]}) == []
    assert drive("qos_compat", [(1.0, G, [])], watch={"node:/camera"}) == []  # neither end watched


def test_qos_compat_looks_again_when_a_qos_changed_in_place():
    # a subscription re-created as reliable on a best-effort topic: no member or edge changed;
    # the collector's qos_version says a QoS did, and the plugin looks again at once
    def frame(t, version):
        sub = Q() if t >= 3 else Q(rel="best_effort")
        G = _qos_model(Q(rel="best_effort"), sub)
        if version:
            G.graph["qos_version"] = int(t >= 3)
        return (float(t), G, [])

    assert [a[0] for a in drive("qos_compat", [frame(t, True) for t in range(6)])] == [3.0, 4.0, 5.0]
    assert drive("qos_compat", [frame(t, False) for t in range(6)]) == []  # its 10 s recheck: later


def test_graph_anomalies_no_longer_judges_qos():
    assert drive("graph_anomalies", [(1.0, _qos_model(Q(rel="best_effort"), Q()), [])]) == []


def drive_alerts(plugin, frames, *, settings=None, watch=None):
    """As `drive`, returning the alerts themselves."""
    from stream_viz.detect.api import record_history
    from stream_viz.detect.plugin_set import PluginSet
    from stream_viz.model.diff import diff
    from stream_viz.model.graph import new_graph
    from stream_viz.model.history import History

    ps = PluginSet.load(enable=[plugin], cwd_plugins=False, settings={plugin: settings or {}}, isolate=False)
    hist, prev, out = History(), new_graph(), []
    for t, G, events in frames:
        record_history(hist, G, t)
        alerts, problems = ps.run(t, G, watch if watch is not None else G.nodes, hist, events, diff(prev, G))
        assert problems == []
        out += alerts
        prev = G
    return out


# --------------------------------------------------------------------------- the RCA and a QoS alert


def test_a_qos_alert_on_the_subscriber_ranks_it_above_its_silent_downstream():
    """camera (best effort) → /img → detector (reliable: receives nothing) → /objects → planner →
    /cmd: the detector's outputs and the planner's go silent, the planner complains loudly. The
    subscriber's own QoS alert makes it the cause of the silence."""
    from stream_viz.model.graph import new_graph

    G = new_graph()
    for m in ("node:/camera", "node:/detector", "node:/planner", "topic:/img", "topic:/objects",
              "topic:/cmd"):
        add_member(G, m)
    for u, v, k in (("node:/camera", "topic:/img", "pub"), ("topic:/img", "node:/detector", "sub"),
                    ("node:/detector", "topic:/objects", "pub"), ("topic:/objects", "node:/planner", "sub"),
                    ("node:/planner", "topic:/cmd", "pub")):
        add_flow_edge(G, u, v, k)
    alerts = []
    for k in range(6):  # an episode's rows every 5 s
        t = 100.0 + 5 * k
        alerts += [Alert("node:/detector", "qos_compat", t, "error", "QoS incompatible on /img"),
                   Alert("topic:/objects", "topic_rate", t + 1, "error", "silent"),
                   Alert("topic:/cmd", "topic_rate", t + 2, "error", "silent"),
                   Alert("node:/planner", "rosout", t + 2.5, "error", "no objects for 5 s")]
    causes = analyze(G, alerts, RcaSettings(), None).root_causes
    ranked = [rc.member for rc in causes]
    assert ranked[0] == "node:/detector", ranked
    assert ranked.index("node:/detector") < ranked.index("node:/planner")
    assert causes[0].evidence["direct"] == 0.8  # the error-weight of its own alert: direct evidence


# --------------------------------------------------------------------------- diagnostics mapping

NODES = NodeNames({"/amr/front_lidar", "/amr/base_driver", "/my_node", "/robot/my_node", "/agg",
                   "/amr/diagnostic_aggregator", "/imu"})


@pytest.mark.parametrize(("name", "hw", "publisher", "want"), [
    # by name: the updater's "<node name>: <task>" with and without namespace
    ("front_lidar: scan rate", "sick-7021", "/amr/front_lidar", ("/amr/front_lidar", "name")),
    ("front_lidar: scan rate", "sick-7021", None, ("/amr/front_lidar", "name")),  # the only such base name
    ("/amr/front_lidar: scan rate", "", "/agg", ("/amr/front_lidar", "name")),
    ("//my_node: motor", "", None, ("/my_node", "name")),  # rclpy's use_fqn form in the root namespace
    ("my_node: motor", "", "/robot/my_node", ("/robot/my_node", "name")),  # two my_node: the publisher's
    ("my_node: motor", "", None, ("/my_node", "name")),  # in the root namespace
    ("/AMR/Sensors/Lidar/front_lidar: scan rate", "", None, ("/amr/front_lidar", "name")),  # aggregator path
    ("/AMR/Sensors/Lidar/ amr front_lidar: scan rate", "", None, ("/amr/front_lidar", "name")),
    # by name spelt flat: the namespace joined with "_" (one such node)
    ("amr_base_driver: motors", "", "/agg", ("/amr/base_driver", "name")),
    ("robot_my_node: motor", "", "/agg", ("/robot/my_node", "name")),
    # by hardware id: a node's name
    ("motor controller", "/amr/base_driver", "/agg", ("/amr/base_driver", "hardware_id")),
    ("motor controller", "imu", "/agg", ("/imu", "hardware_id")),
    # by publisher, then none
    ("motor controller", "roboteq-01", "/amr/base_driver", ("/amr/base_driver", "publisher")),
    ("CPU usage", "", None, (None, "none")),
])
def test_diagnostic_status_mapping_each_path(name, hw, publisher, want):
    assert map_status(name, hw, NODES, publisher) == want


def test_hardware_declared_in_a_parameter_maps_a_status():
    reader = DiagnosticsReader()
    reader.hardware.add(ParameterEvent(node="/amr/base_driver", new_parameters=[
        Parameter(name="motor_controller_id", value=ParameterValue(type=4, string_value="roboteq-01"))]))
    reader.hardware.add(ParameterEvent(node="/amr/front_lidar", new_parameters=[
        Parameter(name="frame", value=ParameterValue(type=4, string_value="base_link"))]))
    reader.hardware.add(ParameterEvent(node="/imu", new_parameters=[
        Parameter(name="frame", value=ParameterValue(type=4, string_value="base_link"))]))
    assert reader.hardware.mapping() == {"roboteq-01": "/amr/base_driver"}  # base_link: two nodes
    msg = DiagnosticArray(status=[DiagnosticStatus(level=b"\x02", name="motors", hardware_id="roboteq-01",
                                                   message="overcurrent")])
    (ev,) = reader.events("/diagnostics", msg, 5.0, "/agg", NODES)
    assert (ev.member, ev.level, ev.data["mapped_by"], ev.data["publisher"]) == (
        "node:/amr/base_driver", "error", "hardware_id", "node:/agg")


def test_hardware_configured_for_the_plugin_maps_a_status():
    G = model()
    ev = [Event(1.0, "diag", "node:/detector", "error", "motors: ERROR hot",
                {"name": "motors", "level": 2, "hardware_id": "roboteq-01", "mapped_by": "publisher"})]
    at_once = {"error_confirm_s": 0.0}  # the ERROR alerts without waiting for its next message
    table = {"hardware": ["roboteq-01=/camera"], **at_once}
    (a,) = drive_alerts("diagnostics", [(1.0, G, ev)], settings=table)
    assert (a.member, a.data["mapped_by"]) == ("node:/camera", "hardware_id")
    assert "(mapped by hardware_id)" in a.message
    (b,) = drive_alerts("diagnostics", [(1.0, G, ev)], settings=at_once)
    assert (b.member, b.data["mapped_by"]) == ("node:/detector", "publisher")


def _status(name, level=0, hw="", message=""):
    return DiagnosticStatus(level=bytes([level]), name=name, hardware_id=hw, message=message)


def test_aggregator_copies_are_not_counted_twice_and_its_news_is():
    reader = DiagnosticsReader(copy_s=30.0, stale_s=3.0)
    direct = DiagnosticArray(status=[_status("front_lidar: scan rate", 2, "sick-7021", "no scans")])
    (ev,) = reader.events("/diagnostics", direct, 10.0, "/amr/front_lidar", NODES)
    assert (ev.member, ev.data["mapped_by"]) == ("node:/amr/front_lidar", "name")

    def agg(level, leaf="front_lidar: scan rate", extra=()):
        return DiagnosticArray(status=[
            _status("/AMR", level), _status("/AMR/Sensors", level), _status("/AMR/Sensors/Lidar", level),
            _status(f"/AMR/Sensors/Lidar/{leaf}", level, "sick-7021", "x"), *extra])

    assert aggregator_groups([s.name for s in agg(2).status]) == {"/AMR", "/AMR/Sensors",
                                                                  "/AMR/Sensors/Lidar"}
    aggregator = "/amr/diagnostic_aggregator"
    assert reader.events("/diagnostics_agg", agg(2), 11.0, aggregator, NODES) == []  # a copy
    # the lidar stopped reporting: the aggregator says STALE, and that is news, mapped as the original
    (stale,) = reader.events("/diagnostics_agg", agg(3), 20.0, "/amr/diagnostic_aggregator", NODES)
    d = stale.data
    assert (stale.member, stale.level, d["level"], d["source"], d["mapped_by"]) == (
        "node:/amr/front_lidar", "warn", 3, "/diagnostics_agg", "name")
    # ... unless /diagnostics just told us it is fine
    assert reader.events("/diagnostics_agg", agg(3), 11.0, "/amr/diagnostic_aggregator", NODES) == []
    # a status only the aggregator shows (its original never seen): mapped by its own name
    other = _status("/AMR/Base/base_driver: motors", 1, "roboteq-01", "warm")
    evs = reader.events("/diagnostics_agg", agg(2, extra=(_status("/AMR/Base", 1), other)), 11.0,
                        "/amr/diagnostic_aggregator", NODES)
    assert [(e.member, e.data["mapped_by"]) for e in evs] == [("node:/amr/base_driver", "name")]
    # a STALE item whose node left the graph: no echo of the absence
    gone = NodeNames(NODES.fqns - {"/amr/front_lidar"})
    assert reader.events("/diagnostics_agg", agg(3), 60.0, "/amr/diagnostic_aggregator", gone) == []
    # ... also while its name is still known (it left lately)
    left = NodeNames(NODES.fqns - {"/amr/front_lidar"}, left={"/amr/front_lidar"})
    assert reader.events("/diagnostics_agg", agg(3), 60.0, "/amr/diagnostic_aggregator", left) == []


def test_a_status_about_a_node_that_left_is_mapped_to_it_not_to_its_publisher():
    live = {"/tools/diag", "/r1/localizer"}
    status = DiagnosticArray(status=[_status("r2_localizer: pose", 2, "", "no pose for 5 s")])
    (ev,) = DiagnosticsReader().events("/diagnostics", status, 1.0, "/tools/diag",
                                       NodeNames(live, left={"/r2/localizer"}))
    assert (ev.member, ev.data["mapped_by"]) == ("node:/r2/localizer", "name")
    (ev,) = DiagnosticsReader().events("/diagnostics", status, 1.0, "/tools/diag", NodeNames(live))
    assert (ev.member, ev.data["mapped_by"]) == ("node:/tools/diag", "publisher")


def test_recently_left_keeps_a_node_that_left_for_a_while():
    left = recently_left({}, {"/a", "/b", "/c"}, {"/a", "/c"}, 10.0, keep_s=60.0)
    assert left == {"/b": 10.0}
    left = recently_left(left, {"/a", "/c"}, {"/a"}, 20.0, keep_s=60.0)
    assert left == {"/b": 10.0, "/c": 20.0}
    assert recently_left(left, {"/a"}, {"/a", "/b"}, 30.0, keep_s=60.0) == {"/c": 20.0}  # /b is back
    assert recently_left(left, {"/a"}, {"/a"}, 75.0, keep_s=60.0) == {"/c": 20.0}  # /b forgotten


def test_diagnostics_plugin_says_how_each_alert_was_mapped():
    G = model()
    evs = DiagnosticsReader().events("/diagnostics", DiagnosticArray(status=[
        _status("detector: inference", 2, "gpu0", "CUDA error"), _status("temperature", 1, "", "warm")]),
        1.0, "/camera", NodeNames({"/camera", "/detector"}))
    alerts = drive_alerts("diagnostics", [(1.0, G, evs)],
                          settings={"learn_s": 0.0, "warn_hold_s": 0.0, "error_confirm_s": 0.0})  # at once
    assert [(a.member, a.severity, a.data["mapped_by"]) for a in alerts] == [
        ("node:/camera", "warn", "publisher"), ("node:/detector", "error", "name")]
    assert alerts[1].message == "diagnostics detector: inference: ERROR CUDA error (mapped by name)"
    assert alerts[1].data["statuses"] == [{"name": "detector: inference", "level": "error",
                                           "text": "detector: inference: ERROR CUDA error",
                                           "mapped_by": "name"}]


# --------------------------------------------------------------------------- names in log text


def test_log_text_names_services_and_nodes_of_the_graph():
    index = NodeNames({"/nav/planner", "/nav/bt_navigator", "/camera"})
    services = {"/nav/plan_path", "/camera/set_mode"}
    assert named_in_text("service /nav/plan_path not available, waiting again...", index, services,
                         "/nav", "/nav/bt_navigator") == ([], ["/nav/plan_path"])
    assert named_in_text("planner timed out; calling 'plan_path'", index, services, "/nav",
                         "/nav/bt_navigator") == (["/nav/planner"], ["/nav/plan_path"])
    assert named_in_text("~/set_mode failed", index, services, "/", "/camera") == ([], ["/camera/set_mode"])
    assert named_in_text("cannot reach /camera", index, services, "/nav", "/nav/bt_navigator") == (
        ["/camera"], [])
    # the writer itself, unknown names and topics are not named members
    assert named_in_text("bt_navigator: goal on /nav/cmd_vel rejected", index, services, "/nav",
                         "/nav/bt_navigator") == ([], [])
    ev = log_event(Log(level=40, name="nav.bt_navigator", msg="service /nav/plan_path not available"),
                   index, frozenset(services))
    assert (ev.member, ev.data["services"]) == ("node:/nav/bt_navigator", ["service:/nav/plan_path"])
    assert "nodes" not in ev.data
    # an action, named relative to the writer's namespace, as Nav2's behaviour tree logs it
    ev = log_event(Log(level=40, name="nav.bt_navigator",
                       msg="Timed out waiting for action server compute_path_to_pose"),
                   index, frozenset(services), frozenset({"/nav/compute_path_to_pose"}))
    assert ev.data["actions"] == ["action:/nav/compute_path_to_pose"] and "services" not in ev.data


# --------------------------------------------------------------------------- service calls


def test_service_calls_open_answered_and_out_of_order():
    calls = ServiceCalls(window_s=3.0, forget_s=60.0)
    c1, c2 = b"\x01" * 12 + b"\x00\x00\x01\x04", b"\x02" * 12 + b"\x00\x00\x01\x04"
    srv = b"\x09" * 12 + b"\x00\x00\x02\x03"
    calls.add("/plan", 10 * S, REQUEST_SENT, c1, 1)
    calls.add("/plan", 10 * S + 1000, REQUEST_RECEIVED, c1, 1, srv)  # the server's view of the same call
    calls.add("/plan", 10 * S + 400_000_000, RESPONSE_SENT, c1, 1, srv)
    calls.add("/plan", 10 * S + 500_000_000, RESPONSE_RECEIVED, c1, 1)  # the same call's last event
    calls.add("/plan", 11 * S, REQUEST_RECEIVED, c2, 7, srv)  # c2 waits
    # a response event that overtook its request event (two writers): no phantom open call
    calls.add("/plan", 11 * S + 5, RESPONSE_SENT, c1, 2, srv)
    calls.add("/plan", 11 * S + 9, REQUEST_SENT, c1, 2)
    st = calls.stats(13 * S)["/plan"]
    assert st.calls_per_s == pytest.approx(1 / 3)  # one call answered in the window (the other's
    assert st.response_ms == pytest.approx(400.0)  # request came after its response)
    assert st.open_calls == [(2.0, c2, srv)]
    st = calls.stats(72 * S)["/plan"]  # forgotten after 60 s
    assert st.open_calls == [] and calls.abandoned == 1 and st.calls_per_s == 0.0
    calls.forget(set())
    assert calls.stats(73 * S) == {}


def test_party_of_a_gid_by_its_participant():
    prefixes = {b"\x01" * 12: ["/bt", "/helper"], b"\x02" * 12: ["/planner"]}
    assert party(b"\x01" * 12 + b"\x00\x00\x01\x04", prefixes, ["/bt", "/other"]) == "/bt"
    assert party(b"\x01" * 12 + b"\x00\x00\x01\x04", prefixes, ["/bt", "/helper"]) is None  # same process
    assert party(None, prefixes, ["/planner"]) == "/planner"  # the only one
    assert party(b"\x05" * 16, prefixes, ["/a", "/b"]) is None


def _service_model(servers=("/planner",), calls=None, response_ms=100.0):
    G = model()
    add_member(G, "node:/planner")
    add_member(G, "node:/bt")
    values = {"servers": len(servers), "clients": 1}
    extra = {}
    if calls is not None:
        values.update(calls_per_s=1.0, response_ms=response_ms, waiting=len(calls),
                      wait_s=max((c["waited_s"] for c in calls), default=0.0))
        extra = {"introspected": True, "calls": calls}
    add_member(G, "service:/plan", servers=list(servers), clients=["/bt"],  # fqns, as the collector
               theta=make_theta("service", values), **extra)
    return G


def test_an_ambiguous_base_name_is_told_apart_by_a_namespace_in_the_line():
    index = NodeNames({"/r1/planner", "/r2/planner", "/fleet/manager"})
    line = "r1: delivery 4 not acknowledged by the planner after 10 s"
    assert named_in_text(line, index, set(), "/fleet", "/fleet/manager") == (["/r1/planner"], [])
    assert named_in_text("R2 planner did not answer", index, set(), "/fleet", "/fleet/manager") == (
        ["/r2/planner"], [])
    # no namespace in the line, or both: still ambiguous, nobody named
    assert named_in_text("the planner did not answer", index, set(), "/fleet", "/fleet/manager") == ([], [])
    assert named_in_text("r1 and r2: planner slow", index, set(), "/fleet", "/fleet/manager") == ([], [])


def test_services_waiting_client_names_the_server():
    quiet = [(float(t), _service_model(calls=[]), []) for t in range(15)]
    waiting = [{"client": "node:/bt", "server": "node:/planner", "waited_s": 2.5},
               {"client": "node:/bt", "server": "node:/planner", "waited_s": 0.2}]
    frames = [*quiet, (15.0, _service_model(calls=waiting, response_ms=float("nan")), [])]
    alerts = drive_alerts("services", frames)
    assert [(a.t, a.member, a.severity) for a in alerts] == [(15.0, "node:/bt", "warn")]
    assert {k: alerts[0].data[k] for k in ("symptom", "service", "server", "client", "waited_s")} == {
        "symptom": "waiting", "service": "service:/plan", "server": "node:/planner", "client": "node:/bt",
        "waited_s": 2.5}
    assert "usually answered in 100 ms" in alerts[0].message
    # a service that usually takes 1 s: 2.5 s is not yet waiting (3 × its usual time)
    slow_usual = [(float(t), _service_model(calls=[], response_ms=1000.0), []) for t in range(15)]
    assert drive("services", [*slow_usual, (15.0, _service_model(calls=waiting, response_ms=float("nan")),
                                            [])]) == []
    # the client is unknown (several in one process): on the service, the server still named
    anon = [{"client": None, "server": None, "waited_s": 3.0}]
    (a,) = drive_alerts("services", [*quiet, (15.0, _service_model(calls=anon), [])])
    assert (a.member, a.data["server"], a.data["client"]) == ("service:/plan", "node:/planner", None)


def test_services_a_call_is_judged_by_the_longest_answer_until_a_baseline_is_learnt():
    # a service called rarely: one answer of 6 s seen, far too few for a baseline
    once = [(0.0, _service_model(calls=[], response_ms=6000.0), [])]
    once += [(float(t), _service_model(calls=[], response_ms=float("nan")), []) for t in range(1, 5)]

    def waited(s, frames):
        call = [{"client": "node:/bt", "server": "node:/planner", "waited_s": s}]
        return drive_alerts("services", [*frames, (5.0, _service_model(calls=call, response_ms=float("nan")),
                                                   [])])
    assert waited(10.0, once) == []  # within 3 × 6 s
    assert [a.data["waited_s"] for a in waited(19.0, once)] == [19.0]
    # never answered yet: some services take seconds, a call is waiting after first_wait_s (30 s)
    none = [(float(t), _service_model(calls=[], response_ms=float("nan")), []) for t in range(5)]
    assert waited(10.0, none) == []
    assert [a.data["waited_s"] for a in waited(31.0, none)] == [31.0]


def test_services_slow_responses_against_their_own_baseline():
    frames = [(float(t), _service_model(calls=[], response_ms=100.0 + (t % 3)), []) for t in range(15)]
    frames += [(float(t), _service_model(calls=[], response_ms=900.0), []) for t in range(15, 18)]
    alerts = drive_alerts("services", frames)
    assert [(a.t, a.member) for a in alerts] == [(16.0, "node:/bt"), (17.0, "node:/bt")]
    assert alerts[0].data["symptom"] == "slow_response" and alerts[0].data["server"] == "node:/planner"


def test_services_an_action_client_log_naming_its_action_names_the_server():
    G = model()
    add_member(G, "node:/planner")
    add_member(G, "node:/bt")
    add_member(G, "action:/compute_path", servers=["/planner"], clients=["/bt"],
               theta=make_theta("action", {"servers": 1, "clients": 1}))
    log = Event(1.0, "log", "node:/bt", "error", "action compute_path timed out",
                {"actions": ["action:/compute_path"]})
    alerts = drive_alerts("services", [(1.0, G, [log])])
    assert [(a.member, a.severity, a.data["server"], a.data["service"]) for a in alerts] == [
        ("node:/bt", "error", "node:/planner", "action:/compute_path")]
    # the action server gone while its client remains
    gone = model()
    add_member(gone, "node:/bt")
    add_member(gone, "action:/compute_path", servers=[], clients=["/bt"],
               theta=make_theta("action", {"servers": 0, "clients": 1}))
    alerts = drive_alerts("services", [(1.0, G, []), (2.0, gone, [])])
    assert [(a.member, a.data["symptom"], a.data["server"]) for a in alerts] == [
        ("node:/bt", "server_gone", "node:/planner")]


def test_services_server_gone_while_clients_remain():
    frames = [(1.0, _service_model(), []), (2.0, _service_model(servers=()), []),
              (3.0, _service_model(servers=()), [])]
    alerts = drive_alerts("services", frames)
    assert [(a.t, a.member, a.data["symptom"], a.data["server"]) for a in alerts] == [
        (2.0, "node:/bt", "server_gone", "node:/planner"), (3.0, "node:/bt", "server_gone", "node:/planner")]
    assert drive("services", [(1.0, _service_model(servers=()), [])]) == []  # never had one: late start


ONCE = {"warn_repeat_s": 0.0}  # a WARN naming a service counts at once


def test_services_client_log_naming_its_service_or_server():
    G = _service_model()
    logs = [Event(1.0, "log", "node:/bt", "warn", "service /plan not available",
                  {"services": ["service:/plan"]}),
            Event(1.0, "log", "node:/bt", "error", "planner timed out", {"nodes": ["node:/planner"]}),
            Event(1.0, "log", "node:/camera", "error", "service /plan not available",  # not its client
                  {"services": ["service:/plan"]})]
    alerts = drive_alerts("services", [(1.0, G, logs[1:])])
    assert [(a.member, a.severity, a.data["via"], a.data["server"], a.data["service"], a.message)
            for a in alerts] == [
        ("node:/bt", "error", "log", "node:/planner", "service:/plan",
         "logged about /plan: planner timed out")]
    # a WARN counts, as a warning (once said again: below); one alert per client and service and
    # sample, at its worst line
    warned = drive_alerts("services", [(1.0, G, logs[:1])], settings=ONCE)
    assert [(a.member, a.severity, a.data["server"]) for a in warned] == [
        ("node:/bt", "warn", "node:/planner")]
    assert [(a.severity, a.data["server"]) for a in drive_alerts("services", [(1.0, G, logs)])] == [
        ("error", "node:/planner")]
    # at an ERROR floor the WARN is not read
    strict = drive_alerts("services", [(1.0, G, logs[:1])], settings={"log_level": "error"})
    assert strict == []


def test_services_a_warn_naming_a_service_counts_once_said_again():
    # A behaviour tree announcing its recovery once (WARN naming /plan) is routine; the same
    # WARN again within 30 s is a client that waits; an ERROR counts at once.
    G = _service_model()

    def line(t, level="warn"):
        return Event(t, "log", "node:/bt", level, "running the recovery (plan)",
                     {"services": ["service:/plan"]})

    assert drive_alerts("services", [(10.0, G, [line(10.0)])]) == []
    again = drive_alerts("services", [(10.0, G, [line(10.0)]), (25.0, G, [line(25.0)])])
    assert [(a.t, a.severity) for a in again] == [(25.0, "warn")]
    apart = drive_alerts("services", [(10.0, G, [line(10.0)]), (50.0, G, [line(50.0)])])
    assert apart == []
    assert [(a.t, a.severity) for a in drive_alerts("services", [(10.0, G, [line(10.0, "error")])])] == [
        (10.0, "error")]


def test_services_a_client_waiting_while_its_servers_come_up_is_their_bring_up():
    # The client's process started at 0 s, the planner's at 20 s (a loaded computer: bring-up
    # outlasts the client's first 10 s). "waiting for /plan" at 25 s is the planner coming up.
    def graph(servers=("/planner",)):
        G = _service_model(servers)
        for proc, node, created in (("process:1", "node:/bt", 0.0), ("process:2", "node:/planner", 20.0)):
            add_member(G, proc, create_time=created)
            add_tree_edge(G, proc, node)
        return G

    def waits(t, G, before=()):
        line = Event(t, "log", "node:/bt", "warn", "waiting for service /plan",
                     {"services": ["service:/plan"]})
        return [(a.t, a.data["symptom"]) for a in drive_alerts("services", [*before, (t, G, [line])],
                                                                 settings=ONCE)]

    assert waits(25.0, graph()) == []
    assert waits(35.0, graph()) == [(35.0, "waiting")]  # the planner up 15 s: it waits on it
    # No server yet and never one: the robot still coming up, for the client's first 60 s.
    assert waits(25.0, graph(servers=())) == []
    assert waits(70.0, graph(servers=())) == [(70.0, "waiting")]
    # A server it had and lost: waiting on it is a symptom at once (beside server_gone).
    lost = waits(36.0, graph(servers=()), before=[(35.0, graph(), [])])
    assert lost == [(36.0, "server_gone"), (36.0, "waiting")]


def test_services_a_client_waiting_for_a_server_the_monitor_sees_appear_is_its_bring_up():
    # Both processes started at 0 s; the planner's service came up only at 70 s (a slow
    # bring-up): the client's lines until then, and in the 2 s after, waited for it.
    def graph(servers=("/planner",)):
        G = _service_model(servers)
        for proc, node in (("process:1", "node:/bt"), ("process:2", "node:/planner")):
            add_member(G, proc, create_time=0.0)
            add_tree_edge(G, proc, node)
        return G

    def waits(t, frames):
        line = Event(t, "log", "node:/bt", "warn", "waiting for service /plan",
                     {"services": ["service:/plan"]})
        return [(a.t, a.data["symptom"]) for a in drive_alerts("services", [*frames, (t, graph(), [line])],
                                                                 settings=ONCE)]

    coming = [(65.0, graph(servers=()), []), (70.0, graph(), [])]
    assert waits(70.0, coming[:1]) == []  # logged before the monitor saw the server
    assert waits(71.5, coming) == []  # the client found it a moment after the monitor did
    assert waits(73.0, coming) == [(73.0, "waiting")]  # up 3 s: it waits on it
    # A server already up when the monitor started came up earlier: no excuse.
    assert waits(71.0, [(70.0, graph(), [])]) == [(71.0, "waiting")]


# --------------------------------------------------------------------------- message age


def _aged(age_ms, t, newest=0.05, young=None):
    G = model()
    theta = G.nodes["topic:/img"]["theta"]
    G.nodes["topic:/img"]["theta"] = make_theta("topic", {
        **{k: float(v) for k, v in zip(("rate_hz", "jitter_ms", "latency_ms", "bandwidth_kBps", "drops_per_s",
                                        "publishers", "subscribers"), theta, strict=False)},
        "age_s": newest, "stamp_age_ms": age_ms, **({} if young is None else {"stamp_age_recent_ms": young})})
    return (float(t), G, [])


def test_message_age_every_recent_message_late_is_stale_without_waiting_out_the_window():
    healthy = [_aged(2.0 + (t % 3) * 0.5, t, young=1.5) for t in range(15)]
    # The youngest of the newest messages 300 ms late too: every one is, after 2 fresh samples.
    lagging = healthy + [_aged(150.0 + 150.0 * (t > 15), t, young=300.0) for t in range(15, 18)]
    alerts = drive_alerts("message_age", lagging)
    assert [(a.t, a.data["symptom"]) for a in alerts] == [(16.0, "stale"), (17.0, "stale")]
    # One old-stamped message among new ones lifts the mean only: the youngest stays young.
    once = healthy + [_aged(302.0 if t < 18 else 2.0, t, young=2.0) for t in range(15, 25)]
    assert drive("message_age", once) == []
    # A stall that delivers a late batch in one sample and fresh messages in the next.
    batch = healthy + [_aged(200.0 if t < 18 else 2.0, t, young=250.0 if t == 15 else 2.0)
                       for t in range(15, 25)]
    assert drive("message_age", batch) == []


def test_message_age_stale_against_its_own_baseline():
    healthy = [_aged(2.0 + (t % 3) * 0.5, t) for t in range(15)]
    assert drive("message_age", healthy) == []
    # Confirmed after 3 samples, counted once it outlasts the 3 s window (hold_s 4 s).
    lagging = healthy + [_aged(302.0, t) for t in range(15, 21)]
    alerts = drive_alerts("message_age", lagging)
    assert [(a.t, a.member, a.severity) for a in alerts] == [(19.0, "topic:/img", "warn"),
                                                             (20.0, "topic:/img", "warn")]
    assert alerts[0].data["symptom"] == "stale" and alerts[0].data["baseline_ms"] == pytest.approx(2.5)
    # A second older than usual is an error, as a topic silent that long is.
    useless = [(a.t, a.severity) for a in drive_alerts("message_age", healthy + [_aged(1102.0, t)
                                                                               for t in range(15, 21)])]
    assert useless == [(19.0, "error"), (20.0, "error")]
    # a pipeline whose data is normally 1 s old: 1.4 s is within half its baseline
    slow = [_aged(1000.0 + (t % 3), t) for t in range(15)] + [_aged(1400.0, t) for t in range(15, 19)]
    assert drive("message_age", slow) == []
    # the same late message held in the window (no newer one): one observation, not three
    held = healthy + [_aged(302.0, t, newest=1.0 + t) for t in range(15, 21)]
    assert drive("message_age", held) == []
    # one old-stamped message among new ones (a latched map sent again) lifts the window's mean
    # for the 3 samples it stays in the window: not stale data
    once = healthy + [_aged(302.0 if t < 18 else 2.0, t) for t in range(15, 25)]
    assert drive("message_age", once) == []


def test_message_age_data_delayed_while_its_publisher_s_process_is_busy_is_the_cpu_s_symptom():
    # The camera's process goes from 5 % to 90 % of a core at 15 s (its executor spinning, a hog)
    # and its images arrive 300 ms after their stamps: the CPU is the symptom (process_resources,
    # which knows the process's bursts), not stale data as well. Not busy, the same age is stale.
    def frame(t, age, cpu):
        f = _aged(age, t, young=age)
        f[1].nodes["process:100"]["theta"] = make_theta("process", {"cpu_percent": cpu, "rss_mb": 50.0})
        return f

    healthy = [frame(t, 2.0 + (t % 3) * 0.5, 5.0 + t % 2) for t in range(15)]
    assert drive("message_age", healthy + [frame(t, 300.0, 90.0) for t in range(15, 22)]) == []
    stale = drive_alerts("message_age", healthy + [frame(t, 300.0, 5.0) for t in range(15, 22)])
    assert stale and {a.data["symptom"] for a in stale} == {"stale"}


def test_message_age_learns_a_slow_topic_s_normal_from_its_messages_not_its_samples():
    # A USBL fix every 4 s (each in four 1 s samples), stamped 0.2-0.6 s before it arrives: after
    # two fixes of 222 and 276 ms, three of ~490 ms are its spread, not stale data.
    # (t, age ms, age of the newest s) as the AUV's monitor sampled them (none between fixes
    # 3 s apart: nothing in its window).
    seen = [(16, 222, 0.7), (17, 222, 1.7), (18, 222, 2.7), (21, 276, 0.1), (22, 276, 1.1), (23, 276, 2.1),
            (24, 484, 0.9), (25, 484, 1.9), (26, 492, 0.5), (27, 500, 1.5), (28, 500, 2.5), (30, 462, 0.8),
            (31, 462, 1.8), (32, 462, 2.8), (35, 465, 0.5), (36, 465, 1.5), (37, 465, 2.5), (41, 416, 1.0),
            (42, 416, 2.0), (43, 416, 3.0), (46, 285, 0.7), (47, 285, 1.7), (50, 411, 0.4), (51, 411, 1.4)]
    frames = [_aged(float("nan"), t, newest=float("nan")) for t in range(5, 16)]  # known, no fix yet
    frames += [_aged(float(ms), t, newest=newest, young=float(ms)) for t, ms, newest in seen]
    assert drive("message_age", frames) == []
    assert drive("message_age", frames, settings={"min_messages": 1})[:1] == [(26.0, "topic:/img", "warn")]
    # Once eight fixes are in, 2.5 s old ones are stale.
    late = frames + [_aged(2500.0, t, newest=0.1 + t % 4, young=2500.0) for t in range(52, 68)]
    assert [a.data["symptom"] for a in drive_alerts("message_age", late)][:1] == ["stale"]


def test_message_age_names_the_publishers_whose_own_stamps_are_late():
    # /img from the camera and a replay node: the camera's stamps froze, the replay's are on time
    def two(t, camera_ms):
        frame = _aged(2.0 if t < 15 else (camera_ms + 2.0) / 2, t)
        frame[1].nodes["topic:/img"]["publisher_ages"] = {"node:/camera": camera_ms, "node:/replay": 2.0}
        return frame
    frames = [two(t, 2.0 + (t % 3) * 0.5) for t in range(15)] + [two(t, 602.0) for t in range(15, 21)]
    alerts = drive_alerts("message_age", frames)
    assert alerts and alerts[0].data["publishers"] == ["node:/camera"], alerts
    assert "from /camera (the others' on time)" in alerts[0].message
    # both late: the topic's, no one named
    both = [two(t, 2.0) for t in range(15)] + [_aged(302.0, t) for t in range(15, 21)]
    for _, G, _ in both[15:]:
        G.nodes["topic:/img"]["publisher_ages"] = {"node:/camera": 302.0, "node:/replay": 302.0}
    alerts = drive_alerts("message_age", both)
    assert alerts and all("publishers" not in a.data for a in alerts)


def test_message_age_a_postdated_publisher_makes_no_one_late():
    # /tf from odometry (its stamps freeze), a robot state publisher on time and a localiser
    # stamping 180 ms ahead: only odometry's messages are late, not the state publisher's 5 ms
    def three(t, odom_ms):
        frame = _aged(2.0 if t < 15 else 900.0, t)
        frame[1].nodes["topic:/img"]["publisher_ages"] = {
            "node:/odom": odom_ms, "node:/rsp": 5.0, "node:/loc": -180.0}
        return frame
    frames = [three(t, 2.0 + (t % 3) * 0.5) for t in range(15)] + [three(t, 2602.0) for t in range(15, 21)]
    alerts = drive_alerts("message_age", frames)
    assert alerts and alerts[0].data["publishers"] == ["node:/odom"], alerts


def test_message_age_skewed_or_implausible_clocks_are_said_so_not_called_latency():
    on_time = [_aged(2.0, t) for t in range(12)]  # past learn_s (10 s): its stamps are on time
    ahead = on_time + [_aged(-250.0, t) for t in range(12, 16)]
    alerts = drive_alerts("message_age", ahead)
    assert [(a.t, a.data["symptom"]) for a in alerts] == [(14.0, "clock_skew"), (15.0, "clock_skew")]
    assert "ahead of this host's clock" in alerts[0].message and "not a latency" in alerts[0].message
    sim = on_time + [_aged(1.7e12, t) for t in range(12, 16)]  # stamps from a simulated clock at 0
    alerts = drive_alerts("message_age", sim)
    assert alerts and all(a.data["symptom"] == "clock_skew" for a in alerts)
    assert "not from the wall clock" in alerts[0].message


def test_transforms_postdated_on_this_computer_are_no_clock_skew():
    # /tf from a robot state publisher (on time) and a localiser stamping map->odom 200 ms ahead
    # (AMCL's transform_tolerance), which publishes faster once the robot moves: the mean goes
    # 25 ms ahead. On this computer, whose clock both read, that is postdating, not a skew.
    def tf(t, moving, where="vm"):
        frame = _aged(-25.0 if moving else 2.0, t)
        G = frame[1]
        G.nodes["topic:/img"]["type"] = "geometry_msgs/msg/TransformStamped"
        G.nodes["topic:/img"]["publisher_ages"] = {"node:/camera": 5.0, "node:/detector": -180.0}
        add_member(G, "host:vm", agent="local")
        add_member(G, "host:nuc", agent="remote")
        G.nodes["node:/camera"]["host"], G.nodes["node:/detector"]["host"] = "vm", where
        return frame

    frames = [tf(t, t >= 12) for t in range(16)]
    assert drive("message_age", frames) == []
    # the one stamping ahead is on another computer: its clock may be skewed, as before
    remote = [tf(t, t >= 12, where="nuc") for t in range(16)]
    assert {a.data["symptom"] for a in drive_alerts("message_age", remote)} == {"clock_skew"}
    # nor is any other type postdated: images stamped ahead from this computer are skewed
    for _, G, _ in frames:
        G.nodes["topic:/img"]["type"] = "sensor_msgs/msg/Image"
    assert {a.data["symptom"] for a in drive_alerts("message_age", frames)} == {"clock_skew"}


def test_a_skew_from_the_start_is_the_topics_normal_and_its_staleness_is_still_seen():
    # a device stamping with its own clock, 400 ms ahead of ours from its first message
    device = [_aged(-400.0 + (t % 3), t) for t in range(30)]
    assert drive("message_age", device) == []
    # its data then lags 300 ms behind its own normal: stale, the offset cancelling out
    alerts = drive_alerts("message_age", device + [_aged(-100.0, t) for t in range(30, 36)])
    assert alerts and {a.data["symptom"] for a in alerts} == {"stale"}
    # a recording's stamps, hours old from the start: no alert, no staleness judged
    assert drive("message_age", [_aged(3.6e7 + t, t) for t in range(30)]) == []
    # stamps on time at first, then hours old: news
    late = [_aged(2.0, t) for t in range(12)] + [_aged(3.6e7, t) for t in range(12, 16)]
    assert {a.data["symptom"] for a in drive_alerts("message_age", late)} == {"clock_skew"}


def test_a_stamp_reset_restarts_what_a_topics_age_is_judged_against():
    # a recording looped: its stamps went back 47 s, its data are 47 s older from then on
    looped = [_aged(100.0 + (t % 3), t) for t in range(30)]
    looped += [_aged(47100.0 + (t % 3), t) for t in range(30, 50)]
    reset = Event(29.5, "stamp_reset", "topic:/img", "info", "header stamps went back 47.0 s",
                  {"back_s": 47.0})
    frames = [(t, G, [reset] if t == 30.0 else ev) for t, G, ev in looped]
    assert drive("message_age", frames) == []
    # the same jump without a reset of its stamps (they went on, the data lag): stale
    assert {a.data["symptom"] for a in drive_alerts("message_age", looped)} == {"stale"}


def test_a_live_clock_that_jumps_back_mid_stream_makes_its_data_stale():
    # a rangefinder stamped by its own clock, 300 ms behind ours; 100 s on, a brown-out resets the
    # clock 2 s further back: the same reset event as a loop's, but 2 s of 100 s is no loop
    live = [_aged(300.0 + (t % 3) + (2000.0 if t >= 100 else 0.0), t) for t in range(110)]
    jump = Event(99.5, "stamp_reset", "topic:/img", "info", "header stamps went back 2.0 s", {"back_s": 2.0})
    alerts = drive_alerts("message_age", [(t, G, [jump] if t == 100.0 else ev) for t, G, ev in live])
    assert alerts and {a.data["symptom"] for a in alerts} == {"stale"}
    assert alerts[0].data["stamps_back_s"] == 2.0 and "its clock jumped" in alerts[0].message


def test_stamps_that_went_back_to_where_they_began_looped():
    from plugins.message_age import looped

    assert looped(47.0, 30.0) and looped(7.0, 7.5) and looped(30.0, 100.0)  # back to the start
    assert not looped(2.0, 100.0) and not looped(29.0, 100.0)  # a clock that jumped mid-stream
    assert looped(0.5, 0.0)  # no stamping seen before: nothing to tell it by


def test_window_tells_stamps_going_back_per_publisher():
    from stream_viz.collect.window import TopicWindow

    s, w = 1_000_000_000, TopicWindow()
    for k in range(5):  # two publishers, 0.5 s apart in their clocks: no reset
        w.add(k * s, k * s, 10, None, b"a", 0)
        w.add(k * s + 1, k * s + 1, 10, None, b"b", s // 2)
    assert w.take_resets() == []
    w.add(5 * s, 5 * s, 10, None, b"a", 48 * s)  # publisher a's stamp went back 47 s (4 s to -43 s)
    w.add(5 * s + 1, 5 * s + 1, 10, None, b"b", s // 2)
    assert w.take_resets() == [(5 * s, 47 * s)] and w.take_resets() == []


def test_snapshot_text_says_who_sends_on_a_multi_publisher_topic():
    from stream_viz.collect.snapshot import _member_line

    G = model()
    G.nodes["topic:/img"]["publisher_rates"] = {"node:/camera": 10.0, "node:/replay": 2.5}
    assert "from node:/camera 10 Hz, node:/replay 2.5 Hz" in _member_line(G, "topic:/img")
    G.nodes["topic:/img"]["publisher_rates"] = {"node:/camera": 10.0}
    assert " from " not in _member_line(G, "topic:/img")


def test_the_longest_gap_since_the_last_look_counts_what_both_clocks_agree_on():
    w = TopicWindow()
    for k in range(5):  # 10 Hz
        w.add(k * S // 10, k * S // 10, 1, k)
    assert w.take_gap() == pytest.approx(0.1)
    assert w.take_gap() == 0.0  # started over
    w.add(3 * S, 3 * S, 1, 5)  # a real quiet: 2.6 s on both clocks
    w.add(3 * S + S // 10, 3 * S + S // 10, 1, 6)
    assert w.take_gap() == pytest.approx(2.6)
    # The monitor stalled: three messages sent 0.1 s apart were received together 2 s late.
    for k in range(3):
        w.add(5 * S + 2 * S // 10 + k, 3 * S + (k + 2) * S // 10, 1, 7 + k)
    assert w.take_gap() == pytest.approx(0.1)


def test_a_parameter_event_that_changes_or_deletes_is_one_param_event_of_its_node():
    def p(name, **value):
        return Parameter(name=name, value=ParameterValue(**value))

    declared = ParameterEvent(node="/amr1/camera", new_parameters=[p("rate_hz", type=3, double_value=10.0)])
    assert param_event(declared, 5.0) is None  # a node declaring its parameters as it starts
    ev = param_event(ParameterEvent(node="/amr1/camera",
                                    changed_parameters=[p("rate_hz", type=3, double_value=4.0),
                                                        p("frame_id", type=4, string_value="cam"),
                                                        p("roi", type=7, integer_array_value=[1, 2])],
                                    deleted_parameters=[p("gain")]), 12.5)
    assert (ev.t, ev.kind, ev.member, ev.level) == (12.5, "param", "node:/amr1/camera", "info")
    assert ev.data == {"changed": {"rate_hz": "4.0", "frame_id": "'cam'", "roi": "[1, 2]"},
                       "deleted": ["gain"]}
    assert ev.text == ("parameters of /amr1/camera: rate_hz = 4.0, frame_id = 'cam', roi = [1, 2], "
                       "gain deleted")
    long = param_event(ParameterEvent(node="/n", changed_parameters=[p("s", type=4, string_value="x" * 100)]),
                       1.0)
    assert len(long.data["changed"]["s"]) == 60 and long.data["changed"]["s"].endswith("…")


def test_a_parameter_set_to_the_value_it_had_is_no_change():
    def p(name, value):
        return Parameter(name=name, value=ParameterValue(type=3, double_value=value))

    known = {}
    assert param_event(ParameterEvent(node="/cam", new_parameters=[p("frame_rate", 5.0)]), 1.0, known) is None
    def set_(node, t, **values):
        return param_event(ParameterEvent(node=node, changed_parameters=[p(k, v) for k, v in values.items()]),
                           t, known)

    assert set_("/cam", 2.0, frame_rate=5.0) is None  # as declared
    ev = set_("/cam", 3.0, frame_rate=10.0, gain=2.0)
    assert ev.data == {"changed": {"frame_rate": "10.0", "gain": "2.0"}, "deleted": []}
    ev = set_("/cam", 4.0, frame_rate=10.0, gain=3.0)
    assert ev.data["changed"] == {"gain": "3.0"} and ev.text == "parameter of /cam: gain = 3.0"
    assert set_("/cam", 5.0, frame_rate=10.0) is None
    assert set_("/cam2", 6.0, frame_rate=10.0)  # another node's parameter of the same name is its own


def _triggered(t, shares, ages, gaps=None):
    """Three cameras on one trigger, each topic's ``stamp_partners`` from ``shares`` (pair -> share)
    and its age from ``ages`` (topic -> ms); ``gaps``: camera -> its ``gap_s``."""
    G = new_graph()
    for cam in ("left", "center", "right"):
        add_member(G, f"node:/{cam}", pid=100, alive=True)
        add_member(G, f"topic:/{cam}/image", theta=make_theta("topic", {
            "rate_hz": 5.0, "publishers": 1, "subscribers": 1, "age_s": 0.1, "stamp_age_ms": ages[cam],
            **({"gap_s": gaps[cam]} if gaps and cam in gaps else {})}),
            stamp_partners={f"topic:/{o}/image": shares[frozenset((cam, o))]
                            for o in ("left", "center", "right") if o != cam})
        add_flow_edge(G, f"node:/{cam}", f"topic:/{cam}/image", "pub")
    return (float(t), G, [])


def test_message_age_a_camera_whose_stamps_leave_its_trigger_group_is_out_of_sync():
    pairs = [frozenset(p) for p in (("left", "center"), ("left", "right"), ("center", "right"))]
    matched = dict.fromkeys(pairs, 1.0)
    moved = {**matched, pairs[1]: 0.0, pairs[2]: 0.0}  # the right camera's stamps 41 ms later
    same = {"left": 100.0, "center": 100.0, "right": 100.0}
    frames = [_triggered(t, matched, same) for t in range(10)]
    assert drive("message_age", frames) == []
    frames += [_triggered(t, moved, {**same, "right": 59.0}) for t in range(10, 15)]
    alerts = drive_alerts("message_age", frames)
    assert [(a.t, a.member) for a in alerts] == [(12.0, "topic:/right/image"), (13.0, "topic:/right/image"),
                                                 (14.0, "topic:/right/image")]
    assert alerts[0].data["symptom"] == "desync" and alerts[0].data["since"] == 9.0  # the last sample matched
    assert alerts[0].data["since_within"] == 1.0  # the first that saw them part: 10
    assert alerts[0].data["partners"] == ["topic:/left/image", "topic:/center/image"]
    assert alerts[0].data["shift_ms"] == pytest.approx(-41.0)
    # Before the partners were learnt (5 samples matching), nothing is lost.
    assert drive("message_age", frames[6:]) == []


def test_message_age_a_burst_that_takes_other_ticks_of_a_shared_clock_is_no_desync():
    # An arm controller's state (every other cycle from its trajectory's start) and the joint
    # states (every other cycle of the loop) share stamps in one pick, not in the next: each pick
    # is a burst after a pause, its partners learnt anew. Parting mid-burst is a desync.
    pairs = [frozenset(p) for p in (("left", "center"), ("left", "right"), ("center", "right"))]
    matched = dict.fromkeys(pairs, 1.0)
    moved = {**matched, pairs[1]: 0.0, pairs[2]: 0.0}
    same = {"left": 100.0, "center": 100.0, "right": 100.0}

    def run(paused_at):  # /right/image resumed after a 4 s pause at that sample
        return drive("message_age", [_triggered(t, matched if t < 10 else moved, same,
                                                {"right": 4.0} if t == paused_at else None)
                                     for t in range(15)])

    assert {m for _, m, _ in run(None)} == {"topic:/right/image"}
    assert run(10) == []
    assert run(11) == []  # seen a sample late: the streak not yet confirmed
    assert {m for _, m, _ in run(5)} == {"topic:/right/image"}  # a pause before they last matched


def test_message_age_of_a_pair_out_of_sync_the_one_whose_age_moved_is_charged():
    frames = [_triggered(t, {frozenset(("left", "right")): 1.0, frozenset(("left", "center")): 0.0,
                             frozenset(("center", "right")): 0.0}, dict(left=100.0, center=7.0, right=100.0))
              for t in range(10)]
    apart = {frozenset(("left", "right")): 0.0, frozenset(("left", "center")): 0.0,
             frozenset(("center", "right")): 0.0}
    moved = frames + [_triggered(t, apart, dict(left=100.0, center=7.0, right=59.0)) for t in range(10, 14)]
    assert {m for _, m, _ in drive("message_age", moved)} == {"topic:/right/image"}
    # Neither age moved: both are charged.
    both = frames + [_triggered(t, apart, dict(left=100.0, center=7.0, right=100.0)) for t in range(10, 14)]
    assert {m for _, m, _ in drive("message_age", both)} == {"topic:/right/image", "topic:/left/image"}


def test_a_line_names_a_topic_it_reads_in_full_or_relative_to_its_namespace():
    from stream_viz.detect.endpoints import named_topics

    topics = ["/usv/odometry/gps", "/usv/gps", "/scan", "/odometry/raw"]
    assert named_topics("Rejecting /usv/odometry/gps: jump 400012 m", topics, "/usv") == ["/usv/odometry/gps"]
    assert named_topics("Rejecting odometry/gps: jump", topics, "/usv") == ["/usv/odometry/gps"]
    assert named_topics("no gps fix", topics, "/usv") == ["/usv/gps"]  # relative, in a namespace
    assert named_topics("/usv/odometry/gps_raw late", topics, "/usv") == []  # part of a longer name
    # In the root namespace a bare word is any word; a relative name with a / is a name.
    assert named_topics("scan matching failed; odometry/raw late", topics, "/") == ["/odometry/raw"]


def test_an_error_naming_an_input_topic_charges_its_publisher_unless_it_receives_nothing():
    # /ekf reads /gps from /navsat and ERRORs about it: the RCA ranks /navsat first. With a
    # reliable subscription against the best-effort publisher it receives nothing: its own doing.
    def graph(sub_reliability):
        G = new_graph()
        for m in ("node:/navsat", "node:/ekf", "topic:/gps", "process:1", "process:2"):
            add_member(G, m)
        add_flow_edge(G, "node:/navsat", "topic:/gps", "pub")
        add_flow_edge(G, "topic:/gps", "node:/ekf", "sub")
        add_tree_edge(G, "process:1", "node:/navsat")
        add_tree_edge(G, "process:2", "node:/ekf")
        G.nodes["topic:/gps"]["qos"] = [
            {"node": "/navsat", "role": "pub", "reliability": "best_effort", "durability": "volatile"},
            {"node": "/ekf", "role": "sub", "reliability": sub_reliability, "durability": "volatile"}]
        return G

    line = Event(10.0, "log", "node:/ekf", "error", "Rejecting /gps: position jump 400012 m", {})
    for rel, named in (("best_effort", ["node:/navsat"]), ("reliable", None)):
        alerts = drive("rosout", [(10.5, graph(rel), [line])], full=True)
        assert alerts and alerts[0].data.get("names") == named, (rel, alerts)
