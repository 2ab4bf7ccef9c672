"""Test helpers of the workspace (only tests import this package; the product
does not): ``pytest_plugin`` (the shared fixtures, loaded through the
``pytest11`` entry point), ``ros_probe``, ``can_rig``, ``foxglove_client``,
``flood_publisher``."""
