"""The viewer's report text (`/rca/report`): the current incident's root causes, the candidates it
cannot tell apart, and every incident."""

from __future__ import annotations

from stream_viz.model.graph import add_flow_edge, add_member, add_tree_edge, new_graph
from stream_viz.rca import RcaSettings, analyze
from stream_viz.records import Alert
from stream_viz.viz.rca import report_markdown

A, B, C, OUT = "node:/a", "node:/b", "node:/c", "topic:/out"


def test_report_lists_incidents_and_names_nodes_it_cannot_tell_apart():
    g = new_graph()
    for m in (A, B, C, OUT, "process:7", "process:8"):
        add_member(g, m)
    add_tree_edge(g, "process:7", A)
    add_tree_edge(g, "process:7", B)
    add_tree_edge(g, "process:8", C)
    add_flow_edge(g, C, OUT, "pub")
    alerts = [Alert(OUT, "topic_rate", 60.0, "warn", "rate dropped"),  # 00:01:00, over by 00:03:20
              Alert("process:7", "process_resources", 200.0, "warn", "cpu 100%")]
    rep = analyze(g, alerts, RcaSettings(), None).to_report()
    text = report_markdown(rep["root_causes"], rep["iterations"][-1], incidents=rep["incidents"])
    assert text.splitlines()[4:] == [
        "Root causes of incident 2 (since 00:03:20 UTC, ongoing, 1 symptomatic members); "
        "1 other incident(s) below.",
        "",
        "| rank | root cause | score | trajectory (first symptom → cause) |",
        "|---|---|---|---|",
        f"| 1 | **`{A}`** | {rep['root_causes'][0]['score']:.3f} | `{A}` |",
        f"| 2 | **`{B}`** | {rep['root_causes'][1]['score']:.3f} | `{B}` |",
        "",
        f"`{A}`, `{B}` run in `process:7` and changed alike: the symptoms cannot tell them apart "
        "(the fault is in that process).",
        "",
        "## Incidents (times UTC)",
        "",
        "| incident | symptomatic members | from | to | top root cause |",
        "|---|---|---|---|---|",
        f"| 1 | 1 | 00:01:00 | 00:01:00 | `{C}` |",
        f"| **2 (current)** | 1 | 00:03:20 | ongoing | `{A}` |",
    ]


def test_a_single_incident_reads_as_before():
    causes = [{"member": A, "score": 0.5, "trajectory": [OUT, A], "evidence": {}}]
    incidents = [{"id": 1, "members": [OUT], "start": 1.0, "end": 2.0, "ongoing": True, "current": True,
                  "root_causes": causes}]
    assert report_markdown(causes, None, incidents=incidents) == report_markdown(causes)
    assert report_markdown([]).endswith("No root cause found yet.")


def test_a_node_told_apart_by_a_waiting_client_says_so():
    causes = [{"member": A, "score": 0.4, "trajectory": [C, A],
               "evidence": {"process": "process:7", "awaited_by": [C]}},
              {"member": B, "score": 0.2, "trajectory": [B], "evidence": {"process": "process:7"}}]
    assert report_markdown(causes).splitlines()[-2:] == [
        "", f"`{A}` runs in `process:7` with other candidates; `{C}` waited on it as its symptoms began, "
        "which tells it from them."]


def test_the_likeliest_blocker_of_a_stalled_executor_says_so():
    causes = [{"member": n, "score": x, "trajectory": [n], "evidence": {"process": "process:7", "blocked": x}}
              for n, x in ((A, 0.84), (B, 0.16))]
    assert report_markdown(causes).splitlines()[-2:] == [
        "", f"`{A}` is the likeliest of `process:7`'s stalled nodes to have blocked its executor (84%): "
        "its next message was due as they stopped."]
    tied = [{**rc, "evidence": {**rc["evidence"], "indistinguishable_from": [B]}} for rc in causes[:1]]
    assert "blocked" not in report_markdown(tied).split("|---|")[-1]


def test_a_suspect_without_a_symptom_of_its_own_says_why():
    # A's output stops with process 7's one executor idle: B, its quiet fellow, is a suspect.
    g = new_graph()
    for m in (A, B, OUT, "process:7"):
        add_member(g, m)
    add_tree_edge(g, "process:7", A)
    add_tree_edge(g, "process:7", B)
    add_flow_edge(g, A, OUT, "pub")
    idle = {"executor_idle": True}
    alerts = [Alert(OUT, "topic_rate", 60.0 + k, "error", "silent", idle) for k in range(3)]
    rep = analyze(g, alerts, RcaSettings(), None).to_report()
    assert [(rc["member"], rc["evidence"].get("implied")) for rc in rep["root_causes"]] == [(A, None),
                                                                                            (B, "executor")]
    assert report_markdown(rep["root_causes"]).splitlines()[-2:] == [
        "", f"`{B}` shows nothing of its own; the executor it shares with `{A}` stopped, and a callback "
        "of any node it runs may have blocked it."]
    ev = {"symptoms": [A], "implied": "server"}
    server = [{"member": C, "score": 0.1, "trajectory": [C], "evidence": ev}]
    assert report_markdown(server).splitlines()[-1] == (
        f"`{C}` shows nothing of its own; it serves `{A}`, whose symptoms their inputs do not explain: "
        "it may be what they wait for.")
