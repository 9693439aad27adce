"""Plugin discovery, validation, the plugin set's policy, and isolation from deliberately broken plugins."""

from __future__ import annotations

import textwrap
import threading

import pytest

from stream_viz.detect.discovery import discover
from stream_viz.detect.plugin_set import PluginSet
from stream_viz.errors import ConfigError
from stream_viz.model.graph import add_member, new_graph
from stream_viz.model.history import History
from stream_viz.records import Alert

BUILTINS = ["diagnostics", "graph_anomalies", "host_state", "member_gone", "message_age", "process_resources",
            "qos_compat", "rosout", "services", "topic_latency", "topic_rate"]

GOOD = '''
from stream_viz.detect.api import Plugin

class Good(Plugin):
    name = "good"
    kinds = ("node",)
    settings = {"severity": "warn", "limit": 1.5}

    def check(self, ctx):
        for m in ctx.watched("node"):
            yield ctx.alert(m, ctx.settings["severity"], f"limit {ctx.settings['limit']}")
'''


def _write(folder, name, code):
    folder.mkdir(exist_ok=True)
    (folder / f"{name}.py").write_text(textwrap.dedent(code))


def _graph():
    G = new_graph()
    add_member(G, "node:/a")
    add_member(G, "node:/b")
    return G


def _run(ps, t=1.0, G=None):
    G = G if G is not None else _graph()
    return ps.run(t, G, G.nodes, History())


def test_builtins_come_from_entry_points_and_the_local_folder_is_not_a_duplicate(monkeypatch, tmp_path):
    found, problems, _ = discover(cwd_plugins=False)
    assert [n for _, n, _ in found] == BUILTINS
    assert problems == []
    assert all(w.endswith(f"plugins/{n}.py") for _, n, w in found)


def test_folder_plugin_runs_with_settings(tmp_path):
    _write(tmp_path / "p", "good", GOOD)
    ps = PluginSet.load([tmp_path / "p"], entry_points=False, cwd_plugins=False,
                        settings={"good": {"severity": "error", "limit": 2}})
    alerts, problems = _run(ps)
    assert problems == []
    assert alerts == [Alert("node:/a", "good", 1.0, "error", "limit 2.0"),
                      Alert("node:/b", "good", 1.0, "error", "limit 2.0")]
    ps.close()


def test_bad_settings_are_config_errors(tmp_path):
    _write(tmp_path / "p", "good", GOOD)
    with pytest.raises(ConfigError,
                       match=r"^cfg\.toml: \[plugins\.good\] unknown key 'limt' \(known: limit, severity\)$"):
        PluginSet.load([tmp_path / "p"], entry_points=False, cwd_plugins=False,
                       settings={"good": {"limt": 2.0}}, config_path="cfg.toml")
    with pytest.raises(ConfigError,
                       match=r'^the configuration: \[plugins\.good\] limit = "x": expected a number$'):
        PluginSet.load([tmp_path / "p"], entry_points=False, cwd_plugins=False,
                       settings={"good": {"limit": "x"}})
    with pytest.raises(ConfigError, match="no plugin named 'nope'"):
        PluginSet.load([tmp_path / "p"], entry_points=False, cwd_plugins=False, settings={"nope": {}})
    # A plugin switched off still has its settings checked.
    with pytest.raises(ConfigError, match=r"\[plugins\.good\] severity = 3: expected a string$"):
        PluginSet.load([tmp_path / "p"], entry_points=False, cwd_plugins=False, disable=["good"],
                       settings={"good": {"severity": 3}})


def test_enable_disable(tmp_path):
    ps = PluginSet.load(cwd_plugins=False, enable=["rosout", "topic_rate"], disable=["topic_rate", "ghost"])
    assert ps.names == ["rosout"]
    assert [(p.plugin, p.kind) for p in ps.load_problems] == [("ghost", "config")]


