"""A fifth robot in plain rclpy: a mobile manipulator (a base, two arms, cameras) in a research lab."""
