"""Safety campaigns (``qpavoid sweep``): many randomized strikes or close-work cases, judged
against the truth, on any executor.

A campaign runs ``n`` cases of the sweep engine (:mod:`qpavoid.experiments.sweep`) from seed
``seed`` on, each along the whole path (until the goal, or a cap), and sums them up
(:func:`~qpavoid.experiments.sweep_summary.summarize`). Its *motion* (:data:`MOTIONS`) is

``strikes`` (kind ``"strike"``)
    a hand, or both, driven from rest into every robot set, the shoulder or the base at up
    to 2 m/s, with lost, inferred or frozen limbs, frame gaps and jitter on a Kinect with
    its latency; each run until the goal or :data:`CAMPAIGN_MAX_TIME_S`;
``closework`` (kind ``"closework"``)
    the operator working within reach of the path, never at the robot
    (:mod:`qpavoid.scenarios.closework`: hands resting or working near it, reaching
    across it, handing over a part) on a clean camera; each run until the goal or its
    case's duration (the path and 15 s more). Its summary adds productivity: the
    fraction reaching the goal, the time to it, the time stopped, per variant.

Every run depends on its seed alone, so a summary is the same whatever the number of
workers and wherever they run: a local process pool, or Ray (:class:`RayExecutor`; a
cluster when ``RAY_ADDRESS`` is set). Only the tick times (``timing``) are measured, not
reproduced.

:func:`write_campaign` writes ``summary.json``, ``runs.json`` and, in ``worst/``, the true
motion of the worst runs as replayable recordings (``qpavoid run --human``) with their
case beside them (its ``replay`` line: a strike's recording, or the close-work scenario
``closework:SEED`` itself).
"""

from __future__ import annotations

import logging
import os
import shlex
import signal
import socket
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import Executor
from dataclasses import asdict
from pathlib import Path
from typing import Any, TypeAlias, cast

import numpy as np

from qpavoid.arm.description import description_reference
from qpavoid.arm.model import load_robot
from qpavoid.core.checks import check_choice
from qpavoid.core.errors import InputError, RobotDescriptionError, Terminated
from qpavoid.core.signals import handled_by
from qpavoid.experiments.run_spec import RunSpec
from qpavoid.experiments.sweep import SweepSpec, sweep
from qpavoid.experiments.sweep_checks import CloseWorkCheck, StrikeCheck
from qpavoid.experiments.sweep_summary import summarize
from qpavoid.human.frames import HumanFrame, HumanMotion
from qpavoid.human.landmarks import format_file
from qpavoid.output.run_files import staged_output, strict_json
from qpavoid.scenarios.closework import closework_case, closework_motion
from qpavoid.scenarios.strikes import strike_case, strike_motion
from qpavoid.sensing.calibration import DEFAULT_FORMAT
from qpavoid.sensing.recording import Recording, save_npz

__all__ = [
    "MAX_RUNS",
    "MOTIONS",
    "CampaignRun",
    "RayExecutor",
    "campaign_motion",
    "campaign_settings",
    "campaign_spec",
    "rerun_command",
    "run_campaign",
    "write_campaign",
]

#: A strike's run lasts until the goal or this cap, s: the 15 s path, a strike's stops and
#: margin.
CAMPAIGN_MAX_TIME_S = 30.0
#: What a campaign's runs are (``qpavoid sweep --motion``): the sweep kind of each.
MOTIONS = {"strikes": "strike", "closework": "closework"}
#: What a campaign's run gives: a strike's or a close-work case's check.
CampaignRun: TypeAlias = StrikeCheck | CloseWorkCheck
#: How many of the worst runs are written out.
WORST = 5
#: The most runs of one campaign: each run's result is held for the summary and is one
#: row of runs.json (about 0.5 kB), and 100 000 runs are the campaign docs/performance.md
#: prices; split a larger one by --seed.
MAX_RUNS = 1_000_000


def campaign_spec(
    controller: str,
    distance: str = "capsules",
    safety: str = "ssm",
    rate_hz: float = 100.0,
    max_speed_mps: float = 2.0,
    max_time_s: float | None = None,
    robot: str = "iiwa14",
    camera: str = "kinect_v2",
    latency_s: float | None = None,
    motion: str = "strikes",
    payload_kg: float = 0.0,
) -> SweepSpec:
    """The runs of a campaign: strikes at up to ``max_speed_mps`` (m/s), or close-work
    cases (``motion``, one of :data:`MOTIONS`), on ``robot``, each until the goal or
    ``max_time_s`` (s; None: a strike's :data:`CAMPAIGN_MAX_TIME_S`, a close-work case's
    own duration), at ``rate_hz`` (Hz), seen through a simulated ``camera`` (a skeleton
    format's name) of ``latency_s`` (s; None: its format file's), carrying ``payload_kg``
    (kg) at the end effector."""
    check_choice("campaign motion (--motion)", motion, tuple(MOTIONS))
    if max_time_s is None and motion == "strikes":
        max_time_s = CAMPAIGN_MAX_TIME_S
    return SweepSpec(
        MOTIONS[motion],
        controller,
        distance,
        safety,
        rate_hz,
        max_time_s,
        max_speed_mps,
        latency_s,
        robot=robot,
        camera=camera,
        payload_kg=payload_kg,
    )


