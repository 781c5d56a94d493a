"""Any body-tracking camera (issue 28): the format files against the SDKs' own joint lists,
confidence to states by hand, the landmark map by hand and over random postures, the
simulated camera of each format, and the controller fed each format."""

import numpy as np
import pytest

from qpavoid.arm.ik import inverse_kinematics
from qpavoid.arm.model import load_robot
from qpavoid.control.analytic import AnalyticController
from qpavoid.control.tick import ControllerConfig
from qpavoid.core.errors import InputError, SkeletonFormatError
from qpavoid.experiments.run_spec import RunSpec
from qpavoid.experiments.runs import build_controller
from qpavoid.experiments.sweep import strike_sweep
from qpavoid.human.conversion import Confidence, parse_rule
from qpavoid.human.frames import HumanFrame
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.human.landmarks import (
    FORMAT_NAMES,
    LandmarkMap,
    body_frame,
    camera_frame,
    landmark_map,
    skeleton_format,
)
from qpavoid.human.posture import Operator, random_posture
from qpavoid.human.skeleton import SkeletonFormat
from qpavoid.loop.camera import Camera, CameraConfig
from qpavoid.perception.tracker import PerceptionConfig
from qpavoid.scenarios.generated import make_scenario
from qpavoid.sensing.calibration import Calibration, SensorCalibration
from qpavoid.sensing.recording_files import csv_header

