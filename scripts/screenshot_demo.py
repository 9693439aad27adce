"""Run the demo and render its recording headless to a PNG (the README's screenshot).

Usage: .venv/bin/python scripts/screenshot_demo.py [--fault hang] [--target /obstacle_detector] [OUT.png]
Needs Debian's mesa-vulkan-drivers and libvulkan1 (software rendering).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

from stream_viz.viz.screenshot import screenshot


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("out", nargs="?", default="docs/img/demo.png", type=Path)
    p.add_argument("--fault", default="hang")
    p.add_argument("--target", default="/obstacle_detector")
    args = p.parse_args()
    with tempfile.TemporaryDirectory() as tmp:
        rrd, rep = Path(tmp) / "demo.rrd", Path(tmp) / "r.json"
        exe = Path(sys.executable).with_name("stream-viz")
        subprocess.run([str(exe), "demo", "--fault", args.fault, "--target", args.target, "--viewer", "none",
                        "--save", str(rrd), "--report", str(rep), "--db", str(Path(tmp) / "a.sqlite")],
                       check=True)
        ended = json.loads(rep.read_text())["ended_at"]
        screenshot(rrd, args.out, timeline="time", time_value=float(ended), settle=6)
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
