"""A second demo system: a warehouse AMR built the way production ROS 2 robots are (docs/demo.md)."""
