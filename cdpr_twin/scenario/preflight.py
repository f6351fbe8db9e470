"""Checks of a scenario's task against the nominal robot, before anything runs.

What :func:`cdpr_twin.run.runner.prepare` refuses about the controller (its options against the
nominal geometry, its control period, the goal it servos to) without building the twin, so
that a campaign can check every run before the first starts (:func:`check_task`).
"""

from __future__ import annotations

import numpy as np

from cdpr_twin import plugins
from cdpr_twin.controllers.base import Controller
from cdpr_twin.options import OptionError
from cdpr_twin.scenario.loading import Scenario, ScenarioError


def controller_for(scenario: Scenario, nominal) -> Controller:
    """The scenario's controller for the nominal robot, checked against its control period.

    The start pose is checked first (:func:`check_start`), as the open-loop waypoints are: the
    nominal robot holds it; a plan, after (:func:`check_plan`). ``run`` and a campaign's checks
    refuse them alike.
    """
    geom = nominal.geometry
    check_start(scenario, geom)
    src = scenario.source
    cls = plugins.lookup("controller", scenario.controller.type)
    try:
        controller = cls(geom, scenario.controller.options)
        controller.check_period(scenario.model.control_period)
    except OptionError as exc:
        raise ScenarioError(f"{src}: controller.{exc.field}: {exc.problem}") from None
    except (Exception, SystemExit) as exc:  # a plugin's own failure (or exit): no traceback
        raise ScenarioError(f"{src}: controller: {type(exc).__name__}: {exc}") from None
    check_plan(scenario, nominal.rate_range, controller)
    return controller


def check_plan(s: Scenario, rate_range, controller: Controller) -> None:
    """Refuse commands the winches cannot follow, before a run (which would stop at the first).

    A plan (open loop): the rates it will command, tick by tick (they read no sensor), on the
    nominal robot. A servo with speed caps (PBVS): the fastest cable rate the caps allow.

    Args:
        s: the scenario.
        rate_range: ((m,), (m,)) the winches' rate range [m/s], or ``None`` (nothing checked).
        controller: the scenario's controller.

    Raises:
        ScenarioError: naming ``controller.durations[i]`` (the segment at fault) or
            ``controller.max_linear_speed``.
    """
    planned = getattr(controller, "planned_rates", None)
    # a plan's segments: the one at fault is named by its index
    durations = getattr(controller, "durations", ())
    capped = getattr(controller, "peak_cable_rate", None)
    if rate_range is None:
        return
    if capped is not None:
        peak, limit = capped(), float(min(rate_range[1].min(), -rate_range[0].max()))
        if peak > limit:
            raise ScenarioError(
                f"{s.source}: controller.max_linear_speed: with max_angular_speed_deg, the "
                f"speed caps let the servo command cable rates up to {peak:.3g} m/s "
                f"(v_max + (|t_pc| + max |b_i|)·ω_max), beyond the winches' {limit:.3g} m/s; "
                "lower them"
            )
    if planned is None:
        return
    period = s.model.control_period
    rates = planned(s.start_pose, period, s.duration)
    lo, hi = rate_range
    over = np.flatnonzero(((rates < lo) | (rates > hi)).any(axis=1))
    if not over.size:
        return
    k = int(over[0])
    t = (k + 0.5) * period
    i = int(np.searchsorted(np.cumsum(durations), t))
    cable = int(np.argmax(np.maximum(rates[k] - hi, lo - rates[k])))
    raise ScenarioError(
        f"{s.source}: controller.durations[{i}]: at t = {t:.3g} s the plan drives cable "
        f"{cable + 1} out at {rates[k, cable]:.3g} m/s, beyond its winch's range "
        f"[{lo[cable]:.3g}, {hi[cable]:.3g}] m/s (peak {np.abs(rates).max():.3g} m/s over the "
        "plan); make the segment longer"
    )


def check_task(scenario: Scenario, nominals: dict | None = None) -> None:
    """Refuse what ``runner.prepare`` would refuse about the task, without building the twin.

    The controller against the nominal robot (waypoints, segment durations, the goal); a
    campaign checks each of its runs so before any starts (the nominal robot built once per
    model: ``nominals`` caches it).

    Raises:
        ScenarioError: naming the file and field at fault.
    """
    from cdpr_twin.sim import ModelError, nominal_robot

    s, nominals = scenario, {} if nominals is None else nominals
    m = s.model
    key = (str(m.file), str(m.nominal), float(m.payload), tuple(np.ravel(m.payload_com).tolist()))
    if key not in nominals:
        try:
            nominals[key] = nominal_robot(m.file, m.nominal, (m.payload, m.payload_com))
        except ModelError as exc:
            raise ScenarioError(f"{s.source}: {exc.field}: {exc}") from None
        except ValueError as exc:
            raise ScenarioError(f"{s.source}: model: {exc}") from None
    nominal = nominals[key]
    check_camera(s, nominal.intrinsics)
    controller = controller_for(s, nominal)  # the start pose and a plan's rates too
    if controller.goal_is_taught:
        # checked when shown to the true robot, as runner.prepare does: its pose, not the
        # nominal model's view
        return
    try:
        goal = controller.goal_pose(nominal.T_base_tag)
    except (Exception, SystemExit) as exc:  # a plugin's own failure (or exit): no traceback
        raise ScenarioError(f"{s.source}: controller: {type(exc).__name__}: {exc}") from None
    if goal is not None:
        check_goal(s, nominal, controller, goal)


