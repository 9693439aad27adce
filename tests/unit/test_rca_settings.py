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
    ("d", "message"),
    [
        ({"polcy": "both"}, "[rca] unknown key 'polcy' (known: charge, direct_plugins, episode_gap, "
                            "icp_iterations, incident_hops, incident_lead, led_max, max_offset, "
                            "max_trajectory, method, metric, pagerank_alpha, policy, replay, severity, "
                            "shortlist, tolerance, top_k, weights, window)"),
        ({"policy": "sideways"}, '[rca] policy = "sideways": expected one of downstream, upstream, both'),
        ({"method": "magic"},
         '[rca] method = "magic": expected one of trajectory, pagerank, hypothesis, count'),
        ({"weights": {"gravity": 1.0}}, "[rca.weights] unknown key 'gravity' (known: cooccurrence, direct, "
                                        "evidence, timelag, topology)"),
        ({"weights": {"topology": -1}}, "[rca.weights] topology = -1: expected a number >= 0"),
        ({"weights": {k: 0 for k in RcaSettings().weights}},
         "[rca] weights = {topology = 0, direct = 0, cooccurrence = 0, timelag = 0, evidence = 0}: "
         "expected a table of numbers >= 0, at least one > 0"),
        ({"weights": 3}, "[rca] weights = 3: expected a table"),
        ({"severity": {"critical": 1.0}},
         "[rca.severity] unknown key 'critical' (known: error, fatal, info, warn)"),
        ({"top_k": 0}, "[rca] top_k = 0: expected an integer >= 1"),
        ({"episode_gap": 0}, "[rca] episode_gap = 0: expected a number > 0"),
        ({"led_max": -1}, "[rca] led_max = -1: expected a number > 0"),
        ({"incident_hops": 0}, "[rca] incident_hops = 0: expected an integer >= 1"),
        ({"top_k": True}, "[rca] top_k = true: expected an integer >= 1"),
        ({"tolerance": "2s"}, '[rca] tolerance = "2s": expected a number > 0'),
        ({"tolerance": 0}, "[rca] tolerance = 0: expected a number > 0"),
        ({"charge": 1.5}, "[rca] charge = 1.5: expected a number in (0, 1]"),
        ({"pagerank_alpha": 1.0}, "[rca] pagerank_alpha = 1.0: expected a number in (0, 1)"),
        ({"replay": "yes"}, '[rca] replay = "yes": expected true or false'),
        ({"direct_plugins": "rosout"}, '[rca] direct_plugins = "rosout": expected a list of strings'),
    ],
)
def test_bad_values_name_file_section_key_and_value(d, message):
    with pytest.raises(ConfigError) as err:
        RcaSettings.from_dict(d, "cfg.toml")
    assert str(err.value) == f"cfg.toml: {message}"


def test_not_a_table():
    with pytest.raises(ConfigError, match=r'^cfg\.toml: rca = \["policy"\]: expected a table$'):
        RcaSettings.from_dict(["policy"], "cfg.toml")  # type: ignore[arg-type]
