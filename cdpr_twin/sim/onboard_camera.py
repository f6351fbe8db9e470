"""The onboard camera as a sensor: render the frame, detect the tag with calibrated intrinsics.

Ideal (``CameraRealism()``): one noise-free render of the current instant through an ideal
pinhole, detected at once with the nominal intrinsics (the twin before realism, bit for bit).

With realism (:class:`~cdpr_twin.robot.realism.CameraRealism`), the frame is *formed* as a real
monochrome camera forms it (:mod:`cdpr_twin.sim.imaging`):

- motion blur: the sensor integrates, in linear light, sub-frames rendered at the true states
  the robot passes through during the exposure [t − exposure, t]; an :class:`ExposureRecorder`
  hooked into the physics records those states while it steps. An exposure during which no
  coordinate of the robot moved more than :data:`STILL` is drawn once (a robot at rest: its
  sub-frames would differ by less than a thousandth of a pixel);
- lens distortion: the ideal pinhole render is remapped through the true Brown–Conrady lens;
  the render reaches as far beyond the sensor's field as the lens sees (a barrel lens
  images the scene beyond the pinhole's frame onto the sensor's edges, which would
  otherwise read black);
- pixel area (``supersample`` > 1): the render is made finer and each pixel averages its
  samples, as a sensor pixel integrates the light over its area (a point-sampled render
  aliases edges narrower than a pixel);
- sensor noise: shot and read noise in electrons, the encoding gamma, 8-bit quantisation;
  each pixel's own gain (PRNU) and dark offset (DSNU), drawn once per robot
  (``[realism.optics] prnu_std``, ``dsnu_e``), act on its electrons;
- the detector uses the robot's *calibrated* intrinsics and distortion (true values plus a
  per-robot calibration error), not the true ones;
- latency: the frame (and tag) delivered at a read is the one exposed ``latency_ticks`` reads
  earlier (a FIFO, full of the start view after each reset).

With a latency of d ≥ 1 reads, a frame is not needed until d reads after it was exposed, as on
the real robot, whose camera pipeline forms and detects a frame while the controller goes on:
:meth:`OnboardCamera.read` renders the sub-frames at once (the GL context belongs to the
caller's thread) and hands their forming and detection to one worker thread, in order, so that
they overlap the physics and the next renders. The frames, their noise draws and detections are
the very ones the sequential path makes (one worker, the same order); ``pipeline=False`` keeps
everything in the caller's thread.

The realistic frame is gray (the sensor is monochrome), returned in three equal channels.
"""

from __future__ import annotations

import math
import warnings
from collections import deque
from concurrent.futures import Future, ThreadPoolExecutor

import cv2
import numpy as np

from cdpr_twin.options import OptionError
from cdpr_twin.robot.realism import CameraRealism, OpticsRealism
from cdpr_twin.sim import camera as cam_mod
from cdpr_twin.sim import imaging
from cdpr_twin.sim import optics as lens
from cdpr_twin.sim.model import SimulationError
from cdpr_twin.sim.physics import Physics
from cdpr_twin.types import CameraIntrinsics, TagDetection

NOISY_QUAD_SIGMA = 0.8
"""The detector's segmentation blur [px] for a noisy camera: AprilTag's advice for very noisy
images (its pose comes from the unblurred image; without it, noise quadruples detection time)."""

STILL = 1e-7
"""An exposure whose states differ by less than this in every coordinate (qpos, mocap; m, rad
or quaternion components) is drawn once: on a camera at least 5 cm from what it sees, with a
focal length of 600 px, they would differ by at most 1e-3 px (the blur of a robot at rest, far
below its noise; the calibration reads at rest, and each sub-frame render costs ≈ 18 ms on
Mesa's llvmpipe)."""

State = tuple[np.ndarray, np.ndarray, np.ndarray]
"""A recorded state: (qpos, mocap_pos, mocap_quat) copies."""


