"""The Jacobian at each witness point is the velocity of that point on the body carrying it.

On every shipped arm (and a description that places points and capsule ends as offsets
from frames), at random configurations and random person points, for both distance
methods, against finite differences of Pinocchio's forward kinematics alone (q perturbed
by ±1e-7 rad, the point held fixed on its body; no Jacobian of Pinocchio's is used):

* the Jacobian the distance table gives for each pair (``DistanceTable.robot_jacobians``:
  the sphere's centre, the control point of eq. (6); for capsules the witness point's
  projection on the axis) is the velocity of that point on its body;
* the velocity-damper rows the QP builds (``−nᵀ J``) are minus the derivative of the
  distance itself (the table recomputed at the perturbed q), which is also ``nᵀ`` the
  velocity of the surface witness point held on its body: the sphere's and the capsule's
  surface points differ from the centre by ``−r n``, whose velocity ``ω × (−r n)`` is
  normal to ``n``.

Agreement within 1e-6 (measured: 2e-9, central differences' rounding, on each arm).
"""

from __future__ import annotations

import shutil
from importlib import resources
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

import qpavoid
from qpavoid.control.qp.kernels import damper_rows, pair_inputs
from qpavoid.core.errors import RobotDescriptionError
from qpavoid.distance.coal_capsules import axis_rotation
from qpavoid.distance.methods import CapsuleDistance, SphereDistance

#: Finite-difference step, rad (central differences: error ~ h² · q̈-terms + ε/h ≈ 2e-9).
H = 1e-7
#: Allowed difference between a Jacobian and its finite differences, m/rad.
TOL = 1e-6
#: Random configurations per arm (each with its own person).
N_CONFIGURATIONS = 12
#: The redundant arms: seven joints once their descriptions' ``locked`` is lifted (the
#: QP's redundant mode), the iiwa's A3, the Panda's and FR3's joint3.
REDUNDANT_ARMS = ("iiwa14", "panda", "fr3")
#: The arms shipped (issue 26), as their descriptions lock them and (``True``) redundant.
SHIPPED = [(name, False) for name in ("iiwa14", "panda", "ur5", "fr3")] + [
    (name, True) for name in REDUNDANT_ARMS
]

#: Three sets added to the iiwa's description, none with a part in the paper's laws, with
#: points and capsule ends as ``{ frame, xyz }`` offsets: a column around the base
#: (before L1), a pad on the elbow's link off every joint axis (between L1 and L2) and a
#: tool on the flange (after EE): six sets, the paper's three unchanged among them.
EXTRA_SETS = {
    "column": """[[sets]]
name = "column"
sphere_radius_m = 0.09
points = [["A1", "A2"]]
capsule = { from = "A1", to = "A2", capsule_radius_m = 0.07 }
""",
    "elbow_pad": """[[sets]]
name = "elbow_pad"
sphere_radius_m = 0.05
points = [
  { frame = "A4", xyz = [0.07, 0.0, 0.05] },
  { frame = "A4", xyz = [0.07, 0.0, 0.15] },
]
[sets.capsule]
from = { frame = "A4", xyz = [0.07, 0.0, 0.05] }
to = { frame = "A4", xyz = [0.07, 0.0, 0.15] }
capsule_radius_m = 0.03
""",
    "tool": """[[sets]]
name = "tool"
sphere_radius_m = 0.04
points = [
  { frame = "flange", xyz = [0.0, 0.0, 0.05] },
  { frame = "flange", xyz = [0.0, 0.0, 0.1] },
]
[sets.capsule]
from = "flange"
to = { frame = "flange", xyz = [0.0, 0.0, 0.1] }
capsule_radius_m = 0.03
""",
}
#: The six sets in order.
SIX_SETS = ("column", "L1", "elbow_pad", "L2", "EE", "tool")


def load_arm(name: str, redundant: bool = False) -> qpavoid.Robot:
    """A shipped arm as its description locks it or, ``redundant``, with nothing locked
    (the QP's redundant mode; joints the description holds, a gripper's fingers, stay
    held); or a skip saying why it cannot be loaded yet (its description not written, or
    its URDF's package not installed)."""
    if not (resources.files("qpavoid.robots") / name / "control_points.toml").is_file():
        pytest.skip(f"robots/{name}/control_points.toml does not exist yet")
    try:
        return qpavoid.load_robot(name, locked=() if redundant else None)
    except RobotDescriptionError as exc:
        if "is not installed" in str(exc):
            pytest.skip(str(exc))
        raise


