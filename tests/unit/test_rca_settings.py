"""RcaSettings.from_dict: defaults, partial tables, and errors naming the key and the file."""

from __future__ import annotations

import dataclasses

import pytest

from stream_viz.errors import ConfigError
from stream_viz.rca.settings import RcaSettings


def test_defaults_and_partial_tables():
    s = RcaSettings.from_dict({"policy": "downstream", "weights": {"timelag": 0.0}, "top_k": 3}, "a.toml")
    assert s.policy == "downstream" and s.top_k == 3
    assert s.weights["timelag"] == 0.0 and s.weights["topology"] == RcaSettings().weights["topology"]
    assert RcaSettings.from_dict({}, "x") == RcaSettings()


def test_roundtrip_through_asdict():
    s = RcaSettings(method="pagerank", direct_plugins=("rosout",), replay=False)
    assert RcaSettings.from_dict(dataclasses.asdict(s), "command line") == s


@pytest.mark.parametrize(
    ("d", "words"),
    [
        ({"polcy": "both"}, ["rca.polcy", "cfg.toml"]),
        ({"policy": "sideways"}, ["rca.policy", "sideways", "cfg.toml"]),
        ({"method": "magic"}, ["rca.method", "magic"]),
        ({"weights": {"gravity": 1.0}}, ["rca.weights.gravity"]),
        ({"weights": {"topology": -1}}, ["rca.weights.topology", "-1"]),
        ({"weights": {k: 0 for k in RcaSettings().weights}}, ["rca.weights"]),
        ({"top_k": 0}, ["rca.top_k"]),
        ({"top_k": True}, ["rca.top_k"]),
        ({"tolerance": "2s"}, ["rca.tolerance", "'2s'"]),
        ({"tolerance": 0}, ["rca.tolerance"]),
        ({"charge": 1.5}, ["rca.charge"]),
        ({"pagerank_alpha": 1.0}, ["rca.pagerank_alpha"]),
        ({"replay": "yes"}, ["rca.replay"]),
        ({"direct_plugins": "rosout"}, ["rca.direct_plugins"]),
    ],
)
def test_bad_values_name_key_and_file(d, words):
    with pytest.raises(ConfigError) as err:
        RcaSettings.from_dict(d, "cfg.toml")
    msg = str(err.value)
    assert "cfg.toml" in msg
    for w in words:
        assert w in msg


def test_not_a_table():
    with pytest.raises(ConfigError, match=r"cfg\.toml"):
        RcaSettings.from_dict(["policy"], "cfg.toml")  # type: ignore[arg-type]
