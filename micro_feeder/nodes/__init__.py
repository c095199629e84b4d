"""Thin rclpy nodes over the physics: actuator, simulator, recorder, replay."""
