"""The replay of a run as one self-contained HTML file, on MeshCat's viewer.

MeshCat (``meshcat``, the viewer of ``pinocchio.visualize.MeshcatVisualizer``) draws the
scene: its three.js bundle is copied into the page, its Python classes build the objects
(unit cylinders and spheres, lines, the arm's collision objects: its meshes as the
vertices and triangles coal loaded, its primitives as MeshCat's shapes of their size;
the floor) and its command format places them. Chosen over
viser because MeshCat's viewer is one JavaScript file that runs from a page with no
server, which is what "opens offline from a file" needs; viser's client expects its
server or a hosted build. The page adds a panel (time slider, play/pause, speed, the
numbers of the tick shown) and moves the objects from the arrays of
:func:`~qpavoid.output.view_data.replay_data`.

The page refers to no network address: the bundle's two (the XHTML namespace, spelled
out as a URL, and the websocket of a live MeshCat server, unused here) are rewritten,
and :func:`replay_html` refuses to write a page in which any ``://`` remains.
"""

from __future__ import annotations

import base64
import json
import uuid
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np

from qpavoid.arm.model import load_robot
from qpavoid.core.errors import InputError
from qpavoid.output.arm_shapes import ArmPart
from qpavoid.output.replay_page import PAGE
from qpavoid.output.run_files import load_log
from qpavoid.output.view_data import replay_data

__all__ = [
    "available",
    "encode",
    "page_data",
    "replay_html",
    "replay_title",
    "scene_commands",
    "viewer_script",
    "write_html",
    "write_replay",
]

#: The bundle's network references and what replaces them (an expression of the page's
#: own namespace; no server to connect to).
_REWRITES = (
    ('"http://www.w3.org/1999/xhtml"', "document.documentElement.namespaceURI"),
    ("`ws://${location.host}`", '""'),
)
#: What every network address (http://, ws://, file://, ...) contains; base64 never does.
_ADDRESS = "://"

#: Thickness of the floor's box, m (thin: a plane that MeshCat draws from both sides).
FLOOR_THICKNESS_M = 0.01
#: How far the floor's top lies below z = 0, m (1 mm: MeshCat's own grid, at z = 0, stays
#: visible on top of it instead of flickering with it).
FLOOR_BELOW_M = 0.001
#: Colours (RGB) of the scene.
COLOURS = {
    "link": 0x8A8F98,
    "arm": 0xC9CDD3,
    "floor": 0xD8C8A8,
    "robot": 0xFF8C1A,
    "human": 0x2F6FE0,
    "path": 0x20A080,
    "trace": 0xC020C0,
    "ee": 0x202020,
    "free": 0x2AA02A,
    "repulsion active": 0xFFB000,
    "within the stop distance": 0xE01010,
}


def available() -> bool:
    """True if meshcat (the extra ``view``) can be imported."""
    try:
        import meshcat  # noqa: F401
    except ImportError:
        return False
    return True


def viewer_script() -> str:
    """MeshCat's viewer bundle, with its network references rewritten (module docstring).

    Raises
    ------
    InputError
        If meshcat is not installed (``pip install 'qpavoid[view]'``) or its bundle is not
        the one these rewrites know.
    """
    try:
        bundle = resources.files("meshcat") / "viewer" / "dist" / "main.min.js"
        script = bundle.read_text(encoding="utf-8")
    except (ModuleNotFoundError, FileNotFoundError) as exc:
        raise InputError(
            "the replay needs MeshCat's viewer: pip install 'qpavoid[view]'",
            name="meshcat",
            value=str(exc),
        ) from None
    for old, new in _REWRITES:
        script = script.replace(old, new)
    at = script.find(_ADDRESS)
    if at >= 0:
        raise InputError(
            "this meshcat's viewer refers to a network address the replay cannot rewrite: "
            f"{script[max(at - 20, 0) : at + 20]!r}; use meshcat 0.3.2",
            name="meshcat",
            value=script[max(at - 20, 0) : at + 20],
        )
    return script


#: MeshCat's cylinder has its axis along y (three.js), coal's along z: the rotation about x
#: by +90° that takes y to z.
_Y_TO_Z = np.array([[1.0, 0, 0, 0], [0, 0, -1.0, 0], [0, 1.0, 0, 0], [0, 0, 0, 1.0]])


def _translation(z: float) -> np.ndarray:
    """(4, 4) a translation by ``z`` along z, m."""
    out = np.eye(4)
    out[2, 3] = z
    return out


