"""Any camera's skeleton as the body's landmarks: the one place a format's joints become
the points the body model, the perception and the fusion work on.

The body's landmarks are the joints of the body format (``formats/kinect_v2.toml``: the
Kinect v2's 25 joints are anatomical landmarks, and keeping them makes every recording,
datagram and recorded command of a Kinect v2 cell what it was). A camera format's
``[landmarks]`` table gives each landmark as a weighted mean of the camera's joints
(:class:`~qpavoid.human.conversion.LandmarkRule`), so a frame maps by one matrix product:

.. math::

    p_l = \\sum_j W_{lj}\\, s\\, x_j, \\qquad
    \\mathrm{state}_l = \\min_{j : W_{lj} \\neq 0} \\mathrm{state}_j

with ``s`` the format's metres per unit and the states from the camera's confidence
(:class:`~qpavoid.human.conversion.Confidence`). A landmark one of whose joints is not
usable is not usable (never guessed from the others). Each rule's ``uncertainty_m`` is
how far the true landmark may be from the point: the perception adds it to the
landmark's uncertainty radius, which widens the body part in both distance methods and so
in speed and separation monitoring (:attr:`LandmarkMap.uncertainty_m`).

The same map runs the other way for a simulated camera of the format
(:meth:`LandmarkMap.simulated`): its ``[simulate]`` table places each of its joints from
the body's landmarks.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

import numpy as np

from qpavoid.core.checks import as_array
from qpavoid.core.errors import InputError, SkeletonFormatError
from qpavoid.human.conversion import LandmarkRule
from qpavoid.human.frames import HumanFrame, check_joints
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.human.skeleton import SkeletonFormat
from qpavoid.human.skeleton_file import FORMATS_DIR

__all__ = [
    "FORMAT_NAMES",
    "LandmarkMap",
    "body_frame",
    "camera_frame",
    "format_file",
    "landmark_map",
    "skeleton_format",
]

#: The smallest extent a camera's frame of three or more usable joints may have, m: a
#: person's hand alone spans more; a whole body 1000 times too small is metres given
#: where the format says millimetres.
MIN_BODY_M = 0.05
#: The units' names, for messages.
UNIT_NAMES = {1.0: "m", 0.001: "mm"}
#: The skeleton formats the library ships (a file ``formats/<name>.toml`` each).
FORMAT_NAMES = ("kinect_v2", "k4abt", "zed_body_34", "zed_body_38", "mediapipe_pose")


@cache
def _load(path: Path) -> SkeletonFormat:
    return SkeletonFormat.load(path)


def format_file(name: object) -> Path | None:
    """The absolute path of the camera's own format file ``name`` names (``*.toml``; its
    body file is found beside this path, not beside a link's target), else None (a
    shipped format's name)."""
    return Path(name).absolute() if isinstance(name, str) and name.endswith(".toml") else None


@cache
def _user_format(path: Path) -> SkeletonFormat:
    """A camera's format file of the user's, checked whole: read; named as its file (its
    body model is ``<name>_body.toml`` beside it) and not as a format the library ships; a
    camera's (``body = "kinect_v2"``, so that the simulation can film the true body with
    it); its ``[landmarks]`` and ``[simulate]`` tables each one matrix."""
    fmt = SkeletonFormat.load(path)

    def fail(message: str, key: str, value: object) -> SkeletonFormatError:
        return SkeletonFormatError(f"{path}: {message}", path=path, name=key, value=value)

    for wrong, message, key, value in (
        (
            fmt.name != path.stem,
            f"name must be the file's name, {path.stem!r} (its body model is "
            f"{path.stem}_body.toml beside it), got {fmt.name!r}",
            "name",
            fmt.name,
        ),
        (
            not fmt.name.replace("_", "").replace("-", "").isalnum(),
            f"name must be letters, digits, _ and -, got {fmt.name!r}",
            "name",
            fmt.name,
        ),
        (
            fmt.name in FORMAT_NAMES,
            f"name {fmt.name!r} is a format the library ships; call your camera's another",
            "name",
            fmt.name,
        ),
        (
            fmt.body != KINECT_V2.name,
            f"body must be {KINECT_V2.name!r}, with [landmarks] and [simulate] tables (a "
            f"camera's format: docs/formats.md), got {fmt.body!r}",
            "body",
            fmt.body,
        ),
    ):
        if wrong:
            raise fail(message, key, value)
    try:
        LandmarkMap.to_body(fmt)
        LandmarkMap.simulated(fmt)
    except SkeletonFormatError as exc:
        raise fail(str(exc), exc.name or "landmarks", exc.value) from None
    return fmt


