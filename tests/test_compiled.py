"""The control loop never waits for numba: every kernel it calls was compiled (or loaded)
at construction, for the very argument types the loop passes."""

from __future__ import annotations

import json
import os
import subprocess
import types
from pathlib import Path

import numba
import numpy as np
from conftest import PYTHON

from qpavoid.core.compiling import kernel_input, recompile_if_stale
from qpavoid.fusion import person as fusion_person
from qpavoid.human.kinect_v2 import KINECT_V2
from qpavoid.laws import _kernels as law_kernels

# A fresh process runs the loop's every compiled path (both distance methods, both
# controllers, SSM, several people, two-sensor fusion with mirrors and outliers) and
# reports how many specialisations each kernel holds: one more than warm_up made means
# the loop compiled a new one mid-run (a second's stall next to a person).
LOOP = """
import json
import numpy as np
from qpavoid.distance import _kernels as distance_kernels
from qpavoid.fusion import _kernels as fusion_kernels
from qpavoid.fusion import person as fusion_person
from qpavoid.laws import _kernels as law_kernels
from qpavoid.perception import _kernels as perception_kernels
from qpavoid.human import _kernels as body_kernels
from qpavoid.human import alpha_beta
from qpavoid.control.qp import kernels as qp_kernels, solver_kernels
from qpavoid.sensing.calibration import Calibration
from qpavoid.control.tick import ControllerConfig
from qpavoid.human.frames import HumanFrame
from qpavoid.fusion.fuser import Fuser
from qpavoid.human.people import People
from qpavoid.control.qp import QPController
from qpavoid.arm.model import load_robot
from qpavoid.experiments.runs import RunSpec, simulate_one
from qpavoid.scenarios.generated import make_scenario
from qpavoid.sensing.synthetic_pair import TwoSensorConfig, two_sensor_data

import sys
from numba.core.registry import CPUDispatcher

def every_kernel():  # each of the package's compiled kernels, by where it is defined
    found = {}
    for name, m in list(sys.modules.items()):
        if name.startswith("qpavoid"):
            for k in vars(m).values():
                if isinstance(k, CPUDispatcher):
                    found[f"{k.py_func.__module__}.{k.py_func.__name__}"] = k
    return found

for controller in ("qp", "analytic"):
    for distance in ("spheres", "capsules"):
        simulate_one(RunSpec(scenario="test1", controller=controller, distance=distance,
                             safety="ssm", max_time_s=3.0, rate_hz=100.0))
robot = load_robot("iiwa14")
motion = make_scenario("test1", robot)
ctrl = QPController(robot, config=ControllerConfig(control_period_s=0.01, distance="capsules"))
q = robot.neutral()
def readonly(*arrays):  # as a recording's or a datagram's arrays are
    for a in arrays:
        a.setflags(write=False)
    return arrays


for k in range(30):
    frame = HumanFrame.check(*motion.frame_at(4.0 + 0.03 * k))
    other = HumanFrame(*readonly(frame.joints + [0.3, 0.2, 0.0], frame.state.copy()))
    ctrl.step(q, People((0, 1), (frame, other)), None, 1.0)
    ctrl.step(q, HumanFrame(*readonly(frame.joints[::-1][::-1], frame.state.astype(float))))
data = two_sensor_data([motion], 4.0, TwoSensorConfig(seed=1))  # swaps, outliers
fuser = Fuser(Calibration(dict(data.calibration.sensors)))
rows = sorted((f.t + data.calibration[f.sensor].time_offset_s, f)
              for rec in data.recordings.values() for f in rec.frames())
for n, (t, f) in enumerate(rows):
    if n % 2:  # read-only, and of other dtypes
        joints, state = readonly(f.joints.astype(np.float32), f.state.astype(int))
        f = f._replace(joints=joints, state=state)
    fuser.add(f)
    fuser.fuse(t)
print(json.dumps({
    "signatures": {name: len(k.signatures) for name, k in every_kernel().items()},
    "counters": dict(fuser.counters),
}))
"""


def test_the_loop_uses_only_the_kernels_warm_up_compiled():
    r = subprocess.run([*PYTHON, "-c", LOOP], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout.strip().splitlines()[-1])
    counts = out["signatures"]
    assert counts["qpavoid.fusion.person.fuse_person"] == 1  # the fusion ran
    assert counts["qpavoid.distance._kernels.sphere_table"] == 1  # the sphere table ran
    assert out["counters"].get("mirrored_corrected", 0) > 0  # mirrors were undone
    assert out["counters"].get("outliers_resolved", 0) > 0  # and outliers settled
    for ran in (  # the tick's kernels outside the modules above were found and ran
        "qpavoid.arm._kernels.frame_jacobians",
        "qpavoid.control.smoothing.command_box",
        "qpavoid.laws.ssm.approach_bounds",
        "qpavoid.distance._kernels.capsule_table",
    ):
        assert counts[ran] == 1, ran
    assert all(n <= 1 for n in counts.values()), counts


