"""Differential drive with an offset turret (DDROT): HAMR's kinematics."""
