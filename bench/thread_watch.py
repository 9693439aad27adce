"""Every thread's CPU of the retail robot's containers, every 2 s, beside a run.

    .venv/bin/python bench/thread_watch.py SECONDS > threads.txt   # while bench.retail.run runs

Reads ``/proc/<pid>/task/*/{comm,schedstat}`` of the ``bench.retail.robot`` processes in `WATCHED`
and prints a line per process and probe whose threads used over 35 % of a core together: the
total, the main thread's (thread id = pid) and the five busiest threads (``M`` the main thread,
else the thread's name). What told the containers' CPU bursts to be their dispatching main
thread's (docs/plugins.md, *CPU of an executor's dispatcher*).
"""

from __future__ import annotations

import os
import sys
import time

WATCHED = ("perception", "navigation", "docking", "camera_container", "mission")


def watched() -> dict[int, str]:
    """pid -> process name of the robot's watched processes."""
    out = {}
    for p in filter(str.isdigit, os.listdir("/proc")):
        try:
            cmd = open(f"/proc/{p}/cmdline", "rb").read().split(b"\0")
        except OSError:
            continue
        if b"bench.retail.robot" in cmd and len(cmd) > 3 and cmd[3].decode() in WATCHED:
            out[int(p)] = cmd[3].decode()
    return out


def threads(pid: int) -> dict[int, tuple[str, int]]:
    """tid -> (name, CPU time ns) of ``pid``'s threads."""
    out = {}
    try:
        for t in os.listdir(f"/proc/{pid}/task"):
            try:
                comm = open(f"/proc/{pid}/task/{t}/comm").read().strip()
                out[int(t)] = (comm, int(open(f"/proc/{pid}/task/{t}/schedstat").read().split()[0]))
            except OSError:
                pass
    except OSError:
        pass
    return out


def main(seconds: float) -> None:
    prev, t0 = {}, time.time()
    while time.time() - t0 < seconds:
        procs, now = watched(), time.monotonic()
        cur = {p: threads(p) for p in procs}
        for p, th in cur.items():
            if p not in prev:
                continue
            dt, before = now - prev[p][0], prev[p][1]
            per = sorted(((ns - before.get(t, (c, 0))[1]) / 1e9 / dt * 100, t, c)
                         for t, (c, ns) in th.items())[::-1]
            total = sum(x for x, _, _ in per)
            if total > 35:
                main_cpu = sum(x for x, t, _ in per if t == p)
                top = " ".join(f"{'M' if t == p else c}:{x:.0f}" for x, t, c in per[:5])
                print(f"{time.time() - t0:6.0f} {procs[p]:12s} tot {total:5.0f} main {main_cpu:5.0f} | {top}",
                      flush=True)
        prev = {p: (now, th) for p, th in cur.items()}
        time.sleep(2)


if __name__ == "__main__":
    main(float(sys.argv[1]))