def skeleton_format(name: str | SkeletonFormat) -> SkeletonFormat:
    """The skeleton format called ``name`` (one of :data:`FORMAT_NAMES`, or the path of a
    format file ``*.toml``: a camera of the user's; a format is returned as it is). Each
    file is read once per process.

    Raises
    ------
    InputError
        For an unknown name, naming the known ones.
    """
    if isinstance(name, SkeletonFormat):
        return name
    if name == KINECT_V2.name:
        return KINECT_V2
    path = format_file(name)
    if path is not None:  # a camera's own format file
        return _user_format(path)
    if not isinstance(name, str) or name not in FORMAT_NAMES:
        raise InputError(
            f"unknown skeleton format {name!r}; the formats are {', '.join(FORMAT_NAMES)}",
            name="format",
            value=name,
        )
    return _load(FORMATS_DIR / f"{name}.toml")


def _matrix(
    rules: tuple[tuple[str, LandmarkRule], ...],
    targets: tuple[str, ...],
    source: SkeletonFormat,
    key: str,
) -> tuple[np.ndarray, np.ndarray]:
    """(len(targets), source joints) weights and (len(targets),) uncertainty, m."""
    table = dict(rules)
    missing = [t for t in targets if t not in table]
    unknown = [t for t in table if t not in targets]
    if missing or unknown:
        raise SkeletonFormatError(
            f"{key} must give exactly the points {list(targets)}: "
            + (f"it lacks {missing}" if missing else f"{unknown} are not among them"),
            name=key,
            value=missing or unknown,
        )
    weights = np.zeros((len(targets), source.n_joints))
    uncertainty = np.zeros(len(targets))
    for t, name in enumerate(targets):
        rule = table[name]
        for joint, w in zip(rule.sources, rule.weights, strict=True):
            if joint not in source.joints:
                raise SkeletonFormatError(
                    f"{key}.{name}: {joint!r} is not a joint of {source.name}",
                    name=f"{key}.{name}",
                    value=joint,
                )
            weights[t, source.index(joint)] += w
        uncertainty[t] = rule.uncertainty_m
    return weights, uncertainty


@dataclass(frozen=True)
class LandmarkMap:
    """One format's joints as another's points (module docstring).

    Attributes
    ----------
    source
        The format of the frames mapped (its joints are ``W``'s columns).
    target
        The format of the frames made (its joints are ``W``'s rows).
    weights
        (targets, sources) ``W``: each row sums to 1 (read-only).
    uncertainty_m
        (targets,) how far each point may be from the truth, m (read-only).
    """

    source: SkeletonFormat
    target: SkeletonFormat
    weights: np.ndarray = field(repr=False)
    uncertainty_m: np.ndarray = field(repr=False)

    def __post_init__(self) -> None:
        for a in (self.weights, self.uncertainty_m):
            a.setflags(write=False)
        uses = self.weights != 0.0
        object.__setattr__(self, "_uses", uses)
        object.__setattr__(self, "_identity", np.array_equal(self.weights, np.eye(*uses.shape)))

    @property
    def identity(self) -> bool:
        """True when the map changes nothing (the body format onto itself)."""
        return bool(self._identity)  # type: ignore[attr-defined]

    def map(self, joints: np.ndarray, state: np.ndarray) -> HumanFrame:
        """The target's frame from a source frame, or frames: ``joints`` (..., J, 3) in
        metres, ``state`` (..., J) tracking states (0, 1, 2), both already checked."""
        if self.identity:
            return HumanFrame(joints, state)
        uses: np.ndarray = self._uses  # type: ignore[attr-defined]
        usable = np.isfinite(joints).all(axis=-1) & (state > 0)
        points = np.einsum("lj,...jx->...lx", self.weights, np.where(usable[..., None], joints, 0))
        worst = np.where(uses, state[..., None, :], 3).min(axis=-1)
        complete = ~np.any(uses & ~usable[..., None, :], axis=-1)
        out_state = np.where(complete, worst, 0).astype(np.int8)
        points[~complete] = np.nan
        return HumanFrame(points, out_state)

    @classmethod
    def to_body(cls, camera: SkeletonFormat) -> LandmarkMap:
        """The map from ``camera``'s joints to its body's landmarks."""
        if not camera.body:  # a body format: its joints are the landmarks
            n = camera.n_joints
            return cls(camera, camera, np.eye(n), np.zeros(n))
        body = skeleton_format(camera.body)
        weights, uncertainty = _matrix(
            camera.landmarks, body.joints, camera, f"{camera.name}: landmarks"
        )
        return cls(camera, body, weights, uncertainty)

    @classmethod
    def simulated(cls, camera: SkeletonFormat) -> LandmarkMap:
        """The map from the body's landmarks to ``camera``'s joints (its simulated camera);
        for a body format, the identity."""
        if not camera.body:
            return cls.to_body(camera)
        body = skeleton_format(camera.body)
        weights, uncertainty = _matrix(
            camera.simulate, camera.joints, body, f"{camera.name}: simulate"
        )
        return cls(body, camera, weights, uncertainty)


