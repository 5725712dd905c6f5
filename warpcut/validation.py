"""What a value given to the library must be, checked where it comes in.

Every public config dataclass and constructor of warpcut and envs (:class:`~warpcut.sim.config.SimConfig`,
:class:`~warpcut.sim.config.SheetGrid`, :class:`~warpcut.task.CuttingTask`, :class:`~warpcut.sim.simulator.
Simulator`, :class:`~warpcut.contours.Contour`, the planner's types, the envs' options and constructors)
checks its fields with these functions, so that a wrong value fails at once, in one line that names
``Class.field``, what it takes and what was given::

    SimConfig.resolution: an integer in [5, 100], or a pair (nx, ny) of them (got 25.5)

and never runs (a bool taken as a number, a count of 0 taken as "the default") or fails deep inside with a
message that does not say which field. The rules are the same everywhere:

- a *number* is an ``int``, a ``float`` or a NumPy integer or floating scalar, never a bool, and finite
  unless the field says ``inf`` means something;
- an *integer* (a count, a size, a seed) is an ``int`` or a NumPy integer, never a bool or a float (``2.0``
  is refused: a count written as a float is usually a computed value gone wrong);
- a *flag* is ``True`` or ``False`` (or a NumPy bool), never ``0``, ``1`` or ``"false"``;
- text is a ``str``.

Each function returns the value as plain Python (NumPy scalars become ``int``, ``float`` or ``bool``).
Everything they raise is a :class:`ConfigError`, a ``ValueError``: the command line reports it in one line.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Collection, Mapping
from typing import Any, NoReturn

import numpy as np

FLOAT32_MAX = float(np.finfo(np.float32).max)
"""The largest magnitude a per-env parameter may have: the kernels read it as float32."""


class ConfigError(ValueError):
    """A configuration value is invalid; the message names the field (``Class.field``) and what it takes.

    Attributes:
        where: The field, e.g. ``"SimConfig.resolution"``.
        requirement: What the field takes and what was given, e.g. ``"an integer >= 5 (got 25.5)"``.
    """

    def __init__(self, where: str, requirement: str):
        self.where = where
        self.requirement = one_line(requirement)
        super().__init__(f"{where}: {self.requirement}")

    @property
    def field(self) -> str:
        """The field's own name, without its class: ``resolution``."""
        return self.where.rsplit(".", 1)[-1]

    def renamed(self, where: str) -> ConfigError:
        """The same requirement, naming the field as the caller knows it (e.g. ``sim.resolution`` in a job,
        ``--set: sim.resolution`` on the command line)."""
        return ConfigError(where, self.requirement)


def one_line(text: str) -> str:
    """``text`` with every run of whitespace (newlines included) as one space."""
    return " ".join(str(text).split())


def shown(value: Any, limit: int = 80) -> str:
    """``repr(value)`` on one line, cut to about ``limit`` characters."""
    text = one_line(repr(value))
    return text if len(text) <= limit else text[: limit - 3] + "..."


def fail(where: str, requirement: str, value: Any) -> NoReturn:
    """Raise :class:`ConfigError` ``"{where}: {requirement} (got {value})"``."""
    raise ConfigError(where, f"{requirement} (got {shown(value)})")


def is_number(value: Any) -> bool:
    """An ``int``, ``float`` or NumPy integer or floating scalar; not a bool."""
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(value, bool)


def is_integer(value: Any) -> bool:
    """An ``int`` or NumPy integer; not a bool, not a float."""
    return isinstance(value, int | np.integer) and not isinstance(value, bool)


def _bound(value: float) -> str:
    """A bound in words: an integer in full (a seed's 2147418111, not 2.14742e+09), a float as ``%g``."""
    if isinstance(value, int) and not isinstance(value, bool):
        return str(value)
    return f"{value:g}"


def range_text(
    kind: str, low: float | None, high: float | None, low_open: bool = False, high_open: bool = False
) -> str:
    """``kind`` with its range in words: ``a number in (0, 1]``, ``an integer >= 1``, ``a number``."""
    if low is not None and high is not None:
        return f"{kind} in {'(' if low_open else '['}{_bound(low)}, {_bound(high)}{')' if high_open else ']'}"
    if low is not None:
        return f"{kind} {'>' if low_open else '>='} {_bound(low)}"
    if high is not None:
        return f"{kind} {'<' if high_open else '<='} {_bound(high)}"
    return kind


def _within(value: float, low, high, low_open: bool, high_open: bool) -> bool:
    if low is not None and (value < low or (low_open and value == low)):
        return False
    return not (high is not None and (value > high or (high_open and value == high)))


def _requirement(base: str, unit: str, optional: bool, note: str) -> str:
    text = base + (f" {unit}" if unit else "")
    if optional:  # the note says what None stands for
        return text + ", or None" + (f" for {note}" if note else "")
    return text + (f" ({note})" if note else "")


