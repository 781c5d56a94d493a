"""Reading a robot description: the control-point file, the URDF and the reduced model.

A robot description is a folder with a URDF and a control-point file (TOML, see
``docs/robot.md``). Every control point and capsule end becomes an operational frame of
the Pinocchio model, so positions and Jacobians come from Pinocchio; locking joints (the
paper locks its third joint) is Pinocchio's ``buildReducedModel``, which carries the
frames over.

Besides the geometry the file says everything about the arm that the controllers need and
that differs from arm to arm: which set plays which part in the paper's laws and on which
joints (:class:`Roles`), how fast the arm reacts and brakes (:class:`ArmDynamics`) and
where its inverse kinematics starts (:class:`IKSeed`) and its home configuration (``home``,
:meth:`~qpavoid.arm.model.Robot.neutral`). No code holds a joint name, length or limit of a
particular arm.

:func:`read_description` returns the pieces a :class:`~qpavoid.arm.model.Robot` is made of;
:func:`qpavoid.arm.model.load_robot` makes the robot from them.
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass
from importlib import metadata, resources
from pathlib import Path
from typing import Any, NamedTuple
from xml.etree import ElementTree

import numpy as np
import pinocchio as pin

from qpavoid.arm.dynamics import ArmDynamics, read_arm
from qpavoid.arm.fields import number as _number
from qpavoid.arm.fields import table as _table
from qpavoid.arm.fields import unknown_keys as _unknown_keys
from qpavoid.core.checks import one_line
from qpavoid.core.errors import InputError, RobotDescriptionError
from qpavoid.core.file_bounds import NotTOMLError, read_bounded, read_toml

CONFIG_NAME = "control_points.toml"
#: Pinocchio's frame for every Jacobian of the arm: the point's velocity in base-frame axes.
LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
#: Keys of a ``[[sets]]`` entry of the control-point file and of its ``capsule`` table.
SET_KEYS = ("name", "sphere_radius_m", "points", "capsule")
CAPSULE_KEYS = ("from", "to", "capsule_radius_m")
#: The control-point file's top-level keys (a misspelt one would otherwise be ignored).
TOP_KEYS = (
    "urdf",
    "end_effector",
    "locked",
    "held",
    "sets",
    "roles",
    "arm",
    "ik_seed",
    "coverage",
    "home",
)
#: Most bytes a control-point file may have (the iiwa's has about 4 kB), and a URDF
#: (the iiwa's has about 5 kB; a detailed arm's, without meshes, well under 1 MB):
#: checked before they are read.
MAX_CONFIG_BYTES = 2**20
MAX_URDF_BYTES = 16 * 2**20
#: What a set's name may hold: it becomes part of frame names, log keys and file names
#: (``fig10_distance_<name>.png``).
SET_NAME = re.compile(r"[A-Za-z0-9_.-]+")
#: The shape of a set's ``points``, for messages.
POINTS_SHAPE = (
    'points = [["<frame>"], ["<frame>", "<frame>"], { frame = "<frame>", xyz = [x, y, z] }]'
)
#: Keys of a point or capsule end given as an offset from a frame (``{ frame, xyz }``), and
#: of a ``urdf`` given as a file of an installed Python package (``{ package, path }``).
OFFSET_KEYS = ("frame", "xyz")
PACKAGE_KEYS = ("package", "path")
#: The extra of qpavoid that installs each package a bundled description takes its URDF
#: from (the error for a missing one names it).
EXTRAS = {"example-robot-data": "robots", "franky-sim": "robots"}
#: How many folders above a URDF are searched for the ``package://`` of its meshes (the
#: example-robot-data URDFs sit four below the folder their ``package://`` names).
MESH_SEARCH_DEPTH = 6


@dataclass(frozen=True)
class ControlSet:
    """One set of control points (L1, L2 or EE in the paper) and its capsule.

    Attributes
    ----------
    name
        Set name, e.g. ``"L2"``.
    sphere_radius_m
        Radius r_R of the spheres centred on the set's points (paper eq. 1), m.
    points
        Indices of the set's points in :attr:`~qpavoid.arm.model.Robot.point_frames` order.
    capsule_frames
        Frame ids of the capsule's two ends (from, to).
    capsule_radius_m
        Capsule radius for the exact distance method, m.
    """

    name: str
    sphere_radius_m: float
    points: tuple[int, ...]
    capsule_frames: tuple[int, int]
    capsule_radius_m: float


#: The parts a control set plays in the paper's laws (``[roles]`` of the control-point
#: file, :class:`Roles`), in the order of :attr:`Roles.rows`.
ROLE_NAMES = ("scaled", "repelled", "end_effector")
#: Keys of the ``[roles]`` table: a set per part, and the elbow point.
ROLE_KEYS = (*ROLE_NAMES, "elbow")


@dataclass(frozen=True)
class Roles:
    """Which control set plays which part in the paper's laws, and on which joints.

    The paper names its sets after the iiwa's links (L1, L2, EE); the controllers address
    them by the part they play, so that any arm's sets, named as its description likes,
    can play them. The parts are given by the ``[roles]`` table of the control-point file
    (``docs/robot.md``).

    Attributes
    ----------
    scaled
        Row (set index) of the set whose distance gives the factor f of eq. (2) (the
        paper's L1).
    scaled_joints
        Joints whose velocity limits eq. (3) scales by (1 − f): the joints that move the
        scaled set (the paper's A1 and A2).
    repelled
        Row of the set whose closest point is pushed away from the person at v_rep of
        eqs. (4)-(5), through eq. (6)'s square Jacobian and eq. (9) (the paper's L2).
    repelled_joints
        Joints of eq. (6)'s square Jacobian and of eq. (9)'s sum, as many as the three
        components of v_rep (the paper's A1, A2 and A4).
    end_effector
        Row of the set that carries the task of eq. (8) and the repulsion of eq. (7)
        (the paper's EE).
    elbow
        Index of the elbow among the control points (the redundancy mode keeps it away
        from the person, :class:`~qpavoid.control.qp.tasks.elbow.ElbowClearanceTask`), or
        None if the description names none.
    """

    scaled: int
    scaled_joints: tuple[str, ...]
    repelled: int
    repelled_joints: tuple[str, ...]
    end_effector: int
    elbow: int | None = None

    @property
    def rows(self) -> tuple[int, int, int]:
        """The rows of the scaled, repelled and end-effector sets (:data:`ROLE_NAMES`)."""
        return (self.scaled, self.repelled, self.end_effector)


@dataclass(frozen=True)
class IKSeed:
    """Where the inverse kinematics of a pose starts (``[ik_seed]``, optional).

    The seed picks the solution's branch: every joint at 0 except ``angles``, and the
    ``aim`` joint (a base joint turning about the vertical) turned to face the wrist
    centre, which lies ``wrist_to_tool_m`` behind the end-effector frame along its z axis.

    Attributes
    ----------
    aim
        The base joint turned to face the wrist centre (``atan2(y, x)``), or None.
    angles
        ``(joint name, angle)`` pairs, rad.
    wrist_to_tool_m
        From the wrist centre to the end-effector frame along the frame's z axis, m (the
        seed only needs it roughly).
    """

    aim: str | None = None
    angles: tuple[tuple[str, float], ...] = ()
    wrist_to_tool_m: float = 0.0


class Description(NamedTuple):
    """A read robot description: the arguments of :class:`~qpavoid.arm.model.Robot`, in order."""

    model: pin.Model
    sets: list[ControlSet]
    point_frames: list[int]
    ee_frame: int
    name: str
    locked: dict[str, float]
    roles: Roles
    arm: ArmDynamics
    ik_seed: IKSeed
    urdf: Path
    mesh_dirs: tuple[Path, ...]
    coverage_exclude: dict[str, str]
    path: Path
    home: dict[str, float]


def _bundled_root() -> Path:
    """Folder of the bundled descriptions: the installed ``qpavoid.robots`` package, or
    ``robots/`` beside the package in a source checkout."""
    try:
        return Path(str(resources.files("qpavoid.robots")))
    except ModuleNotFoundError:
        return Path(__file__).resolve().parents[2] / "robots"  # qpavoid/arm/ -> the checkout


def bundled_robots() -> tuple[str, ...]:
    """Names of the bundled descriptions (``--robot NAME``), sorted: those whose URDF comes
    from an extra load only once it is installed."""
    root = _bundled_root()
    return tuple(sorted(p.name for p in root.iterdir() if (p / CONFIG_NAME).is_file()))


def _description_dir(name: str | Path) -> Path:
    """Folder of a robot description: the name of a bundled description (a bare name, as
    text: it wins over a folder of that name in the working directory, which ``./name``
    reaches), or a path."""
    root = _bundled_root()
    if isinstance(name, str) and SET_NAME.fullmatch(name) and (root / name / CONFIG_NAME).is_file():
        return root / name
    path = Path(name)
    if path.suffix == ".toml" and path.is_file():
        return path.parent
    if path.is_dir() and (path / CONFIG_NAME).is_file():
        return path
    available = list(bundled_robots())
    raise RobotDescriptionError(
        f"unknown robot {str(name)!r}: not a folder with {CONFIG_NAME} and not one of the "
        f"bundled descriptions {available}",
        path=path,
        name="robot",
        value=str(name),
    )


def description_reference(name: str | Path) -> str:
    """How a run records the robot it ran: a bundled description's name, or the absolute
    folder of any other (so that ``qpavoid view`` finds the same arm from anywhere)."""
    folder = _description_dir(name)
    if isinstance(name, str) and folder == _bundled_root() / name:
        return name
    return str(folder.resolve())


def _carriers(model: pin.Model, frame_id: int) -> set[int]:
    """Joints whose body carries the origin of a frame.

    The origin of a revolute joint's frame lies on its axis, so it is fixed on both the
    parent body and the joint's own body.
    """
    frame = model.frames[frame_id]
    carriers = {frame.parentJoint}
    if frame.type == pin.FrameType.JOINT:
        carriers.add(model.parents[frame.parentJoint])
    return carriers


def _frame_list(model: pin.Model, count: int) -> str:
    """The URDF's frame names (the first ``count`` frames of the model, the universe
    aside), shortened for a message."""
    names = [str(model.frames[i].name) for i in range(1, count)]
    shown = names if len(names) <= 20 else [*names[:20], f"... ({len(names)} in all)"]
    return "[" + ", ".join(shown) + "]"


def _add_point_frame(
    model: pin.Model,
    data: pin.Data,
    label: str,
    spot: Sequence[str] | Mapping[str, Any],
    where: tuple[str, str, Path, Path, int],
) -> int:
    """Add an operational frame at a spot of the file; return its id.

    A spot is the centroid of the named frames (``["A2", "A3"]``), or an offset from one
    frame in its axes (``{ frame = "panda_link4", xyz = [0.0, 0.0, 0.1] }``, m), which
    then moves with that frame's body. ``where`` says where in the file the spot is: the
    key as the file says it (``"[[sets]] entry 0 (L1) points[2]"``), as the error's
    ``name``, the file, the URDF and the number of the URDF's own frames (for the list in
    the message).
    """
    said, key, path, urdf, n_frames = where
    if isinstance(spot, Mapping):
        names: Sequence[str] = [spot["frame"]]
        offset = np.asarray(spot["xyz"], dtype=float)
    else:
        names, offset = spot, None
    ids = []
    for n in names:
        if not model.existFrame(n):
            raise RobotDescriptionError(
                f"{path}: {said}: no frame named {n!r} in {urdf.name}; its frames are "
                f"{_frame_list(model, n_frames)}",
                path=path,
                name=key,
                value=n,
            )
        ids.append(model.getFrameId(n))
    if offset is not None:  # off the frame's origin: only the frame's own body carries it
        _exists_free(model, label, said, key, path, urdf)
        frame = model.frames[ids[0]]
        placement = frame.placement * pin.SE3(np.eye(3), offset)
        return model.addFrame(
            pin.Frame(label, frame.parentJoint, placement, pin.FrameType.OP_FRAME)
        )
    common = set.intersection(*(_carriers(model, i) for i in ids))
    if not common:
        raise RobotDescriptionError(
            f"{path}: {said}: frames {list(names)} are not on one rigid body of {urdf.name}; "
            "a point is the centroid of frames of one link (or of the joints at its ends)",
            path=path,
            name=key,
            value=list(names),
        )
    _exists_free(model, label, said, key, path, urdf)
    parent = max(common)  # the deepest body carrying all of them
    centre = np.mean([data.oMf[i].translation for i in ids], axis=0)
    placement = data.oMi[parent].actInv(pin.SE3(np.eye(3), centre))
    return model.addFrame(pin.Frame(label, parent, placement, pin.FrameType.OP_FRAME))


def _exists_free(model: pin.Model, label: str, said: str, key: str, path: Path, urdf: Path) -> None:
    """Refuse a URDF that already has a frame of the name qpavoid gives a point."""
    if model.existFrame(label):
        raise RobotDescriptionError(
            f"{path}: {said}: {urdf.name} already has a frame named {label!r}, the name "
            "qpavoid gives this point; rename the set",
            path=path,
            name=key,
            value=label,
        )


def _set_error(path: Path, k: int, key: str, message: str, value: object) -> RobotDescriptionError:
    """A :class:`RobotDescriptionError` about key ``key`` of ``[[sets]]`` entry ``k``."""
    return RobotDescriptionError(
        f"{path}: [[sets]] entry {k}: {message}",
        path=path,
        name=f"sets[{k}].{key}",
        value=value,
    )


def _is_spot(spot: object, frame_name: bool = False) -> bool:
    """Whether ``spot`` names a point: a non-empty list of frame names, an offset
    ``{ frame = "<frame>", xyz = [x, y, z] }`` (finite, m), or with ``frame_name`` a
    frame name alone (a capsule end)."""
    if isinstance(spot, str):
        return frame_name
    if isinstance(spot, list):
        return bool(spot) and all(isinstance(n, str) for n in spot)
    if not isinstance(spot, dict) or set(spot) != set(OFFSET_KEYS):
        return False
    xyz = spot["xyz"]
    return (
        isinstance(spot["frame"], str)
        and isinstance(xyz, list)
        and len(xyz) == 3
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in xyz)
        and bool(np.isfinite(xyz).all())
    )


def _check_points(points: object, path: Path, k: int) -> None:
    """Refuse a set's ``points`` unless it is a non-empty list of non-empty lists of frame
    names (:data:`POINTS_SHAPE`)."""
    if isinstance(points, list) and points and all(_is_spot(p) for p in points):
        return
    raise _set_error(
        path,
        k,
        "points",
        "points must be a non-empty list of control points, each the list of the frames "
        f"it is the centroid of, e.g. {POINTS_SHAPE}; got {points!r}",
        points,
    )


def _check_sets(set_cfgs: list, path: Path) -> None:
    """Raise :class:`RobotDescriptionError` unless every ``[[sets]]`` entry has its keys,
    no other, a name of its own made of letters, digits, ``_``, ``.`` and ``-``, points
    of the shape :data:`POINTS_SHAPE`, capsule ends named by frame names and radii above
    0 m."""
    names: list[object] = []
    for k, sc in enumerate(set_cfgs):
        sc = sc if isinstance(sc, dict) else {}
        missing = [key for key in SET_KEYS if key not in sc]
        cap = sc.get("capsule")
        if isinstance(cap, dict):
            missing += [f"capsule.{key}" for key in CAPSULE_KEYS if key not in cap]
        if missing:
            raise RobotDescriptionError(
                f"{path}: [[sets]] entry {k} is missing key(s) {', '.join(missing)}",
                path=path,
                name=f"sets[{k}]",
                value=missing,
            )
        _unknown_keys(sc, SET_KEYS, f"[[sets]] entry {k}", path, f"sets[{k}]")
        name = sc["name"]
        if not isinstance(name, str) or not SET_NAME.fullmatch(name):
            raise _set_error(
                path,
                k,
                "name",
                "name must be letters, digits, '_', '.' and '-' only (it becomes part of "
                f"frame names, log keys and figure file names), got {name!r}",
                name,
            )
        if name in names:
            raise _set_error(
                path,
                k,
                "name",
                f"the name {name!r} is already entry {names.index(name)}'s; give each "
                "set a name of its own",
                name,
            )
        names.append(name)
        _check_points(sc["points"], path, k)
        if not isinstance(cap, dict):
            raise RobotDescriptionError(
                f"{path}: [[sets]] entry {k}: capsule must be a table "
                '{ from = "<frame>", to = "<frame>", capsule_radius_m = <m> }',
                path=path,
                name=f"sets[{k}].capsule",
                value=cap,
            )
        _unknown_keys(cap, CAPSULE_KEYS, f"[[sets]] entry {k}: capsule", path, f"sets[{k}].capsule")
        for end in ("from", "to"):
            if not _is_spot(cap[end], frame_name=True):
                raise _set_error(
                    path,
                    k,
                    f"capsule.{end}",
                    f"capsule.{end} must be a frame name or an offset from one, "
                    f'{{ frame = "<frame>", xyz = [x, y, z] }} (m), got {cap[end]!r}',
                    cap[end],
                )
        _number(sc["sphere_radius_m"], f"sets[{k}].sphere_radius_m", path, 0.0, strict=True)
        _number(cap["capsule_radius_m"], f"sets[{k}].capsule.capsule_radius_m", path, 0.0, True)


def _read_config(folder: Path) -> tuple[dict, Path, list, str]:
    """The parsed control-point file of ``folder``, its URDF path, sets and end effector."""
    path = folder / CONFIG_NAME
    try:
        cfg = read_toml(path, MAX_CONFIG_BYTES)
    except NotTOMLError as exc:
        raise RobotDescriptionError(f"{path}: {one_line(exc)}", path=path) from None
    except (OSError, ValueError) as exc:  # too large, not a regular file, not UTF-8
        raise RobotDescriptionError(
            f"{path}: cannot read the file: {one_line(exc)}", path=path
        ) from None
    try:
        urdf_name, set_cfgs, ee_name = cfg["urdf"], cfg["sets"], cfg["end_effector"]
    except KeyError as exc:
        raise RobotDescriptionError(
            f"{path}: missing key {exc}", path=path, name=exc.args[0]
        ) from None
    _unknown_keys(cfg, TOP_KEYS, "the top level", path, "")
    _check_finished(cfg, path)
    for key, value in (("urdf", urdf_name), ("end_effector", ee_name)):
        if key == "urdf" and isinstance(value, dict):
            continue
        if not isinstance(value, str) or not value:
            raise RobotDescriptionError(
                f"{path}: {key} must be a name (text), got {value!r}",
                path=path,
                name=key,
                value=value,
            )
    if not isinstance(set_cfgs, list):
        raise RobotDescriptionError(
            f"{path}: sets must be an array of tables, one [[sets]] per set (docs/robot.md)",
            path=path,
            name="sets",
            value=set_cfgs,
        )
    _check_sets(set_cfgs, path)
    return cfg, _urdf_path(urdf_name, folder, path), set_cfgs, ee_name


#: What ``qpavoid robot fit`` writes where the user has to fill something in.
TO_DO = "TO DO"


def _check_finished(value: object, path: Path, key: str = "") -> None:
    """Refuse a file that still holds a :data:`TO_DO` of ``qpavoid robot fit`` (a role, a
    frame or a source left as written), naming the first such key."""
    if isinstance(value, dict):
        for k, v in value.items():
            _check_finished(v, path, f"{key}.{k}" if key else str(k))
    elif isinstance(value, list):
        for i, v in enumerate(value):
            _check_finished(v, path, f"{key}[{i}]")
    elif isinstance(value, str) and TO_DO in value:
        raise RobotDescriptionError(
            f"{path}: {key} is still {value!r}, as `qpavoid robot fit` wrote it: fill it in "
            "(docs/robot.md, Adding an arm)",
            path=path,
            name=key,
            value=value,
        )


def _urdf_path(value: str | dict, folder: Path, path: Path) -> Path:
    """The URDF a description names: a file beside it (``urdf = "iiwa14.urdf"``), or a
    file of an installed Python package (``urdf = { package = "example-robot-data", path =
    "cmeel.prefix/share/.../panda.urdf" }``), found with :mod:`importlib.metadata`.

    Raises
    ------
    RobotDescriptionError
        If the table has other keys, or the package is not installed (naming the extra of
        qpavoid that installs it).
    """
    if isinstance(value, str):
        return folder / value
    _unknown_keys(value, PACKAGE_KEYS, "urdf", path, "urdf")
    package, inner = value.get("package"), value.get("path")
    if not isinstance(package, str) or not isinstance(inner, str) or not package or not inner:
        raise RobotDescriptionError(
            f"{path}: urdf must be a file name or a table "
            '{ package = "<Python package>", path = "<file inside it>" }, '
            f"got {value!r}",
            path=path,
            name="urdf",
            value=value,
        )
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


def check_lock_angle(model: pin.Model, joint: str, angle: float) -> None:
    """Raise :class:`InputError` if ``joint`` cannot be locked at ``angle`` (rad)."""
    fault = angle_fault(model, joint, angle)
    if fault:
        raise InputError(
            f"cannot lock {joint} at {angle!r} rad: {fault}", name="locked", value={joint: angle}
        )


def angle_fault(model: pin.Model, joint: str, angle: float) -> str:
    """What is wrong with locking the model's joint ``joint`` at ``angle`` (rad), or ``""``."""
    idx = model.joints[model.getJointId(joint)].idx_q
    low, high = model.lowerPositionLimit[idx], model.upperPositionLimit[idx]
    if not (np.isfinite(angle) and low <= angle <= high):
        return f"not within the joint's limits [{low:g}, {high:g}] rad"
    return ""


