"""Each camera's body model on its own joints (issue 41): it covers the true body, its
centres are what they say, a cell of one camera runs on it, and a wrong file is refused
in one line with exit 2."""

from __future__ import annotations

import re
import shlex
import shutil
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from qpavoid.arm.ik import inverse_kinematics
from qpavoid.arm.model import load_robot
from qpavoid.cli.commands import main
from qpavoid.control.qp import QPController
from qpavoid.core.errors import InputError, SkeletonFormatError
from qpavoid.experiments.campaign import campaign_spec, rerun_command
from qpavoid.experiments.run_spec import RunSpec
from qpavoid.human.body import BodyModel, KinectHuman, body_model
from qpavoid.human.frames import HumanFrame
from qpavoid.human.landmarks import FORMAT_NAMES, LandmarkMap, skeleton_format
from qpavoid.human.people import People
from qpavoid.human.skeleton import INFERRED, NOT_TRACKED, TRACKED, SkeletonFormat
from qpavoid.human.skeleton_file import FORMATS_DIR
from qpavoid.loop.camera import Camera, CameraConfig
from qpavoid.scenarios.generated import make_scenario
from qpavoid.scenarios.strikes import strike_case, strike_motion

CAMERAS = [name for name in FORMAT_NAMES if name != "kinect_v2"]


def _segment_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
    ab = b - a
    u = np.clip(np.dot(p - a, ab) / max(float(np.dot(ab, ab)), 1e-12), 0.0, 1.0)
    return float(np.linalg.norm(p - (a + u * ab)))


@pytest.fixture(scope="module")
def true_frames() -> list[HumanFrame]:
    """The true body in the scenarios' and strikes' poses (seated, reaching, striking)."""
    robot = load_robot()
    frames = []
    for name in ("free", "test1", "test2", "random:0", "random:1", "random:2"):
        motion = make_scenario(name, robot)
        frames += [HumanFrame.check(*_pair(motion.frame_at(t))) for t in np.arange(0, 20, 0.5)]
    for seed in range(8):
        motion = strike_motion(strike_case(seed, robot=robot), robot)
        frames += [HumanFrame.check(*motion.frame_at(t)) for t in np.arange(0, 9, 0.4)]
    return frames


def _pair(frame: object) -> tuple[np.ndarray, np.ndarray]:
    if isinstance(frame, HumanFrame):
        return frame.joints, frame.state
    return frame  # type: ignore[return-value]


@pytest.mark.parametrize("camera", CAMERAS)
def test_each_cameras_capsules_hold_the_true_bodys(camera, true_frames):
    """Where the camera puts its joints (its ``[simulate]`` table), each part's capsule
    on them holds the truth judge's whole capsule (both ends of its axis, its radius and
    its fingers' reach): a capsule is convex, so its ends inside suffice. The needed
    radius is within 1 cm of the file's, so the model is not needlessly fat either."""
    fmt = skeleton_format(camera)
    body, truth, films = body_model(fmt), KinectHuman(), LandmarkMap.simulated(fmt)
    assert body.part_names == truth.part_names and body.regions == truth.regions
    assert body.body_parts == truth.body_parts == ("head", "trunk")
    need = np.zeros(len(body.parts))
    for frame in true_frames:
        true = truth.geometry(frame)
        seen = films.map(frame.joints, frame.state)
        mine = body.geometry(seen.joints, seen.state)
        for k in range(len(body.parts)):
            a, b = mine.segments[k]
            r_true = truth.capsule_radii[k] + true.reach_margin[k]
            for end in true.segments[k]:
                need[k] = max(need[k], _segment_distance(end, a, b) + r_true - mine.reach_margin[k])
    radii, measured = body.capsule_radii, dict(zip(body.part_names, need.round(3), strict=True))
    assert np.all(need <= radii + 1e-9), measured
    assert np.all(radii - need < 0.01 + 1e-9), measured


