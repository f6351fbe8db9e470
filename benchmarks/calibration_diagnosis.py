"""Where a calibration's common scale comes from, on one robot.

    python benchmarks/calibration_diagnosis.py --seed 4
    python benchmarks/calibration_diagnosis.py --seed 4 --set realism.camera.noise=false \\
        --set "realism.camera.distortion=[0,0,0,0]" --set realism.camera.focal_error_std=0 \\
        --set realism.camera.center_error_std_px=0 \\
        --set "realism.camera.distortion_error_std=[0,0,0,0]"

Records robot SEED's calibration (run seed 1 + SEED, 240 poses, as the study does) once, then:

1. the readings at the twin's truth: each drum's scale fitted from its own cable's encoder
   readings against the true rest lengths (true geometry, true poses, elastic pulley model),
   and how far the detected tag views read from the true ones (distance ratio; the spread of
   their camera-frame positions regressed on the true ones, per axis);
2. the solve three ways — with the noise model written down beforehand only, weighted by the
   variance components (what ``cdpr-twin calibrate`` does), and the same with the tag views
   replaced by the exact ones from the truth — each with the drums' common-scale error and
   the exit points' absolute and shape errors.

``--set KEY=VALUE`` changes the scenario as in ``calibration_study.py`` (the second command
above: an ideal camera).
"""

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from calibration_study import scenario


def true_views(rec) -> np.ndarray:
    """(K, 4, 4) the tag poses the camera would see at the truth, at every recorded pose."""
    from cdpr_twin.math.se3 import inverse

    tr = rec.truth
    cam = inverse(tr.geometry.T_platform_cam)
    return np.array([cam @ inverse(T) @ tr.T_base_tag for T in tr.T_base_platform])


def at_truth(rec) -> None:
    """Part 1: drum scales from the encoders, tag views against the truth."""
    from cdpr_twin.math.kinematics import pulley_vectors

    o, tr = rec.obs, rec.truth
    g, T = tr.geometry, tr.T_base_platform
    print("drum scale from each cable's readings at the truth [%] (fitted / drawn, residual):")
    for i in range(g.n_cables):
        k = np.flatnonzero(o.taut[:, i])
        b = np.einsum("nij,j->ni", T[k, :3, :3], g.b_platform[i]) + T[k, :3, 3]
        a = np.repeat(g.a_base[i][None], len(k), 0)
        l_f, _ = pulley_vectors(a, np.full(len(k), g.pulley_radius[i]), b)
        l0 = g.es[i] * l_f / (g.es[i] + o.tensions[k, i])
        e = o.encoder[k, i]
        A = np.c_[np.ones(len(k)), e - e.mean()]
        coef, *_ = np.linalg.lstsq(A, l0 - e, rcond=None)
        rms = np.sqrt(np.mean((l0 - e - A @ coef) ** 2))
        print(
            f"  cable {i + 1}: {coef[1] * 100:+.4f} / {tr.drum_scale[i] * 100:+.4f}"
            f"  ({rms * 1e6:.1f} µm)"
        )
    seen = np.flatnonzero(o.seen)
    true = true_views(rec)[seen]
    meas = o.T_cam_tag[seen]
    ratio = np.linalg.norm(meas[:, :3, 3], axis=1) / np.linalg.norm(true[:, :3, 3], axis=1) - 1
    P = true[:, :3, 3] - true[:, :3, 3].mean(axis=0)
    M = meas[:, :3, 3] - meas[:, :3, 3].mean(axis=0)
    spread = [(M[:, j] @ P[:, j]) / (P[:, j] @ P[:, j]) - 1 for j in range(3)]
    print(
        f"tag views ({len(seen)}): distance read {ratio.mean() * 100:+.3f} % (std "
        f"{ratio.std() * 100:.3f} %); spread read x {spread[0] * 100:+.3f} %, "
        f"y {spread[1] * 100:+.3f} %, z {spread[2] * 100:+.3f} %"
    )


def solves(outcome, nominal, frames: int) -> None:
    """Part 2: the common scale and the exit points, solved three ways."""
    from cdpr_twin.calibrate.pipeline import noise_of, truth_check
    from cdpr_twin.calibrate.problem import Problem
    from cdpr_twin.calibrate.solver import solve, solve_weighted

    rec, tr = outcome.recording, outcome.recording.truth
    exact = true_views(rec)
    exact_obs = replace(
        rec.obs, T_cam_tag=np.where(rec.obs.seen[:, None, None], exact, rec.obs.T_cam_tag)
    )
    for label, obs, weighted in (
        ("noise model as written", rec.obs, False),
        ("variance components", rec.obs, True),
        ("variance components, exact tag views", exact_obs, True),
    ):
        p = Problem(
            nominal.geometry,
            nominal.T_base_tag,
            obs,
            outcome.priors,
            noise_of(rec, frames),
            rec.detector,
        )
        cal = solve_weighted(p)[0] if weighted else solve(p)
        solved = replace(outcome, calibration=cal, recording=replace(rec, obs=obs))
        c = truth_check(solved, nominal.geometry, nominal.T_base_tag)["calibrated"]
        common = (cal.model.scale.mean() - tr.drum_scale.mean()) * 100
        print(
            f"{label:38s} drums' common scale {common:+.3f} %, exit points "
            f"{c['exit_error_median_mm']:.2f} mm (shape {c['exit_shape_error_median_mm']:.2f} "
            f"mm), centroid {c['exit_frame_shift_mm']} mm"
        )


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, default=4, help="truth seed (robot)")
    ap.add_argument("--poses", type=int, default=240)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE")
    a = ap.parse_args()
    from cdpr_twin.calibrate.pipeline import calibrate
    from cdpr_twin.sim import build_robot

    s = scenario(a.set)
    s = replace(s, truth=replace(s.truth, seed=a.seed))
    outcome = calibrate(replace(s, seed=s.seed + a.seed), a.poses, workers=a.workers)
    nominal = build_robot(s.model.file).nominal
    changes = f", {a.set}" if a.set else ""
    print(f"robot {a.seed}, {outcome.recording.obs.n_poses} poses{changes}")
    at_truth(outcome.recording)
    solves(outcome, nominal, frames=4)


if __name__ == "__main__":
    main()
