"""A user's file checked against its schema: msgspec, one line per refusal naming the field.

The shape of every file a user writes (a robot description, a camera format, a body, a
calibration, a key file, ...) is a :class:`msgspec.Struct` beside its reader: the types,
the ranges (``Meta(ge=..., le=...)``, each bound's unit and reason beside it), the keys
known (``forbid_unknown_fields=True``) and those required. :func:`convert` checks the
parsed TOML against it (``msgspec.convert(..., strict=True)``: no ``"1"`` for ``1``, no
``true`` for ``1``) and turns msgspec's refusal into the reader's own error, one line that
names the field's path as the file says it (``sets[1].capsule.capsule_radius_m``,
``arm.max_acceleration_radps2.A4``: a table's key by its name, where msgspec says
``[...]``) and the offending value.

The wording is the project's: a number ``must be a number at least 0 and at most 0.1, got
8`` (its bounds from the schema; its unit after them, ``..., m, got 8``, where its type's
``Meta(extra={"unit": "m"})`` says one); a field whose type carries a ``description``
(``Meta(description=...)``) ``must be <description>, got ...`` (or ``<description>, got
...`` where the description says its own verb: ``must map each ...``, ``needs ...``); an
unknown key lists every unknown key and the keys the table has; a missing key is named,
in the field's own words where its type's ``Meta(extra={"missing": ...})`` gives them
(``roles needs end_effector = { set = ... }``, ``no [arm] table; add one, e.g. ...``); a
number beyond its upper bound says what that most likely is where its type's
``Meta(extra={"beyond": ...})`` does (``..., N/mm, got 75000.0 (a unit error?)``).
Any other refusal keeps msgspec's own words (``Expected `str`, got `int```). An entry of a
list that has a ``name`` is named before the message (``part 'trunk': parts[1]...``), and
a table whose struct has a ``docs`` class variable (``docs: ClassVar[str] =
"docs/robot.md: Arm"``) points there, the innermost such table on the path
(``arm is missing key(s) max_point_speed_mps (docs/robot.md: Arm)``).

msgspec was chosen over pydantic 2 for the command line's start-up and for its messages:
its import is about 30 ms against pydantic's 45-71 ms, it is strict by default where asked,
and its errors are one line naming the path (``Expected `float` <= 1.0 - at
`$.sets[1].sphere_radius_m```), where pydantic's span several lines and a URL.
"""

from __future__ import annotations

import math
import re
import types
import typing
from collections.abc import Callable, Mapping
from typing import Any, TypeVar, overload

import msgspec

__all__ = ["Fail", "SchemaError", "convert"]

T = TypeVar("T")

#: Makes the reader's own error from the field's path (``""`` for the whole file), the
#: one-line message (without the file's name) and the offending value.
Fail = Callable[[str, str, object], Exception]

#: One step of msgspec's path: ``.name``, ``[3]`` or ``[...]`` (a table's key, unnamed).
_STEP = re.compile(r"\.([^.\[]+)|\[(\d+|\.\.\.)\]")


class SchemaError(Exception):
    """A refusal as :func:`refusal` words it: the field's path, the message, the value."""

    def __init__(self, name: str, message: str, value: object) -> None:
        super().__init__(message)
        self.name, self.message, self.value = name, message, value


@overload
def convert(data: object, schema: type[T], fail: Fail, *, prefix: str = "") -> T: ...


@overload
def convert(data: object, schema: object, fail: Fail, *, prefix: str = "") -> Any: ...


def convert(data: object, schema: object, fail: Fail, *, prefix: str = "") -> Any:
    """``data`` (a parsed file, or one of its tables) as a ``schema``, or ``fail``'s error.

    Parameters
    ----------
    data
        What :func:`~qpavoid.core.file_bounds.read_toml` returned, or a table of it.
    schema
        The file's (or the table's) :class:`msgspec.Struct`, or any type msgspec
        converts to (a union, an annotated type).
    fail
        Makes the reader's error from the field's path, the message and the value.
    prefix
        The table's path in its file (``"arm"``), put before every field's path.

    Raises
    ------
    Exception
        ``fail``'s, for the first field msgspec refuses (one line).
    """
    try:
        return msgspec.convert(data, schema, strict=True)
    except msgspec.ValidationError as exc:
        found = refusal(data, schema, str(exc), prefix)
        raise fail(found.name, found.message, found.value) from None


