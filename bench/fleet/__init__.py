"""A fourth robot in plain rclpy, on simulation time: a two-robot delivery fleet in a simulator."""
