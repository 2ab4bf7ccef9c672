"""The object dictionary of a CiA 402 drive: what the drive has, from its
EDS/DCF file or the built-in generic one, as the ``cia402`` driver and the
emulated drive read it.

A drive's EDS (electronic data sheet, CiA 306) lists every object with its
data type, access right, PDO mappability and default value; a DCF is the
same file with the values of one configured device. ``canopen`` parses both
(:func:`load_dictionary`). Without a file the driver assumes
:func:`generic_dictionary` -- the objects and types of CiA 402's
recommendations (32-bit velocities, four RPDOs/TPDOs, heartbeat consumer),
which is what the driver hard-coded before it read EDS files.

Multi-axis devices (CiA 402 part 2, "virtual devices"): axis ``k`` of a
device keeps its profile objects 0x6000..0x67FF at ``index + 0x800 * k``
(so axis 1's controlword is 0x6840); the communication objects (0x1xxx)
are the device's, shared by its axes. :class:`AxisObjects` is one axis's
view of a dictionary.
"""

from __future__ import annotations

from dataclasses import dataclass

import canopen
from canopen.objectdictionary import ODArray, ODRecord, ODVariable, ObjectDictionary
from canopen.objectdictionary import datatypes as dt

from holonomic_drivers import cia402_protocol as co

#: profile objects of axis k are at index + AXIS_OFFSET * k
AXIS_OFFSET = 0x800
MAX_AXES = 8
#: indices that move with the axis (CiA 402 part 2: 0x6000..0x67FF per axis)
_PROFILE_RANGE = range(0x6000, 0x6800)

#: CiA 402 0x60A9 "SI unit velocity" values the driver knows, and the
#: velocity units per motor rev/s each one means (None: counts/s, i.e.
#: encoder counts per rev). Encoding (CiA 402 part 2, 0x60A8/0x60A9):
#: prefix << 24 | numerator unit << 16 | denominator unit << 8, with
#: 0xB4 = revolution, 0xB5 = increment (count), 0x03 = second, 0x47 = minute
#: and prefix 0xFF = 10^-1, 0xFD = 10^-3.
SI_VELOCITY_UNITS = {
    0x00B50300: ("counts/s", None),
    0x00B44700: ("rpm", 60.0),
    0xFFB44700: ("0.1 rpm", 600.0),
    0xFDB44700: ("0.001 rpm", 60000.0),
    0x00B40300: ("rev/s", 1.0),
}


class DictionaryError(ValueError):
    """An EDS/DCF file that cannot be read, or that lacks what is needed."""


def load_dictionary(path: str, node_id: int) -> ObjectDictionary:
    """Parse the EDS/DCF at ``path`` for ``node_id`` ($NODEID resolved).

    Raises :class:`DictionaryError` with one line saying what is wrong.
    """
    try:
        od = canopen.import_od(path, node_id)
    except FileNotFoundError:
        raise DictionaryError(f"no such file: {path}") from None
    except (OSError, ValueError, KeyError, canopen.ObjectDictionaryError) as exc:
        # configparser's errors are ValueErrors; import_od's unknown suffix too
        raise DictionaryError(f"cannot read {path} as an EDS/DCF file "
                              f"({type(exc).__name__}: {str(exc).splitlines()[0]})") from None
    except Exception as exc:  # noqa: BLE001 (a malformed file can break the parser anywhere)
        raise DictionaryError(f"cannot read {path} as an EDS/DCF file "
                              f"({type(exc).__name__}: {exc})") from None
    if co.DEVICE_TYPE not in od:
        raise DictionaryError(f"{path} has no device type object 0x1000: not a CANopen EDS")
    return od


def mode_names(bits: int) -> str:
    """The CiA 402 modes set in a 0x6502 value, e.g. ``"pp, pv, csv"``."""
    names = [name for mode, name in _MODE_NAMES.items() if bits & mode_bit(mode)]
    return ", ".join(names) if names else "none"


def mode_bit(mode: int) -> int:
    """Bit of mode of operation ``mode`` (1..10) in 0x6502."""
    return 1 << (int(mode) - 1)


