"""A key file's shape: a sensor's ``<sensor>.key`` as a schema (msgspec).

The types, ranges, keys known and keys required of a key file (:mod:`qpavoid.sensing.keys`,
``docs/security.md``): the sensor's name and one or two ``[[key]]`` tables, each an id and
a secret of 64 hex digits. That the file is its owner's only, that it is the key of the
sensor asked for and that no two keys share an id stay code beside the reader. A secret is
never shown in a refusal (the reader hides it).
"""

from __future__ import annotations

from typing import Annotated, ClassVar

from msgspec import Meta, Struct

__all__ = ["KEY_BYTES", "MAX_KEYS", "MAX_KEY_ID", "KeyFile", "KeyTable"]

#: A key is 256 bits, the size of HMAC-SHA256's hash (RFC 2104: longer adds nothing).
KEY_BYTES = 32
#: At most two keys are accepted at once: the new one and, during a rotation, the old one.
MAX_KEYS = 2
#: Key ids are sent as 32-bit unsigned integers.
MAX_KEY_ID = 2**32 - 1
#: The shape of the key tables, said when they are missing or too many.
KEYS_SHAPE = f"1 or {MAX_KEYS} [[key]] tables (id, secret)"


class KeyTable(Struct, frozen=True, forbid_unknown_fields=True):
    """One ``[[key]]``: its id (sent in each datagram's header) and its secret."""

    #: A 32-bit unsigned integer: from 0 to 2³² - 1.
    id: Annotated[int, Meta(ge=0, le=MAX_KEY_ID)]
    secret: Annotated[
        str,
        Meta(
            pattern=f"^[0-9a-fA-F]{{{2 * KEY_BYTES}}}$",
            description=f"{2 * KEY_BYTES} hex digits ({8 * KEY_BYTES} bits)",
        ),
    ]


class KeyFile(Struct, frozen=True, forbid_unknown_fields=True):
    """A sensor's key file."""

    docs: ClassVar[str] = "docs/security.md"

    sensor: Annotated[
        str,
        Meta(
            description="a sensor's name (text)",
            extra={"missing": "it names no sensor (sensor = NAME, then [[key]] tables)"},
        ),
    ]
    key: Annotated[
        list[KeyTable],
        Meta(
            min_length=1,
            max_length=MAX_KEYS,
            description=KEYS_SHAPE,
            extra={"missing": f"it must hold {KEYS_SHAPE}"},
        ),
    ]
