"""ROS 2 nodes (rclpy): thin wrappers that convert messages, hold parameters and call the
layers below."""
