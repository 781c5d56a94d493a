"""The URDF of a robot description: where it is, its meshes, its Pinocchio model, and the
joints the controllers can drive.

A description names its URDF as a file beside it, or as a file of an installed Python
package (:func:`urdf_path`; ``qpavoid robot fit`` writes that entry, :func:`package_entry`).
The model is built from the text read bounded (:data:`MAX_URDF_BYTES`), and a joint the
controllers cannot drive (one without ``<limit>``, a continuous, floating or planar joint)
is refused by name: of a missing ``<limit>``, the URDF parser only says so on the console.
"""

from __future__ import annotations

from importlib import metadata
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pinocchio as pin

from qpavoid.arm.description_schema import UrdfPackage
from qpavoid.core.checks import one_line
from qpavoid.core.errors import RobotDescriptionError
from qpavoid.core.file_bounds import read_bounded

__all__ = [
    "MAX_URDF_BYTES",
    "build_urdf_model",
    "check_urdf_joints",
    "mesh_dirs",
    "package_entry",
    "urdf_path",
]

#: Most bytes a URDF may have (the iiwa's has about 5 kB; a detailed arm's, without meshes,
#: well under 1 MB): checked before it is read.
MAX_URDF_BYTES = 16 * 2**20
#: The extra of qpavoid that installs each package a bundled description takes its URDF
#: from (the error for a missing one names it).
EXTRAS = {"example-robot-data": "robots", "franky-sim": "robots"}
#: How many folders above a URDF are searched for the ``package://`` of its meshes (the
#: example-robot-data URDFs sit four below the folder their ``package://`` names).
MESH_SEARCH_DEPTH = 6


def urdf_path(value: str | UrdfPackage, folder: Path, path: Path) -> Path:
    """The URDF a description names: a file beside it (``urdf = "iiwa14.urdf"``), or a
    file of an installed Python package (``urdf = { package = "example-robot-data", path =
    "cmeel.prefix/share/.../panda.urdf" }``, its shape checked by the file's schema), found
    with :mod:`importlib.metadata`.

    Raises
    ------
    RobotDescriptionError
        If the package is not installed (naming the extra of qpavoid that installs it), or
        has no such file.
    """
    if isinstance(value, str):
        return folder / value
    package, inner = value.package, value.path
    try:
        dist = metadata.distribution(package)
    except metadata.PackageNotFoundError:
        extra = EXTRAS.get(package)
        how = f'pip install "qpavoid[{extra}]"' if extra else f"pip install {package}"
        raise RobotDescriptionError(
            f"robot {folder.name!r} takes its URDF from the package {package!r}, which is not "
            f"installed: {how}",
            path=path,
            name="urdf.package",
            value=package,
        ) from None
    found = Path(str(dist.locate_file(inner)))
    if not found.is_file():
        raise RobotDescriptionError(
            f"{path}: urdf.path {inner!r} is not a file of the installed package {package!r} "
            f"(looked for {found}); give the path of its URDF inside the package",
            path=path,
            name="urdf.path",
            value=inner,
        )
    return found


def package_entry(urdf: Path) -> dict[str, str] | None:
    """The ``urdf = { package, path }`` entry naming ``urdf`` as a file of an installed
    Python distribution (what ``qpavoid robot fit`` writes for a package's URDF), or None
    if no installed distribution lists it."""
    target = urdf.resolve()
    for dist in metadata.distributions():
        if dist.metadata["Name"] == "qpavoid":  # its own robots are folders, not packages
            continue
        for file in dist.files or ():
            if file.name == target.name and Path(str(dist.locate_file(file))).resolve() == target:
                return {"package": str(dist.metadata["Name"]), "path": str(file)}
    return None


def mesh_dirs(urdf: Path) -> tuple[Path, ...]:
    """Folders where Pinocchio looks for the meshes a URDF names: its own and the
    :data:`MESH_SEARCH_DEPTH` above it (a ``package://name/...`` resolves in the folder
    that holds ``name``)."""
    return tuple(urdf.resolve().parents[:MESH_SEARCH_DEPTH])


def build_urdf_model(urdf: Path) -> pin.Model:
    """The Pinocchio model of a URDF (read bounded to :data:`MAX_URDF_BYTES`), or
    :class:`RobotDescriptionError`."""
    try:
        text = read_bounded(urdf, MAX_URDF_BYTES).decode("utf-8")
    except (ValueError, OSError) as exc:  # missing, too large, not UTF-8
        raise RobotDescriptionError(
            f"{urdf}: cannot build a model from this URDF: {one_line(exc)}", path=urdf
        ) from exc
    _check_limit_elements(text, urdf)
    try:
        return pin.buildModelFromXML(text)
    except (ValueError, RuntimeError) as exc:  # malformed
        raise RobotDescriptionError(
            f"{urdf}: cannot build a model from this URDF: {one_line(exc)}", path=urdf
        ) from exc


def _check_limit_elements(text: str, urdf: Path) -> None:
    """Refuse a revolute or prismatic joint without ``<limit>`` (or its ``velocity``), naming
    it (the URDF parser only says so on the console): every joint the controllers drive
    needs its position and velocity limits. A text that is not XML is left to the parser."""
    try:
        root = ElementTree.fromstring(text)
    except ElementTree.ParseError:
        return
    for joint in root.iter("joint"):
        if joint.get("type") not in ("revolute", "prismatic"):
            continue
        limit = joint.find("limit")
        if limit is None or limit.get("velocity") is None:
            missing = "<limit>" if limit is None else "the velocity of its <limit>"
            name = joint.get("name", "?")
            raise RobotDescriptionError(
                f"{urdf}: joint {name!r} ({joint.get('type')}) has no {missing}: give it "
                '<limit lower="..." upper="..." velocity="..."/> (rad or m, and per s), '
                'the limits of its maker, or make it type="fixed"',
                path=urdf,
                name=name,
                value="limit",
            )


def check_urdf_joints(model: pin.Model, urdf: Path) -> None:
    """Refuse a model with a joint the controllers cannot drive: one that is not a single
    revolute or prismatic degree of freedom (a continuous joint, whose angle Pinocchio
    keeps as cos and sin, a floating or planar joint), or without finite position limits
    (lower below upper) and a velocity limit above 0."""
    for j in range(1, model.njoints):
        joint, name = model.joints[j], str(model.names[j])
        fault = ""
        if joint.nq != 1 or joint.nv != 1:
            fault = f"it is a {joint.shortname()} (nq = {joint.nq}, nv = {joint.nv})"
        else:
            low, high = model.lowerPositionLimit[joint.idx_q], model.upperPositionLimit[joint.idx_q]
            speed = model.velocityLimit[joint.idx_v]
            if not (np.isfinite(low) and np.isfinite(high) and low < high):
                fault = f"its position limits are [{low:g}, {high:g}]"
            elif not (np.isfinite(speed) and speed > 0.0):
                fault = f"its velocity limit is {speed:g}"
        if fault:
            raise RobotDescriptionError(
                f"{urdf}: joint {name!r}: {fault}; only revolute and prismatic joints with "
                'limits are supported: give it type="revolute" or "prismatic" and '
                '<limit lower="..." upper="..." velocity="..."/> with lower < upper and '
                "velocity > 0 (a continuous joint: revolute with the range it needs), or "
                'make it type="fixed"',
                path=urdf,
                name=name,
                value=joint.shortname(),
            )
