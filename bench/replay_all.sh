#!/bin/bash
# Replay every committed samples file (bench/results/**/*.jsonl.gz) through the code of a work tree;
# print one line per file: its alert count and top 3 (how many share the first place when more
# than one, and plugin problems, if any).
#
#   bash bench/replay_all.sh [TREE] > out.txt     # TREE: a work tree (default: this repository)
#
# To compare commits, give each its own work tree (`git worktree add /tmp/base <commit>`) and
# diff the outputs. The built-in plugins load through the entry point `stream_viz_plugins`, which
# the editable install maps to *this* repository's plugins/ whatever the current directory:
# a link named `stream_viz_plugins` to TREE/plugins, first on PYTHONPATH, makes TREE's plugins
# the ones run. Two replays at a time, each into its own database (one database holds one run).
set -euo pipefail
here="$(cd "$(dirname "$0")/.." && pwd)"
tree="$(cd "${1:-$here}" && pwd)"
py="$here/.venv/bin/python"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
mkdir -p "$work/path" && ln -s "$tree/plugins" "$work/path/stream_viz_plugins"
cd "$tree"
find bench/results -name "*.jsonl.gz" | sort > "$work/files"
export PYTHONPATH="$work/path" PY="$py" WORK="$work"
xargs -P2 -I{} sh -c 'n=$(echo "$1" | tr / _); "$PY" -m stream_viz.cli replay "$1" --viewer none \
    --report "$WORK/$n.json" --db "$WORK/$n.sqlite" > "$WORK/$n.log" 2>&1 || true' _ {} < "$work/files"
while read -r f; do
  n=$(echo "$f" | tr / _)
  "$py" - "$f" "$work/$n.json" "$work/$n.log" <<'PY'
import json, sys
f, out, log = sys.argv[1:]
try:
    r = json.load(open(out))
except Exception as e:
    print(f, "ERROR", e)
    sys.exit()
causes = r["root_causes"]
top = [c["member"] for c in causes[:3]]
first = sum(1 for c in causes if causes and c["score"] == causes[0]["score"])  # how many share first place
probs = sum(1 for line in open(log) if "plugin problem" in line)
print(f"{f}: alerts={len(r['alerts'])} top3={top}" + (f" first_tied={first}" if first > 1 else "")
      + (f" plugin_problems={probs}" if probs else ""))
PY
done < "$work/files"
