"""The recording as a person sees it: a real headless viewer, a vanished viewer, the web server."""

from __future__ import annotations

import ctypes.util
import functools
import os
import signal
import socket
import subprocess
import sys
import time
import urllib.request

import numpy as np
import psutil
import pytest
from rerun.chunk import RrdReader
from stream_viz_blueprints.default import build_blueprint

from stream_viz.errors import OutputError
from stream_viz.model.theta import make_theta
from stream_viz.records import Alert
from stream_viz.testing import wait_for
from stream_viz.viz import paths
from stream_viz.viz.children import free_port
from stream_viz.viz.health import STATE_COLOR
from stream_viz.viz.recorder import TELEMETRY_ENV, Recorder, disable_rerun_telemetry
from stream_viz.viz.sample import demo_graph
from stream_viz.viz.screenshot import colour_pixels, hue_pixels, rerun_executable, screenshot
from stream_viz.viz.serve import check_free
from stream_viz.viz.style import KIND_COLOR, SEVERITY_COLOR
from tests.viz.rrd import rows

T0 = 1_700_000_000.0


def _renderer_missing() -> str | None:
    if rerun_executable() is None:
        return "the 'rerun' viewer executable is not installed"
    if ctypes.util.find_library("vulkan") is None:
        return "no Vulkan loader (Debian: apt-get install mesa-vulkan-drivers libvulkan1)"
    return None


def _demo_recording(path, collapse=True):
    G = demo_graph()
    it = {"j": 1, "t": T0 + 5, "subgraph": ["topic:/objects", "node:/planner"],
          "watchlist": ["node:/controller"], "edges": [["topic:/objects", "node:/planner"]],
          "alert": "node:/planner"}
    rc = [{"member": "node:/detector", "score": 0.9,
           "trajectory": ["node:/planner", "topic:/objects", "node:/detector"]}]
    with Recorder(save=path, blueprint=build_blueprint(collapse_panels=collapse)) as r:
        r.system(G, t=T0)
        r.metrics([(T0 + i, G) for i in range(5)])
        r.rca(G, it, rc)
    return G


def test_rendered_recording_shows_the_graph(tmp_path):
    reason = _renderer_missing()
    if reason:
        pytest.skip(f"headless renderer unavailable: {reason}")
    rrd, png = tmp_path / "demo.rrd", tmp_path / "demo.png"
    _demo_recording(rrd)
    screenshot(rrd, png, timeline=paths.RCA_ITERATION, time_value=1)
    Image = pytest.importorskip("PIL.Image", reason="Pillow decodes the PNG")

    img = np.asarray(Image.open(png).convert("RGB"))
    assert img.shape[0] >= 600 and img.shape[1] >= 1000
    colors = {tuple(int(c) for c in px) for px in img.reshape(-1, 3)[::7]}
    assert len(colors) > 200, "the picture is nearly blank"
    # Node labels are drawn in the kind colours (node blue, topic orange): both present on screen.
    for kind in ("node", "topic"):
        assert colour_pixels(img, KIND_COLOR[kind]) > 50, f"no {kind} colour {KIND_COLOR[kind]} in the graph"


def _diagnosed_recording(path):
    """A minute of the demo robot: /objects' rate falls at 30 s, the planner warns, one diagnosis."""
    G = demo_graph()
    with Recorder(save=path, blueprint=functools.partial(build_blueprint, collapse_panels=True)) as r:
        r.system(G, t=T0)
        batch = []
        for i in range(60):
            late = i > 30
            for m, d in G.nodes(data=True):
                if d.get("kind") == "topic":
                    rate = 2.0 if late and m == "topic:/objects" else 10.0
                    d["theta"] = make_theta("topic", {"rate_hz": rate})
                elif d.get("kind") == "process":
                    cpu = 80.0 if late else 20.0
                    d["theta"] = make_theta("process", {"cpu_percent": cpu, "rss_mb": 100.0})
            batch.append((T0 + i, G.copy()))
        r.metrics(batch)
        r.alerts([Alert("topic:/objects", "topic_rate", T0 + 31 + 5 * k, "error", "rate fell", {"value": 2.0})
                  for k in range(5)] + [Alert("node:/planner", "rosout", T0 + 40, "warn", "slow")])
        r.system(G, t=T0 + 59)
        it = {"j": 1, "t": T0 + 31, "subgraph": ["topic:/objects", "node:/planner"], "watchlist": [],
              "edges": [["topic:/objects", "node:/planner"]], "alert": "topic:/objects"}
        r.rca(G, it, [{"member": "node:/detector", "score": 0.9,
                       "trajectory": ["node:/planner", "topic:/objects", "node:/detector"]}])
        assert list(r.diagnosis) == ["node:/detector", "node:/planner", "topic:/objects"]


