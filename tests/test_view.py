"""The browser replay: its numbers, its size, no network address, and a real browser."""

from __future__ import annotations

import base64
import io
import json
import re
import shutil
import signal
import socket
import subprocess
import time
from importlib import resources
from pathlib import Path
from urllib.request import urlopen

import numpy as np
import pinocchio as pin
import pytest
from conftest import PYTHON
from PIL import Image

import qpavoid
from qpavoid.arm.meshes import collision_geometry
from qpavoid.arm.roles import Roles
from qpavoid.cli.commands import main
from qpavoid.control.path import ArcPath
from qpavoid.experiments.runs import RunSpec, run_one
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.laws.avoidance import AvoidanceConfig
from qpavoid.output import view_data
from qpavoid.output.arm_shapes import arm_parts, reach_m
from qpavoid.output.live_view import LiveView, _one_tick
from qpavoid.output.replay_html import replay_html, write_replay
from qpavoid.output.run_files import load_log
from qpavoid.output.view_data import CAMERA_HALF_FOV_RAD, pair_states, replay_data
from qpavoid.scenarios.generated import nominal_configurations
from qpavoid.sensing.calibration import Calibration, SensorCalibration
from qpavoid.sensing.synthetic_pair import look_at

pytest.importorskip("meshcat", reason="the replay needs the extra 'view' (meshcat)")
umsgpack = pytest.importorskip("umsgpack", reason="meshcat's command format")

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
#: Headless Chromium as this machine runs it: no sandbox (root), software WebGL, and no
#: background connections (the network is closed).
CHROMIUM_ARGS = [
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--use-angle=swiftshader",
    "--enable-unsafe-swiftshader",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]


@pytest.fixture(scope="module")
def test2_run(tmp_path_factory):
    """The paper's Test 2 at 100 Hz, its first 5 s (the first stop is at 3.1 s), with its replay."""
    out = tmp_path_factory.mktemp("test2")
    run_one(RunSpec(scenario="test2", rate_hz=100.0, max_time_s=5.0), out, plots=False)
    return out


def test_pair_states_follow_the_paper_thresholds_by_hand(robot):
    cfg = AvoidanceConfig()
    # L1 stops where f = 0.8: d = ρ/2 (1 + ln(1/0.8 − 1)/α) = 0.05 (1 − 0.154) = 0.0423 m;
    # L2/EE stop at 0.05 m; repulsion is active below d(1 %) = ρ/2 (1 + ln 99 / 9)
    # = 0.0755 m for L1 (ρ = 0.1) and 0.151 m for L2, EE (ρ = 0.2)
    d = np.array(
        [
            [0.0420, 0.0499, 0.0500],  # all within the stop distance
            [0.0430, 0.0510, 0.1500],  # L1 just out: active; L2, EE active
            [0.0760, 0.1520, 0.3000],  # free
        ]
    )
    assert pair_states(d, cfg, robot.roles).tolist() == [[2, 2, 2], [1, 1, 1], [0, 0, 0]]
    # the same by role on a robot whose sets come in another order, with a fourth that
    # plays no part (it stops at contact and is repelled by nobody's law: eq. 4's shape)
    roles = Roles(scaled=2, scaled_joints=(), repelled=0, repelled_joints=(), end_effector=1)
    d4 = np.c_[d[:, [1, 2, 0]], [-0.001, 0.1, 0.16]]
    assert pair_states(d4, cfg, roles).tolist() == [[2, 2, 2, 2], [1, 1, 1, 1], [0, 0, 0, 0]]