class ExposureRecorder:
    """Records the robot's states at the sub-frame times of each exposure (a physics step hook).

    The camera is read every ``period`` seconds of simulation time (t_k = k · period, time
    restarting at 0 on each reset); the exposure of read k spans [t_k − exposure, t_k] and its
    sub-frame i is taken at ``t_k − offsets[i]`` (:func:`imaging.subframe_offsets`). The physics
    stops stepping at each of those times and calls :meth:`fire`, which copies the state.
    Sub-frame times are rounded to the physics step.

    Args:
        physics: the simulated robot.
        period: the time between reads [s].
        offsets: (n,) how long before the read each sub-frame is taken [s], each in [0, period).
    """

    def __init__(self, physics: Physics, period: float, offsets: np.ndarray) -> None:
        self.physics, self.period = physics, float(period)
        self.offsets = np.sort(np.asarray(offsets, dtype=float))[::-1]  # earliest first
        self._done = -math.inf  # the latest sub-frame time already recorded
        self._states: list[tuple[float, State]] = []
        self.active = True
        self._dt = physics.timestep
        # the last answer of next_time and the time it was the next after: it stays the
        # answer while that time only moves forward short of it (called on every chunk)
        self._cached = (math.inf, -math.inf)

    def _forget_if_reset(self) -> None:
        if self._done > self.physics.time + self._dt:  # time went back: a reset
            self._done = -math.inf
            self._states.clear()

    def next_time(self) -> float:
        """The next sub-frame time after those already recorded [s] (``inf`` once closed)."""
        if not self.active:
            return math.inf
        self._forget_if_reset()
        after = max(self._done, self.physics.time - 0.5 * self._dt)
        since, t_next = self._cached
        if since <= after < t_next:
            return t_next
        k0 = math.floor(after / self.period)
        times = [k * self.period - o for k in range(k0, k0 + 3) for o in self.offsets]
        t_next = min(t for t in times if t > after)
        self._cached = (after, t_next)
        return t_next

    def fire(self, time: float) -> None:
        """Record the current state for every sub-frame time due at or before ``time`` [s]."""
        self._forget_if_reset()
        while (t := self.next_time()) <= time:
            self._done = t
        d = self.physics.data
        state = (d.qpos.copy(), d.mocap_pos.copy(), d.mocap_quat.copy())
        self._states.append((self.physics.time, state))
        horizon = self.physics.time - self.period - self.offsets[0] - self._dt
        self._states = [(t, s) for t, s in self._states if t >= horizon]

    def states(self, now: float) -> list[State]:
        """The states of the exposure that ends at ``now`` [s], earliest first.

        A sub-frame time with no recorded state (before the first step after a reset, when the
        robot rests at its start pose, or a read off the period grid) takes the current state.
        """
        self._forget_if_reset()
        d = self.physics.data
        current = (d.qpos, d.mocap_pos, d.mocap_quat)
        tol = 0.5 * self.physics.timestep + 1e-9
        out = []
        for target in now - self.offsets:
            near = [s for t, s in self._states if abs(t - target) <= tol]
            out.append(near[-1] if near else current)
        return out


