"""The warehouse AMR as data: its processes, nodes and endpoints, and how each process runs.

Everything lives under the namespace ``/amr1`` except what ROS keeps global (``/diagnostics``,
``/diagnostics_agg``). The :class:`~stream_viz.demo.topology.Topology` is the ground truth the
tests and the evaluation use; :data:`PROCESSES` says how each process runs its nodes (the
executor, a late start, a one-shot job); :data:`BEST_EFFORT` and :data:`LATCHED` are the QoS.
"""

from __future__ import annotations

from dataclasses import dataclass

from stream_viz.demo.topology import ClientSpec, GroupSpec, NodeSpec, PubSpec, ServiceSpec, SubSpec, Topology

NS = "/amr1"
ENTRY = "stream_viz.demo.amr.process"

T = {
    "scan": "sensor_msgs/msg/LaserScan",
    "imu": "sensor_msgs/msg/Imu",
    "image": "sensor_msgs/msg/Image",
    "poses": "geometry_msgs/msg/PoseArray",
    "odom": "nav_msgs/msg/Odometry",
    "joints": "sensor_msgs/msg/JointState",
    "battery": "sensor_msgs/msg/BatteryState",
    "twist": "geometry_msgs/msg/Twist",
    "pose_cov": "geometry_msgs/msg/PoseWithCovarianceStamped",
    "pose": "geometry_msgs/msg/PoseStamped",
    "grid": "nav_msgs/msg/OccupancyGrid",
    "path": "nav_msgs/msg/Path",
    "string": "std_msgs/msg/String",
    "diag": "diagnostic_msgs/msg/DiagnosticArray",
    "diag_status": "diagnostic_msgs/msg/DiagnosticStatus",
    "transition": "lifecycle_msgs/msg/TransitionEvent",
    "get_plan": "nav_msgs/srv/GetPlan",
    "change_state": "lifecycle_msgs/srv/ChangeState",
}


def n(name: str) -> str:
    """The fully qualified name of ``name`` in the robot's namespace."""
    return f"{NS}/{name}"


# Sensor streams: best effort on both ends (qos_profile_sensor_data), as real drivers publish them.
BEST_EFFORT = frozenset({n("scan_front"), n("scan_rear"), n("scan"), n("imu"), n("camera/image_raw"),
                         n("camera/image_rect")})
# Published once, kept for late joiners (transient local, reliable, depth 1).
LATCHED = frozenset({n("map"), n("robot_description")})
DIAG = "/diagnostics"


@dataclass(frozen=True)
class ProcessPlan:
    """How a process runs its nodes.

    ``executor``: ``single`` (one SingleThreadedExecutor for all: a component_container; a blocked
    callback starves every node), ``multi`` (one MultiThreadedExecutor, a callback group per node:
    component_container_mt; a blocked node holds one thread) or ``isolated`` (an executor and a
    thread per node: component_container_isolated). ``join_after``: the nodes appear this many
    seconds after the process starts (someone starts them later). ``run_for``: a one-shot job that
    exits with code 0 after this many seconds.
    """

    executor: str
    join_after: float = 0.0
    run_for: float = 0.0


PROCESSES: dict[str, ProcessPlan] = {
    "sensors": ProcessPlan("single"),
    "camera": ProcessPlan("isolated"),
    "perception": ProcessPlan("single"),
    "base": ProcessPlan("isolated"),
    "navigation": ProcessPlan("multi"),
    "behavior": ProcessPlan("single"),
    "lifecycle": ProcessPlan("isolated"),
    "system": ProcessPlan("single"),
    "calibration": ProcessPlan("single", run_for=25.0),
    "console": ProcessPlan("single", join_after=45.0),
}

# diagnostic_updater tasks per node: (task, hardware_id); statuses are named "<node name>: <task>".
UPDATERS: dict[str, tuple[tuple[str, str], ...]] = {
    n("front_lidar"): (("scan rate", "sick-nanoscan3-7021"), ("connection", "sick-nanoscan3-7021")),
    n("rear_lidar"): (("scan rate", "sick-nanoscan3-7022"), ("connection", "sick-nanoscan3-7022")),
    n("imu_driver"): (("imu", "bno085-0x4a"),),
    n("camera_driver"): (("frame rate", "realsense-d435-8321"),),
    n("base_driver"): (("motors", "roboteq-sbl2360"), ("battery", "bms-48v-01")),
}

