"""Sphere (paper eq. 1) versus capsule (coal, exact) robot-human distances on the iiwa14.

Draws ``--n`` configurations uniformly within the joint limits of ``load_robot("iiwa14")``
(A3 locked) and, for each, a seated posture with one hand aimed at a random control point
(:func:`qpavoid.human.posture.random_posture`); sample ``i`` uses the hand-target spread
``spreads[i % len(spreads)]`` (default: alternately 0.10 m and 0.25 m). Both 3 x 8 tables
are compared entry by entry, per set (minimum over parts) and for the whole robot (table
minimum). ``diff = spheres - capsules``: negative = spheres say closer (conservative),
positive = spheres say farther (the dangerous side). "Unsafe" = spheres > 0.05 m while
capsules < 0.05 m. Timings (perf_counter_ns, one call per sample, after a warm-up) cover
the table call alone and, separately, ``robot.kinematics(q, jacobians=False)`` +
``human.geometry(joints)``; posture generation is not timed.

Usage: ``python benchmarks/distances.py [--n 10000] [--seed 0] [--json FILE]``
"""

from __future__ import annotations

import argparse
import json
import platform
import time

import numpy as np

import qpavoid
from qpavoid.human.kinect_v2 import JointType
from qpavoid.human.posture import random_posture

SAFE_M, NEAR_M = 0.05, 0.20  # "safe" threshold; the interesting range (capsules below it), m
NEAR_START_M = 0.10  # "near the capsule start" (A2 for L1, A4 for L2, A6 for EE), m
TRUNK = 1  # column of the trunk in the tables


def uncovered_zones(robot: qpavoid.Robot) -> np.ndarray:
    """(S,) length (m) of each capsule's start not covered by its own set's spheres.

    The points lie on the axes: a sphere covers the cross-section at axial distance h iff
    h^2 + r_c^2 <= r_s^2."""
    kin = robot.kinematics(robot.neutral(), jacobians=False)
    zones = []
    for k, s in enumerate(robot.sets):
        a, b = kin.segments[k]
        first = np.min((kin.points[list(s.points)] - a) @ (b - a)) / np.linalg.norm(b - a)
        zones.append(first - np.sqrt(s.sphere_radius_m**2 - s.capsule_radius_m**2))
    return np.array(zones)


def run(n: int, seed: int, spreads: list[float]) -> dict:
    """Sample, compute both tables and time them; returns per-sample arrays."""
    robot, human = qpavoid.load_robot("iiwa14"), qpavoid.KinectHuman()
    spheres, capsules = qpavoid.SphereDistance(robot, human), qpavoid.CapsuleDistance(robot, human)
    rng = np.random.default_rng(seed)
    spine_mid = list(human.joint_ids).index(int(JointType.SpineMid))
    out: dict = {
        k: np.empty((n, len(robot.sets), len(human.parts)))
        for k in ("sph", "cap", "robot_pos", "human_pos")
    }
    out.update({k: np.empty(n, dtype=np.int64) for k in ("t_sph", "t_cap", "t_in")})
    out["human_mid"] = np.empty(n)
    out["spread"] = np.array([spreads[i % len(spreads)] for i in range(n)])
    kin0 = robot.kinematics(robot.neutral(), jacobians=False)
    geo0 = human.geometry(random_posture(np.random.default_rng(seed + 1), kin0.points))
    for _ in range(200):  # warm-up
        spheres(kin0, geo0), capsules(kin0, geo0)
    pc = time.perf_counter_ns
    for i in range(n):
        q = rng.uniform(robot.q_min, robot.q_max)
        joints = random_posture(rng, robot.control_points(q), spread_m=float(out["spread"][i]))
        t0 = pc()
        kin = robot.kinematics(q, jacobians=False)
        geo = human.geometry(joints)
        t1 = pc()
        ts = spheres(kin, geo)
        t2 = pc()
        tc = capsules(kin, geo)
        t3 = pc()
        out["t_in"][i], out["t_sph"][i], out["t_cap"][i] = t1 - t0, t2 - t1, t3 - t2
        out["sph"][i], out["cap"][i] = ts.distance, tc.distance
        length = np.linalg.norm(kin.segments[:, 1] - kin.segments[:, 0], axis=1)
        out["robot_pos"][i] = tc.robot_s * length[:, None]  # along the set's axis, m
        a, ab = geo.segments[:, 0], geo.segments[:, 1] - geo.segments[:, 0]  # proximal first
        u = ab / np.linalg.norm(ab, axis=1)[:, None]
        out["human_pos"][i] = np.einsum("skx,kx->sk", tc.human_point - a, u)
        out["human_mid"][i] = (geo.points[spine_mid] - a[TRUNK]) @ u[TRUNK]  # SpineMid on trunk
    out.update(set_names=robot.set_names, part_names=human.part_names, zones=uncovered_zones(robot))
    return out


