"""ROS shell of the holonomic base stack: base controller node, bringup, demo."""
