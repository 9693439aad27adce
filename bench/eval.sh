#!/usr/bin/env bash
# The fault-injection evaluation (docs/evaluation.md).
#   bench/eval.sh --short   each demo fault once + 2 fault-free runs + one generated 20-node run (~12 min)
#   bench/eval.sh --full    3 targets x 8 faults x 3 reps on the demo, generated 20/100 nodes (hours;
#                           --sizes 20,100,500 adds the 500-node system)
# Extra options go to `python -m bench.eval.run` (--report-only, --out DIR, --warmup S, --post S).
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
exec .venv/bin/python -m bench.eval.run --plots docs/img "$@"
