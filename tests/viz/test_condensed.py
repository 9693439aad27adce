"""The condensed system graph (`stream_viz.viz.condensed`): the pure condensing on a tiny literal
graph, and real recordings read back from their .rrd."""

from __future__ import annotations

import itertools
from pathlib import Path

import networkx as nx
import pytest
from rerun.chunk import RrdReader

from stream_viz.model import add_flow_edge, add_member, add_tree_edge, new_graph
from stream_viz.model.ids import ROOT
from stream_viz.records import Alert
from stream_viz.viz import paths
from stream_viz.viz.condensed import (
    Condensed,
    condense,
    condense_groups,
    focus_members,
    group_label,
    is_condensed,
    with_neighbours,
)
from stream_viz.viz.layout import display_members
from stream_viz.viz.recorder import Recorder
from tests.viz.rrd import rows, shown, strings

T0 = 1_700_000_000.0


def two_namespaces() -> nx.MultiDiGraph:
    """/a/cam -> /a/image -> /a/det -> /a/objects -> /b/plan -> /b/cmd -> /b/ctrl, and four flat
    nodes in two processes both called python3: /mon -> /status -> /x1, /x2 -> /status2 -> /logger."""
    G = new_graph()
    add_member(G, ROOT)
    chain = ["node:/a/cam", "topic:/a/image", "node:/a/det", "topic:/a/objects", "node:/b/plan",
             "topic:/b/cmd", "node:/b/ctrl"]
    flat = ["node:/mon", "topic:/status", "node:/x1", "node:/x2", "topic:/status2", "node:/logger"]
    for m in chain + flat:
        add_member(G, m)
    edges = [*itertools.pairwise(chain), ("node:/mon", "topic:/status"), ("topic:/status", "node:/x1"),
             ("node:/x2", "topic:/status2"), ("topic:/status2", "node:/logger")]
    for u, v in edges:
        add_flow_edge(G, u, v, "pub" if u.startswith("node:") else "sub")
    hosted = [(10, "vision", ["node:/a/cam", "node:/a/det"]), (11, "nav", ["node:/b/plan", "node:/b/ctrl"]),
              (12, "python3", ["node:/mon", "node:/logger"]), (13, "python3", ["node:/x1", "node:/x2"])]
    for pid, name, nodes in hosted:
        add_member(G, f"process:{pid}", name=name)
        add_tree_edge(G, ROOT, f"process:{pid}")
        for n in nodes:
            add_tree_edge(G, f"process:{pid}", n)
    return G


GROUPS = {"node:/a/cam": "/a", "topic:/a/image": "/a", "node:/a/det": "/a", "topic:/a/objects": "/a",
          "node:/b/plan": "/b", "topic:/b/cmd": "/b", "node:/b/ctrl": "/b",
          "node:/mon": "python3 12", "node:/logger": "python3 12",
          "node:/x1": "python3 13", "node:/x2": "python3 13"}


def test_groups_are_namespaces_else_processes_and_a_topic_between_groups_has_none():
    G = two_namespaces()
    assert condense_groups(G, display_members(G), "namespace") == GROUPS
    # Under --group-by process every node goes by its process; /a/image and /a/objects stay
    # inside vision, /b/cmd inside nav, /a/objects links vision and nav: no group.
    assert condense_groups(G, display_members(G), "process") == {
        "node:/a/cam": "vision", "topic:/a/image": "vision", "node:/a/det": "vision",
        "node:/b/plan": "nav", "topic:/b/cmd": "nav", "node:/b/ctrl": "nav",
        "node:/mon": "python3 12", "node:/logger": "python3 12",
        "node:/x1": "python3 13", "node:/x2": "python3 13"}


def test_without_a_focus_each_group_is_one_disc_and_edges_are_one_per_group_pair():
    G = two_namespaces()
    assert condense(G, GROUPS, set()) == Condensed(
        members=[],
        groups={"group:/a": ("/a", 2, 2), "group:/b": ("/b", 2, 2),
                "group:python3 12": ("python3 12", 2, 2), "group:python3 13": ("python3 13", 2, 2)},
        # /status and /status2 link two groups: gone, replaced by publisher group -> subscriber group
        edges=[("group:/a", "group:/b"), ("group:python3 12", "group:python3 13"),
               ("group:python3 13", "group:python3 12")])


