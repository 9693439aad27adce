"""The monitor's cost and ``.rrd`` size on one synthetic recording, this tree against an earlier commit.

One synthetic recording of a generated system (`stream_viz.demo.synthetic`, as in
`bench_replay.py`: one sample a second, at ``--crash-at`` the process whose loss silences the most
topics is killed; ``--crash-at`` past ``--samples``: no crash) is replayed through the real
`Monitor` with a ``.rrd`` written, once with the code of ``--base`` (a git worktree of that commit
put first on PYTHONPATH) and once with this tree, alternating which goes first, each in its own
process. Printed per version: process CPU per step and sample (healthy: samples 5 to the crash;
faulted: from the crash on), the ``.rrd`` size (every part) grown over each phase as MB an
hour (healthy from ``--warmup``: the layout settles first), and whether the two reports name the
same alerts and root causes; then the ratios this / base.

    .venv/bin/python bench/bench_scale_ab.py --base 2ca5774 --nodes 1000 --samples 90
    .venv/bin/python bench/bench_scale_ab.py --base 2ca5774 --samples 300 --crash-at 400   # healthy
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STEPS = ("record", "detect", "store", "diagnose", "show")


def child(recording: Path, out: Path, workdir: Path, marks: str) -> None:
    """Replay ``recording`` with the stream_viz first on the path; write what was measured to ``out``.

    After each sample of ``marks`` the pending metrics and the recording are flushed and the
    ``.rrd`` size noted (the size grown between two marks is what those samples wrote)."""
    sys.path.insert(0, str(ROOT / "bench"))
    from bench_replay import replay

    sizes: dict[int, int] = {}

    def mark(mon, i: int) -> None:
        if i in at:
            mon.view._flush_metrics()
            mon.view.rec.flush()
            sizes[i] = rrd_size(workdir)

    at = {int(x) for x in marks.split(",")}
    run = replay(recording, workdir, None, after=mark)
    rrd = rrd_size(workdir)
    report = {k: v for k, v in run["report"].items() if k != "ended_at"}  # ended_at: the replay's clock
    out.write_text(json.dumps({"cpu": run["cpu"], "loop": run["loop"], "rrd": rrd, "sizes": sizes,
                               "causes": run["causes"], "alerts": run["alerts"], "report": report}))


def rrd_size(workdir: Path) -> int:
    return sum(p.stat().st_size for p in workdir.glob("r*.rrd"))


def code_path(tree: Path, tmp: Path) -> str:
    """PYTHONPATH that imports stream_viz, its plugins and blueprints from ``tree``."""
    pkgs = tmp / f"pkgs_{tree.name}"
    pkgs.mkdir(exist_ok=True)
    for name, sub in (("stream_viz_plugins", "plugins"), ("stream_viz_blueprints", "blueprints")):
        if not (pkgs / name).exists():
            (pkgs / name).symlink_to(tree / sub)
    return os.pathsep.join([str(tree), str(pkgs)])


def ms(xs: list[float], sl: slice) -> float:
    return 1e3 * statistics.fmean(xs[sl]) if xs[sl] else float("nan")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--base", required=True, help="the earlier commit")
    ap.add_argument("--nodes", type=int, default=1000)
    ap.add_argument("--samples", type=int, default=90)
    ap.add_argument("--crash-at", type=int, default=40)
    ap.add_argument("--rounds", type=int, default=1)
    ap.add_argument("--warmup", type=int, default=20, help="samples before the healthy size is measured")
    ap.add_argument("--child", nargs=4, metavar=("RECORDING", "OUT", "WORKDIR", "MARKS"),
                    help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.child:
        child(*map(Path, args.child[:3]), args.child[3])
        return 0
    sys.path.insert(0, str(ROOT / "bench"))
    from bench_replay import commit, record

    with tempfile.TemporaryDirectory(prefix="bench_scale_ab_") as t:
        tmp = Path(t)
        base = tmp / "base"
        subprocess.run(["git", "worktree", "add", "--detach", str(base), args.base], cwd=ROOT, check=True,
                       capture_output=True)
        try:
            recording = tmp / "g.jsonl.gz"
            members, _, group = record(args.nodes, args.samples, args.crash_at, recording)
            print(f"{args.nodes} nodes, {members} members, {args.samples} samples, crash of {group} at "
                  f"{args.crash_at}: base {args.base} vs this tree ({commit()})", flush=True)
            got: dict[str, list[dict]] = {"base": [], "this": []}
            marks = f"{args.warmup - 1},{min(args.crash_at, args.samples) - 1},{args.samples - 1}"
            for i in range(args.rounds):
                order = [("base", base), ("this", ROOT)] if i % 2 == 0 else [("this", ROOT), ("base", base)]
                for name, tree in order:
                    work = tmp / f"{name}_{i}"
                    work.mkdir()
                    out = work / "out.json"
                    subprocess.run([sys.executable, str(Path(__file__).resolve()), "--base", args.base,
                                    "--child", str(recording), str(out), str(work), marks],
                                   env=dict(os.environ, PYTHONPATH=code_path(tree, tmp)), cwd=tree,
                                   check=True)
                    got[name].append(json.loads(out.read_text()))
            print(summary(got, args.samples, args.crash_at, args.warmup))
        finally:
            subprocess.run(["git", "worktree", "remove", "--force", str(base)], cwd=ROOT, capture_output=True)
    return 0


def mb_an_hour(run: dict, phase: str, samples: int, crash_at: int, warmup: int) -> float:
    """The ``.rrd`` grown over the phase's samples, in MB an hour at one sample a second."""
    sizes = {int(k): v for k, v in run["sizes"].items()}
    end = min(crash_at, samples) - 1
    if phase == "healthy":
        return (sizes[end] - sizes[warmup - 1]) / (end - warmup + 1) / 1e6 * 3600
    # To the last sample's mark, as the healthy phase: the footer written at close (an index
    # entry for every chunk of the file, both phases) is printed apart (`closed_kb`).
    last = sizes.get(samples - 1, run["rrd"])
    return (last - sizes[end]) / (samples - end - 1) / 1e6 * 3600