def part_objects(part: ArmPart) -> list[tuple[str, Any, np.ndarray]]:
    """MeshCat geometries of one collision object, each with its matrix in the frame of
    the joint that carries it (a capsule is a cylinder and two spheres): (name, geometry,
    (4, 4) matrix)."""
    import meshcat.geometry as g

    m = part.placement
    if part.shape == "mesh":
        return [(part.name, g.TriangularMeshGeometry(part.vertices, part.triangles), m)]
    if part.shape == "box":
        return [(part.name, g.Box(list(part.size)), m)]
    if part.shape == "sphere":
        return [(part.name, g.Sphere(part.size[0]), m)]
    radius, length = part.size
    out = [(f"{part.name}/body", g.Cylinder(length, radius), m @ _Y_TO_Z)]
    if part.shape == "capsule":
        for end, z in (("a", -length / 2), ("b", length / 2)):
            out.append((f"{part.name}/{end}", g.Sphere(radius), m @ _translation(z)))
    return out


def scene_commands(data: dict[str, Any]) -> list[str]:
    """MeshCat commands (msgpack, base64) that create every object of the replay.

    Shapes are unit cylinders (axis y, height 1, radius 1) and unit spheres that the page
    scales and places each frame; the arm's collision objects (``data["parts"]``) hang,
    each at its placement in its joint's frame, under ``robot/meshes/j<joint>``, which the
    page places at the joint's pose each frame; the floor is a thin box whose top is the
    plane z = 0 (:data:`FLOOR_BELOW_M` below it); the planned path and the end-effector
    trace are lines.
    """
    import meshcat.geometry as g
    import umsgpack
    from meshcat.commands import SetObject
    from meshcat.path import Path as MeshcatPath

    def solid(colour: int, opacity: float = 1.0, **extra: Any) -> Any:
        return g.MeshLambertMaterial(color=colour, opacity=opacity, **extra)

    objects: list[tuple[str, Any, Any]] = []
    matrices: dict[str, np.ndarray] = {}

    def capsule(path: str, colour: int, opacity: float) -> None:
        objects.append((f"{path}/body", g.Cylinder(1.0, 1.0), solid(colour, opacity)))
        for end in ("a", "b"):
            objects.append((f"{path}/{end}", g.Sphere(1.0), solid(colour, opacity)))

    x0, x1, y0, y1 = data["floor"]
    floor = g.Box([x1 - x0, y1 - y0, FLOOR_THICKNESS_M])
    objects.append(("floor", floor, solid(COLOURS["floor"], 0.35)))
    matrices["floor"] = _translation(-FLOOR_THICKNESS_M / 2 - FLOOR_BELOW_M)
    matrices["floor"][:2, 3] = [(x0 + x1) / 2, (y0 + y1) / 2]
    # the arm's own surfaces, drawn behind a safety shape of the same radius (no flicker)
    arm = solid(COLOURS["arm"], polygonOffset=True, polygonOffsetFactor=1, polygonOffsetUnits=1)
    for part in data.get("parts", ()):
        for name, geometry, matrix in part_objects(part):
            path = f"robot/meshes/j{part.joint}/{name}"
            objects.append((path, geometry, arm))
            matrices[path] = matrix
    for i in range(data["links"].shape[1] - 1):
        objects.append((f"robot/link{i}", g.Cylinder(1.0, 1.0), solid(COLOURS["link"])))
    spheres = data["method"] == "spheres"
    for i in range(data["robot"].shape[1]):
        if spheres:
            objects.append((f"robot/shapes/{i}", g.Sphere(1.0), solid(COLOURS["robot"], 0.45)))
        else:
            capsule(f"robot/shapes/{i}", COLOURS["robot"], 0.45)
    for i in range(data["human"].shape[1]):
        if spheres:
            objects.append((f"human/shapes/{i}", g.Sphere(1.0), solid(COLOURS["human"], 0.6)))
        else:
            capsule(f"human/shapes/{i}", COLOURS["human"], 0.6)
    for s in range(len(data["set_names"])):
        for k, state in enumerate(data["pair_states"]):
            objects.append((f"pairs/set{s}/{k}", g.Cylinder(1.0, 1.0), solid(COLOURS[state])))
    objects.append(("robot/ee", g.Sphere(1.0), solid(COLOURS["ee"])))
    for name in ("path", "trace"):
        points = np.asarray(data[name], dtype=np.float32)
        points = points[np.isfinite(points).all(axis=1)].T
        if points.shape[1] < 2:  # a live view's start: no path yet
            continue
        line = g.Line(g.PointsGeometry(points), g.LineBasicMaterial(color=COLOURS[name]))
        objects.append((name, line, None))
    out = []
    for path, geometry, material in objects:
        cmd = SetObject(geometry, material, MeshcatPath(("qpavoid", *path.split("/"))))
        # the same page for the same run: ids from the path, not MeshCat's clock-based ones
        obj = cmd.object
        for part in ("object", "geometry", "material"):
            element = obj if part == "object" else getattr(obj, part)
            element.uuid = str(uuid.uuid5(uuid.NAMESPACE_OID, f"qpavoid/{path}/{part}"))
        lowered = cmd.lower()
        if path in matrices:  # three.js reads a matrix column by column
            lowered["object"]["object"]["matrix"] = matrices[path].flatten(order="F").tolist()
        out.append(base64.b64encode(umsgpack.packb(lowered)).decode("ascii"))
    return out


