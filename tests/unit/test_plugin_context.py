"""The plugin context: watched members of the declared kinds, and the graph questions it answers."""

from __future__ import annotations

import pytest

from stream_viz.detect.api import PluginContext
from stream_viz.errors import PluginError
from stream_viz.model.graph import add_flow_edge, add_member, add_tree_edge, new_graph
from stream_viz.model.history import History


def _graph():
    """camera (pid 1) -pub-> /img -sub-> detector (pid 2, by pid only); /get_map served by /map."""
    G = new_graph()
    add_member(G, "process:1", pid=1)
    add_member(G, "process:2", pid=2)
    add_member(G, "node:/camera", pid=1, alive=True, instances=2)
    add_member(G, "node:/detector", pid=2, alive=False)
    add_member(G, "node:/map")
    add_member(G, "topic:/img")
    add_member(G, "service:/get_map", servers=["/map"], clients=["/detector"])
    add_flow_edge(G, "node:/camera", "topic:/img", "pub", qos={"reliability": "reliable"})
    add_flow_edge(G, "topic:/img", "node:/detector", "sub")
    add_tree_edge(G, "process:1", "node:/camera")
    return G


def _ctx(watch, kinds=()):
    return PluginContext(1.0, _graph(), frozenset(watch), History(), plugin="p", kinds=kinds)


def test_watched_yields_the_declared_kinds_without_an_argument():
    ctx = _ctx({"process:2", "node:/detector", "node:/camera", "topic:/img", "node:/gone"},
               kinds=("process", "node"))
    assert list(ctx.watched()) == ["process:2", "node:/camera", "node:/detector"]
    assert list(ctx.watched("node")) == ["node:/camera", "node:/detector"]
    with pytest.raises(PluginError, match=r"plugin 'p' asked for watched 'topic' members but declares "
                                          r"kinds = \('process', 'node'\); add 'topic'"):
        list(ctx.watched("topic"))
    # A context made without kinds (a test's, a bench's) answers any kind.
    assert list(_ctx({"topic:/img"}).watched("topic")) == ["topic:/img"]


def test_graph_questions():
    ctx = _ctx(())
    assert ctx.nodes_of("process:1") == ["node:/camera"]
    assert ctx.nodes_of("process:2") == []
    assert ctx.nodes_of("process:2", by_pid=True) == ["node:/detector"]
    assert ctx.process_of("node:/camera") == "process:1"
    assert ctx.process_of("node:/detector") == "process:2"  # from its pid
    assert ctx.process_of("node:/map") is None
    assert ctx.publishers("topic:/img") == ["node:/camera"]
    assert ctx.subscribers("topic:/img") == ["node:/detector"]
    assert ctx.published_topics("node:/camera") == ["topic:/img"]
    assert ctx.subscribed_topics("node:/detector") == ["topic:/img"]
    assert ctx.servers("service:/get_map") == ["node:/map"]
    assert ctx.clients("service:/get_map") == ["node:/detector"]
    assert ctx.publishers("topic:/nothing") == [] and ctx.nodes_of("process:9") == []


def test_members_attributes_and_edges():
    ctx = _ctx(())
    assert list(ctx.members("node")) == ["node:/camera", "node:/detector", "node:/map"]
    assert ctx.kind("process:7") == "process"  # from the id: also for a member gone from the graph
    assert ctx.attr("node:/camera", "instances") == 2
    assert ctx.attr("node:/detector", "alive") is False
    assert ctx.attr("node:/map", "alive", "?") == "?" and ctx.attr("node:/nope", "alive") is None
    assert ctx.flow_edge("node:/camera", "topic:/img")["qos"] == {"reliability": "reliable"}
    assert ctx.flow_edge("topic:/img", "node:/camera") == {}


def test_what_plugins_keep_between_calls():
    from stream_viz.model.diff import GraphDiff

    G, state, calls = _graph(), {}, []

    def ctx(t, watch=("topic:/img",), diff=None):
        return PluginContext(t, G, frozenset(watch), History(), diff=diff or GraphDiff(), state=state,
                             plugin="p")

    def compute():
        calls.append(1)
        return len(calls)

    c = ctx(1.0)
    assert c.since_last_call() == float("inf") and ctx(1.5).since_last_call() == 0.5
    assert ctx(2.0).structural(compute, 10.0) == 1
    assert ctx(3.0).structural(compute, 10.0) == 1  # same graph and watchlist: cached
    assert ctx(4.0, watch=("node:/camera",)).structural(compute, 10.0) == 2  # watchlist changed
    assert ctx(5.0, watch=("node:/camera",), diff=GraphDiff(frozenset({"node:/x"}))).structural(
        compute, 10.0) == 3  # the graph changed
    assert ctx(16.0, watch=("node:/camera",)).structural(compute, 10.0) == 4  # recheck_s passed
    # another analysis of the same plugin is kept apart, and both stay cached
    assert ctx(17.0, watch=("node:/camera",)).structural(lambda: "other", key="b") == "other"
    assert ctx(18.0, watch=("node:/camera",)).structural(compute, 10.0) == 4
    assert c.topic_ids(["/a", "topic:/b"]) == {"topic:/a", "topic:/b"}
