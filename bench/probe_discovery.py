"""What a super client sees of N rclpy clients of Fast DDS's discovery server, in a lab computer.

Runs inside one computer of a `stream_viz.testing_hosts.Lab` (network, PID and mount namespaces
of its own): the discovery server on its loopback, N idle rclpy processes its clients, set up as
`bench_agent.py --lab --discovery-server` sets them up (`bench_agent.with_server`), and one rclpy
node as super client. After the last client started it prints how many nodes the super client
sees, ``--rounds`` times ``--every`` seconds apart, then which clients it never saw and how many
are alive. It asks where discovery stops (a port, a load), not what the agent costs.

    .venv/bin/python bench/probe_discovery.py --clients 200 --rounds 15 --every 20
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from bench.bench_agent import CHILD, discovery_server, with_server  # noqa: E402
from stream_viz.testing import claim_domain  # noqa: E402
from stream_viz.testing_hosts import Lab, lab_env, why_not  # noqa: E402


def probe(domain: int, n: int, rounds: int, every: float, work: Path) -> None:
    env = with_server(lab_env)(domain)
    ds = discovery_server(env, work / "server.log")
    os.environ.update(env)
    os.environ["ROS_SUPER_CLIENT"] = "TRUE"
    import rclpy

    rclpy.init()
    node = rclpy.create_node("probe")
    kids = []
    try:
        for i in range(n):
            kids.append(subprocess.Popen([sys.executable, "-c", CHILD, f"n{i}"], env=env,
                                         stdout=subprocess.DEVNULL, stderr=subprocess.STDOUT))
            if (i + 1) % 10 == 0:
                time.sleep(1.0)
        for _ in range(rounds):
            time.sleep(every)
            print(time.strftime("%X"), "nodes seen", len(node.get_node_names()), flush=True)
        names = set(node.get_node_names())
        miss = [i for i in range(n) if f"n{i}" not in names]
        print("missing", len(miss), miss[:5], miss[-5:], flush=True)
        print("alive", sum(k.poll() is None for k in kids), flush=True)
    finally:
        for k in kids:
            k.kill()
        ds.kill()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--clients", type=int, default=200)
    ap.add_argument("--rounds", type=int, default=8)
    ap.add_argument("--every", type=float, default=5.0)
    ap.add_argument("--inside", type=int, help=argparse.SUPPRESS)  # the domain, in the lab computer
    a = ap.parse_args()
    work = Path(tempfile.mkdtemp(prefix="probe_discovery_"))
    if a.inside is not None:
        probe(a.inside, a.clients, a.rounds, a.every, work)
        return 0
    reason = why_not()
    if reason is not None:
        print(f"no lab here: {reason}", file=sys.stderr)
        return 2
    argv = ["--clients", str(a.clients), "--rounds", str(a.rounds), "--every", str(a.every)]
    with Lab(work) as lab:
        p = lab.add("robot").run([sys.executable, __file__, *argv, "--inside", str(claim_domain())],
                                 os.environ.copy(), work / "probe.log")
        code = p.wait()
    print((work / "probe.log").read_text(), end="")
    return code


if __name__ == "__main__":
    raise SystemExit(main())
