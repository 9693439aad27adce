"""A process's CPU quota from its cgroup: parsing on literal texts, the walk on a literal tree."""

from __future__ import annotations

import math
from pathlib import Path

from stream_viz.collect.cgroups import (
    MemoryGroup,
    Mount,
    Quota,
    QuotaReading,
    cgroup_dir,
    memory_group_of,
    parse_memory_use,
    parse_mountinfo,
    parse_oom_kills,
    parse_proc_cgroup,
    parse_stat,
    quota_of,
    quota_use,
    read_memory_use,
    read_quota,
)

MOUNTINFO = """\
25 30 0:22 / /sys/fs/cgroup/cpu rw,relatime shared:9 - cgroup cgroup rw,cpu
26 30 0:23 / /sys/fs/cgroup/cpuacct rw,relatime shared:10 - cgroup cgroup rw,cpuacct
27 30 0:24 / /sys/fs/cgroup/memory rw,relatime shared:11 - cgroup cgroup rw,memory
28 30 0:25 /docker/abc /sys/fs/cgroup/unified rw,relatime shared:12 - cgroup2 cgroup2 rw
29 30 0:26 / /proc rw - proc proc rw
"""


def test_mounts_and_a_process_s_groups_are_parsed():
    assert parse_mountinfo(MOUNTINFO) == [
        Mount("/sys/fs/cgroup/cpu", "/", frozenset({"cpu"})),
        Mount("/sys/fs/cgroup/cpuacct", "/", frozenset({"cpuacct"})),
        Mount("/sys/fs/cgroup/memory", "/", frozenset({"memory"})),
        Mount("/sys/fs/cgroup/unified", "/docker/abc", frozenset({""}))]
    groups = parse_proc_cgroup("4:memory:/m\n2:cpu,cpuacct:/robot\n0::/docker/abc/app\n")
    assert groups == {"memory": "/m", "cpu": "/robot", "cpuacct": "/robot", "": "/docker/abc/app"}
    mounts = parse_mountinfo(MOUNTINFO)
    assert cgroup_dir(mounts, "cpu", groups) == ("/sys/fs/cgroup/cpu/robot", "/sys/fs/cgroup/cpu")
    # A mount that shows a group below the root (a container's namespace): paths relative to it.
    assert cgroup_dir(mounts, "", groups) == ("/sys/fs/cgroup/unified/app", "/sys/fs/cgroup/unified")
    assert cgroup_dir(mounts, "", {"": "/elsewhere"}) is None
    assert parse_stat("usage_usec 2500\nnr_periods 10\nnr_throttled 4\nbogus x\n") == \
        {"usage_usec": 2500, "nr_periods": 10, "nr_throttled": 4}


def _write(root: Path, files: dict[str, str]) -> None:
    for name, text in files.items():
        (root / name).parent.mkdir(parents=True, exist_ok=True)
        (root / name).write_text(text)


def test_the_tightest_quota_over_a_process_is_found_up_its_groups(tmp_path):
    # cgroup v2: the pod holds 1.5 CPUs, its container none, the machine's root none.
    _write(tmp_path, {"proc/7/cgroup": "0::/pod/app\n", "cg/pod/cpu.max": "150000 100000\n",
                      "cg/pod/app/cpu.max": "max 100000\n", "cg/pod/cpu.stat": "usage_usec 0\n"})
    mounts = [Mount(str(tmp_path / "cg"), "/", frozenset({""}))]
    q = quota_of(7, mounts, proc=str(tmp_path / "proc"))
    assert q == Quota(str(tmp_path / "cg/pod"), 1.5, str(tmp_path / "cg/pod/cpu.stat"), 1e-6,
                      str(tmp_path / "cg/pod/cpu.stat"))
    # cgroup v1, cpu and cpuacct mounted apart: the usage of the same group in cpuacct.
    _write(tmp_path, {"proc/8/cgroup": "3:cpuacct:/box/a\n2:cpu:/box/a\n",
                      "v1cpu/box/cpu.cfs_quota_us": "50000\n", "v1cpu/box/cpu.cfs_period_us": "100000\n",
                      "v1cpu/box/a/cpu.cfs_quota_us": "-1\n", "v1cpu/box/a/cpu.cfs_period_us": "100000\n",
                      "v1acct/box/cpuacct.usage": "0\n"})
    mounts = [Mount(str(tmp_path / "v1cpu"), "/", frozenset({"cpu"})),
              Mount(str(tmp_path / "v1acct"), "/", frozenset({"cpuacct"}))]
    q = quota_of(8, mounts, proc=str(tmp_path / "proc"))
    assert (q.cpus, q.path, q.usage, q.usage_s) == (0.5, str(tmp_path / "v1cpu/box"),
                                                    str(tmp_path / "v1acct/box/cpuacct.usage"), 1e-9)
    # None set anywhere, no cgroup mount shown, or a process gone: no quota.
    _write(tmp_path, {"proc/9/cgroup": "2:cpu:/free\n", "v1cpu/free/cpu.cfs_quota_us": "-1\n",
                      "v1cpu/free/cpu.cfs_period_us": "100000\n"})
    assert quota_of(9, mounts, proc=str(tmp_path / "proc")) is None
    assert quota_of(8, [], proc=str(tmp_path / "proc")) is None
    assert quota_of(10, mounts, proc=str(tmp_path / "proc")) is None


