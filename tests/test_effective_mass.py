"""The arm's effective mass (qpavoid.arm.inertia): against closed forms on toy arms, against
the kinetic energy on the iiwa, the payload's exact effect, the refusals, and the rated payload
of the ``[arm]`` table."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from qpavoid.arm.dynamics import read_arm
from qpavoid.arm.inertia import EffectiveMass
from qpavoid.arm.model import load_robot
from qpavoid.core.errors import InputError, RobotDescriptionError

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

ROBOTS = Path(__file__).resolve().parents[1] / "robots"


@pytest.fixture(scope="module")
def iiwa():
    return load_robot("iiwa14", coverage=False)


def pendulum(mass_kg: float, length_m: float) -> tuple[pin.Model, int]:
    """A point mass on a massless link of length L, turning about z: M = m L²."""
    model = pin.Model()
    joint = model.addJoint(0, pin.JointModelRZ(), pin.SE3.Identity(), "j1")
    tip = np.array([length_m, 0.0, 0.0])
    model.appendBodyToJoint(joint, pin.Inertia(mass_kg, tip, np.zeros((3, 3))), pin.SE3.Identity())
    frame = model.addFrame(pin.Frame("tip", joint, pin.SE3(np.eye(3), tip), pin.FrameType.OP_FRAME))
    return model, frame


def slider(mass_kg: float) -> tuple[pin.Model, int]:
    """A mass sliding along x: M = m."""
    model = pin.Model()
    joint = model.addJoint(0, pin.JointModelPX(), pin.SE3.Identity(), "j1")
    model.appendBodyToJoint(joint, pin.Inertia.FromSphere(mass_kg, 0.05), pin.SE3.Identity())
    frame = model.addFrame(pin.Frame("tip", joint, pin.SE3.Identity(), pin.FrameType.OP_FRAME))
    return model, frame


# -- closed forms ---------------------------------------------------------------------------


def test_a_point_mass_on_a_massless_link_weighs_its_mass_along_the_tangent():
    m, L = 2.5, 0.4
    mass = EffectiveMass.from_model(*pendulum(m, L), name="pendulum")
    for q in (0.0, 0.7, -2.0):
        # the tip's velocity is L q̇ along the tangent (-sin q, cos q, 0): J by hand
        tangent = np.array([-math.sin(q), math.cos(q), 0.0])
        radial = np.array([math.cos(q), math.sin(q), 0.0])
        jac = np.broadcast_to((L * tangent)[:, None], (4, 3, 1))
        normals = np.array([tangent, -tangent, radial, tangent + radial])  # last: not unit
        m_r = mass(np.array([q]), jac, normals)
        assert m_r[0] == pytest.approx(m, rel=1e-12) and m_r[1] == pytest.approx(m, rel=1e-12)
        assert m_r[2] == math.inf  # no joint moves the tip radially
        assert m_r[3] == pytest.approx(2.0 * m, rel=1e-12)  # cos² 45° = 1/2
    np.testing.assert_allclose(mass.minverse([0.3]), [[1.0 / (m * L * L)]], rtol=1e-12)


def test_the_payload_sits_at_the_end_effector_frame_s_origin():
    m, L, p = 2.5, 0.4, 1.5
    model, frame = pendulum(m, L)
    mass = EffectiveMass.from_model(model, frame, name="pendulum", payload_kg=p)
    jac = np.array([[[0.0], [L], [0.0]]])  # at q = 0
    assert mass([0.0], jac, [[0.0, 1.0, 0.0]])[0] == pytest.approx(m + p, rel=1e-12)
    assert model.inertias[1].mass == m  # the model given is never changed
    assert mass.model.inertias[1].mass == pytest.approx(m + p)


def test_a_slider_weighs_its_mass_along_its_axis_only():
    mass = EffectiveMass.from_model(*slider(4.0), name="slider", payload_kg=1.0)
    jac = np.array([[[1.0], [0.0], [0.0]]] * 3)
    m_r = mass([0.2], jac, [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 0.0, 0.0]])
    assert m_r[0] == pytest.approx(5.0, rel=1e-12)
    assert m_r[1] == math.inf and m_r[2] == math.inf  # a zero direction: the heaviest case


# -- the iiwa: energy, Pinocchio's M, the payload ------------------------------------------


def test_the_effective_mass_is_the_least_kinetic_energy_that_moves_the_point(iiwa):
    mass = EffectiveMass(iiwa)
    rng = np.random.default_rng(7)
    for _ in range(5):
        q = rng.uniform(iiwa.q_min, iiwa.q_max)
        kin = iiwa.kinematics(q)
        jac = kin.point_jacobians  # (9, 3, nv)
        n = rng.normal(size=(len(jac), 3))
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        m_r = mass(q, jac, n)
        upper = pin.crba(iiwa.model, iiwa.model.createData(), q)  # independent of M⁻¹
        M = np.triu(upper) + np.triu(upper, 1).T
        np.testing.assert_allclose(mass.minverse(q) @ M, np.eye(iiwa.nv), atol=1e-9)
        assert np.all(m_r > 0.0) and np.all(np.isfinite(m_r))
        for a in range(len(jac)):
            row = n[a] @ jac[a]  # nᵀ J
            for dq in rng.normal(size=(20, iiwa.nv)):  # ½ q̇ᵀ M q̇ ≥ ½ m_R (nᵀ J q̇)²
                assert 0.5 * dq @ M @ dq >= 0.5 * m_r[a] * (row @ dq) ** 2 * (1 - 1e-12)
            best = np.linalg.solve(M, row)  # q̇ = M⁻¹ Jᵀ n: equality
            kinetic = 0.5 * best @ M @ best
            assert kinetic == pytest.approx(0.5 * m_r[a] * (row @ best) ** 2, rel=1e-9)


def test_one_call_equals_one_call_per_point(iiwa):
    mass = EffectiveMass(iiwa)
    q = iiwa.neutral() + 0.3
    kin = iiwa.kinematics(q)
    n = np.tile([0.0, 0.6, 0.8], (len(kin.point_jacobians), 1))
    together = mass(q, kin.point_jacobians, n)
    alone = [mass(q, j[None], v[None])[0] for j, v in zip(kin.point_jacobians, n)]
    np.testing.assert_allclose(together, alone, rtol=1e-12)
    assert mass(q, np.zeros((1, 3, iiwa.nv)), n[:1])[0] == math.inf  # a point no joint moves


def test_the_payload_adds_exactly_itself_to_the_end_effector_s_operational_inertia(iiwa):
    p = 3.0
    last = iiwa.model.njoints - 1
    before = iiwa.model.inertias[last].mass
    bare, loaded = EffectiveMass(iiwa), EffectiveMass(iiwa, payload_kg=p)
    rng = np.random.default_rng(11)
    for _ in range(5):
        q = rng.uniform(iiwa.q_min, iiwa.q_max)
        J = iiwa.kinematics(q).ee_jacobian[:3]  # the end-effector frame origin's velocity
        # Λ = (J M⁻¹ Jᵀ)⁻¹ gains p I exactly (Woodbury: M' = M + p JᵀJ)
        lam = np.linalg.inv(J @ bare.minverse(q) @ J.T)
        lam_loaded = np.linalg.inv(J @ loaded.minverse(q) @ J.T)
        np.testing.assert_allclose(lam_loaded - lam, p * np.eye(3), atol=1e-6 * np.abs(lam).max())
        n = rng.normal(size=(8, 3))
        n /= np.linalg.norm(n, axis=1, keepdims=True)
        jac = np.broadcast_to(J, (8, 3, iiwa.nv))
        m0, m1 = bare(q, jac, n), loaded(q, jac, n)
        expected = 1.0 / np.einsum("ax,xy,ay->a", n, np.linalg.inv(lam + p * np.eye(3)), n)
        np.testing.assert_allclose(m1, expected, rtol=1e-8)
        assert np.all(m1 >= m0 + p - 1e-9)  # never less than the payload more
    assert iiwa.model.inertias[last].mass == before  # the robot's model is unchanged
    assert loaded.model.inertias[last].mass == pytest.approx(before + p)


# -- refusals ---------------------------------------------------------------------------


@pytest.mark.parametrize("payload", [-0.5, math.nan, math.inf, 14.5, True])
def test_a_payload_that_is_negative_not_finite_or_above_the_rating_is_refused(iiwa, payload):
    with pytest.raises(InputError) as err:
        EffectiveMass(iiwa, payload)
    assert err.value.name == "payload_kg" and err.value.value is payload
    assert "\n" not in str(err.value)


def test_the_rated_payload_itself_is_allowed(iiwa):
    assert EffectiveMass(iiwa, 14.0).payload_kg == 14.0
    with pytest.raises(InputError, match=r"the iiwa14 arm's rated payload, 14 kg"):
        EffectiveMass(iiwa, 14.01)


NO_INERTIA = """<robot name="toy">
  <link name="base"/>
  <link name="l1">{inertial1}</link>
  <link name="l2"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <axis xyz="0 0 1"/><limit lower="-3" upper="3" velocity="1" effort="1"/></joint>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.3 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-3" upper="3" velocity="1" effort="1"/></joint>
