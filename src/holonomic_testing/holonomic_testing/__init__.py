"""Test helpers of the workspace (only tests import this package; the product
does not): ``pytest_plugin`` (the shared fixtures, loaded through the
``pytest11`` entry point), ``ros_probe``, ``can_rig`` (with ``drive_host``
and ``ipc_can``, the python-can interface ``holonomic_ipc``),
``foxglove_client``, ``flood_publisher``, ``effort_driver`` (a driver with
torque mode that records what the controller writes)."""