def test_rendered_diagnosis_opens_on_lanes_and_plots_of_its_members(tmp_path):
    reason = _renderer_missing()
    if reason:
        pytest.skip(f"headless renderer unavailable: {reason}")
    Image = pytest.importorskip("PIL.Image", reason="Pillow decodes the PNG")
    rrd, png = tmp_path / "diag.rrd", tmp_path / "diag.png"
    _diagnosed_recording(rrd)
    screenshot(rrd, png, timeline=paths.TIME, time_value=T0 + 59, settle=3)
    img = np.asarray(Image.open(png).convert("RGB"))
    h, w, _ = img.shape
    metrics = img[int(h * 0.6):, : int(w * 0.42)]  # the lower left panel: the metrics tabs
    # The Diagnosis tab is the one shown: the lanes of /objects (error, then ok) and /planner
    # (warn, then ok) in their severity colours, and the plots' alert crosses.
    assert hue_pixels(metrics, SEVERITY_COLOR["error"]) > 1000
    assert hue_pixels(metrics, SEVERITY_COLOR["warn"]) > 500
    assert hue_pixels(metrics, STATE_COLOR["ok"]) > 200
    # The graph above keeps its colours (nodes blue, topics orange).
    graph = img[: int(h * 0.55)]
    assert hue_pixels(graph, KIND_COLOR["node"]) > 50 and hue_pixels(graph, KIND_COLOR["topic"]) > 50


