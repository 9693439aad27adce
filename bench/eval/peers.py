"""Peers on the same runs, in the peer venv: RCAEval's BARO and n-sigma, PyRCA's ε-Diagnosis, HT, random walk.

``bench/.peers-venv/bin/python bench/eval/peers.py RUN_DIR...`` reads each run's ``metrics.csv`` and
``meta.json`` (fault time, service → member map, service-level topology) and writes
``peers.json``: per peer the ranked members (best first) or why it failed. Peers are told the fault
time; stream-viz is not. A ranking equal to the input column order is treated as a silent failure.
"""

from __future__ import annotations

import bisect
import json
import sys
import time
import traceback
import warnings
from pathlib import Path

import numpy as np
import pandas as pd

warnings.filterwarnings("ignore")


def to_members(ranked_cols: list[str], services: dict[str, str]) -> list[str]:
    """Ranked metric columns → ranked members (first appearance of each service)."""
    out: list[str] = []
    for c in ranked_cols:
        m = services.get(str(c).partition("_")[0])
        if m and m not in out:
            out.append(m)
    return out


def parents_frame(cols: list[str], service_edges: list[list[str]]) -> pd.DataFrame:
    """Column-level adjacency (row = cause, column = effect) from the service-level topology, acyclic.

    Services without columns are contracted (``a → x → b`` gives ``a → b``), so dropping a
    constant node's metrics does not cut its process off from its topics.
    """
    by_svc: dict[str, list[str]] = {}
    for c in cols:
        by_svc.setdefault(c.partition("_")[0], []).append(c)
    succ: dict[str, list[str]] = {}
    for a, b in service_edges:
        if a != b:
            succ.setdefault(a, []).append(b)

    def targets(a: str) -> list[str]:  # nearest services with columns downstream of a
        out, seen, stack = [], {a}, list(succ.get(a, ()))
        while stack:
            x = stack.pop()
            if x in seen:
                continue
            seen.add(x)
            if x in by_svc:
                out.append(x)
            else:
                stack.extend(succ.get(x, ()))
        return sorted(out)

    adj = pd.DataFrame(0, index=cols, columns=cols)
    reach: dict[str, set[str]] = {}

    def reachable(s: str) -> set[str]:
        seen, stack = {s}, [s]
        while stack:
            for n in reach.get(stack.pop(), ()):
                if n not in seen:
                    seen.add(n)
                    stack.append(n)
        return seen

    for a in sorted(by_svc):
        for b in targets(a):
            if a != b and a not in reachable(b):
                reach.setdefault(a, set()).add(b)
                adj.loc[by_svc[a], by_svc[b]] = 1
    return adj


def walk(graph: dict, start: str, num_steps: int, num_repeats: int, random_seed: int | None = 0) -> dict:
    """PyRCA's ``RandomWalk._random_walk`` with the same draws, without ``np.random.choice`` per step.

    ``np.random.choice(n, p=probs)`` (legacy RandomState) takes one ``random_sample()`` and finds it
    in ``cumsum(probs) / its last``; drawing them all at once gives the same numbers in the same
    order, and the same steps, 20x faster (seconds per run on the AMR's column graph).
    """
    if random_seed is not None:
        np.random.seed(random_seed)
    cdfs = {}
    for node, g in graph.items():
        cdf = np.asarray(g["probs"], dtype=float).cumsum()
        cdf /= cdf[-1]
        cdfs[node] = cdf.tolist()
    draws = np.random.random_sample(num_repeats * num_steps).tolist()
    counts: dict = {}
    k = 0
    for _ in range(num_repeats):
        node, path = start, []
        for _ in range(num_steps):
            node = graph[node]["nodes"][bisect.bisect_right(cdfs[node], draws[k])]
            k += 1
            path.append(node)
        for n in path:
            counts[n] = counts.get(n, 0) + 1
    return counts


EPS_MAX_COLUMNS = 300  # ε-Diagnosis above this takes minutes per run (docs/evaluation.md)