def stats(sph: np.ndarray, cap: np.ndarray) -> dict[str, float]:
    """Difference statistics and unsafe counts over paired 1-D samples (finite only)."""
    ok = np.isfinite(sph) & np.isfinite(cap)
    sph, cap = sph[ok], cap[ok]
    d, nan = sph - cap, float("nan")
    unsafe, n_close = int(np.sum((sph > SAFE_M) & (cap < SAFE_M))), int(np.sum(cap < SAFE_M))
    f = (lambda g: float(g(d))) if d.size else (lambda g: nan)
    return {
        "n": int(d.size),
        "mean": f(np.mean),
        "std": f(np.std),
        "under": f(np.min),
        "over": f(np.max),
        "n_cap_below_safe": n_close,
        "unsafe": unsafe,
        "unsafe_rate": unsafe / d.size if d.size else nan,
        "unsafe_rate_of_close": unsafe / n_close if n_close else nan,
    }


def comparison(r: dict) -> dict:
    """stats() per level (pairs, set minima) and group, over all and capsules < NEAR_M."""
    sph, cap, names = r["sph"], r["cap"], r["set_names"]
    smin, cmin = sph.min(axis=2), cap.min(axis=2)
    levels = {
        "pairs": {
            "all": (sph.ravel(), cap.ravel()),
            **{s: (sph[:, k].ravel(), cap[:, k].ravel()) for k, s in enumerate(names)},
        },
        "set_min": {
            "all": (smin.ravel(), cmin.ravel()),
            **{s: (smin[:, k], cmin[:, k]) for k, s in enumerate(names)},
            "robot": (smin.min(axis=1), cmin.min(axis=1)),
        },
    }
    return {
        lvl: {
            g: {"all": stats(s, c), "cap_below_near": stats(s[c < NEAR_M], c[c < NEAR_M])}
            for g, (s, c) in gs.items()
        }
        for lvl, gs in levels.items()
    }


def locations(r: dict, top: int) -> dict:
    """Where spheres over-estimate: per set (capsule start, uncovered zone), part, robot."""
    diff = np.where(np.isfinite(r["sph"]) & np.isfinite(r["cap"]), r["sph"] - r["cap"], np.nan)
    over, unsafe = diff > 0, (r["sph"] > SAFE_M) & (r["cap"] < SAFE_M)
    near, zone = r["robot_pos"] < NEAR_START_M, r["robot_pos"] < r["zones"][None, :, None] + 1e-6
    below_mid = r["human_pos"] > r["human_mid"][:, None, None]  # trunk: SpineMid-SpineBase
    cnt = lambda m: int(m.sum())  # noqa: E731
    per_set = {
        s: {
            "zone_m": float(r["zones"][k]),
            "n_over": cnt(over[:, k]),
            "over_near_start": cnt((over & near)[:, k]),
            "over_in_zone": cnt((over & zone)[:, k]),
            "max_over": float(np.nanmax(diff[:, k])),
            "max_diff_outside_zone": float(np.nanmax(np.where(zone, np.nan, diff)[:, k])),
            "n_over_outside_zone": cnt((over & ~zone)[:, k]),
            "max_cap_over_outside_zone": float(
                np.max(r["cap"][:, k][(over & ~zone)[:, k]], initial=-np.inf)
            ),
            "n_unsafe": cnt(unsafe[:, k]),
            "unsafe_near_start": cnt((unsafe & near)[:, k]),
        }
        for k, s in enumerate(r["set_names"])
    }
    per_part = {
        p: {
            "n_over": cnt(over[:, :, j]),
            "max_over": float(np.nanmax(diff[:, :, j])),
            "n_unsafe": cnt(unsafe[:, :, j]),
        }
        for j, p in enumerate(r["part_names"])
    }
    per_part["trunk"].update(
        over_below_spine_mid=cnt((over & below_mid)[:, :, TRUNK]),
        unsafe_below_spine_mid=cnt((unsafe & below_mid)[:, :, TRUNK]),
        max_diff_below_spine_mid_outside_zone=float(
            np.nanmax(np.where(below_mid & ~zone, diff, np.nan)[:, :, TRUNK])
        ),
    )
    n = diff.shape[0]  # whole robot: the capsule argmin gives the set and part
    ks, js = np.unravel_index(r["cap"].reshape(n, -1).argmin(axis=1), diff.shape[1:])
    cmin = r["cap"].min(axis=(1, 2))
    d_rob = r["sph"].min(axis=(1, 2)) - cmin
    robot = {
        "n_over": cnt(d_rob > 0),
        "n_over_cap_below_near": cnt((d_rob > 0) & (cmin < NEAR_M)),
        "over_by_set": {s: cnt((d_rob > 0) & (ks == k)) for k, s in enumerate(r["set_names"])},
        "over_in_zone": cnt((d_rob > 0) & zone[np.arange(n), ks, js]),
        "max_over_cap_below_safe": float(np.max(d_rob[cmin < SAFE_M], initial=-np.inf)),
        "max_sph_cap_below_safe": float(
            np.max(d_rob[cmin < SAFE_M] + cmin[cmin < SAFE_M], initial=-np.inf)
        ),
    }

    def worst(d: np.ndarray, cells: list[tuple[int, int, int]]) -> list[dict]:
        order = np.argsort(np.nan_to_num(d, nan=-np.inf))[::-1][:top]
        return [
            {
                "sample": i,
                "set": r["set_names"][k],
                "part": r["part_names"][j],
                "diff": float(d[m]),
                "capsules": float(r["cap"][i, k, j]),
                "robot_pos_m": float(r["robot_pos"][i, k, j]),
                "human_pos_m": float(r["human_pos"][i, k, j]),
            }
            for m in order
            for i, k, j in [cells[m]]
        ]

    cells = [tuple(int(x) for x in c) for c in np.ndindex(*diff.shape)]
    close = np.where(r["cap"] < NEAR_M, diff, -np.inf).ravel()
    return {
        "per_set": per_set,
        "per_part": per_part,
        "robot": robot,
        "worst_pairs": worst(diff.ravel(), cells),
        "worst_close_pairs": worst(close, cells),
        "worst_robot": worst(d_rob, [(i, int(ks[i]), int(js[i])) for i in range(n)]),
    }