def test_replay_data_is_the_log_tick_by_tick(test2_run, robot):
    log = load_log(test2_run)
    metrics = json.loads((test2_run / "metrics.json").read_text())
    data = replay_data(log, metrics, robot)
    n = len(log["t"])
    np.testing.assert_array_equal(data["t"], log["t"])
    np.testing.assert_allclose(data["distance"], log["distance"], rtol=1e-6)
    stopped = log["stopped"]
    assert stopped.any() and (data["stopped"] == stopped).all()
    shown = [data["reasons"][i] if i >= 0 else "" for i in data["reason"]]
    assert shown == list(log["stop_reason"]) and all(shown[k] for k in np.flatnonzero(stopped))
    # scene frames every 1/30 s at most, the first at tick 0, each a tick of the log
    ticks = data["frame_tick"]
    assert ticks[0] == 0 and np.all(np.diff(log["t"][ticks]) <= 1 / 30 + 1e-9)
    assert data["links"].shape == (len(ticks), robot.model.njoints + 1, 3)
    assert data["robot"].shape == (len(ticks), 3, 2, 3)  # capsules: the three sets
    assert len(data["reason"]) == n
    # the links end at the end effector the log recorded
    np.testing.assert_allclose(data["links"][:, -1], log["ee_pos"][ticks], atol=1e-5)


@pytest.mark.slow  # seconds of a subprocess or a browser: with the slow suite
def test_a_30_s_run_fits_in_4_mb_and_names_no_network_address(robot):
    """A 30 s run at 500 Hz, every tick stopped with its own reason (the worst case)."""
    n = 15000
    t = np.arange(n) / 500.0
    q = nominal_configurations(robot, ArcPath(), np.linspace(0.0, ArcPath().duration_s, n))
    rng = np.random.default_rng(0)
    joints = np.broadcast_to(np.array([0.5, 0.8, 0.2]), (n, 25, 3)) + rng.normal(0, 0.2, (n, 25, 3))
    log = {
        "t": t,
        "q": q,
        "joints": joints,
        "state": np.full((n, 25), 2, dtype=np.int8),
        "stopped": np.ones(n, dtype=bool),
        "stop_reason": np.array([f"f = {0.8 + k * 1e-5:.5f} > 0.8 (L1)" for k in range(n)]),
        "f": rng.uniform(0, 1, n),
        "distance": rng.uniform(0, 0.5, (n, 3)),
        "robot_point": rng.normal(0, 0.5, (n, 3, 3)),
        "human_point": rng.normal(0, 0.5, (n, 3, 3)),
        "ee_pos": rng.normal(0, 0.5, (n, 3)),
        "ee_ref": rng.normal(0, 0.5, (n, 3)),
        "frame_age_s": rng.uniform(0, 0.1, n),
        "true_distance": rng.uniform(0, 0.5, (n, 3)),
    }
    html = replay_html(replay_data(log, {"distance_method": "capsules"}, robot), "size")
    assert len(html.encode()) < 4e6  # 3.42 MB (3.21 MB before the arm's own shapes)
    assert "://" not in html and "<script src" not in html and "@import" not in html


def scene(html: str) -> dict[str, dict]:
    """The replay page's MeshCat commands that create objects, by path."""
    found = re.search(r"const SCENE = (\[.*?\]);\n", html)
    assert found is not None
    commands = json.loads(found.group(1))
    out = {}
    for text in commands:
        command = umsgpack.unpackb(base64.b64decode(text))
        out[command["path"]] = command["object"]
    return out


def unpacked(array: dict) -> np.ndarray:
    """A MeshCat buffer attribute as an (N, itemSize) array (float32 or uint32)."""
    dtype = {0x17: np.float32, 0x16: np.uint32}[array["array"].type]
    return np.frombuffer(array["array"].data, dtype=dtype).reshape(-1, array["itemSize"])


def pose_matrix(pose: np.ndarray) -> np.ndarray:
    """(4, 4) of a replay pose (quaternion x, y, z, w and translation)."""
    x, y, z, w, *t = (float(v) for v in pose)
    return pin.SE3(pin.Quaternion(w, x, y, z).normalized().matrix(), np.array(t)).homogeneous


