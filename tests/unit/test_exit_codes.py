"""Exit codes from the kernel's process events connector: parsing one netlink message."""

from __future__ import annotations

import struct

from stream_viz.collect.exitcodes import PROC_EVENT_EXIT, describe_exit, exit_code, parse, stamp_ns


def message(what: int, pid: int, tgid: int, status: int) -> bytes:
    """A netlink message as the kernel sends one (header, connector header, proc_event)."""
    body = struct.pack("=IIQ", what, 0, 123) + struct.pack("=IIII", pid, tgid, status, 17)
    cn = struct.pack("=IIIIHH", 1, 1, 0, 0, len(body), 0) + body
    return struct.pack("=IHHII", 16 + len(cn), 3, 0, 0, 0) + cn


def test_exit_codes_as_subprocess_gives_them():
    assert exit_code(0) == 0 and exit_code(3 << 8) == 3 and exit_code(9) == -9 and exit_code(15 | 0x80) == -15
    assert describe_exit(None) == "exited" and describe_exit(0) == "exited with code 0"
    assert describe_exit(-9) == "was killed by SIGKILL" and describe_exit(-200) == "was killed by signal 200"


def test_parse_keeps_process_exits_only():
    assert parse(message(PROC_EVENT_EXIT, 42, 42, 1 << 8)) == (42, 1)
    assert parse(message(PROC_EVENT_EXIT, 43, 42, 0)) is None  # a thread of 42 ended
    assert parse(message(0x00000002, 42, 42, 0)) is None  # a fork, not an exit
    assert parse(message(PROC_EVENT_EXIT, 42, 42, 0)[:40]) is None  # cut short
    assert stamp_ns(message(PROC_EVENT_EXIT, 42, 42, 1 << 8)) == 123  # the kernel's clock, ns