def encode(value: Any) -> Any:
    """JSON for the page: arrays as ``{"dtype", "shape", "b64"}`` (NaN kept)."""
    if isinstance(value, np.ndarray):
        kind = {"f": "float32", "i": "int32", "u": "int32", "b": "int32"}[value.dtype.kind]
        if value.dtype == np.float64:
            kind = "float64"
        array = np.ascontiguousarray(value, dtype=kind)
        return {
            "dtype": kind,
            "shape": list(array.shape),
            "b64": base64.b64encode(array.tobytes()).decode(),
        }
    if isinstance(value, dict):
        return {k: encode(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [encode(v) for v in value]
    return value


def page_data(data: dict[str, Any]) -> dict[str, Any]:
    """``data`` as the page's numbers: without the collision objects, which the page gets
    as scene objects (:func:`scene_commands`)."""
    return {key: value for key, value in data.items() if key != "parts"}


def replay_html(data: dict[str, Any], title: str, live: bool = False) -> str:
    """The replay page of ``data`` (:func:`~qpavoid.output.view_data.replay_data`); ``live``: the
    page of :class:`~qpavoid.output.live_view.LiveView`, which asks its server for each tick.

    Raises
    ------
    InputError
        If the page would refer to a network address (never expected: a safeguard).
    """
    payload = json.dumps(encode(page_data(data)), separators=(",", ":"), allow_nan=False)
    html = (
        PAGE.replace("{{TITLE}}", json.dumps(title)[1:-1].replace("<", "&lt;"))
        .replace("{{VIEWER}}", viewer_script())
        .replace("{{SCENE}}", json.dumps(scene_commands(data)))
        .replace("{{DATA}}", payload)
        .replace("{{COLOURS}}", json.dumps(COLOURS))
        .replace("{{LIVE}}", json.dumps(live))
    )
    at = html.find(_ADDRESS)
    if at >= 0:
        around = html[max(at - 20, 0) : at + 20]
        raise InputError(
            f"the replay page would refer to a network address ({around!r})",
            name="replay.html",
            value=around,
        )
    return html


def write_html(path: str | Path, html: str) -> Path:
    """Write ``html`` to ``path`` (UTF-8); the path."""
    out = Path(path)
    out.write_text(html, encoding="utf-8")
    return out


def write_replay(run_dir: str | Path, out: str | Path | None = None) -> Path:
    """Write the replay of the run in ``run_dir`` (``RUN_DIR/replay.html`` by default).

    Raises
    ------
    InputError, RecordingError
        If ``run_dir`` holds no readable run, or meshcat is missing.
    """
    folder = Path(run_dir)
    try:
        metrics = json.loads((folder / "metrics.json").read_text())
    except (OSError, ValueError) as exc:
        raise InputError(
            f"{str(folder)!r} is not a run folder (no readable metrics.json: {exc})",
            name="RUN_DIR",
            value=str(folder),
        ) from None
    if not isinstance(metrics, dict):
        raise InputError(
            f"{str(folder)!r}: metrics.json must hold an object, not {type(metrics).__name__}",
            name="RUN_DIR",
            value=str(folder),
        )
    log = load_log(folder)
    locked = () if metrics.get("redundant") else None  # A3 free in a redundant run
    robot = load_robot(str(metrics.get("robot", "iiwa14")), locked=locked)
    data = replay_data(log, metrics, robot)
    title = replay_title(metrics, folder.name)
    return write_html(out or folder / "replay.html", replay_html(data, title))


def replay_title(metrics: dict[str, Any], fallback: str) -> str:
    """The page title of a run's replay."""
    what = metrics.get("scenario") or fallback
    method = metrics.get("distance_method")
    return f"qpavoid: {what}, {metrics.get('controller')} controller, {method}"
