"""The peers' speed-ups give PyRCA's own results (run in the peer venv, skipped without it)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
PEER_PY = ROOT / "bench/.peers-venv/bin/python"

SCRIPT = """
import sys
sys.path.insert(0, "bench/eval")
import numpy as np
from peers import walk
from pyrca.analyzers.random_walk import RandomWalk

rng = np.random.default_rng(3)
nodes = [f"m{i}" for i in range(40)]
graph = {}
for n in nodes:
    nb = list(rng.choice(nodes, size=int(rng.integers(1, 8)), replace=False))
    w = rng.random(len(nb))
    w[rng.random(len(nb)) < 0.2] = 0.0
    w[0] += 0.01
    graph[n] = {"nodes": nb, "weights": list(w), "probs": w / w.sum()}
for seed, start in ((0, "m0"), (5, "m7"), (None, "m3")):
    if seed is None:
        np.random.seed(11)
    want = RandomWalk._random_walk(graph, start, 10, 500, random_seed=seed)
    if seed is None:
        np.random.seed(11)
    got = walk(graph, start, 10, 500, random_seed=seed)
    assert got == want and list(got) == list(want), (seed, start)
print("same")
"""


@pytest.mark.skipif(not PEER_PY.exists(), reason="no peer venv (bench/eval.sh creates it)")
def test_the_fast_random_walk_takes_pyrcas_steps():
    out = subprocess.run([str(PEER_PY), "-c", SCRIPT], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert out.returncode == 0 and out.stdout.strip() == "same", out.stderr[-2000:]