def calibrate(
    nominal: CameraIntrinsics,
    realism: CameraRealism,
    rng: np.random.Generator,
    optics: OpticsRealism | None = None,
) -> tuple[CameraIntrinsics, tuple[float, ...] | None]:
    """The robot's calibrated intrinsics and distortion: the true ones plus calibration errors.

    fx, fy are each scaled by ``1 + N(0, focal_error_std)``, cx, cy shifted by
    ``N(0, center_error_std_px)``, each distortion coefficient shifted by
    ``N(0, distortion_error_std)`` (drawn in that order from the per-robot generator; a
    4-sequence of stds, one per coefficient, is accepted too: a calibration pins k1, k2 and
    p1, p2 to very different precisions). With correlations (``optics``), the eight errors are
    instead drawn together, as a calibration leaves them: eight standard normals z (one draw),
    then L·z with L the Cholesky factor of the covariance diag(σ)·R·diag(σ)
    (:meth:`OpticsRealism.calibration_correlation`), the focal errors relative as above.

    Args:
        nominal: the nominal intrinsics (the true ones in this model).
        realism: the camera's imperfections.
        rng: the per-robot generator.
        optics: the correlations of the errors (``None``: independent).

    Returns:
        The calibrated intrinsics and (k1, k2, p1, p2), or ``None`` for a pinhole (no draw is
        made when every error is off: the ideal twin keeps its nominal intrinsics as they are).
    """
    r = realism
    dist_std = np.broadcast_to(np.asarray(r.distortion_error_std, dtype=float), (4,))
    if not (r.focal_error_std or r.center_error_std_px or dist_std.any()):
        dist = tuple(r.distortion) if any(r.distortion) else None
        return nominal, dist
    if optics is not None and optics.correlated:
        std = np.concatenate([[r.focal_error_std] * 2, [r.center_error_std_px] * 2, dist_std])
        cov = std[:, None] * optics.calibration_correlation() * std[None, :]
        # (a zero std makes its row zero: the factor of the nonzero block, zeros elsewhere)
        on = std > 0
        L = np.zeros((8, 8))
        L[np.ix_(on, on)] = np.linalg.cholesky(cov[np.ix_(on, on)])
        e = L @ rng.standard_normal(8)
        df, dc, dd = e[:2], e[2:4], e[4:]
    else:
        df = rng.normal(0.0, r.focal_error_std, 2)
        dc = rng.normal(0.0, r.center_error_std_px, 2)
        dd = rng.normal(0.0, dist_std)
    K = nominal
    calibrated = CameraIntrinsics(
        K.width, K.height, K.fx * (1 + df[0]), K.fy * (1 + df[1]), K.cx + dc[0], K.cy + dc[1]
    )
    dist = tuple(float(c) for c in np.asarray(r.distortion, dtype=float) + dd)
    return calibrated, dist if any(dist) else None


