"""A third robot, written by hand in plain rclpy (not from the demo's topologies): a pick station."""