def six_set_description(folder: Path) -> Path:
    """The iiwa's description with :data:`EXTRA_SETS` added (:data:`SIX_SETS`), written into
    ``folder`` beside a copy of its URDF."""
    src = resources.files("qpavoid.robots") / "iiwa14"
    folder.mkdir(parents=True, exist_ok=True)
    shutil.copy(str(src / "iiwa14.urdf"), folder)
    text = (src / "control_points.toml").read_text()
    first = text.index("[[sets]]")
    text = text[:first] + EXTRA_SETS["column"] + "\n" + text[first:]
    l2 = text.index('[[sets]]\nname = "L2"')
    text = text[:l2] + EXTRA_SETS["elbow_pad"] + "\n" + text[l2:]
    roles = text.index("# Which set plays")
    text = text[:roles] + EXTRA_SETS["tool"] + "\n" + text[roles:]
    (folder / "control_points.toml").write_text(text)
    return folder


@pytest.fixture(scope="module")
def six_sets(tmp_path_factory) -> Path:
    return six_set_description(tmp_path_factory.mktemp("arms") / "six_sets")


def carrying_body(robot: qpavoid.Robot, frames: tuple[int, int], rng) -> int:
    """A body that carries both capsule ends as points fixed on it (forward kinematics
    only): each end keeps its place in the body's frame at random configurations. A joint
    between the ends that turns about the capsule's axis leaves them fixed on the body
    before it."""
    model, data = robot.model, robot.model.createData()
    qs = [rng.uniform(robot.q_min, robot.q_max) for _ in range(4)]
    for body in range(model.njoints):
        placed = []
        for q in qs:
            pin.framesForwardKinematics(model, data, q)
            placed.append([data.oMi[body].actInv(data.oMf[f].translation) for f in frames])
        if np.abs(np.array(placed) - placed[0]).max() < 1e-12:
            return body
    raise AssertionError(f"no body carries both ends of frames {frames}")


def person_near(robot: qpavoid.Robot, kin, rng) -> np.ndarray:
    """(25, 3) Kinect joints scattered 0-0.5 m around random control points, m."""
    P = kin.points
    return P[rng.integers(len(P), size=25)] + rng.normal(scale=0.25, size=(25, 3))


def witness_errors(robot: qpavoid.Robot, seed: int = 0) -> dict[str, tuple[float, float, int]]:
    """Per distance method: the largest difference between the table's Jacobians and the
    finite differences of their points held on their bodies, and between the damper rows
    and minus the finite differences of the distance (m/rad), over ``N_CONFIGURATIONS``
    random configurations and people; and the number of pairs compared."""
    rng = np.random.default_rng(seed)
    human = qpavoid.KinectHuman()
    model, data = robot.model, robot.model.createData()
    bodies = [carrying_body(robot, s.capsule_frames, rng) for s in robot.sets]
    methods = [SphereDistance(robot, human), CapsuleDistance(robot, human)]
    out = {m.method: (0.0, 0.0, 0) for m in methods}
    for _ in range(N_CONFIGURATIONS):
        q = rng.uniform(robot.q_min + 0.05, robot.q_max - 0.05)
        kin = robot.kinematics(q)
        geo = human.geometry(person_near(robot, kin, rng))
        for method in methods:
            table = method(kin, geo)
            S, K = table.distance.shape
            sets, parts = np.divmod(np.arange(S * K), K)
            J = table.robot_jacobians(kin, sets, parts)  # (A, 3, nv)
            # the point each Jacobian is of, and the body carrying it
            if table.method == "spheres":
                idx = table.robot_index.ravel()
                points = kin.points[idx]
                body = [model.frames[robot.point_frames[p]].parentJoint for p in idx]
            else:
                s = table.robot_s.ravel()[:, None]
                points = (1.0 - s) * kin.segments[sets, 0] + s * kin.segments[sets, 1]
                body = [bodies[i] for i in sets]
            pin.forwardKinematics(model, data, q)
            local = [data.oMi[b].actInv(x) for b, x in zip(body, points, strict=True)]
            G, h = np.zeros((S * K, robot.nv + 2)), np.zeros(S * K)
            every = np.full(S * K, -1.0)  # every row active: d_i above every distance
            damper_rows(
                table.distance.ravel(), *pair_inputs(table, kin), every, 10.0, 0.25,
                np.zeros(S * K), G, h,
            )  # fmt: skip
            fd_J, fd_d = np.empty_like(J), np.empty((S * K, robot.nv))
            for k in range(robot.nv):
                moved = []
                for sign in (1.0, -1.0):
                    qk = q.copy()
                    qk[k] += sign * H
                    pin.forwardKinematics(model, data, qk)
                    held = [data.oMi[b].act(x) for b, x in zip(body, local, strict=True)]
                    d = method(robot.kinematics(qk, jacobians=False), geo).distance
                    moved.append((np.array(held), d.ravel()))
                fd_J[:, :, k] = (moved[0][0] - moved[1][0]) / (2 * H)
                fd_d[:, k] = (moved[0][1] - moved[1][1]) / (2 * H)
            apart = table.distance.ravel() > 1e-6  # coal's normal under contact: not a gradient
            worst_J, worst_d, n = out[table.method]
            out[table.method] = (
                max(worst_J, float(np.abs(J - fd_J)[apart].max())),
                max(worst_d, float(np.abs(G[:, : robot.nv] + fd_d)[apart].max())),
                n + int(apart.sum()),
            )
    return out