def test_a_viewer_that_goes_away_does_not_stop_the_file(tmp_path):
    exe = rerun_executable()
    if exe is None or ctypes.util.find_library("vulkan") is None:
        pytest.skip("needs the rerun viewer and a Vulkan loader to run a viewer to connect to")
    port = free_port()
    viewer = subprocess.Popen([exe, "--headless", "--hide-welcome-screen", f"--port={port}"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                              start_new_session=True, env=dict(os.environ, CI="1"))
    rrd = tmp_path / "tee.rrd"
    try:
        time.sleep(2.0)
        r = Recorder(viewer=f"rerun+http://127.0.0.1:{port}/proxy", save=rrd)
        G = demo_graph()
        r.system(G, t=T0)
        r.metrics([(T0 + i, G) for i in range(3)])
        r.flush()
    finally:
        os.killpg(viewer.pid, signal.SIGKILL)
        viewer.wait(10)
    r.metrics([(T0 + i, G) for i in range(3, 6)])  # viewer gone: no exception
    r.close(timeout=3)
    assert r.url.endswith("/proxy")
    theta = [row for row in rows(rrd)["/metrics/topic/image/theta"] if "Scalars:scalars" in row]
    # Both batches are in the file: the same θ each sample, so each batch sends its run's ends.
    assert [row["time"] // 10**9 - int(T0) for row in theta] == [0, 2, 3, 5]
    assert paths.SYSTEM in RrdReader(str(rrd)).store().schema().entity_paths()  # footer written


def _listening(pid: int, ports: set[int]) -> set[tuple[str, int]]:
    procs = [psutil.Process(pid), *psutil.Process(pid).children(recursive=True)]
    return {(c.laddr.ip, c.laddr.port) for p in procs for c in p.net_connections(kind="tcp")
            if c.status == psutil.CONN_LISTEN and c.laddr.port in ports}


@pytest.mark.parametrize("bind", ["127.0.0.1", "0.0.0.0"])
def test_serve_listens_on_loopback_unless_told_and_gives_the_url(tmp_path, bind):
    if rerun_executable() is None:
        pytest.skip("the 'rerun' executable is not installed")
    grpc_port, web_port = free_port(), free_port()
    said = []
    r = Recorder(viewer="serve", grpc_port=grpc_port, web_port=web_port, save=tmp_path / "s.rrd",
                 announce=said.append, bind=bind)
    try:
        assert r.url == (f"http://127.0.0.1:{web_port}/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A{grpc_port}"
                         "%2Fproxy")
        assert said[0] == f"Rerun web viewer: {r.url}"
        assert len(said) == (1 if bind == "127.0.0.1" else 2)  # exposed: how to reach it from elsewhere
        # The page and its data on the same address: loopback by default, every interface if asked.
        assert _listening(r.server.proc.pid, {web_port, grpc_port}) == {(bind, web_port), (bind, grpc_port)}
        with urllib.request.urlopen(f"http://127.0.0.1:{web_port}/", timeout=10) as page:
            assert page.status == 200 and b"<canvas" in page.read().lower()
        r.system(demo_graph(), t=T0)
        server = r.server.proc
    finally:
        r.close()
    assert server.poll() is not None  # the server went with the run
    with pytest.raises(OSError):
        socket.create_connection(("127.0.0.1", web_port), timeout=2).close()
    assert paths.SYSTEM in rows(tmp_path / "s.rrd")


def test_a_served_viewer_ends_with_a_monitor_killed_by_sigkill():
    if rerun_executable() is None:
        pytest.skip("the 'rerun' executable is not installed")
    web, grpc = free_port(), free_port()
    code = ("import time; from stream_viz.viz.recorder import Recorder; "
            f"r = Recorder(viewer='serve', web_port={web}, grpc_port={grpc}, announce=lambda s: None); "
            "print(r.server.proc.pid, flush=True); time.sleep(120)")
    p = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        server = psutil.Process(int(p.stdout.readline()))
        assert server.is_running()
    finally:
        p.kill()  # SIGKILL to the monitor only, not to its process group
        p.wait(10)

    def ended() -> bool:
        try:
            return server.status() == psutil.STATUS_ZOMBIE
        except psutil.NoSuchProcess:
            return True

    assert wait_for(ended, 20), "the served viewer outlived its monitor"

    def free() -> bool:
        try:
            check_free("127.0.0.1", web)
            check_free("127.0.0.1", grpc)
        except OutputError:
            return False
        return True

    # the ports are free for the next run (a dead server's sockets may take a moment to go)
    assert wait_for(free, 10), [(c.pid, c.status, c.laddr) for c in psutil.net_connections("tcp")
                                if c.laddr and c.laddr.port in (web, grpc)]


def test_serve_refuses_a_port_already_taken(tmp_path):
    if rerun_executable() is None:
        pytest.skip("the 'rerun' executable is not installed")
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(OutputError, match=f"port {port}"):
            Recorder(viewer="serve", grpc_port=port, web_port=free_port())


def test_telemetry_off_by_default_and_opt_in(monkeypatch):
    for var in ("CI", "TELEMETRY_ENABLED", TELEMETRY_ENV):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setenv(TELEMETRY_ENV, "1")
    assert disable_rerun_telemetry() is True and "CI" not in os.environ
    monkeypatch.delenv(TELEMETRY_ENV)
    Recorder().close()  # Rerun analytics skip processes whose environment has CI set
    assert os.environ.get("CI") == "1" and os.environ.get("TELEMETRY_ENABLED") == "false"


def test_rendered_rca_iterations_show_their_own_colours(tmp_path):
    """Stepping through the iterations: the graph is logged once on rca_iteration, iteration 2
    logs only the colours an alert changed, and the viewer draws the whole graph at both, each
    in its own colours (latest-at)."""
    reason = _renderer_missing()
    if reason:
        pytest.skip(f"headless renderer unavailable: {reason}")
    Image = pytest.importorskip("PIL.Image", reason="Pillow decodes the PNG")
    rrd = tmp_path / "steps.rrd"
    G = demo_graph()
    it = {"subgraph": [], "watchlist": [], "edges": []}  # no overlay: only /system's colours
    with Recorder(save=rrd, blueprint=build_blueprint(collapse_panels=True)) as r:
        r.system(G, t=T0)
        r.rca(G, {**it, "j": 1, "t": T0 + 1})
        topics = sorted(m for m, k in G.nodes(data="kind") if k == "topic")
        r.alerts([Alert(m, "topic_rate", T0 + 2, "error", "rate fell", {"value": 2.0}) for m in topics])
        r.system(G, t=T0 + 2)
        r.rca(G, {**it, "j": 2, "t": T0 + 2})
    assert {k for row in rows(rrd)[paths.SYSTEM] if row.get("rca_iteration") == 2
            for k in row if k.startswith("Graph")} == {"GraphNodes:colors"}
    seen = {}
    for j in (1, 2):
        png = tmp_path / f"j{j}.png"
        screenshot(rrd, png, timeline=paths.RCA_ITERATION, time_value=j, settle=2)
        img = np.asarray(Image.open(png).convert("RGB"))
        graph = img[: int(img.shape[0] * 0.55)]
        seen[j] = {c: hue_pixels(graph, col) for c, col in
                   (("node", KIND_COLOR["node"]), ("topic", KIND_COLOR["topic"]),
                    ("error", SEVERITY_COLOR["error"]))}
    assert seen[1]["node"] > 50 and seen[2]["node"] > 50, seen  # the graph is drawn at both
    assert seen[1]["topic"] > 50, seen
    assert seen[2]["error"] > 50 + 3 * seen[1]["error"], seen  # iteration 2: the topics in alert colour
    assert seen[2]["topic"] < seen[1]["topic"] / 2, seen
