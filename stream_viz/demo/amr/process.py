"""Process entry of the AMR: ``python -m stream_viz.demo.amr.process --group NAME [options]``.

Runs the group's nodes the way :data:`~stream_viz.demo.amr.topology.PROCESSES` says (one
single-threaded executor for all, a multi-threaded one with a callback group per node, or an
executor per node), joins late or ends as a one-shot job when the plan says so, and injects the
run's fault if it concerns this process. Ends cleanly on SIGINT/SIGTERM or when its parent dies.
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from pathlib import Path

from stream_viz.demo.amr.topology import AMR, PROCESSES
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
from stream_viz.demo.topology import Topology

RESTART_AFTER = 3.0  # the "restart" fault: the target's nodes live this long in each process, then it exits 1
ERRLOG = "failed to compute a result (error #{n}): internal exception"
NODE_FAULTS = ("hang", "degrade", "delay", "flap", "slow_service", "qos", "diag")
_exit_code = 0


def _inject(fault: str, target: str, at: float, size: float | None, nodes: dict, run_dir: Path,
            up: float) -> None:
    """At ``at`` (unix s) inject ``fault`` of ``size`` if its target runs here (nodes up since ``up``)."""
    global _exit_code
    if target not in nodes:
        return
    if fault == "restart":  # every process of the target fails again, a few seconds after it starts
        if STOP.wait(max(0.0, at - time.time(), up + RESTART_AFTER - time.time())):
            return
        record_injection(run_dir, fault, target)
        nodes[target].log.fatal("failed to open /dev/video0: device or resource busy")
        _exit_code = 1
        STOP.set()
        return
    if STOP.wait(max(0.0, at - time.time())) or not record_injection(run_dir, fault, target, size):
        return
    print(f"injecting {fault} into {target}" + ("" if size is None else f" (size {size:g})"), flush=True)
    behaviour = nodes[target]
    if fault == "crash":
        os.kill(os.getpid(), signal.SIGKILL)
    elif fault in NODE_FAULTS:
        behaviour.set_fault(fault, size)
    else:
        process_fault(fault, size, behaviour.log, STOP, ERRLOG)


def _injector(args, nodes: dict, run_dir: Path, up: float) -> None:
    got = next_fault(args, run_dir)
    if got is not None:
        _inject(*got, nodes, run_dir, up)


def _executors(kind: str, nodes: list, ctx) -> list:
    """The executors of a process plan's ``executor`` kind, with the nodes added."""
    from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor

    if kind == "isolated":
        out = []
        for b in nodes:
            ex = SingleThreadedExecutor(context=ctx)
            ex.add_node(b.node)
            out.append(ex)
        return out
    ex = MultiThreadedExecutor(num_threads=4, context=ctx) if kind == "multi" else \
        SingleThreadedExecutor(context=ctx)
    for b in nodes:
        ex.add_node(b.node)
    return [ex]


def main(argv: list[str] | None = None) -> int:
    args = parser("python -m stream_viz.demo.amr.process",
                  "Run one process (group of nodes) of the warehouse AMR.").parse_args(argv)
    end_on_signals()
    started = time.time()
    topo = Topology.load(args.topology) if args.topology else AMR
    group = topo.group(args.group)
    plan = PROCESSES[group.name]
    run_dir = Path(args.run_dir)
    ready = run_dir / f"{group.name}.ready"
    if plan.join_after:  # the process is up; its nodes come when someone starts them
        write_json(ready, {"pid": os.getpid(), "nodes": [], "joins_at": started + plan.join_after})
        if STOP.wait(plan.join_after):
            return 0

    import rclpy
    from rclpy.context import Context
    from rclpy.signals import SignalHandlerOptions

    from stream_viz.demo.amr.nodes import BEHAVIOURS

    if STOP.is_set():  # ended (or orphaned) while importing
        return 0
    ctx = Context()
    rclpy.init(context=ctx, signal_handler_options=SignalHandlerOptions.NO)
    nodes = {spec.name: BEHAVIOURS[spec.name](spec, ctx) for spec in group.nodes}
    executors = _executors(plan.executor, list(nodes.values()), ctx)
    spinners = [threading.Thread(target=spin, args=(ex,), daemon=True, name=f"spin{i}")
                for i, ex in enumerate(executors)]
    for t in spinners:
        t.start()
    threading.Thread(target=_injector, args=(args, nodes, run_dir, time.time()), daemon=True,
                     name="inject").start()
    write_json(ready, {"pid": os.getpid(), "nodes": list(nodes)})

    end = started + plan.run_for if plan.run_for else float("inf")
    while not STOP.wait(0.5) and time.time() < end:  # a timeout keeps the main thread responsive
        pass
    if not STOP.is_set():  # a one-shot job done
        for b in nodes.values():
            b.finish()
        STOP.set()
    end_process(executors, spinners, [b.destroy for b in nodes.values()], ctx, _exit_code)

if __name__ == "__main__":
    sys.exit(main())