def _file_locked(
    value: object, path: Path, model: pin.Model, key: str = "locked"
) -> dict[str, float]:
    """The file's ``locked`` (or ``held``, as ``key`` says): a table of joint angles
    (rad), or a list of joint names (locked at 0), each a joint of the URDF locked within
    its limits."""
    if value is None:
        return {}
    if isinstance(value, list) and all(isinstance(n, str) for n in value):
        twice = sorted({n for n in value if value.count(n) > 1})
        if twice:
            raise RobotDescriptionError(
                f"{path}: {key} lists {twice} more than once",
                path=path,
                name=key,
                value=twice,
            )
        value = dict.fromkeys(value, 0.0)
    if not isinstance(value, dict):
        raise RobotDescriptionError(
            f"{path}: {key} must be a table of angles (rad), e.g. {key} = {{ <joint> = 0.0 }}, "
            f'or a list of joint names locked at 0, e.g. {key} = ["<joint>"]; got {value!r}',
            path=path,
            name=key,
            value=value,
        )
    for joint, angle, fault in _angle_faults(value, path, model, key):
        raise RobotDescriptionError(
            f"{path}: {key}: {joint} = {angle!r} is {fault}; lock it at an angle (rad) "
            "within its limits",
            path=path,
            name=f"{key}.{joint}",
            value=angle,
        )
    return {joint: float(angle) for joint, angle in value.items()}


