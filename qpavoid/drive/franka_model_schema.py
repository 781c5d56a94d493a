"""A Franka model file's shape: a description's ``franka.toml`` as a schema (msgspec).

The types, ranges, keys known and keys required of the file that says which Franka arm a
description is (:class:`qpavoid.drive.franka_model.FrankaModel`; ``robots/fr3/franka.toml``
shows each key with its meaning): the arm's model, the versions of libfranka's protocol its
controllers speak and, optionally, their sources. Whether the arm that answers speaks one
of those versions is checked at connect (:meth:`~qpavoid.drive.franka_model.FrankaModel.check`).
"""

from __future__ import annotations

from typing import Annotated, ClassVar

from msgspec import Meta, Struct

__all__ = ["MAX_SERVER_VERSION", "ModelFile", "ModelSources"]

#: libfranka's robot server version is an unsigned 16-bit number (its ``uint16_t``
#: ``kVersion``): 1 to 65535 (Franka's own are 1-10 so far).
MAX_SERVER_VERSION = 65535

Text = Annotated[str, Meta(pattern=r"\S", description="a non-empty text")]


class ModelSources(Struct, frozen=True, forbid_unknown_fields=True):
    """``[sources]``: where the model's name and its versions come from."""

    model: Text | None = None
    server_versions: Text | None = None


class ModelFile(Struct, frozen=True, forbid_unknown_fields=True):
    """A description's ``franka.toml``."""

    docs: ClassVar[str] = "docs/real-robot.md §1b"

    #: The arm's model as Franka names it, for messages.
    model: Annotated[str, Meta(pattern=r"\S", description='must name the arm (model = "FR3")')]
    server_versions: Annotated[
        list[Annotated[int, Meta(ge=1, le=MAX_SERVER_VERSION)]],
        Meta(
            min_length=1,
            description="must list the versions of libfranka's protocol the arm speaks, whole "
            f"numbers from 1 to {MAX_SERVER_VERSION} (server_versions = [10])",
        ),
    ]
    sources: ModelSources = ModelSources()