def report(r: dict, top: int) -> dict:
    """All the numbers, as a JSON-ready dict."""
    cmin = r["cap"].min(axis=2)
    close = {
        f"spread_{s:g}": {
            "n": int(m.sum()),
            "below_safe": float(np.mean(cmin[m] < SAFE_M)),
            "below_near": float(np.mean(cmin[m] < NEAR_M)),
        }
        for s in np.unique(r["spread"])
        for m in [r["spread"] == s]
    }
    close["all"] = {
        "n": len(cmin),
        "below_safe": float(np.mean(cmin < SAFE_M)),
        "below_near": float(np.mean(cmin < NEAR_M)),
        "robot_below_safe": float(np.mean(cmin.min(axis=1) < SAFE_M)),
        "robot_below_near": float(np.mean(cmin.min(axis=1) < NEAR_M)),
    }
    timing = {
        k: {
            "median_us": float(np.median(us)),
            "p99_us": float(np.percentile(us, 99)),
            "mean_us": float(np.mean(us)),
        }
        for k, t in (
            ("spheres", "t_sph"),
            ("capsules", "t_cap"),
            ("kinematics_plus_geometry", "t_in"),
        )
        for us in [r[t] / 1e3]
    }
    return {
        "closeness_set_min": close,
        "comparison": comparison(r),
        "locations": locations(r, top),
        "timing": timing,
    }


