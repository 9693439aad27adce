"""Where the ``.rrd`` bytes go: the recording's size per entity path, healthy and after a crash.

One synthetic recording of a generated system (as `bench_scale_ab.py`: ``--nodes``, ``--samples``,
the process whose loss silences the most topics killed at ``--crash-at``) is replayed through the
real `Monitor` with a ``.rrd`` written. After sample ``--warmup`` − 1 and after the last sample
before the crash the recording is flushed and a copy of the file so far is kept: the chunks past
a copy's were written in the next phase (a file is written in order).

Each chunk's size is its Arrow record batch as written (IPC stream, LZ4-compressed as Rerun does),
summed per entity path with member names folded into ``*`` (``/metrics/topic/*/theta``); the
blueprint's store is counted apart. The sums are scaled to the file's real growth over the phase
(the estimate and the real size are both printed) and given as MB an hour at one sample a second.

    .venv/bin/python bench/bench_rrd_entities.py --nodes 1000 --samples 200 --crash-at 40
"""

from __future__ import annotations

import argparse
import shutil
import sys
import tempfile
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FOLD = {"/metrics": 2, "/health": 2, "/namespace": 1, "/process": 1, "/host": 1, "/hosts": 1}


def entity_key(path: str) -> str:
    """Fold member and group names of ``path`` into ``*``, keeping the kind and the leaf:
    ``/metrics/topic/a/b/theta`` -> ``/metrics/topic/*/theta``, ``/health/node/x`` -> ``/health/node/*``."""
    parts = [p for p in path.split("/") if p]
    if not parts:
        return "/"
    keep = FOLD.get("/" + parts[0])
    if keep is None or len(parts) <= keep:
        return path
    leaf = (
        parts[-1]
        if parts[0] == "metrics" and parts[-1] in ("theta", "alerts") and len(parts) > keep + 1
        else None
    )
    return "/" + "/".join([*parts[:keep], "*", *([leaf] if leaf else [])])


def chunk_bytes(rb) -> int:
    """The record batch as an LZ4-compressed Arrow IPC stream (how a chunk is stored, near enough)."""
    import pyarrow as pa

    sink = pa.BufferOutputStream()
    with pa.ipc.new_stream(sink, rb.schema) as w:
        w.write_batch(rb)
    return len(pa.compress(sink.getvalue(), codec="lz4", asbytes=True))


def sizes(path: Path, blueprint: bool = False) -> list[tuple[str, bool, int, int]]:
    """``(entity path, static, rows, bytes)`` of each chunk of ``path`` (its recording, or its
    blueprint), in file order."""
    from rerun.chunk import RrdReader

    reader = RrdReader(str(path))
    store = None
    if blueprint:
        bps = reader.blueprints()
        if not bps:
            return []
        store = bps[0]
    out = []
    for chunk in reader.stream(store=store):
        rb = chunk.to_record_batch()
        out.append((chunk.entity_path, chunk.is_static, rb.num_rows, chunk_bytes(rb)))
    return out


def breakdown(chunks: list[tuple[str, bool, int, int]]) -> dict[str, list[int]]:
    """entity key -> [chunks, rows, bytes]."""
    out: dict[str, list[int]] = defaultdict(lambda: [0, 0, 0])
    for path, static, n, b in chunks:
        row = out[entity_key(path) + (" (static)" if static else "")]
        row[0] += 1
        row[1] += n
        row[2] += b
    return dict(out)


def run(nodes: int, samples: int, crash_at: int, warmup: int, work: Path) -> dict:
    sys.path.insert(0, str(ROOT / "bench"))
    from bench_replay import commit, record, replay

    recording = work / "g.jsonl.gz"
    members, _, group = record(nodes, samples, crash_at, recording)
    marks = {warmup - 1: "warm", min(crash_at, samples) - 1: "crash", samples - 1: "end"}
    copies: dict[str, tuple[Path, int]] = {}

    def mark(mon, i: int) -> None:
        if i in marks:
            mon.view._flush_metrics()
            mon.view.rec.flush()
            parts = sorted(work.glob("r*.rrd"))
            if len(parts) != 1:
                raise SystemExit("more than one file part: run with one part (the default replay has one)")
            copy = work / f"{marks[i]}.rrd"
            shutil.copyfile(parts[0], copy)
            copies[marks[i]] = (copy, copy.stat().st_size)

    rrd = work / "r.rrd"
    replay(recording, work, crash_at, after=mark)
    return {"commit": commit(), "members": members, "group": group, "rrd": rrd, "copies": copies}