def test_import_and_validation_failures_are_reported_by_name_and_place(tmp_path):
    folder = tmp_path / "p"
    _write(folder, "good", GOOD)
    _write(folder, "broken_import", "import not_a_module_xyz\n")
    _write(folder, "broken_syntax", "def f(:\n")
    _write(folder, "bad_api", '''
        from stream_viz.detect.api import Plugin
        class Future(Plugin):
            name = "future"
            kinds = ("node",)
            api_version = 99
            def check(self, ctx):
                return []
        class NoKinds(Plugin):
            name = "nokinds"
            kinds = ("gizmo",)
            def check(self, ctx):
                return []
        class BadInit(Plugin):
            name = "badinit"
            kinds = ("node",)
            def __init__(self):
                raise RuntimeError("no init")
            def check(self, ctx):
                return []
    ''')
    _write(folder, "zz_dup", GOOD)  # sorted after good.py: good.py wins
    found, problems, failed = discover([folder], entry_points=False, cwd_plugins=False)
    assert [n for _, n, _ in found] == ["good"]
    by = {p.plugin: p for p in problems}
    assert set(by) == {"broken_import", "broken_syntax", "future", "nokinds", "badinit", "good"}
    assert by["broken_import"].kind == "import"
    assert "ModuleNotFoundError" in by["broken_import"].message
    assert by["broken_import"].line.startswith(str(folder / "broken_import.py") + ":1")
    assert by["broken_syntax"].kind == "import"
    assert by["broken_syntax"].line == f"{folder / 'broken_syntax.py'}:1"
    assert "API 99" in by["future"].message
    assert "kinds" in by["nokinds"].message
    assert "RuntimeError: no init" in by["badinit"].message and "bad_api.py:18" in by["badinit"].line
    assert by["good"].kind == "duplicate" and by["good"].where.endswith("zz_dup.py")
    assert {"broken_import", "broken_syntax", "future"} <= failed


def test_plugins_list_in_a_module(tmp_path):
    _write(tmp_path / "p", "listed", '''
        from stream_viz.detect.api import Plugin
        class _Base(Plugin):
            kinds = ("node",)
            def check(self, ctx):
                return [ctx.alert("node:/a", "info", self.name)]
        class One(_Base):
            name = "one"
        class Two(_Base):
            name = "two"
        PLUGINS = [Two, One()]
    ''')
    ps = PluginSet.load([tmp_path / "p"], entry_points=False, cwd_plugins=False)
    assert ps.names == ["two", "one"]
    alerts, _ = _run(ps)
    assert [a.message for a in alerts] == ["two", "one"]


RAISING = '''
from stream_viz.detect.api import Plugin
class Raising(Plugin):
    name = "raising"
    kinds = ("node",)
    def check(self, ctx):
        ctx.state["n"] = ctx.state.get("n", 0) + 1
        if ctx.state["n"] != 2:
            raise ValueError("bad luck")
        return [ctx.alert("node:/a", "warn", "ok")]
'''


def test_raising_plugin_is_reported_then_disabled_and_others_go_on(tmp_path):
    folder = tmp_path / "p"
    _write(folder, "good", GOOD)
    _write(folder, "raising", RAISING)
    ps = PluginSet.load([folder], entry_points=False, cwd_plugins=False, max_failures=3)
    kinds = []
    for t in range(6):
        alerts, problems = _run(ps, t=float(t))
        assert [a.plugin for a in alerts].count("good") == 2  # the good one always goes on
        kinds.append([p.kind for p in problems])
        if problems:
            assert problems[0].plugin == "raising" and problems[0].message == "ValueError: bad luck"
            assert problems[0].line.endswith("raising.py:9 in check")
    # call 1 fails, call 2 works (resets), calls 3, 4, 5 fail -> disabled; then skipped
    assert kinds == [["run"], [], ["run"], ["run"], ["run", "disabled"], []]
    assert ps.names == ["good"]


