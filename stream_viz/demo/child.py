"""What every robot process does, whatever nodes it runs: its arguments, its end, readiness, the fault.

A process entry (``Topology.entry``) parses :func:`parser`'s arguments, calls :func:`end_on_signals`
first, writes ``<run-dir>/<group>.ready`` with :func:`write_json` once its nodes spin, and waits for
its fault with :func:`next_fault` (from the command line, or ``<run-dir>/fault.json`` that
``Robot.inject`` writes). :func:`record_injection` writes ``injected.json`` once per run, so a
respawned process does not inject a one-off fault again. The process-wide faults are here too.
"""

from __future__ import annotations

import argparse
import datetime
import faulthandler
import hashlib
import json
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, NoReturn

from stream_viz.demo.faults import CPU_SHARE, ERRLOG_PER_S, FAULTS, LEAK_MB_S, STOP

# The last resort of `end_process` (whole seconds), and the line faulthandler prints first.
WATCHDOG_S = 6
WATCHDOG = f"Timeout ({datetime.timedelta(seconds=WATCHDOG_S)})!"

LEAK_CAP = 1536 * 2**20
BURN_PERIOD = 0.1  # s: a partial ``cpu`` fault burns its share of each such period
# s between looks for fault.json: looking 5 times a second put the thread over the collector's
# floor for a running thread, so a single-threaded process looked multi-threaded
FAULT_POLL_S = 1.0


def parser(prog: str, description: str) -> argparse.ArgumentParser:
    """The arguments ``Robot`` gives every process entry."""
    ap = argparse.ArgumentParser(prog=prog, description=description)
    ap.add_argument("--group", required=True)
    ap.add_argument("--topology", help="topology JSON (default: the entry's own robot)")
    ap.add_argument("--run-dir", default=".", help="where ready/injection files go")
    ap.add_argument("--fault", choices=sorted(FAULTS))
    ap.add_argument("--target", help="fqn of the faulty node")
    ap.add_argument("--at", type=float, help="unix time of the injection")
    ap.add_argument("--size", type=float, help="the fault's size (FaultSpec.size)")
    return ap


def write_json(path: Path, data: dict) -> None:
    """Write ``data`` to ``path`` atomically (readers never see half a file)."""
    tmp = path.with_suffix(".tmp")
    with open(tmp, "w") as f:
        json.dump(data, f)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def end_on_signals() -> None:
    """Set STOP on SIGINT/SIGTERM and when the parent dies (polled every 0.5 s from now on)."""
    parent = os.getppid()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: STOP.set())

    def watch() -> None:
        while not STOP.wait(0.5):
            if os.getppid() != parent:  # the parent died: end with it
                STOP.set()

    threading.Thread(target=watch, daemon=True, name="watch-parent").start()


def next_fault(args: argparse.Namespace, run_dir: Path) -> tuple[str, str, float, float | None] | None:
    """``(fault, target, at, size)`` from the command line, else the first ``fault.json``; None on STOP."""
    if args.fault and args.target and args.at is not None:
        return args.fault, args.target, args.at, args.size
    path = run_dir / "fault.json"
    while not STOP.wait(FAULT_POLL_S):
        try:
            spec = json.loads(path.read_text())
        except (OSError, ValueError):
            continue
        return spec["fault"], spec["target"], spec["at"], spec.get("size")
    return None


def record_injection(run_dir: Path, fault: str, target: str, size: float | None = None) -> bool:
    """Write ``injected.json`` for ``fault`` into ``target`` now; False if this run has one already."""
    path = run_dir / "injected.json"
    if path.exists():
        return False
    record = {"fault": fault, "target": f"node:{target}", "t": time.time(), "pid": os.getpid()}
    write_json(path, record if size is None else {**record, "size": size})
    return True


def burn(stop: threading.Event, share: float = CPU_SHARE) -> None:
    """Burn ``share`` of a core until ``stop``: the ``cpu`` fault.

    hashlib releases the GIL on large buffers, so the executors keep running. Below a whole core
    the thread burns until it has used its share of each `BURN_PERIOD` (CPU time), then idles.
    """
    buf = b"\x5a" * 2**20
    part = buf[: 2**18]  # finer steps for a partial share
    while not stop.is_set():
        if share >= 1.0:
            hashlib.sha256(buf).digest()
            continue
        wall, cpu = time.monotonic(), time.thread_time()
        end = wall + BURN_PERIOD
        while time.thread_time() - cpu < share * BURN_PERIOD and time.monotonic() < end:
            hashlib.sha256(part).digest()
        stop.wait(max(0.0, end - time.monotonic()))


def leak(stop: threading.Event, mb_per_s: float = LEAK_MB_S) -> None:
    """Allocate and write ``mb_per_s`` MB per second until ``stop`` or ``LEAK_CAP``."""
    hoard, step = [], int(mb_per_s * 2**20) // 10
    while not stop.wait(0.1) and len(hoard) * step < LEAK_CAP:
        hoard.append(b"\x01" * step)  # written, so resident (RSS grows)


def spin(executor) -> None:
    """Spin ``executor`` until it is shut down."""
    try:
        executor.spin()
    except Exception:  # shutdown races end the spin; the process is ending anyway
        pass


def errlog(logger: Any, stop: threading.Event, text: str, per_s: float = ERRLOG_PER_S) -> None:
    """Log ``text`` (``{n}``: a counter) at ERROR ``per_s`` times a second until ``stop`` (``errlog``)."""
    n = 0
    while not stop.wait(1.0 / per_s):
        n += 1
        logger.error(text.format(n=n))


def process_fault(fault: str, size: float | None, logger: Any, stop: threading.Event, text: str) -> None:
    """Start the thread of a process-wide fault (``cpu``, ``leak``, else ``errlog`` logging ``text``).

    ``size`` as in ``FaultSpec.size`` (None: the kind's default).
    """
    if fault == "cpu":
        work, args = burn, (stop, CPU_SHARE if size is None else size)
    elif fault == "leak":
        work, args = leak, (stop, LEAK_MB_S if size is None else size)
    else:
        work, args = errlog, (logger, stop, text, ERRLOG_PER_S if size is None else size)
    threading.Thread(target=work, args=args, daemon=True, name=f"fault-{fault}").start()


def end_process(executors: list, spinners: list[threading.Thread], destroy: Iterable[Callable[[], None]],
                context: Any, code: int = 0) -> NoReturn:
    """Shut the executors down, destroy the nodes and the DDS participant, exit with ``code``.

    A clean shutdown can hang (an executor busy in a callback, DDS teardown): a watchdog exits
    regardless after 5 s. Destroying the participant makes peers see the nodes leave at once.
    Fast DDS's participant teardown can also spin for good in C holding the GIL (its
    ``set_listener`` waiting on a discovery callback), which no Python thread outlives: then
    faulthandler's own C thread prints every thread's stack and exits with code 1 after 6 s.
    """
    watchdog = threading.Timer(5.0, os._exit, args=(code,))
    watchdog.daemon = True
    watchdog.start()
    faulthandler.dump_traceback_later(WATCHDOG_S, exit=True)
    for ex in executors:
        ex.shutdown(timeout_sec=1.0)
    for t in spinners:  # a node still in use by a spinning executor would not really be destroyed
        t.join(2.0)
    for fn in destroy:
        fn()
    context.try_shutdown()
    context.destroy()
    sys.stdout.flush()
    os._exit(code)  # skip joining stuck executor threads