#: The SDKs' joint orders, copied from their documentation (an independent reference):
#: k4abttypes.h's k4abt_joint_id_t, pyzed's BODY_34_PARTS, MediaPipe's PoseLandmark.
K4ABT = [
    "PELVIS",
    "SPINE_NAVEL",
    "SPINE_CHEST",
    "NECK",
    "CLAVICLE_LEFT",
    "SHOULDER_LEFT",
    "ELBOW_LEFT",
    "WRIST_LEFT",
    "HAND_LEFT",
    "HANDTIP_LEFT",
    "THUMB_LEFT",
    "CLAVICLE_RIGHT",
    "SHOULDER_RIGHT",
    "ELBOW_RIGHT",
    "WRIST_RIGHT",
    "HAND_RIGHT",
    "HANDTIP_RIGHT",
    "THUMB_RIGHT",
    "HIP_LEFT",
    "KNEE_LEFT",
    "ANKLE_LEFT",
    "FOOT_LEFT",
    "HIP_RIGHT",
    "KNEE_RIGHT",
    "ANKLE_RIGHT",
    "FOOT_RIGHT",
    "HEAD",
    "NOSE",
    "EYE_LEFT",
    "EAR_LEFT",
    "EYE_RIGHT",
    "EAR_RIGHT",
]
ZED_BODY_34 = [
    "PELVIS",
    "NAVAL_SPINE",
    "CHEST_SPINE",
    "NECK",
    "LEFT_CLAVICLE",
    "LEFT_SHOULDER",
    "LEFT_ELBOW",
    "LEFT_WRIST",
    "LEFT_HAND",
    "LEFT_HANDTIP",
    "LEFT_THUMB",
    "RIGHT_CLAVICLE",
    "RIGHT_SHOULDER",
    "RIGHT_ELBOW",
    "RIGHT_WRIST",
    "RIGHT_HAND",
    "RIGHT_HANDTIP",
    "RIGHT_THUMB",
    "LEFT_HIP",
    "LEFT_KNEE",
    "LEFT_ANKLE",
    "LEFT_FOOT",
    "RIGHT_HIP",
    "RIGHT_KNEE",
    "RIGHT_ANKLE",
    "RIGHT_FOOT",
    "HEAD",
    "NOSE",
    "LEFT_EYE",
    "LEFT_EAR",
    "RIGHT_EYE",
    "RIGHT_EAR",
    "LEFT_HEEL",
    "RIGHT_HEEL",
]
MEDIAPIPE = [
    "NOSE",
    "LEFT_EYE_INNER",
    "LEFT_EYE",
    "LEFT_EYE_OUTER",
    "RIGHT_EYE_INNER",
    "RIGHT_EYE",
    "RIGHT_EYE_OUTER",
    "LEFT_EAR",
    "RIGHT_EAR",
    "MOUTH_LEFT",
    "MOUTH_RIGHT",
    "LEFT_SHOULDER",
    "RIGHT_SHOULDER",
    "LEFT_ELBOW",
    "RIGHT_ELBOW",
    "LEFT_WRIST",
    "RIGHT_WRIST",
    "LEFT_PINKY",
    "RIGHT_PINKY",
    "LEFT_INDEX",
    "RIGHT_INDEX",
    "LEFT_THUMB",
    "RIGHT_THUMB",
    "LEFT_HIP",
    "RIGHT_HIP",
    "LEFT_KNEE",
    "RIGHT_KNEE",
    "LEFT_ANKLE",
    "RIGHT_ANKLE",
    "LEFT_HEEL",
    "RIGHT_HEEL",
    "LEFT_FOOT_INDEX",
    "RIGHT_FOOT_INDEX",
]
ZED_BODY_38 = [
    "PELVIS",
    "SPINE_1",
    "SPINE_2",
    "SPINE_3",
    "NECK",
    "NOSE",
    "LEFT_EYE",
    "RIGHT_EYE",
    "LEFT_EAR",
    "RIGHT_EAR",
    "LEFT_CLAVICLE",
    "RIGHT_CLAVICLE",
    "LEFT_SHOULDER",
    "RIGHT_SHOULDER",
    "LEFT_ELBOW",
    "RIGHT_ELBOW",
    "LEFT_WRIST",
    "RIGHT_WRIST",
    "LEFT_HIP",
    "RIGHT_HIP",
    "LEFT_KNEE",
    "RIGHT_KNEE",
    "LEFT_ANKLE",
    "RIGHT_ANKLE",
    "LEFT_BIG_TOE",
    "RIGHT_BIG_TOE",
    "LEFT_SMALL_TOE",
    "RIGHT_SMALL_TOE",
    "LEFT_HEEL",
    "RIGHT_HEEL",
    "LEFT_HAND_THUMB_4",
    "RIGHT_HAND_THUMB_4",
    "LEFT_HAND_INDEX_1",
    "RIGHT_HAND_INDEX_1",
    "LEFT_HAND_MIDDLE_4",
    "RIGHT_HAND_MIDDLE_4",
    "LEFT_HAND_PINKY_1",
    "RIGHT_HAND_PINKY_1",
]
CAMERAS = ("k4abt", "zed_body_34", "zed_body_38", "mediapipe_pose")


def truth_at(motion, t):
    return HumanFrame.check(*motion.frame_at(t))


ROBOT_POINTS = np.random.default_rng(5).uniform(-0.6, 0.6, size=(20, 3)) + np.array([0.5, 0.0, 0.5])


def test_the_format_files_are_the_sdks_joint_orders():
    assert skeleton_format("k4abt").joints == tuple(K4ABT)
    assert skeleton_format("zed_body_34").joints == tuple(ZED_BODY_34)
    assert skeleton_format("mediapipe_pose").joints == tuple(MEDIAPIPE)
    assert skeleton_format("zed_body_38").joints == tuple(ZED_BODY_38)
    assert skeleton_format("kinect_v2") is KINECT_V2
    for name in FORMAT_NAMES:
        fmt = skeleton_format(name)
        # every pair swaps a LEFT joint with its RIGHT one
        for a, b in fmt.mirror_pairs:
            assert a.replace("LEFT", "RIGHT").replace("Left", "Right") == b
        assert skeleton_format(name) is fmt  # read once
    assert (
        skeleton_format("k4abt").unit_m == 0.001 and skeleton_format("zed_body_34").unit_m == 0.001
    )
    # the Kinect v2 camera space: x left, y up; the others are the optical frame
    np.testing.assert_array_equal(KINECT_V2.axes_matrix, np.diag([-1.0, -1.0, 1.0]))
    np.testing.assert_array_equal(skeleton_format("k4abt").axes_matrix, np.eye(3))


