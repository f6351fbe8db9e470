"""A Gymnasium environment over the twin: a policy takes the place of a scenario's controller.

Each episode is a run of the scenario (its robot model, calibration-error magnitudes, sensors,
realism profile, control rate, start pose and events, as ``cdpr-twin run`` would build it) in
which the policy commands the winches at every control tick:

- **action** (``Box(-1, 1)``, scaled by :attr:`CdprEnv.action_scale`): the platform twist
  ᵇv_p = [v (m/s), ω (rad/s)] in the base frame, turned into cable rates through the *nominal*
  Jacobian at the estimator's current pose (``action="twist"``, eq. 30), or the cable rates
  l̇ (m/s) themselves (``action="cable_rates"``);
- **observation** (a ``Dict``): the :class:`~cdpr_twin.types.Measurement` — ``cable_lengths``
  (encoders, m), ``tensions`` (N), ``tag_detected`` (0/1) and ``tag_pose`` (the detected
  ᶜT_o as [t (m), θu (rad)], pupil-apriltags' tag frame; zeros when not detected),
  ``image`` (with ``image=True``) — and ``pose_estimate``, the configured estimator's
  ᵇT_p from those measurements as [t (m), θu (rad)]. No ground truth;
- **reward, termination** from the task (:mod:`cdpr_twin.gym.tasks`), scored on the truth;
  truncation at the task's horizon. ``info`` carries the truth (``T_base_platform``, errors)
  for evaluation only;
- **limits and faults**, as on the real robot: a twist whose cable rates exceed a winch's rate
  limit is scaled down as a whole (its direction kept; ``info["rate_scale"]`` < 1); a winch
  run past its length range, a diverging simulation, a non-finite estimate, or a fault of the
  robot's monitor (platform on the floor, cable overload or slack, outside the frame — with
  the scenario's ``[monitor] on_fault = "stop"``; one already present at reset ends the first
  step, the robot unmoved) ends the episode (``terminated``, ``info["failure"]``) with a reward
  no policy gains by: the step's cost (where the robot was, when the simulation lost its
  state) for every step left to the horizon, plus :data:`FAILURE_REWARD`. A lost (non-finite)
  estimate ends the step that produced it; the observation then keeps the last finite pose
  estimate (``info["estimate_valid"]`` says so). After an episode ends (terminated or
  truncated), ``step()`` raises until ``reset()``;
- ``reset(seed=)`` draws the robot (its calibration errors; ``random_robot=False`` keeps the
  scenario's) and the run seed (sensor noise, homing offset) from the seed.
"""

from __future__ import annotations

import dataclasses
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from cdpr_twin.gym.configuration import check_arguments, configure
from cdpr_twin.gym.tasks import Score, Truth, make_task
from cdpr_twin.math.kinematics import jacobian
from cdpr_twin.math.se3 import so3_log
from cdpr_twin.run.episode import Episode
from cdpr_twin.run.runner import RunSetup, prepare
from cdpr_twin.scenario.loading import Scenario
from cdpr_twin.sim import SimulationError, WinchLimitError
from cdpr_twin.types import Command, Measurement, PoseEstimate, TickRecord

ACTIONS = ("twist", "cable_rates")
"""What an action commands."""
SEED_BOUND = 2**31
"""Robot and run seeds are drawn in [0, SEED_BOUND)."""
FAILURE_REWARD = -10.0
"""Added to a failed step's reward: the step's cost times the steps left to the horizon."""


def pose6(T: np.ndarray) -> np.ndarray:
    """A pose as the observations write it: [t (m), θu (rad)], (6,)."""
    return np.concatenate([T[:3, 3], so3_log(T[:3, :3])])