def test_a_quota_s_use_and_throttling_between_two_readings(tmp_path):
    stat = tmp_path / "cpu.stat"
    q = Quota(str(tmp_path), 2.0, str(stat), 1e-6, str(stat))
    stat.write_text("usage_usec 1000000\nnr_periods 100\nnr_throttled 5\n")
    a = read_quota(q, 10.0)
    stat.write_text("usage_usec 2500000\nnr_periods 120\nnr_throttled 15\n")
    b = read_quota(q, 11.0)
    assert (a, b) == (QuotaReading(10.0, 1.0, 100, 5), QuotaReading(11.0, 2.5, 120, 15))
    assert quota_use(q, a, b) == (75.0, 50.0)  # 1.5 CPU-s of 2 in 1 s; 10 of 20 periods
    idle = quota_use(q, b, QuotaReading(12.0, 2.5, 120, 15))
    assert idle[0] == 0.0 and math.isnan(idle[1])  # no period enforced: throttling unknown
    stat.unlink()
    assert read_quota(q, 12.0) is None  # the group is gone


def test_a_process_s_memory_group_its_oom_count_and_tightest_limit(tmp_path):
    # v2: the pod limited to 512 MiB, its container to none; memory.events counts the OOM kills.
    _write(tmp_path, {"proc/7/cgroup": "0::/pod/app\n", "cg/pod/memory.max": f"{512 * 2**20}\n",
                      "cg/pod/app/memory.max": "max\n",
                      "cg/pod/app/memory.events": "low 0\nhigh 0\nmax 3\noom 1\noom_kill 1\n"})
    mounts = [Mount(str(tmp_path / "cg"), "/", frozenset({""}))]
    g = memory_group_of(7, mounts, proc=str(tmp_path / "proc"))
    app = tmp_path / "cg/pod/app"
    assert g == MemoryGroup(str(app), str(app / "memory.events"), 512 * 2**20, str(tmp_path / "cg/pod"))
    # v1: memory.oom_control; "no limit" is a page-rounded 2^63 - 1.
    _write(tmp_path, {"proc/8/cgroup": "4:memory:/box\n2:cpu:/\n",
                      "v1mem/box/memory.limit_in_bytes": "9223372036854771712\n",
                      "v1mem/box/memory.oom_control": "oom_kill_disable 0\nunder_oom 0\noom_kill 2\n"})
    mounts = [Mount(str(tmp_path / "v1mem"), "/", frozenset({"memory"}))]
    g = memory_group_of(8, mounts, proc=str(tmp_path / "proc"))
    assert g == MemoryGroup(str(tmp_path / "v1mem/box"), str(tmp_path / "v1mem/box/memory.oom_control"), None)
    assert parse_oom_kills((tmp_path / "v1mem/box/memory.oom_control").read_text()) == 2
    assert parse_oom_kills("oom_kill_disable 0\nunder_oom 0\n") is None  # a kernel before 4.13
    # No memory mount, or a process gone: none.
    assert memory_group_of(8, [], proc=str(tmp_path / "proc")) is None
    assert memory_group_of(9, mounts, proc=str(tmp_path / "proc")) is None


def test_a_group_s_memory_use_is_its_usage_less_its_inactive_file_cache(tmp_path):
    # v2: memory.current and memory.stat's inactive_file; v1: usage_in_bytes and total_inactive_file.
    _write(tmp_path, {"v2/memory.current": "1000000\n",
                      "v2/memory.stat": "anon 300000\ninactive_file 600000\n",
                      "v1/memory.usage_in_bytes": "900\n",
                      "v1/memory.stat": "cache 500\ninactive_file 100\ntotal_inactive_file 400\n"})
    assert read_memory_use(str(tmp_path / "v2")) == 400000
    assert read_memory_use(str(tmp_path / "v1")) == 500  # the hierarchy's total, as the limit counts it
    assert parse_memory_use("100\n", "inactive_file 300\n") == 0
    assert parse_memory_use("max\n", "") is None
    assert read_memory_use(str(tmp_path / "none")) is None
