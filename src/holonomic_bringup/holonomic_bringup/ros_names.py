"""ROS names given on the command line, checked before anything starts.

rclpy's own check (``validate_namespace``) raises a three-line exception deep
inside node creation; here a bad ``--namespace`` becomes argparse's one-line
error instead.
"""

from __future__ import annotations

import argparse


def namespace(text: str) -> str:
    """An argparse ``type``: a ROS namespace (``robot1``, ``/fleet/r1``) ->
    its absolute form without a trailing slash (``""`` for the root)."""
    from rclpy.exceptions import InvalidNamespaceException
    from rclpy.validate_namespace import validate_namespace

    stripped = text.strip("/")
    if not stripped:
        return ""
    absolute = "/" + stripped
    try:
        validate_namespace(absolute)
    except InvalidNamespaceException as exc:
        # The exception's first line says why; the next two point at the
        # character (they would be a multi-line message).
        why = str(exc).splitlines()[0].removeprefix("Invalid namespace: ").rstrip(":")
        raise argparse.ArgumentTypeError(
            f"{text!r} is not a ROS namespace: {why} (letters, digits and '_', "
            "not starting with a digit, tokens separated by '/')") from None
    return absolute