def table(phases: dict[str, tuple[dict[str, list[int]], int, int]]) -> str:
    """Markdown: per entity key, MB an hour in each phase (the estimate scaled to the file's real
    growth over the phase) and rows logged per sample."""
    mbh = {}  # phase -> MB an hour per estimated byte
    for p, (bd, n, real) in phases.items():
        est = sum(v[2] for v in bd.values()) or 1
        mbh[p] = real / est / n * 3600 / 1e6
    keys = sorted(
        {k for bd, *_ in phases.values() for k in bd},
        key=lambda k: -max(bd.get(k, [0, 0, 0])[2] * mbh[p] for p, (bd, *_) in phases.items()),
    )
    lines = [
        "| entity | " + " | ".join(f"{p} MB/h | {p} rows/sample" for p in phases) + " |",
        "|---|" + "---|---|" * len(phases),
    ]
    for k in keys:
        cells = []
        for p, (bd, n, _) in phases.items():
            _, r, b = bd.get(k, [0, 0, 0])
            cells.append(f"{b * mbh[p]:.1f} | {r / n:.1f}")
        lines.append(f"| `{k}` | " + " | ".join(cells) + " |")
    lines.append(
        "| **file (real)** | "
        + " | ".join(f"**{real / n * 3600 / 1e6:.1f}** | " for _, n, real in phases.values())
        + " |"
    )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--nodes", type=int, default=1000)
    ap.add_argument("--samples", type=int, default=200)
    ap.add_argument("--crash-at", type=int, default=40)
    ap.add_argument("--warmup", type=int, default=20)
    ap.add_argument("--keep", type=Path, help="copy the .rrd files here")
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench_rrd_entities_") as t:
        work = Path(t)
        got = run(args.nodes, args.samples, args.crash_at, args.warmup, work)
        whole = sizes(got["rrd"])
        bp = sizes(got["rrd"], blueprint=True)
        (warm, warm_size), (crash, crash_size) = got["copies"]["warm"], got["copies"]["crash"]
        end_size = got["copies"]["end"][1]
        n_warm, n_crash = len(sizes(warm)), len(sizes(crash))
        b_warm, b_crash = len(sizes(warm, True)), len(sizes(crash, True))
        total = got["rrd"].stat().st_size
        healthy = breakdown(whole[n_warm:n_crash])
        healthy.update(breakdown([("(blueprint) " + p, *r) for p, *r in bp[b_warm:b_crash]]))
        n_healthy = min(args.crash_at, args.samples) - args.warmup
        phases = {"healthy": (healthy, n_healthy, crash_size - warm_size)}
        if args.crash_at < args.samples:
            after = breakdown(whole[n_crash:])
            after.update(breakdown([("(blueprint) " + p, *r) for p, *r in bp[b_crash:]]))
            # The footer (an index entry per chunk of the file) is written at close: not an hour's.
            phases["after crash"] = (after, args.samples - args.crash_at, end_size - crash_size)
        print(
            f"{args.nodes} nodes, {got['members']} members, {args.samples} samples, crash of "
            f"{got['group']} at {args.crash_at}; commit {got['commit']}; healthy: samples {args.warmup}–"
            f"{min(args.crash_at, args.samples) - 1}"
        )
        print(table(phases))
        est = {p: sum(v[2] for v in bd.values()) for p, (bd, *_) in phases.items()}
        print(
            "estimated (compressed IPC) / real bytes per phase: "
            + ", ".join(f"{p} {est[p] / 1e6:.2f} / {phases[p][2] / 1e6:.2f} MB" for p in phases)
        )
        print(
            f"whole file {total / 1e6:.2f} MB, of which written at close (footer, last report): "
            f"{(total - end_size) / 1e3:.1f} kB, {(total - end_size) / len(whole):.0f} B per chunk; "
            f"chunks per sample: healthy {(n_crash - n_warm) / n_healthy:.1f}, after the crash "
            f"{(len(whole) - n_crash) / max(args.samples - args.crash_at, 1):.1f}; "
            f"blueprint store {len(bp)} chunks"
        )
        if args.keep:
            args.keep.mkdir(parents=True, exist_ok=True)
            for p in (got["rrd"], warm, crash):
                shutil.copyfile(p, args.keep / p.name)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