def test_a_centre_is_the_mean_of_its_joints_as_uncertain_as_the_worst():
    """mediapipe_pose's trunk runs between two centres: hand-computed mean, state, radius
    and velocity; one of its joints lost and the centre is not usable."""
    fmt = skeleton_format("mediapipe_pose")
    body = body_model(fmt)
    ls, rs, lh, rh = fmt.indices(["LEFT_SHOULDER", "RIGHT_SHOULDER", "LEFT_HIP", "RIGHT_HIP"])
    joints = np.zeros((fmt.n_joints, 3))
    joints[[ls, rs]] = [[0.2, 0.0, 1.4], [-0.2, 0.0, 1.4]]
    joints[[lh, rh]] = [[0.1, 0.0, 0.9], [-0.1, 0.0, 0.9]]
    state = np.full(fmt.n_joints, TRACKED, dtype=np.int8)
    state[rs] = INFERRED
    radius = np.zeros(fmt.n_joints)
    radius[[ls, rs]] = [0.01, 0.07]
    velocity = np.zeros((fmt.n_joints, 3))
    velocity[[ls, rs]] = [[1.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
    geometry, part_velocity = body.tracked_geometry(HumanFrame(joints, state), radius, velocity)
    trunk = body.part_names.index("trunk")
    np.testing.assert_allclose(geometry.segments[trunk], [[0.0, 0.0, 1.4], [0.0, 0.0, 0.9]])
    assert geometry.part_margin[trunk] == pytest.approx(0.07)  # the worse shoulder's
    # the part's velocity: its fastest member, the left shoulder (the centre moves at 0.5)
    np.testing.assert_allclose(part_velocity[trunk], [1.0, 0.0, 0.0])
    assert body.part_joints()[trunk, [ls, rs, lh, rh]].all()
    joints[lh], state[lh] = np.nan, NOT_TRACKED
    lost = body.geometry(joints, state)
    # HIPS lost: the capsule shrinks to the shoulders' centre, never a NaN
    np.testing.assert_allclose(lost.segments[trunk], [[0.0, 0.0, 1.4], [0.0, 0.0, 1.4]])


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        (('ELBOW_LEFT"]', 'ELBOW_LFT"]'), "'ELBOW_LFT' is not a joint of the k4abt format"),
        (
            ("capsule_radius_m = 0.16", "capsule_radius_m = 0"),
            r"part 'trunk': parts\[1\].capsule_radius_m must be a number at least 0.01 and at "
            r"most 1, m, got 0",
        ),
        (
            ("capsule_radius_m = 0.16", "capsule_radius_m = -0.1"),
            r"capsule_radius_m must be a number at least 0.01",
        ),
        (
            ("capsule_radius_m = 0.16", "capsule_radius_m = 1e300"),
            "at least 0.01 and at most 1, m, got 1e",
        ),
        (
            (
                'CLAVICLES = ["CLAVICLE_LEFT", "CLAVICLE_RIGHT"]',
                'CLAVICLES = ["CLAVICLE_LEFT", "CLAVICLE_LEFT", "CLAVICLE_RIGHT"]',
            ),
            "named twice",
        ),
        (
            ('CLAVICLES = ["CLAVICLE_LEFT", "CLAVICLE_RIGHT"]', 'CLAVICLES = ["CLAVICLE_LEFT"]'),
            "a centre is the mean of two or more",
        ),
        (
            ('CLAVICLES = ["CLAVICLE_LEFT", "CLAVICLE_RIGHT"]', 'NECK = ["CLAVICLE_LEFT", "HEAD"]'),
            "a centre needs a name that is no joint",
        ),
    ],
)
def test_a_wrong_body_file_is_refused_naming_the_key(tmp_path, edit, match):
    text = (FORMATS_DIR / "k4abt_body.toml").read_text()
    assert edit[0] in text
    path = tmp_path / "k4abt_body.toml"
    path.write_text(text.replace(edit[0], edit[1], 1))
    with pytest.raises(SkeletonFormatError, match=match):
        BodyModel.load(path, skeleton_format("k4abt"))


def _user_camera(tmp_path: Path, fmt_edit=None, body_edit=None) -> Path:
    """The Azure Kinect's files as a camera of the user's, ``mycam``."""
    for name, edit in (("k4abt.toml", fmt_edit), ("k4abt_body.toml", body_edit)):
        text = (FORMATS_DIR / name).read_text()
        text = text.replace('name = "k4abt"', 'name = "mycam"').replace(
            'format = "k4abt"', 'format = "mycam"'
        )
        if edit is not None:
            assert edit[0] in text
            text = text.replace(edit[0], edit[1], 1)
        (tmp_path / name.replace("k4abt", "mycam")).write_text(text)
    return tmp_path / "mycam.toml"


