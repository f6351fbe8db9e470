"""``Estimator.update`` does every estimator's preamble; a subclass implements only ``_step``.

``Step`` below is the smallest estimator of the recommended form: it records each call of its
``_step`` and returns the pose it was reset at with the watch flags it was given, so what the
base class did before the step is all that its estimates show.
"""

import re

import numpy as np
import pytest

from cdpr_twin import plugins
from cdpr_twin.estimators.base import NO_INPUTS, Estimator, SensorWatch
from cdpr_twin.math.geometry import CdprGeometry
from cdpr_twin.types import Command, Measurement, PoseEstimate

# a stand-in robot: Step never reads its geometry
GEOMETRY = CdprGeometry(np.eye(8, 3), np.eye(8, 3), 0.0, 1.0, 1.0, np.zeros(3))
START = np.eye(4)
START[:3, 3] = [0.1, -0.2, 0.3]
LENGTHS = np.linspace(1.0, 1.7, 8)
TENSIONS = np.linspace(20.0, 27.0, 8)
STILL = Command(np.zeros(8), np.zeros(6))


class Step(Estimator):
    """Its own work: none. It returns the start pose with the flags ``update`` gave it."""

    name = "step_only"

    def __init__(self, geometry, options=None) -> None:
        super().__init__(geometry, options)
        self.steps: list[tuple[float, frozenset[str]]] = []

    def _step(self, measurement, inputs, watch_flags) -> PoseEstimate:
        self.steps.append((measurement.time, watch_flags))
        self._time = measurement.time
        return PoseEstimate(measurement.time, self._T, flags=watch_flags)


class EncoderStep(Step):
    name = "encoder_step"
    watches = SensorWatch.ENCODERS


class TensionStep(Step):
    name = "tension_step"
    watches = SensorWatch.TENSIONS


class BothStep(Step):
    name = "both_step"
    watches = SensorWatch.ENCODERS | SensorWatch.TENSIONS


def _still(time: float, lengths: np.ndarray = LENGTHS) -> Measurement:
    return Measurement(time, lengths, TENSIONS, STILL)


def test_an_update_before_reset_is_refused_with_the_documented_error():
    est = Step(GEOMETRY)
    message = "step_only: call reset(T_base_platform0) before update()"
    with pytest.raises(RuntimeError, match=f"^{re.escape(message)}$"):
        est.update(_still(0.0))
    assert est.steps == []


@pytest.mark.parametrize("time", [np.nan, np.inf, -np.inf])
def test_a_non_finite_time_holds_the_estimate_without_calling_the_step(time):
    est = BothStep(GEOMETRY)
    est.reset(START, time=0.5)
    out = est.update(_still(time))
    assert est.steps == []
    assert not out.valid and out.flags == {"non_finite_input"}
    # held: the reset's pose and time, not the measurement's
    np.testing.assert_array_equal(out.T_base_platform, START)
    assert out.time == 0.5


def test_a_non_finite_time_is_not_fed_to_the_watches():
    # truth: the encoders moved 1 cm between t = 0.08 s and t = 0.12 s under a still command;
    # a measurement with a NaN time in between must not become the watch's reference
    est = EncoderStep(GEOMETRY)
    est.reset(START)
    for k in range(3):
        est.update(_still(0.04 * k))
    est.update(_still(np.nan, LENGTHS + 0.01))
    jumped = est.update(_still(0.12, LENGTHS + 0.01))
    assert jumped.flags == {"encoder_mismatch"}


@pytest.mark.parametrize(
    ("cls", "expected"),
    [
        (Step, set()),
        (EncoderStep, {"encoder_mismatch"}),
        (TensionStep, {"tension_stuck"}),
        (BothStep, {"encoder_mismatch", "tension_stuck"}),
    ],
)
def test_the_declared_watches_flags_reach_the_step_and_its_estimate(cls, expected):
    # truth: every reading of the tensions is bit-identical (a real sensor's carries noise):
    # stuck from the 26th one (the first one is the reference, then 25 in a row); under a still
    # command, cable 1's encoder jumps by 1 cm (the watch's limit: 5 mm over a second)
    est = cls(GEOMETRY)
    est.reset(START)
    for k in range(25):
        assert est.update(_still(0.04 * k)).flags == set()
    jumped = LENGTHS.copy()
    jumped[0] += 0.01
    out = est.update(_still(1.0, jumped))
    assert out.flags == expected
    assert est.steps[-1] == (1.0, frozenset(expected))
    assert len(est.steps) == 26


def test_a_step_only_estimator_registers_and_an_update_only_one_still_does():
    class OldStyle(Estimator):
        """Written against the older interface: update() does the whole job."""

        name = "old_style_update"

        def update(self, measurement, inputs=NO_INPUTS):
            return PoseEstimate(measurement.time, np.eye(4), flags=frozenset({"own"}))

    class Neither(Estimator):
        name = "neither_step_nor_update"

    try:
        assert plugins.register(Step) is Step
        assert plugins.register(OldStyle) is OldStyle
        # the older interface's update() runs as written: no preamble, not even the reset check
        assert OldStyle(GEOMETRY).update(_still(np.nan)).flags == {"own"}
        with pytest.raises(
            TypeError, match=r"^Neither: implement _step \(abstract in Estimator\)$"
        ):
            plugins.register(Neither)
    finally:
        for name in ("step_only", "old_style_update"):
            plugins._REGISTRY["estimator"].pop(name, None)


def test_a_watches_declaration_that_is_not_a_sensor_watch_is_refused_at_definition():
    with pytest.raises(TypeError, match=r"^Typo: watches must be a SensorWatch \(e\.g\. "):

        class Typo(Step):
            watches = "encoders"
