"""Sensor keys: one 256-bit secret per sensor, in a key file of its own (docs/security.md).

A key file is TOML, readable by its owner only (mode 0600: a file that its group or others
may read, write or run is refused), at most :data:`MAX_KEY_FILE_BYTES`::

    sensor = "kinect_left"

    [[key]]                 # the first key signs ...
    id = 2
    secret = "64 hex digits: 256 bits from secrets.token_bytes"

    [[key]]                 # ... and a second, the previous one, is accepted during a rotation
    id = 1
    secret = "..."

The file's shape is :class:`~qpavoid.sensing.key_schema.KeyFile`'s, refused in one line
naming the field's path (``key[0].secret``) and never showing a secret; that the file is
its owner's only, the sensor's and holds no id twice is checked here.

A calibration file names each sensor's key file (``key_file``, relative to the calibration
file) and may restrict the ids it accepts (``key_ids = [2, 1]``: the first signs). The
secrets are never printed: a :class:`SensorKeys` shows its ids only.

:func:`new_key_file` writes one (``qpavoid keygen``), or rotates one: the new key first,
the current key kept second, anything older dropped.
"""

from __future__ import annotations

import os
import secrets
from dataclasses import dataclass, field
from pathlib import Path

from qpavoid.core.checks import one_line
from qpavoid.core.errors import CalibrationError
from qpavoid.core.file_bounds import read_toml
from qpavoid.core.schema import convert
from qpavoid.sensing.key_schema import KEY_BYTES, MAX_KEY_ID, MAX_KEYS, KeyFile

__all__ = [
    "KEY_BYTES",
    "MAX_KEY_FILE_BYTES",
    "SensorKeys",
    "load_key_file",
    "new_key_file",
    "sensor_name_error",
    "toml_string",
]

#: A key file holds two keys of 64 hex digits and a name: 4 KiB leaves room for comments
#: and refuses a file that is something else (a device, a log) before it is read whole.
MAX_KEY_FILE_BYTES = 4096
#: A sensor's name is sent in each datagram's header after a one-byte length.
MAX_SENSOR_NAME_BYTES = 255


def sensor_name_error(name: object) -> str | None:
    """Why ``name`` cannot be a sensor's name (None if it can): a string of 1 to 255 UTF-8
    bytes (its length is one byte of the signed header) with no control character."""
    if not isinstance(name, str) or not name:
        return "a sensor's name is a non-empty string"
    if len(name.encode("utf-8", "surrogatepass")) > MAX_SENSOR_NAME_BYTES:
        return f"a sensor's name is at most {MAX_SENSOR_NAME_BYTES} bytes in UTF-8"
    if not name.isprintable():
        return "a sensor's name has no control characters"
    return None


def toml_string(text: str) -> str:
    """``text`` as a TOML basic string: quoted, with backslash, quote and every control
    character escaped (a name written must read back as itself)."""
    out = []
    for ch in text:
        if ch in '"\\':
            out.append("\\" + ch)
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04X}")
        else:
            out.append(ch)
    return '"' + "".join(out) + '"'


@dataclass(frozen=True)
class SensorKeys:
    """One sensor's keys: ``(key id, secret)`` pairs, the first one signing.

    The secrets stay out of ``repr`` (an error message or a log must never show one).
    """

    sensor: str
    keys: tuple[tuple[int, bytes], ...] = field(repr=False)

    def __post_init__(self) -> None:
        ids = [kid for kid, _ in self.keys]
        if not 1 <= len(self.keys) <= MAX_KEYS or len(set(ids)) != len(ids):
            raise CalibrationError(
                f"sensor {self.sensor!r}: 1 or {MAX_KEYS} keys of distinct ids, got ids {ids}",
                sensor=self.sensor,
                name="key",
                value=ids,
            )
        for kid, secret in self.keys:
            if not 0 <= kid <= MAX_KEY_ID or len(secret) != KEY_BYTES:
                raise CalibrationError(
                    f"sensor {self.sensor!r}: key {kid} must have an id from 0 to {MAX_KEY_ID} "
                    f"and {KEY_BYTES} bytes",
                    sensor=self.sensor,
                    name="key",
                    value=kid,
                )

    @property
    def ids(self) -> tuple[int, ...]:
        """The key ids, the signing one first."""
        return tuple(kid for kid, _ in self.keys)

    @property
    def signing(self) -> tuple[int, bytes]:
        """``(key id, secret)`` a sender signs with."""
        return self.keys[0]

    def __repr__(self) -> str:
        return f"SensorKeys(sensor={self.sensor!r}, ids={self.ids})"

    @classmethod
    def generate(cls, sensor: str, key_id: int = 1) -> SensorKeys:
        """A new random key (``secrets.token_bytes``) for ``sensor``."""
        return cls(sensor, ((key_id, secrets.token_bytes(KEY_BYTES)),))

    def only(self, ids: tuple[int, ...], where: str = "") -> SensorKeys:
        """These keys restricted to ``ids``, in that order (the first signs).

        Raises
        ------
        CalibrationError
            If an id is not among the keys ("unknown key id").
        """
        table = dict(self.keys)
        unknown = [kid for kid in ids if kid not in table]
        if unknown:
            raise CalibrationError(
                f"{where}sensor {self.sensor!r}: unknown key id {unknown[0]} (its key file "
                f"holds {', '.join(map(str, self.ids))})",
                sensor=self.sensor,
                name="key_ids",
                value=unknown[0],
            )
        return SensorKeys(self.sensor, tuple((kid, table[kid]) for kid in ids))

    def to_toml(self) -> str:
        """The text of this sensor's key file."""
        lines = [
            "# qpavoid sensor key: keep it secret, mode 0600 (docs/security.md)",
            f"sensor = {toml_string(self.sensor)}",
        ]
        for kid, secret in self.keys:
            lines += ["", "[[key]]", f"id = {kid}", f'secret = "{secret.hex()}"']
        return "\n".join(lines) + "\n"