def _angle_faults(
    table: Mapping[str, object], path: Path, model: pin.Model, key: str
) -> Iterator[tuple[str, object, str]]:
    """``(joint, angle, fault)`` of each angle of ``table`` (the file's ``key``) that is not
    a number within its joint's limits; a name that is not a joint of the URDF raised."""
    for joint, angle in table.items():
        if not model.existJointName(joint):
            raise RobotDescriptionError(
                f"{path}: {key}: {joint!r} is not a joint of the URDF; its joints are "
                f"{list(model.names)[1:]}",
                path=path,
                name=key,
                value=joint,
            )
        if not isinstance(angle, (int, float)) or isinstance(angle, bool):
            yield joint, angle, "not an angle (rad)"
        elif fault := angle_fault(model, joint, float(angle)):
            yield joint, angle, fault


def _locked_angles(
    locked: Mapping[str, float] | Sequence[str] | None,
    default: Mapping[str, float],
    model: pin.Model,
) -> dict[str, float]:
    """The joints to lock and their angles (rad); see :func:`read_description`.

    ``default`` is the file's ``locked`` (already checked); a fault of the argument
    ``locked`` alone is an :class:`InputError`.
    """
    if locked is None:
        return dict(default)
    if isinstance(locked, (str, bytes)):
        raise InputError(
            f"locked must be joint names or a mapping of joint names to angles (rad), "
            f"not the text {locked!r}",
            name="locked",
            value=locked,
        )
    if not isinstance(locked, Mapping):
        locked = {n: default.get(n, 0.0) for n in locked}
    try:
        angles = {str(k): float(v) for k, v in locked.items()}
    except (TypeError, ValueError) as exc:
        raise InputError(
            f"locked angles must be numbers (rad), got {dict(locked)!r}",
            name="locked",
            value=dict(locked),
        ) from exc
    for joint, angle in angles.items():
        if not model.existJointName(joint):
            raise InputError(
                f"cannot lock {joint!r}: joints are {list(model.names)[1:]}",
                name="locked",
                value=joint,
            )
        check_lock_angle(model, joint, angle)
    return angles