def closed_kb(run: dict, samples: int) -> float:
    """What the file grew by at close (its footer), in kB."""
    sizes = {int(k): v for k, v in run["sizes"].items()}
    return (run["rrd"] - sizes.get(samples - 1, run["rrd"])) / 1e3


def summary(got: dict[str, list[dict]], samples: int, crash_at: int, warmup: int) -> str:
    phases = {"healthy": slice(5, min(crash_at, samples))}
    if crash_at < samples:
        phases["faulted"] = slice(crash_at, samples)
    lines = ["| version | phase | " + " | ".join(STEPS) + " | main loop | .rrd MB an hour |",
             "|---|---|" + "---|" * (len(STEPS) + 2)]
    means: dict[tuple[str, str], list[float]] = {}
    for name, runs in got.items():
        for phase, sl in phases.items():
            row = [statistics.fmean(ms(r["cpu"][s], sl) for r in runs) for s in STEPS]
            row.append(sum(row))
            row.append(statistics.fmean(mb_an_hour(r, phase, samples, crash_at, warmup) for r in runs))
            means[name, phase] = row
            lines.append(f"| {name} | {phase} | " + " | ".join(f"{x:.1f}" for x in row) + " |")
    for phase in phases:
        b, n = means["base", phase], means["this", phase]
        lines.append(f"| this / base | {phase} | " + " | ".join(
            f"{y / x:.2f}" if x > 0.05 else "–" for x, y in zip(b, n, strict=True)) + " |")
    b, n = got["base"][0], got["this"][0]
    lines.append(f".rrd size, whole run: base {b['rrd'] / 1e6:.1f} MB, this {n['rrd'] / 1e6:.1f} MB; MB an "
                 f"hour: the size grown over the phase's samples (healthy: from sample {warmup}; both to the "
                 f"phase's last sample, before close) × 3600; written at close (footer): base "
                 f"{closed_kb(b, samples):.0f} kB, this {closed_kb(n, samples):.0f} kB")
    same = {k: b["report"][k] == n["report"][k] for k in ("alerts", "root_causes", "incidents", "iterations")}
    lines.append(f"alerts stored per sample identical: {b['alerts'] == n['alerts']}; report identical "
                 f"(ended_at aside): {b['report'] == n['report']} ({same}); top causes {n['causes'][:3]}")
    return "\n".join(lines)


if __name__ == "__main__":
    raise SystemExit(main())