def test_garbage_is_dropped_and_counted(tmp_path):
    _write(tmp_path / "p", "garbage", '''
        from stream_viz.detect.api import Plugin
        from stream_viz.records import Alert
        class Garbage(Plugin):
            name = "garbage"
            kinds = ("node",)
            def check(self, ctx):
                return [
                    ctx.alert("node:/a", "warn", "fine"),
                    "not an alert",
                    ctx.alert("node:/ghost", "warn", "unknown member"),
                    ctx.alert("node:/a", "catastrophic", "unknown severity"),
                    Alert("node:/b", "someone_else", ctx.t, "info", "renamed"),
                    None,
                ]
    ''')
    ps = PluginSet.load([tmp_path / "p"], entry_points=False, cwd_plugins=False)
    alerts, problems = _run(ps)
    assert alerts == [Alert("node:/a", "garbage", 1.0, "warn", "fine"),
                      Alert("node:/b", "garbage", 1.0, "info", "renamed")]
    assert len(problems) == 1 and problems[0].kind == "garbage" and problems[0].count == 4
    assert "unknown member 'node:/ghost'" in problems[0].message
    assert "unknown severity 'catastrophic'" in problems[0].message


def test_flood_is_truncated_and_counted(tmp_path):
    _write(tmp_path / "p", "flood", '''
        from stream_viz.detect.api import Plugin
        class Flood(Plugin):
            name = "flood"
            kinds = ("node",)
            def check(self, ctx):
                return [ctx.alert("node:/a", "info", str(i)) for i in range(250)]
        class Endless(Plugin):
            name = "endless"
            kinds = ("node",)
            def check(self, ctx):
                while True:
                    yield ctx.alert("node:/b", "info", "again")
    ''')
    ps = PluginSet.load([tmp_path / "p"], entry_points=False, cwd_plugins=False, max_alerts_per_call=100)
    alerts, problems = _run(ps)
    assert [a.message for a in alerts if a.plugin == "flood"] == [str(i) for i in range(100)]
    assert sum(a.plugin == "endless" for a in alerts) == 100
    by = {p.plugin: p for p in problems}
    assert by["flood"].kind == "flood" and by["flood"].count == 150
    assert by["endless"].kind == "flood" and "dropped 900+" in by["endless"].message


def test_hanging_plugin_is_cut_off_then_disabled(tmp_path):
    folder = tmp_path / "p"
    _write(folder, "good", GOOD)
    _write(folder, "hang", '''
        import threading
        from stream_viz.detect.api import Plugin
        RELEASE = threading.Event()
        class Hang(Plugin):
            name = "hang"
            kinds = ("node",)
            def check(self, ctx):
                RELEASE.wait()
                return []
    ''')
    ps = PluginSet.load([folder], entry_points=False, cwd_plugins=False, timeout_s=0.5, max_failures=3)
    seen = []
    for t in range(4):
        alerts, problems = _run(ps, t=float(t))
        assert sum(a.plugin == "good" for a in alerts) == 2
        seen.append([(p.kind, p.message.split(";")[0]) for p in problems])
    assert seen[0] == [("timeout", "took longer than 0.5 s")]
    assert seen[1] == [("timeout", "still running its call from t=0.000")]
    assert seen[2][0][0] == "timeout" and seen[2][1][0] == "disabled"
    assert seen[3] == []
    assert ps.names == ["good"]
    # The abandoned thread ends once its call returns.
    import sys

    mod = next(m for n, m in sys.modules.items() if n.endswith(".hang"))
    mod.RELEASE.set()
    ps.close()
    hung = [th for th in threading.enumerate() if th.name == "stream-viz-plugin-hang"]
    for th in hung:
        th.join(2)
    assert not any(th.is_alive() for th in hung)


def test_inline_mode_gives_the_same_alerts(tmp_path):
    _write(tmp_path / "p", "good", GOOD)
    a = PluginSet.load([tmp_path / "p"], entry_points=False, cwd_plugins=False)
    b = PluginSet.load([tmp_path / "p"], entry_points=False, cwd_plugins=False, isolate=False)
    assert _run(a) == _run(b)