def test_an_unknown_format_names_the_known_ones():
    with pytest.raises(InputError, match=r"unknown skeleton format .kinect_v3.*k4abt"):
        skeleton_format("kinect_v3")


@pytest.mark.parametrize(
    "name, values, states",
    [
        ("kinect_v2", [0, 1, 2], [0, 1, 2]),
        ("k4abt", [0, 1, 2, 3], [0, 1, 2, 2]),  # NONE, LOW, MEDIUM, HIGH
        ("zed_body_34", [0.0, 19.9, 20.0, 49.9, 50.0, 100.0], [0, 0, 1, 1, 2, 2]),
        ("mediapipe_pose", [0.0, 0.099, 0.1, 0.49, 0.5, 1.0], [0, 0, 1, 1, 2, 2]),
    ],
)
def test_confidence_becomes_states_by_hand(name, values, states):
    conf = skeleton_format(name).confidence
    np.testing.assert_array_equal(conf.states(np.array(values)), states)


@pytest.mark.parametrize(
    "name, bad",
    [
        ("kinect_v2", 3),
        ("k4abt", 4),
        ("k4abt", 1.5),
        ("zed_body_34", 100.5),
        ("zed_body_34", -1),
        ("mediapipe_pose", 1.2),
        ("mediapipe_pose", np.nan),
    ],
)
def test_a_confidence_out_of_range_is_refused_naming_the_joint(name, bad):
    fmt = skeleton_format(name)
    good = {"kinect_v2": 2, "k4abt": 2, "zed_body_34": 80.0, "mediapipe_pose": 0.9}[name]
    confidence = np.full(fmt.n_joints, good, dtype=float)
    confidence[3] = bad
    joints = np.random.default_rng(0).uniform(-0.5, 0.5, (fmt.n_joints, 3)) / fmt.unit_m
    with pytest.raises(InputError, match=f"confidence of {fmt.joints[3]} .*expected"):
        camera_frame(fmt, joints, confidence)


def test_a_camera_frame_in_the_wrong_units_or_types_is_refused():
    """An adversarial tester's cases: a ZED opened in metres (or a streamer that divided by
    1000 already) shrank the body to a millimetre on the camera and the robot moved on;
    booleans passed as confidence were taken as levels."""
    fmt = skeleton_format("zed_body_34")
    metres = np.random.default_rng(1).uniform(-0.5, 0.5, (34, 3)) + np.array([0.0, 0.0, 2.0])
    with pytest.raises(InputError, match="no body is that small; zed_body_34 joints are in mm"):
        camera_frame("zed_body_34", metres, np.full(34, 90.0))
    joints, states = camera_frame("zed_body_34", metres * 1000.0, np.full(34, 90.0))
    np.testing.assert_allclose(joints, metres)  # the name does as the format
    with pytest.raises(InputError, match="must be numeric"):
        camera_frame(fmt, metres * 1000.0, np.full(34, True))
    with pytest.raises(InputError, match="must be numeric"):
        camera_frame(fmt, metres.astype(str), None)
    # an undetected keypoint: NaN position and NaN confidence, not tracked
    lost = metres * 1000.0
    lost[5] = np.nan
    confidence = np.full(34, 90.0)
    confidence[5] = np.nan
    joints, states = camera_frame(fmt, lost, confidence)
    assert states[5] == 0 and (np.delete(states, 5) == 2).all()
    confidence[6] = np.nan  # a detected joint without a confidence: refused
    with pytest.raises(InputError, match=f"confidence of {fmt.joints[6]}"):
        camera_frame(fmt, lost, confidence)