_MODE_NAMES = {1: "pp", 2: "vl", 3: "pv", 4: "tq", 6: "hm", 7: "ip", 8: "csp", 9: "csv",
               10: "cst"}


@dataclass(frozen=True)
class AxisObjects:
    """One axis of one drive as its dictionary describes it.

    ``od``: the device's dictionary; ``axis``: 0 for the first (or only)
    axis; ``source``: the file it came from ("" for the generic one).
    """

    od: ObjectDictionary
    axis: int = 0
    source: str = ""

    def index(self, profile_index: int) -> int:
        """The index of a profile object on this axis (communication objects
        are the device's and do not move)."""
        if profile_index in _PROFILE_RANGE:
            return profile_index + AXIS_OFFSET * self.axis
        return profile_index

    def variable(self, index: int, sub: int = 0) -> ODVariable | None:
        """The dictionary entry of ``index`` (axis-relative for profile
        objects) and ``sub``, or None if the drive does not have it."""
        obj = self.od.get(self.index(index))
        if obj is None:
            return None
        if isinstance(obj, ODVariable):
            return obj if sub == 0 else None
        if isinstance(obj, (ODRecord, ODArray)):
            try:
                return obj[sub]
            except KeyError:
                return None
        return None

    def has(self, index: int, sub: int = 0) -> bool:
        return self.variable(index, sub) is not None

    def mappable(self, index: int, sub: int = 0) -> bool:
        var = self.variable(index, sub)
        return var is not None and var.pdo_mappable

    def bits(self, index: int, sub: int = 0) -> int:
        """Size of the object in bits (for a PDO mapping entry)."""
        return len(self._require(index, sub))

    def encode(self, index: int, sub: int, value) -> bytes:
        """``value`` in the object's own type; integers are clipped to its range
        (a 16-bit target velocity saturates rather than wraps)."""
        var = self._require(index, sub)
        if var.data_type in dt.INTEGER_TYPES:
            low, high = integer_range(var)
            value = int(min(max(int(value), low), high))
        return var.encode_raw(value)

    def decode(self, index: int, sub: int, data: bytes):
        return self._require(index, sub).decode_raw(bytes(data))

    def default(self, index: int, sub: int = 0):
        """The file's ParameterValue (DCF) or DefaultValue, None if it has none."""
        var = self.variable(index, sub)
        if var is None:
            return None
        return var.value if var.value is not None else var.default

    def pdo_count(self, comm_base: int) -> int:
        """How many PDO communication objects (0x1400.. or 0x1800..) the drive has."""
        n = 0
        while n < 512 and (comm_base + n) in self.od:
            n += 1
        return n

    def mapping_capacity(self, map_index: int) -> int:
        """How many objects the PDO mapping record ``map_index`` (0x16xx or
        0x1Axx) can hold: the mapping sub-indices the file declares (some
        drives declare fewer than eight, e.g. one on their first PDO)."""
        record = self.od.get(map_index)
        if not isinstance(record, (ODRecord, ODArray)):
            return 0
        return sum(1 for sub in record if sub != 0)

    def cob_id_flags(self, comm_index: int) -> int:
        """Bit 30 of a PDO's COB-ID as the file sets it by default (CiA 301:
        no RTR allowed on this PDO), to be written back as the file has it.
        Bit 29 (29-bit identifier) is not kept: the driver configures and
        uses 11-bit identifiers (bits 0..10); bit 31 is the valid bit, which
        the set-up sequence itself clears and sets."""
        default = self.default(comm_index, 1)
        return (int(default) & co.PDO_NO_RTR) if default is not None else 0

    def cob_id_default(self, comm_index: int) -> int | None:
        """The 11-bit CAN identifier that the file gives a PDO, if any."""
        default = self.default(comm_index, 1)
        return None if default is None else int(default) & 0x7FF

    def _require(self, index: int, sub: int) -> ODVariable:
        var = self.variable(index, sub)
        if var is None:
            raise KeyError(f"0x{self.index(index):04X}:{sub} is not in the dictionary")
        return var


