"""How long the served web viewer takes to show the graph in headless Chromium, with and without
the software-WebGL flags, and what a plain ``chromium --headless --screenshot`` catches.

A `Recorder` serves the demo graph (``--viewer serve`` on loopback); for each case a fresh
Chromium opens the URL and screenshots every 0.5 s until the node blue and topic orange are on
screen (`stream_viz.viz.browser.web_screenshot`). Needs Debian's ``chromium``.

    .venv/bin/python bench/bench_web.py --runs 3
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np

from stream_viz.viz import browser
from stream_viz.viz.children import free_port
from stream_viz.viz.recorder import Recorder
from stream_viz.viz.sample import demo_graph
from stream_viz.viz.screenshot import graph_drawn

SWIFTSHADER = ("--use-angle=swiftshader", "--enable-unsafe-swiftshader")


def plain_screenshot(url: str, png: Path) -> tuple[float, np.ndarray]:
    """``chromium --headless --screenshot``: seconds it took and the picture."""
    from PIL import Image

    exe = browser.chromium_executable()
    with tempfile.TemporaryDirectory() as profile:
        t0 = time.monotonic()
        cmd = [exe, "--headless", "--no-sandbox", f"--user-data-dir={profile}", "--window-size=1600,900",
               f"--screenshot={png}", url]
        subprocess.run(cmd, capture_output=True, timeout=120)
        took = time.monotonic() - t0
    return took, np.asarray(Image.open(png).convert("RGB"))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--out", type=Path, default=Path("bench/out/web"))
    args = ap.parse_args()
    reason = browser.missing()
    if reason:
        raise SystemExit(reason)
    args.out.mkdir(parents=True, exist_ok=True)
    flags = browser.CHROMIUM_FLAGS
    rec = Recorder(viewer="serve", web_port=free_port(), grpc_port=free_port(), announce=lambda s: None)
    try:
        rec.system(demo_graph(), t=time.time())
        rec.flush()
        took, img = plain_screenshot(rec.url, args.out / "plain.png")
        print(f"plain --screenshot: {took:.1f} s, {len(np.unique(img.reshape(-1, 3), axis=0))} colours, "
              f"graph drawn: {graph_drawn(img)}")
        for case, case_flags in (("swiftshader flags", flags),
                                 ("no swiftshader flags", tuple(f for f in flags if f not in SWIFTSHADER))):
            browser.CHROMIUM_FLAGS = case_flags
            secs = []
            for i in range(args.runs):
                png = args.out / f"{case.replace(' ', '_')}_{i}.png"
                shot = browser.web_screenshot(rec.url, png, graph_drawn, every=0.5, timeout=120)
                secs.append(shot.seconds if shot.ready else float("nan"))
            print(f"{case:22s} s to graph: " + "  ".join(f"{s:.1f}" for s in secs)
                  + f"   median {statistics.median(secs):.1f}")
    finally:
        browser.CHROMIUM_FLAGS = flags
        rec.close()


if __name__ == "__main__":
    main()