def _add_frames(model: pin.Model, set_cfgs: list, path: Path, urdf: Path) -> None:
    """Operational frames for points and capsule ends, placed at the neutral configuration."""
    data = model.createData()
    pin.framesForwardKinematics(model, data, pin.neutral(model))
    n_frames = model.nframes
    for i, sc in enumerate(set_cfgs):
        name, cap = sc["name"], sc["capsule"]
        entries = [(f"{name}_p{k}", spot, f"points[{k}]") for k, spot in enumerate(sc["points"])]
        entries += [
            (
                f"{name}_capsule_{end}",
                [cap[end]] if isinstance(cap[end], str) else cap[end],
                f"capsule.{end}",
            )
            for end in ("from", "to")
        ]
        for label, spot, key in entries:
            said = f"[[sets]] entry {i} ({name}) {key}"
            _add_point_frame(
                model, data, label, spot, (said, f"sets[{i}].{key}", path, urdf, n_frames)
            )


def _lock(model: pin.Model, locked: Mapping[str, float]) -> pin.Model:
    """The model with the ``locked`` joints (checked) removed at their angles
    (``buildReducedModel``)."""
    if not locked:
        return model
    q_ref = pin.neutral(model)
    for jn, angle in locked.items():
        q_ref[model.joints[model.getJointId(jn)].idx_q] = angle
    return pin.buildReducedModel(model, [model.getJointId(jn) for jn in locked], q_ref)


