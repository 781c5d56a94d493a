"""Reaching a Franka arm through a binding of libfranka, and what its failures mean.

The connection is made within a bounded time (:func:`connect_within`); a connection the
arm refuses, or a binding's exception later, becomes an :class:`~qpavoid.core.errors.ArmError`
whose reason says what happened (:func:`connect_error`, :func:`binding_error`).
"""

from __future__ import annotations

import ipaddress
import re
import threading
from collections.abc import Callable
from typing import Any, TypeVar

from qpavoid.core.checks import one_line
from qpavoid.core.errors import ArmError
from qpavoid.drive.franka_model import BINDINGS, Binding, FrankaModel

__all__ = [
    "binding_error",
    "connect_error",
    "connect_within",
    "is_loopback",
    "refused_versions",
]

#: libfranka's refusal of a connection, in every release from 0.9 to 0.21 (its
#: ``IncompatibleVersionException``; panda-python 1.0 passes it on as a RuntimeError).
_REFUSAL = re.compile(r"server version: (\d+), library version: (\d+)")

T = TypeVar("T")


def refused_versions(exc: BaseException) -> tuple[int, int] | None:
    """The robot server's and the library's versions of libfranka's refusal ``exc`` of a
    connection to an arm of another version, or None if it is not one.

    libfranka's ``IncompatibleVersionException`` (franky-control's, panda-python 1.0's as
    a RuntimeError) says both in its text; panda-python 1.1's ``IncompatibleVersionError``
    carries them as attributes.
    """
    server = getattr(exc, "server_version", None)
    library = getattr(exc, "library_version", None)
    if isinstance(server, int) and isinstance(library, int):
        return server, library
    found = _REFUSAL.search(str(exc))
    return (int(found[1]), int(found[2])) if found else None


def is_loopback(host: str) -> bool:
    """Whether ``host`` is a loopback address (a simulator's, on this machine)."""
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return host == "localhost"


def connect_within(make: Callable[[], T], timeout_s: float, arm: str, host: str) -> T:
    """``make()`` (a binding's connection) within ``timeout_s`` s; what it raised, raised
    again; or :class:`ArmError` "unreachable" when it has not returned by then.

    libfranka refuses at once when nothing listens on the address but waits 60 s for an
    address that does not answer (its TCP timeout); the connection is made in a thread of
    its own, abandoned (its robot released when it comes) after ``timeout_s``.
    """
    box: dict[str, Any] = {}
    lock, done = threading.Lock(), threading.Event()

    def connect() -> None:
        try:
            robot = make()
        except Exception as e:  # libfranka's: NetworkException, IncompatibleVersion, ...
            box["error"] = e
        else:
            with lock:
                if "abandoned" not in box:
                    box["robot"] = robot
            del robot  # if abandoned, released here: libfranka disconnects
        finally:
            done.set()

    threading.Thread(target=connect, name=f"connect {arm}", daemon=True).start()
    done.wait(timeout_s)
    with lock:
        box["abandoned"] = True
        if "robot" in box:
            return box["robot"]
    if "error" in box:
        raise box["error"]
    raise ArmError(
        f"{arm}: no answer from {host} within {timeout_s:g} s "
        "(is the arm on, FCI enabled, the address right?)",
        arm=arm,
        reason="unreachable",
        value=host,
    )


def connect_error(
    e: Exception, arm: str, host: str, model: FrankaModel, binding: Binding
) -> ArmError:
    """The :class:`ArmError` of the binding ``binding``'s failure ``e`` to connect the arm
    ``arm`` at ``host``, described by ``model``: "model" for an arm of another model than
    the description's, "unreachable" otherwise."""
    versions = refused_versions(e)
    if versions is not None:
        return _refused(arm, host, model, binding, *versions)
    text = one_line(e)
    if "incorrect object size" in text:  # libfranka's ProtocolException, at connect
        text += (
            f": the arm accepted version {binding.server_version} of libfranka's "
            "protocol but does not speak it (a real controller refuses a version it "
            "does not speak; franky-sim accepts every one)"
        )
    return ArmError(
        f"{arm}: cannot connect ({type(e).__name__}: {text})",
        arm=arm,
        reason="unreachable",
        value=host,
    )


def _refused(
    arm: str, host: str, model: FrankaModel, binding: Binding, server: int, library: int
) -> ArmError:
    """The error of a connection the arm refused: its controller speaks version
    ``server`` of libfranka's protocol, the binding's libfranka ``library``."""
    another = model.mismatch(arm, server)
    if another is not None:  # another arm answered: "model", naming both
        return another
    others = [b for b in BINDINGS if b.server_version == server]
    what = (
        f"drive it with --arm {others[0].kind}:{host} ({others[0].package}'s "
        f"libfranka {others[0].libfranka} speaks {server}: {others[0].install()})"
        if others
        else "no adapter here speaks it ("
        + ", ".join(f"{b.package} {b.server_version}" for b in BINDINGS)
        + "): update the arm's robot system, or install a build of a binding for it "
        "(docs/real-robot.md §1b)"
    )
    return ArmError(
        f"{arm}: the {model.name} there speaks version {server} of libfranka's "
        f"protocol, {binding.package}'s libfranka {binding.libfranka} speaks "
        f"{library}: {what}",
        arm=arm,
        reason="unreachable",
        value=host,
    )


def binding_error(e: BaseException, arm: str) -> ArmError:
    """The :class:`ArmError` of a binding's exception ``e`` on the arm ``arm``: "stalled"
    for a network timeout, "unreachable" for another network error, "fault" otherwise."""
    text = one_line(e)
    kind = type(e).__name__
    network = kind == "NetworkException" or text == "Net Exception"
    if network or text.startswith(("libfranka: UDP", "libfranka: TCP")):
        reason = "stalled" if "timeout" in text.lower() else "unreachable"
    else:
        reason = "fault"
    return ArmError(f"{arm}: {kind}: {text}", arm=arm, reason=reason, value=text)