def refusal(data: object, schema: object, text: str, prefix: str = "") -> SchemaError:
    """msgspec's refusal ``text`` of ``data`` against ``schema`` in the project's words."""
    said, _, where = text.partition(" - at `$")
    steps = _STEP.findall(where.rstrip("`"))
    node, value, path = _plain(schema, data), data, prefix
    described: tuple[str, str, object] | None = None  # the nearest table that says its shape
    docs = _docs(node)  # the nearest table's page in the docs
    named: list[str] = []  # the named entries on the way: "part 'trunk'"
    for k, (name, index) in enumerate(steps):
        if description := _description(node):
            described = (path, description, value)
        node, value, key = _step(node, value, name, index)
        node = _plain(node, value)
        entry = value.get("name") if index.isdigit() and isinstance(value, Mapping) else None
        if isinstance(entry, str) and steps[k + 1 :] != [("name", "")]:
            named.append(f"{_singular(path)} {entry!r}")
        path = f"{path}.{key}" if path and not key.startswith("[") else f"{path}{key}"
        docs = _docs(node) or docs
    found = _worded(node, value, path, said, described)
    if said.startswith("Object missing required field") and isinstance(found.value, list):
        # a missing key: its own table's page
        docs = _docs(_fields(node).get(found.value[0])) or docs
    lead = f"{', '.join(named)}: " if named else ""
    tail = f" ({docs})" if docs and docs not in found.message else ""
    return SchemaError(found.name, f"{lead}{found.message}{tail}", found.value)


def _worded(
    node: object,
    value: object,
    path: str,
    said: str,
    described: tuple[str, str, object] | None,
) -> SchemaError:
    """The refusal of ``value`` (of type ``node``, at ``path``) that msgspec ``said``."""
    missing = re.fullmatch(r"Object missing required field `(.+)`", said)
    unknown = re.fullmatch(r"Object contains unknown field `(.+)`", said)
    if missing:  # every required key the table lacks, in the schema's order
        fields = _fields(node)
        given = value if isinstance(value, Mapping) else {}
        keys = [k for k in fields if k not in given and k in _required(node)]
        keys = keys or [missing.group(1)]
        name = f"{path}.{keys[0]}" if path else keys[0]
        if said_so := _extra(fields.get(keys[0]), "missing"):  # the table's own words
            return SchemaError(name, f"{path} {said_so}" if path else said_so, keys)
        hint = _description(fields.get(keys[0]))
        return SchemaError(
            name,
            f"{f'{path} is missing' if path else 'missing'} key(s) {', '.join(keys)}"
            + (f": {keys[0]} {_must(hint)}" if hint else ""),
            keys,
        )
    if unknown and isinstance(value, Mapping):
        known = list(_fields(node))
        extra = sorted(k for k in value if k not in known)
        return SchemaError(
            f"{path}.{extra[0]}" if path else extra[0],
            f"{path or 'the top level'} has unknown key(s) {extra}; its keys are {known}",
            extra,
        )
    if description := _description(node):
        return SchemaError(path, f"{path} {_must(description)}, got {value!r}", value)
    bound = _bounds(node)
    if bound is not None and (bound or described is None):  # else the table's shape
        unit = _extra(node, "unit")
        bound += f", {unit}" if unit else ""
        number = "a whole number" if _unannotated(node) is int else "a number"
        beyond = _extra(node, "beyond") if _above(node, value) else None
        why = f" ({beyond})" if beyond else ""
        return SchemaError(path, f"{path} must be {number}{bound}, got {value!r}{why}", value)
    said = re.sub(r", got `[^`]*`$", "", said)  # the value itself is said instead
    said = re.sub(r"(of length .*), got (\d+)$", r"\1 (it has \2)", said)
    if described is not None:
        name, description, shown = described
        return SchemaError(
            name, f"{name} {_must(description)}; {path}: {said}, got {value!r}", shown
        )
    return SchemaError(path, f"{path}: {said}, got {value!r}", value)


def _must(description: str) -> str:
    """What a field must be, as its description says it: ``must be <description>``, or the
    description itself where it says its verb (``must map each ...``, ``needs ...``)."""
    return description if description.startswith(("must ", "needs ")) else f"must be {description}"


def _singular(path: str) -> str:
    """What one entry of the list at ``path`` is called: ``parts`` -> ``part``."""
    last = re.split(r"[.\]]", path)[-1] or "entry"
    return last[:-1] if last.endswith("s") else last


def _docs(node: object) -> str | None:
    """The docs page a table's struct points to (its ``docs`` class variable), if any."""
    node = _unannotated(node)
    found = getattr(node, "docs", None) if isinstance(node, type) else None
    return found if isinstance(found, str) else None