def _control_sets(model: pin.Model, set_cfgs: list) -> tuple[list[ControlSet], list[int]]:
    """The control sets and the frame id of every control point, set after set."""
    sets: list[ControlSet] = []
    point_frames: list[int] = []
    for sc in set_cfgs:
        idx = []
        for k in range(len(sc["points"])):
            idx.append(len(point_frames))
            point_frames.append(model.getFrameId(f"{sc['name']}_p{k}"))
        sets.append(
            ControlSet(
                name=sc["name"],
                sphere_radius_m=float(sc["sphere_radius_m"]),
                points=tuple(idx),
                capsule_frames=(
                    model.getFrameId(f"{sc['name']}_capsule_from"),
                    model.getFrameId(f"{sc['name']}_capsule_to"),
                ),
                capsule_radius_m=float(sc["capsule"]["capsule_radius_m"]),
            )
        )
    return sets, point_frames


def _joint_list(value: object, where: str, path: Path, joints: Sequence[str]) -> tuple[str, ...]:
    """``value`` as a tuple of joint names of the URDF, or a :class:`RobotDescriptionError`."""
    if not isinstance(value, list) or not all(isinstance(n, str) for n in value):
        raise RobotDescriptionError(
            f"{path}: {where} must be a list of joint names, got {value!r}",
            path=path,
            name=where,
            value=value,
        )
    missing = [n for n in value if n not in joints]
    if missing:
        raise RobotDescriptionError(
            f"{path}: {where}: {missing} are not joints of the URDF; its joints are {list(joints)}",
            path=path,
            name=where,
            value=missing,
        )
    return tuple(value)


def _roles(cfg: Mapping[str, Any], path: Path, set_cfgs: list, joints: Sequence[str]) -> Roles:
    """The ``[roles]`` table: which set plays which part, and the elbow point."""
    table = _table(cfg, "roles", path, 'scaled = { set = "<set>", joints = ["<joint>", ...] }')
    _unknown_keys(table, ROLE_KEYS, "[roles]", path, "roles")
    names = [sc["name"] for sc in set_cfgs]
    rows: dict[str, int] = {}
    role_joints: dict[str, tuple[str, ...]] = {}
    for role in ROLE_NAMES:
        entry = table.get(role)
        keys = ("set",) if role == "end_effector" else ("set", "joints")
        if not isinstance(entry, dict) or any(k not in entry for k in keys):
            shape = ", ".join(f"{k} = ..." for k in keys)
            raise RobotDescriptionError(
                f"{path}: [roles] needs {role} = {{ {shape} }} (docs/robot.md: Roles)",
                path=path,
                name=f"roles.{role}",
                value=entry,
            )
        _unknown_keys(entry, keys, f"[roles] {role}", path, f"roles.{role}")
        if entry["set"] not in names:
            raise RobotDescriptionError(
                f"{path}: [roles] {role}: no set named {entry['set']!r}; the sets are {names}",
                path=path,
                name=f"roles.{role}.set",
                value=entry["set"],
            )
        rows[role] = names.index(entry["set"])
        if "joints" in keys:
            where = f"roles.{role}.joints"
            role_joints[role] = _joint_list(entry["joints"], where, path, joints)
            twice = sorted({n for n in role_joints[role] if role_joints[role].count(n) > 1})
            if not role_joints[role] or twice:
                raise RobotDescriptionError(
                    f"{path}: [roles] {role}.joints "
                    + (f"lists {twice} more than once" if twice else "is empty")
                    + f"; name each joint that moves the set {entry['set']!r} once "
                    "(docs/robot.md: Roles)",
                    path=path,
                    name=where,
                    value=twice or [],
                )
    return Roles(
        scaled=rows["scaled"],
        scaled_joints=role_joints["scaled"],
        repelled=rows["repelled"],
        repelled_joints=role_joints["repelled"],
        end_effector=rows["end_effector"],
        elbow=_elbow(table.get("elbow"), path, set_cfgs),
    )