class OnboardCamera:
    """Renders what the platform camera sees and detects the tag in it.

    Args:
        physics: the simulated robot (the image is made with its *true* camera).
        intrinsics: the nominal intrinsics (the base of the calibrated ones the detector uses;
            equal to the true, rendered ones in this model).
        tag_size: the tag's edge the detector assumes [m].
        realism: the camera's imperfections.
        robot_rng: the per-robot generator (calibration errors; the pixels' fixed pattern
            from a stream spawned from its seed).
        run_rng: the run's generator (pixel noise).
        period: the time between reads [s] (the control period); needed for motion blur
            (``exposure_s > 0``), whose sub-frames are recorded while the physics steps towards
            the reads at k · period.
        tag_window: search the tag near its last detection first (``TagDetector``'s ``roi``;
            off by default: it moves corners by ~1e-5 px, which closed loops carry on).
        pipeline: with ``latency_ticks`` ≥ 1, form and detect each frame in a worker thread
            while the caller goes on (the same frames and detections, sooner).
        optics: the optics' realism (correlated calibration errors; ``None``: none).

    Raises:
        SimulationError: without a camera in the model.
        ValueError: motion blur without ``period``, or an exposure longer than it.
    """

    def __init__(
        self,
        physics: Physics,
        intrinsics: CameraIntrinsics,
        tag_size: float,
        realism: CameraRealism,
        robot_rng: np.random.Generator,
        run_rng: np.random.Generator,
        period: float | None = None,
        tag_window: bool = False,
        pipeline: bool = True,
        optics: OpticsRealism | None = None,
    ) -> None:
        if not physics.has_camera:
            raise SimulationError(
                f"{physics.source} has no camera {cam_mod.CAMERA_NAME!r}; run with the camera off"
            )
        r = realism
        imaging.check_exposure(r, period, physics.timestep)
        from cdpr_twin.vision.detection import TagDetector  # OpenCV and pupil-apriltags, on demand

        self.physics, self.realism, self.run_rng = physics, realism, run_rng
        # render()'s own noise: a look at the camera must not shift the run's frames
        seed_seq = run_rng.bit_generator.seed_seq
        # a run's generator comes from a seed: its bit generator holds a SeedSequence
        assert isinstance(seed_seq, np.random.SeedSequence)
        self._view_rng = np.random.default_rng(seed_seq.spawn(1)[0])
        self.calibrated, self.calibrated_distortion = calibrate(intrinsics, r, robot_rng, optics)
        self._renderer: cam_mod.CameraRenderer | None = cam_mod.CameraRenderer(
            physics.model, scale=r.supersample, lens=r.distortion
        )
        self.margins = self._renderer.margins  # what the lens sees beyond the pinhole's field
        self.true_intrinsics = self._renderer.intrinsics
        self._maps = None
        self.optics = OpticsRealism() if optics is None else optics
        o = self.optics
        self._formed = (
            r.noise or r.exposure_s > 0 or any(r.distortion) or r.supersample > 1 or o.forms
        )
        self._vignette = (
            lens.vignetting_map(self.true_intrinsics, o.vignetting_power)
            if o.vignetting_power
            else None
        )
        self._row_w: np.ndarray | None = None  # a rolling shutter's (canvas rows, K) weights
        self._pattern: tuple[np.ndarray, np.ndarray] | None = None
        if o.fixed_pattern:
            # per robot, from a stream of its own: the calibration's draws stay as they were
            robot_seq = robot_rng.bit_generator.seed_seq
            # a robot's generator comes from a seed: its bit generator holds a SeedSequence
            assert isinstance(robot_seq, np.random.SeedSequence)
            K = self.true_intrinsics
            self._pattern = imaging.fixed_pattern(
                (K.height, K.width),
                o.prnu_std,
                o.dsnu_e,
                np.random.default_rng(robot_seq.spawn(1)[0]),
            )
        self._flicker_phase = 0.0
        if o.flicker_depth:  # per run, from a stream of its own (the noise's stays as it was)
            spawned = np.random.default_rng(seed_seq.spawn(1)[0])
            self._flicker_phase = float(spawned.uniform(0.0, 2.0 * math.pi))
        self._fifo: deque[Future] = deque()
        self._pool: ThreadPoolExecutor | None = None
        self._last_job: Future | None = None  # the worker's newest frame (it works in order)
        self.pipeline = pipeline  # may be switched between reads (order is kept)
        self._last_read = -math.inf
        self.exposure: ExposureRecorder | None = None
        try:
            if any(r.distortion):
                self._maps = imaging.distortion_maps(
                    self._renderer.render_intrinsics, r.distortion, self.margins
                )
            self._detector = TagDetector(
                self.calibrated,
                tag_size=tag_size,
                distortion=self.calibrated_distortion,
                quad_sigma=NOISY_QUAD_SIGMA if self._formed else 0.0,
                roi=tag_window,
            )
        except BaseException:
            self.close()
            raise
        if o.line_time > 0:
            offsets = self._rolling_offsets(period)
            # _rolling_offsets refused a rolling shutter without a read period
            assert period is not None
            self.exposure = ExposureRecorder(physics, period, offsets)
            physics.add_hook(self.exposure)
        elif r.exposure_s > 0:
            offsets = imaging.subframe_offsets(r.exposure_s, r.blur_subframes)
            # check_exposure refused an exposure without a period
            assert period is not None
            self.exposure = ExposureRecorder(physics, period, offsets)
            physics.add_hook(self.exposure)

    def _rolling_offsets(self, period: float | None) -> np.ndarray:
        """A rolling shutter's sub-frame offsets before the read [s], and its rows' weights.

        ``blur_subframes`` + 1 renders span the readout and exposure, from the first row's
        exposure start to the last row's end; each row of the render canvas weighs them by its
        sensor row's window (:func:`cdpr_twin.sim.optics.row_weights`).

        Raises:
            OptionError: naming ``realism.optics.line_time`` when readout and exposure do not
                fit in the read period.
        """
        r, o, K = self.realism, self.optics, self.true_intrinsics
        span = r.exposure_s + (K.height - 1) * o.line_time
        if period is None or not span < period:
            raise OptionError(
                "realism.optics.line_time",
                f"a readout of {(K.height - 1) * o.line_time:g} s and exposure of "
                f"{r.exposure_s:g} s must fit in the camera's read period ({period} s)",
            )
        offsets = np.linspace(span, 0.0, r.blur_subframes + 1)
        scale, margin = r.supersample, self.margins[1]
        # the renderer is closed only by close(), never before the constructor returns
        assert self._renderer is not None
        canvas_rows = np.arange(self._renderer.canvas.height)
        sensor_rows = (canvas_rows - margin + 0.5) / scale - 0.5
        self._row_w = lens.row_weights(
            -offsets, sensor_rows, K.height, 0.0, r.exposure_s, o.line_time
        )
        return offsets

    def close(self) -> None:
        """Free the GL context and stop recording exposures.

        The worker finishes the frame it is forming; the frames queued behind it are dropped
        (never delivered, they change no output). An error met in a frame formed but never
        delivered is reported as a ``RuntimeWarning``.
        """
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None
            undelivered = {id(job): job for job in (*self._fifo, self._last_job) if job}
            for job in undelivered.values():
                if not job.cancelled() and job.exception() is not None:
                    warnings.warn(
                        f"camera: a frame never delivered failed to form: {job.exception()!r}",
                        RuntimeWarning,
                        stacklevel=2,
                    )
            self._fifo.clear()
            self._last_job = None
        if self.exposure is not None:
            self.exposure.active = False
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def render(self) -> np.ndarray:
        """The frame the camera takes now (exposure ending now), (H, W, 3) RGB uint8.

        Its noise comes from a stream of its own (from the run seed): rendering between reads
        (a viewer, a video wrapper) leaves the run's frames, detections and estimates as they
        are without it.
        """
        self._drain()  # the frames in hand are formed before this one, as they were taken
        return self._form(self._renders(), self._view_rng, self._scene())

    def _scene(self) -> tuple[float, float]:
        """What the lens and the light need of this instant: (the tag's depth [m], time [s])."""
        p = self.physics
        depth = float(p.T_cam_tag[2, 3]) if self.optics.defocus and p.has_tag else math.nan
        return depth, p.time

    def _renders(self) -> list[np.ndarray]:
        """The GL part of a frame: the render(s) of the exposure ending now (this thread's)."""
        # only close() drops the renderer, after which no frame is taken
        assert self._renderer is not None, "the camera is closed"
        if self.exposure is not None:
            states = self.exposure.states(self.physics.time)
            if _still(states):
                states = states[-1:]
            return [self._renderer.render_state(*s) for s in states]
        return [self._renderer.render(self.physics.data)]

    def _form(
        self,
        renders: list[np.ndarray],
        rng: np.random.Generator | None = None,
        scene: tuple[float, float] = (math.nan, 0.0),
    ) -> np.ndarray:
        """The frame the sensor forms from the renders of its exposure (``rng``: the run's).

        ``scene``: the tag's depth [m] (``nan``: no defocus) and the exposure's end [s].
        """
        if not self._formed:
            return renders[0]
        r = self.realism
        frames = [imaging.linear_luminance(f, r.gamma) for f in renders]
        if self._row_w is not None and len(frames) > 1:  # a rolling shutter's rows
            linear = frames[0] * self._row_w[:, :1]
            for k in range(1, len(frames)):
                linear += frames[k] * self._row_w[:, k : k + 1]
        else:
            linear = imaging.average(frames)
        if self._maps is not None:
            linear = imaging.distort(linear, self._maps)
        if r.supersample > 1:
            linear = imaging.integrate_pixels(linear, r.supersample)
        if (r.black_level, r.white_level) != (0.0, 1.0):  # the scene's exposure levels
            linear *= np.float32(r.white_level - r.black_level)  # in place: b + (w − b)·L
            linear += np.float32(r.black_level)
        # the lamp and the lens act on all the light of the scene, the ink's black included
        linear = self._lens_and_light(linear, *scene)
        if r.noise:
            rng = self.run_rng if rng is None else rng
            gray = imaging.expose(
                linear, r.full_well_e, r.read_noise_e, r.gamma, rng, self._pattern
            )
        else:
            if self._pattern is not None:
                linear = imaging.apply_pattern(linear, self._pattern, r.full_well_e)
            gray = imaging.encode(linear, r.gamma)
        if self.optics.jpeg_quality:  # the frame as the camera's encoder delivers it
            gray = imaging.jpeg(gray, self.optics.jpeg_quality)
        return cv2.cvtColor(gray, cv2.COLOR_GRAY2RGB)

    def _lens_and_light(self, linear: np.ndarray, depth: float, time: float) -> np.ndarray:
        """The flicker of the light, the lens's defocus and vignetting, on the linear image."""
        o = self.optics
        if o.flicker_depth:
            # each row's exposure ends (H − 1 − r)·t_line before the frame's (a rolling shutter
            # bands the flicker; a global one dims or brightens the whole frame)
            rows = np.arange(linear.shape[0], dtype=float)
            ends = time - (linear.shape[0] - 1 - rows) * o.line_time
            e, phase = self.realism.exposure_s, self._flicker_phase
            gain = lens.flicker_gain(ends, e, o.flicker_hz, o.flicker_depth, phase)
            linear = linear * gain.astype(np.float32)[:, None]
        if o.defocus and math.isfinite(depth):
            K = self.true_intrinsics
            c = lens.blur_circle_px(depth, o.focus_distance, o.focal_length, o.f_number, K.fy)
            linear = lens.defocus(linear, c)
        if self._vignette is not None:
            linear = linear * self._vignette
        return linear

    def _develop(
        self, renders: list[np.ndarray], forget: bool, scene: tuple[float, float]
    ) -> tuple[np.ndarray, TagDetection | None]:
        """Form the frame and detect the tag in it (a new run first forgets the last place)."""
        if forget:
            self._detector.forget()
        image = self._form(renders, None, scene)
        return image, self._detector.detect(image)

    def _drain(self) -> None:
        """Wait until the worker has formed every frame handed to it (it works in order)."""
        if self._last_job is not None:
            self._last_job.exception()  # done, its error (if any) left for its reader

    def read(self) -> tuple[np.ndarray, TagDetection | None]:
        """The frame delivered now and the tag detected in it (``None`` when not found).

        With ``latency_ticks = d`` it is the frame exposed d reads ago. At the first read after
        a reset the robot has been resting at its start pose while the camera streamed: the
        pipeline then holds d frames of that view (the one taken now, repeated), so the first
        d reads deliver it rather than nothing. A frame the worker failed to form raises its
        error at the read that delivers it (d reads after its exposure), or at a reset that
        discards it.
        """
        reset = self.physics.time < self._last_read
        forget = self.physics.time <= self._last_read  # a new run (or a re-read): search anew
        renders, scene = self._renders(), self._scene()
        d = self.realism.latency_ticks
        if self.pipeline and d > 0:
            if self._pool is None:
                self._pool = ThreadPoolExecutor(1, thread_name_prefix="camera")
            job = self._last_job = self._pool.submit(self._develop, renders, forget, scene)
        else:
            self._drain()  # switched off mid-run: the worker's frames come first
            job = Future()
            job.set_result(self._develop(renders, forget, scene))
        first, self._last_read = not self._fifo, self.physics.time
        if d == 0:
            return job.result()
        if first or reset:
            discarded, self._fifo = self._fifo, deque([job] * d)
            for frame in discarded:  # a failure is not lost with its frame
                frame.result()
        self._fifo.append(job)
        return self._fifo.popleft().result()


def _still(states: list[State]) -> bool:
    """Whether no coordinate changes by more than :data:`STILL` over ``states``."""
    first = states[0]
    return all(
        np.abs(a - b).max(initial=0.0) <= STILL
        for state in states[1:]
        for a, b in zip(state, first, strict=True)
    )
