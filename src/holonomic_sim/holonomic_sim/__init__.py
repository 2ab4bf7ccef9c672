"""pybullet stand-in for the hardware: URDF from the robot config, the `sim` driver backend."""