def test_the_documented_example_plugin_works(tmp_path):
    from pathlib import Path

    from stream_viz.model.theta import make_theta

    doc = (Path(__file__).parents[2] / "docs" / "plugins.md").read_text()
    code = doc.split("```python\n", 1)[1].split("```", 1)[0]
    _write(tmp_path / "my_plugins", "cpu_ceiling", code)
    ps = PluginSet.load([tmp_path / "my_plugins"], entry_points=False, cwd_plugins=False,
                        settings={"cpu_ceiling": {"ceiling": 50}})
    G = new_graph()
    add_member(G, "process:1", theta=make_theta("process", {"cpu_percent": 70.0}))
    add_member(G, "process:2", theta=make_theta("process", {"cpu_percent": 10.0}))
    alerts, problems = ps.run(3.0, G, G.nodes, History())
    assert problems == []
    assert alerts == [Alert("process:1", "cpu_ceiling", 3.0, "warn", "cpu 70%", {"cpu": 70.0})]


def test_declared_kinds_are_what_the_context_yields(tmp_path):
    _write(tmp_path / "p", "kinds", '''
        from stream_viz.detect.api import Plugin
        class Declared(Plugin):
            name = "declared"
            kinds = ("topic", "node")
            def check(self, ctx):
                return [ctx.alert(m, "info", "seen") for m in ctx.watched()]
        class Undeclared(Plugin):
            name = "undeclared"
            kinds = ("topic",)
            def check(self, ctx):
                return [ctx.alert(m, "info", "seen") for m in ctx.watched("node")]
    ''')
    ps = PluginSet.load([tmp_path / "p"], entry_points=False, cwd_plugins=False)
    G = _graph()
    add_member(G, "topic:/t")
    alerts, problems = ps.run(1.0, G, G.nodes, History())
    assert [a.member for a in alerts] == ["topic:/t", "node:/a", "node:/b"]
    assert [(p.plugin, p.kind) for p in problems] == [("undeclared", "run")]
    assert "declares kinds = ('topic',); add 'node'" in problems[0].message
    ps.close()


def test_settings_the_helpers_read_are_checked_at_load(tmp_path):
    folder = tmp_path / "p"
    _write(folder, "good", GOOD)
    _write(folder, "risen", '''
        from stream_viz.detect.api import Plugin
        from stream_viz.detect.baseline import BASELINE_SETTINGS, rise

        class Risen(Plugin):
            name = "risen"
            kinds = ("node",)
            uses = (rise,)
            settings = {**BASELINE_SETTINGS, "k": 5.0}  # no "confirm", which rise reads

            def check(self, ctx):
                return []

        class Whole(Plugin):
            name = "whole"
            kinds = ("node",)
            uses = (rise,)
            settings = {**BASELINE_SETTINGS, "k": 5.0, "confirm": 2}

            def check(self, ctx):
                return [ctx.alert("node:/a", "info", str(ctx.settings["confirm"]))]

        class NotHelpers(Plugin):
            name = "not_helpers"
            kinds = ("node",)
            uses = "rise"

            def check(self, ctx):
                return []
    ''')
    ps = PluginSet.load([folder], entry_points=False, cwd_plugins=False)
    assert ps.names == ["good", "whole"]
    by = {p.plugin: p for p in ps.load_problems}
    assert set(by) == {"risen", "not_helpers"}
    assert by["risen"].kind == "validate" and by["risen"].where == str(folder / "risen.py")
    assert by["risen"].message == ("settings lack 'confirm', read by stream_viz.detect.baseline.rise "
                                   "(listed in uses): add defaults for them")
    assert str(by["risen"]).startswith(f"plugin 'risen' ({folder / 'risen.py'}): validate: "
                                       "settings lack 'confirm'")
    assert "uses must be a tuple of helper functions" in by["not_helpers"].message
    alerts, problems = _run(ps)
    assert problems == []
    assert [(a.plugin, a.message) for a in alerts if a.plugin == "whole"] == [("whole", "2")]
    ps.close()