def test_a_k4abt_frame_maps_onto_the_landmarks_by_hand():
    """Millimetres to metres, MEDIUM to tracked, LOW to inferred, the derived landmarks as
    the file writes them, and a landmark one of whose joints is lost is lost."""
    fmt = skeleton_format("k4abt")
    rng = np.random.default_rng(1)
    mm = rng.uniform(-800.0, 800.0, size=(32, 3)) + np.array([0.0, 0.0, 2000.0])
    levels = np.full(32, 2)
    levels[K4ABT.index("CLAVICLE_LEFT")] = 1  # LOW: predicted
    levels[K4ABT.index("HANDTIP_RIGHT")] = 0  # NONE
    body = body_frame("k4abt", mm, levels)
    m = mm / 1000.0
    j = {name: m[k] for k, name in enumerate(K4ABT)}
    np.testing.assert_allclose(body.joints[KINECT_V2.index("SpineBase")], j["PELVIS"])
    np.testing.assert_allclose(
        body.joints[KINECT_V2.index("SpineMid")], (j["SPINE_NAVEL"] + j["SPINE_CHEST"]) / 2
    )
    np.testing.assert_allclose(
        body.joints[KINECT_V2.index("Neck")],
        j["SPINE_CHEST"] + 0.8 * (j["NECK"] - j["SPINE_CHEST"]),
    )
    shoulder = KINECT_V2.index("SpineShoulder")
    np.testing.assert_allclose(
        body.joints[shoulder], (j["CLAVICLE_LEFT"] + j["CLAVICLE_RIGHT"]) / 2
    )
    assert body.state[shoulder] == 1  # the worst of its joints: one was LOW
    tip = KINECT_V2.index("HandTipRight")
    assert body.state[tip] == 0 and np.isnan(body.joints[tip]).all()
    assert (np.delete(body.state, [shoulder, tip]) == 2).all()
    # its uncertainty: the derived landmarks only
    derived = {"SpineMid", "Neck", "SpineShoulder"}
    u = landmark_map(fmt).uncertainty_m
    assert {KINECT_V2.joints[k] for k in np.flatnonzero(u)} == derived


def test_the_kinect_v2_maps_onto_itself_unchanged():
    joints = np.random.default_rng(2).normal(size=(25, 3))
    state = np.full(25, 2, dtype=np.int8)
    out = landmark_map(KINECT_V2).map(joints, state)
    assert out.joints is joints and out.state is state
    assert landmark_map(KINECT_V2).identity and not landmark_map(skeleton_format("k4abt")).identity


@pytest.mark.parametrize("name", CAMERAS)
def test_each_landmark_comes_back_within_its_uncertainty_over_random_postures(name):
    """The true body filmed as the format's joints ([simulate]) and mapped back
    ([landmarks]): a landmark the camera measures comes back exactly, a derived one within
    the uncertainty the file gives it (which the perception adds), over 300 postures."""
    fmt = skeleton_format(name)
    to_body, films = landmark_map(fmt), LandmarkMap.simulated(fmt)
    rng = np.random.default_rng(3)
    worst = np.zeros(25)
    for _ in range(300):
        truth = random_posture(rng, ROBOT_POINTS)
        seen = films.map(truth, np.full(25, 2, dtype=np.int8))
        back = to_body.map(seen.joints, seen.state)
        assert (back.state == 2).all()
        worst = np.maximum(worst, np.linalg.norm(back.joints - truth, axis=1))
    measured = to_body.uncertainty_m == 0
    assert worst[measured].max() < 1e-12
    assert (worst[~measured] <= to_body.uncertainty_m[~measured]).all(), dict(
        zip(np.array(KINECT_V2.joints)[~measured], worst[~measured].round(3), strict=True)
    )