def check_camera(s: Scenario, intrinsics) -> None:
    """Refuse camera settings the run's camera would refuse when built (its exposure, its size).

    Raises:
        ScenarioError: naming the field.
    """
    from cdpr_twin.sim.camera import check_frame_size
    from cdpr_twin.sim.imaging import lens_margins

    cam = s.realism.camera
    if not s.sensors.camera or intrinsics is None:
        return
    period = s.model.control_period
    if cam.exposure_s > period:
        raise ScenarioError(
            f"{s.source}: realism.camera.exposure_s: {cam.exposure_s:g} s is longer than the "
            f"camera's read period ({period:g} s, one frame a control tick); shorten it"
        )
    try:  # the frame alone first: the lens's margins cost memory in proportion to it
        check_frame_size(intrinsics.width, intrinsics.height, cam.supersample)
        margins = lens_margins(intrinsics.scaled(cam.supersample), cam.distortion)
        check_frame_size(intrinsics.width, intrinsics.height, cam.supersample, margins)
    except ValueError as exc:
        raise ScenarioError(f"{s.source}: {exc}") from None


def check_start(s: Scenario, geometry) -> None:
    """Refuse a start pose outside the frame or that no tension distribution holds.

    For the nominal robot, as the open-loop waypoints are checked (``runner.prepare`` also
    places the true robot there, moved by its homing offset, and refuses what it cannot hold).

    Raises:
        ScenarioError: naming ``start.pose``.
    """
    from cdpr_twin.math.workspace import infeasible_reason, is_feasible

    try:
        geometry.check_pose_inside(s.start_pose, "start.pose")
    except ValueError as exc:
        raise ScenarioError(f"{s.source}: start.pose: {exc}") from None
    if not is_feasible(geometry, s.start_pose):
        raise ScenarioError(f"{s.source}: start.pose {infeasible_reason(geometry)}")


def check_goal(s: Scenario, nominal, controller, goal: np.ndarray) -> None:
    """Refuse an unreachable goal or a goal view without the whole tag, before a run.

    :func:`check_goal_pose` and :func:`check_goal_view`, as ``runner.prepare`` and campaigns
    check them.

    Raises:
        ScenarioError: naming the file and field at fault.
    """
    check_goal_pose(s, nominal.geometry, goal)
    view = getattr(controller.options, "goal_T_cam_tag", None)
    if view is not None and nominal.intrinsics is not None and nominal.tag_size > 0:
        check_goal_view(s, nominal.intrinsics, nominal.tag_size, np.asarray(view, dtype=float))


def check_goal_view(s: Scenario, intrinsics, tag_size: float, T_cam_tag: np.ndarray) -> None:
    """Refuse a goal view in which the camera would not see the whole tag.

    The servo measures its feature from the tag's detection: with a corner outside the image it
    loses the tag as it nears the goal, and the run times out with a stale detection.

    Raises:
        ScenarioError: naming ``controller.goal_tag_pose_visp`` and the corners' pixels.
    """
    from cdpr_twin.vision.detection import inside_image, tag_pixels

    uv, in_front = tag_pixels(intrinsics, T_cam_tag, tag_size)
    if in_front and inside_image(intrinsics, uv):
        return
    seen = f"its corners at {np.round(uv).astype(int).tolist()} px" if in_front else "behind it"
    raise ScenarioError(
        f"{s.source}: controller.goal_tag_pose_visp: at this goal view the camera would not see "
        f"the whole tag ({seen}, image {intrinsics.width}×{intrinsics.height} px): the servo "
        "would lose it; choose a view with the tag inside the image"
    )


def check_goal_pose(s: Scenario, geometry, goal: np.ndarray) -> None:
    """Refuse a goal view the nominal robot could only reach outside its workspace.

    Such a goal cannot be reached: the run would go on to its time limit (or stop on a fault).

    Raises:
        ScenarioError: the goal pose leaves the frame or is not wrench-feasible.
    """
    from cdpr_twin.math.se3 import vector_from_pose
    from cdpr_twin.math.workspace import infeasible_reason, is_feasible

    where = f"{s.source}: controller: its goal (the view it servos to, or the pose it is "
    where += f"taught at) puts the platform at {vector_from_pose(goal).round(4).tolist()}, which"
    try:
        geometry.check_pose_inside(goal, "goal pose")
    except ValueError as exc:
        raise ScenarioError(f"{where} is outside the frame: {exc}") from None
    if not is_feasible(geometry, goal):
        raise ScenarioError(f"{where} {infeasible_reason(geometry)}")