def _step(node: object, value: object, name: str, index: str) -> tuple[object, object, str]:
    """The type and the value one step of the path down, and the step as the file says it."""
    node = _unannotated(node)
    if name:
        field = _fields(node).get(name)
        child = value.get(name) if isinstance(value, Mapping) else None
        return field, child, name
    origin, args = typing.get_origin(node), typing.get_args(node)
    if index == "...":  # a table's value: find the key msgspec does not name
        item = args[1] if len(args) == 2 else Any
        entries = value.items() if isinstance(value, Mapping) else ()
        for key, child in entries:
            try:
                msgspec.convert(child, item, strict=True)
            except msgspec.ValidationError:
                return item, child, str(key)
        return item, None, "[...]"
    k = int(index)
    child = value[k] if isinstance(value, list) and k < len(value) else None
    if origin is tuple and args and args[-1] is not Ellipsis:
        return (args[k] if k < len(args) else Any), child, f"[{k}]"
    return (args[0] if args else Any), child, f"[{k}]"


def _plain(node: object, value: object) -> object:
    """Of an optional field, its type; of a union, the member ``value`` is of (a table's
    or a list's), with its metadata; any other type as it is."""
    if typing.get_origin(_unannotated(node)) in (typing.Union, types.UnionType):
        members = [m for m in typing.get_args(_unannotated(node)) if m is not type(None)]
        if len(members) == 1:  # an optional field: its type
            return members[0]
        for member in members:
            plain = _unannotated(member)
            table = isinstance(plain, type) and issubclass(plain, msgspec.Struct)
            table = table or typing.get_origin(plain) is dict
            listed = typing.get_origin(plain) in (list, tuple)
            if (isinstance(value, Mapping) and table) or (isinstance(value, list) and listed):
                return member
    return node


def _unannotated(node: object) -> object:
    while typing.get_origin(node) is typing.Annotated:
        node = typing.get_args(node)[0]
    return node


def _metas(node: object) -> list[msgspec.Meta]:
    """The :class:`msgspec.Meta` of ``node``'s ``Annotated`` layers, outermost first."""
    metas: list[msgspec.Meta] = []
    while typing.get_origin(node) is typing.Annotated:
        node, *extras = typing.get_args(node)
        metas += [m for m in extras if isinstance(m, msgspec.Meta)]
    return metas


def _description(node: object) -> str | None:
    return next((m.description for m in _metas(node) if m.description), None)


def _extra(node: object, key: str) -> str | None:
    """``key`` of the ``extra`` of ``node``'s metadata: a number's ``unit`` (``"m"``), a
    field's words when it is ``missing`` (``"needs end_effector = { set = ... }"``)."""
    return next((str(m.extra[key]) for m in _metas(node) if m.extra and key in m.extra), None)


def _fields(node: object) -> dict[str, object]:
    """A struct's fields by the name the file gives them, with their types."""
    node = _unannotated(node)
    if not (isinstance(node, type) and issubclass(node, msgspec.Struct)):
        return {}
    hints = typing.get_type_hints(node, include_extras=True)
    return {f.encode_name: hints[f.name] for f in msgspec.structs.fields(node)}


def _required(node: object) -> set[str]:
    """The keys a struct's table must give."""
    node = _unannotated(node)
    if not (isinstance(node, type) and issubclass(node, msgspec.Struct)):
        return set()
    return {f.encode_name for f in msgspec.structs.fields(node) if f.required}


def _bounds(node: object) -> str | None:
    """A number's bounds as the messages say them (``" above 0 and at most 1"``, ``""``
    without bounds), or None for a type that is not a number."""
    if _unannotated(node) not in (float, int):
        return None
    metas = _metas(node)
    gt, ge, le, lt = (_first(metas, attr) for attr in ("gt", "ge", "le", "lt"))

    def shown(x: float) -> str:  # short, unless that loses digits (4294967295, not 4.29497e+09)
        return f"{x:g}" if float(f"{x:g}") == x or not float(x).is_integer() else str(int(x))

    parts = []
    if gt is not None:
        parts.append(f"above {shown(gt)}")
    elif ge is not None:
        parts.append(f"at least {shown(ge)}")
    if le is not None and math.isfinite(le):
        parts.append(f"at most {shown(le)}")
    elif lt is not None:
        parts.append(f"below {shown(lt)}")
    return "".join(f" {p}" if not k else f" and {p}" for k, p in enumerate(parts))


def _first(metas: list[msgspec.Meta], attr: str) -> float | None:
    """The outermost of ``metas``' bounds ``attr`` (``"gt"``, ``"le"``, ...), if any."""
    return next((getattr(m, attr) for m in metas if getattr(m, attr) is not None), None)


def _above(node: object, value: object) -> bool:
    """Whether ``value`` is a number beyond the upper bound of the number type ``node``."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    metas = _metas(node)
    le, lt = _first(metas, "le"), _first(metas, "lt")
    return (le is not None and value > le) or (lt is not None and value >= lt)