@pytest.mark.parametrize(
    "rule, message",
    [
        ({"weights": {"A": 0.5, "B": 0.4}}, "summing to 1"),
        (
            {"lerp": ["A", "B"], "t": 3.0},
            r"landmarks.Neck.t must be a number at least -1 and at most 2, got 3.0",
        ),
        ({"lerp": ["A"], "t": 0.5}, "two joints"),
        ({"mean": ["A"], "t": 0.5}, "t goes with lerp"),
        ({"mean": []}, "must name joints"),
        ({"joint": "A", "mean": ["B"]}, "one of joint, mean, lerp or weights"),
        (
            {"mean": ["A", "B"], "uncertainty_m": 0.9},
            "landmarks.Neck.uncertainty_m must be a number at least 0 and at most 0.5",
        ),
        (3, "a joint name or a table"),
    ],
)
def test_a_bad_rule_is_refused_with_its_key(rule, message):
    with pytest.raises(SkeletonFormatError, match=message):
        parse_rule(rule, "landmarks.Neck")


@pytest.mark.parametrize(
    "change, message",
    [
        ({"units": "cm"}, "units must be one of"),
        ({"axes": ["left", "right", "up"]}, "three perpendicular directions"),
        (
            {
                "confidence": {
                    "kind": "score",
                    "range": [0, 1],
                    "inferred_at": 0.6,
                    "tracked_at": 0.5,
                }
            },
            "inferred_at",
        ),
        ({"confidence": {"kind": "levels", "levels": [0, 1, 5]}}, "states"),
        ({"landmarks": {"SpineBase": "NOPE"}}, "unknown joint 'NOPE'"),
        ({"body": ""}, "body and \\[landmarks\\] together"),
    ],
)
def test_a_bad_camera_format_file_is_refused(tmp_path, change, message):
    import tomllib

    from qpavoid.human.skeleton_file import FORMATS_DIR

    data = tomllib.loads((FORMATS_DIR / "k4abt.toml").read_text())
    data.update(change)
    with pytest.raises(SkeletonFormatError, match=message):
        SkeletonFormat.from_mapping(data)


def test_a_rule_that_misses_a_landmark_is_refused():
    import tomllib

    from qpavoid.human.skeleton_file import FORMATS_DIR

    data = tomllib.loads((FORMATS_DIR / "k4abt.toml").read_text())
    del data["landmarks"]["Head"]
    with pytest.raises(SkeletonFormatError, match="it lacks \\['Head'\\]"):
        LandmarkMap.to_body(SkeletonFormat.from_mapping(data))


def test_the_simulated_kinect_v2_is_the_one_before():
    """CameraConfig.of("kinect_v2") is the default camera: the same frames, bit for bit."""
    robot = load_robot("iiwa14")
    scenario = make_scenario("test2", robot)
    a, b = (
        Camera(scenario, CameraConfig(seed=4)),
        Camera(scenario, CameraConfig.of("kinect_v2", seed=4)),
    )
    for t in np.arange(0.0, 3.0, 0.07):
        (fa, ca), (fb, cb) = a.frame_at(t), b.frame_at(t)
        assert ca == cb
        np.testing.assert_array_equal(fa.joints, fb.joints)


