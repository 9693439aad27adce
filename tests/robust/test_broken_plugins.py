"""Broken user plugins through the real ``stream-viz monitor``: isolated, named, the run goes on.

The pure parts (each failure kind, disabling, the flood cap) are in tests/unit/test_plugin_set.py;
here one real monitor run loads a folder with every kind of broken plugin next to a good one.
"""

from __future__ import annotations

import pytest

from stream_viz.testing import TALKER, wait_for
from tests.robust.common import db_rows, monitor_cmd, report

HEAD = """
from __future__ import annotations
import time
from stream_viz.detect.api import Plugin
from stream_viz.records import Alert
"""

PLUGINS = {
    "broken_import.py": "raise RuntimeError('boom while importing')\n",
    "good.py": HEAD + """
class Good(Plugin):
    name = "good"
    kinds = ("node",)
    def check(self, ctx):
        if "node:/talker" in ctx.graph:
            yield ctx.alert("node:/talker", "warn", "the good plugin sees the talker")
""",
    "raiser.py": HEAD + """
class Raiser(Plugin):
    name = "raiser"
    kinds = ("node",)
    def check(self, ctx):
        raise ZeroDivisionError("raised on every call")
""",
    "garbage.py": HEAD + """
class Garbage(Plugin):
    name = "garbage"
    kinds = ("node",)
    def check(self, ctx):
        return [42, "text", None, Alert("node:/no_such_node", "garbage", ctx.t, "error", "x"),
                Alert("node:/talker", "garbage", ctx.t, "catastrophic", "x"),
                Alert("node:/talker", "garbage", float("nan"), "error", "x")]
""",
    "hang.py": HEAD + """
class Hang(Plugin):
    name = "hang"
    kinds = ("node",)
    def check(self, ctx):
        time.sleep(3600)
        return []
""",
    "flood.py": HEAD + """
class Flood(Plugin):
    name = "flood"
    kinds = ("node",)
    def check(self, ctx):
        members = sorted(ctx.graph.nodes) or ["root"]
        return [ctx.alert(members[i % len(members)], "info", f"flood {i}") for i in range(5000)]
""",
}


@pytest.mark.ros
def test_monitor_with_broken_plugins_exits_0_keeps_good_alerts_and_records_problems(children, tmp_path):
    folder = tmp_path / "myplugins"
    folder.mkdir()
    for name, code in PLUGINS.items():
        (folder / name).write_text(code)
    cfg = tmp_path / "cfg.toml"
    cfg.write_text(f'[plugins]\npaths = ["{folder}"]\n')
    children.python(TALKER, name="talker")
    rep, db = tmp_path / "r.json", tmp_path / "a.sqlite"
    p = children.run(monitor_cmd("--config", str(cfg), "--db", str(db), "--report", str(rep),
                                 "--duration", "14"), name="monitor")
    # Not a fixed wait: it ends on --duration; this only bounds a hung monitor.
    wait_for(lambda: p.poll() is not None, timeout=120, period=0.5)
    log = (tmp_path / "monitor_1.log").read_text()
    assert p.returncode == 0, log
    assert "Traceback" not in log

    r = report(rep)
    good = [a for a in r["alerts"] if a["plugin"] == "good"]
    assert good and all(a["member"] == "node:/talker" for a in good)
    assert not any(a["plugin"] in ("garbage", "raiser", "hang") for a in r["alerts"])

    problems = db_rows(db, "SELECT plugin, kind, message, count FROM problems WHERE kind != 'unreadable'")
    kinds: dict[str, set[str]] = {}
    for plugin, kind, _, _ in problems:
        kinds.setdefault(plugin, set()).add(kind)
    assert "import" in kinds["broken_import"]
    assert any("boom while importing" in m for pl, _, m, _ in problems if pl == "broken_import")
    assert {"run", "disabled"} <= kinds["raiser"]
    assert any("ZeroDivisionError" in m for pl, _, m, _ in problems if pl == "raiser")
    assert "timeout" in kinds["hang"] and "disabled" in kinds["hang"]
    assert "garbage" in kinds["garbage"]
    garbage_msgs = " ".join(m for pl, _, m, _ in problems if pl == "garbage")
    for why in ("not an Alert", "unknown member 'node:/no_such_node'", "unknown severity", "bad time"):
        assert why in garbage_msgs
    # The flood is cut at 200 per call, and the cut is counted, not silent.
    flood = [(m, c) for pl, k, m, c in problems if pl == "flood" and k == "flood"]
    assert flood and all(c == 4800 for _, c in flood)
    stored = db_rows(db, "SELECT count(*) FROM alerts WHERE plugin = 'flood'")[0][0]
    assert 0 < stored <= 200 * len(flood)
    # And the report lists them: a reader knows which plugins failed or were disabled.
    reported = {(x["plugin"], x["kind"]) for x in r["problems"]}
    assert {("broken_import", "import"), ("raiser", "disabled"), ("hang", "timeout")} <= reported, reported
    # The problems were said on the terminal too, by name.
    for name in ("broken_import", "raiser", "hang", "garbage", "flood"):
        assert f"plugin {name!r}" in log