def test_a_kernel_cached_before_an_edit_of_what_it_calls_is_recompiled(tmp_path):
    """numba keys a cache on the kernel's own file: compiling.recompile_if_stale compares
    it with the files whose code the kernel compiles in."""
    index = tmp_path / "kernel.nbi"
    index.write_text("")
    module = types.ModuleType("callee")
    module.__file__ = str(tmp_path / "callee.py")
    Path(module.__file__).write_text("")
    os.utime(index, (1000.0, 1000.0))

    class Kernel:  # numba's attributes for the cache's index file
        recompiled = 0
        _cache = types.SimpleNamespace(_cache_file=types.SimpleNamespace(_index_path=str(index)))

        def recompile(self):
            self.recompiled += 1

    kernel = Kernel()
    os.utime(module.__file__, (999.0, 999.0))  # older than the cache: kept
    assert not recompile_if_stale(kernel, module) and kernel.recompiled == 0
    os.utime(module.__file__, (1001.0, 1001.0))  # edited after: recompiled
    assert recompile_if_stale(kernel, module) and kernel.recompiled == 1
    index.unlink()  # nothing cached: nothing to do
    assert not recompile_if_stale(kernel, module)


def test_numba_still_keeps_a_cache_index_where_recompile_if_stale_looks():
    """A numba that moved it would silently switch the check off."""
    law_kernels.warm_up()
    fusion_person.warm_up(KINECT_V2)
    for kernel in (law_kernels.avoidance_terms, fusion_person.fuse_person):
        assert os.path.exists(kernel._cache._cache_file._index_path)


def test_kernel_input_passes_only_the_warmed_up_array_type_through():
    plain = np.arange(6.0).reshape(2, 3)
    assert kernel_input(plain, np.float64) is plain  # no copy in the control loop
    readonly = plain.copy()
    readonly.setflags(write=False)
    odd = {
        "read-only": readonly,
        "a strided view": np.arange(12.0).reshape(2, 6)[:, ::2],
        "Fortran order": np.asfortranarray(np.arange(6.0).reshape(3, 2)).T,
        "big-endian": plain.astype(">f8"),
        "float32": plain.astype(np.float32),
        "a list": plain.tolist(),
    }
    for name, value in odd.items():
        got = kernel_input(value, np.float64)
        assert numba.typeof(got) == numba.typeof(plain), name  # the one specialisation
        assert got.flags.c_contiguous and got.flags.writeable, name
        np.testing.assert_array_equal(got, np.asarray(value, dtype=np.float64), err_msg=name)
    states = np.array([2, 1, 0], dtype=np.int8)
    assert kernel_input(states, np.int8) is states
    assert numba.typeof(kernel_input(states.astype(int), np.int8)) == numba.typeof(states)


def test_cold_is_true_only_for_a_kernel_without_its_cache_index(tmp_path):
    """The first run after an install compiles for tens of seconds: the command line says so
    (``core.compiling.cold``) instead of waiting in silence; a cached kernel, or one whose
    cache numba keeps elsewhere, says nothing."""
    from qpavoid.core.compiling import cold

    index = tmp_path / "kernel.nbi"

    class Kernel:
        _cache = types.SimpleNamespace(_cache_file=types.SimpleNamespace(_index_path=str(index)))

    assert cold(Kernel(), law_kernels.avoidance_terms)  # nothing cached for the first
    index.write_text("")
    assert not cold(Kernel(), law_kernels.avoidance_terms)
    assert not cold(object())  # nowhere to look: nothing known


def test_the_command_line_says_once_that_it_compiles_on_a_cold_cache(monkeypatch, capsys, tmp_path):
    from qpavoid.cli import commands

    def run(out: str) -> str:
        argv = ["run", "free", "--max-time", "0.2", "-q", "--no-plots", "--no-view"]
        assert commands.main([*argv, "--out", str(tmp_path / out)]) == 0
        return capsys.readouterr().err

    monkeypatch.setattr(commands, "cold", lambda *kernels: True)
    err = run("cold")
    assert err.count("compiling its kernels for this install") == 1, err
    monkeypatch.setattr(commands, "cold", lambda *kernels: False)
    assert "compiling" not in run("warm")
