"""``--viewer serve``: the web viewer and its gRPC data server, on loopback unless asked otherwise.

The SDK's own ``serve_web_viewer`` takes no address and listens on every interface, while its
gRPC server listens where it is told: a page anyone on the network could load, whose data only
this machine could read. The ``rerun`` executable takes one address for both (``--serve-web
--bind ADDR``), so the served viewer runs as that child process, in its own process group, and
the run streams into it like into any viewer (``GrpcSink``). On Linux the server is told to end
when the process that started it does (``PR_SET_PDEATHSIG``), so a monitor killed with SIGKILL
does not leave it holding the ports.
"""

from __future__ import annotations

import ctypes
import ipaddress
import os
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from urllib.parse import quote

from stream_viz.errors import OutputError
from stream_viz.viz.children import end_group
from stream_viz.viz.screenshot import rerun_executable

DEFAULT_BIND = "127.0.0.1"
DEFAULT_GRPC_PORT = 9876
DEFAULT_WEB_PORT = 9090


@dataclass(frozen=True)
class ServeAt:
    """Where ``--viewer serve`` listens: one address for the page and its data, and two ports."""

    bind: str = DEFAULT_BIND
    web_port: int = DEFAULT_WEB_PORT
    grpc_port: int = DEFAULT_GRPC_PORT


def is_loopback(bind: str) -> bool:
    """Return True if ``bind`` (an IP address or ``localhost``) is reachable from this machine only."""
    if bind == "localhost":
        return True
    try:
        return ipaddress.ip_address(bind).is_loopback
    except ValueError:
        return False


def url_host(bind: str) -> str:
    """Return the host a browser on this machine uses for a server bound to ``bind``."""
    try:
        addr = ipaddress.ip_address(bind)
    except ValueError:
        return bind  # a host name
    if addr.is_unspecified:  # 0.0.0.0 / ::: every interface, loopback included
        return "127.0.0.1"
    return f"[{bind}]" if addr.version == 6 else bind


def viewer_urls(bind: str, web_port: int, grpc_port: int) -> tuple[str, str]:
    """Return ``(web page URL, gRPC URL)`` of a viewer served on ``bind``; the page opens the data."""
    host = url_host(bind)
    grpc = f"rerun+http://{host}:{grpc_port}/proxy"
    return f"http://{host}:{web_port}/?url={quote(grpc, safe='')}", grpc


def server_executable() -> str | None:
    """Return the ``rerun`` binary itself (the one on PATH is a Python wrapper around it), else
    the wrapper, else None."""
    try:
        import rerun_cli
    except ImportError:
        return rerun_executable()
    exe = os.path.join(os.path.dirname(rerun_cli.__file__), "rerun")
    return exe if os.access(exe, os.X_OK) else rerun_executable()


def _die_with_parent() -> Callable[[], None] | None:
    """Return a pre-exec hook making the child get SIGTERM when its parent dies (Linux), else None."""
    if not sys.platform.startswith("linux"):
        return None
    prctl = ctypes.CDLL(None, use_errno=True).prctl  # looked up before the fork: the hook only calls it
    pr_set_pdeathsig = 1
    return lambda: prctl(pr_set_pdeathsig, signal.SIGTERM)


def check_free(bind: str, port: int) -> None:
    """Raise `OutputError` if ``port`` is taken on ``bind`` (a stale viewer would get the run's data)."""
    host = bind.strip("[]")
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family) as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # only a listener counts, not TIME_WAIT
        try:
            s.bind((host, port))
        except OSError as e:
            raise OutputError(f"--viewer serve: cannot listen on {bind} port {port}: {e.strerror}") from e


class WebViewerServer:
    """A ``rerun --serve-web`` child serving the web viewer and a gRPC server on ``bind``.

    Parameters
    ----------
    bind : str
        Address of both servers: ``127.0.0.1`` (default, this machine only), ``0.0.0.0`` or
        ``::`` (every interface), or one interface's address.
    web_port, grpc_port : int
        Ports of the web page and of the data.
    memory_limit : str
        How much the gRPC server buffers for viewers that connect late (oldest data dropped first).
    timeout : float
        Seconds to wait for the server to listen.
    """

    def __init__(self, bind: str = DEFAULT_BIND, web_port: int = DEFAULT_WEB_PORT,
                 grpc_port: int = DEFAULT_GRPC_PORT, memory_limit: str = "512MiB",
                 timeout: float = 30.0) -> None:
        exe = server_executable()
        if exe is None:
            raise OutputError("--viewer serve: the 'rerun' executable is not on PATH")
        self.bind, self.web_port, self.grpc_port = bind, web_port, grpc_port
        self.loopback = is_loopback(bind)
        self.url, self.grpc_url = viewer_urls(bind, web_port, grpc_port)
        for port in (web_port, grpc_port):
            check_free(bind, port)
        env = dict(os.environ, CI=os.environ.get("CI", "1"))  # no viewer analytics
        self.proc = subprocess.Popen(
            [exe, "--serve-web", "--bind", bind, f"--web-viewer-port={web_port}", f"--port={grpc_port}",
             f"--server-memory-limit={memory_limit}"],
            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True, env=env,
            preexec_fn=_die_with_parent())  # only prctl runs between fork and exec
        try:
            self._wait_listening(timeout)
        except BaseException:
            self.stop()
            raise

    def _wait_listening(self, timeout: float) -> None:
        host = url_host(self.bind).strip("[]")
        deadline = time.monotonic() + timeout
        pending = [self.grpc_port, self.web_port]
        while pending:
            if self.proc.poll() is not None:
                err = self.proc.stderr.read().decode(errors="replace")[-1500:] if self.proc.stderr else ""
                raise OutputError(f"--viewer serve: the rerun server exited ({self.proc.returncode}); "
                                  f"ports {self.web_port} and {self.grpc_port} in use? {err.strip()}")
            try:
                with socket.create_connection((host, pending[0]), timeout=1.0):
                    pending.pop(0)
                    continue
            except OSError:
                if time.monotonic() > deadline:
                    raise OutputError(f"--viewer serve: nothing listens on {host}:{pending[0]} "
                                      f"after {timeout:g} s") from None
                time.sleep(0.1)

    def stop(self) -> None:
        """Stop the server (its process group: the ``rerun`` wrapper starts the real binary as a child)."""
        end_group(self.proc)