def test_each_simulated_camera_has_its_files_numbers_and_failures():
    robot = load_robot("iiwa14")
    scenario = make_scenario("test1", robot)
    for name in CAMERAS:
        cfg = CameraConfig.of(name, seed=1)
        sensor = skeleton_format(name).sensor
        assert (cfg.latency_s, cfg.noise_m, cfg.format) == (sensor.latency_s, sensor.noise_m, name)
    # the ZED's noise grows with the square of the range: a camera twice as far, 4x the noise
    errors = {}
    for away in (1.0, 2.0):
        position = tuple(
            Operator().rest()[KINECT_V2.index("SpineShoulder")] + np.array([0.0, -away, 0.0])
        )
        cam = Camera(
            scenario, CameraConfig.of("zed_body_34", latency_s=0.0, sensor_position_m=position)
        )
        hand = KINECT_V2.index("HandLeft")  # a measured landmark, near the chest's range
        errors[away] = np.std(
            [
                cam.frame_at(t)[0].joints[hand]
                - truth_at(scenario, cam.frame_at(t)[1]).joints[hand]
                for t in np.arange(0.0, 6.0, 1 / 30)
            ]
        )
    assert 2.5 < errors[2.0] / errors[1.0] < 6.0, errors
    # MediaPipe swaps left and right: at its rate, a swapped frame puts the left hand where
    # the right one is
    cam = Camera(scenario, CameraConfig.of("mediapipe_pose", latency_s=0.0, noise_m=0.0))
    left, right = KINECT_V2.index("ElbowLeft"), KINECT_V2.index("ElbowRight")
    swapped = 0
    times = np.arange(0.0, 200.0, 0.5)
    for t in times:
        seen, captured = cam.frame_at(t)
        truth = truth_at(scenario, captured).joints
        swapped += bool(np.allclose(seen.joints[left], truth[right]))
    expected = len(times) * skeleton_format("mediapipe_pose").sensor.left_right_swap_per_s * 0.5
    assert 0.3 * expected <= swapped <= 3 * expected, (swapped, expected)


def test_the_controller_takes_a_frame_of_any_format():
    """A k4abt frame given with camera_format is the mapped body given to a controller
    whose perception knows the format's landmark uncertainty: the same commands, tick by
    tick; a frame of the wrong size for its format is refused."""
    robot = load_robot("iiwa14")
    fmt = skeleton_format("k4abt")
    films, to_body = LandmarkMap.simulated(fmt), landmark_map(fmt)
    scenario = make_scenario("test1", robot)
    extra = tuple(float(u) for u in to_body.uncertainty_m)
    mine = AnalyticController(robot)
    other = AnalyticController(
        robot, config=ControllerConfig(perception=PerceptionConfig(landmark_uncertainty_m=extra))
    )
    q = q_other = inverse_kinematics(robot, mine.path.reference(0.0)[0])
    rng = np.random.default_rng(0)
    for k in range(300):
        t = k * 0.01
        truth = truth_at(scenario, t)
        seen = films.map(truth.joints + rng.normal(0, 0.002, (25, 3)), truth.state)
        a = mine.step(q, seen.joints, seen.state, t, frame_age_s=0.0, camera_format="k4abt")
        b = other.step(q_other, *to_body.map(seen.joints, seen.state), t, frame_age_s=0.0)
        np.testing.assert_array_equal(a.dq, b.dq)
        q, q_other = q + a.dq * 0.01, q_other + b.dq * 0.01
    radius = mine.perceiver.perceived[0].joint_radius
    assert (radius >= to_body.uncertainty_m - 1e-12).all()
    assert radius[KINECT_V2.index("SpineShoulder")] >= 0.05
    with pytest.raises(InputError, match=r"must have shape \(32, 3\)"):
        mine.step(q, np.zeros((25, 3)), None, 0.0, camera_format="k4abt")
    with pytest.raises(InputError, match="unknown skeleton format"):
        mine.step(q, np.zeros((25, 3)), None, 0.0, camera_format="kinect_v1")


def test_a_run_names_its_camera():
    assert RunSpec("test1", camera="mediapipe_pose").sensor_latency_s == 0.1
    assert RunSpec("test1").sensor_latency_s == KINECT_V2.sensor.latency_s
    assert RunSpec("test1", camera="k4abt", latency_s=0.2).sensor_latency_s == 0.2
    with pytest.raises(InputError, match="camera"):
        RunSpec("test1", camera="kinect_v1")


def test_confidence_tables_are_checked():
    with pytest.raises(SkeletonFormatError, match="kind"):
        Confidence(kind="stars")
    with pytest.raises(SkeletonFormatError, match="level_names"):
        Confidence(kind="levels", levels=(0, 2), level_names=("NONE",))