# The aggregator's analyzers: status name prefix (the node name) -> path under /AMR.
ANALYZERS: dict[str, str] = {
    "front_lidar": "Sensors/Lidar", "rear_lidar": "Sensors/Lidar", "imu_driver": "Sensors/IMU",
    "camera_driver": "Sensors/Camera", "base_driver": "Base",
}


def _diag_pub() -> PubSpec:
    return PubSpec(DIAG, T["diag"], 1.0)


def _scan_driver(name: str, topic: str) -> NodeSpec:
    return NodeSpec(n(name), pubs=(PubSpec(n(topic), T["scan"], 10.0), _diag_pub()))



AMR_GROUPS = (
    GroupSpec("sensors", (
        _scan_driver("front_lidar", "scan_front"),
        _scan_driver("rear_lidar", "scan_rear"),
        NodeSpec(n("imu_driver"), pubs=(PubSpec(n("imu"), T["imu"], 30.0), _diag_pub())),
        NodeSpec(n("scan_merger"),
                 subs=(SubSpec(n("scan_front"), T["scan"]), SubSpec(n("scan_rear"), T["scan"])),
                 pubs=(PubSpec(n("scan"), T["scan"], 10.0, trigger=n("scan_front"),
                               requires=(n("scan_rear"),), max_age=0.5),)),
    )),
    GroupSpec("camera", (
        NodeSpec(n("camera_driver"), pubs=(PubSpec(n("camera/image_raw"), T["image"], 10.0), _diag_pub())),
    ), respawn=True),
    GroupSpec("perception", (
        NodeSpec(n("image_rectifier"), subs=(SubSpec(n("camera/image_raw"), T["image"]),),
                 pubs=(PubSpec(n("camera/image_rect"), T["image"], 10.0, trigger=n("camera/image_raw")),)),
        # publishes only while a pallet is in view: 3-30 s at a time, then none for 15-40 s
        NodeSpec(n("pallet_detector"), subs=(SubSpec(n("camera/image_rect"), T["image"]),),
                 pubs=(PubSpec(n("pallet_detections"), T["poses"], 10.0, trigger=n("camera/image_rect")),)),
    )),
    GroupSpec("base", (
        NodeSpec(n("base_driver"), subs=(SubSpec(n("cmd_vel"), T["twist"]),),
                 pubs=(PubSpec(n("odom"), T["odom"], 20.0), PubSpec(n("joint_states"), T["joints"], 10.0),
                       PubSpec(n("battery_state"), T["battery"], 1.0), _diag_pub())),
        # twist_mux: teleop (priority) over navigation; republishes the active source's commands
        NodeSpec(n("velocity_mux"),
                 subs=(SubSpec(n("cmd_vel_nav"), T["twist"]), SubSpec(n("cmd_vel_teleop"), T["twist"])),
                 pubs=(PubSpec(n("cmd_vel"), T["twist"], 10.0, trigger=n("cmd_vel_nav")),)),
        # a joystick: commands only while the operator pushes it (a few seconds a minute)
        NodeSpec(n("teleop_joy"), pubs=(PubSpec(n("cmd_vel_teleop"), T["twist"], 10.0),)),
    ), respawn=True),
    GroupSpec("navigation", (
        NodeSpec(n("amcl"),
                 subs=(SubSpec(n("scan"), T["scan"]), SubSpec(n("odom"), T["odom"]),
                       SubSpec(n("map"), T["grid"])),
                 pubs=(PubSpec(n("amcl_pose"), T["pose_cov"], 5.0, trigger=n("scan"),
                               requires=(n("map"), n("odom")), max_age=0.5),)),
        NodeSpec(n("local_costmap"), subs=(SubSpec(n("scan"), T["scan"]),),
                 pubs=(PubSpec(n("local_costmap/costmap"), T["grid"], 2.0, requires=(n("scan"),)),)),
        NodeSpec(n("planner_server"), subs=(SubSpec(n("map"), T["grid"]),),
                 services=(ServiceSpec(n("compute_path"), T["get_plan"]),)),
        NodeSpec(n("controller_server"),
                 subs=(SubSpec(n("plan"), T["path"]), SubSpec(n("odom"), T["odom"]),
                       SubSpec(n("local_costmap/costmap"), T["grid"])),
                 pubs=(PubSpec(n("cmd_vel_nav"), T["twist"], 10.0,
                               requires=(n("plan"), n("local_costmap/costmap"), n("odom")), max_age=5.0),)),
    )),
    GroupSpec("behavior", (
        # the behaviour tree: asks the planner for a path every 2 s, publishes it for the controller
        NodeSpec(n("bt_navigator"), subs=(SubSpec(n("amcl_pose"), T["pose_cov"]),),
                 clients=(ClientSpec(n("compute_path"), T["get_plan"], period=2.0, timeout=3.0),),
                 pubs=(PubSpec(n("plan"), T["path"], 0.5, requires=(n("compute_path"), n("amcl_pose"))),)),
        # sets the controller's max_vel_x per warehouse zone (parameter services: not model edges)
        NodeSpec(n("zone_manager"), subs=(SubSpec(n("amcl_pose"), T["pose_cov"]),)),
    )),
    GroupSpec("lifecycle", (
        NodeSpec(n("lifecycle_manager"),
                 clients=(ClientSpec(n("map_server/change_state"), T["change_state"], period=30.0),
                          ClientSpec(n("docking_server/change_state"), T["change_state"], period=30.0))),
        NodeSpec(n("map_server"), services=(ServiceSpec(n("map_server/change_state"), T["change_state"]),),
                 pubs=(PubSpec(n("map"), T["grid"], 0.0), PubSpec(n("map_server/transition_event"),
                                                                  T["transition"], 0.0))),
        # active 10 s of every 30 s (the robot docks to charge), silent while inactive
        NodeSpec(n("docking_server"),
                 services=(ServiceSpec(n("docking_server/change_state"), T["change_state"]),),
                 pubs=(PubSpec(n("dock_pose"), T["pose"], 5.0),
                       PubSpec(n("docking_server/transition_event"), T["transition"], 0.0))),
    )),
    GroupSpec("system", (
        NodeSpec(n("robot_state_publisher"), subs=(SubSpec(n("joint_states"), T["joints"]),),
                 pubs=(PubSpec(n("robot_description"), T["string"], 0.0),)),
        NodeSpec(n("diagnostic_aggregator"), subs=(SubSpec(DIAG, T["diag"]),),
                 pubs=(PubSpec("/diagnostics_agg", T["diag"], 1.0),
                       PubSpec("/diagnostics_toplevel_state", T["diag_status"], 1.0))),
    )),
    GroupSpec("calibration", (
        NodeSpec(n("imu_calibration"), subs=(SubSpec(n("imu"), T["imu"]),)),
    )),
    GroupSpec("console", (
        NodeSpec(n("operator_console"),
                 subs=(SubSpec("/diagnostics_agg", T["diag"]), SubSpec(n("battery_state"), T["battery"]),
                       SubSpec(n("pallet_detections"), T["poses"]), SubSpec(n("map"), T["grid"]),
                       SubSpec(n("robot_description"), T["string"]))),
    )),
)