def integer_range(var: ODVariable) -> tuple[int, int]:
    """Smallest and largest value of an integer object."""
    bits = len(var)
    if var.data_type in dt.SIGNED_TYPES:
        return -(1 << (bits - 1)), (1 << (bits - 1)) - 1
    return 0, (1 << bits) - 1


# -- the generic drive ---------------------------------------------------------------------
def _var(index: int, sub: int, name: str, data_type: int, access: str, default=None,
         mappable: bool = False, default_raw: str | None = None) -> ODVariable:
    var = ODVariable(name, index, sub)
    var.data_type, var.access_type, var.pdo_mappable = data_type, access, mappable
    var.default = default
    if default_raw is not None:
        var.default_raw = default_raw
        var.relative = "$NODEID" in default_raw
    return var


def _record(index: int, name: str, members) -> ODRecord:
    record = ODRecord(name, index)
    for member in members:
        record.add_member(member)
    return record


def generic_dictionary(node_id: int | None = None, *, axes: int = 1,
                       supported_modes: int = (mode_bit(3) | mode_bit(9) | mode_bit(10)),
                       target_velocity_type: int = dt.INTEGER32,
                       torque: bool = True, error_code: str = "pdo",
                       watchdog: str = "heartbeat", velocity_unit: int | None = None,
                       pdos: int = 4, rated_torque_mnm: int = 1000,
                       rtr_not_allowed: bool = False, rpdo_rtr_bit: bool = False,
                       abort_connection: tuple[str, int] | None = ("rw", 1),
                       first_pdo_entries: int = 8) -> ObjectDictionary:
    """A CiA 402 drive's object dictionary, built in code.

    Defaults: the drive that the ``cia402`` driver assumes without an EDS
    (pv, csv and cst in 0x6502; 32-bit 0x60FF; 0x6071 and 0x6076 = 1 N m;
    0x603F mappable; heartbeat consumer 0x1016; four RPDOs and TPDOs).
    The keywords change one feature each -- ``axes`` (profile objects at
    +0x800 per axis), ``target_velocity_type`` (a canopen data type, e.g.
    INTEGER16), ``torque`` (0x6071/0x6076 present), ``error_code`` ("pdo": 0x603F
    mappable, "sdo": not mappable, "none": no 0x603F),
    ``watchdog`` ("heartbeat": 0x1016, "guarding": 0x100C/0x100D only,
    "none"), ``velocity_unit`` (0x60A9 value, None: no 0x60A9), ``pdos``,
    ``rtr_not_allowed`` (bit 30 in the TPDO COB-IDs), ``rpdo_rtr_bit`` (bit
    30 in the RPDO COB-IDs too, ``$NODEID+0x40000200``), ``abort_connection``
    (0x6007: (access, default), e.g. ("rw", 0) or ("ro", 0); None: no 0x6007),
    ``first_pdo_entries``
    (mapping entries of RPDO1 and TPDO1; the others hold 8) -- which is how the
    tests' EDS files are written (``canopen.export_od``). ``node_id``:
    resolves $NODEID in the COB-ID defaults (None keeps them relative).
    """
    od = ObjectDictionary()
    od.node_id = node_id

    def add(obj):
        od.add_object(obj)

    u8, u16, u32 = dt.UNSIGNED8, dt.UNSIGNED16, dt.UNSIGNED32
    device_type = co.PROFILE_402 | (0x00020000 if axes == 1 else 0x00FF0000)
    add(_var(co.DEVICE_TYPE, 0, "Device type", u32, "const", device_type))
    add(_var(co.ERROR_REGISTER, 0, "Error register", u8, "ro", 0, mappable=True))
    if watchdog == "heartbeat":
        add(_record(co.CONSUMER_HEARTBEAT_TIME, "Consumer heartbeat time", [
            _var(co.CONSUMER_HEARTBEAT_TIME, 0, "Highest sub-index supported", u8, "const", 1),
            _var(co.CONSUMER_HEARTBEAT_TIME, 1, "Consumer heartbeat time 1", u32, "rw", 0)]))
    elif watchdog == "guarding":
        add(_var(co.GUARD_TIME, 0, "Guard time", u16, "rw", 0))
        add(_var(co.LIFE_TIME_FACTOR, 0, "Life time factor", u8, "rw", 0))
    elif watchdog != "none":
        raise ValueError(f"watchdog {watchdog!r}: heartbeat, guarding or none")
    add(_var(co.PRODUCER_HEARTBEAT_TIME, 0, "Producer heartbeat time", u16, "rw", 0))
    add(_record(0x1018, "Identity object", [
        _var(0x1018, 0, "Highest sub-index supported", u8, "const", 1),
        _var(0x1018, 1, "Vendor-ID", u32, "ro", 0)]))
    for k in range(pdos):
        for comm, mapping, base in ((co.RPDO_COMM, co.RPDO_MAP, co.RPDO),
                                    (co.TPDO_COMM, co.TPDO_MAP, co.TPDO)):
            cob = base[k] if k < 4 else 0x80000000
            rtr = rtr_not_allowed and base is co.TPDO or rpdo_rtr_bit and base is co.RPDO
            flags = (co.PDO_NO_RTR if rtr else 0) | \
                (0 if k == 0 else co.PDO_INVALID)
            raw = f"$NODEID+0x{cob | flags:X}" if k < 4 else f"0x{cob:X}"
            default = (cob | flags) + (node_id or 0) if k < 4 else cob
            kind = "RPDO" if base is co.RPDO else "TPDO"
            add(_record(comm + k, f"{kind}{k + 1} communication parameter", [
                _var(comm + k, 0, "Highest sub-index supported", u8, "const", 2),
                _var(comm + k, 1, "COB-ID", u32, "rw", default, default_raw=raw),
                _var(comm + k, 2, "Transmission type", u8, "rw", 0xFF)]))
            entries = first_pdo_entries if k == 0 else 8
            add(_record(mapping + k, f"{kind}{k + 1} mapping parameter", [
                _var(mapping + k, 0, "Number of mapped objects", u8, "rw", 0)] + [
                _var(mapping + k, s, f"Mapped object {s}", u32, "rw", 0)
                for s in range(1, entries + 1)]))
    for axis in range(axes):
        o = AXIS_OFFSET * axis
        if error_code != "none":
            add(_var(co.ERROR_CODE + o, 0, "Error code", u16, "ro", 0,
                     mappable=error_code == "pdo"))
        add(_var(co.CONTROLWORD + o, 0, "Controlword", u16, "rww", 0, mappable=True))
        add(_var(co.STATUSWORD + o, 0, "Statusword", u16, "ro", 0, mappable=True))
        add(_var(co.QUICK_STOP_OPTION + o, 0, "Quick stop option code", dt.INTEGER16, "rw", 2))
        if abort_connection is not None:
            add(_var(co.ABORT_CONNECTION_OPTION + o, 0, "Abort connection option code",
                     dt.INTEGER16, *abort_connection))
        add(_var(co.MODES_OF_OPERATION + o, 0, "Modes of operation", dt.INTEGER8, "rww", 0,
                 mappable=True))
        add(_var(co.MODES_DISPLAY + o, 0, "Modes of operation display", dt.INTEGER8, "ro", 0,
                 mappable=True))
        add(_var(co.POSITION_ACTUAL + o, 0, "Position actual value", dt.INTEGER32, "ro", 0,
                 mappable=True))
        add(_var(co.VELOCITY_ACTUAL + o, 0, "Velocity actual value", target_velocity_type,
                 "ro", 0, mappable=True))
        add(_var(co.TARGET_VELOCITY + o, 0, "Target velocity", target_velocity_type, "rww", 0,
                 mappable=True))
        if torque:
            add(_var(co.TARGET_TORQUE + o, 0, "Target torque", dt.INTEGER16, "rww", 0,
                     mappable=True))
            add(_var(co.MOTOR_RATED_TORQUE + o, 0, "Motor rated torque", u32, "ro",
                     rated_torque_mnm))
        if velocity_unit is not None:
            add(_var(co.SI_UNIT_VELOCITY + o, 0, "SI unit velocity", u32, "rw", velocity_unit))
        add(_var(co.SUPPORTED_MODES + o, 0, "Supported drive modes", u32, "const",
                 supported_modes))
    return od