@pytest.mark.parametrize("name", ["k4abt", "zed_body_34", "zed_body_38"])
def test_a_simulated_camera_puts_derived_landmarks_anywhere_within_their_uncertainty(name):
    """The simulated camera does not hand back the rule's own point: each person's derived
    landmarks are off by a random anatomy within the rule's uncertainty (what the
    perception widens them by), so that the safety campaigns test the uncertainty."""
    scenario = make_scenario("test1", load_robot("iiwa14"))
    u = landmark_map(skeleton_format(name)).uncertainty_m
    errors = []
    for seed in range(30):
        cam = Camera(scenario, CameraConfig.of(name, seed=seed, noise_m=0.0))
        frame, captured = cam.frame_at(1.0)
        errors.append(np.linalg.norm(frame.joints - truth_at(scenario, captured).joints, axis=1))
    worst = np.max(errors, axis=0)
    assert (worst <= u + 1e-9).all()
    assert (worst[u > 0] > 0.7 * u[u > 0]).all()  # the whole ball is used
    assert worst[u == 0].max() < 1e-9


def test_a_runs_controller_knows_its_cells_cameras(tmp_path):
    """The simulated camera's format, and each calibrated sensor's: the largest landmark
    uncertainty and Z_d of them reach the perception and speed and separation."""
    robot = load_robot("iiwa14")
    calibration = Calibration(
        {
            "kinect": SensorCalibration("kinect", np.eye(4)),
            "femto": SensorCalibration("femto", np.eye(4), format="k4abt"),
        }
    )
    path = tmp_path / "calib.toml"
    path.write_text(calibration.to_toml())
    fused = RunSpec(human_file=None, sensors=str(path), listen="127.0.0.1:5005")
    config = build_controller(fused, robot).config
    k4abt = landmark_map(skeleton_format("k4abt")).uncertainty_m
    np.testing.assert_array_equal(config.perception.landmark_uncertainty_m, k4abt)
    assert config.ssm.sensing_uncertainty_m == skeleton_format("k4abt").sensor.tracked_uncertainty_m
    # one camera of another format: its own body model on its own joints, nothing widened
    alone = build_controller(RunSpec("test1", camera="mediapipe_pose"), robot)
    assert alone.human.skeleton.name == "mediapipe_pose"
    assert alone.config.perception.landmark_uncertainty_m == ()
    assert alone.config.ssm.sensing_uncertainty_m == 0.05  # mediapipe_pose.toml's Z_d
    # ... but a recording of derived landmarks keeps the landmarks' path, widened
    mediapipe = landmark_map(skeleton_format("mediapipe_pose")).uncertainty_m
    recorded = tmp_path / "mp.csv"  # its format is read from the header alone
    recorded.write_text(",".join(csv_header(skeleton_format("mediapipe_pose"))) + "\n")
    replay = build_controller(
        RunSpec(human_file=str(recorded), camera="mediapipe_pose"), robot
    ).config
    np.testing.assert_array_equal(replay.perception.landmark_uncertainty_m, mediapipe)
    kinect = build_controller(RunSpec("test1"), robot).config
    assert kinect.perception == PerceptionConfig()  # a Kinect v2 cell: as before
    assert kinect.ssm.sensing_uncertainty_m == KINECT_V2.sensor.tracked_uncertainty_m


