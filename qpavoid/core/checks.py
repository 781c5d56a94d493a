"""Input validation shared by the modules (internal)."""

from __future__ import annotations

import ipaddress
import math
import socket

import numpy as np

from qpavoid.core.errors import InputError


def arg_name(label: str) -> str:
    """The argument's name in a message label: ``"q (joint angles, rad)"`` -> ``"q"``."""
    return label.split(" (", 1)[0]


def one_line(exc: BaseException) -> str:
    """A third-party exception's text on one line (never empty)."""
    return " ".join(str(exc).split()) or type(exc).__name__


def as_array(
    value: object, shape: tuple[int | None, ...], name: str, *, finite: bool = True
) -> np.ndarray:
    """Return ``value`` as a float array of ``shape`` (``None`` = any size) or raise InputError.

    Parameters
    ----------
    value
        Anything numpy can turn into a float array.
    shape
        Expected shape; ``None`` entries accept any length.
    name
        Label of the argument in the error message, e.g. ``"q (joint angles, rad)"``; the
        error's ``name`` attribute is its first word(s) before `` (`` (here ``"q"``).
    finite
        If True, NaN or infinite entries are rejected too.

    Raises
    ------
    InputError
        With ``name`` set as above and ``value`` the value given (the converted array for
        a wrong shape or a non-finite entry).
    """
    if (  # the control loop's case, checked in one pass: a float array of the right shape
        type(value) is np.ndarray
        and value.dtype == np.float64
        and value.shape == shape
        and (not finite or math.isfinite(value.sum()))  # finite sum: every entry finite
    ):
        return value
    kind = np.asarray(value).dtype.kind if not isinstance(value, np.ndarray) else value.dtype.kind
    if kind not in "iuf":  # no bools, complex numbers, strings or objects taken as numbers
        raise InputError(
            f"{name} must be numeric (real numbers), got {np.asarray(value).dtype} values",
            name=arg_name(name),
            value=value,
        )
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"{name} must be numeric, got {type(value).__name__}", name=arg_name(name), value=value
        ) from exc
    if arr.shape != shape and (
        arr.ndim != len(shape)
        or any(s is not None and s != n for s, n in zip(shape, arr.shape, strict=True))
    ):
        want = str(tuple("N" if s is None else s for s in shape)).replace("'", "")
        raise InputError(
            f"{name} must have shape {want}, got {arr.shape}", name=arg_name(name), value=arr
        )
    if finite and not np.isfinite(arr).all():
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise InputError(
            f"{name} has a non-finite entry at index {tuple(int(i) for i in bad)}: "
            f"{arr[tuple(bad)]}",
            name=arg_name(name),
            value=arr,
        )
    return arr


def finite_number(value: object, name: str, *, positive: bool = False) -> float:
    """``value`` as a finite float (``> 0`` if ``positive``), else :class:`InputError`."""
    try:
        number = float(value)  # type: ignore[arg-type]  # anything float() accepts
    except (TypeError, ValueError):
        number = float("nan")
    if not math.isfinite(number) or (positive and number <= 0):
        kind = "positive and finite" if positive else "a finite number"
        raise InputError(f"{name} must be {kind}, got {value!r}", name=arg_name(name), value=value)
    return number


def check_range(name: str, value: float, low: float, high: float, unit: str) -> float:
    """``value`` as a float if it is finite and in ``[low, high]``, else :class:`InputError`."""
    if not (math.isfinite(value) and low <= value <= high):
        raise InputError(
            f"{name} must be between {low:g} and {high:g} {unit}, got {value:g}",
            name=name.split()[-1].strip("()"),
            value=value,
        )
    return float(value)


def check_choice(name: str, value: str, choices: tuple[str, ...]) -> str:
    """``value`` if it is one of ``choices``, else :class:`InputError`."""
    if value not in choices:
        raise InputError(
            f"unknown {name} {value!r}; choose from {', '.join(choices)}", name=name, value=value
        )
    return value


def is_loopback(host: str) -> bool:
    """True if ``host`` (a name or an address) resolves to this machine's loopback only."""
    try:
        infos = socket.getaddrinfo(host, None)
        return bool(infos) and all(
            ipaddress.ip_address(str(info[4][0]).split("%")[0]).is_loopback for info in infos
        )
    except (OSError, ValueError, UnicodeError):
        return False
