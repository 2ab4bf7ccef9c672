"""Powered-caster vehicles: kinematics and slip-minimising odometry."""
