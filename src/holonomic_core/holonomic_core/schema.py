"""Parameter schema: one entry per configuration key, shared by YAML and ROS.

Each :class:`ParamSpec` carries what generate_parameter_library's YAML does --
type, default, description with units, allowed range or choices, read-only --
so the ROS node declares descriptors from it and the ROS-free loader validates
the very same keys. Keys are flat, dot-separated names (``ddrot.wheel_radius``),
which is how ROS 2 params files name nested parameters.
"""

from __future__ import annotations

import difflib
import math
from dataclasses import dataclass
from typing import Any, Iterable, Mapping, Sequence

_TYPES = ("double", "int", "bool", "string", "double_array", "string_array")


class ConfigError(ValueError):
    """An invalid configuration value, naming the key and what is allowed."""

    def __init__(self, key: str, value: Any, allowed: str, message: str | None = None):
        self.key = key
        self.value = value
        self.allowed = allowed
        super().__init__(message or f"invalid parameter '{key}' = {value!r}: expected {allowed}")


@dataclass(frozen=True)
class ParamSpec:
    """Schema of one parameter.

    ``minimum``/``maximum`` bound numbers (and each element of arrays);
    ``exclusive_minimum`` makes the lower bound strict (e.g. a radius > 0).
    ``default`` of ``None`` means the key is required, unless ``optional``:
    then an absent key validates to None (e.g. a joint range: absent means
    the joint is continuous).
    """

    name: str
    type: str
    description: str
    default: Any = None
    minimum: float | None = None
    maximum: float | None = None
    exclusive_minimum: bool = False
    choices: tuple[str, ...] | None = None
    read_only: bool = True
    min_length: int = 0
    optional: bool = False

    def __post_init__(self):
        if self.type not in _TYPES:
            raise ValueError(f"ParamSpec {self.name}: unknown type {self.type}")

    @property
    def required(self) -> bool:
        return self.default is None and not self.optional

    def allowed(self) -> str:
        """Human-readable statement of the allowed values."""
        kind = {"double": "a number", "int": "an integer", "bool": "true or false",
                "string": "a string", "double_array": "a list of numbers",
                "string_array": "a list of strings"}[self.type]
        parts = [kind]
        if self.choices:
            parts = [f"one of {list(self.choices)}"]
        low = self.minimum
        if low is not None and self.maximum is not None:
            bra = "(" if self.exclusive_minimum else "["
            parts.append(f"in {bra}{low:g}, {self.maximum:g}]")
        elif low is not None:
            parts.append(f"{'>' if self.exclusive_minimum else '>='} {low:g}")
        elif self.maximum is not None:
            parts.append(f"<= {self.maximum:g}")
        if self.min_length:
            parts.append(f"with at least {self.min_length} entries")
        return " ".join(parts)

    def coerce(self, value: Any) -> Any:
        """Return ``value`` converted to this type or raise :class:`ConfigError`."""
        if value is None:
            if self.optional:       # written out unset (a recording's config): still unset
                return None
            raise ConfigError(self.name, value, self.allowed())
        if self.type == "double":
            out = self._number(value, self.name)
        elif self.type == "int":
            if isinstance(value, bool) or not isinstance(value, int):
                if isinstance(value, float) and value.is_integer():
                    value = int(value)
                else:
                    raise ConfigError(self.name, value, self.allowed())
            out = int(value)
            self._check_range(out, self.name, value)
        elif self.type == "bool":
            if not isinstance(value, bool):
                raise ConfigError(self.name, value, self.allowed())
            out = value
        elif self.type == "string":
            if not isinstance(value, str):
                raise ConfigError(self.name, value, self.allowed())
            out = value
            if self.choices and out not in self.choices:
                nearest = difflib.get_close_matches(out, self.choices, n=1)
                raise ConfigError(self.name, value, self.allowed() + (
                    f"; did you mean '{nearest[0]}'?" if nearest else ""))
        elif self.type == "double_array":
            if isinstance(value, (str, bytes)) or not isinstance(value, Sequence):
                raise ConfigError(self.name, value, self.allowed())
            out = tuple(self._number(v, self.name, whole=value) for v in value)
        else:  # string_array
            if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) \
                    or not all(isinstance(v, str) for v in value):
                raise ConfigError(self.name, value, self.allowed())
            out = tuple(value)
        if self.type.endswith("_array") and len(out) < self.min_length:
            raise ConfigError(self.name, value, self.allowed())
        return out

    def _number(self, value: Any, key: str, whole: Any = None) -> float:
        shown = value if whole is None else whole
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ConfigError(key, shown, self.allowed())
        out = float(value)
        if not math.isfinite(out):
            raise ConfigError(key, shown, "a finite number")
        self._check_range(out, key, shown)
        return out

    def _check_range(self, out: float, key: str, shown: Any) -> None:
        low, high = self.minimum, self.maximum
        if low is not None and (out < low or (self.exclusive_minimum and out == low)):
            raise ConfigError(key, shown, self.allowed())
        if high is not None and out > high:
            raise ConfigError(key, shown, self.allowed())


