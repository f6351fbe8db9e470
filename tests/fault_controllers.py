"""A test controller outside the package: every winch at one constant rate (reel in, pay out).

Scenario files name this module in ``plugins`` (``plugins = ["fault_controllers"]``) to drive
the robot past its limits, as a runaway or a wrong command would.
"""

import dataclasses

import numpy as np

from cdpr_twin import plugins
from cdpr_twin.controllers.base import Controller
from cdpr_twin.plugins import option
from cdpr_twin.types import Command, Measurement, PoseEstimate


@dataclasses.dataclass(frozen=True)
class ConstantRatesOptions:
    """The one rate of every winch."""

    rate: float = option(0.0, unit="m/s")


@plugins.register
class ConstantRates(Controller):
    """Every winch at ``rate`` (positive pays out), for ever."""

    name = "constant_rates"
    Options = ConstantRatesOptions

    def reset(self, T_base_platform0: np.ndarray) -> None:
        pass

    def command(
        self, t: float, period: float, estimate: PoseEstimate, measurement: Measurement
    ) -> Command:
        rates = np.full(len(measurement.cable_lengths), self.options.rate)
        return Command(rates, np.zeros(6))
