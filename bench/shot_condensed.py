"""The condensed system graph of a 1,000-node system with a crash, replayed and rendered headless.

``.venv/bin/python -m bench.shot_condensed --png docs/img/condensed_1000.png``

A generated system (`stream_viz.demo.generated`, seed 0) of ``--nodes`` nodes in ``--namespaces``
subsystems (``/perception``, ``/planning``, …) is recorded without running it
(`stream_viz.demo.synthetic`, one sample a second; at ``--crash-at`` the process whose loss
silences the most topics is killed), replayed through the real `Monitor` (default
configuration, a ``.rrd`` written), and the end of the recording rendered at ``--size``
(2400×1350: at 1600×900 the graph's labels are too small to read) with its default blueprint
(`stream_viz.viz.screenshot`). Prints the top root causes, the ``.rrd`` size
and the paths written.
"""

from __future__ import annotations

import argparse
import os
import tempfile
from pathlib import Path


def record(nodes: int, namespaces: int, samples: int, crash_at: int, path: Path) -> str:
    """Write the synthetic samples file of the system; return the crashed process group."""
    from stream_viz.collect.samples_file import SamplesWriter
    from stream_viz.demo.generated import generate
    from stream_viz.demo.synthetic import Crash, silenced
    from stream_viz.demo.synthetic import samples as synthesise

    topo = generate(nodes, namespaces=namespaces)
    group = max((g.name for g in topo.groups), key=lambda g: (len(silenced(topo, g)), g))
    writer = SamplesWriter(path, {"started_at": 1.7e9 - 1, "generated": topo.name, "crash": group})
    for s in synthesise(topo, samples, Crash(group, crash_at)):
        writer.write(s)
    writer.close()
    return group


def main(argv: list[str] | None = None) -> int:
    from stream_viz.collect.replay import ReplayCollector
    from stream_viz.commands.replay import PLUGIN_TIMEOUT_S, replay_config
    from stream_viz.monitor import Monitor
    from stream_viz.progress import Progress
    from stream_viz.viz.screenshot import screenshot

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--nodes", type=int, default=1000)
    ap.add_argument("--namespaces", type=int, default=12)
    ap.add_argument("--samples", type=int, default=70)
    ap.add_argument("--crash-at", type=int, default=30)
    ap.add_argument("--png", type=Path)
    ap.add_argument("--rrd", type=Path, help="keep the recording here (default: a temporary file)")
    ap.add_argument("--condensed", choices=("auto", "on", "off"), default="auto")
    ap.add_argument("--size", default="2400x1350", help="the viewer window, WIDTHxHEIGHT")
    args = ap.parse_args(argv)
    tmp = Path(tempfile.mkdtemp(prefix="stream_condensed_"))
    rrd = args.rrd or tmp / "run.rrd"
    group = record(args.nodes, args.namespaces, args.samples, args.crash_at, tmp / "run.jsonl.gz")
    source = ReplayCollector(tmp / "run.jsonl.gz")
    mon = Monitor(replay_config(None, source.header), db=tmp / "a.sqlite", save=rrd, collector=source,
                  started_at=source.header.get("started_at"), plugin_timeout_s=PLUGIN_TIMEOUT_S,
                  progress=Progress(open(os.devnull, "w")), condensed=args.condensed)
    while not source.done:
        mon.step()
    report = mon.close()
    for rc in report["root_causes"][:3]:
        print(f"{rc['member']}  score {rc['score']:.2f}")
    print(f"crashed process group {group}; recording {rrd} ({rrd.stat().st_size / 1e6:.1f} MB, "
          f"{args.samples} s)")
    if args.png:
        print(f"screenshot {screenshot(rrd, args.png, size=_size(args.size), settle=6.0)}")
    return 0


def _size(text: str) -> tuple[int, int]:
    w, _, h = text.partition("x")
    return int(w), int(h)


if __name__ == "__main__":
    raise SystemExit(main())