def test_the_focus_and_its_neighbours_are_drawn_in_full_the_rest_of_their_group_stays_one_disc():
    G = two_namespaces()
    full = with_neighbours(G, {"node:/a/det"})
    assert full == {"node:/a/det", "topic:/a/image", "topic:/a/objects"}
    c = condense(G, GROUPS, full | {"topic:/status"})
    assert c.members == ["node:/a/det", "topic:/a/image", "topic:/a/objects", "topic:/status"]
    assert c.groups["group:/a"] == ("/a", 1, 2)  # /a/cam is left in the disc
    assert c.edges == [("group:/a", "topic:/a/image"), ("group:python3 12", "topic:/status"),
                       ("group:python3 13", "group:python3 12"), ("node:/a/det", "topic:/a/objects"),
                       ("topic:/a/image", "node:/a/det"), ("topic:/a/objects", "group:/b"),
                       ("topic:/status", "group:python3 13")]
    assert group_label("/a", 1, 2) == "/a (1 of 2 nodes)"
    assert group_label("/b", 2, 2) == "/b (2 nodes)"


def test_the_focus_is_alerted_gone_and_diagnosed_members_an_alerted_process_its_nodes():
    G = two_namespaces()
    causes = [{"member": "node:/b/plan", "trajectory": ["topic:/b/cmd", "node:/b/plan"]}]
    assert focus_members(G, {"process:13": "error", "topic:/a/image": "warn", "host:x": "error"}, causes,
                         {"node:/mon"}) == {"node:/x1", "node:/x2", "topic:/a/image", "node:/mon",
                                            "topic:/b/cmd", "node:/b/plan"}


def test_the_mode_decides_above_the_threshold():
    assert [is_condensed("auto", n, 300) for n in (300, 301)] == [False, True]
    assert is_condensed("on", 5) and not is_condensed("off", 5000)
    with pytest.raises(ValueError):
        is_condensed("maybe", 5)


def test_a_recording_holds_the_condensed_graph_and_its_tab(tmp_path: Path):
    G = two_namespaces()
    path = tmp_path / "c.rrd"
    with Recorder(save=path, condensed="on") as rec:
        rec.system(G, T0)
        rec.alerts([Alert(t=T0 + 1, member="topic:/a/image", plugin="topic_rate", severity="error",
                          message="rate 0")])
        rec.system(G, T0 + 1)
    r = rows(path)
    ids = shown(r[paths.CONDENSED])["GraphNodes:node_ids"]
    labels = dict(zip(ids, shown(r[paths.CONDENSED])["GraphNodes:labels"], strict=True))
    # the alerted topic in full; its group /a still holds both nodes; the others condensed
    assert labels["topic:/a/image"] == "/a/image"
    assert labels["group:/a"] == "/a (2 nodes)" and labels["group:/b"] == "/b (2 nodes)"
    assert "node:/a/cam" not in ids
    # the layout was sent again with the condensed tab (the store order is not fixed)
    assert any("Condensed system graph" in strings(path, bp) for bp in RrdReader(str(path)).blueprints())


def test_a_replayed_generated_system_with_a_crash_condenses_all_but_the_diagnosis(tmp_path: Path):
    """200 nodes in 4 namespaces (~370 members: above the default 300), a process crashes; the
    real monitor replays it and writes the .rrd, read back here."""
    from bench.shot_condensed import record
    from stream_viz.collect.replay import ReplayCollector
    from stream_viz.commands.replay import PLUGIN_TIMEOUT_S, replay_config
    from stream_viz.demo.generated import namespace_names
    from stream_viz.monitor import Monitor

    record(200, 4, 45, 15, tmp_path / "s.jsonl.gz")
    source = ReplayCollector(tmp_path / "s.jsonl.gz")
    mon = Monitor(replay_config(None, source.header), db=tmp_path / "a.sqlite", save=tmp_path / "r.rrd",
                  collector=source, started_at=source.header.get("started_at"),
                  plugin_timeout_s=PLUGIN_TIMEOUT_S)
    while not source.done:
        mon.step()
    report = mon.close()
    end = shown(rows(tmp_path / "r.rrd")[paths.CONDENSED])
    ids, labels = end["GraphNodes:node_ids"], end["GraphNodes:labels"]
    groups = {i for i in ids if i.startswith("group:")}
    assert {f"group:{ns}" for ns in namespace_names(4)} <= groups
    assert len(ids) < 0.3 * len({m for m in mon.seen if m.split(":")[0] in ("node", "topic", "service")})
    # every alerted member and the top root cause are drawn in full
    alerted = {a["member"] for a in report["alerts"] if a["severity"] in ("warn", "error", "fatal")
               and a["member"].split(":")[0] in ("node", "topic")}
    assert alerted and alerted <= set(ids)
    assert report["root_causes"][0]["member"] in ids
    assert all("nodes)" in label or "(topics)" in label for i, label in zip(ids, labels, strict=True)
               if i in groups)