def test_the_builtins_declare_the_settings_their_helpers_read():
    from stream_viz.detect.api import missing_settings

    found, _, _ = discover(cwd_plugins=False)
    uses = {n: [h.__name__ for h in type(p).uses] for p, n, _ in found if type(p).uses}
    assert uses == {"process_resources": ["symptoms"], "topic_latency": ["excess", "confirm"],
                    "topic_rate": ["cached_baseline"], "message_age": ["excess", "confirm"],
                    "services": ["cached_baseline", "rise"]}
    assert all(missing_settings(type(p)) == {} for p, _, _ in found)


def test_the_documented_helper_example_works(tmp_path):
    from pathlib import Path

    from stream_viz.detect.api import record_history
    from stream_viz.model.graph import add_tree_edge
    from stream_viz.model.theta import make_theta

    doc = (Path(__file__).parents[2] / "docs" / "plugins.md").read_text()
    code = doc.split("```python\n")[2].split("```", 1)[0]
    assert "class ThreadRise" in code
    _write(tmp_path / "my_plugins", "thread_rise", code)
    ps = PluginSet.load([tmp_path / "my_plugins"], entry_points=False, cwd_plugins=False)
    assert ps.load_problems == []
    G = new_graph()
    add_member(G, "process:1")
    add_member(G, "node:/a")
    add_tree_edge(G, "process:1", "node:/a")
    hist, seen = History(), []
    for t in range(16):
        G.nodes["process:1"]["theta"] = make_theta("process", {"threads": 4.0 if t < 13 else 40.0})
        record_history(hist, G, float(t))
        alerts, problems = ps.run(float(t), G, G.nodes, hist)
        assert problems == []
        seen += [(a.t, a.member, a.message) for a in alerts]
    # 13 samples of 4 threads (past the 10 s warm-up), then 40: confirmed on the second sample.
    assert seen == [(14.0, "node:/a", "40 threads, normally 4"), (15.0, "node:/a", "40 threads, normally 4")]
    ps.close()


LEARNING = '''
from stream_viz.detect.api import Plugin

class Learning(Plugin):
    name = "learning"
    kinds = ("node",)

    def check(self, ctx):
        seen = ctx.learned.setdefault("seen", [])
        if ctx.t not in seen:
            seen.append(ctx.t)
        if len(seen) > 2:  # what this run adds is not what it started from
            yield ctx.alert("node:/a", "info", f"seen {seen}, started from {ctx.primed.get('seen')}")
'''

UNJSON = '''
from stream_viz.detect.api import Plugin

class Unjson(Plugin):
    name = "unjson"
    kinds = ("node",)

    def check(self, ctx):
        ctx.learned["when"] = {1.0, 2.0}
        return []
'''


def test_what_a_plugin_learned_is_carried_to_a_later_run_and_only_as_json(tmp_path):
    folder = tmp_path / "p"
    _write(folder, "learning", LEARNING)
    _write(folder, "unjson", UNJSON)
    first = PluginSet.load([folder], entry_points=False, cwd_plugins=False)
    _run(first, t=1.0)
    _run(first, t=2.0)
    learned, problems = first.learned(t=2.0)
    first.close()
    assert learned == {"learning": {"seen": [1.0, 2.0]}}
    assert [(p.plugin, p.kind) for p in problems] == [("unjson", "garbage")]
    later = PluginSet.load([folder], entry_points=False, cwd_plugins=False)
    assert later.prime({**learned, "unjson": "not a mapping", "gone": {"x": 1}}) == ["learning"]
    alerts, _ = _run(later, t=3.0)
    assert [a.message for a in alerts] == ["seen [1.0, 2.0, 3.0], started from [1.0, 2.0]"]
    with pytest.raises(TypeError):  # read-only for the plugin
        later.plugins[0].primed["seen"] = []
    learned["learning"]["seen"].append(99.0)  # primed with a copy: the source is not shared
    assert later.learned()[0] == {"learning": {"seen": [1.0, 2.0, 3.0]}}
    later.close()
