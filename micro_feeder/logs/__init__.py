"""MCAP logs (ROS 2 profile): writing, reading, summaries, plots. No rclpy needed."""
