"""`timeseries.csv`: what TimeseriesWriter writes, Timeseries reads back exactly."""

from pathlib import Path

import numpy as np
import pytest

from cdpr_twin.math.se3 import pose_from_vector
from cdpr_twin.recording.timeseries import Timeseries, TimeseriesWriter, header, load_timeseries
from cdpr_twin.types import Command, Measurement, PoseEstimate, Status, TagDetection

NAMES = ("control", "image", "model_simple", "fused")


def _pose(rng: np.random.Generator) -> np.ndarray:
    return pose_from_vector(np.r_[rng.normal(0.0, 0.3, 3), rng.uniform(-170.0, 170.0, 3)])


def _write(path: Path, n_cables: int, rows: int = 40, flush_every: int = 7) -> dict:
    """Write ``rows`` ticks of known content; returns what was written, by column group."""
    rng = np.random.default_rng(n_cables)
    w = TimeseriesWriter(path, NAMES, n_cables, flush_every=flush_every)
    truth = {k: [] for k in ("t", "true", "est", "valid", "tau", "l0", "rate", "plan", "tag")}
    truth["status"] = []
    for k in range(rows):
        t = 0.04 * k
        T_true, plan = _pose(rng), _pose(rng) if k % 4 else None
        estimates = {n: PoseEstimate(t, _pose(rng), valid=bool(rng.integers(2))) for n in NAMES}
        tag = None if k % 3 == 0 else TagDetection(0, np.zeros((4, 2)), _pose(rng), 50.0, 0.1)
        status = (Status.TRACKING, Status.SERVOING, Status.TAG_LOST)[k % 3]
        command = None if k == 0 else Command(rng.normal(size=n_cables), np.zeros(6), False, status)
        m = Measurement(t, rng.uniform(0.5, 1.5, n_cables), rng.uniform(0, 30, n_cables), command)
        m = Measurement(m.time, m.cable_lengths, m.tensions, m.command, tag=tag)
        w.tick(t, T_true, estimates, m, command, plan)
        for key, value in (
            ("t", t),
            ("true", T_true),
            ("est", {n: e.T_base_platform for n, e in estimates.items()}),
            ("valid", {n: e.valid for n, e in estimates.items()}),
            ("tau", m.tensions),
            ("l0", m.cable_lengths),
            ("rate", m.cable_rates),
            ("plan", plan),
            ("tag", None if tag is None else tag.T_cam_tag),
            ("status", Status.START if command is None else status),
        ):
            truth[key].append(value)
    assert path.with_name(path.name + ".partial").exists() and not path.exists()
    w.close()
    assert path.exists() and not path.with_name(path.name + ".partial").exists()
    assert w.rows == rows
    return truth


def _same_pose(T_read: np.ndarray, T_written: np.ndarray) -> None:
    """A pose read back is the written one to 1e-15 (the quaternion is the only conversion)."""
    np.testing.assert_array_equal(T_read[:3, 3], T_written[:3, 3])
    np.testing.assert_allclose(T_read, T_written, rtol=0, atol=1e-15)


@pytest.mark.parametrize("n_cables", [6, 8, 12])
def test_round_trip(tmp_path, n_cables):
    path = tmp_path / "timeseries.csv"
    w = _write(path, n_cables)
    ts = Timeseries.load(path)
    assert ts.estimator_names == NAMES and ts.n_cables == n_cables
    np.testing.assert_array_equal(ts.t, w["t"])
    for i, T in enumerate(ts.poses("true")):
        _same_pose(T, w["true"][i])
    for n in NAMES:
        for i, T in enumerate(ts.poses(n)):
            _same_pose(T, w["est"][i][n])
        np.testing.assert_array_equal(ts.columns[f"{n}_valid"], [v[n] for v in w["valid"]])
    for prefix, key in (("tension", "tau"), ("length", "l0"), ("rate", "rate")):
        assert ts.matrix(prefix).shape == (len(ts.t), n_cables)
        np.testing.assert_array_equal(ts.matrix(prefix), np.array(w[key]))
    for prefix in ("plan", "tag"):  # empty cells read as NaN poses
        for i, T in enumerate(ts.poses(prefix)):
            if w[prefix][i] is None:
                assert np.all(np.isnan(T)) and np.isnan(ts.columns[f"{prefix}_x"][i])
            else:
                _same_pose(T, w[prefix][i])
    assert ts.status.tolist() == [str(s) for s in w["status"]]
    assert ts.status[0] == Status.START == "start"
    assert Status(ts.status[1]) is Status.SERVOING


def test_header_is_the_one_schema(tmp_path):
    path = tmp_path / "timeseries.csv"
    TimeseriesWriter(path, ("control",), 3).close()
    first = path.read_text().splitlines()[0].split(",")
    assert first == header(("control",), 3)
    assert first[:2] == ["t", "true_x"] and first[-2:] == ["status", "event"]
    pose = [f"control_{k}" for k in ("x", "y", "z", "qw", "qx", "qy", "qz")]
    assert first[8:16] == [*pose, "control_valid"]
    assert [c for c in first if c.startswith("rate_")] == ["rate_1", "rate_2", "rate_3"]
    ts = load_timeseries(path)  # no rows: empty columns, same names
    assert ts.estimator_names == ("control",) and ts.n_cables == 3 and len(ts.t) == 0


def test_rows_are_exact_and_the_start_row_says_start(tmp_path):
    path = tmp_path / "timeseries.csv"
    w = TimeseriesWriter(path, ("control",), 2, flush_every=1)
    T = pose_from_vector([0.1, -0.2, 0.3, 0, 0, 0])
    m = Measurement(0.1, np.array([1.0 / 3.0, 0.5]), np.array([10.0, 20.0]))
    w.tick(0.1, T, {"control": PoseEstimate(0.1, T)}, m, None, None)
    assert w.rows == 1  # written at once with flush_every=1
    w.close()
    row = path.read_text().splitlines()[1].split(",")
    assert row[0] == "0.10000000000000001" and row[-2:] == ["start", ""]
    position = ["0.10000000000000001", "-0.20000000000000001", "0.29999999999999999"]
    assert row[8:16] == [*position, "1", "0", "0", "0", "1"]  # x y z qw qx qy qz valid
    assert row[16:22] == ["10", "20", "0.33333333333333331", "0.5", "0", "0"]
    assert row[22:] == [*[""] * 14, "start", ""]  # no plan, no tag; no event


def test_a_file_of_another_schema_is_refused(tmp_path):
    path = tmp_path / "timeseries.csv"
    path.write_text("t,x,y\n0,1,2\n")
    with pytest.raises(ValueError, match=r"not a timeseries\.csv header"):
        Timeseries.load(path)
