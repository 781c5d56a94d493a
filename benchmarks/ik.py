"""The inverse kinematics on random reachable targets, per shipped arm, against pink.

    python benchmarks/ik.py [--n 100] [--seed 0] [--robots iiwa14 panda fr3 ur5] [--json FILE]

Each target is the end effector's pose at a configuration drawn uniformly inside the
joint limits (so it is reachable); each is solved from the description's seed
(:func:`qpavoid.arm.ik.ik_seed`). Per arm and method: how many of ``--n`` converged to
``‖log6‖ < 1e-10``, the median iterations of the runs that did, and the time per target
(ms, one core; information, not a bound).

* **qpavoid**: :func:`qpavoid.arm.ik.inverse_kinematics` (the seed, then 64 seeded
  restarts if it fails, the solution nearest the seed), and its run from the seed alone
  (:func:`qpavoid.arm.ik.solve_from`).
* **pink** (with ``pip install ".[peers,solvers]"``): ``solve_ik`` with a ``FrameTask``
  (gain 1) and a ``ConfigurationLimit``, ``dt = 1``, integrated 200 times at most from the
  same seed, on daqp and on OSQP (``eps_abs = eps_rel = 1e-9``, polished): the peer the
  issue weighed as a dependency.
"""

from __future__ import annotations

import argparse
import json
import time
import warnings
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

from qpavoid.arm.ik import IKConfig, ik_seed, inverse_kinematics, solve_from
from qpavoid.arm.model import Robot, load_robot
from qpavoid.core.errors import IKNotConvergedError
from qpavoid.core.geometry import orthonormalize

TOL = IKConfig().tol


def targets(robot: Robot, n: int, seed: int) -> list[np.ndarray]:
    """``n`` reachable poses (4, 4): forward kinematics of uniform configurations."""
    rng = np.random.default_rng(seed)
    return [robot.end_effector(rng.uniform(robot.q_min, robot.q_max)) for _ in range(n)]


def pink_from_seed(robot: Robot, target: np.ndarray, solver: str, **options: Any) -> int | None:
    """Iterations pink's ``solve_ik`` needs from the seed (None: not within 200)."""
    import pink
    from pink.limits import ConfigurationLimit
    from pink.tasks import FrameTask

    model = robot.model
    frame = model.frames[robot.ee_frame].name
    configuration = pink.Configuration(model, model.createData(), ik_seed(robot, target))
    task = FrameTask(frame, position_cost=1.0, orientation_cost=1.0)
    goal = pin.SE3(orthonormalize(target[:3, :3]), target[:3, 3])
    task.set_target(goal)
    limits = [ConfigurationLimit(model)]
    for it in range(200):
        T = configuration.get_transform_frame_to_world(frame)
        if np.linalg.norm(pin.log6(T.actInv(goal)).vector) < TOL:
            return it
        try:
            v = pink.solve_ik(configuration, [task], 1.0, solver=solver, limits=limits, **options)
        except Exception:  # pink's NoSolutionFound, a limit left: not converged
            return None
        configuration.integrate_inplace(v, 1.0)
    return None


def run(robot_name: str, n: int, seed: int) -> dict[str, Any]:
    """Every method on ``n`` targets of one arm."""
    robot = load_robot(robot_name)
    poses = targets(robot, n, seed)
    out: dict[str, Any] = {}

    def tally(name: str, solve: Any, counts_iterations: bool = True) -> None:
        its: list[int] = []
        t0 = time.perf_counter()
        for pose in poses:
            it = solve(pose)
            if it is not None:
                its.append(it)
        ms = (time.perf_counter() - t0) / n * 1e3
        out[name] = dict(
            converged=len(its),
            of=n,
            median_iterations=float(np.median(its)) if its else None,
            ms_per_target=round(ms, 2),
        )
        print(
            f"{robot_name:7s} {name:22s} {len(its):4d}/{n}  "
            f"median it {out[name]['median_iterations']}  {ms:7.2f} ms",
            flush=True,
        )

    def ours(pose: np.ndarray) -> int | None:
        try:
            inverse_kinematics(robot, pose)
        except IKNotConvergedError:
            return None
        return 0

    def seed_alone(pose: np.ndarray) -> int | None:
        goal = pin.SE3(orthonormalize(pose[:3, :3]), pose[:3, 3])
        result = solve_from(robot, goal, ik_seed(robot, pose))
        return result.iterations if result.converged else None

    tally("qpavoid", ours, counts_iterations=False)
    tally("qpavoid, seed alone", seed_alone)
    try:
        import pink  # noqa: F401
    except ImportError:
        print("pink is not installed (pip install '.[peers,solvers]'): skipped")
        return out
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        for solver, options in (
            ("daqp", {}),
            ("osqp", dict(eps_abs=1e-9, eps_rel=1e-9, polish=True, verbose=False)),
        ):
            try:
                tally(
                    f"pink {solver}",
                    lambda p, s=solver, o=options: pink_from_seed(robot, p, s, **o),
                )
            except Exception as exc:  # the solver is not installed
                print(f"pink on {solver}: {exc}")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--n", type=int, default=100)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--robots", nargs="+", default=["iiwa14", "panda", "fr3", "ur5"])
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    results = {name: run(name, args.n, args.seed) for name in args.robots}
    if args.json:
        args.json.write_text(json.dumps(results, indent=2) + "\n")


if __name__ == "__main__":
    main()
