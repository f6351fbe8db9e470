"""MuJoCo's own warnings reach the monitor (a fault per onset) and the divergence check."""

import mujoco
import numpy as np
import pytest
from conftest import paper_pose

from cdpr_twin.sim import build_robot
from cdpr_twin.sim.model import SimulationError
from cdpr_twin.sim.monitor import FaultKind, Monitor, MonitorLimits

FULL = mujoco.mjtWarning.mjWARN_CNSTRFULL


def _warn_constraints_full(physics) -> None:
    """What MuJoCo's mj_warning does when its constraint buffer fills: count one more."""
    physics.data.warning[FULL].number += 1


def test_each_new_mujoco_warning_is_one_fault_at_the_next_look():
    physics = build_robot().physics
    physics.reset(paper_pose("p1"), settle_time=0.0)
    monitor = Monitor(physics, MonitorLimits())  # no limit but MuJoCo's warnings
    monitor.reset()
    physics.add_hook(monitor)
    physics.advance(0.04, np.zeros(8))
    assert monitor.take() == []
    for _ in range(2):  # a second warning of the same kind is a new onset
        _warn_constraints_full(physics)
        t = physics.time
        physics.advance(0.04, np.zeros(8))  # the monitor looks before the first chunk
        faults = [(f.time, f.kind, f.detail) for f in monitor.take()]
        assert faults == [(t, FaultKind.MUJOCO_WARNING, "mjWARN_CNSTRFULL")]
        physics.advance(0.04, np.zeros(8))  # the count stays: nothing new
        assert monitor.take() == []


def test_a_bad_control_that_mujoco_warns_about_stops_the_physics():
    physics = build_robot().physics
    physics.reset(paper_pose("p1"), settle_time=0.0)
    physics.data.ctrl[0] = np.nan  # MuJoCo zeroes it and warns mjWARN_BADCTRL
    with pytest.raises(SimulationError, match=r"diverged at t = .*mjWARN_BADCTRL"):
        physics.step(1)