def campaign_motion(spec: SweepSpec) -> str:
    """The campaign motion (a key of :data:`MOTIONS`) whose runs ``spec`` describes.

    Raises
    ------
    InputError
        For a sweep that is no campaign's (an approach sweep).
    """
    for motion, kind in MOTIONS.items():
        if spec.kind == kind:
            return motion
    raise InputError(
        f"a campaign runs strikes or close work, got a sweep of {spec.kind!r}",
        name="kind",
        value=spec.kind,
    )


def campaign_settings(spec: SweepSpec, n: int, seed: int) -> dict[str, Any]:
    """The ``settings`` of ``summary.json``: what a campaign of ``n`` runs of ``spec``
    from seed ``seed`` on was (its ``motion``: :data:`MOTIONS`), on which arm (a bundled
    description's name or the absolute folder of another:
    :func:`~qpavoid.arm.description.description_reference`); the cap, fixed on the
    command line, aside. ``max_speed_mps`` is the strikes' (None for close work)."""
    motion = campaign_motion(spec)
    return {
        "n": n,
        "motion": motion,
        "robot": description_reference(spec.robot),
        "controller": spec.controller,
        "distance": spec.distance,
        "safety": spec.safety,
        "seed": seed,
        "max_speed_mps": spec.max_speed_mps if motion == "strikes" else None,
        "rate_hz": spec.rate_hz,
        "camera": spec.camera,
        "latency_s": spec.run_spec(0, 1.0).sensor_latency_s,
        "payload_kg": spec.payload_kg,
    }


class RayExecutor(Executor):
    """``map`` on Ray: a cluster when ``RAY_ADDRESS`` is set, else a local Ray of
    ``workers`` CPUs. Results come back in the order of the items (``pip install
    "qpavoid[cluster]"``)."""

    def __init__(self, workers: int | None = None):
        try:
            import ray
        except ImportError:  # the optional dependency
            raise InputError(
                'the ray executor needs Ray: pip install "qpavoid[cluster]"',
                name="--executor",
                value="ray",
            ) from None
        self.ray, self.started = ray, False
        if ray.is_initialized():
            return
        address = os.environ.get("RAY_ADDRESS")
        try:
            with handled_by(None):  # ray.init sets its own SIGTERM handler: ours comes back
                self._init(address, workers)
        except BaseException as exc:
            ray.shutdown()  # whatever it started or joined
            self.started = False
            if isinstance(exc, SystemExit) and exc.code == signal.SIGTERM:
                raise Terminated from None  # ray.init's own SIGTERM handler exits so
            if not isinstance(exc, Exception):  # Ctrl-C, SIGTERM: as they are
                raise
            where = f"the Ray cluster at RAY_ADDRESS={address!r}" if address else "a local Ray"
            raise InputError(  # Ray's own errors, whatever their type: not our bug
                f"cannot start or reach {where}: {type(exc).__name__}: {exc}",
                name="RAY_ADDRESS" if address else "--workers",
                value=address or workers,
            ) from None

    def _init(self, address: str | None, workers: int | None) -> None:
        if address:
            _reachable(address)
            self.ray.init(address=address, log_to_driver=False, logging_level=logging.ERROR)
        else:
            self.started = True  # from here a Ctrl-C must take a half-started Ray down
            self.ray.init(
                address="local",  # a new one, even beside a `ray start` cluster
                num_cpus=workers or os.cpu_count(),
                include_dashboard=False,
                log_to_driver=False,
                logging_level=logging.ERROR,
            )

    def map(self, fn: Callable[..., Any], *iterables: Iterable[Any], **_: Any) -> Iterator[Any]:
        """``fn`` over the items as Ray tasks; results yielded in order as they complete."""
        remote = self.ray.remote(fn)
        refs = [remote.remote(*args) for args in zip(*iterables, strict=True)]
        for ref in refs:
            yield self.ray.get(ref)

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        """Stop the local Ray this executor started, its processes with it; leave any
        other as it is (a cluster outlives the campaign)."""
        if self.started:
            self.ray.shutdown()
            self.started = False


def _reachable(address: str, timeout_s: float = 5.0) -> None:
    """Raise ``ConnectionError`` unless ``address`` is ``auto``, ``ray://...`` (Ray's to
    resolve) or a ``host:port`` where something answers within ``timeout_s`` (Ray itself
    retries an unreachable head for minutes)."""
    if address == "auto" or address.startswith("ray://"):
        return
    host, _, port = address.rpartition(":")
    if not (host and port.isdigit()) or address != address.strip() or "://" in host:
        raise ConnectionError(f"{address!r} is not host:port, auto or ray://host:port")
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=timeout_s).close()
    except (OSError, ValueError) as exc:
        raise ConnectionError(f"nothing answers at {address} ({exc})") from None


