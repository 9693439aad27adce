"""Local participants never discovered: the pure parts (`stream_viz.collect.undiscovered`)."""

from __future__ import annotations

from stream_viz.collect.undiscovered import Participant, discovered_low16, explain, undiscovered


def _gid(host: int, pid: int) -> bytes:
    # Fast DDS: vendor 01.0f, host id (2 bytes), PID low 16 bits (little endian), participant id.
    return b"\x01\x0f" + host.to_bytes(2, "big") + (pid & 0xFFFF).to_bytes(2, "little") + bytes(10)


def test_discovered_low16_keeps_this_hosts_fast_dds_participants():
    gids = [_gid(7, 70001), _gid(7, 12), _gid(9, 13), b"\x01\x10" + bytes(14)]
    assert discovered_low16(gids, own_host=7) == {70001 & 0xFFFF, 12}
    assert discovered_low16(gids, own_host=None) == {70001 & 0xFFFF, 12, 13}


def test_undiscovered_matches_by_own_pid_bits_after_the_grace():
    found = [Participant(100, 5, "a", started=0.0), Participant(101, 70006, "b", started=0.0),
             Participant(102, 7, "c", started=95.0)]
    # 5 discovered; 70006 is 4470 in 16 bits, not discovered; 7 too young to tell.
    assert [p.pid for p in undiscovered(found, {5}, now=100.0, grace_s=10.0)] == [101]
    assert [p.pid for p in undiscovered(found, {5, 70006 & 0xFFFF}, now=100.0, grace_s=10.0)] == []


def test_explain_names_differing_discovery_settings_or_the_localhost_limit():
    off = Participant(9, 9, "cam", 0.0, (("ROS_AUTOMATIC_DISCOVERY_RANGE", "OFF"),))
    text = explain(off, 3, {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}, 10.0)
    assert text.startswith("process 9 (cam) has Fast DDS loaded with ROS_DOMAIN_ID=3")
    assert "ROS_AUTOMATIC_DISCOVERY_RANGE=OFF (monitor: LOCALHOST)" in text
    local = {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    same = Participant(9, 9, "cam", 0.0, tuple(local.items()))
    assert "start the monitor before the robot" in explain(same, 3, local, 10.0)
    assert "start the monitor" not in explain(Participant(9, 9, "cam", 0.0), 3, {}, 10.0)


def test_undiscovered_counts_the_grace_from_when_its_participant_showed():
    # Started at 0, its participant (first node) only at 95: too young to tell at 100.
    found = [Participant(101, 101, "b", started=0.0)]
    assert undiscovered(found, set(), now=100.0, grace_s=10.0, since={101: 95.0}) == []
    assert [p.pid for p in undiscovered(found, set(), now=105.0, grace_s=10.0, since={101: 95.0})] == [101]