</robot>"""
INERTIAL = '<inertial><mass value="2.0"/><inertia ixx="0.01" iyy="0.01" izz="0.01" ixy="0" ixz="0" iyz="0"/></inertial>'  # noqa: E501


def test_a_description_without_inertias_is_refused_naming_the_robot():
    model = pin.buildModelFromXML(NO_INERTIA.format(inertial1=""))
    with pytest.raises(RobotDescriptionError, match="toy: no moving link has mass") as err:
        EffectiveMass.from_model(model, model.nframes - 1, name="toy")
    assert "\n" not in str(err.value) and err.value.name == "inertias"
    # l1 has mass but l2 none: joint 2 moves nothing, M is singular
    model = pin.buildModelFromXML(NO_INERTIA.format(inertial1=INERTIAL))
    with pytest.raises(
        RobotDescriptionError, match=r"toy: the mass matrix .* not positive definite"
    ):
        EffectiveMass.from_model(model, model.nframes - 1, name="toy")


def test_bad_arrays_are_refused(iiwa):
    mass = EffectiveMass(iiwa)
    q = iiwa.neutral()
    with pytest.raises(InputError, match="jacobians"):
        mass(q, np.zeros((2, 3, iiwa.nv + 1)), np.ones((2, 3)))
    with pytest.raises(InputError, match="normals"):
        mass(q, np.zeros((2, 3, iiwa.nv)), np.ones((3, 3)))
    with pytest.raises(InputError, match="normals"):
        mass(q, np.zeros((1, 3, iiwa.nv)), [[np.nan, 0.0, 1.0]])
    with pytest.raises(InputError, match="q"):
        mass.minverse(np.zeros(iiwa.nq + 1))


# -- the rated payload of the [arm] table ------------------------------------------------

ARM = """
[arm]
reaction_time_s = 0.008
max_acceleration_radps2 = { j1 = 10.0, j2 = 10.0 }
max_point_speed_mps = 3.0
rated_payload_kg = PAYLOAD