def check_number(
    where: str,
    value: Any,
    low: float | None = None,
    high: float | None = None,
    *,
    low_open: bool = False,
    high_open: bool = False,
    allow_inf: bool = False,
    optional: bool = False,
    unit: str = "",
    note: str = "",
) -> float | None:
    """``value`` as a ``float`` (None where ``optional``), or :class:`ConfigError` naming ``where``.

    Args:
        where: ``Class.field``.
        value: What was given.
        low, high: The range (None: unbounded); ``low_open``/``high_open`` exclude the bound itself.
        allow_inf: Accept an infinite value (within the range); NaN never.
        optional: Accept None.
        unit: The unit, said after the range (``mm``).
        note: What else the message says, in parentheses (a default, what a value means); where
            ``optional``, what None stands for (``or None for {note}``).
    """
    if optional and value is None:
        return None
    ok = is_number(value)
    if ok:
        number = float(value)
        ok = not math.isnan(number) and (allow_inf or math.isfinite(number))
        ok = ok and _within(number, low, high, low_open, high_open)
    if not ok:
        kind = "a number" if allow_inf else "a finite number"
        if low is not None or high is not None:
            kind = "a number"
        fail(
            where, _requirement(range_text(kind, low, high, low_open, high_open), unit, optional, note), value
        )
    return number


def check_integer(
    where: str,
    value: Any,
    low: int | None = None,
    high: int | None = None,
    *,
    optional: bool = False,
    note: str = "",
) -> int | None:
    """``value`` as an ``int`` (None where ``optional``), or :class:`ConfigError` naming ``where``; a bool or
    a float (even ``2.0``) is refused."""
    if optional and value is None:
        return None
    if not (is_integer(value) and _within(int(value), low, high, False, False)):
        fail(where, _requirement(range_text("an integer", low, high), "", optional, note), value)
    return int(value)


def check_flag(where: str, value: Any, note: str = "") -> bool:
    """``value`` as a ``bool``, or :class:`ConfigError`: only ``True`` or ``False`` (or a NumPy bool)."""
    if not isinstance(value, bool | np.bool_):
        fail(where, _requirement("True or False", "", False, note), value)
    return bool(value)


def check_choice(where: str, value: Any, choices: Collection[str], *, optional: bool = False) -> str | None:
    """``value`` if it is one of ``choices`` (None where ``optional``), or :class:`ConfigError`."""
    if optional and value is None:
        return None
    if not (isinstance(value, str) and value in choices):
        listed = ", ".join(repr(c) for c in choices)
        fail(where, f"one of {listed}" + (", or None" if optional else ""), value)
    return value


def check_text(where: str, value: Any, *, optional: bool = False, note: str = "") -> str | None:
    """``value`` if it is a non-empty ``str`` (None where ``optional``), or :class:`ConfigError`."""
    if optional and value is None:
        return None
    if not (isinstance(value, str) and value):
        fail(where, _requirement("a non-empty string", "", optional, note), value)
    return value


def check_numbers(
    where: str,
    value: Any,
    low: float | None = None,
    high: float | None = None,
    *,
    low_open: bool = False,
    high_open: bool = False,
    unit: str = "",
    note: str = "",
) -> Any:
    """A per-env parameter: one number, or a non-empty list (tuple, 1-D array) of numbers, one per env, each
    finite, within float32's range and within ``[low, high]``. Returns ``value`` with NumPy scalars as
    Python numbers and lists as they were given; :class:`ConfigError` naming ``where`` otherwise."""
    one = range_text("a number", low, high, low_open, high_open) + (f" {unit}" if unit else "")
    requirement = _requirement(f"{one}, or a list of one per env", "", False, note)
    if is_number(value):
        values, result = np.array([float(value)]), float(value)
    elif isinstance(value, list | tuple) and value and all(is_number(v) for v in value):
        values, result = np.array([float(v) for v in value]), value
    elif isinstance(value, np.ndarray) and value.ndim == 1 and value.size and value.dtype.kind in "iuf":
        values, result = value.astype(np.float64), value
    else:
        fail(where, requirement, value)
    finite = np.isfinite(values).all() and (np.abs(values) <= FLOAT32_MAX).all()
    if not finite or not all(_within(v, low, high, low_open, high_open) for v in values.tolist()):
        fail(where, requirement, value)
    return result


def check_instance(where: str, value: Any, kind: type | tuple[type, ...], what: str) -> Any:
    """``value`` if it is an instance of ``kind``, or :class:`ConfigError` saying ``what`` to give."""
    if not isinstance(value, kind):
        fail(where, what, value)
    return value


def check_known_fields(where: str, data: Mapping[str, Any], kind: type) -> None:
    """``ValueError`` naming ``where`` and the keys of ``data`` that are not fields of the dataclass ``kind``
    (with the known ones), as a settings file or a run directory's JSON is read back."""
    known = {f.name for f in dataclasses.fields(kind)}
    unknown = sorted(set(data) - known)
    if unknown:
        raise ValueError(f"{where}: unknown field(s) {', '.join(unknown)}; known: {', '.join(sorted(known))}")