def show(rep: dict, args: argparse.Namespace) -> None:
    """Print the readable report (differences in mm, positions in m)."""
    mm, loc = 1e3, rep["locations"]
    print(
        f"qpavoid distance benchmark: n={args.n} seed={args.seed} spreads={args.spreads} m "
        f"(Python {platform.python_version()}, {platform.machine()})"
    )
    print("\nCloseness (set minima of the capsule distance; whole robot = table minimum):")
    for g, c in rep["closeness_set_min"].items():
        extra = (
            f"  whole robot: <0.05 m {c['robot_below_safe']:.1%}, <0.20 m "
            f"{c['robot_below_near']:.1%}"
            if g == "all"
            else ""
        )
        print(
            f"  {g:12s} samples {c['n']:6d}  <0.05 m {c['below_safe']:6.1%}  <0.20 m "
            f"{c['below_near']:6.1%}{extra}"
        )
    for lvl, gs in rep["comparison"].items():
        for sub, label in (("all", "all finite"), ("cap_below_near", "capsules < 0.20 m")):
            print(f"\n{lvl} ({label}); diff = spheres - capsules; unsafe = sph > .05 & cap < .05")
            print("  group        n   mean   std  under  over cap<.05 unsafe    rate of cap<.05")
            for g, s in ((g, s[sub]) for g, s in gs.items()):
                print(
                    f"  {g:6s} {s['n']:7d} {s['mean'] * mm:6.1f} {s['std'] * mm:5.1f} "
                    f"{s['under'] * mm:6.1f} {s['over'] * mm:5.1f} {s['n_cap_below_safe']:7d} "
                    f"{s['unsafe']:6d} {s['unsafe_rate']:7.3%} {s['unsafe_rate_of_close']:10.2%}"
                )
    print(
        "\nOver-estimates (diff > 0). pos = capsule witness along the axis from its start "
        "(L1: A2, L2: A4, EE: A6); zone = start not covered by the set's own spheres"
    )
    for s, v in loc["per_set"].items():
        print(
            f"  {s:3s} zone {v['zone_m']:.3f}  n_over {v['n_over']:6d} (pos<0.1: "
            f"{v['over_near_start']}, in zone: {v['over_in_zone']})  max {v['max_over'] * mm:5.1f}"
            f"; unsafe {v['n_unsafe']} (pos<0.1: {v['unsafe_near_start']})\n"
            f"      outside zone: max diff {v['max_diff_outside_zone'] * mm:5.1f}, n_over "
            f"{v['n_over_outside_zone']} (largest capsule distance among them "
            f"{v['max_cap_over_outside_zone']:.3f} m)"
        )
    for p, v in loc["per_part"].items():
        extra = (
            f"  below SpineMid: over {v['over_below_spine_mid']}, unsafe "
            f"{v['unsafe_below_spine_mid']}, max diff with robot witness outside zone "
            f"{v['max_diff_below_spine_mid_outside_zone'] * mm:.1f}"
            if p == "trunk"
            else ""
        )
        print(
            f"  {p:15s} n_over {v['n_over']:6d}  max {v['max_over'] * mm:5.1f}  unsafe "
            f"{v['n_unsafe']:4d}{extra}"
        )
    rb = loc["robot"]
    print(
        f"  whole robot: n_over {rb['n_over']} (capsules < 0.2 m: {rb['n_over_cap_below_near']}),"
        f" by set of the capsule minimum {rb['over_by_set']}, in zone {rb['over_in_zone']};"
        f" where capsules < 0.05 m: max diff {rb['max_over_cap_below_safe'] * mm:.1f}, max "
        f"spheres {rb['max_sph_cap_below_safe']:.3f} m"
    )
    for key, title in (
        ("worst_pairs", "pairs"),
        ("worst_close_pairs", "pairs, capsules < 0.2 m"),
        ("worst_robot", "whole robot (set/part of the capsule minimum)"),
    ):
        print(f"Worst over-estimates, {title}:")
        for w in loc[key]:
            print(
                f"  #{w['sample']:5d} {w['set']:3s} {w['part']:15s} diff {w['diff'] * mm:5.1f}  "
                f"capsules {w['capsules']:6.3f}  robot pos {w['robot_pos_m']:.3f}  human pos "
                f"{w['human_pos_m']:.3f}"
            )
    print("\nTime per call (us): median / p99 / mean")
    for k, t in rep["timing"].items():
        print(f"  {k:25s} {t['median_us']:8.1f} {t['p99_us']:8.1f} {t['mean_us']:8.1f}")


def main(argv: list[str] | None = None) -> None:
    """Command-line entry point."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=10000, help="number of samples")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument(
        "--spreads",
        type=lambda s: [float(x) for x in s.split(",")],
        default=[0.10, 0.25],
        help="hand-target spreads (m), comma-separated, in turn",
    )
    ap.add_argument("--top", type=int, default=5, help="worst over-estimates listed")
    ap.add_argument("--json", metavar="FILE", help="also write the numbers as JSON")
    args = ap.parse_args(argv)
    rep = report(run(args.n, args.seed, args.spreads), args.top)
    show(rep, args)
    if args.json:
        rep["config"] = {
            "n": args.n,
            "seed": args.seed,
            "spreads_m": args.spreads,
            "safe_m": SAFE_M,
            "near_m": NEAR_M,
            "near_start_m": NEAR_START_M,
        }
        with open(args.json, "w") as fh:  # NaN/inf (empty group) -> null: strict JSON
            fh.write(
                json.dumps(rep, indent=1)
                .replace("NaN", "null")
                .replace("-Infinity", "null")
                .replace("Infinity", "null")
                + "\n"
            )


if __name__ == "__main__":
    main()
