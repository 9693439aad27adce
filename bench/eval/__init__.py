"""The fault-injection evaluation of stream-viz against peers (see docs/evaluation.md).

Pure parts (metrics, the rule-based baseline, the metric-table export, tables) are importable
without ROS; :mod:`bench.eval.run_one` drives one live run; :mod:`bench.eval.peers` runs in the
separate peer venv (``bench/.peers-venv``).
"""
