"""A rover prototyped in simulation (a Gazebo-like simulator, its ROS bridge, nav2, SLAM, tools)."""
