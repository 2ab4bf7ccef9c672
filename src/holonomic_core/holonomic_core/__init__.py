"""ROS-free core of the holonomic base stack: model, kinematics protocol,
odometry, limits, the driver interface and the control cycle."""
