"""Controllers for the feeder, as pure logic (no rclpy): usable offline and in the nodes."""