BAD_USER_FILES = [
    (None, ('ELBOW_LEFT"]', 'ELBOW_LFT"]'), "'ELBOW_LFT' is not a joint"),
    (None, ("capsule_radius_m = 0.16", "capsule_radius_m = 0"), "must be a number at least 0.01"),
    (None, ('region = "face"', 'region = "fcae"'), "fcae"),
    (('name = "mycam"', 'name = "other"'), None, "name must be the file's name, 'mycam'"),
    (('body = "kinect_v2"', 'body = "mycam"'), None, "body must be 'kinect_v2'"),
    (
        ("frame_rate_hz = 30.0", "frame_rate_hz = 1e300"),
        None,
        "sensor.frame_rate_hz must be a number at least 1 and at most 1000",
    ),
    (('NOSE = { lerp = ["Neck", "Head"], t = 1.2, uncertainty_m = 0.05 }', ""), None, "simulate"),
    (
        ("latency_s = 0.10", "latency_s = -0.1"),
        None,
        "sensor.latency_s must be a number at least 0 and at most 1",
    ),
    (
        ('latency_s = { basis = "estimate"', 'latency_s = { basis = "measured"'),
        None,
        "a measured number needs its source",
    ),
]


@pytest.mark.parametrize(("fmt_edit", "body_edit", "match"), BAD_USER_FILES)
def test_a_users_camera_file_is_refused_by_the_runs_spec(tmp_path, fmt_edit, body_edit, match):
    """``--camera FILE.toml``: the issue's bad inputs, refused where the run is specified."""
    path = _user_camera(tmp_path, fmt_edit, body_edit)
    with pytest.raises(SkeletonFormatError, match=match):
        RunSpec("free", camera=str(path))


@pytest.mark.parametrize(("fmt_edit", "body_edit", "match"), BAD_USER_FILES[::10])
def test_a_users_camera_file_gets_one_line_and_exit_2(
    tmp_path, fmt_edit, body_edit, match, monkeypatch, capsys
):
    """... and on the command line: one line on stderr, exit 2 (one file: the others above;
    the command line's main in this process, the installed program's refusals are
    tests/test_cli_errors.py's)."""
    path = _user_camera(tmp_path, fmt_edit, body_edit)
    monkeypatch.chdir(tmp_path)  # (a run that went ahead would write runs/ here)
    status = main(["run", "free", "--camera", str(path), "--max-time", "1"])
    out, err = capsys.readouterr()
    assert status == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and match in lines[0], err
    assert out == "" and not (tmp_path / "runs").exists()


def test_a_users_camera_without_its_body_file_is_refused(tmp_path):
    path = _user_camera(tmp_path)
    (tmp_path / "mycam_body.toml").unlink()
    with pytest.raises(SkeletonFormatError, match="has no body model"):
        body_model(skeleton_format(str(path)))
    _user_camera(tmp_path)
    assert body_model(skeleton_format(str(path))).part_names == KinectHuman().part_names


def test_a_users_camera_may_not_take_a_shipped_formats_name(tmp_path):
    for name in ("k4abt", "kinect_v2"):
        text = (
            (FORMATS_DIR / "k4abt.toml").read_text().replace('name = "k4abt"', f'name = "{name}"')
        )
        (tmp_path / f"{name}.toml").write_text(text)
        with pytest.raises(SkeletonFormatError, match="a format the library ships"):
            skeleton_format(str(tmp_path / f"{name}.toml"))


def test_a_body_whose_joints_the_tracker_cannot_bound_is_refused(tmp_path):
    """An adversarial tester's case: MediaPipe's hips were roots of their own, so a hip never
    seen was bounded by nothing and the trunk shrank to the shoulders. Now the body's
    joints must be in one tree of the format (the hips hang from the shoulders)."""
    text = (FORMATS_DIR / "mediapipe_pose.toml").read_text()
    old = '{ id = 23, name = "LEFT_HIP", parent = "LEFT_SHOULDER", max_bone_m = 0.90 }'
    new = '{ id = 23, name = "LEFT_HIP" }'
    assert old in text
    text = text.replace(old, new).replace(
        '{ id = 24, name = "RIGHT_HIP", parent = "RIGHT_SHOULDER", max_bone_m = 0.90 }',
        '{ id = 24, name = "RIGHT_HIP" }',
    )
    (tmp_path / "mediapipe_pose.toml").write_text(text)
    shutil.copy(FORMATS_DIR / "mediapipe_pose_body.toml", tmp_path)
    with pytest.raises(SkeletonFormatError, match="in 3 trees of the mediapipe_pose format"):
        BodyModel.load(tmp_path / "mediapipe_pose_body.toml")


