#!/usr/bin/env bash
# The fault-injection evaluation (docs/evaluation.md). One suite per call, runs one after the other:
#   bench/eval.sh --short     each demo fault once + 1 fault-free + one generated 20-node run, each AMR
#                             fault on its default target + 1 fault-free (~25 min)
#   bench/eval.sh --control   the AMR's 10-minute healthy-dynamics run (~11 min)
#   bench/eval.sh --sweep     fault sizes: degrade, delay, leak, cpu, errlog at 2-4 sizes on the AMR (~30 min)
#   bench/eval.sh --full      2-3 targets per fault x 3 reps on the demo and the AMR, generated 20/100 nodes,
#                             the control run (hours; --sizes 20,100,500 adds the 500-node system)
# Extra options go to `python -m bench.eval.run` (--report-only, --out DIR, --reps N, --only SYSTEMS,
# --kinds FAULTS, --warmup S, --post S). Results: bench/out/<suite>/ (everything) and
# bench/results/<suite>-<commit>/ (the small files committed in the repo); plots in docs/img.
# First time: creates the peer venv bench/.peers-venv (RCAEval, PyRCA; never project dependencies).
set -euo pipefail
cd "$(dirname "$0")/.."
PEERS=bench/.peers-venv
if [ ! -x "$PEERS/bin/python" ]; then
  python3.11 -m venv "$PEERS"
  "$PEERS/bin/pip" install -q --no-deps rcaeval sfr-pyrca
  "$PEERS/bin/pip" install -q "numpy<2" "pandas<3" scikit-learn scipy "networkx<3" causal-learn pingouin \
      statsmodels "setuptools<81" matplotlib pyyaml schema wheel requests dill
fi
exec .venv/bin/python -m bench.eval.run --plots docs/img --results bench/results "$@"
