"""Where each unknown of a calibration sits in its parameter vector (numpy only)."""

from __future__ import annotations

import numpy as np

BLOCKS = (
    "exit",
    "anchor",
    "offset",
    "scale",
    "tension_bias",
    "tension_gain",
    "camera",
    "tag",
    "intrinsics",
)
"""The shared parameter blocks, in the order they sit in the parameter vector."""

PER_CABLE = {"exit": 3, "anchor": 3, "offset": 1, "scale": 1, "tension_bias": 1, "tension_gain": 1}
"""The blocks with values per cable, and how many each cable has."""


class Layout:
    """Where each parameter sits in the vector: shared blocks, then 6 per pose.

    Args:
        m: cable count.
        n_poses: K.
        priors: which blocks are estimated, and their prior σ
            (:class:`cdpr_twin.calibrate.problem.Priors`).
        with_intrinsics: whether the intrinsics block can be estimated (a detector is known).
        with_statics: whether the tension sensors' blocks can be estimated (the force balance
            at each pose is a residual).
    """

    def __init__(
        self,
        m: int,
        n_poses: int,
        priors,
        with_intrinsics: bool = False,
        with_statics: bool = False,
    ) -> None:
        sizes = {name: m * w for name, w in PER_CABLE.items()} | dict(camera=6, tag=6, intrinsics=8)
        possible = {
            "intrinsics": with_intrinsics,
            "tension_bias": with_statics,
            "tension_gain": with_statics,
        }
        self.m, self.n_poses, self.blocks = m, n_poses, {}
        at = 0
        for name in BLOCKS:
            if name in priors.estimate and possible.get(name, True):
                self.blocks[name] = slice(at, at + sizes[name])
                at += sizes[name]
        self.n_shared = at
        self.n = at + 6 * n_poses
        self.sigma = np.concatenate([self._prior(n, priors) for n in self.blocks] or [np.zeros(0)])

    def _prior(self, name: str, p) -> np.ndarray:
        if name == "intrinsics":
            return np.asarray(p.intrinsics, dtype=float)
        if name in ("camera", "tag"):
            pos, rot = getattr(p, f"{name}_position"), getattr(p, f"{name}_rotation")
            return np.array([pos] * 3 + [rot] * 3)
        return np.full(self.m * PER_CABLE[name], getattr(p, name))

    def pose(self, k: int) -> slice:
        """The slice of pose k's six parameters."""
        return slice(self.n_shared + 6 * k, self.n_shared + 6 * k + 6)

    def names(self) -> list[str]:
        """A name per shared parameter (``exit3.y``, ``offset5``, ``camera.rx``…; from 1)."""
        out: list[str] = []
        for name in self.blocks:
            if name in ("exit", "anchor"):
                out += [f"{name}{i + 1}.{ax}" for i in range(self.m) for ax in "xyz"]
            elif name in ("camera", "tag"):
                out += [f"{name}.{ax}" for ax in ("x", "y", "z", "rx", "ry", "rz")]
            elif name == "intrinsics":
                out += [f"intrinsics.{k}" for k in ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2")]
            else:
                out += [f"{name}{i + 1}" for i in range(self.m)]
        return out

    def get(self, x: np.ndarray, name: str) -> np.ndarray:
        """A block's values (zeros when not estimated), shaped (m, 3), (m,), (6,) or (8,)."""
        m = self.m
        shared: dict[str, tuple[int, ...]] = {"intrinsics": (8,), "camera": (6,), "tag": (6,)}
        shape = shared.get(name) or ((m, 3) if PER_CABLE[name] == 3 else (m,))
        if name not in self.blocks:
            return np.zeros(shape)
        return x[self.blocks[name]].reshape(shape)

    def columns(self, name: str, i: int | None = None) -> range:
        """The columns of a block (of cable ``i`` only, for a per-cable block); empty if absent."""
        if name not in self.blocks:
            return range(0)
        at = self.blocks[name]
        if i is None:
            return range(at.start, at.stop)
        w = PER_CABLE[name]
        return range(at.start + w * i, at.start + w * i + w)
