"""How fast a crash is seen on another computer (through its agent) against one on the monitor's
own computer, side by side in one run.

Two computers on this machine (`stream_viz.testing_hosts.Lab`: network and PID namespaces, ROS 2
discovery over UDP on a veth bridge): host ``a`` runs the collector (sampling every
``--period``) and a node, host ``b`` an agent (the same period) and a node. Each round both nodes
are SIGKILLed at the same moment, at a random phase of the two samplers; the figure is the time
from the kill to the collector's ``exit`` event of each node (both on this machine's clock).

    .venv/bin/python bench/bench_hosts_crash.py --rounds 5 --period 0.5
"""

from __future__ import annotations

import argparse
import os
import random
import shutil
import signal
import statistics
import sys
import tempfile
import time
from pathlib import Path

from stream_viz.testing import EXE, claim_domain
from stream_viz.testing_hosts import NODE, OBSERVER, Lab, Samples, inner, lab_env, why_not


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--rounds", type=int, default=5)
    ap.add_argument("--period", type=float, default=0.5, help="the collector's and the agent's period")
    a = ap.parse_args()
    why = why_not()
    if why:
        sys.exit(f"cannot make network/PID namespaces here: {why}")
    work = Path(tempfile.mkdtemp(prefix="bench_hosts_"))
    (work / "node.py").write_text(NODE)
    (work / "observe.py").write_text(OBSERVER)
    env = lab_env(claim_domain())
    local, remote = [], []
    with Lab(work) as lab:
        ha, hb = lab.add("a"), lab.add("b")
        hb.run([EXE, "agent", "--period", str(a.period)], env, work / "agent.log")
        samples = Samples(work / "samples.jsonl")
        ha.run([sys.executable, str(work / "observe.py"), str(samples.path), str(a.period)], env,
               work / "observe.log")
        for r in range(a.rounds):
            near, far = f"near_{r}", f"far_{r}"
            pn = ha.run([sys.executable, str(work / "node.py"), near], env, work / f"{near}.log")
            pf = hb.run([sys.executable, str(work / "node.py"), far], env, work / f"{far}.log")
            samples.until(lambda s, n=near, f=far: all(
                s["members"].get(f"node:/{x}", {}).get("pid_status") == "confirmed" for x in (n, f)), 60.0)
            # Tracked a while, as in a running robot; then a kill at a random phase of the samplers.
            time.sleep(2.0 + random.uniform(0.0, a.period))
            targets = (inner(pn), inner(pf))
            t_kill = time.time()
            for pid in targets:
                os.kill(pid, signal.SIGKILL)
            seen: dict[str, float] = {}

            def both(s, n=near, f=far, seen=seen):
                for x in samples.all():
                    for kind, member, _, t, *_ in x["events"]:
                        if kind == "exit" and member in (f"node:/{n}", f"node:/{f}"):
                            seen.setdefault(member, t)
                return len(seen) == 2

            samples.until(both, 30.0)
            local.append(seen[f"node:/{near}"] - t_kill)
            remote.append(seen[f"node:/{far}"] - t_kill)
            print(f"round {r}: local {local[-1]:.2f} s, remote {remote[-1]:.2f} s", flush=True)
    shutil.rmtree(work, ignore_errors=True)
    print(f"\n| crash seen (s from the kill), {a.rounds} rounds, period {a.period} s | median | max |")
    print("|---|---|---|")
    for what, xs in (("on the monitor's computer (from its /proc)", local),
                     ("on another computer (its agent's report)", remote)):
        print(f"| {what} | {statistics.median(xs):.2f} | {max(xs):.2f} |")


if __name__ == "__main__":
    main()