def validate(specs: Iterable[ParamSpec], flat: Mapping[str, Any]) -> dict[str, Any]:
    """Validate ``flat`` against ``specs``: typed values, defaults filled in.

    Raises :class:`ConfigError` for the first missing or invalid key. Keys in
    ``flat`` that no spec names are left to :func:`unknown_keys`.
    """
    specs = list(specs)
    names = [s.name for s in specs]
    out: dict[str, Any] = {}
    for spec in specs:
        if spec.name in flat:
            out[spec.name] = spec.coerce(flat[spec.name])
        elif spec.required:
            # A required key that is missing is usually a misspelt one: name
            # the misspelling as written (``ddrot.turet_offset``), not only
            # the key it should have been.
            typo = [k for k in flat if k not in names and _misspelt(k, spec.name)]
            if typo:
                raise unknown_key_error(typo[0], flat[typo[0]], names)
            raise ConfigError(spec.name, "<missing>", spec.allowed() + " (required)")
        else:
            out[spec.name] = spec.default
    return out


def _misspelt(written: str, meant: str) -> bool:
    """``written`` is ``meant`` with one dotted component misspelt
    (``ddrot.turet_offset``, ``ddrott.wheel_radius``) -- not another
    section's key of the same name (``cia402.joints.J.node_id`` is no typo of
    ``odrive_can.joints.J.node_id``)."""
    a, b = written.split("."), meant.split(".")
    differ = [(x, y) for x, y in zip(a, b) if x != y]
    return len(a) == len(b) and len(differ) == 1 and \
        difflib.SequenceMatcher(None, *differ[0]).ratio() >= 0.75


def unknown_key_error(key: str, value: Any, names: Iterable[str]) -> ConfigError:
    """The error for a key no spec declares: the key as written, the nearest
    declared key (difflib) and the valid keys of its section (or the sections,
    when the section itself is unknown)."""
    names = sorted(set(names))
    section = key.rsplit(".", 1)[0] + "." if "." in key else ""
    siblings = [n for n in names if n.startswith(section) and "." not in n[len(section):]] \
        if section else [n for n in names if "." not in n]
    nearest = difflib.get_close_matches(key, names, n=1, cutoff=0.6)
    text = "no such parameter"
    if nearest:
        text += f"; did you mean '{nearest[0]}'?"
    if siblings:
        where = f"section '{section[:-1]}'" if section else "the top level"
        text += f" Valid keys of {where}: {', '.join(n[len(section):] for n in siblings)}"
    else:
        sections = sorted({n.split(".")[0] for n in names if "." in n})
        text += f" Known sections: {', '.join(sections)}"
    return ConfigError(key, value, text, f"unknown parameter '{key}' (= {value!r}): {text}")


def unknown_keys(specs: Iterable[ParamSpec], flat: Mapping[str, Any]) -> list[str]:
    """Keys of ``flat`` that no spec declares (typos, usually)."""
    names = {s.name for s in specs}
    return sorted(k for k in flat if k not in names)


def flatten(tree: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    """``{'a': {'b': 1}}`` -> ``{'a.b': 1}``; lists are leaves."""
    out: dict[str, Any] = {}
    for key, value in tree.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping):
            out.update(flatten(value, name + "."))
        else:
            out[name] = value
    return out


def parse_overrides(items: Iterable[str]) -> dict[str, Any]:
    """``["NAME:=VALUE", ...]`` (the command lines' ``-p``) to a flat dict,
    each VALUE read as YAML (``true``, ``10``, ``[0, 1]``, text). Raises
    ValueError on an item without ``:=``."""
    import yaml

    out: dict[str, Any] = {}
    for item in items:
        name, sep, text = item.partition(":=")
        if not sep or not name.strip():
            raise ValueError(f"-p expects NAME:=VALUE, got {item!r}")
        try:
            out[name.strip()] = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise ValueError(f"-p {name.strip()}: unreadable value {text!r}") from exc
    return out


def number_or_none(value) -> float | None:
    """``value`` as a float default for keys that fall back on a shared key
    (``pcv.NAME.wheel_radius`` on ``pcv.wheel_radius``), or None when it is
    not a number (then the key is required and validation says so)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return None
    return float(value)