[arm.sources]
rated_payload_kg = "a test's"
"""
PATH = Path("/robots/toy/control_points.toml")


def arm_of(text: str):
    return read_arm(tomllib.loads(text), PATH, ("j1", "j2"))


def test_the_rated_payload_is_read_and_bounded():
    assert arm_of(ARM.replace("PAYLOAD", "5")).rated_payload_kg == 5.0
    without = ARM.replace("PAYLOAD", "5").replace("rated_payload_kg = 5\n", "")
    assert arm_of(without).rated_payload_kg is None  # optional: older descriptions load
    for bad in ("0", "-1", "1e4", "nan", '"5"'):
        with pytest.raises(RobotDescriptionError) as err:
            arm_of(ARM.replace("PAYLOAD", bad))
        assert err.value.name == "arm.rated_payload_kg" and str(err.value).startswith(f"{PATH}: ")
    unsourced = ARM.replace("PAYLOAD", "5").replace('rated_payload_kg = "a test\'s"\n', "")
    with pytest.raises(RobotDescriptionError, match="rated_payload_kg needs its source"):
        arm_of(unsourced)


@pytest.mark.parametrize(
    ("arm", "payload"), [("iiwa14", 14.0), ("panda", 3.0), ("fr3", 3.0), ("ur5", 5.0)]
)
def test_each_shipped_arm_gives_its_maker_s_rated_payload(arm, payload):
    path = ROBOTS / arm / "control_points.toml"
    cfg = tomllib.loads(path.read_text())
    joints = tuple(cfg["arm"]["max_acceleration_radps2"])
    dynamics = read_arm(cfg, path, joints)
    assert dynamics.rated_payload_kg == payload
    assert "payload" in dict(dynamics.sources)["rated_payload_kg"]