def test_a_hip_never_seen_keeps_mediapipes_trunk_whole():
    """The same case through a controller: the trunk, 0.3 m from the end effector, with
    a hip lost from the first frame on, still stops the robot (the hip bounded by its
    shoulder), as it does with every joint seen."""
    robot = load_robot()
    fmt = skeleton_format("mediapipe_pose")
    q = None
    for lost in ((), ("LEFT_HIP",)):
        controller = QPController(robot, human=body_model(fmt))
        if q is None:
            q = inverse_kinematics(robot, controller.path.reference(0.0)[0])
        ee = robot.kinematics(q).ee_placement[:3, 3]
        truth = HumanFrame.check(*_pair(make_scenario("test1", robot).frame_at(0.0)))
        seen = LandmarkMap.simulated(fmt).map(truth.joints, truth.state)
        joints, state = seen.joints.copy(), seen.state.copy()
        hips = joints[fmt.indices(["LEFT_HIP", "RIGHT_HIP"])].mean(axis=0)
        chest = joints[fmt.indices(["LEFT_SHOULDER", "RIGHT_SHOULDER"])].mean(axis=0)
        joints += ee + np.array([0.0, 0.30, 0.0]) - (hips + 0.25 * (chest - hips))
        joints[fmt.indices(list(lost))], state[fmt.indices(list(lost))] = np.nan, NOT_TRACKED
        assert controller.step(q, joints, state, 0.0, frame_age_s=0.01).stopped, lost


def test_a_frame_of_another_format_of_the_same_name_is_refused():
    """An adversarial tester's case: a file called k4abt with NECK and HEAD swapped was read
    in the shipped k4abt's order. A format of the body's name that is not the body's own
    (any difference) is refused; an equal one (the same file read again) is the body's."""
    robot = load_robot()
    shipped = skeleton_format("k4abt")
    controller = QPController(robot, human=body_model(shipped))
    q = inverse_kinematics(robot, controller.path.reference(0.0)[0])
    frame = np.tile([1.5, 0.0, 0.5], (32, 1))
    again = SkeletonFormat.load(FORMATS_DIR / "k4abt.toml")
    assert again is not shipped
    controller.step(q, frame, None, 0.0, frame_age_s=0.01, camera_format=again)
    other = replace(again, title="a k4abt of another file")
    with pytest.raises(InputError, match="not the body model's 'k4abt' format"):
        controller.step(q, frame, None, 0.0, frame_age_s=0.01, camera_format=other)


def test_a_camera_films_its_own_joints_for_a_body_on_them():
    """A camera of another format gives the controller on its own body model its joints
    (noise 0): where its ``[simulate]`` table puts them, each off by this person's anatomy,
    within its rule's ``uncertainty_m``, the same in every frame, none for a joint the
    table takes as a landmark; nothing mapped back."""
    robot = load_robot()
    motion = make_scenario("test1", robot)
    fmt = skeleton_format("zed_body_38")
    cfg = CameraConfig.of("zed_body_38", noise_m=0.0)
    native = Camera(motion, cfg, fmt)
    films = LandmarkMap.simulated(fmt)
    offsets = []
    for k in (40, 80):
        frame, captured, _, _ = native.frame(k)
        truth = HumanFrame.check(*_pair(motion.frame_at(captured)))
        expected = films.map(truth.joints, truth.state)
        assert frame.joints.shape == (fmt.n_joints, 3)
        offsets.append(frame.joints - expected.joints)
    np.testing.assert_allclose(offsets[0], offsets[1], atol=1e-12)
    size = np.linalg.norm(offsets[0], axis=1)
    u = films.uncertainty_m
    assert np.all(size <= u + 1e-12) and np.all(size[u == 0.0] == 0.0) and size.max() > 0.01
    assert u[fmt.index("NECK")] == 0.05 and u[fmt.index("LEFT_SHOULDER")] == 0.0
    assert Camera(motion, cfg).frame(40)[0].joints.shape == (25, 3)  # the landmarks' path


