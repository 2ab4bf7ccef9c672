"""ODrive firmware 0.6 endpoint ids: the ``flat_endpoints.json`` of a firmware build.

Over CAN, firmware 0.6.x reads and writes any property by *endpoint id*
(RxSdo/TxSdo). The ids are generated per firmware build **and** board: the
same property has another id on another firmware version or on an ODrive
Pro, S1 or Micro. ODrive publishes one ``flat_endpoints.json`` per firmware
release and board; its layout (the one ODrive's CAN examples read)::

    {"fw_version": "0.6.11", "hw_version": "4.4.58",
     "endpoints": {"axis0.config.watchdog_timeout": {"id": 123, "type": "float",
                                                     "access": "rw"}, ...}}

No package the set-up installs ships these files (the ``odrive`` package
reads the ids from the device over USB), so the user points the driver at
the file of their drives (``odrive_can.endpoints``) and the driver checks
each drive's Get_Version against the file's versions before it reads or
writes a single endpoint: with another build's ids it would touch the wrong
property. Pure functions, no bus.
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass

from holonomic_drivers import odrive_protocol as proto

#: the axis watchdog of a single-axis 0.6 board (Pro, S1, Micro): axis0
ENABLE_WATCHDOG = "axis0.config.enable_watchdog"
WATCHDOG_TIMEOUT = "axis0.config.watchdog_timeout"
WATCHDOG_ENDPOINTS = (ENABLE_WATCHDOG, WATCHDOG_TIMEOUT)


@dataclass(frozen=True)
class Endpoint:
    path: str
    id: int
    type: str


@dataclass(frozen=True)
class EndpointFile:
    """The endpoints this driver uses, from one ``flat_endpoints.json``."""

    source: str
    fw_version: str
    hw_version: str
    endpoints: dict[str, Endpoint]

    def mismatch(self, version: proto.Version) -> str | None:
        """Why this file does not describe a drive that answered ``version``
        (None: it does). The file's firmware may carry a suffix ("0.6.11-rc1")."""
        fw = self.fw_version.partition("-")[0]
        if fw != version.fw_text or self.hw_version != version.hw_text:
            return (f"the drive runs firmware {version.fw_text} on board {version.hw_text}, "
                    f"{self.source} is for firmware {self.fw_version} on board "
                    f"{self.hw_version}")
        return None


def parse(text: str, source: str) -> EndpointFile:
    """The watchdog endpoints of a flat_endpoints.json's text; ValueError,
    naming what is wrong, for anything else."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"not JSON ({exc})") from None
    if not isinstance(data, dict):
        raise ValueError("not a JSON object")
    missing = [k for k in ("fw_version", "hw_version", "endpoints") if k not in data]
    if missing or not isinstance(data["endpoints"], dict):
        raise ValueError(f"no {', '.join(missing) or 'endpoints object'}: not an ODrive "
                         "flat_endpoints.json")
    endpoints = {}
    for path in WATCHDOG_ENDPOINTS:
        entry = data["endpoints"].get(path)
        if not isinstance(entry, dict):
            raise ValueError(f"has no endpoint {path} (a multi-axis or 0.5 board?)")
        kind, ident = entry.get("type"), entry.get("id")
        if kind not in proto.ENDPOINT_TYPES or \
                struct.calcsize("<" + proto.ENDPOINT_TYPES[kind]) > 4:
            raise ValueError(f"{path} has type {kind!r}, not one of 4 bytes or less")
        if not isinstance(ident, int) or not 0 <= ident <= 0xFFFF:
            raise ValueError(f"{path} has id {ident!r}, not 0..65535")
        endpoints[path] = Endpoint(path, ident, kind)
    return EndpointFile(source, str(data["fw_version"]), str(data["hw_version"]), endpoints)


def load(path: str) -> EndpointFile:
    """:func:`parse` of the file at ``path`` (OSError if it cannot be read)."""
    with open(path, encoding="utf-8") as f:
        return parse(f.read(), path)

