"""The report contract: reports the code builds validate against docs/report.schema.json, and the
schema is strict enough to reject a missing or mistyped field."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import jsonschema
import pytest

from stream_viz.demo.faults import FAULTS
from stream_viz.model.graph import FLOW_KINDS, add_flow_edge, add_member, add_tree_edge, new_graph
from stream_viz.model.ids import KINDS, ROOT
from stream_viz.rca import RcaSettings, analyze
from stream_viz.rca.settings import METHODS
from stream_viz.records import SEVERITIES, Alert
from stream_viz.report import SCHEMA, build_report, write_report

SCHEMA_FILE = Path(__file__).resolve().parents[2] / "docs" / "report.schema.json"
VALIDATOR = jsonschema.Draft202012Validator(json.loads(SCHEMA_FILE.read_text()))
CAM, DET, IMAGE, OBJECTS = "node:/cam", "node:/det", "topic:/image", "topic:/objects"


@pytest.fixture
def G():
    """cam (process 7) → /image → det → /objects; det calls cam's service; det has vanished."""
    g = new_graph()
    add_member(g, ROOT)
    add_member(g, "process:7", name="cam")
    add_member(g, CAM, pid=7)
    add_member(g, DET, pid=None, gone=True)
    for m in (IMAGE, OBJECTS, "service:/cam/set"):
        add_member(g, m)
    add_tree_edge(g, ROOT, "process:7")
    add_tree_edge(g, "process:7", CAM)
    add_flow_edge(g, CAM, IMAGE, "pub")
    add_flow_edge(g, IMAGE, DET, "sub")
    add_flow_edge(g, DET, OBJECTS, "pub")
    add_flow_edge(g, DET, CAM, "send", services=["service:/cam/set"])
    return g


ALERTS = [
    Alert(CAM, "member_gone", 100.0, "fatal", "process 7 exited"),
    Alert(IMAGE, "topic_rate", 101.0, "error", "silent for 1.5 s", {"value": 0.0}),
    Alert(OBJECTS, "topic_rate", 102.0, "warn", "rate dropped"),
]


def report(G, method: str = "trajectory", injected=None) -> dict:
    result = analyze(G, ALERTS, RcaSettings(method=method), None)
    return build_report(G, ALERTS, result.to_report(), 90.0, 110.0, injected)


@pytest.mark.parametrize("method", METHODS)
def test_a_report_of_every_method_is_valid_as_written(G, tmp_path, method):
    path = tmp_path / "r.json"
    write_report(path, report(G, method, {"fault": "crash", "target": CAM, "t": 99.5}))
    rep = json.loads(path.read_text())
    VALIDATOR.validate(rep)
    assert rep["schema"] == SCHEMA
    assert rep["members"][:2] == [{"id": CAM, "kind": "node", "pid": 7},
                                  {"id": DET, "kind": "node", "pid": None, "gone": True}]
    assert {"src": DET, "dst": CAM, "kind": "send"} in rep["edges"]
    assert [it["j"] for it in rep["iterations"]] == [0, 1, 2, 3]
    assert rep["root_causes"][0]["member"] == CAM


def test_a_report_without_alerts_or_injection_is_valid(G):
    rep = build_report(G, [], analyze(G, [], RcaSettings(), None).to_report(), 90.0, 91.0)
    VALIDATOR.validate(json.loads(json.dumps(rep)))
    assert "injected" not in rep and rep["root_causes"] == [] and len(rep["iterations"]) == 1


def test_a_report_lists_the_plugins_problems_not_unreadable_members(G):
    problems = [{"t": 90.5, "plugin": "raiser", "kind": "disabled", "where": None,
                 "message": "disabled after 3 failed calls in a row", "line": None, "count": 1},
                {"t": 90.6, "plugin": "", "kind": "unreadable", "where": "process:7",
                 "message": "access denied", "line": None, "count": 1}]
    rep = build_report(G, [], analyze(G, [], RcaSettings(), None).to_report(), 90.0, 91.0, None, problems)
    VALIDATOR.validate(json.loads(json.dumps(rep)))
    assert rep["problems"] == [{"t": 90.5, "plugin": "raiser", "kind": "disabled", "where": None,
                                "message": "disabled after 3 failed calls in a row", "count": 1}]
    rep["problems"][0]["count"] = 0
    with pytest.raises(jsonschema.ValidationError):
        VALIDATOR.validate(rep)


def _drop(key):
    return lambda r: r.pop(key)


def _set(path, value):
    def edit(r):
        *where, last = path
        for k in where:
            r = r[k]
        r[last] = value
    return edit