def run_campaign(
    spec: SweepSpec,
    n: int,
    seed: int = 0,
    workers: int | None = None,
    executor: Executor | None = None,
    progress: bool = False,
) -> list[CampaignRun]:
    """``n`` strikes or close-work cases of ``spec`` from seed ``seed`` on, in seed order."""
    if not 1 <= n <= MAX_RUNS:
        raise InputError(f"--n must be from 1 to {MAX_RUNS}, got {n}", name="--n", value=n)
    campaign_motion(spec)  # a campaign's kind
    return cast(list[CampaignRun], sweep(spec, range(seed, seed + n), workers, executor, progress))


def worst_runs(runs: list[CampaignRun], count: int = WORST) -> list[CampaignRun]:
    """The ``count`` runs that came closest to the person while moving (contact first)."""
    return sorted(
        runs, key=lambda r: (-r.ticks_moving_in_true_contact, r.min_true_clearance_moving_m)
    )[:count]


def true_recording(run: CampaignRun, spec: SweepSpec, rate_hz: float = 30.0) -> Recording:
    """The true motion of ``run``'s strike or close-work case (drawn as ``spec`` draws
    them, on its robot), sampled at ``rate_hz`` (Hz) for the run's duration."""
    robot = load_robot(spec.robot)
    motion: HumanMotion
    if spec.kind == "closework":
        motion = closework_motion(closework_case(run.seed, robot), robot)
    else:
        motion = strike_motion(strike_case(run.seed, spec.max_speed_mps, robot), robot)
    times = np.arange(0.0, run.duration_s + 1.0 / rate_hz, 1.0 / rate_hz)
    frames = [HumanFrame.check(*motion.frame_at(t)) for t in times]
    return Recording(
        times, np.array([f.joints for f in frames]), np.array([f.state for f in frames])
    )


def rerun_command(run: CampaignRun, spec: SweepSpec) -> str:
    """The ``qpavoid run`` line that drives the campaign's controller with ``run``'s true
    motion (from inside ``worst/``; a worst case's ``"replay"`` key).

    A strike's is its recording: its camera faults are not in it, the rerun sees the
    person through ``run``'s ordinary Kinect (``--bench real``). A close-work case's is
    its scenario, ``closework:SEED``, until the goal or the case's own duration, through
    the campaign's camera and latency, its noise drawn from the case's seed as the
    campaign drew it: the same run."""
    try:  # a folder absolute: the line runs from inside worst/
        reference = description_reference(spec.robot)
    except RobotDescriptionError:  # no such robot: the line says what the spec said
        reference = spec.robot
    robot = "" if reference == RunSpec.robot else f" --robot {shlex.quote(reference)}"
    if spec.kind == "closework":
        cap = spec.max_time_s
        if cap is None:
            cap = closework_case(run.seed, load_robot(spec.robot)).duration_s
        named = str(format_file(spec.camera) or spec.camera)  # a file: absolute, from worst/
        camera = "" if spec.camera == DEFAULT_FORMAT else f" --camera {shlex.quote(named)}"
        latency = "" if spec.latency_s is None else f" --latency {spec.latency_s:g}"
        latency += f" --payload {spec.payload_kg:g}" if spec.payload_kg else ""
        return (
            f"qpavoid run closework:{run.seed} --controller {spec.controller} "
            f"--distance {spec.distance} --safety {spec.safety} --bench real "
            f"--rate {spec.rate_hz:g} --max-time {cap:g}{robot}{camera}{latency}"
        )
    return (
        f"qpavoid run --human seed{run.seed}.npz --controller {spec.controller} "
        f"--distance {spec.distance} --safety {spec.safety} --bench real "
        f"--rate {spec.rate_hz:g} --max-time {CAMPAIGN_MAX_TIME_S:g}{robot}"
        + (f" --payload {spec.payload_kg:g}" if spec.payload_kg else "")
    )


def write_campaign(
    out: str | Path, spec: SweepSpec, n: int, seed: int, runs: list[CampaignRun]
) -> dict[str, Any]:
    """Write ``summary.json``, ``runs.json`` and ``worst/`` of the campaign of ``n`` runs
    of ``spec`` from seed ``seed`` on into ``out``; return the summary."""
    summary = {"settings": campaign_settings(spec, n, seed), **summarize(runs)}
    with staged_output(out) as stage:
        (stage / "summary.json").write_text(strict_json(summary, indent=1))
        (stage / "runs.json").write_text(strict_json([asdict(r) for r in runs], indent=1))
        worst = stage / "worst"
        worst.mkdir()
        for r in worst_runs(runs):
            save_npz(worst / f"seed{r.seed}.npz", true_recording(r, spec))
            case = {**asdict(r), "replay": rerun_command(r, spec)}
            (worst / f"seed{r.seed}.json").write_text(strict_json(case, indent=1))
    return summary
