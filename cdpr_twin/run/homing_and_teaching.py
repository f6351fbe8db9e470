"""The experimenters' procedure before a run: homing repeatability and teach-by-showing.

- Homing (``[realism.homing]``): each repetition's true start pose differs from the nominal
  start pose by a small per-run offset drawn from the run seed, while the encoders are homed
  (and the estimators and controller reset) as if the robot stood at the nominal start pose.
- Homing per drum (``[realism.drive] zero_error_std``): each winch is zeroed against its own
  reference with its own error, so each cable is off the start's rest length by its own
  error, and the true platform starts where the cables then settle.
- Teaching (:meth:`cdpr_twin.controllers.base.Controller.teach`): before the run the true robot
  is placed at a pose and the controller records what the sensors measure there (e.g. PBVS's
  ``goal = "taught"``), as experimenters do with their tracker.

Truth stays with the runner: the controller sees only a :class:`Measurement`.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from cdpr_twin.controllers.base import Controller
from cdpr_twin.math.kinematics import cable_lengths, rest_lengths
from cdpr_twin.math.se3 import so3_exp
from cdpr_twin.math.statics import InfeasibleTensionError, tension_distribution
from cdpr_twin.options import OptionError, spec_of
from cdpr_twin.robot.realism import draw_homing_offset, run_rng
from cdpr_twin.scenario.loading import Scenario, ScenarioError
from cdpr_twin.types import Measurement


def true_start_pose(T_start: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """The start pose moved by a homing offset in the base frame.

    ᵇT_p0' = (exp([δθ]×) ᵇR_p0, ᵇp_p0 + δp).

    Args:
        T_start: (4, 4) the nominal start pose ᵇT_p0.
        offset: (6,) [δp (m), δθ (rad)], as :func:`cdpr_twin.robot.realism.draw_homing_offset`
            draws.

    Returns:
        A new (4, 4) pose.
    """
    T = np.array(T_start, dtype=float)
    T[:3, :3] = so3_exp(np.asarray(offset[3:], dtype=float)) @ T[:3, :3]
    T[:3, 3] += offset[:3]
    return T


def homing(s: Scenario) -> tuple[np.ndarray | None, np.ndarray]:
    """This run's homing offset and the true start pose.

    Args:
        s: the scenario (its ``[realism.homing]``, run seed and start pose).

    Returns:
        The offset (6,) [δp (m), δθ (rad)] drawn from ``run_rng(seed, "homing")`` (``None``
        when homing is exact), and the (4, 4) true start pose (``s.start_pose`` itself when
        exact: bit for bit the run before realism).
    """
    h = s.realism.homing
    if h.position_std == 0 and h.rotation_std == 0:
        return None, s.start_pose  # the start pose itself, bit for bit
    offset = draw_homing_offset(h, run_rng(s.seed, "homing"))
    return offset, true_start_pose(s.start_pose, offset)


def drum_zero_errors(s: Scenario, n_cables: int) -> np.ndarray | None:
    """This run's error of each drum's zero [m of cable], or ``None`` (pose homing).

    Drawn from ``run_rng(seed, "drive")``, N(0, ``[realism.drive] zero_error_std``) per winch.
    """
    std = s.realism.drive.zero_error_std
    if std == 0:
        return None
    return run_rng(s.seed, "drive").normal(0.0, std, n_cables)


def home_by_drums(s: Scenario, physics, sensors, nominal, errors: np.ndarray) -> None:
    """Home each drum on its own reference, wind to the start, and let the platform settle.

    The robot's zero lengths were measured on the robot at its start pose (the true robot's
    rest lengths there, under its tension distribution), and each winch is zeroed against its
    reference with its own error δ_i: each true cable then has the start's rest length plus
    δ_i. The platform comes to rest where those lengths hold it (some cables perhaps slack: a
    millimetre on a cable of E·S/l ≈ 3e5 N/m is 300 N), and the encoders read the rest lengths
    the nominal model predicts at the start pose (its own tension distribution): the robot
    believes it stands there.

    Args:
        s: the scenario (its start pose).
        physics: the simulated robot (:class:`cdpr_twin.sim.Physics`).
        sensors: its sensors (:class:`cdpr_twin.sim.Sensors`).
        nominal: what its software believes (:class:`cdpr_twin.sim.NominalRobot`).
        errors: (m,) each drum's zero error δ_i [m].
    """
    T = s.start_pose
    physics.settle_at_lengths(physics.rest_lengths_at(T) + errors, T)
    sensors.encoders.home_lengths(start_rest_lengths(nominal.geometry, T))


def start_rest_lengths(g, T: np.ndarray) -> np.ndarray:
    """A geometry's rest lengths at a pose under its minimum-norm tension distribution (m,) [m].

    Args:
        g: the geometry (:class:`cdpr_twin.math.geometry.CdprGeometry`).
        T: (4, 4) the platform pose.
    """
    tau = tension_distribution(g, T, *g.tension_bounds(None, None))
    return rest_lengths(cable_lengths(g, T, "pulley"), tau, g.es)


def teach(s: Scenario, physics, sensors, controller: Controller) -> np.ndarray | None:
    """Let the controller learn by being shown poses (:meth:`Controller.teach`).

    Showing a pose resets the true robot there (static equilibrium, all cables taut, settled
    0.3 s), waits out the camera's latency at rest (``latency_ticks`` reads, one control period
    apart), and reads every sensor: what the experimenters' tracker-guided placement and one
    acquisition give on the real robot. The readings draw from the run's noise generators. Call
    it before events are hooked into the physics; the run then resets the robot at its start.

    Args:
        s: the scenario.
        physics: the simulated robot (:class:`cdpr_twin.sim.Physics`).
        sensors: its sensors (:class:`cdpr_twin.sim.Sensors`).
        controller: the controller to teach.

    Returns:
        (4, 4) the true tag pose in the camera frame at the last pose shown (truth, for the
        summary's true tag error), or ``None`` when nothing was shown or there is no camera/tag.

    Raises:
        ScenarioError: naming the controller option at fault, or a pose that cannot be shown.
    """
    shown: list[np.ndarray] = []
    wait, period = s.realism.camera.latency_ticks, s.model.control_period

    def show(T_base_platform: np.ndarray) -> Measurement:
        physics.reset(T_base_platform)
        for _ in range(wait):  # the frame read last was exposed `wait` ticks earlier
            sensors.read(None)
            physics.advance(period, np.zeros(physics.n_cables))
        m = sensors.read(None)
        if physics.has_camera and physics.has_tag:
            shown.append(np.array(physics.T_cam_tag))
        return m

    try:
        controller.teach(show)
    except OptionError as exc:
        fields = dataclasses.fields(controller.options)
        keys = {f.name: spec_of(f).file_key(f.name) for f in fields}
        raise ScenarioError(
            f"{s.source}: controller.{keys.get(exc.field, exc.field)}: {exc.problem}"
        ) from None
    except (ValueError, InfeasibleTensionError) as exc:
        raise ScenarioError(f"{s.source}: controller: a pose shown to teach it: {exc}") from None
    return shown[-1] if shown else None
