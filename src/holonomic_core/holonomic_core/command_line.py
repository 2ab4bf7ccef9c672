"""Command-line parsing shared by every ``holonomic-*`` program.

A bad argument ends the program with ONE line on stderr naming the argument
and what it allows, and exit status 2 -- never a traceback, never argparse's
multi-line usage block. The argument types below say what they accept in that
line; the programs' own checks after parsing go through
:meth:`ArgumentParser.error` too.
"""

from __future__ import annotations

import argparse
import math
import sys
from typing import NoReturn

#: exit status of every program for invalid input (argparse's convention)
EXIT_USAGE = 2


def usage_error(prog: str, message: str) -> NoReturn:
    """Print ``prog: message`` on stderr and exit 2."""
    print(f"{prog}: {message}", file=sys.stderr)
    raise SystemExit(EXIT_USAGE)


class ArgumentParser(argparse.ArgumentParser):
    """argparse with a one-line error (``prog: message (see prog --help)``).

    The description and epilog may be docstring text: their reST literals
    (double backquotes) are shown plain in ``--help``."""

    def __init__(self, *args, **kwargs):
        for key in ("description", "epilog"):
            if kwargs.get(key):
                kwargs[key] = kwargs[key].replace("``", "")
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        usage_error(self.prog, f"{message} (see {self.prog} --help)")


class ShowDefaults(argparse.RawDescriptionHelpFormatter):
    """``--help`` keeps the description's line breaks and shows every default."""

    def _get_help_string(self, action):
        text = action.help or ""
        if "%(default)" not in text and action.option_strings \
                and action.default not in (None, False, "", [], argparse.SUPPRESS):
            text += " (default: %(default)s)"
        return text


def number(low: float | None = None, high: float | None = None, *, strict_low: bool = False,
           integer: bool = False, unit: str = ""):
    """An argparse ``type`` for a finite number in [low, high] (``strict_low``:
    (low, high]); its error names the range and unit."""
    kind = "an integer" if integer else "a number"
    parts = [kind]
    if low is not None and high is not None:
        parts.append(f"in {'(' if strict_low else '['}{low:g}, {high:g}]")
    elif low is not None:
        parts.append(f"{'>' if strict_low else '>='} {low:g}")
    elif high is not None:
        parts.append(f"<= {high:g}")
    if unit:
        parts.append(unit)
    wanted = " ".join(parts)

    def parse(text: str):
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {wanted}, got {text!r}") from None
        if not math.isfinite(value) or (low is not None and (value < low or
                                                              (strict_low and value == low))) \
                or (high is not None and value > high):
            raise argparse.ArgumentTypeError(f"expected {wanted}, got {text!r}")
        return value

    parse.__name__ = kind   # argparse names the type in some messages
    return parse


def output_file(text: str) -> str:
    """An argparse ``type``: a file path the program can write at its end --
    checked now, before minutes of work, not when the results are ready."""
    from pathlib import Path
    import os

    path = Path(text)
    folder = path.absolute().parent
    if path.is_dir():
        raise argparse.ArgumentTypeError(f"cannot write {text!r}: it is a folder")
    if not folder.is_dir():
        raise argparse.ArgumentTypeError(f"cannot write {text!r}: no folder {str(folder)!r}")
    if not os.access(folder, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise argparse.ArgumentTypeError(f"cannot write {text!r}: permission denied")
    return text


def robot_config(text: str) -> str:
    """An argparse ``type``: a robot config name or YAML path whose whole
    configuration is valid (the config's own one-line error otherwise)."""
    from holonomic_core.config import load_config
    from holonomic_core.schema import ConfigError

    try:
        load_config(text)
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return text
