"""What the study's explanations need of the robot: its calibration errors and cable physics.

Numbers of the robot the runs were made with (its scenario file and model), and of the cables
along a run (stretch, pulley wrap, sag), for :mod:`.analysis`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cdpr_twin.recording.timeseries import Timeseries


def model_physics(ts: Timeseries, scenario_file: Path) -> dict:
    """Why the model-based variants agree or not: stretch, wrap and sag along the run."""
    from cdpr_twin.math import kinematics as kin
    from cdpr_twin.scenario.loading import load_scenario
    from cdpr_twin.sim import build_model, read_geometry
    from cdpr_twin.sim.model import numeric

    model = build_model(load_scenario(scenario_file).model.file)
    geom = read_geometry(model)
    try:
        rho = float(numeric(model, "cable_linear_density")[0])
    except ValueError:  # a model without it: massless cables, no sag to estimate
        rho = float("nan")
    tau, l0 = ts.matrix("tension"), ts.matrix("length")
    stretch = np.abs(tau) * l0 / geom.es  # eq. 14 with τ(0) = 0
    T = ts.poses("true")
    wrap = np.array(
        [
            kin.cable_lengths(geom, Ti, "pulley") - kin.cable_lengths(geom, Ti)
            for Ti in T[:: max(1, len(T) // 200)]
        ]
    )
    return {
        "max_stretch_m": float(np.nanmax(stretch)),
        "wrap_min_m": float(wrap.min()),
        "wrap_max_m": float(wrap.max()),
        "wrap_change_max_m": float((wrap.max(axis=0) - wrap.min(axis=0)).max()),
        **sag_numbers(geom, rho, T[:: max(1, len(T) // 50)], tau[:: max(1, len(T) // 50)]),
    }


def sag_numbers(geom, rho: float, poses: np.ndarray, tau: np.ndarray) -> dict[str, float]:
    """Largest mid-span sag, and arc − chord, of the cables along the run if they had their mass.

    Irvine's elastic catenary (:mod:`cdpr_twin.math.catenary`, exact, not the small-sag law) for
    each span A_i → B_i with a tension above 1 N, its unstretched length the straight one at
    the measured tension; NaN without a density (rho [kg/m]).

    Returns:
        ``{"max_sag_m": …, "max_sag_excess_m": …}`` [m].
    """
    from cdpr_twin.math.catenary import CatenaryError, solve_catenary

    if not rho > 0:
        return {"max_sag_m": float("nan"), "max_sag_excess_m": float("nan")}
    sag = excess = 0.0
    for T, t in zip(poses, tau, strict=True):
        span = geom.a_base - (geom.b_platform @ T[:3, :3].T + T[:3, 3])
        for i, (d, ti) in enumerate(zip(span, t, strict=True)):
            h, chord = float(np.hypot(d[0], d[1])), float(np.linalg.norm(d))
            if not (ti > 1.0 and h > 0):
                continue
            try:
                cat = solve_catenary(
                    chord / (1.0 + ti / geom.es[i]), geom.es[i], rho * 9.81, h, d[2]
                )
            except CatenaryError:
                continue
            sag, excess = max(sag, cat.sag), max(excess, cat.length - chord)
    return {"max_sag_m": sag, "max_sag_excess_m": excess}


def robot_errors(scenario_file: str | Path) -> dict:
    """The drawn robot's calibration errors, and what the explanations need of the robot.

    Camera-mount and tag-placement errors, the largest exit- and anchor-point offsets, the tag's
    size, the PBVS goal's camera–tag distance, and whether the cables sag in the physics.
    """
    from cdpr_twin.scenario.loading import load_scenario
    from cdpr_twin.sim import build_model, cable_count
    from cdpr_twin.sim.model import has_numeric, numeric

    scenario = load_scenario(scenario_file)
    model = build_model(scenario.model.file)
    dev = scenario.truth.draw(cable_count(model))  # as the twin does
    goal = getattr(scenario.controller.options, "goal_T_cam_tag", None)
    try:
        tag = float(numeric(model, "tag_size")[0])
    except ValueError:  # no tag in this model
        tag = float("nan")
    return {
        "camera_rotation_deg": float(np.degrees(np.linalg.norm(dev.camera_offset[3:]))),
        "camera_position_m": float(np.linalg.norm(dev.camera_offset[:3])),
        "tag_rotation_deg": float(np.degrees(np.linalg.norm(dev.tag_offset[3:]))),
        "tag_position_m": float(np.linalg.norm(dev.tag_offset[:3])),
        "exit_point_error_max_m": float(np.linalg.norm(dev.exit_offsets, axis=1).max()),
        "anchor_point_error_max_m": float(np.linalg.norm(dev.anchor_offsets, axis=1).max()),
        "tag_size_m": tag,
        "goal_tag_distance_m": float("nan") if goal is None else float(goal[2, 3]),
        "sag_simulated": has_numeric(model, "cable_sag"),
    }


def payloads(records: list[dict]) -> dict[str, float]:
    """The payload each experiment's scenario fixes to the platform [kg]."""
    from cdpr_twin.scenario.loading import load_scenario

    files = {r["kind"]: r["scenario"] for r in records}
    return {kind: float(load_scenario(f).model.payload) for kind, f in files.items()}
