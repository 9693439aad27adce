"""The QoS reader the plugins share, on literal endpoint dicts."""

from __future__ import annotations

from stream_viz_plugins.topic_rate import latched

from stream_viz.model.qos import qos_policy


def test_policies_read_the_same_in_every_form():
    for raw in ("transient_local", "TRANSIENT_LOCAL", "DurabilityPolicy.TRANSIENT_LOCAL", 1):
        assert qos_policy({"durability": raw}, "durability") == "transient_local"
    assert qos_policy({"reliability": 2}, "reliability") == "best_effort"
    assert qos_policy({}, "reliability") == ""
    # topic_rate's latched-topic test reads through it: numbers as older models stored them too
    assert latched([{"role": "pub", "durability": 1}, {"role": "sub", "durability": "volatile"}])
    assert not latched([{"role": "pub", "durability": 1}, {"role": "pub", "durability": "volatile"}])
    assert not latched([])
