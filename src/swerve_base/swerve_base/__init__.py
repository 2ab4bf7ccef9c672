"""Swerve bases: steered wheels without caster offset -- kinematics, steering law, odometry."""