@cache
def landmark_map(camera: SkeletonFormat) -> LandmarkMap:
    """:meth:`LandmarkMap.to_body` of ``camera``, built once per process and format."""
    return LandmarkMap.to_body(camera)


def camera_frame(
    camera: str | SkeletonFormat, joints: object, confidence: object = None
) -> tuple[np.ndarray, np.ndarray]:
    """A camera's frame checked: ``joints`` (J, 3) in the camera's units (an SDK's
    millimetres for ``k4abt``) and its ``confidence`` values (None: every joint tracked)
    as metres and tracking states; ``camera`` a format or its name.

    Raises
    ------
    InputError
        On a shape not the format's, a value that is not a real number, an infinite
        coordinate, a body no bigger than :data:`MIN_BODY_M` (metres given where the
        format says millimetres), or a confidence the format cannot have; the message
        names the format and the joint.
    """
    fmt = skeleton_format(camera)
    raw = as_array(joints, (fmt.n_joints, 3), f"joints ({fmt.title})", finite=False)
    j = check_joints(raw * fmt.unit_m, skeleton=fmt)
    usable = np.isfinite(j).all(axis=1)
    if usable.sum() >= 3 and np.ptp(j[usable], axis=0).max() < MIN_BODY_M:
        raise InputError(
            f"joints ({fmt.title}) span {np.ptp(j[usable], axis=0).max():.3g} m: no body is "
            f"that small; {fmt.name} joints are in {UNIT_NAMES[fmt.unit_m]}",
            name="joints",
            value=joints,
        )
    if confidence is None:
        return j, np.full(fmt.n_joints, 2, dtype=np.int8)
    from_camera = as_array(confidence, (fmt.n_joints,), f"confidence ({fmt.title})", finite=False)
    # an SDK gives no confidence (NaN) for a joint it did not detect (NaN): not tracked
    undetected = ~usable & np.isnan(from_camera)
    values = np.where(undetected, fmt.confidence.range[0], from_camera)
    try:
        states = fmt.confidence.states(values)
    except (ValueError, TypeError) as exc:
        bad = _first_bad(fmt, values)
        raise InputError(
            f"confidence of {fmt.joints[bad]} ({fmt.title}) is "
            f"{float(values[bad])!r}: {exc}; expected {fmt.confidence.describe()}",
            name="confidence",
            value=from_camera,
        ) from None
    states[undetected] = 0
    return j, states


def _first_bad(camera: SkeletonFormat, values: np.ndarray) -> int:
    for k, v in enumerate(values):
        try:
            camera.confidence.states(np.array([v]))
        except (ValueError, TypeError):
            return k
    return 0


def body_frame(
    camera: str | SkeletonFormat, joints: object, confidence: object = None
) -> HumanFrame:
    """The body's landmarks from one frame of ``camera`` (module docstring): joints in the
    camera's units, its own confidence values (None: all tracked)."""
    fmt = skeleton_format(camera)
    j, state = camera_frame(fmt, joints, confidence)
    return landmark_map(fmt).map(j, state)
