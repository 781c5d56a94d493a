"""The paper's Test 1 in closed loop with both controllers, from the library API."""

from qpavoid import load_robot
from qpavoid.control.analytic import AnalyticController
from qpavoid.control.qp import QPController
from qpavoid.loop.simulation import SimConfig, simulate
from qpavoid.scenarios.generated import make_scenario

robot = load_robot("iiwa14")
motion = make_scenario("test1", robot)  # the right hand comes beside the wrist
for controller in (AnalyticController(robot), QPController(robot)):
    m = simulate(controller, motion, SimConfig(control_rate_hz=500)).metrics
    print(
        f"{controller.name:8s} goal {m['reached_goal']}, "
        f"path error {m['rms_path_error_m'] * 1e3:.2f} mm "
        f"rms, min distance {m['min_distance_m']['spheres']:.3f} m, stops {len(m['stop_events'])}, "
        f"tick {m['tick_us']['median']:.0f} us"
    )