_ALL: tuple[str, ...] = ()  # every node
_SERVERS = (n("planner_server"),)
_BEST_EFFORT_READERS = tuple(s.name for g in AMR_GROUPS for s in g.nodes
                             if any(sub.topic in BEST_EFFORT for sub in s.subs))
_RESPAWNED = tuple(s.name for g in AMR_GROUPS if g.respawn for s in g.nodes)

AMR = Topology("warehouse_amr", AMR_GROUPS, entry=ENTRY, faults=(
    ("crash", _ALL), ("hang", _ALL), ("degrade", _ALL), ("cpu", _ALL), ("leak", _ALL), ("delay", _ALL),
    ("errlog", _ALL), ("diag", tuple(UPDATERS)), ("slow_service", _SERVERS), ("qos", _BEST_EFFORT_READERS),
    ("restart", _RESPAWNED), ("flap", _ALL),
))

# The target each fault hits unless told otherwise: where a warehouse robot would plausibly fail.
DEFAULT_TARGETS: dict[str, str] = {
    "crash": n("amcl"),                 # the navigation container dies with it
    "hang": n("scan_merger"),           # its single-threaded container starves the lidar and IMU drivers
    "degrade": n("front_lidar"),
    "cpu": n("pallet_detector"),
    "leak": n("local_costmap"),
    "delay": n("base_driver"),          # odometry arrives 300 ms old
    "errlog": n("controller_server"),
    "diag": n("base_driver"),           # "base_driver: motors" ERROR, hardware_id roboteq-sbl2360
    "slow_service": n("planner_server"),  # bt_navigator's compute_path calls time out
    "qos": n("amcl"),                   # a reliable /amr1/scan subscription on a best-effort publisher
    "restart": n("camera_driver"),      # respawned by its launcher, fails again
    "flap": n("rear_lidar"),
}
