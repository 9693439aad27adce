"""Render a saved recording in a headless Rerun viewer and save a PNG (for docs and checks).

Starts ``rerun --headless`` (software Vulkan: Debian ``mesa-vulkan-drivers libvulkan1``) in its
own process group, opens the ``.rrd`` through ``rerun.experimental.ViewerClient``, sets the time
and saves a screenshot; the viewer is always stopped afterwards. Also the checks of what a
picture shows (`colour_pixels`, `hue_pixels`, `graph_drawn`) that the render tests assert.
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from stream_viz.errors import OutputError
from stream_viz.viz.children import end_group, free_port
from stream_viz.viz.style import KIND_COLOR


def rerun_executable() -> str | None:
    """Return the ``rerun`` viewer executable: on PATH, else beside this Python (a venv's bin/)."""
    exe = shutil.which("rerun")
    if exe is None:
        cand = Path(sys.executable).with_name("rerun")
        exe = str(cand) if cand.is_file() and os.access(cand, os.X_OK) else None
    return exe


def screenshot(
    rrd: str | Path,
    png: str | Path,
    timeline: str | None = None,
    time_value: float | int | None = None,
    size: tuple[int, int] = (1600, 900),
    blueprint: str | Path | None = None,
    timeout: float = 60.0,
    settle: float = 1.0,
) -> Path:
    """Render ``rrd`` in a headless viewer and write ``png``; return the PNG path.

    Parameters
    ----------
    rrd, png : path
        The recording to open and the image to write.
    timeline, time_value : optional
        Show this point of this timeline (``rca_iteration`` and ``j``, or ``time`` and seconds).
    size : (int, int)
        Window size in pixels.
    blueprint : path, optional
        An ``.rbl`` to apply instead of the recording's default blueprint.
    settle : float
        Seconds to wait before the shot (≈6 lets the viewer's start-up notifications fade).
    """
    exe = rerun_executable()
    if exe is None:
        raise OutputError("screenshot: the 'rerun' executable is not on PATH")
    rrd, png = Path(rrd).resolve(), Path(png).resolve()
    if not rrd.is_file():
        raise OutputError(f"screenshot: no recording at {rrd}")
    from rerun.experimental import ViewerClient

    port = free_port()
    env = dict(os.environ, CI=os.environ.get("CI", "1"))  # no viewer analytics
    proc = subprocess.Popen(
        [exe, "--headless", "--hide-welcome-screen", f"--window-size={size[0]}x{size[1]}", f"--port={port}"],
        stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True, env=env)
    try:
        url = f"rerun+http://127.0.0.1:{port}/proxy"
        deadline = time.monotonic() + timeout
        client, last = None, None
        while client is None:
            if proc.poll() is not None:
                err = proc.stderr.read().decode(errors="replace")[-2000:] if proc.stderr else ""
                raise OutputError(f"screenshot: the headless viewer exited ({proc.returncode}): {err}")
            try:
                client = ViewerClient.connect(url)
            except Exception as e:  # not listening yet
                last = e
                if time.monotonic() > deadline:
                    raise OutputError(f"screenshot: cannot reach the headless viewer: {last}") from e
                time.sleep(0.3)
        client.open(str(rrd))
        if blueprint is not None:
            client.open(str(Path(blueprint).resolve()))
        if timeline is not None:
            _set_time(client, timeline, time_value)
        time.sleep(settle)  # let the viewer lay out and draw
        png.parent.mkdir(parents=True, exist_ok=True)
        client.save_screenshot(str(png))
    finally:
        end_group(proc)
    if not png.is_file():
        raise OutputError(f"screenshot: the viewer wrote no image to {png}")
    return png


def _set_time(client, timeline: str, value: float | int | None) -> None:
    if value is None:
        client.set_time(timeline, play_state="paused")
    elif isinstance(value, int):
        client.set_time(timeline, sequence=value, play_state="paused")
    else:
        client.set_time(timeline, timestamp=value, play_state="paused")


# -- what a picture shows (checks on screenshots, headless viewer or browser) --------------------
def colour_pixels(img: np.ndarray, rgb: tuple[int, int, int], tol: int = 40) -> int:
    """Return how many pixels of ``img`` (H, W, 3) are within ``tol`` (sum of |channel diffs|) of ``rgb``."""
    return int((np.abs(img.astype(int) - np.array(rgb)).sum(axis=2) < tol).sum())


def hue_pixels(img: np.ndarray, rgb: tuple[int, int, int], tol: float = 0.06) -> int:
    """Return how many pixels have ``rgb``'s hue (channel shares within ``tol``) and at least half
    its brightness: the viewer draws some things (lane bars) in a shade of the logged colour."""
    px = img.reshape(-1, 3).astype(float)
    total = px.sum(axis=1)
    want = np.asarray(rgb, dtype=float)
    bright = total > 0.5 * want.sum()
    shares = px[bright] / total[bright, None]
    return int((np.abs(shares - want / want.sum()).sum(axis=1) < tol).sum())


def graph_drawn(img: np.ndarray, min_pixels: int = 100, tol: int = 80) -> bool:
    """Return True if the system graph is on screen: labels in the node blue and the topic orange
    (`style.KIND_COLOR`), and a picture of many colours (not a loading screen).

    The viewer's top bar is left out (its "Software rasterizer" warning is amber); ``tol`` is wide
    because labels are small anti-aliased text, blended into the background at their edges.
    """
    body = img[img.shape[0] // 20:]
    return (colour_pixels(body, KIND_COLOR["node"], tol) > min_pixels
            and colour_pixels(body, KIND_COLOR["topic"], tol) > min_pixels
            and len(np.unique(body.reshape(-1, 3)[::7], axis=0)) > 200)
