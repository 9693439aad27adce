"""The kernel's process events, read for real: exit codes of processes this test ends."""

from __future__ import annotations

import signal
import subprocess
import sys
import time

import pytest

from stream_viz.collect.exitcodes import ExitCodes


def test_exit_codes_of_real_processes():
    codes = ExitCodes()
    if codes.reason is not None:
        pytest.skip(codes.reason)
    try:
        ended = {}
        for how in ("os._exit(0)", "raise SystemExit(3)", "import time; time.sleep(60)"):
            p = subprocess.Popen([sys.executable, "-c", f"import os\n{how}"])
            if "sleep" in how:
                time.sleep(0.3)
                killed_at = time.time()
                p.send_signal(signal.SIGKILL)
            p.wait()
            if "sleep" in how:
                reaped_at = time.time()
            ended[how] = p.pid
        deadline = time.monotonic() + 5.0
        got: dict[str, int | None] = dict.fromkeys(ended)
        when: dict[str, float | None] = {}
        while time.monotonic() < deadline and None in got.values():
            for how, pid in ended.items():
                if got[how] is None:
                    got[how], when[how] = codes.take_exit(pid)
            time.sleep(0.05)
        assert got == {"os._exit(0)": 0, "raise SystemExit(3)": 3, "import time; time.sleep(60)": -9}
        # when it ended, by the kernel's clock, however late this thread read it
        assert killed_at - 0.01 <= when["import time; time.sleep(60)"] <= reaped_at + 0.01, when
        assert codes.take(ended["os._exit(0)"]) is None  # taken once: pids are reused
    finally:
        codes.close()