@pytest.mark.parametrize(("name", "edit"), [
    ("no schema", _drop("schema")),
    ("other schema version", _set(["schema"], "stream-viz.report/v1")),
    ("no incidents", _drop("incidents")),
    ("incident without ongoing", lambda r: r["incidents"][0].pop("ongoing")),
    ("incident id 0", _set(["incidents", 0, "id"], 0)),
    ("incident root cause a topic", _set(["incidents", 0, "root_causes", 0, "member"], IMAGE)),
    ("indistinguishable from a topic",
     _set(["root_causes", 0, "evidence", "indistinguishable_from"], [IMAGE])),
    ("no root_causes", _drop("root_causes")),
    ("unknown top-level key", _set(["extra"], 1)),
    ("started_at as text", _set(["started_at"], "90")),
    ("member without kind", lambda r: r["members"][0].pop("kind")),
    ("node without pid", lambda r: r["members"][0].pop("pid")),
    ("topic with a pid", _set(["members", 5, "pid"], 3)),
    ("malformed member id", _set(["members", 0, "id"], "cam")),
    ("unknown member kind", _set(["members", 0, "kind"], "robot")),
    ("unknown edge kind", _set(["edges", 0, "kind"], "call")),
    ("pub edge from a topic", _set(["edges", 0, "src"], IMAGE)),
    ("unknown severity", _set(["alerts", 0, "severity"], "critical")),
    ("alert time as text", _set(["alerts", 0, "t"], "100")),
    ("iteration without watchlist", lambda r: r["iterations"][1].pop("watchlist")),
    ("iteration edge of one member", _set(["iterations", 1, "edges"], [[CAM]])),
    ("score above 1", _set(["root_causes", 0, "score"], 1.5)),
    ("empty trajectory", _set(["root_causes", 0, "trajectory"], [])),
    ("a topic as root cause", _set(["root_causes", 0, "member"], IMAGE)),
    ("evidence without hypothesis", lambda r: r["root_causes"][0]["evidence"].pop("hypothesis")),
    ("unknown injected fault", _set(["injected", "fault"], "meltdown")),
])
def test_the_schema_rejects_a_missing_or_mistyped_field(G, name, edit):
    rep = json.loads(json.dumps(report(G, injected={"fault": "crash", "target": CAM, "t": 99.5})))
    VALIDATOR.validate(rep)
    bad = copy.deepcopy(rep)
    edit(bad)
    with pytest.raises(jsonschema.ValidationError):
        VALIDATOR.validate(bad)


def test_the_schema_names_the_codes_vocabulary():
    """Kinds, severities, edge kinds, faults and methods in the schema are the code's own."""
    defs = json.loads(SCHEMA_FILE.read_text())["$defs"]
    assert defs["kind"]["enum"] == list(KINDS)
    assert defs["severity"]["enum"] == list(SEVERITIES)
    assert defs["edge"]["properties"]["kind"]["enum"] == list(FLOW_KINDS)
    assert defs["injected"]["properties"]["fault"]["enum"] == list(FAULTS)
    assert set(defs["evidence"]["properties"]["method"]["enum"]) == set(METHODS) - {"trajectory"}


def test_incidents_in_the_report(G):
    old = [Alert(OBJECTS, "topic_rate", 10.0, "warn", "rate dropped")]  # long before: its own incident
    result = analyze(G, old + ALERTS, RcaSettings(), None)
    rep = json.loads(json.dumps(build_report(G, old + ALERTS, result.to_report(), 5.0, 110.0)))
    VALIDATOR.validate(rep)
    got = [(i["id"], i["members"], i["start"], i["end"], i["ongoing"], i["current"])
           for i in rep["incidents"]]
    assert got == [(1, [OBJECTS], 10.0, 10.0, False, False),
                   (2, [CAM, IMAGE, OBJECTS], 100.0, 102.0, True, True)]
    assert rep["incidents"][1]["root_causes"] == rep["root_causes"]
    assert rep["incidents"][0]["root_causes"][0]["member"] == DET


def test_nodes_that_cannot_be_told_apart_are_named_in_the_report(G):
    add_member(G, "node:/cam2", pid=7)
    add_tree_edge(G, "process:7", "node:/cam2")
    alerts = [Alert("process:7", "process_resources", 100.0, "warn", "cpu 100%")]
    rep = build_report(G, alerts, analyze(G, alerts, RcaSettings(), None).to_report(), 90.0, 110.0)
    VALIDATOR.validate(json.loads(json.dumps(rep)))
    ev = {rc["member"]: rc["evidence"] for rc in rep["root_causes"]}
    assert ev[CAM]["process"] == "process:7" and ev[CAM]["indistinguishable_from"] == ["node:/cam2"]


def test_a_report_carries_the_collectors_limits_only_when_there_are_some(G):
    result = analyze(G, [], RcaSettings(), None).to_report()
    limits = {"discovery of process 4242": "process 4242 (cam) has Fast DDS loaded …"}
    rep = build_report(G, [], result, 90.0, 91.0, None, (), limits)
    VALIDATOR.validate(json.loads(json.dumps(rep)))
    assert rep["collector_limits"] == limits
    assert "collector_limits" not in build_report(G, [], result, 90.0, 91.0, None, (), {})
    rep["collector_limits"] = {"x": 1}
    with pytest.raises(jsonschema.ValidationError):
        VALIDATOR.validate(rep)
