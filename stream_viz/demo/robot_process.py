"""Process entry of the demo: ``python -m stream_viz.demo.robot_process --group NAME [options]``.

Creates the group's nodes, each on its own single-threaded executor thread, writes
``<run-dir>/<group>.ready`` once spinning, injects the fault at the agreed unix time if it concerns this
process (writing ``<run-dir>/injected.json``), and ends cleanly on SIGINT/SIGTERM or when its parent dies.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from pathlib import Path

from stream_viz.demo.child import (
    end_on_signals,
    end_process,
    next_fault,
    parser,
    process_fault,
    record_injection,
    spin,
    write_json,
)
from stream_viz.demo.faults import STOP
from stream_viz.demo.topology import DEMO, Topology


def _inject(fault: str, target: str, at: float, size: float | None, sims: dict, run_dir: Path,
            stop: threading.Event) -> None:
    """Wait until ``at`` (unix s), then inject ``fault`` of ``size`` if this process is concerned."""
    monitor = next((s for s in sims.values() if s.spec.diag_monitor), None)
    if fault == "diag":
        if monitor is None:
            return
    elif target not in sims:
        return
    if stop.wait(max(0.0, at - time.time())) or not record_injection(run_dir, fault, target, size):
        return
    sim = sims.get(target)
    print(f"injecting {fault} into {target}" + ("" if size is None else f" (size {size:g})"), flush=True)
    if fault == "crash":
        os.kill(os.getpid(), signal.SIGKILL)
    elif fault in ("hang", "degrade", "delay"):
        sim.set_fault(fault, size)
    elif fault == "diag":
        monitor.diag_errors.add(target)
    else:
        process_fault(fault, size, sim.log, stop, "injected error #{n}: sensor read failed")


def _injector(args, sims: dict, run_dir: Path) -> None:
    """The fault from the command line, else the first ``<run-dir>/fault.json`` (Robot.inject)."""
    got = next_fault(args, run_dir)
    if got is not None:
        _inject(*got, sims, run_dir, STOP)


def main(argv: list[str] | None = None) -> int:
    args = parser("python -m stream_viz.demo.robot_process",
                  "Run one process (group of nodes) of the demo robot.").parse_args(argv)
    end_on_signals()

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
        spinners.append(threading.Thread(target=spin, args=(ex,), daemon=True, name=f"spin{s.spec.name}"))
        spinners[-1].start()
    threading.Thread(target=_injector, args=(args, sims, run_dir), daemon=True, name="inject").start()
    write_json(run_dir / f"{group.name}.ready", {"pid": os.getpid(), "nodes": list(sims)})

    while not STOP.wait(0.5):  # a timeout keeps the main thread responsive to signals
        pass
    end_process(executors, spinners, [s.destroy for s in sims.values()], ctx)

if __name__ == "__main__":
    sys.exit(main())
