"""A body model's parts, and its parts and centres checked against their skeleton format.

A :class:`BodyPart` is a chain of a format's joints covered by spheres and a capsule (its
radii, between a finger's :data:`MIN_RADIUS_M` and :data:`MAX_RADIUS_M`), with a mid-point,
the joints it must reach (a hand's fingers) and its ISO/TS 15066 body region. A model's
centres are points that are the mean of two or more of the format's joints. The checks
here are the model's (:class:`~qpavoid.human.body.BodyModel` runs them when built): names,
radii and regions (:func:`check_parts`), every joint one of the format's or a centre
(:func:`joint_id`), the centres (:func:`centre_joints`), and every joint the parts use in
one tree of the format's parents (:func:`check_one_tree`). Each refusal is a
:class:`~qpavoid.core.errors.SkeletonFormatError` naming the key and the offending value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from qpavoid.core.errors import SkeletonFormatError
from qpavoid.human.skeleton import SkeletonFormat

__all__ = [
    "MAX_RADIUS_M",
    "MIN_RADIUS_M",
    "BodyPart",
    "Joint",
    "centre_joints",
    "check_one_tree",
    "check_parts",
    "joint_id",
]

#: A joint of a part: its name in the skeleton format, or its id (row).
Joint = str | int
#: A part's radius, m: a finger is 1 cm thick; a capsule over 1 m wide covers no body part.
MIN_RADIUS_M, MAX_RADIUS_M = 0.01, 1.0


@dataclass(frozen=True)
class BodyPart:
    """One part of an upper-body model.

    Attributes
    ----------
    name
        Part name.
    chain
        Joints along the part, proximal first (names in the skeleton format, or ids). The
        capsule runs between the first and the last usable joint of the chain.
    mid
        The two joints whose mid-point is the part's extra point (paper Fig. 3).
    sphere_radius_m
        Radius r_j of the part's spheres (eq. 1), m.
    capsule_radius_m
        Radius of the part's capsule (exact method), m.
    reach
        Joints beyond the chain that the capsule must cover (a hand's HandTip and Thumb):
        the capsule is widened, each frame, by how far they stick out of it.
    moves_with_body
        The part moves with the body, not the arm (the head and trunk of a seated
        person): speed and separation monitoring gives it the body's approach speed.
        Default False: an arm's part, the faster case.
    region
        The ISO/TS 15066 Annex A body region the part is (a name of
        ``qpavoid/laws/body_regions.toml``, e.g. ``"hand_finger"``): power and force limiting
        takes its limits from it (:mod:`qpavoid.laws.pfl`). None (the default): no region.
    """

    name: str
    chain: tuple[Joint, ...]
    mid: tuple[Joint, Joint]
    sphere_radius_m: float
    capsule_radius_m: float
    reach: tuple[Joint, ...] = ()
    moves_with_body: bool = False
    region: str | None = None


def check_parts(parts: tuple[BodyPart, ...]) -> None:
    """The parts' own checks: some parts, each with a distinct non-empty name, radii in
    [:data:`MIN_RADIUS_M`, :data:`MAX_RADIUS_M`], a region that is text or absent, a chain
    and two mid joints (:class:`SkeletonFormatError` naming the part and the key)."""
    if not parts:
        raise SkeletonFormatError("a body model needs parts", name="parts", value=parts)
    names = [p.name for p in parts]
    for p in parts:
        if not isinstance(p.name, str) or not p.name.strip():
            raise SkeletonFormatError(
                f"a part's name must be a non-empty string, got {p.name!r}",
                name="parts",
                value=p.name,
            )
        if names.count(p.name) > 1:
            raise SkeletonFormatError(f"two parts are called {p.name!r}", name="parts", value=names)
        for key in ("sphere_radius_m", "capsule_radius_m"):
            r = getattr(p, key)
            if not isinstance(r, (int, float)) or isinstance(r, bool) or not r > 0:
                raise SkeletonFormatError(
                    f"part {p.name!r}: {key} must be a number > 0, m, got {r!r}",
                    name=f"{p.name}.{key}",
                    value=r,
                )
            if not math.isfinite(r):
                raise SkeletonFormatError(
                    f"part {p.name!r}: {key} is {r!r}", name=f"{p.name}.{key}", value=r
                )
            if not MIN_RADIUS_M <= r <= MAX_RADIUS_M:
                raise SkeletonFormatError(
                    f"part {p.name!r}: {key} must be between {MIN_RADIUS_M} and "
                    f"{MAX_RADIUS_M} m (a body part's), got {r!r}",
                    name=f"{p.name}.{key}",
                    value=r,
                )
        if p.region is not None and (not isinstance(p.region, str) or not p.region.strip()):
            raise SkeletonFormatError(
                f"part {p.name!r}: region must name a body region (text) or be absent, "
                f"got {p.region!r}",
                name=f"{p.name}.region",
                value=p.region,
            )
        if not p.chain or len(p.mid) != 2:
            raise SkeletonFormatError(
                f"part {p.name!r} needs a chain of joints and two mid joints, got chain "
                f"{p.chain!r} and mid {p.mid!r}",
                name=f"{p.name}.chain",
                value=(p.chain, p.mid),
            )


def joint_id(
    skeleton: SkeletonFormat,
    centres: tuple[tuple[str, tuple[Joint, ...]], ...],
    joint: Joint,
    key: str,
    with_centres: bool = True,
) -> int:
    """The id of ``joint`` (a name or an id) in ``skeleton``, a centre's (after the
    format's joints; only ``with_centres``), or :class:`SkeletonFormatError` naming
    ``key``."""
    if isinstance(joint, str) and joint in skeleton.joints:
        return skeleton.index(joint)
    names = [name for name, _ in centres]
    if with_centres and isinstance(joint, str) and joint in names:
        return skeleton.n_joints + names.index(joint)
    is_id = isinstance(joint, (int, np.integer)) and not isinstance(joint, bool)
    if is_id and 0 <= int(joint) < skeleton.n_joints:
        return int(joint)
    raise SkeletonFormatError(
        f"{key}: {joint!r} is not a joint of the {skeleton.name} format"
        + (f" nor a centre of the model ({names})" if with_centres and names else "")
        + f"; its joints are {list(skeleton.joints)}",
        name=key,
        value=joint,
    )


def centre_joints(
    skeleton: SkeletonFormat, centres: tuple[tuple[str, tuple[Joint, ...]], ...]
) -> np.ndarray:
    """(C, J) bool: the joints each of ``centres`` is the mean of, checked: a centre's name
    is no joint's nor another centre's, its joints two or more different joints of the
    format (not centres)."""
    names = [name for name, _ in centres]
    out = np.zeros((len(centres), skeleton.n_joints), dtype=bool)
    for c, (name, joints) in enumerate(centres):
        key = f"centres.{name}"
        if not isinstance(name, str) or not name.strip() or name in skeleton.joints:
            raise SkeletonFormatError(
                f"{key}: a centre needs a name that is no joint of the {skeleton.name} "
                f"format, got {name!r}",
                name=key,
                value=name,
            )
        if names.count(name) > 1:
            raise SkeletonFormatError(f"two centres are called {name!r}", name=key, value=names)
        ids = [joint_id(skeleton, centres, j, key, with_centres=False) for j in joints]
        if len(set(ids)) != len(ids):
            raise SkeletonFormatError(
                f"{key}: a joint is named twice in {list(joints)!r} (the mean weighs each "
                "joint once)",
                name=key,
                value=list(joints),
            )
        if len(set(ids)) < 2:
            raise SkeletonFormatError(
                f"{key}: a centre is the mean of two or more different joints, got "
                f"{list(joints)!r}",
                name=key,
                value=list(joints),
            )
        out[c, ids] = True
    return out


def check_one_tree(skeleton: SkeletonFormat, used: np.ndarray) -> None:
    """The joints the parts use (``used``, (J,) bool) are all in one tree of the format's
    parents: the tracker bounds a joint never seen by the nearest seen joint along the
    tree, and a joint in a tree of its own would be bounded by nothing (a part would
    shrink)."""
    roots: dict[str, str] = {}  # root: the first joint found in its tree
    for j in np.flatnonzero(used):
        r = int(j)
        while skeleton.parent[r] >= 0:
            if not skeleton.bone_bounds_m[r] > 0.0:  # a bone of unknown length
                raise SkeletonFormatError(
                    f"joint {skeleton.joints[r]!r} of the {skeleton.name} format has a "
                    "parent but no max_bone_m: a joint never seen through it would be "
                    "bounded by nothing (the body's parts use it)",
                    name="max_bone_m",
                    value=skeleton.joints[r],
                )
            r = int(skeleton.parent[r])
        roots.setdefault(skeleton.joints[r], skeleton.joints[int(j)])
    if len(roots) > 1:
        raise SkeletonFormatError(
            f"the body's joints are in {len(roots)} trees of the {skeleton.name} format "
            f"(rooted at {', '.join(roots)}): a joint never seen is bounded only by the "
            "seen joints of its tree; give the roots parents in the format file",
            name="parts",
            value=sorted(roots),
        )
