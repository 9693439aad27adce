"""Process entry of the demo: ``python -m stream_viz.demo.robot_process --group NAME [options]``.

Creates the group's nodes, each on its own single-threaded executor thread, writes
``<run-dir>/<group>.ready`` once spinning, injects the fault at the agreed unix time if it concerns this
process (writing ``<run-dir>/injected.json``), and ends cleanly on SIGINT/SIGTERM or when its parent dies.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import signal
import sys
import threading
import time
from pathlib import Path

from stream_viz.demo.faults import FAULTS, STOP
from stream_viz.demo.topology import DEMO, Topology

LEAK_RATE = 20 * 2**20  # bytes per second
LEAK_CAP = 1536 * 2**20


def _write_json(path: Path, data: dict) -> None:
    tmp = path.with_suffix(".tmp")
    with open(tmp, "w") as f:
        json.dump(data, f)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def _burn(stop: threading.Event) -> None:
    # hashlib releases the GIL on large buffers: a real core burns, the executor keeps running
    buf = b"\x5a" * 2**20
    while not stop.is_set():
        hashlib.sha256(buf).digest()


def _leak(stop: threading.Event) -> None:
    hoard, step = [], LEAK_RATE // 10
    while not stop.wait(0.1) and len(hoard) * step < LEAK_CAP:
        hoard.append(b"\x01" * step)  # written, so resident (RSS grows)


def _errlog(sim, stop: threading.Event) -> None:
    n = 0
    while not stop.wait(0.5):
        n += 1
        sim.log.error(f"injected error #{n}: sensor read failed")


def _inject(fault: str, target: str, at: float, sims: dict, run_dir: Path, stop: threading.Event) -> None:
    """Wait until ``at`` (unix s), then inject ``fault`` if this process is concerned."""
    monitor = next((s for s in sims.values() if s.spec.diag_monitor), None)
    if fault == "diag":
        if monitor is None:
            return
    elif target not in sims:
        return
    if stop.wait(max(0.0, at - time.time())):
        return
    _write_json(run_dir / "injected.json",
                {"fault": fault, "target": f"node:{target}", "t": time.time(), "pid": os.getpid()})
    sim = sims.get(target)
    print(f"injecting {fault} into {target}", flush=True)
    if fault == "crash":
        os.kill(os.getpid(), signal.SIGKILL)
    elif fault in ("hang", "degrade", "delay"):
        sim.fault = fault
    elif fault == "diag":
        monitor.diag_errors.add(target)
    else:
        work = {"cpu": _burn, "leak": _leak}.get(fault)
        args = (stop,) if work else (sim, stop)
        threading.Thread(target=work or _errlog, args=args, daemon=True, name=f"fault-{fault}").start()


def _injector(args: argparse.Namespace, sims: dict, run_dir: Path) -> None:
    """The fault from the command line, else the first ``<run-dir>/fault.json`` (Robot.inject)."""
    if args.fault and args.target and args.at is not None:
        _inject(args.fault, args.target, args.at, sims, run_dir, STOP)
        return
    path = run_dir / "fault.json"
    while not STOP.wait(0.2):
        try:
            spec = json.loads(path.read_text())
        except (OSError, ValueError):
            continue
        _inject(spec["fault"], spec["target"], spec["at"], sims, run_dir, STOP)
        return


def _spin(executor) -> None:
    try:
        executor.spin()
    except Exception:  # shutdown races end the spin; the process is ending anyway
        pass


def _watch_parent(parent: int) -> None:
    while not STOP.wait(0.5):
        if os.getppid() != parent:  # the parent died: end with it
            STOP.set()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m stream_viz.demo.robot_process",
                                 description="Run one process (group of nodes) of the demo robot.")
    ap.add_argument("--group", required=True)
    ap.add_argument("--topology", help="topology JSON (default: the demo robot)")
    ap.add_argument("--run-dir", default=".", help="where ready/injection files go")
    ap.add_argument("--fault", choices=sorted(FAULTS))
    ap.add_argument("--target", help="fqn of the faulty node")
    ap.add_argument("--at", type=float, help="unix time of the injection")
    args = ap.parse_args(argv)
    parent = os.getppid()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: STOP.set())
    threading.Thread(target=_watch_parent, args=(parent,), daemon=True, name="watch-parent").start()

    import rclpy
    from rclpy.context import Context
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    from stream_viz.demo.sim_node import SimNode

    topo = Topology.load(args.topology) if args.topology else DEMO
    group = topo.group(args.group)
    run_dir = Path(args.run_dir)
    if STOP.is_set():  # ended (or orphaned) while importing
        return 0
    ctx = Context()
    rclpy.init(context=ctx, signal_handler_options=SignalHandlerOptions.NO)
    sims = {n.name: SimNode(n, ctx, topo.node_names()) for n in group.nodes}
    # one single-threaded executor (and thread) per node: a hung node blocks only itself, and it
    # costs far less CPU than one MultiThreadedExecutor for the whole process (docs/demo.md)
    executors, spinners = [], []
    for s in sims.values():
        ex = SingleThreadedExecutor(context=ctx)
        ex.add_node(s.node)
        executors.append(ex)
        spinners.append(threading.Thread(target=_spin, args=(ex,), daemon=True, name=f"spin{s.spec.name}"))
        spinners[-1].start()
    threading.Thread(target=_injector, args=(args, sims, run_dir), daemon=True, name="inject").start()
    _write_json(run_dir / f"{group.name}.ready", {"pid": os.getpid(), "nodes": list(sims)})

    while not STOP.wait(0.5):  # a timeout keeps the main thread responsive to signals
        pass
    # A clean shutdown can hang (an executor busy in a callback, DDS teardown): end regardless.
    watchdog = threading.Timer(5.0, os._exit, args=(0,))
    watchdog.daemon = True
    watchdog.start()
    for ex in executors:
        ex.shutdown(timeout_sec=1.0)
    for t in spinners:  # a node still in use by a spinning executor would not really be destroyed
        t.join(2.0)
    for s in sims.values():
        s.destroy()
    ctx.try_shutdown()
    ctx.destroy()  # deletes the DDS participant: peers see the nodes leave at once
    sys.stdout.flush()
    os._exit(0)  # skip joining stuck executor threads


if __name__ == "__main__":
    sys.exit(main())