def assert_exact(robot: qpavoid.Robot) -> None:
    errors = witness_errors(robot)
    for method, (worst_J, worst_d, n) in errors.items():
        assert n > 0, method
        assert worst_J < TOL, f"{method}: Jacobian off by {worst_J:.2e} m/rad"
        assert worst_d < TOL, f"{method}: damper row off by {worst_d:.2e} m/rad"


@pytest.mark.parametrize(
    "name, redundant", SHIPPED, ids=[n + ("_redundant" if r else "") for n, r in SHIPPED]
)
def test_witness_jacobians_are_finite_differences_on_every_shipped_arm(name, redundant):
    robot = load_arm(name, redundant)
    assert robot.nv == (7 if redundant else 6)
    assert_exact(robot)


@pytest.mark.parametrize("locked", [None, ()], ids=["A3_locked", "A3_free"])
def test_witness_jacobians_with_offsets_and_six_sets(six_sets, locked):
    """Points and capsule ends given as ``{ frame, xyz }`` offsets, on six sets."""
    robot = qpavoid.load_robot(six_sets, locked=locked)
    assert robot.set_names == SIX_SETS
    assert_exact(robot)


def test_the_finite_differences_see_a_wrong_body():
    """The check can fail: the same points held on the next body out (the wrist's capsule
    on A6's body instead of the one carrying it) differ by far more than the tolerance."""
    robot = qpavoid.load_robot("iiwa14")
    model, data = robot.model, robot.model.createData()
    rng = np.random.default_rng(1)
    q = rng.uniform(robot.q_min, robot.q_max)
    kin = robot.kinematics(q)
    cs = robot.sets[robot.roles.repelled]  # L2: A4 -> A6, carried by A4's body
    body = carrying_body(robot, cs.capsule_frames, rng)
    wrong = model.frames[cs.capsule_frames[1]].parentJoint  # A6's own body, past the wrist
    assert wrong != body
    a, b = kin.segments[robot.roles.repelled]
    x = 0.5 * (a + b)
    J = kin.segment_point_jacobian(robot.roles.repelled, 0.5)
    pin.forwardKinematics(model, data, q)
    errors = []
    for held in (body, wrong):
        local = data.oMi[held].actInv(x)
        fd = np.empty((3, robot.nv))
        for k in range(robot.nv):
            ends = []
            for sign in (1.0, -1.0):
                qk = q.copy()
                qk[k] += sign * H
                pin.forwardKinematics(model, data, qk)
                ends.append(data.oMi[held].act(local))
            fd[:, k] = (ends[0] - ends[1]) / (2 * H)
        errors.append(float(np.abs(fd - J).max()))
    assert errors[0] < TOL < 0.01 < errors[1]


def test_axis_rotation_is_exact_near_minus_z():
    """The capsules' axis rotation takes z onto u to rounding even as u nears −z, where
    ``FromTwoVectors(z, u)`` loses digits (1.3e-10 at 1 + u_z = 9e-7: the capsule distance
    then moved by 1e-12 m between q ± 1e-7 rad, a finite difference off by 6e-5)."""
    rng = np.random.default_rng(3)
    naive = []
    for tilt in (1e-2, 1e-3, 1e-4, 1e-5, 0.0):
        for _ in range(20):
            side = rng.normal(size=2)
            u = np.array([*(tilt * side / np.linalg.norm(side)), -1.0])
            u /= np.linalg.norm(u)
            R = axis_rotation(u).matrix()
            assert np.abs(R[:, 2] - u).max() < 1e-15
            assert np.abs(R @ R.T - np.eye(3)).max() < 1e-15
            if tilt:
                smallest = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), u).matrix()
                naive.append(np.abs(smallest[:, 2] - u).max())
    assert max(naive) > 1e-12  # what it replaces
