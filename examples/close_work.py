"""A handover beside the iiwa under the three safety modes, from the library API.

The operator hands a part across the end effector's path. Speed and separation (`ssm`)
waits until the hand has gone; power and force limiting (`pfl`) lets the arm pass beside
the hand and would touch it no faster than its ISO/TS 15066 Annex A limit, with a 2 kg
payload counted in the arm's effective mass. Each run is judged against where the person
really is (docs/safety.md §9).
"""

from qpavoid import load_robot
from qpavoid.control.qp import QPController
from qpavoid.control.tick import ControllerConfig
from qpavoid.laws.pfl import PFLConfig
from qpavoid.loop.simulation import SimConfig, simulate
from qpavoid.scenarios.generated import make_scenario

robot = load_robot("iiwa14")
motion = make_scenario("handover", robot)  # closework:0, a fixed case
for safety in ("paper", "ssm", "pfl"):
    config = ControllerConfig(safety=safety, control_period_s=0.01, pfl=PFLConfig(payload_kg=2.0))
    sim = SimConfig(control_rate_hz=100, max_time_s=30.0, measure_truth=True)
    m = simulate(QPController(robot, config=config), motion, sim).metrics
    touched = m["true_contacts"]
    print(
        f"{safety:5s} goal {m['reached_goal']} in {m['duration_s']:.2f} s, stopped "
        f"{m['stopped_s']:.2f} s; moving in true contact {m['ticks_moving_in_true_contact']} "
        f"ticks, above a region's limit {touched['ticks_above_limit']}, head or trunk "
        f"{touched['ticks_moving_protected']}"
    )
