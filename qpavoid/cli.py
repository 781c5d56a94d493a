"""The ``qpavoid`` command line.

    qpavoid run SCENARIO --controller analytic --distance spheres --out DIR
    qpavoid run --human FILE.npz --controller analytic --out DIR

SCENARIO is ``test1``, ``test2`` or ``free`` (generated in code, :mod:`qpavoid.scenarios`);
``--human FILE`` replays a recording (NPZ or CSV, docs/formats.md) along the paper's task.
The run writes ``metrics.json``, ``log.npz`` and the paper's figures into DIR.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .controller import ControllerConfig
from .errors import QpavoidError
from .simulation import SimConfig, simulate

CONTROLLERS = ("analytic", "qp")
DISTANCES = ("spheres", "capsules")


def build_controller(name: str, robot, config: ControllerConfig, solver: str | None = None,
                     redundant: bool = False):
    """The controller called ``name`` with the shared ``config``.

    For ``"qp"``: ``solver`` names a qpsolvers solver (a new problem each tick); without
    it the persistent OSQP problem is used. ``redundant`` turns on the elbow-clearance
    cost that uses A3 (the robot must then be loaded with all 7 joints).
    """
    from .errors import InputError
    if name == "analytic":
        if redundant:
            raise InputError("redundancy mode (--redundant) needs --controller qp")
        if solver:
            raise InputError("--solver applies to --controller qp only")
        from .analytic import AnalyticController
        return AnalyticController(robot, config=config)
    if name == "qp":
        from .qp import QPConfig, QPController
        qp = QPConfig(backend="qpsolvers" if solver else "persistent", solver=solver or "osqp")
        if redundant:
            qp = QPConfig(backend=qp.backend, solver=qp.solver, elbow_weight=REDUNDANT_ELBOW_WEIGHT,
                          regularization=REDUNDANT_REGULARIZATION)
        return QPController(robot, config=config, qp=qp)
    raise InputError(f"unknown controller {name!r}; choose from {list(CONTROLLERS)}")


#: Redundancy mode (docs/qp.md): weight of the elbow-clearance cost, and a regularisation
#: large enough to give the end effector's null-space direction curvature (with 1e-7
#: OSQP cannot reach its tolerance there).
REDUNDANT_ELBOW_WEIGHT = 0.05
REDUNDANT_REGULARIZATION = 1e-4


def load_motion(scenario: str | None, human_file: str | None, robot):
    """The human motion of a scenario name or a recording file, and its label."""
    from .errors import InputError
    if human_file:
        from .recording import load_recording
        return load_recording(human_file), Path(human_file).stem
    if not scenario:
        raise InputError("give a SCENARIO (test1, test2, free) or --human FILE")
    from .scenarios import make_scenario
    return make_scenario(scenario, robot), scenario


def simulate_one(scenario, human_file, controller_name, distance, max_time_s=40.0, rate_hz=500.0,
                 limit_mode="scale", robot_name="iiwa14", solver=None, redundant=False):
    """Build everything for one run and simulate it; return (result, robot, config, label)."""
    from .robot import load_robot
    robot = load_robot(robot_name, locked=() if redundant else None)
    config = ControllerConfig(distance=distance, limit_mode=limit_mode,
                              control_period_s=1.0 / rate_hz)
    controller = build_controller(controller_name, robot, config, solver, redundant)
    motion, label = load_motion(scenario, human_file, robot)
    result = simulate(controller, motion, SimConfig(control_rate_hz=rate_hz, max_time_s=max_time_s))
    result.metrics.update(scenario=label, redundant=bool(redundant),
                          solver=getattr(getattr(controller, "backend", None), "name", None))
    return result, robot, config, label


def run_one(scenario, human_file, controller_name, distance, out, max_time_s=40.0,
            rate_hz=500.0, plots=True, limit_mode="scale", robot_name="iiwa14", solver=None,
            redundant=False) -> dict:
    """Run one simulation and write its files into ``out``; return its metrics."""
    from . import plots as plotting
    from .io import write_run
    result, robot, config, label = simulate_one(scenario, human_file, controller_name, distance,
                                                max_time_s, rate_hz, limit_mode, robot_name,
                                                solver, redundant)
    extra = {}
    if plots and plotting.available():
        Path(out).mkdir(parents=True, exist_ok=True)
        figures = plotting.write_figures(out, result.log, robot, config.avoidance, distance)
        extra["plots"] = [p.name for p in figures]
    else:
        extra["plots"] = []
        extra["plots_skipped"] = ("disabled by --no-plots" if not plots
                                  else "matplotlib is not installed (pip install 'qpavoid[plot]')")
    write_run(out, result, extra)
    return {**result.metrics, **extra}


def _summary(m: dict) -> str:
    stops = "; ".join(f"{e['t']:.2f} s: {e['reason']}" for e in m["stop_events"]) or "none"
    return (f"{m['scenario']}: controller {m['controller']}, distances {m['distance_method']}\n"
            f"  reached goal {m['reached_goal']} in {m['duration_s']:.2f} s "
            f"(final error {m['final_position_error_m'] * 1e3:.3f} mm)\n"
            f"  path error rms {m['rms_path_error_m'] * 1e3:.3f} mm, max {m['max_path_error_m'] * 1e3:.3f} mm\n"
            f"  min distance spheres {m['min_distance_m']['spheres']:.4f} m, "
            f"capsules {m['min_distance_m']['capsules']:.4f} m, max f {m['max_f']:.3f}\n"
            f"  stopped {m['stopped_s']:.2f} s, stops: {stops}\n"
            f"  tick {m['tick_us']['median']:.0f} us median, {m['tick_us']['p99']:.0f} us p99; "
            f"limit violations: velocity {m['joint_velocity_limit_violations']}, "
            f"position {m['joint_position_limit_violations']}")


def _add_common(p: argparse.ArgumentParser) -> None:
    p.add_argument("--max-time", type=float, default=40.0, help="cap on the run, s (default 40)")
    p.add_argument("--rate", type=float, default=500.0, help="control rate, Hz (default 500)")
    p.add_argument("--no-plots", action="store_true", help="do not write the figures")
    p.add_argument("--robot", default="iiwa14", help="robot description (name or folder)")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="qpavoid", description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="simulate one scenario or recording")
    run.add_argument("scenario", nargs="?", help="test1, test2, free or random:SEED")
    run.add_argument("--human", metavar="FILE", help="replay a recording (NPZ or CSV) instead")
    run.add_argument("--controller", choices=CONTROLLERS, default="analytic")
    run.add_argument("--distance", choices=DISTANCES, default="spheres")
    run.add_argument("--limit-mode", choices=("scale", "clip"), default="scale",
                     help="how the analytic controller enforces eq. (3)")
    run.add_argument("--solver", help="QP solver through qpsolvers (osqp, proxqp, daqp, ...); "
                                      "default: a persistent OSQP problem")
    run.add_argument("--redundant", action="store_true",
                     help="QP only: free A3 (7 joints) and keep the elbow away from the person")
    run.add_argument("--out", required=True, help="output directory")
    _add_common(run)
    cmp = sub.add_parser("compare", help="analytic vs QP, spheres vs capsules, on the same inputs")
    cmp.add_argument("--out", required=True, help="output directory")
    cmp.add_argument("--scenarios", nargs="*", default=None,
                     help="generated scenarios (default: test1 test2 free)")
    cmp.add_argument("--human", nargs="*", default=[], metavar="FILE", help="recordings to replay too")
    cmp.add_argument("--random", type=int, default=0, metavar="N",
                     help="also N random hand approaches (seeds --seed .. --seed+N-1)")
    cmp.add_argument("--seed", type=int, default=0)
    _add_common(cmp)
    args = parser.parse_args(argv)
    try:
        if args.command == "run":
            if args.scenario and args.human:
                parser.error("give either SCENARIO or --human FILE, not both")
            m = run_one(args.scenario, args.human, args.controller, args.distance, args.out,
                        args.max_time, args.rate, not args.no_plots, args.limit_mode, args.robot,
                        args.solver, args.redundant)
            print(_summary(m))
            if m.get("plots_skipped"):
                print(f"  plots skipped: {m['plots_skipped']}")
            print(f"  wrote {Path(args.out) / 'metrics.json'}, log.npz"
                  + (f" and {len(m['plots'])} figures" if m["plots"] else ""))
        else:
            from .compare import compare
            scenarios = ["test1", "test2", "free"] if args.scenarios is None else args.scenarios
            table = compare(args.out, scenarios, args.human, args.random, args.seed, args.max_time,
                            args.rate, not args.no_plots, args.robot)
            print(table)
    except QpavoidError as exc:
        print(f"qpavoid: error: {exc}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