@pytest.mark.parametrize(
    ("edit", "match"),
    [
        # a bone of unknown length bounds nothing: the arm's joints hang on it
        (
            '{ id = 6, name = "ELBOW_LEFT", parent = "SHOULDER_LEFT", max_bone_m = 0.40 }',
            "has a parent but no max_bone_m",
        ),
        # weights far off their joints (lerp's t is bounded to [-1, 2]; so are they now)
        ("NOSE = { lerp = [", "weights must be joint = weight pairs in [-1, 2]"),
        ('name = "mycam"', "name must be letters, digits"),
    ],
)
def test_a_second_testers_cases_are_refused(tmp_path, edit, match):
    """A second adversarial pass: a joint with a parent and no bone bound (the tracker
    placed a never-seen arm on the shoulder with no uncertainty), ``weights`` that escaped
    lerp's bound (joints 65 km away), a name that is no plain name."""
    path = _user_camera(tmp_path)
    text = path.read_text()
    if "ELBOW_LEFT" in edit:
        text = text.replace(edit, edit.replace(", max_bone_m = 0.40", ""))
        text = text.replace(
            '{ id = 13, name = "ELBOW_RIGHT", parent = "SHOULDER_RIGHT", max_bone_m = 0.40 }',
            '{ id = 13, name = "ELBOW_RIGHT", parent = "SHOULDER_RIGHT" }',
        )
    elif "NOSE" in edit:
        text = text.replace(
            'NOSE = { lerp = ["Neck", "Head"], t = 1.2, uncertainty_m = 0.05 }',
            "NOSE = { weights = { Head = 1e6, Neck = -999999.0 } }",
        )
    else:
        text = text.replace(edit, 'name = "my cam"')
        path = tmp_path / "my cam.toml"
        (tmp_path / "mycam_body.toml").rename(tmp_path / "my cam_body.toml")
    path.write_text(text)
    with pytest.raises(SkeletonFormatError, match=re.escape(match)):
        RunSpec("free", camera=str(path))


def test_equal_formats_hash_equal(tmp_path):
    """The same format read from two places is equal and hashes equal (its source is not
    part of either): a cache keyed on the format finds it."""
    shutil.copy(FORMATS_DIR / "k4abt.toml", tmp_path)
    again = SkeletonFormat.load(tmp_path / "k4abt.toml")
    shipped = skeleton_format("k4abt")
    assert again == shipped and hash(again) == hash(shipped) and again in {shipped}


def test_a_frame_built_by_hand_with_an_infinity_or_a_wrong_shape_is_refused():
    """An adversarial tester's case: a HumanFrame built without HumanFrame.check, one
    clavicle at infinity, dropped the clavicles' centre and the robot moved; a (J, 2)
    frame raised a bare ValueError. Both are InputErrors now, alone or among People."""
    robot = load_robot()
    controller = QPController(robot, human=body_model(skeleton_format("k4abt")))
    q = inverse_kinematics(robot, controller.path.reference(0.0)[0])
    joints = np.tile([1.5, 0.0, 0.5], (32, 1))
    joints[4] = np.inf
    state = np.full(32, TRACKED, dtype=np.int8)
    for frame in (HumanFrame(joints, state), HumanFrame(joints[:, :2], state)):
        with pytest.raises(InputError, match="HumanFrame's joints must be"):
            controller.step(q, frame, None, 0.0, frame_age_s=0.01)
        with pytest.raises(InputError, match="HumanFrame's joints must be"):
            controller.step(q, People((0,), (frame,)), None, 0.0, frame_age_s=0.01)


def test_a_close_work_rerun_line_names_a_users_camera_file_whole(tmp_path):
    """A second tester's case: the re-run line of a worst close-work case named a camera
    file relative and unquoted, so it broke from inside worst/ or on a space."""
    folder = tmp_path / "dir with space"
    folder.mkdir()
    path = _user_camera(folder)
    spec = campaign_spec("analytic", camera=str(path), motion="closework")
    line = rerun_command(SimpleNamespace(seed=3), spec)
    assert f"--camera {shlex.quote(str(path.absolute()))}" in line
    assert shlex.split(line)[shlex.split(line).index("--camera") + 1] == str(path.absolute())


def test_body_model_takes_a_format_name():
    """Issue 46 (item 6.2): ``body_model("k4abt")`` raised ``AttributeError: 'str' object
    has no attribute 'source'``. A name, a format and a user's format file's path give the
    same model; an unknown name is refused naming the formats."""
    body = body_model("k4abt")
    assert body is body_model(skeleton_format("k4abt"))  # read once, whichever way named
    assert body.skeleton.name == "k4abt" and body.part_names == KinectHuman().part_names
    assert body.centres == (("CLAVICLES", ("CLAVICLE_LEFT", "CLAVICLE_RIGHT")),)
    head = body.parts[body.part_names.index("head")]
    assert head.chain == ("CLAVICLES", "NECK", "HEAD") and head.capsule_radius_m == 0.11
    assert isinstance(body_model("kinect_v2"), KinectHuman)
    with pytest.raises(InputError, match="unknown skeleton format 'k4'; the formats are kinect_v2"):
        body_model("k4")


def test_body_model_takes_a_users_format_file_by_its_path(tmp_path):
    path = _user_camera(tmp_path)
    assert body_model(str(path)) is body_model(skeleton_format(str(path)))
