"""MediaPipe Pose landmarks lifted to metric 3D with an aligned depth image.

MediaPipe's image landmarks are ``x, y`` normalised by the image's width ``W`` and height
``H``, and ``z_rel``, a depth relative to the hips' midpoint in the scale of ``x`` (smaller
is closer); its world landmarks are hip-centred, not placed in the camera. With a depth
image aligned to the colour image (metres; 0 or NaN: no depth) and the colour camera's
pinhole :class:`Intrinsics`, :func:`lift_landmarks` returns each landmark in the camera's
optical frame (x right, y down, z forward, m) with a state: 0 not tracked (NaN), 1
inferred, 2 tracked.

Math
----
Pixel coordinates (OpenCV's convention: pixel centres at integers, as ``cx, cy``) are
``u = x W`` and ``v = y H``; the ray through them is ``r = ((u - cx)/fx, (v - cy)/fy, 1)``
and the point at depth ``z`` is ``z r``: ``X = (u - cx) z / fx``, ``Y = (v - cy) z / fy``,
``Z = z``. The landmark samples pixel ``(round(v), round(u))``; a landmark with ``x`` or
``y`` outside ``[0, 1)`` is not tracked.

1. **Surface depth** ``d``: the median of the valid depths (finite, in ``[min_depth_m,
   max_depth_m]``) in the ``(2 window_px + 1)²`` window around the pixel; none: state 0.
2. **Measured centre**: the joint centre lies ``s = surface_offset_m`` behind the surface
   along the ray: ``z_meas = d + s / |r|`` (exact for a sphere or a cylinder of radius
   ``s`` seen across its axis).
3. **Reference**: MediaPipe's ``z_rel`` is in units of ``x``; at the hips' depth ``Z_ref``
   one unit of ``x`` is ``W Z_ref / fx`` metres (what the torso's metric size over its
   normalised size measures, under MediaPipe's weak perspective), so a landmark's expected
   centre depth is ``z_exp = Z_ref (1 + k z_rel)``, ``k = W / fx``. Each reference landmark
   (``reference_indices``: shoulders and hips) with a measured centre and enough visibility
   gives ``Z_ref = z_meas / (1 + k z_rel)``; their median is ``Z_ref`` (one occluded
   reference in four does not move it). ``Z_ref`` comes from measured depth only.
4. **Occlusion**: ``e = z_meas - z_exp``. ``|e| <= tracked_tolerance_m`` (the format's
   Z_d, 0.05 m): *tracked* at ``z_meas``. Up to the tolerances below: *inferred* at
   ``z_meas`` (the truth is at ``z_meas`` or, behind an occluder, near ``z_exp``: within
   the perception's inferred uncertainty of it either way). ``e < -occlusion_tolerance_m``:
   the surface is in front of the landmark (an arm, an object): hidden.
   ``e > background_tolerance_m``: the
   depth is behind it (a hole to the background, e.g. between fingers): not trusted. Both
   are *inferred* at ``z_exp`` along the landmark's ray, never at the measured depth. A
   ``z_exp`` outside the depth range (an implausible ``z_rel``) is no estimate: the
   landmark is lost. Without a reference (no torso landmark measured) a measured landmark
   cannot be checked: inferred at ``z_meas``.
5. **Visibility** (optional): its state by the format's ``[confidence]`` thresholds
   (``formats/mediapipe_pose.toml``: tracked from 0.5, inferred from 0.1) caps the
   landmark's.

The landmarks are those of a skeleton format (MediaPipe Pose's by default): its torso
joints (shoulders and hips) are the reference and its confidence the visibility's reading.
The result is a frame of that format, in metres in the camera frame: calibrated by the
calibration file (the sensor's ``format = "mediapipe_pose"``) or given to
:meth:`~qpavoid.control.controller.Controller.step` with ``camera_format``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from qpavoid.core.checks import as_array
from qpavoid.core.errors import InputError
from qpavoid.human.landmarks import skeleton_format
from qpavoid.human.skeleton import INFERRED, NOT_TRACKED, TRACKED, SkeletonFormat

__all__ = ["MEDIAPIPE_POSE", "Intrinsics", "LiftConfig", "lift_landmarks"]

#: Largest window half-size, px: 101 x 101 pixels is a body at 2 m, not a landmark.
MAX_WINDOW_PX = 50
#: MediaPipe Pose's skeleton format (``formats/mediapipe_pose.toml``).
MEDIAPIPE_POSE = skeleton_format("mediapipe_pose")


@dataclass(frozen=True)
class Intrinsics:
    """A pinhole camera (the colour camera the depth image is aligned to), in pixels.

    Attributes
    ----------
    fx, fy
        Focal lengths, px (positive).
    cx, cy
        Principal point, px (OpenCV's convention), inside ``[0, width] x [0, height]``.
    width, height
        Image size, px (positive whole numbers).
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    def __post_init__(self) -> None:
        for name in ("width", "height", "fx", "fy", "cx", "cy"):  # sizes first: cx, cy need them
            v, whole = getattr(self, name), name in ("width", "height")
            size = {"cx": self.width, "cy": self.height}.get(name)
            ok = isinstance(v, (int, float, np.integer, np.floating)) and not isinstance(v, bool)
            ok = ok and bool(np.isfinite(v)) and (not whole or float(v).is_integer())
            if not (ok and (0 <= v <= size if size is not None else v > 0)):
                want = (
                    "positive" + (" and whole" if whole else "") if size is None else "in the image"
                )
                raise InputError(f"{name} must be {want}, px, got {v!r}", name=name, value=v)
            object.__setattr__(self, name, int(v) if whole else float(v))

    def project(self, points: object) -> np.ndarray:
        """Normalised image coordinates (N, 2) of ``points`` (N, 3), m, camera frame.

        The inverse of the back-projection: ``x = (fx X / Z + cx) / W``, ``y = (fy Y / Z +
        cy) / H``; rows with NaN or ``Z <= 0`` give NaN.
        """
        p = as_array(points, (None, 3), "points (camera frame, m)", finite=False)
        with np.errstate(divide="ignore", invalid="ignore"):
            z = np.where((p[:, 2] > 0) & np.isfinite(p).all(axis=1), p[:, 2], np.nan)
            x = (self.fx * p[:, 0] / z + self.cx) / self.width
            y = (self.fy * p[:, 1] / z + self.cy) / self.height
        return np.stack((x, y), axis=1)


@dataclass(frozen=True)
class LiftConfig:
    """How landmarks are lifted (module docstring); the defaults' reasons.

    Attributes
    ----------
    window_px
        Half-size of the window whose valid depths' median is the surface depth: 2 (a 5 x 5
        window) survives holes and flying pixels at edges, and at 3 m with a 600 px focal
        length spans ±1 cm, inside a wrist (radius ~3 cm) seen face-on.
    surface_offset_m
        Joint centre's distance behind the visible surface, one value or one per landmark:
        0.04 m, the mean radius of the arm (upper arm ~4.5 cm, forearm ~3.5 cm, wrist ~3
        cm), the part that comes near the robot. Face landmarks lie on the surface (0).
    tracked_tolerance_m
        How far the measured depth may be from the expected one for a *tracked* landmark,
        m; None (the default): the format's ``sensor.tracked_uncertainty_m`` (0.05 m), the
        error speed and separation counts for a tracked joint. Beyond it the landmark is
        at most inferred: an occluder nearer than that to the landmark is within Z_d.
    occlusion_tolerance_m
        How much nearer than expected the surface may be before the landmark counts as
        hidden (inferred at the expected depth): 0.10 m, the perception's uncertainty of
        an inferred joint (``PerceptionConfig.inferred_uncertainty_m``), so that an
        inferred landmark at the measured depth is within it of the truth. MediaPipe's
        relative depth errs by about as much on limbs: an unoccluded limb often counts as
        inferred (the price of a monocular reference; an adversarial tester's occluder
        0.1-0.2 m in front of a wrist was taken as tracked at 0.2 m).
    background_tolerance_m
        How much farther than expected the depth may be before it counts as a hole through
        to the background: 0.10 m, as above.
    min_depth_m, max_depth_m
        The depth camera's valid range: 0.3-5.0 m, the RGB-D cameras of a robot cell
        (Kinect v2: 0.5-4.5 m; RealSense D4xx: ~0.3 m near, several cm of noise past 5 m).
    reference_indices
        Landmarks whose measured depth gives the reference; None (the default): the
        format's torso joints (MediaPipe's shoulders and hips: the most rigid and most
        often visible).
    """

    window_px: int = 2
    tracked_tolerance_m: float | None = None
    surface_offset_m: float | tuple[float, ...] = 0.04
    occlusion_tolerance_m: float = 0.10
    background_tolerance_m: float = 0.10
    min_depth_m: float = 0.3
    max_depth_m: float = 5.0
    reference_indices: tuple[int, ...] | None = None

    def __post_init__(self) -> None:
        def bad(name: str, want: str) -> InputError:
            v = getattr(self, name)
            return InputError(f"{name} must be {want}, got {v!r}", name=name, value=v)

        if isinstance(self.window_px, bool) or not isinstance(self.window_px, (int, np.integer)):
            raise bad("window_px", "a whole number of pixels")
        if not 0 <= self.window_px <= MAX_WINDOW_PX:
            raise bad("window_px", f"in [0, {MAX_WINDOW_PX}] px")
        offsets = np.atleast_1d(np.asarray(self.surface_offset_m, dtype=float))
        if offsets.ndim != 1 or not (np.isfinite(offsets).all() and (offsets >= 0).all()):
            raise bad("surface_offset_m", "finite and >= 0, m (one value or one a landmark)")
        if self.tracked_tolerance_m is not None and not (
            np.isfinite(self.tracked_tolerance_m)
            and 0
            < self.tracked_tolerance_m
            <= min(self.occlusion_tolerance_m, self.background_tolerance_m)
        ):
            raise bad("tracked_tolerance_m", "positive, m, and at most the other tolerances")
        for name in ("occlusion_tolerance_m", "background_tolerance_m"):
            if not (np.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise bad(name, "positive, m")
        if not 0 <= self.min_depth_m < self.max_depth_m < np.inf:
            raise bad("max_depth_m", f"finite and above min_depth_m={self.min_depth_m!r}")
        if self.reference_indices is not None and not all(
            isinstance(i, (int, np.integer)) and i >= 0 for i in self.reference_indices
        ):
            raise bad("reference_indices", "landmark indices (>= 0)")


def lift_landmarks(
    image_xy: object,
    z_rel: object,
    depth: object,
    intrinsics: Intrinsics,
    cfg: LiftConfig = LiftConfig(),  # frozen, hence shareable
    visibility: object = None,
    skeleton: SkeletonFormat = MEDIAPIPE_POSE,
) -> tuple[np.ndarray, np.ndarray]:
    """Landmarks in the camera's optical frame, m, and their states (module docstring).

    Parameters
    ----------
    image_xy
        (J, 2) MediaPipe image landmarks' ``x, y``, normalised by the image size; finite.
    z_rel
        (J,) their relative depth (``x``'s scale, origin at the hips' midpoint).
    depth
        (H, W) depth image aligned to the colour image, m; 0 or NaN: no depth.
    intrinsics
        The colour camera's; its size must be the depth image's.
    cfg
        Window, offsets, tolerances, depth range, visibility thresholds.
    visibility
        (J,) MediaPipe's visibility in [0, 1] (or min(visibility, presence)), or None
        (all visible).
    skeleton
        The landmarks' format: its torso is the reference (unless
        ``cfg.reference_indices``), its confidence reads ``visibility``.

    Returns
    -------
    joints
        (J, 3) float64, m, optical frame; NaN rows where the state is 0.
    states
        (J,) int8: 0 not tracked, 1 inferred, 2 tracked.

    Raises
    ------
    InputError
        A wrong shape, NaN in ``image_xy``/``z_rel``/``visibility``, a depth image not 2-D,
        of integers (millimetres?), of another size than ``intrinsics``' or negative, or a
        ``cfg`` (offsets, reference indices) that does not fit J landmarks.
    """
    xy = as_array(image_xy, (None, 2), "image_xy (normalised image landmarks)")
    J = len(xy)
    if cfg.reference_indices is None and skeleton.n_joints != J:
        raise InputError(
            f"image_xy must have shape ({skeleton.n_joints}, 2), one row per landmark of "
            f"{skeleton.title}, got {xy.shape}",
            name="image_xy",
            value=xy,
        )
    zr = as_array(z_rel, (J,), "z_rel (relative depth)")
    if getattr(depth, "dtype", np.dtype(float)).kind in "iu":  # millimetres, most likely
        raise InputError("depth must be float metres (uint16 in mm: / 1000)", name="depth")
    d = as_array(depth, (None, None), "depth (depth image, m)", finite=False)
    W, H = intrinsics.width, intrinsics.height
    if d.shape != (H, W):
        msg = f"depth must have the intrinsics' size ({H}, {W}), got {d.shape}"
        raise InputError(msg, name="depth", value=d)
    if (d < 0).any():
        raise InputError("depth has negative depths (m; 0 or NaN: no depth)", name="depth", value=d)
    vis = np.ones(J) if visibility is None else as_array(visibility, (J,), "visibility")
    if ((vis < 0) | (vis > 1)).any():
        raise InputError("visibility must be in [0, 1]", name="visibility", value=vis)
    offset = np.asarray(cfg.surface_offset_m, dtype=float)
    ref = np.asarray(
        skeleton.torso_ids if cfg.reference_indices is None else cfg.reference_indices, dtype=int
    )
    if (offset.ndim == 1 and offset.shape != (J,)) or (ref >= J).any():
        msg = f"cfg does not fit {J} landmarks (surface_offset_m length, reference_indices)"
        raise InputError(msg, name="cfg", value=cfg)

    u, v = xy[:, 0] * W, xy[:, 1] * H
    inside = ((xy >= 0) & (xy < 1)).all(axis=1)
    col = np.clip(np.rint(u), 0, W - 1).astype(np.intp)
    row = np.clip(np.rint(v), 0, H - 1).astype(np.intp)
    steps = np.arange(-cfg.window_px, cfg.window_px + 1)
    rr = (row[:, None, None] + steps[None, :, None]).repeat(len(steps), axis=2).reshape(J, -1)
    cc = (col[:, None, None] + steps[None, None, :]).repeat(len(steps), axis=1).reshape(J, -1)
    in_img = (rr >= 0) & (rr < H) & (cc >= 0) & (cc < W)
    vals = d[np.clip(rr, 0, H - 1), np.clip(cc, 0, W - 1)]
    valid = in_img & (vals >= cfg.min_depth_m) & (vals <= cfg.max_depth_m)  # NaN: False
    vals = np.sort(np.where(valid, vals, np.inf), axis=1)  # valid depths first
    n = valid.sum(axis=1)
    rows = np.arange(J)
    median = 0.5 * (vals[rows, np.maximum(n - 1, 0) // 2] + vals[rows, n // 2])
    surface = np.where(inside & (n > 0), median, np.nan)

    x_ray, y_ray = (u - intrinsics.cx) / intrinsics.fx, (v - intrinsics.cy) / intrinsics.fy
    rays = np.stack((x_ray, y_ray, np.ones(J)), axis=1)
    z_meas = surface + offset / np.linalg.norm(rays, axis=1)
    scale = 1.0 + (W / intrinsics.fx) * zr  # z_exp / Z_ref
    seen = skeleton.confidence.states(vis)  # the visibility's own state
    use = np.isfinite(z_meas[ref]) & (seen[ref] == TRACKED) & (scale[ref] > 0)
    z_ref = float(np.median(z_meas[ref][use] / scale[ref][use])) if use.any() else np.nan
    z_exp = np.where(scale > 0, z_ref * scale, np.nan)

    z_exp = np.where((z_exp >= cfg.min_depth_m) & (z_exp <= cfg.max_depth_m), z_exp, np.nan)
    measured, checkable = np.isfinite(z_meas), np.isfinite(z_exp)
    referenced = np.isfinite(z_ref)
    err = np.where(measured & checkable, z_meas - z_exp, 0.0)
    hidden = measured & ((err < -cfg.occlusion_tolerance_m) | (err > cfg.background_tolerance_m))
    agree = np.abs(err) <= (
        skeleton.sensor.tracked_uncertainty_m
        if cfg.tracked_tolerance_m is None
        else cfg.tracked_tolerance_m
    )
    tracked = measured & checkable & agree
    z = np.where(hidden, z_exp, np.where(measured, z_meas, np.nan))
    states = np.where(tracked, TRACKED, np.where(measured, INFERRED, NOT_TRACKED))
    # a reference, but no plausible expected depth: the relative depth is garbage
    states = np.where(referenced & ~checkable, NOT_TRACKED, states)
    states = np.minimum(states, seen).astype(np.int8)
    z = np.where(states == NOT_TRACKED, np.nan, z)
    return rays * z[:, None], states
