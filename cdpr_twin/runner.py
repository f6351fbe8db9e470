"""The headless run: sense → estimate → control → actuate → step → record (DESIGN §6)."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from cdpr_twin.controllers import Command, Controller, make_controller
from cdpr_twin.estimators import Estimator, PoseEstimate, make_estimator
from cdpr_twin.metrics import DeviationTrack, pose_error
from cdpr_twin.record import CsvRecorder, RerunRecorder, SceneInfo, write_json_atomic
from cdpr_twin.scenario import Scenario, ScenarioError
from cdpr_twin.se3 import pose_distance, pose_distances, vector_from_pose
from cdpr_twin.statics import InfeasibleTensionError, tension_distribution


@dataclass
class RunSetup:
    """Everything a run needs, built and validated before any output is written."""

    scenario: Scenario
    twin: object  # cdpr_twin.sim.Twin (kept untyped: this module does not import mujoco)
    estimators: dict[str, Estimator]
    controller: Controller
    goal_pose: np.ndarray | None


@dataclass(frozen=True)
class RunResult:
    """What :func:`run` returns.

    Attributes:
        summary: the content of ``summary.json``.
        wall_time: seconds of wall-clock time the loop took.
        out_dir: where the outputs are, or ``None``.
    """

    summary: dict
    wall_time: float
    out_dir: Path | None

    @property
    def real_time_factor(self) -> float:
        """Simulated seconds per wall-clock second."""
        return self.summary["simulated_time_s"] / max(self.wall_time, 1e-9)


def prepare(scenario: Scenario) -> RunSetup:
    """Build the twin, estimators and controller; map every problem to a scenario field.

    Raises:
        ScenarioError: naming the file and field at fault.
    """
    from cdpr_twin.sim import ModelError, Twin  # the runner's only door to MuJoCo

    src = scenario.source
    try:
        twin = Twin(
            model_path=scenario.model.file,
            deviations=scenario.truth,
            tension_noise_std=scenario.sensors.tension_noise_std,
            noise_seed=scenario.seed,
            camera=scenario.sensors.camera,
            align_every=scenario.model.align_every,
            timestep=scenario.model.timestep,
        )
    except ModelError as exc:
        raise ScenarioError(f"{src}: model.file: {exc}") from None
    except ValueError as exc:
        raise ScenarioError(f"{src}: model: {exc}") from None
    geom = twin.nominal_geometry
    try:
        twin.reset(scenario.start_pose, settle_time=0.0)
    except (ValueError, InfeasibleTensionError) as exc:
        twin.close()
        raise ScenarioError(f"{src}: start.pose: {exc}") from None
    params = dict(scenario.controller.params)
    if scenario.controller.type == "open_loop":
        for i, w in enumerate(params["waypoints"]):
            try:
                geom.check_pose_inside(w, "waypoint")
                tension_distribution(geom, w, tau_min=0.5)
            except (ValueError, InfeasibleTensionError) as exc:
                twin.close()
                raise ScenarioError(
                    f"{src}: controller.waypoints[{i}]: "
                    f"{vector_from_pose(w).round(4).tolist()} is outside the "
                    f"workspace: {exc}"
                ) from None
    try:
        controller = make_controller(scenario.controller.type, geom, **params)
        estimators = {
            name: make_estimator(name, geom, **scenario.estimators.options.get(name, {}))
            for name in scenario.estimators.names
        }
    except ValueError as exc:
        twin.close()
        raise ScenarioError(f"{src}: {exc}") from None
    goal = None
    if scenario.controller.type == "open_loop":
        goal = params["waypoints"][-1]
    elif twin.nominal_T_base_tag is not None:  # the pose at which the nominal robot sees s*
        goal = controller.platform_goal(twin.nominal_T_base_tag)
    return RunSetup(scenario, twin, estimators, controller, goal)


def _scene(twin) -> SceneInfo:
    g = twin.true_geometry
    return SceneInfo(
        a_base=g.a_base,
        b_platform=g.b_platform,
        platform_half_size=twin.platform_half_size,
        T_platform_cam=g.T_platform_cam,
        intrinsics=twin.intrinsics,
        T_base_tag=twin.T_base_tag if twin.nominal_T_base_tag is not None else None,
        tag_size=twin.tag_size if twin.nominal_T_base_tag is not None else 0.0,
        frame_min=g.frame_min,
        frame_max=g.frame_max,
    )


def run(
    scenario: Scenario,
    out_dir: Path | None = None,
    progress: Callable[[float, float], None] | None = None,
    spawn: bool = False,
    record_rrd: bool = True,
) -> RunResult:
    """Run a scenario headless and write its outputs.

    Args:
        scenario: a validated scenario.
        out_dir: output directory (created); ``None`` writes nothing.
        progress: called after each tick with (fraction done, simulated time).
        spawn: also stream to a live Rerun viewer.
        record_rrd: write ``recording.rrd`` (with ``out_dir``).

    Returns:
        The :class:`RunResult`. On Ctrl-C the outputs so far are completed and flushed, the
        summary says ``"status": "interrupted"``, and KeyboardInterrupt is raised again.
    """
    setup = prepare(scenario)
    twin, estimators, controller = setup.twin, setup.estimators, setup.controller
    in_loop = scenario.estimators.in_loop
    period = scenario.model.control_period
    n_ticks = round(scenario.duration / period)
    names = scenario.estimators.names
    tracks = {name: DeviationTrack() for name in names}
    csv_rec = rrd_rec = None
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        csv_rec = CsvRecorder(out_dir / "timeseries.csv", names, twin.true_geometry.n_cables)
        if record_rrd:
            rrd_rec = RerunRecorder(
                out_dir / "recording.rrd",
                _scene(twin),
                names,
                "cdpr-twin",
                f"{scenario.name}-{scenario.seed}",
                spawn=spawn,
            )
    checkpoints = _checkpoints(scenario)
    segment_ends: list[dict] = []
    status, command = "running", None
    last_tag = None
    counts = {"tag_lost_ticks": 0, "saturated_ticks": 0}

    def record(m, estimates: dict[str, PoseEstimate], command: Command | None) -> None:
        plan = controller.planned_pose(m.time)
        dts, drs = pose_distances(
            np.array([e.T_base_platform for e in estimates.values()]), m.T_base_platform_true[None]
        )
        deviations = {
            n: tracks[n].add(e, m.T_base_platform_true, (float(a), float(b)))
            for (n, e), a, b in zip(estimates.items(), dts, drs, strict=True)
        }
        if csv_rec is not None:
            csv_rec.tick(m, estimates, command, plan)
        if rrd_rec is not None:
            rrd_rec.tick(m, estimates, deviations, plan)
        for t_c, waypoint in checkpoints:
            if abs(m.time - t_c) < 0.5 * period:
                segment_ends.append(
                    {
                        "time_s": m.time,
                        "waypoint": vector_from_pose(waypoint).tolist(),
                        "truth_vs_waypoint": pose_error(m.T_base_platform_true, waypoint),
                        "estimates_vs_truth": {
                            n: pose_error(e.T_base_platform, m.T_base_platform_true)
                            for n, e in estimates.items()
                        },
                        "estimates_vs_plan": {
                            n: pose_error(e.T_base_platform, waypoint) for n, e in estimates.items()
                        },
                    }
                )

    start = time.perf_counter()
    try:
        twin.reset(scenario.start_pose)
        controller.reset(scenario.start_pose)
        for est in estimators.values():
            est.reset(scenario.start_pose, 0.0)
        m = twin.sense()
        estimates = {n: est.update(m) for n, est in estimators.items()}
        record(m, estimates, None)
        for k in range(n_ticks):
            command = controller.command(k * period, period, estimates[in_loop], m)
            counts["tag_lost_ticks"] += command.status == "tag_lost"
            counts["saturated_ticks"] += command.status == "saturated"
            twin.advance(period, command.cable_rates, command.twist_platform)
            m = twin.sense()
            last_tag = m.tag if m.tag is not None else last_tag
            estimates = {n: est.update(m) for n, est in estimators.items()}
            record(m, estimates, command)
            if progress is not None:
                progress((k + 1) / n_ticks, m.time)
            if command.done:
                status = command.status
                break
        else:
            status = "time_limit" if scenario.controller.type == "pbvs" else "completed"
    except KeyboardInterrupt:
        status = "interrupted"
        raise
    except Exception as exc:  # a diverged simulation or an impossible command: keep the record
        status = f"failed: {type(exc).__name__}: {exc}"
        raise
    finally:
        wall = time.perf_counter() - start
        summary = _summary(setup, tracks, twin, status, segment_ends, command, last_tag, counts)
        if csv_rec is not None:
            csv_rec.close()
            summary["ticks_recorded"] = csv_rec.rows
        if rrd_rec is not None:
            rrd_rec.close()
        if out_dir is not None:
            write_json_atomic(out_dir / "summary.json", summary)
        twin.close()
    return RunResult(summary, wall, out_dir)


def _checkpoints(scenario: Scenario) -> list[tuple[float, np.ndarray]]:
    if scenario.controller.type != "open_loop":
        return []
    params = scenario.controller.params
    ends = np.cumsum(params["durations"])
    return [
        (float(t), w)
        for t, w in zip(ends, params["waypoints"], strict=True)
        if t <= scenario.duration + 1e-9
    ]


def _summary(
    setup: RunSetup,
    tracks: dict[str, DeviationTrack],
    twin,
    status: str,
    segment_ends: list[dict],
    command: Command | None,
    last_tag,
    counts: dict,
) -> dict:
    s, goal = setup.scenario, setup.goal_pose
    T_end = twin.T_base_platform
    out = {
        "scenario": s.name,
        "source": str(s.source),
        "status": status,
        "controller": s.controller.type,
        "in_loop": s.estimators.in_loop,
        "estimator_names": list(s.estimators.names),
        "seed": s.seed,
        "truth_seed": s.truth.seed,
        "camera": s.sensors.camera,
        "overrides": dict(s.overrides),
        "timestep_s": s.model.timestep,
        "control_rate_hz": s.model.control_rate,
        "simulated_time_s": twin.time,
        "final_pose": vector_from_pose(T_end).tolist(),
        "goal_pose": None if goal is None else vector_from_pose(goal).tolist(),
        "final_error_vs_goal": None if goal is None else pose_error(T_end, goal),
        "estimators": {n: t.summary() for n, t in tracks.items()},
        "segment_ends": segment_ends,
        "final_tensions_n": twin.tensions.tolist(),
    }
    if s.controller.type == "pbvs":
        goal = s.controller.params["goal_T_cam_tag"]
        tag_err = None
        if last_tag is not None:
            dt, dr = pose_distance(last_tag.T_cam_tag, goal)
            tag_err = {"translation_m": dt, "rotation_deg": float(np.degrees(dr))}
        out["pbvs"] = {
            "converged": status == "converged",
            "final_tag_error": tag_err,
            "true_final_tag_error": pose_error(twin.T_cam_tag, goal),
            **counts,
        }
    return out
