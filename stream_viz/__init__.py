"""STREAM: a live visual debugger for ROS 2 robots."""

from __future__ import annotations

__version__ = "0.1.0"
