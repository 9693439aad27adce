"""Plausible, cheap message contents for the simulated nodes, one factory per message type."""

from __future__ import annotations

import importlib
import math
import random
from collections.abc import Callable
from typing import Any

from stream_viz.errors import DemoError

_IMAGE_W, _IMAGE_H = 160, 120
_IMAGE_BYTES = bytes(random.Random(0).randrange(256) for _ in range(_IMAGE_W * _IMAGE_H * 3))


def load_type(name: str) -> type:
    """Import a ROS interface class from ``pkg/msg/Name`` or ``pkg/srv/Name``."""
    try:
        pkg, kind, cls = name.split("/")
        return getattr(importlib.import_module(f"{pkg}.{kind}"), cls)
    except (ValueError, ImportError, AttributeError) as exc:
        raise DemoError(f"cannot import ROS interface {name!r}: {exc}") from exc


def _stamp(msg: Any, stamp: Any, frame: str) -> Any:
    msg.header.stamp = stamp
    msg.header.frame_id = frame
    return msg


def _scan(cls, stamp, seq):
    msg = _stamp(cls(), stamp, "laser")
    msg.angle_min, msg.angle_max = -math.pi, math.pi
    msg.angle_increment = 2 * math.pi / 360
    msg.range_min, msg.range_max, msg.scan_time = 0.1, 12.0, 0.1
    msg.ranges = [2.0 + math.sin(seq * 0.05 + i * 0.1) for i in range(360)]
    return msg


def _image(cls, stamp, seq):
    msg = _stamp(cls(), stamp, "camera")
    msg.height, msg.width, msg.encoding, msg.step = _IMAGE_H, _IMAGE_W, "rgb8", _IMAGE_W * 3
    msg.data = _IMAGE_BYTES
    return msg


def _imu(cls, stamp, seq):
    msg = _stamp(cls(), stamp, "imu")
    msg.orientation.w = 1.0
    msg.angular_velocity.z = 0.1 * math.sin(seq * 0.01)
    msg.linear_acceleration.z = 9.81
    return msg


def _odom(cls, stamp, seq):
    msg = _stamp(cls(), stamp, "odom")
    msg.child_frame_id = "base_link"
    msg.pose.pose.position.x = 0.01 * seq
    msg.pose.pose.orientation.w = 1.0
    msg.twist.twist.linear.x = 0.2
    return msg


def _pose_array(cls, stamp, seq):
    geo = importlib.import_module("geometry_msgs.msg")
    msg = _stamp(cls(), stamp, "base_link")
    msg.poses = [geo.Pose() for _ in range(3)]
    for i, p in enumerate(msg.poses):
        p.position.x, p.position.y, p.orientation.w = 1.0 + i, math.sin(seq * 0.1 + i), 1.0
    return msg


def _pose_cov(cls, stamp, seq):
    msg = _stamp(cls(), stamp, "map")
    msg.pose.pose.position.x = 0.01 * seq
    msg.pose.pose.orientation.w = 1.0
    return msg


def _path(cls, stamp, seq):
    geo = importlib.import_module("geometry_msgs.msg")
    msg = _stamp(cls(), stamp, "map")
    msg.poses = [geo.PoseStamped() for _ in range(10)]
    for i, p in enumerate(msg.poses):
        p.header.frame_id, p.pose.position.x, p.pose.orientation.w = "map", 0.5 * i, 1.0
    return msg


def _twist(cls, stamp, seq):
    msg = cls()
    msg.linear.x, msg.angular.z = 0.2, 0.1 * math.sin(seq * 0.05)
    return msg


def _float_array(cls, stamp, seq):
    msg = cls()
    msg.data = [0.2, 0.2 + 0.01 * math.sin(seq * 0.05)]
    return msg


def _battery(cls, stamp, seq):
    msg = _stamp(cls(), stamp, "base_link")
    msg.voltage, msg.percentage, msg.present = 24.0, max(0.0, 1.0 - seq * 1e-4), True
    return msg


def _string(cls, stamp, seq):
    msg = cls()
    msg.data = f"msg {seq}"
    return msg


def _float64(cls, stamp, seq):
    msg = cls()
    msg.data = float(seq)
    return msg


_FACTORIES: dict[str, Callable] = {
    "sensor_msgs/msg/LaserScan": _scan,
    "sensor_msgs/msg/Image": _image,
    "sensor_msgs/msg/Imu": _imu,
    "nav_msgs/msg/Odometry": _odom,
    "geometry_msgs/msg/PoseArray": _pose_array,
    "geometry_msgs/msg/PoseWithCovarianceStamped": _pose_cov,
    "nav_msgs/msg/Path": _path,
    "geometry_msgs/msg/Twist": _twist,
    "std_msgs/msg/Float64MultiArray": _float_array,
    "sensor_msgs/msg/BatteryState": _battery,
    "std_msgs/msg/String": _string,
    "std_msgs/msg/Float64": _float64,
}


def factory(type_name: str) -> Callable[[Any, int], Any]:
    """Return ``make(stamp, seq) -> message`` for ``type_name`` (DemoError if we cannot fill it)."""
    cls = load_type(type_name)
    fill = _FACTORIES.get(type_name)
    if fill is None:
        raise DemoError(f"no message factory for {type_name!r}; known: {', '.join(sorted(_FACTORIES))}")
    return lambda stamp, seq: fill(cls, stamp, seq)


def fill_response(type_name: str, response: Any) -> Any:
    """Fill a service response of ``type_name`` (GetMap gets a small occupancy grid)."""
    if type_name == "nav_msgs/srv/GetMap":
        grid = response.map
        grid.header.frame_id = "map"
        grid.info.resolution, grid.info.width, grid.info.height = 0.1, 50, 50
        grid.info.origin.orientation.w = 1.0
        grid.data = [0] * (50 * 50)
    elif hasattr(response, "success"):
        response.success = True
        if hasattr(response, "message"):
            response.message = "ok"
    return response
