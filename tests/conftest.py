"""Shared fixtures: the paper's poses, twins of the nominal robot, a disk that fills up."""

import builtins
import errno
import io
import os
from collections import Counter
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")  # before any test module imports mujoco

import numpy as np
import pytest

from cdpr_twin.math import se3

# ACROBOT's exit and anchor points (models/acrobot), typed here independently of the model file
A_BASE = [
    (-0.4725, -0.5275, 1.165),
    (-0.5225, -0.4675, 1.165),
    (-0.5225, 0.4725, 1.165),
    (-0.4725, 0.5275, 1.165),
    (0.4675, 0.5275, 1.165),
    (0.5175, 0.4725, 1.165),
    (0.5225, -0.4725, 1.165),
    (0.4675, -0.5225, 1.165),
]
B_PLATFORM = [
    (0.0774, -0.085, 0.0347),
    (-0.09, 0.072, -0.0342),
    (-0.09, -0.073, 0.0347),
    (0.0752, 0.085, -0.0353),
    (-0.0829, 0.085, 0.0353),
    (0.09, -0.073, -0.0347),
    (0.0895, 0.0744, 0.0347),
    (-0.0747, -0.085, -0.0347),
]

PAPER_POSES = {
    "p0": [0.112, -0.032, 0.301, -12.0, -10.0, 0.0],
    "p1": [0.284, -0.197, 0.08, 0.0, 0.0, 0.0],
    "p2": [0.284, -0.197, 0.25, 0.0, 0.0, 0.0],
}


EXACT_OPEN_LOOP = {
    "realism.profile": "ideal",
    "truth.exit_point_std": 0.0,
    "truth.anchor_point_std": 0.0,
    "truth.es_scale_std": 0.0,
    "truth.pulley_radius_std": 0.0,
    "truth.camera_position_std": 0.0,
    "truth.camera_rotation_std_deg": 0.0,
    "sensors.tension_noise_std": 0.0,
    "sensors.camera": False,
    "duration": 10.0,
}
"""Dotted overrides of ``paper_open_loop``: the robot exactly as modelled, ideal sensors, no
camera, p0 → p1 (10 s): what a test then switches on is the only error."""


def processes() -> list[tuple[int, str, int, int]]:
    """Every process's (pid, state, parent pid, process group), from ``/proc``."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()  # after "comm)"
        except OSError:
            continue
        out.append((int(stat.parent.name), fields[0], int(fields[1]), int(fields[2])))
    return out


def group_alive(pgid: int) -> bool:
    """Whether a process of group ``pgid`` still runs (zombies awaiting their reaper do not)."""
    return any(group == pgid and state != "Z" for _, state, _, group in processes())


def children(pid: int) -> list[int]:
    """The live child processes of ``pid``."""
    return [p for p, state, parent, _ in processes() if parent == pid and state != "Z"]


def outlived_by_its_group(proc, wait: float = 10.0) -> bool:
    """SIGKILL the process ``proc`` (started with ``start_new_session``) alone, without any
    cleanup: whether a process of its group still runs ``wait`` seconds later (then killed)."""
    import signal
    import time

    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    deadline = time.monotonic() + wait
    while group_alive(proc.pid) and time.monotonic() < deadline:
        time.sleep(0.2)
    alive = group_alive(proc.pid)
    if alive:
        os.killpg(proc.pid, signal.SIGKILL)
    return alive


def pool_threads() -> list:
    """The live threads that manage a ``ProcessPoolExecutor``'s workers (Python's own)."""
    import threading
    from concurrent.futures.process import _ExecutorManagerThread

    return [t for t in threading.enumerate() if isinstance(t, _ExecutorManagerThread)]


EARLIER_SUMMARY = (
    '{"scenario": "paper_open_loop", "status": "%s", "estimator_names": [], '
    '"simulated_time_s": 1.0}\n'
)
"""An earlier run's ``summary.json`` (``% status``): the keys that mark it as a run of ours."""


def paper_pose(name: str) -> np.ndarray:
    return se3.pose_from_vector(PAPER_POSES[name])


def random_workspace_poses(n: int, seed: int = 0) -> list[np.ndarray]:
    """Poses spread over ACROBOT's workspace (positions and ±15° tilts, ±20° yaw)."""
    rng = np.random.default_rng(seed)
    poses = []
    for _ in range(n):
        p = [
            rng.uniform(-0.3, 0.3),
            rng.uniform(-0.3, 0.3),
            rng.uniform(0.08, 0.6),
            rng.uniform(-15, 15),
            rng.uniform(-15, 15),
            rng.uniform(-20, 20),
        ]
        poses.append(se3.pose_from_vector(p))
    return poses


@pytest.fixture(scope="module")
def twin():
    """Nominal robot, noise off, camera off."""
    from cdpr_twin.sim import Twin

    with Twin(camera=False, tension_noise_std=0.0) as t:
        yield t


@pytest.fixture(scope="module")
def camera_twin():
    """Nominal robot, noise off, camera on."""
    from cdpr_twin.sim import Twin

    with Twin(camera=True, tension_noise_std=0.0) as t:
        yield t


def pytest_xdist_auto_num_workers(config: pytest.Config) -> int:
    """``-n auto`` (the suite's default, ``pyproject.toml``): one worker per core this process
    may use, at most 4 — several tests start process pools and renderer threads of their own, so
    more workers only crowd the cores. ``-n 0`` runs the suite in one process."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    return max(1, min(cores or 1, 4))


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Run the modules holding ``slow`` tests first, most ``slow`` tests first.

    With ``--dist loadfile`` each module goes whole to one worker, in this order
    (``--no-loadscope-reorder``): the long modules start at once instead of one of them being
    left to run alone at the end while the other workers idle. Within a module the order stays.
    """

    def module(item: pytest.Item) -> str:
        return item.nodeid.split("::")[0]

    slow = Counter(module(it) for it in items if it.get_closest_marker("slow") is not None)
    items.sort(key=lambda it: -slow[module(it)])  # a stable sort: the rest keeps its order


ENOSPC = "No space left on device"


class _FullFile:
    """A file on a disk with ``budget[0]`` bytes free: what does not fit raises ENOSPC."""

    def __init__(self, f, budget: list[int]) -> None:
        self._f, self._budget = f, budget

    def write(self, data):
        room = self._budget[0]
        if len(data) > room:
            self._f.write(data[:room])
            self._f.flush()
            self._budget[0] = 0
            raise OSError(errno.ENOSPC, ENOSPC)
        self._budget[0] -= len(data)
        return self._f.write(data)

    def __getattr__(self, name):
        return getattr(self._f, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self._f.close()


@pytest.fixture
def full_disk(monkeypatch):
    """``full_disk(n)``: from now on the disk takes ``n`` more bytes (``open`` and sendfile)."""

    def fill(free: int) -> None:
        real, budget = io.open, [free]

        def fake_open(file, mode="r", *args, **kwargs):
            f = real(file, mode, *args, **kwargs)
            return _FullFile(f, budget) if any(c in mode for c in "wax+") else f

        def fake_sendfile(*args):
            raise OSError(errno.ENOSPC, ENOSPC)

        monkeypatch.setattr(io, "open", fake_open)
        monkeypatch.setattr(builtins, "open", fake_open)
        monkeypatch.setattr(os, "sendfile", fake_sendfile)

    return fill
