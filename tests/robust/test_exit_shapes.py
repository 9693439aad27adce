"""How a Python node's process ends on Ctrl-C, SIGTERM and an uncaught exception, for the three
shapes of its main that robots use (docs/plugins.md, *An error after the goodbye*): what
`stream_viz.detect.exits.error_exits` tells apart rests on these codes.
"""

from __future__ import annotations

import signal
import subprocess
import sys

import pytest

from stream_viz.testing import ros_env

pytestmark = pytest.mark.ros

NODE = """
import signal, sys
# Python's own Ctrl-C handler, as a process started from a terminal or launch has it; one started
# in the background of a shell (a CI run so) inherits SIGINT ignored, and rclpy keeps that.
signal.signal(signal.SIGINT, signal.default_int_handler)
import rclpy
from rclpy.executors import ExternalShutdownException
shape, act = sys.argv[1], sys.argv[2]
rclpy.init()
n = rclpy.create_node("shape_" + shape)
said = []
def tick():
    if not said:  # spinning: a signal now comes to the spin
        said.append(print("ready", flush=True))
    elif act == "raise":
        raise RuntimeError("boom")
n.create_timer(0.2, tick)
if shape == "plain":
    rclpy.spin(n)
elif shape == "keyboard":
    try:
        rclpy.spin(n)
    except KeyboardInterrupt:
        pass
    finally:
        n.destroy_node()
        rclpy.try_shutdown()
else:  # as `ros2 pkg create` writes it
    try:
        rclpy.spin(n)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
"""

# shape -> (codes on SIGINT, on SIGTERM, on an exception in a callback), as `subprocess` gives
# them. The template's SIGTERM is 1 when rclpy's handler shuts the context down as its executor
# builds a wait set (an RCLError, not the ExternalShutdownException it catches): a race.
EXPECTED = {"plain": ({-signal.SIGINT}, {1}, {1}), "keyboard": ({0}, {1}, {1}),
            "template": ({0}, {0, 1}, {1})}


def _end(shape: str, act: str, env: dict[str, str]) -> int:
    p = subprocess.Popen([sys.executable, "-c", NODE, shape, act], env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.DEVNULL, start_new_session=True, text=True)
    assert p.stdout.readline().strip() == "ready"
    if act != "raise":
        p.send_signal(signal.SIGINT if act == "int" else signal.SIGTERM)
    return p.wait(timeout=20)


@pytest.mark.parametrize("shape", sorted(EXPECTED))
def test_how_a_python_node_ends(shape, ros_domain):
    env = ros_env(ros_domain)
    got = tuple(_end(shape, act, env) for act in ("int", "term", "raise"))
    assert all(code in codes for code, codes in zip(got, EXPECTED[shape], strict=True)), got
