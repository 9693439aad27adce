"""``stream-viz replay``: a recorded run's samples through detection, the store, the RCA and the viewer.

The samples come from a samples file (``monitor``/``demo`` ``--samples``); the monitor is the
live one with a `ReplayCollector` in place of the live collector, so the diagnosis is the live
run's. As fast as it goes by default, or at ``--speed`` times real time.
"""

from __future__ import annotations

import argparse
import threading
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from stream_viz.commands.monitor import (
    add_healthy,
    add_outputs,
    install_stop_handlers,
    linger,
    say_healthy,
    serve_at,
)

if TYPE_CHECKING:
    from stream_viz.collect.replay import ReplayCollector
    from stream_viz.config import Config
    from stream_viz.monitor import Monitor

# A replay gives each plugin call this long (live: 0.5 s): a loaded machine must not cut a call
# off and change the diagnosis; a plugin that hangs is still stopped.
PLUGIN_TIMEOUT_S = 30.0

NAME = "replay"
HELP = "replay a recorded run's samples through detection, the RCA and the viewer"


def _speed(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = -1.0
    if not value >= 0:
        raise argparse.ArgumentTypeError(f"{text!r} is not a speed (a number >= 0; 0: as fast as it goes)")
    return value


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("file", type=Path, metavar="FILE.jsonl.gz", help="a samples file (monitor/demo --samples)")
    p.add_argument("--speed", type=_speed, default=0.0, metavar="X",
                   help="X times real time (1: as recorded); 0, the default: as fast as it goes")
    add_outputs(p)
    add_healthy(p)


def run(args: argparse.Namespace) -> int:
    """Replay ``file``; write the outputs asked for and print the diagnosis."""
    from stream_viz.collect.replay import ReplayCollector
    from stream_viz.commands.demo import print_diagnosis
    from stream_viz.monitor import Monitor

    source = ReplayCollector(args.file)
    viewer = args.viewer or "none"
    try:
        config = replay_config(args.config, source.header)
        mon = Monitor(config, db=args.db, save=args.save, report=args.report, viewer=viewer,
                      serve_at=serve_at(args), group_by=args.group_by, collector=source,
                      condensed=args.condensed,
                      started_at=source.header.get("started_at"), plugin_timeout_s=PLUGIN_TIMEOUT_S,
                      healthy=args.healthy)
    except BaseException:
        source.close()
        raise
    stop = threading.Event()
    install_stop_handlers(stop)
    version = source.header.get("stream_viz", "an unknown version")
    mon.progress.say(f"replaying {args.file} (recorded by stream-viz {version})")
    last_t = None
    try:
        last_t = replay(mon, source, args.speed, stop)
    finally:
        # The note at the end of the file (a complete run): when it ended, the fault injected.
        end = source.notes.get("end") or {}
        mon.injected = end.get("injected") or None
        report = mon.close(keep_view=viewer == "serve", ended_at=end.get("ended_at") or last_t)
    if mon.samples == 0:
        mon.progress.say(f"{args.file} holds no samples")
    if source.truncated:
        mon.progress.say(f"{args.file} ends mid-way (its run was killed?): replayed its {mon.samples} "
                         "complete samples")
    print_diagnosis(report, mon)
    say_healthy(mon)
    if args.report:
        mon.progress.say(f"report: {args.report}")
    linger(mon, viewer)
    return 0


def replay_config(path: Path | None, header: dict[str, Any]) -> Config:
    """``--config`` if given, else the configuration the run was recorded with."""
    from stream_viz.config import load_config

    if path is not None:
        return load_config(path)
    recorded = header.get("config") or {}
    if recorded.get("toml") is None:
        return load_config(None)
    return load_config(recorded.get("path") or "recorded configuration", text=recorded["toml"])


def replay(mon: Monitor, source: ReplayCollector, speed: float, stop: threading.Event) -> float | None:
    """Step ``mon`` through every sample of ``source`` (``speed`` × real time; 0: at once) until
    the samples end or ``stop`` is set; return the last sample's time."""
    first, began = source.next_t, time.monotonic()
    last = None
    while not source.done and not stop.is_set():
        if speed > 0:
            wait = (source.next_t - first) / speed - (time.monotonic() - began)
            if wait > 0 and stop.wait(wait):
                break
        last = source.next_t
        mon.step()
    return last