def load_key_file(path: str | Path, sensor: str) -> SensorKeys:
    """The keys of ``sensor`` in the key file ``path`` (module docstring).

    Raises
    ------
    CalibrationError
        If the file is missing, unreadable, larger than :data:`MAX_KEY_FILE_BYTES`, not
        private to its owner, not valid TOML, for another sensor, or holds no key, more
        than two, a duplicate id or a secret that is not 64 hex digits.
    """
    p = str(path)

    def fail(message: str, name: str = "key_file") -> CalibrationError:
        return CalibrationError(
            f"key file {p} of sensor {sensor!r}: {message}", path=p, sensor=sensor, name=name
        )

    try:
        data = read_toml(p, MAX_KEY_FILE_BYTES, private=True)
    except FileNotFoundError:
        raise fail("missing (write one with: qpavoid keygen " + sensor + f" --out {p})") from None
    except (OSError, ValueError) as exc:
        raise fail(one_line(exc)) from None
    entries = data.get("key")
    secrets_given = [
        repr(entry["secret"])
        for entry in (entries if isinstance(entries, list) else [])
        if isinstance(entry, dict) and isinstance(entry.get("secret"), str)
    ]

    def refused(name: str, message: str, value: object) -> CalibrationError:
        for secret in secrets_given:  # a secret is never shown, even a wrong one
            message = message.replace(secret, "<hidden>")
        return fail(message, name or "key_file")

    named = data.get("sensor", sensor)
    if isinstance(named, str) and named != sensor:  # another sensor's file: whatever its shape
        raise fail(f"it is the key of sensor {named!r}", "sensor")
    file = convert(data, KeyFile, refused)
    keys = [(entry.id, bytes.fromhex(entry.secret)) for entry in file.key]
    if len({kid for kid, _ in keys}) != len(keys):
        raise fail("two keys have the same id", "id")
    return SensorKeys(sensor, tuple(keys))


def new_key_file(path: str | Path, sensor: str, *, rotate: bool = False) -> SensorKeys:
    """Write a new key for ``sensor`` to ``path`` (mode 0600) and return the keys written.

    Without ``rotate`` the file must not exist. With it, it must: the new key (its id one
    more than the highest there) goes first and signs, the current signing key stays
    second, accepted until the next rotation; an older one is dropped.

    Raises
    ------
    CalibrationError
        If ``path`` exists (without ``rotate``) or not (with it), or cannot be written.
    """
    p = Path(path)
    if rotate:
        p = p.resolve()  # a link to the key file: the file is rotated, the link kept
        old = load_key_file(p, sensor)
        keys = SensorKeys(sensor, ((max(old.ids) + 1, secrets.token_bytes(KEY_BYTES)), old.signing))
    else:
        keys = SensorKeys.generate(sensor)
    text = keys.to_toml().encode()
    exists = CalibrationError(
        f"{p} exists: rotate it with --rotate, or choose another path",
        path=str(p),
        sensor=sensor,
        name="--out",
    )
    if not rotate and p.exists():
        raise exists
    temporary = p.with_name(f".{p.name}.new")
    try:
        temporary.unlink(missing_ok=True)  # left by a write that was cut short
        fd = os.open(temporary, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "wb") as handle:
            handle.write(text)
        if rotate:
            owner = p.stat()
            if (owner.st_uid, owner.st_gid) != (os.getuid(), os.getgid()):
                os.chown(temporary, owner.st_uid, owner.st_gid)  # still its owner's to read
            os.replace(temporary, p)
        else:
            os.link(temporary, p)  # fails if p appeared meanwhile: never overwrite a key
    except FileExistsError:
        raise exists from None
    except OSError as exc:
        raise CalibrationError(
            f"cannot write key file {p}: {one_line(exc)}", path=str(p), sensor=sensor
        ) from None
    finally:
        temporary.unlink(missing_ok=True)
    return keys