def run_peers(run_dir: Path) -> dict:
    meta = json.loads((run_dir / "meta.json").read_text())
    t_inj = meta["inject_time"]
    out: dict = {}
    if t_inj is None:
        return {"_skipped": "fault-free run: the peers need a fault time"}
    data = pd.read_csv(run_dir / "metrics.csv")
    cols = [c for c in data.columns if c != "time"]
    normal = data[data["time"] < t_inj][cols]
    abnormal = data[data["time"] >= t_inj][cols]
    services = meta["services"]

    def record(name: str, fn) -> None:
        t0 = time.perf_counter()
        try:
            ranked = [c for c in fn() if c != "time"]
            if ranked[: len(cols)] == cols[: len(ranked)] and len(ranked) > 3:
                out[name] = {"error": "returned the input column order (silent failure)"}
                return
            out[name] = {
                "ranking": to_members(ranked, services),
                "columns": ranked[:10],
                "seconds": time.perf_counter() - t0,
            }
        except Exception as exc:  # a peer failing is a result, not a crash of the benchmark
            out[name] = {
                "error": f"{type(exc).__name__}: {exc}",
                "trace": traceback.format_exc(limit=3)[-600:],
            }

    from RCAEval.e2e import nsigma
    from RCAEval.e2e.baro import baro

    record("BARO", lambda: baro(data, inject_time=t_inj, dataset=None)["ranks"])
    record("n-sigma", lambda: nsigma(data, inject_time=t_inj, dataset=None)["ranks"])

    from pyrca.analyzers.epsilon_diagnosis import EpsilonDiagnosis, EpsilonDiagnosisConfig
    from pyrca.analyzers.ht import HT, HTConfig
    from pyrca.analyzers.random_walk import RandomWalk, RandomWalkConfig

    def eps():
        if len(cols) > EPS_MAX_COLUMNS:
            raise RuntimeError(
                f"skipped: {len(cols)} columns > {EPS_MAX_COLUMNS}; its bootstrap test loops over the "
                "columns in Python (> 3 min per run at 587 columns), too slow for this suite"
            )
        n = min(len(normal), len(abnormal))
        model = EpsilonDiagnosis(EpsilonDiagnosisConfig(alpha=0.01, root_cause_top_k=len(cols)))
        model.train(normal.tail(n))
        return [r[0] for r in model.find_root_causes(abnormal.head(n)).root_cause_nodes]

    graph = parents_frame(cols, meta["service_edges"])

    def ht():
        model = HT(HTConfig(graph=graph, aggregator="max", root_cause_top_k=len(cols)))
        model.train(normal)
        return [r[0] for r in model.find_root_causes(abnormal).root_cause_nodes]

    def rw():
        mu, sd = normal.mean(), normal.std().replace(0, np.nan)
        z = ((abnormal - mu) / sd).abs().max().fillna(0)
        # a constant column that changed is anomalous too (sd = 0)
        changed = (abnormal != normal.iloc[-1]).any() & normal.std().eq(0)
        anomalous = sorted(set(z[z > 3].index) | set(changed[changed].index))
        if not anomalous:
            raise ValueError("no anomalous metric (|z| > 3) to start the walks from")
        # constant columns give NaN correlations (edge weights): the walk needs them gone
        # and so do metrics outside the topology (no edge: a zero-weight row)
        live = [c for c in cols if data[c].std() > 0]
        g = parents_frame(live, meta["service_edges"])
        live = [c for c in live if g.loc[c].any() or g[c].any()]
        g = g.loc[live, live]
        anomalous = [c for c in anomalous if c in live]
        model = RandomWalk(RandomWalkConfig(graph=g, root_cause_top_k=len(live)))
        # Its explanation paths (every path from a root to every anomaly) explode on deep dense
        # column graphs (minutes per run on the AMR); the ranking is computed before them.
        model._get_root_cause_paths = lambda *_: []
        model._random_walk = walk
        return [r[0] for r in model.find_root_causes(anomalous, data[live], random_seed=0).root_cause_nodes]

    record("ε-Diagnosis", eps)
    record("PyRCA-HT", ht)
    record("PyRCA-RW", rw)
    return out


def main(argv: list[str]) -> int:
    for d in map(Path, argv):
        try:
            res = run_peers(d)
        except Exception as exc:
            res = {"_error": f"{type(exc).__name__}: {exc}"}
        (d / "peers.json").write_text(json.dumps(res, indent=1))
        print(
            d.name,
            {
                k: ("ok" if "ranking" in v else v.get("error", "?")) if isinstance(v, dict) else v
                for k, v in res.items()
            },
            flush=True,
        )
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