def _elbow(frames: object, path: Path, set_cfgs: list) -> int | None:
    """Index of the control point ``[roles] elbow`` names: the list of its frames, or its
    offset table (``{ frame = "<frame>", xyz = [x, y, z] }``), as in its set's points."""
    if frames is None:
        return None
    points = [
        _spot_key(spot) for sc in set_cfgs for spot in sc["points"]
    ]  # every point, set after set
    if _is_spot(frames):
        given = _spot_key(frames)  # type: ignore[arg-type]
        if given in points:
            return points.index(given)
    shown = [sorted(spot) if isinstance(spot, list) else spot for spot in points]
    raise RobotDescriptionError(
        f"{path}: [roles] elbow must be one control point as its set's points give it (the "
        f"list of its frames, or its {{ frame, xyz }} table); {frames!r} is none of {shown}",
        path=path,
        name="roles.elbow",
        value=frames,
    )


def _spot_key(spot: Sequence[str] | Mapping[str, Any]) -> object:
    """A comparable form of a point: its frames sorted, or its frame and offset."""
    if isinstance(spot, Mapping):
        return {"frame": spot["frame"], "xyz": [float(v) for v in spot["xyz"]]}
    return sorted(str(n) for n in spot)


def _ik_seed(cfg: Mapping[str, Any], path: Path, joints: Sequence[str]) -> IKSeed:
    """The ``[ik_seed]`` table, or the zero configuration's seed without one."""
    if "ik_seed" not in cfg:
        return IKSeed()
    table = _table(cfg, "ik_seed", path, 'aim = "<joint>", angles = { <joint> = 0.5 }')
    _unknown_keys(table, ("aim", "angles", "wrist_to_tool_m"), "[ik_seed]", path, "ik_seed")
    aim = table.get("aim")
    if aim is not None:
        (aim,) = _joint_list([aim], "ik_seed.aim", path, joints)
    angles = table.get("angles", {})
    if not isinstance(angles, dict):
        raise RobotDescriptionError(
            f"{path}: [ik_seed] angles must map joint names to angles (rad), got {angles!r}",
            path=path,
            name="ik_seed.angles",
            value=angles,
        )
    _joint_list(list(angles), "ik_seed.angles", path, joints)
    return IKSeed(
        aim=aim,
        angles=tuple(
            (n, _number(a, f"ik_seed.angles.{n}", path, -np.inf, True)) for n, a in angles.items()
        ),
        wrist_to_tool_m=_number(
            table.get("wrist_to_tool_m", 0.0), "ik_seed.wrist_to_tool_m", path, 0.0, False
        ),
    )


def _home(value: object, path: Path, model: pin.Model) -> dict[str, float]:
    """The file's ``home``: a table of joint angles (rad), each a joint of the URDF at a
    finite angle within its limits; ``{}`` without one (:meth:`Robot.neutral
    <qpavoid.arm.model.Robot.neutral>` then puts every joint at 0, or mid-range where 0 is
    outside its limits)."""
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise RobotDescriptionError(
            f"{path}: home must be a table of joint angles (rad), e.g. home = "
            f"{{ <joint> = -0.785 }}; got {value!r}",
            path=path,
            name="home",
            value=value,
        )
    for joint, angle, fault in _angle_faults(value, path, model, "home"):
        raise RobotDescriptionError(
            f"{path}: home: {joint} = {angle!r}: {fault}",
            path=path,
            name="home",
            value={joint: angle},
        )
    return {str(joint): float(angle) for joint, angle in value.items()}


def _coverage(cfg: Mapping[str, Any], path: Path) -> dict[str, str]:
    """The ``[coverage]`` table's exclusions: collision object name -> the reason it may
    lie outside the capsules and spheres (each reason required); ``{}`` without one."""
    if "coverage" not in cfg:
        return {}
    table = _table(cfg, "coverage", path, 'exclude = { "<collision object>" = "<why>" }')
    _unknown_keys(table, ("exclude",), "[coverage]", path, "coverage")
    exclude = table.get("exclude", {})
    if not isinstance(exclude, dict) or not all(
        isinstance(v, str) and v.strip() for v in exclude.values()
    ):
        raise RobotDescriptionError(
            f"{path}: [coverage] exclude must map each collision object it leaves out to "
            'the reason, e.g. exclude = { "link_0_0" = "fixed to the base: never moves" }; '
            f"got {exclude!r}",
            path=path,
            name="coverage.exclude",
            value=exclude,
        )
    return {str(k): str(v) for k, v in exclude.items()}


#: Where along a capsule's axis, and at how many configurations, the check of
#: :func:`_check_capsules` compares Jacobians (beyond the zero configuration); its
#: tolerance, m/s per rad/s (far above rounding, far below any joint's lever arm).
CHECK_PARAMETERS = (0.2, 0.5, 0.8)
CHECK_CONFIGURATIONS = 3
CHECK_TOLERANCE = 1e-9