class CdprEnv(gym.Env):
    """The twin as a Gymnasium environment (see the module's description).

    Args:
        task: ``"reach"`` (:class:`~cdpr_twin.gym.tasks.ReachPose`, to p1 by default),
            ``"servo"`` (:class:`~cdpr_twin.gym.tasks.ServoToTag`, the paper's PBVS goal
            view), or a task instance.
        scenario: a shipped scenario's name, a scenario file or a :class:`Scenario`.
        action: ``"twist"`` or ``"cable_rates"``.
        estimator: the registered estimator behind ``pose_estimate`` (and the twist's Jacobian).
        camera: render the camera and detect the tag (default: when the task, the estimator,
            ``image`` or the render mode needs it).
        image: add the camera frame to the observation.
        random_robot: draw the robot's calibration errors at each seeded reset.
        truth_scale: factor on the scenario's calibration-error magnitudes (0: nominal robot).
        realism: a realism profile (``"ideal"``, ``"acrobot"``, ``"acrobot_full"``) instead of
            the scenario's.
        max_speed: |v| per axis at action ±1 [m/s] (twist).
        max_angular_speed: |ω| per axis at action ±1 [rad/s] (twist).
        max_cable_rate: |l̇| at action ±1 [m/s] (cable rates).
        render_mode: ``None`` or ``"rgb_array"`` (the onboard camera's frame).
        on_fault: ``"stop"`` (a monitor fault ends the episode) or ``"continue"`` (it is listed
            in ``info["faults"]``); ``None``: the scenario's ``[monitor] on_fault``. Uniformly
            random full-scale twists slacken cables within 2–4 steps: explore with
            ``"continue"``, or with smoother actions.

    Raises:
        ValueError: for an unknown task, action, estimator or render mode, a scale that is not
            a positive number, a ``max_cable_rate`` above the winches' limit, or a bad scenario.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 25}  # noqa: RUF012 (gymnasium's)

    def __init__(
        self,
        task: Any = "reach",
        scenario: str | Scenario = "paper_open_loop",
        action: str = "twist",
        estimator: str = "model_elastic_pulley",
        camera: bool | None = None,
        image: bool = False,
        random_robot: bool = True,
        truth_scale: float = 1.0,
        realism: str | None = None,
        max_speed: float = 0.1,
        max_angular_speed: float = 0.3,
        max_cable_rate: float = 0.1,
        render_mode: str | None = None,
        on_fault: str | None = None,
    ) -> None:
        self.task = make_task(task)
        check_arguments(
            on_fault,
            max_speed=max_speed,
            max_angular_speed=max_angular_speed,
            max_cable_rate=max_cable_rate,
        )
        if action not in ACTIONS:
            raise ValueError(f"unknown action {action!r}; choose one of {', '.join(ACTIONS)}")
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"unknown render_mode {render_mode!r}; use None or 'rgb_array'")
        wants = {
            "the task": self.task.needs_camera,
            "image=True": image,
            f"render_mode={render_mode!r}": render_mode is not None,
        }
        self.action_kind, self.image, self.render_mode = action, bool(image), render_mode
        self.random_robot, self.estimator = bool(random_robot), estimator
        self.scenario = configure(scenario, estimator, camera, wants, truth_scale, realism)
        if on_fault is not None:
            monitor = dataclasses.replace(self.scenario.monitor, on_fault=on_fault)
            self.scenario = dataclasses.replace(self.scenario, monitor=monitor)
        self._period = self.scenario.model.control_period
        self._horizon = max(1, round(self.task.horizon / self._period))
        self._setup: RunSetup | None = prepare(self.scenario)  # the robot: cable count, camera
        self._check_goal()
        n = self._setup.physics.n_cables
        self._max_rates = np.minimum(
            -self._setup.physics.rate_range[0], self._setup.physics.rate_range[1]
        )
        if action == "cable_rates" and max_cable_rate > self._max_rates.min():
            raise ValueError(
                f"max_cable_rate {max_cable_rate} m/s exceeds the winches' rate limit "
                f"{self._max_rates.min()} m/s; choose at most that"
            )
        twist = [max_speed] * 3 + [max_angular_speed] * 3
        self.action_scale = np.array(twist if action == "twist" else [max_cable_rate] * n)
        """Units of an action of 1: [m/s ×3, rad/s ×3] (twist) or m/s per cable."""
        self.action_space = spaces.Box(-1.0, 1.0, (len(self.action_scale),), np.float32)
        self.observation_space = self._observation_space(n)
        self._episode: Episode | None = None
        self._tick: TickRecord | None = None  # the last step that went through (or reset's)
        self._last: Truth | None = None  # the truth after the last step that went through
        self._pending: str | None = None  # a stopping fault found at reset
        self._ended: str | None = None  # how the episode ended: step() then needs a reset()
        self._pose = np.zeros(6)  # the last finite estimate's pose6 (the observation's)
        self._steps, self._seeds = 0, (self.scenario.truth.seed, self.scenario.seed)

    @property
    def nominal_geometry(self):
        """The nominal geometry (what a policy may believe: exit/anchor points, camera mount)."""
        return self._run.nominal.geometry

    def _observation_space(self, n: int) -> spaces.Dict:
        """Unbounded where physics is (an overload's tension, a lost estimate's position)."""
        pose_high = np.array([np.inf] * 3 + [np.pi] * 3)
        space = {
            "cable_lengths": spaces.Box(0.0, np.inf, (n,), np.float64),
            "tensions": spaces.Box(-np.inf, np.inf, (n,), np.float64),
            "tag_detected": spaces.Discrete(2),
            "tag_pose": spaces.Box(-pose_high, pose_high, (6,), np.float64),
            "pose_estimate": spaces.Box(-pose_high, pose_high, (6,), np.float64),
        }
        if self.image:
            k = self._run.nominal.intrinsics
            # (image is on only for a robot with a camera)
            assert k is not None
            space["image"] = spaces.Box(0, 255, (k.height, k.width, 3), np.uint8)
        return spaces.Dict(space)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        """Start an episode: a robot and run drawn from the seed, settled at the start pose.

        Returns:
            ``(observation, info)``.
        """
        super().reset(seed=seed)
        if options:
            raise ValueError(f"reset() takes no options, got {sorted(options)}")
        robot_seed, run_seed = (int(v) for v in self.np_random.integers(SEED_BOUND, size=2))
        if not self.random_robot:
            robot_seed = self.scenario.truth.seed
        s = dataclasses.replace(
            self.scenario,
            seed=run_seed,
            truth=dataclasses.replace(self.scenario.truth, seed=robot_seed),
        )
        self.close()
        self._setup = prepare(s)
        self._episode = Episode(self._setup, true_tag_view=self._sees_tag())
        self._steps, self._seeds, self._ended = 0, (robot_seed, run_seed), None
        self._pose = pose6(self.scenario.start_pose)  # a lost first estimate: the start's
        self._tick = self._episode.reset()
        self._last = self._truth_of(self._tick)
        faults = self._faults(self._tick)
        self._pending = faults.get("failure")  # the first step ends with it, as a run would
        info = self._info(self.task.score(self._last), self._last)
        return self._observation(), {**info, **faults}

    def step(self, action):
        """Command the winches for one control period, then read the sensors.

        Returns:
            ``(observation, reward, terminated, truncated, info)``.
        """
        if self._setup is None or self._tick is None or self._episode is None:
            raise RuntimeError("call reset() before step()")
        if self._ended is not None:  # gymnasium leaves it undefined: here it is an error
            raise RuntimeError(f"the episode ended ({self._ended}); call reset() before step()")
        a = np.asarray(action, dtype=float)
        if a.shape != self.action_space.shape or not np.isfinite(a).all():
            raise ValueError(
                f"an action is {len(self.action_scale)} finite numbers (Box(-1, 1), values "
                f"outside are clipped), got shape {a.shape}: {np.round(a, 4).tolist()}"
            )
        command, scale = self._command(np.clip(a, -1.0, 1.0) * self.action_scale)
        self._steps += 1
        extra = {"rate_scale": scale}
        if self._pending is not None:  # a stopping fault at reset: the robot does not move
            return self._failed(self._pending, extra)
        if not np.isfinite(command.cable_rates).all():
            return self._failed(f"the {self.estimator} estimate is not finite: no command", extra)
        try:
            tick = self._episode.step(command)
        except WinchLimitError as exc:  # refused before any step: the state is the last one
            return self._failed(str(exc), extra)
        except SimulationError as exc:  # MuJoCo reset its state: score where the robot was
            return self._failed(str(exc), extra, self._last)
        self._tick = tick
        faults = self._faults(tick)
        if "failure" in faults:
            return self._failed(faults.pop("failure"), {**extra, **faults})
        if not np.isfinite(self._estimate.T_base_platform).all():  # ends now, not a step later
            return self._failed(f"the {self.estimator} estimate is not finite", extra)
        self._last = self._truth_of(tick)
        score = self.task.score(self._last)
        truncated = self._steps >= self._horizon and not score.success
        if score.success or truncated:
            self._ended = "reached the goal" if score.success else "the horizon: truncated"
        info = {**self._info(score, self._last), **extra, **faults}
        return self._observation(), float(score.reward), score.success, truncated, info

    def _failed(self, why: str, extra: dict, truth: Truth | None = None) -> tuple:
        """A terminated step: its cost for each step left to the horizon, plus the penalty.

        Args:
            why: the failure, in words.
            extra: more ``info``.
            truth: where the robot is (default: now; a non-finite state: the last step's).
        """
        truth = self._truth() if truth is None else truth
        if not np.isfinite(truth.T_base_platform).all():
            # reset() recorded a finite truth before any step could fail
            assert self._last is not None
            truth = self._last
        score = self.task.score(truth)
        left = max(self._horizon - self._steps, 0) + 1
        reward = float(score.reward) * left + FAILURE_REWARD
        info = {**self._info(score, truth), **extra, "failure": why}
        self._ended = f"terminated: {why}"
        return self._observation(), reward, True, False, info

    def _faults(self, tick: TickRecord) -> dict[str, Any]:
        """The monitor's faults during a tick, and the failure they are if they stop.

        Returns:
            ``{}``, or ``{"faults": [...]}`` plus ``"failure"`` when the scenario's
            ``[monitor] on_fault`` is ``"stop"``.
        """
        if not tick.faults:
            return {}
        out: dict[str, Any] = {"faults": [f.described for f in tick.faults]}
        if tick.stop is not None:
            out["failure"] = out["faults"][0]
        return out

    def _command(self, a: np.ndarray) -> tuple[Command, float]:
        """The winch command of an action (and the platform twist it implies, ᵖv_p).

        Returns:
            The command, and the factor (≤ 1) by which a twist was scaled down to keep every
            cable rate within its winch's limit.
        """
        geometry = self._run.nominal.geometry
        T = self._estimate.T_base_platform
        R = T[:3, :3]
        if self.action_kind == "twist":
            rates = jacobian(geometry, T, "base") @ a
            over = float(np.max(np.abs(rates) / self._max_rates))
            scale = 1.0 if over <= 1.0 else 1.0 / over
            a, rates = a * scale, np.clip(rates * scale, -self._max_rates, self._max_rates)
            return Command(rates, np.concatenate([R.T @ a[:3], R.T @ a[3:]])), scale
        twist, *_ = np.linalg.lstsq(jacobian(geometry, T, "platform"), a, rcond=None)
        return Command(a, twist), 1.0

    @property
    def _run(self) -> RunSetup:
        """The robot's setup (from construction until :meth:`close`)."""
        assert self._setup is not None, "the environment is closed"
        return self._setup

    @property
    def _ticked(self) -> TickRecord:
        """The last tick that went through (from :meth:`reset` on)."""
        assert self._tick is not None, "call reset() first"
        return self._tick

    @property
    def _m(self) -> Measurement:
        return self._ticked.measurement

    @property
    def _estimate(self) -> PoseEstimate:
        return self._ticked.estimates[self.estimator]

    def _sees_tag(self) -> bool:
        p = self._run.physics
        return p.has_camera and p.has_tag

    def _truth(self) -> Truth:
        """Where the robot is now (after a failed step: no tick recorded it)."""
        p = self._run.physics
        return Truth(p.T_base_platform.copy(), p.T_cam_tag.copy() if self._sees_tag() else None)

    @staticmethod
    def _truth_of(tick: TickRecord) -> Truth:
        view = None if tick.T_cam_tag is None else tick.T_cam_tag.copy()
        return Truth(tick.T_base_platform.copy(), view)

    def _observation(self) -> dict[str, Any]:
        m = self._m
        obs = {
            "cable_lengths": np.array(m.cable_lengths, dtype=np.float64),
            "tensions": np.array(m.tensions, dtype=np.float64),
            "tag_detected": np.int64(m.tag is not None),
            "tag_pose": pose6(m.tag.T_cam_tag) if m.tag is not None else np.zeros(6),
            "pose_estimate": self._pose_estimate(),
        }
        if self.image:
            obs["image"] = np.array(m.image, dtype=np.uint8)
        return obs

    def _pose_estimate(self) -> np.ndarray:
        """The estimate's pose6, or the last finite one (a lost estimate ends the episode)."""
        T = self._estimate.T_base_platform
        if np.isfinite(T).all():
            self._pose = pose6(T)
        return self._pose.copy()

    def _info(self, score: Score, truth: Truth) -> dict[str, Any]:
        """Truth and scores, for evaluation (a policy must not read them)."""
        return {
            "time": float(self._m.time),
            "T_base_platform": truth.T_base_platform.copy(),
            "translation_error": score.translation_error,
            "rotation_error": score.rotation_error,
            "is_success": score.success,
            "estimate_valid": bool(self._estimate.valid)
            and bool(np.isfinite(self._estimate.T_base_platform).all()),
            "robot_seed": self._seeds[0],
            "run_seed": self._seeds[1],
        }

    def render(self) -> np.ndarray | None:
        """The onboard camera's current frame (``render_mode="rgb_array"``), else ``None``."""
        if self.render_mode != "rgb_array" or self._setup is None:
            return None
        return self._setup.sensors.render()

    def _check_goal(self) -> None:
        """Refuse a task's goal pose outside the frame (every step would score the same)."""
        goal = getattr(self.task, "goal_pose", None)
        if not isinstance(goal, np.ndarray):
            return
        try:
            self._run.nominal.geometry.check_pose_inside(goal, "the task's goal")
        except ValueError as exc:
            self.close()
            raise ValueError(f"{getattr(self.task, 'name', 'task')}: goal: {exc}") from None

    def close(self) -> None:
        """Free the renderer (safe to call more than once)."""
        if self._setup is not None:
            self._setup.close()
            self._setup = None