@pytest.mark.parametrize("lost", [("RIGHT_SHOULDER", "RIGHT_ELBOW", "RIGHT_WRIST")])
def test_an_arm_never_seen_beside_the_robot_stops_it(lost):
    """An adversarial tester's case: MediaPipe's spine derives from both shoulders, so a
    shoulder lost from the first frame lost the whole spine; the arm, with no tracked
    ancestor, stayed missing and the robot moved on beside the hand's tracked knuckles.
    Now the arm is bounded by the nearest tracked joint along the tree (the thumb)."""
    robot = load_robot("iiwa14")
    fmt = skeleton_format("mediapipe_pose")
    controller = AnalyticController(robot)
    q = inverse_kinematics(robot, controller.path.reference(0.0)[0])
    ee = robot.kinematics(q).ee_placement[:3, 3]
    body = Operator().reach(Operator().rest(), "right", ee + np.array([0.0, 0.10, 0.0]))
    seen = LandmarkMap.simulated(fmt).map(body, np.full(25, 2, dtype=np.int8))
    joints, state = seen.joints.copy(), seen.state.copy()
    joints[fmt.indices(list(lost))], state[fmt.indices(list(lost))] = np.nan, 0
    mapped = landmark_map(fmt).map(joints, state)
    assert mapped.state[KINECT_V2.index("SpineShoulder")] == 0  # the spine is lost too
    for k in range(100):
        wobble = joints + 1e-4 * np.sin(k)  # a live sensor: never bit-identical
        command = controller.step(
            q, wobble, state, 1.0, frame_age_s=0.0, frame_id=k, camera_format=fmt
        )
        assert command.stopped and not np.any(command.dq), (k, command.reason)
        q = q + command.dq * 0.002
    radius = controller.perceiver.perceived[0].joint_radius
    assert np.isfinite(radius).all() and radius[KINECT_V2.index("WristRight")] > 0


def test_a_replayed_recording_of_a_camera_is_widened_as_that_camera(tmp_path):
    """An adversarial tester's case: ``run --human femto.npz`` replayed a k4abt recording
    with no widening of its derived landmarks."""
    fmt = skeleton_format("k4abt")
    body = Operator().rest()
    seen = LandmarkMap.simulated(fmt).map(body, np.full(25, 2, dtype=np.int8))
    path = tmp_path / "femto.npz"
    np.savez(
        path,
        t=np.arange(3) / 30,
        joints=np.repeat(seen.joints[None], 3, axis=0),
        state=np.repeat(seen.state[None], 3, axis=0),
        format="k4abt",
    )
    config = build_controller(RunSpec(human_file=str(path)), load_robot("iiwa14")).config
    np.testing.assert_array_equal(
        config.perception.landmark_uncertainty_m, landmark_map(fmt).uncertainty_m
    )


@pytest.mark.slow
@pytest.mark.parametrize("name", CAMERAS)
def test_strikes_through_each_camera_never_move_in_true_contact(name):
    """A short campaign through each format's simulated camera (its latency, noise, joint
    set, derived landmarks off by a random anatomy, swaps): the sweep of docs/safety.md,
    20 strikes per format here (the 1000-strike figures are docs/safety.md's)."""
    checks = strike_sweep(range(20), "qp", "ssm", camera=name, workers=1)
    assert sum(c.ticks_moving_in_true_contact for c in checks) == 0
    assert sum(c.command_limit_violations for c in checks) == 0


def test_a_camera_frame_written_into_the_same_buffer_each_tick_is_new_each_tick():
    """A caller that reuses one array for every frame (as a driver's buffer does) gets each
    new content mapped, never the first frame held."""
    robot = load_robot("iiwa14")
    fmt = skeleton_format("k4abt")
    films = LandmarkMap.simulated(fmt)
    controller = AnalyticController(robot)
    q = inverse_kinematics(robot, controller.path.reference(0.0)[0])
    buffer = np.empty((32, 3))
    state = np.full(32, 2, dtype=np.int8)
    body = Operator().rest()
    for k in range(3):
        buffer[:] = films.map(body + np.array([0.0, 0.0, 0.01 * k]), np.full(25, 2, np.int8)).joints
        controller.step(q, buffer, state, 0.0, frame_age_s=0.0, camera_format="k4abt")
        head = controller.closest_frame.joints[KINECT_V2.index("Head")]
        np.testing.assert_allclose(
            head, body[KINECT_V2.index("Head")] + np.array([0.0, 0.0, 0.01 * k])
        )
