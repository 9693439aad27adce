"""The TOML configuration: values, defaults, and every error naming the key and the file."""

from __future__ import annotations

import re
import textwrap

import pytest

from stream_viz.config import Config, load_config
from stream_viz.detect.plugin_set import PluginSet
from stream_viz.errors import ConfigError

FULL = """
[monitor]
period = 0.5
topic_metrics = false
history = 120

[watchlist]
mode = "config"
members = ["node:/camera*", "/planner"]

[rca]
policy = "upstream"

[plugins]
disable = ["graph_anomalies"]
paths = ["my_plugins"]

[plugins.topic_rate]
drop_ratio = 0.3
confirm = 3

[topics."/camera/image"]
expected_rate_hz = 30

[topics."scan"]
expected_rate_hz = 10.5
"""


def _cfg(tmp_path, text, name="stream.toml"):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def test_defaults():
    c = load_config(None)
    assert c.path is None
    assert (c.monitor.period, c.monitor.topic_metrics, c.monitor.history) == (1.0, True, 600)
    assert (c.watchlist.mode, c.watchlist.members) == ("auto", ())
    assert c.plugins.enable == () and c.plugins.settings == {}
    assert c.expected_rates == {}


def test_full_file(tmp_path):
    path = _cfg(tmp_path, FULL)
    c = load_config(path)
    assert isinstance(c, Config) and c.path == path
    assert (c.monitor.period, c.monitor.topic_metrics, c.monitor.history) == (0.5, False, 120)
    assert c.watchlist.mode == "config"
    assert c.watchlist.members == ("node:/camera*", "/planner")
    assert c.plugins.disable == ("graph_anomalies",)
    assert c.plugins.paths == ((tmp_path / "my_plugins").resolve(),)  # relative to the file
    assert c.plugins.settings == {"topic_rate": {"drop_ratio": 0.3, "confirm": 3}}
    assert c.expected_rates == {"topic:/camera/image": 30.0, "topic:/scan": 10.5}
    assert isinstance(c.expected_rates["topic:/camera/image"], float)
    assert c.rca.policy == "upstream"


def test_plugin_settings_checked_against_the_plugin(tmp_path):
    path = _cfg(tmp_path, """
        [plugins.topic_rate]
        drop_ratio = "half"
    """)
    c = load_config(path)
    with pytest.raises(ConfigError, match=re.escape(f'{path}: [plugins.topic_rate] drop_ratio = "half": '
                                                    "expected a number")):
        PluginSet.from_config(c, cwd_plugins=False)
    path = _cfg(tmp_path, """
        [plugins.topic_rate]
        confirm = 3
    """, "ok.toml")
    ps = PluginSet.from_config(load_config(path), cwd_plugins=False)
    assert next(p for p in ps.plugins if p.name == "topic_rate").settings["confirm"] == 3


@pytest.mark.parametrize(("text", "message"), [
    ("[monitr]\nperiod = 1\n", "unknown section [monitr] (known: monitor, plugins, rca, topics, watchlist)"),
    ("[monitor]\nperod = 1\n", "[monitor] unknown key 'perod' (known: condense_above, condensed, "
                               "forget_gone_s, history, period, recording_part_minutes, topic_metrics)"),
    ("[monitor]\nperiod = 'fast'\n", '[monitor] period = "fast": expected a number > 0'),
    ("[monitor]\nperiod = -1\n", "[monitor] period = -1: expected a number > 0"),
    ("[monitor]\nperiod = nan\n", "[monitor] period = nan: expected a number > 0"),
    ("[monitor]\nhistory = 1.5\n", "[monitor] history = 1.5: expected an integer >= 2"),
    ("[monitor]\nhistory = 1\n", "[monitor] history = 1: expected an integer >= 2"),
    ("[monitor]\nrecording_part_minutes = -1\n",
     "[monitor] recording_part_minutes = -1: expected a number >= 0"),
    ("[monitor]\ntopic_metrics = 1\n", "[monitor] topic_metrics = 1: expected true or false"),
    ("[watchlist]\nmode = 'some'\n", '[watchlist] mode = "some": expected one of auto, all, config'),
    ("[watchlist]\nmembers = 'node:/a'\n", '[watchlist] members = "node:/a": expected a list of strings'),
    ("[watchlist]\nmembers = [1]\n", "[watchlist] members = [1]: expected a list of strings"),
    ("[plugins]\nenable = 'x'\n", '[plugins] enable = "x": expected a list of strings'),
    ("[plugins]\nextra = 1\n", "[plugins] unknown key 'extra' (known: disable, enable, paths)"),
    ('[topics."/a"]\nexpected_rate = 3\n',
     '[topics."/a"] unknown key \'expected_rate\' (known: expected_rate_hz)'),
    ('[topics."/a"]\nexpected_rate_hz = 0\n', '[topics."/a"] expected_rate_hz = 0: expected a number > 0'),
    ('[topics."/a"]\nexpected_rate_hz = "10"\n',
     '[topics."/a"] expected_rate_hz = "10": expected a number > 0'),
    ('[topics]\n"/a" = 10\n', '[topics] "/a" = 10: expected a table'),
    ("monitor = 3\n", "monitor = 3: expected a table"),
    ("[rca]\ntop_k = 0\n", "[rca] top_k = 0: expected an integer >= 1"),
    ("[rca.weights]\ngravity = 1\n", "[rca.weights] unknown key 'gravity' (known: cooccurrence, direct, "
                                      "evidence, timelag, topology)"),
    ("[rca.severity]\ncritical = 1\n",
     "[rca.severity] unknown key 'critical' (known: error, fatal, info, warn)"),
    ("[monitor\nperiod = 1\n", "malformed TOML: .*line 1"),
])
def test_errors_name_key_and_file(tmp_path, text, message):
    path = _cfg(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_config(path)
    if ".*" in message:
        assert re.match(re.escape(f"{path}: ") + message, str(info.value))
    else:
        assert str(info.value) == f"{path}: {message}"


def test_rca_section_is_validated_by_the_rca_settings(tmp_path):
    path = _cfg(tmp_path, "[rca]\nnot_a_setting = 1\n")
    with pytest.raises(ConfigError, match=re.escape(str(path)) + ".*not_a_setting"):
        load_config(path)


def test_unreadable_file(tmp_path):
    with pytest.raises(ConfigError, match="cannot read"):
        load_config(tmp_path / "missing.toml")
    bad = tmp_path / "bin.toml"
    bad.write_bytes(b"\xff\xfe\x00garbage")
    with pytest.raises(ConfigError, match=r"bin\.toml"):
        load_config(bad)
