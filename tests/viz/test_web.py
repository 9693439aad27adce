"""The served web viewer as a user opens it: a real demo run with ``--viewer serve``, real Chromium."""

from __future__ import annotations

import re
import signal
import socket
import subprocess
import threading

import numpy as np
import psutil
import pytest

from stream_viz.testing import EXE, wait_for
from stream_viz.viz import browser
from stream_viz.viz.children import end_group, free_port
from stream_viz.viz.screenshot import colour_pixels, graph_drawn
from stream_viz.viz.serve import is_loopback, url_host, viewer_urls
from stream_viz.viz.style import KIND_COLOR

URL_LINE = re.compile(r"Rerun web viewer: (\S+)")


def listening(pid: int) -> dict[int, set[str]]:
    """Port -> addresses a process tree listens on (TCP)."""
    procs = [psutil.Process(pid), *psutil.Process(pid).children(recursive=True)]
    out: dict[int, set[str]] = {}
    for p in procs:
        try:
            conns = p.net_connections(kind="tcp")
        except psutil.NoSuchProcess:
            continue
        for c in conns:
            if c.status == psutil.CONN_LISTEN:
                out.setdefault(c.laddr.port, set()).add(c.laddr.ip)
    return out


def other_addresses() -> list[str]:
    """This machine's IPv4 addresses that are not loopback."""
    return [a.address for addrs in psutil.net_if_addrs().values() for a in addrs
            if a.family.name == "AF_INET" and not is_loopback(a.address)]


def test_served_urls_name_a_host_the_browser_reaches():
    assert viewer_urls("127.0.0.1", 9090, 9876) == (
        "http://127.0.0.1:9090/?url=rerun%2Bhttp%3A%2F%2F127.0.0.1%3A9876%2Fproxy",
        "rerun+http://127.0.0.1:9876/proxy")
    assert url_host("0.0.0.0") == "127.0.0.1" and url_host("::") == "127.0.0.1"
    assert url_host("192.168.1.7") == "192.168.1.7" and url_host("::1") == "[::1]"
    assert [is_loopback(a) for a in ("127.0.0.1", "::1", "localhost", "0.0.0.0", "10.0.0.2")] == \
        [True, True, True, False, False]


@pytest.mark.ros
@pytest.mark.slow
def test_a_served_demo_run_shows_its_live_graph_in_headless_chromium(ros_domain, tmp_path):
    reason = browser.missing()
    if reason:
        pytest.skip(f"no headless browser: {reason}")
    web, grpc = free_port(), free_port()
    cmd = [EXE, "demo", "--fault", "none", "--duration", "90", "--domain", str(ros_domain),
           "--viewer", "serve", "--web-port", str(web), "--grpc-port", str(grpc),
           "--save", str(tmp_path / "d.rrd"), "--db", str(tmp_path / "a.sqlite")]
    p = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                         text=True, start_new_session=True)
    said: list[str] = []
    reader = threading.Thread(target=lambda: said.extend(iter(p.stderr.readline, "")), daemon=True)
    reader.start()
    png = tmp_path / "web.png"  # kept by pytest in its basetemp: look at it
    try:
        assert wait_for(lambda: any(URL_LINE.search(s) for s in said) or p.poll() is not None, 60), said
        url = next(m.group(1) for s in said if (m := URL_LINE.search(s)))
        assert url == viewer_urls("127.0.0.1", web, grpc)[0]
        # Page and data on loopback only: what listens, and what another interface answers.
        ports = listening(p.pid)
        assert ports.get(web) == {"127.0.0.1"} and ports.get(grpc) == {"127.0.0.1"}, ports
        for addr in other_addresses():
            with pytest.raises(OSError):
                socket.create_connection((addr, web), timeout=2).close()
        assert wait_for(lambda: any("demo robot on" in s for s in said), 60), said
        shot = browser.web_screenshot(url, png, graph_drawn, size=(1600, 900), timeout=120)
    finally:
        p.send_signal(signal.SIGINT) if p.poll() is None else None
        try:
            p.wait(60)
        finally:
            end_group(p)
            reader.join(5)
    assert shot.ready, f"no graph on screen after {shot.seconds:.0f} s; see {png}; page: {shot.text!r}"
    assert "Loading" not in shot.text  # the HTML loading screen is gone: the app runs
    from PIL import Image

    img = np.asarray(Image.open(png).convert("RGB"))
    assert img.shape == (900, 1600, 3)
    # The graph sits in the upper part (the blueprint's top panel), not a loading screen's middle.
    graph = img[img.shape[0] // 20: img.shape[0] * 2 // 5]
    for kind in ("node", "topic"):
        assert colour_pixels(graph, KIND_COLOR[kind], 80) > 100, kind
    assert p.returncode == 0, "".join(said)[-3000:]