def _check_capsules(model: pin.Model, sets: Sequence[ControlSet], path: Path) -> None:
    """Refuse a capsule whose axis does not move with one rigid body.

    The controllers take the Jacobian of a capsule's witness point as the interpolation
    ``(1 − s) J_a + s J_b`` of its ends' Jacobians
    (:meth:`~qpavoid.arm.model.Kinematics.segment_point_jacobian`). That is the Jacobian of
    the point on the body that carries it exactly when some body carries the whole axis:
    both ends on one link, or ends on the axis of every joint between them (the iiwa's
    roll joints turn about their capsules' axes). Checked here with Pinocchio: some body's
    Jacobian, taken at points along the axis, must equal the interpolation at the zero
    configuration and at a few others.

    Raises
    ------
    RobotDescriptionError
        For the first capsule carried by no single body, naming the joints that bend it
        and how to fix the file.
    """
    data = model.createData()
    rng = np.random.default_rng(0)  # the same configurations every time
    configurations = [pin.neutral(model)] + [
        pin.integrate(model, pin.neutral(model), rng.uniform(-1.0, 1.0, model.nv))
        for _ in range(CHECK_CONFIGURATIONS)
    ]
    carried = {k: set(range(model.njoints)) for k in range(len(sets))}  # bodies left
    for q in configurations:
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        for k, cs in enumerate(sets):
            a_id, b_id = cs.capsule_frames
            a, b = data.oMf[a_id].translation, data.oMf[b_id].translation
            Ja = pin.getFrameJacobian(model, data, a_id, LWA)[:3]
            Jb = pin.getFrameJacobian(model, data, b_id, LWA)[:3]
            for s in CHECK_PARAMETERS:
                point = pin.SE3(np.eye(3), (1.0 - s) * a + s * b)
                interpolated = (1.0 - s) * Ja + s * Jb
                carried[k] = {
                    j
                    for j in carried[k]
                    if np.allclose(
                        pin.getFrameJacobian(model, data, j, data.oMi[j].actInv(point), LWA)[:3],
                        interpolated,
                        rtol=0.0,
                        atol=CHECK_TOLERANCE,
                    )
                }
    for k, cs in enumerate(sets):
        if carried[k]:
            continue
        # the joints bending it: where the velocity of its mid-point on the body carrying
        # its first end differs from the interpolation (at the last configuration)
        a_id, b_id = cs.capsule_frames
        a, b = data.oMf[a_id].translation, data.oMf[b_id].translation
        interpolated = 0.5 * (
            pin.getFrameJacobian(model, data, a_id, LWA)[:3]
            + pin.getFrameJacobian(model, data, b_id, LWA)[:3]
        )
        body = model.frames[a_id].parentJoint
        mid = data.oMi[body].actInv(pin.SE3(np.eye(3), 0.5 * (a + b)))
        J = pin.getFrameJacobian(model, data, body, mid, LWA)[:3]
        columns = [
            str(model.names[j]) for j in range(1, model.njoints) for _ in range(model.joints[j].nv)
        ]
        bent = np.abs(J - interpolated).max(axis=0) > CHECK_TOLERANCE
        between = [columns[v] for v in np.flatnonzero(bent)]
        raise RobotDescriptionError(
            f"{path}: the capsule of set {cs.name!r} is carried by no single body: joint(s) "
            f"{between} between its ends turn one end about an axis that is not the "
            "capsule's, so a point on it does not move as the interpolation of its ends. "
            "Fix the file: give the set a capsule whose two ends lie on one link (split it "
            "at the joint into two sets), or whose ends lie on the axis of every joint "
            "between them",
            path=path,
            name=f"sets.{cs.name}.capsule",
            value=between,
        )


def _check_point_speed(
    model: pin.Model, point_frames: Sequence[int], bound_mps: float, path: Path
) -> None:
    """Refuse an ``[arm] max_point_speed_mps`` that some control point exceeds: with one
    joint alone at its URDF velocity limit, a point moves at ``‖J_p[:, j]‖ q̇_max,j``, a
    lower bound of its fastest speed, checked at the zero configuration and at
    :data:`CHECK_CONFIGURATIONS` others (speed and separation leaves out the rows whose
    bound exceeds ``max_point_speed_mps``: too low a value would drop rows that bind)."""
    data = model.createData()
    rng = np.random.default_rng(0)
    configurations = [pin.neutral(model)] + [
        pin.integrate(model, pin.neutral(model), rng.uniform(-1.0, 1.0, model.nv))
        for _ in range(CHECK_CONFIGURATIONS)
    ]
    fastest, where = 0.0, ""
    for q in configurations:
        pin.computeJointJacobians(model, data, q)
        pin.updateFramePlacements(model, data)
        for f in point_frames:
            J = pin.getFrameJacobian(model, data, f, LWA)[:3]
            speeds = np.linalg.norm(J, axis=0) * model.velocityLimit
            if speeds.max() > fastest:
                fastest, where = float(speeds.max()), str(model.frames[f].name)
    if fastest > bound_mps:
        raise RobotDescriptionError(
            f"{path}: [arm] max_point_speed_mps = {bound_mps:g} m/s, but the control point "
            f"{where} moves at {fastest:.2f} m/s with a single joint at its URDF speed limit: "
            "give a bound no point of the arm reaches (docs/robot.md, Arm)",
            path=path,
            name="arm.max_point_speed_mps",
            value=bound_mps,
        )


def _check_free(joints: Sequence[str], locked: Mapping[str, float], path: Path, by: str) -> None:
    """Refuse locking every joint (a model with nothing to move)."""
    if set(joints) <= set(locked):
        raise RobotDescriptionError(
            f"{path}: {by} locks every joint, {list(joints)}: nothing is left to move; "
            "leave at least the joints of [roles] free",
            path=path,
            name="locked",
            value=sorted(locked),
        )


def _check_role_joints(model: pin.Model, roles: Roles, set_cfgs: list, path: Path) -> None:
    """Refuse a role joint that moves none of its set's points: in Pinocchio's tree
    (``model.supports``) it must be an ancestor of at least one point's body."""
    for role, row, role_joints in (
        ("scaled", roles.scaled, roles.scaled_joints),
        ("repelled", roles.repelled, roles.repelled_joints),
    ):
        name = set_cfgs[row]["name"]
        bodies = {
            model.frames[model.getFrameId(f"{name}_p{k}")].parentJoint
            for k in range(len(set_cfgs[row]["points"]))
        }
        moving = sorted({j for b in bodies for j in model.supports[b] if j > 0})
        moving_names = [str(model.names[j]) for j in moving]
        idle = [j for j in role_joints if j not in moving_names]
        if idle:
            raise RobotDescriptionError(
                f"{path}: [roles] {role}.joints: {idle} move no point of the set {name!r} "
                f"(they come after its points in the URDF's chain); the joints that move it "
                f"are {moving_names}: name those",
                path=path,
                name=f"roles.{role}.joints",
                value=idle,
            )