def test_the_replay_places_each_collision_object_where_pinocchio_does(
    test2_run: Path, robot: qpavoid.Robot
) -> None:
    """The page puts joint j's group at the replay's pose and each object at its placement
    in that group: their product is Pinocchio's placement of the object (oMg), and a
    cylinder's axis (MeshCat's y) is the object's z."""
    log = load_log(test2_run)
    data = replay_data(log, {}, robot)
    objects = scene(replay_html(data, "objects"))
    geometry = collision_geometry(robot)
    gdata = geometry.createData()
    parts = arm_parts(robot)
    assert [p.name for p in parts] == [o.name for o in geometry.geometryObjects]
    mdata = robot.model.createData()
    for j in (0, len(data["frame_tick"]) // 2, len(data["frame_tick"]) - 1):
        q = log["q"][data["frame_tick"][j]]
        pin.updateGeometryPlacements(robot.model, mdata, geometry, gdata, q)
        for i, part in enumerate(parts):
            if part.joint == 0:
                group = np.eye(4)  # the base's objects never move
            else:
                group = pose_matrix(data["mesh_poses"][j, data["mesh_joints"].index(part.joint)])
            drawn = group @ part.placement
            np.testing.assert_allclose(drawn, gdata.oMg[i].homogeneous, atol=2e-6)
    for part in parts:  # the iiwa's: primitive cylinders, drawn as MeshCat's
        assert part.shape == "cylinder"
        obj = objects[f"/qpavoid/robot/meshes/j{part.joint}/{part.name}/body"]
        (geo,) = obj["geometries"]
        assert geo["type"] == "CylinderGeometry"
        assert (geo["radiusTop"], geo["height"]) == pytest.approx(part.size)
        matrix = np.reshape(obj["object"]["matrix"], (4, 4), order="F")
        np.testing.assert_allclose(matrix[:3, 1], part.placement[:3, 2], atol=1e-12)
        np.testing.assert_allclose(matrix[:3, 3], part.placement[:3, 3], atol=1e-12)


def box_stl(path: Path, half: np.ndarray) -> np.ndarray:
    """Write a binary STL of the box of half sides ``half`` (12 triangles); its corners."""
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)]) * half
    faces = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1)]
    faces += [(2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    body = b"".join(
        np.zeros(3, "<f4").tobytes() + corners[list(f)].astype("<f4").tobytes() + b"\0\0"
        for f in faces
    )
    path.write_bytes(b"\0" * 80 + np.uint32(len(faces)).tobytes() + body)
    return corners


def test_a_description_with_a_mesh_gets_its_mesh_in_the_replay(
    tmp_path: Path, robot: qpavoid.Robot
) -> None:
    """An iiwa whose link_2 is an STL box scaled by 0.5 in the URDF: the page holds that
    mesh, its vertices the file's times 0.5, as coal loaded it (8 corners, 12 triangles)."""
    src = resources.files("qpavoid.robots") / "iiwa14"
    folder = tmp_path / "meshy"
    folder.mkdir()
    corners = box_stl(folder / "box.stl", np.array([0.1, 0.05, 0.2]))
    urdf = (src / "iiwa14.urdf").read_text()
    cylinder = '<cylinder radius="0.07" length="0.2045"/>'
    assert urdf.count(cylinder) == 1
    mesh = f'<mesh filename="{folder / "box.stl"}" scale="0.5 0.5 0.5"/>'
    (folder / "iiwa14.urdf").write_text(urdf.replace(cylinder, mesh))
    (folder / "control_points.toml").write_text((src / "control_points.toml").read_text())
    meshy = qpavoid.load_robot(str(folder))
    (part,) = [p for p in arm_parts(meshy) if p.shape == "mesh"]
    data = replay_data(_one_tick(meshy, KINECT_V2), {}, meshy)
    objects = scene(replay_html(data, "mesh"))
    obj = objects[f"/qpavoid/robot/meshes/j{part.joint}/{part.name}"]
    (geo,) = obj["geometries"]
    assert geo["type"] == "BufferGeometry"
    vertices = unpacked(geo["data"]["attributes"]["position"])
    triangles = unpacked(geo["data"]["index"])
    assert vertices.shape == (8, 3) and triangles.shape == (12, 3)
    order = np.lexsort(vertices.T)  # the corners are distinct in every coordinate order
    np.testing.assert_allclose(vertices[order], 0.5 * corners[np.lexsort(corners.T)], atol=1e-7)
    assert set(triangles.ravel()) == set(range(8))
    np.testing.assert_allclose(
        np.reshape(obj["object"]["matrix"], (4, 4), order="F"), part.placement
    )


@pytest.mark.skipif(
    not (resources.files("qpavoid.robots") / "panda" / "control_points.toml").is_file(),
    reason="no Panda description",
)
def test_the_panda_replay_draws_its_own_collision_meshes() -> None:
    """The Panda of example-robot-data (the extra ``robots``): every collision object of
    its URDF in the page, each mesh with coal's triangles."""
    pytest.importorskip("cmeel", reason="the Panda's URDF ships with example-robot-data")
    panda = qpavoid.load_robot("panda")
    parts = arm_parts(panda)
    data = replay_data(_one_tick(panda, KINECT_V2), {}, panda, parts=parts)
    html = replay_html(data, "panda")
    objects = scene(html)
    meshes = [p for p in parts if p.shape == "mesh"]
    assert len(meshes) >= 8  # link0 to link7 and the hand
    for part in meshes:
        (geo,) = objects[f"/qpavoid/robot/meshes/j{part.joint}/{part.name}"]["geometries"]
        np.testing.assert_array_equal(unpacked(geo["data"]["index"]), part.triangles)
    assert data["set_names"] == list(panda.set_names) and len(panda.set_names) > 3
    assert len(html.encode()) < 1.5e6  # one tick: the viewer, the meshes and little else


def test_the_floor_holds_the_reach_and_the_camera_sees_the_whole_scene(
    test2_run: Path, robot: qpavoid.Robot
) -> None:
    data = replay_data(load_log(test2_run), {}, robot)
    x0, x1, y0, y1 = data["floor"]
    reach = reach_m(robot)
    assert reach == pytest.approx(1.306 + 0.09)  # base to flange (docs/robot.md), a sphere
    assert x0 <= -reach and x1 >= reach and y0 <= -reach and y1 >= reach
    shown = np.vstack([data["links"].reshape(-1, 3), data["human"].reshape(-1, 3)])
    shown = shown[np.isfinite(shown).all(axis=1)]
    assert np.all((shown[:, 0] > x0) & (shown[:, 0] < x1) & (shown[:, 1] > y0) & (shown[:, 1] < y1))
    eye = np.array(data["camera"]["position"])
    look = np.array(data["camera"]["target"]) - eye
    assert eye[2] > max(shown[:, 2])  # above
    to = shown - eye
    cos = to @ look / np.linalg.norm(to, axis=1) / np.linalg.norm(look)
    assert np.degrees(np.arccos(cos.min())) < np.degrees(CAMERA_HALF_FOV_RAD)  # all in view


def test_qpavoid_view_writes_the_replay_and_refuses_a_folder_without_a_run(
    test2_run, tmp_path, capsys
):
    assert (test2_run / "replay.html").is_file()  # run writes it ...
    out = tmp_path / "again.html"
    assert main(["view", str(test2_run), "--out", str(out)]) == 0  # ... and view does too
    assert out.read_bytes() == (test2_run / "replay.html").read_bytes()
    assert main(["view", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "not a run folder" in err and err.count("\n") == 1
    assert write_replay(test2_run, tmp_path / "x.html").stat().st_size > 1e5


@pytest.fixture(scope="module")
def browser():
    sync_api = pytest.importorskip(
        "playwright.sync_api", reason="no playwright: pip install 'qpavoid[dev]'"
    )
    if CHROMIUM is None:
        pytest.skip("no Chromium on this machine (Debian: apt-get install chromium)")
    with sync_api.sync_playwright() as p:
        chromium = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        yield chromium
        chromium.close()


def changed_pixels(page, name: str) -> int:
    """Pixels of the canvas that change when object ``name`` is hidden (it is drawn)."""
    shown = screenshot(page)
    page.evaluate(f"window.qpavoidReplay.visible({name!r}, false)")
    page.wait_for_timeout(200)
    hidden = screenshot(page)
    page.evaluate(f"window.qpavoidReplay.visible({name!r}, true)")
    return int((np.abs(shown - hidden).max(axis=2) > 30).sum())


def screenshot(page) -> np.ndarray:
    """The page as an (H, W, 3) int array."""
    image = Image.open(io.BytesIO(page.screenshot())).convert("RGB")
    return np.asarray(image).astype(int)


@pytest.mark.slow  # seconds of a subprocess or a browser: with the slow suite
def test_the_replay_renders_in_a_browser_and_shows_the_stop_of_test2(browser, test2_run):
    log = load_log(test2_run)
    page = browser.new_page(viewport={"width": 1000, "height": 700})
    errors: list[str] = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    requests: list[str] = []
    page.on("request", lambda r: requests.append(r.url))
    page.goto(Path(test2_run / "replay.html").resolve().as_uri())
    page.wait_for_function("window.qpavoidReplay !== undefined", timeout=30000)
    page.wait_for_timeout(300)
    assert errors == []
    assert set(page.evaluate("window.qpavoidReplay.objects()")) >= {
        "robot",
        "human",
        "pairs",
        "floor",
    }
    # the canvas is not blank, and the robot and the person are drawn on it
    assert screenshot(page).std() > 20
    assert changed_pixels(page, "robot") > 2000, "no robot drawn"
    assert changed_pixels(page, "human") > 2000, "no person drawn"
    # the slider to the first stop of Test 2
    k = int(np.flatnonzero(log["stopped"])[0])
    t_stop = float(log["t"][k])
    page.eval_on_selector(
        "#time",
        "(el, t) => { el.value = t; el.dispatchEvent(new Event('input')); }",
        t_stop,
    )
    assert page.evaluate("window.qpavoidReplay.tick()") == k
    assert page.inner_text("#t") == f"{t_stop:.3f}"
    assert page.inner_text("#reason") == f"stopped: {log['stop_reason'][k]}"
    for s in range(3):
        assert page.inner_text(f"#d{s}") == f"{log['distance'][k, s]:.3f} m"
    # the arm's own cylinders, where Pinocchio puts them at the tick shown
    robot = qpavoid.load_robot("iiwa14")
    parts = arm_parts(robot)
    joints = {f"j{p.joint}" for p in parts}
    assert set(page.evaluate("window.qpavoidReplay.children('robot/meshes')")) == joints
    data = replay_data(log, {}, robot)
    frame = int(np.searchsorted(data["frame_tick"], k, side="right")) - 1
    q = log["q"][data["frame_tick"][frame]]
    geometry = collision_geometry(robot)
    gdata = geometry.createData()
    pin.updateGeometryPlacements(robot.model, robot.model.createData(), geometry, gdata, q)
    for i, part in enumerate(parts):
        path = f"robot/meshes/j{part.joint}/{part.name}/body"
        world = np.reshape(page.evaluate(f"window.qpavoidReplay.world({path!r})"), (4, 4), "F")
        placed = gdata.oMg[i].homogeneous
        np.testing.assert_allclose(world[:3, 1], placed[:3, 2], atol=1e-5)  # the axis
        np.testing.assert_allclose(world[:3, 3], placed[:3, 3], atol=1e-5)
    assert changed_pixels(page, "robot/meshes") > 500, "no arm drawn"
    assert changed_pixels(page, "floor") > 20000, "no floor drawn"
    assert all(u.startswith("file:") or u.startswith("data:") for u in requests), requests
    page.close()


def test_the_live_view_serves_the_page_and_the_newest_tick(test2_run, robot):
    log = load_log(test2_run)
    k = int(np.flatnonzero(log["stopped"])[0])
    row = {key: v[k] for key, v in log.items()}
    with LiveView(("127.0.0.1", 0), robot, "capsules", "live") as view:
        page = urlopen(view.url, timeout=10).read().decode()
        assert "const LIVE = true" in page and "://" not in page
        assert urlopen(view.url + "state", timeout=10).read() == b"null"  # nothing yet
        view.update(row)
        state = json.loads(urlopen(view.url + "state", timeout=10).read())
    shown = replay_data({key: np.asarray(v)[None] for key, v in row.items()}, {}, robot)
    assert state["reasons"] == [str(log["stop_reason"][k])]
    t = np.frombuffer(base64.b64decode(state["t"]["b64"]), dtype=np.float64)
    assert t.tolist() == [log["t"][k]] == shown["t"].tolist()


@pytest.mark.slow
def test_qpavoid_run_view_follows_a_live_run_in_a_browser(browser, tmp_path):
    calib = tmp_path / "calib.toml"
    pose = look_at(np.array([1.0, 2.5, 1.3]), np.zeros(3))
    calib.write_text(Calibration({"a": SensorCalibration("a", pose)}).to_toml())
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    cmd = [*PYTHON, "-m", "qpavoid", "run", "--listen", f"127.0.0.1:{port}", "--sensors"]
    cmd += [str(calib), "--view", "--out", str(tmp_path / "live"), "--rate", "100", "-q"]
    cmd += ["--allow-unauthenticated"]  # no sensor: the opt-in path, on loopback
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = proc.stdout.readline()
        url = re.search(r"live view: (\S+)", line).group(1)
        page = browser.new_page()
        page.goto(url)
        page.wait_for_function("document.getElementById('t').textContent !== '0.000'")
        first = float(page.inner_text("#t"))
        time.sleep(0.6)
        assert float(page.inner_text("#t")) > first  # it follows the run
        assert "stale" in page.inner_text("#reason")  # no sensor: stopped, and says why
        page.close()
    finally:
        proc.send_signal(signal.SIGINT)
        proc.communicate(timeout=30)
    assert proc.returncode == 0


def test_view_refuses_to_overwrite_the_run_and_bad_logs_in_one_line(test2_run, tmp_path, capsys):
    """An adversarial tester's cases: `--out RUN/log.npz` replaced the log with the page;
    malformed logs gave an internal error or a broken page."""
    log_bytes = (test2_run / "log.npz").read_bytes()
    for out in ("log.npz", "metrics.json"):
        assert main(["view", str(test2_run), "--out", str(test2_run / out)]) == 2
    assert (test2_run / "log.npz").read_bytes() == log_bytes
    assert capsys.readouterr().err.count("must be a .html file") == 2
    log = dict(load_log(test2_run))
    metrics = (test2_run / "metrics.json").read_text()
    bad = {
        "t reversed": {"t": log["t"][::-1]},
        "t with a NaN": {"t": np.where(np.arange(len(log["t"])) == 3, np.nan, log["t"])},
        "f short": {"f": log["f"][:-10]},
        "distance (N, 2)": {"distance": log["distance"][:, :2]},
        "reasons as numbers": {"stop_reason": np.arange(len(log["t"]))},
    }
    for name, change in bad.items():
        folder = tmp_path / name.replace(" ", "_")
        folder.mkdir()
        np.savez(folder / "log.npz", **(log | change))
        (folder / "metrics.json").write_text(metrics)
        assert main(["view", str(folder)]) == 2, name
        err = capsys.readouterr().err
        assert err.startswith("qpavoid: error: log.npz: ") and err.count("\n") == 1, err
    (folder / "metrics.json").write_text("[]")
    assert main(["view", str(folder)]) == 2
    assert "must hold an object" in capsys.readouterr().err
    old = {k: v for k, v in log.items() if k != "human_point"}  # an older log: still opens
    np.savez(folder / "log.npz", **old)
    (folder / "metrics.json").write_text(metrics)
    assert main(["view", str(folder)]) == 0


def test_a_fast_run_keeps_at_most_max_ticks_each_one_of_the_log(test2_run, robot, monkeypatch):
    monkeypatch.setattr(view_data, "MAX_TICKS", 100)
    log = load_log(test2_run)
    data = replay_data(log, {}, robot)
    assert 50 <= len(data["t"]) <= 100
    rows = np.searchsorted(log["t"], data["t"])
    np.testing.assert_array_equal(log["t"][rows], data["t"])  # real ticks, not averages
    np.testing.assert_allclose(data["distance"], log["distance"][rows], rtol=1e-6)


def test_the_live_view_serves_this_machine_only_and_makes_each_tick_once(test2_run, robot):
    with pytest.raises(Exception, match="loopback"):
        LiveView(("0.0.0.0", 0), robot, "capsules", "live")
    log = load_log(test2_run)
    with LiveView(("127.0.0.1", 0), robot, "capsules", "live") as view:
        view.update({key: v[5] for key, v in log.items()})
        first = view.state()
        assert view.state() is first  # asked again: not made again
        view.update({key: v[6] for key, v in log.items()})
        assert view.state() != first