def _check_roles_free(model: pin.Model, roles: Roles, path: Path, by: str) -> None:
    """Refuse a role joint that is not in the reduced model (locked)."""
    for role, role_joints in (
        ("scaled", roles.scaled_joints),
        ("repelled", roles.repelled_joints),
    ):
        locked = [j for j in role_joints if not model.existJointName(j)]
        if locked:
            raise RobotDescriptionError(
                f"{path}: [roles] {role}.joints: {locked} locked (by {by}); a role's joints "
                f"must be free: unlock them, or name free joints in [roles] {role}.joints",
                path=path,
                name=f"roles.{role}.joints",
                value=locked,
            )


#: How far the end-effector frame may lie outside the end-effector set's capsule, m
#: (rounding of the capsule's written ends and radius: 1 µm).
EE_INSIDE_TOLERANCE_M = 1e-6


def _check_end_effector(
    model: pin.Model, set_cfgs: list, roles: Roles, ee_name: str, path: Path
) -> None:
    """Refuse an end-effector set whose capsule does not hold the end-effector frame.

    The laws push the end effector (eq. 7) and servo its frame (eq. 8) with the set's
    distance, so the frame must lie on the set's body and inside its capsule: the
    capsule ends at the frame (by name, or at the same place of the same body, the
    paper's), or the frame lies within the capsule's radius of its axis (a capsule
    fitted to a hand's meshes) on a body that carries both ends.
    """
    sc = set_cfgs[roles.end_effector]
    ends = [model.frames[model.getFrameId(f"{sc['name']}_capsule_{e}")] for e in ("from", "to")]
    ee = model.frames[model.getFrameId(ee_name)]
    same = ends[1].parentJoint == ee.parentJoint and np.allclose(
        ends[1].placement.translation, ee.placement.translation, rtol=0.0, atol=1e-12
    )
    if sc["capsule"]["to"] == ee_name or same:
        return
    # within the capsule, on the body of both ends (so at every configuration)
    radius = float(sc["capsule"]["capsule_radius_m"])
    excess = np.inf
    if ends[0].parentJoint == ends[1].parentJoint == ee.parentJoint:
        a, b = ends[0].placement.translation, ends[1].placement.translation
        ab, rel = b - a, ee.placement.translation - a
        s = float(np.clip(rel @ ab / (ab @ ab), 0.0, 1.0)) if ab @ ab > 0.0 else 0.0
        excess = float(np.linalg.norm(rel - s * ab)) - radius
        if excess <= EE_INSIDE_TOLERANCE_M:
            return
    where = (
        f"{excess:.4f} m outside it" if np.isfinite(excess) else "on another body than the capsule"
    )
    raise RobotDescriptionError(
        f"{path}: [roles] end_effector: the end_effector frame {ee_name!r} must lie in the "
        f"end-effector set's capsule; it is {where} (set {sc['name']!r}): name the set "
        f'whose capsule holds it, give this set capsule.to = "{ee_name}", or name a frame '
        "inside the capsule as end_effector",
        path=path,
        name="roles.end_effector.set",
        value=sc["name"],
    )


def read_description(
    name: str | Path = "iiwa14", locked: Mapping[str, float] | Sequence[str] | None = None
) -> Description:
    """Read a robot description and build its (reduced) Pinocchio model.

    Arguments and errors as :func:`qpavoid.arm.model.load_robot`, which makes the
    :class:`~qpavoid.arm.model.Robot` from the returned :class:`Description`.
    """
    folder = _description_dir(name)
    cfg, urdf, set_cfgs, ee_name = _read_config(folder)
    path = folder / CONFIG_NAME
    model = build_urdf_model(urdf)
    check_urdf_joints(model, urdf)
    joints = tuple(str(n) for n in model.names)[1:]
    held = _file_locked(cfg.get("held"), path, model, "held")
    default = _file_locked(cfg.get("locked"), path, model)
    both = sorted(set(held) & set(default))
    if both:
        raise RobotDescriptionError(
            f"{path}: {both} are both held and locked; a joint is held (locked in every "
            "mode) or locked (by default), not both: remove it from one",
            path=path,
            name="held",
            value=both,
        )
    also = " and `held`" if held else ""
    _check_free(joints, {**default, **held}, path, f"the file's `locked`{also}")
    by = f"the file's `locked`{also}" if locked is None else "the locked= argument"
    by += " and the file's `held`" if held and locked is not None else ""
    locked = {**_locked_angles(locked, default, model), **held}
    _check_free(joints, locked, path, by)
    if not set_cfgs:
        raise RobotDescriptionError(
            f"{path}: no [[sets]]; give at least one (docs/robot.md)",
            path=path,
            name="sets",
            value=set_cfgs,
        )
    roles = _roles(cfg, path, set_cfgs, joints)
    arm = read_arm(cfg, path, joints)
    ik_seed = _ik_seed(cfg, path, joints)
    home = _home(cfg.get("home"), path, model)
    coverage_exclude = _coverage(cfg, path)
    _add_frames(model, set_cfgs, path, urdf)
    if not model.existFrame(ee_name):
        raise RobotDescriptionError(
            f"{path}: end_effector {ee_name!r} is not a frame of {urdf.name}",
            path=path,
            name="end_effector",
            value=ee_name,
        )
    _check_end_effector(model, set_cfgs, roles, ee_name, path)
    _check_role_joints(model, roles, set_cfgs, path)
    model = _lock(model, locked)
    _check_roles_free(model, roles, path, by)
    sets, point_frames = _control_sets(model, set_cfgs)
    _check_capsules(model, sets, path)
    _check_point_speed(model, point_frames, arm.max_point_speed_mps, path)
    return Description(
        model,
        sets,
        point_frames,
        model.getFrameId(ee_name),
        folder.name,
        locked,
        roles,
        arm,
        ik_seed,
        urdf,
        mesh_dirs(urdf),
        coverage_exclude,
        path,
        home,
    )
