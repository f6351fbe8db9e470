"""A calibration's outputs: the corrected robot description, and the report (numpy only).

``calibrated_robot.toml`` is the robot's own description (same schema, every other number
kept) with the estimated exit and anchor points, drum radii (``[winches] drum_radius_scale``),
camera mount and tag pose; a scenario uses it
as its nominal model with ``[model] nominal = "calibrated_robot.toml"``. ``calibration.json``
holds each parameter's estimate and 1σ, the fit, the rank analysis and timings, and — clearly
apart, under ``"check_against_truth"`` — the twin's truth errors, which the solver never saw.
"""

from __future__ import annotations

import json
import os
import tomllib
from pathlib import Path

import numpy as np

from cdpr_twin.calibrate.solver import Calibration
from cdpr_twin.files.transaction import MARKERS, Marker
from cdpr_twin.math.se3 import quat_wxyz_from_matrix, rot_x
from cdpr_twin.robot.description import DRUM_SCALE_TOLERANCE

R_CV_MJCAM = rot_x(np.pi)
"""OpenCV camera frame ↔ MuJoCo camera frame (a rotation by π about x, its own inverse)."""


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, str):  # JSON's escapes are TOML's, but for DEL, which TOML forbids raw
        return json.dumps(v, ensure_ascii=False).replace("\x7f", "\\u007f")
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    return repr(float(v)) if isinstance(v, float) else str(v)


def toml_text(data: dict, header: str = "") -> str:
    """TOML for a robot description's shape: top-level scalars, then one level of tables."""
    lines = [f"# {h}" for h in header.splitlines()]
    tables = {k: v for k, v in data.items() if isinstance(v, dict)}
    lines += [f"{k} = {_value(v)}" for k, v in data.items() if k not in tables]
    for name, table in tables.items():
        lines += ["", f"[{name}]"] + [f"{k} = {_value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


def calibrated_description(
    source: Path, cal: Calibration, drum_radii: np.ndarray, beside: Path | None = None
) -> str:
    """The robot description ``source`` with the calibration's estimates, as TOML text.

    Args:
        source: the description the software believed while recording.
        cal: the calibration.
        drum_radii: (m,) the radii the drives and encoders were set to while recording [m]
            (``Physics.drum_radius_set``): the drum scale errors s_i are relative to them.
        beside: the directory the text will be written in: the tag's texture is named relative
            to it when both lie in one tree below the root (a clone or copy of that tree still
            finds it); otherwise, or ``None``, by its absolute path.
    """
    data = tomllib.loads(source.read_text(encoding="utf-8-sig"))
    mod = cal.model
    data["cables"]["exit_points_m"] = np.round(mod.a_base, 7).tolist()
    data["cables"]["anchor_points_m"] = np.round(mod.b_platform, 7).tolist()
    winches = data["winches"]  # each drum: the radius it was read with, times (1 + s_i)
    radii = np.asarray(drum_radii, dtype=float) * (1.0 + mod.scale)
    if np.any(abs(radii / winches["drum_radius_m"] - 1) > DRUM_SCALE_TOLERANCE):  # read at
        winches["drum_radius_m"] = float(np.round(np.median(radii), 9))  # another radius
    winches["drum_radius_scale"] = np.round(radii / winches["drum_radius_m"], 9).tolist()
    if "camera" in data:
        R = mod.T_platform_cam[:3, :3] @ R_CV_MJCAM
        data["camera"]["position_m"] = np.round(mod.T_platform_cam[:3, 3], 7).tolist()
        data["camera"]["quat_wxyz"] = np.round(quat_wxyz_from_matrix(R), 9).tolist()
    if "tag" in data:
        data["tag"]["position_m"] = np.round(mod.T_base_tag[:3, 3], 7).tolist()
        q = quat_wxyz_from_matrix(mod.T_base_tag[:3, :3])
        data["tag"]["quat_wxyz"] = np.round(q, 9).tolist()
        texture = (source.parent / data["tag"]["texture"]).resolve()
        here = None if beside is None else Path(beside).resolve()
        if here is not None and Path(os.path.commonpath([texture, here])) != Path(texture.anchor):
            texture = Path(os.path.relpath(texture, here))  # (sharing no more than the root or
            # drive, e.g. a package installed apart from the output: absolute)
        data["tag"]["texture"] = str(texture)
    header = (
        f"{data.get('name', 'robot')}, calibrated by `cdpr-twin calibrate` from {source}.\n"
        "Exit and anchor points, drum radii (scale), camera mount and tag pose estimated\n"
        "(calibration.json: each one's 1-sigma); everything else as in the original description."
    )
    return toml_text(data, header)


UNITS = (
    "exit/anchor/offset and camera/tag x y z: m; camera/tag rx ry rz: rad (twists on the "
    "nominal); scale: relative drum radius error; tension_bias: N, tension_gain: relative "
    "(each tension sensor reads (1 + gain)·tension + bias; estimated, reported, not written "
    "into the description); intrinsics: the tag detector's error, fx fy cx cy: px, k1 k2 p1 "
    "p2: dimensionless (estimated, reported, not written into the description)"
)
"""The units of ``calibration.json``'s parameters."""

GAUGE = (
    "lengths and tag views do not see the base frame (a rigid motion of exit points, tag and "
    "platform poses) or the platform frame (of anchor points, camera mount and poses); the "
    "wrench balance levels the first (gravity) and places the second's horizontal position "
    "against the platform's centre of mass (its orientation stays unseen where the centre of "
    "mass is on the platform's origin, its vertical position is seen weakly); what is left, "
    "the priors fix (builder's tolerances, and the homing's repeatability at the homed pose)"
)
"""What the data cannot see, for ``calibration.json``."""


def report(cal: Calibration, extra: dict) -> dict:
    """The report's content (JSON-ready): estimates, σ, fit, rank; ``extra`` merged in."""
    idn = cal.identifiability
    params = [
        {"name": n, "estimate": float(e), "sigma": float(s), "prior_sigma": float(p)}
        for n, e, s, p in zip(cal.names, cal.estimate, cal.sigma, cal.prior_sigma, strict=True)
    ]
    return {
        "units": UNITS,
        "parameters": params,
        "fit": {
            "chi2_data": cal.chi2,
            "n_data": cal.n_data,
            "dof": cal.dof,
            "rms_cable_m": cal.rms_cable,
            "rms_tag_position_m": float(cal.rms_tag[0]),
            "rms_tag_rotation_rad": float(cal.rms_tag[1]),
            "nfev": cal.nfev,
            "solve_s": cal.wall_time,
        },
        "identifiability": {
            "rank": idn.rank,
            "n_params": idn.n_params,
            "tolerance": idn.tolerance,
            "smallest_singular_values": idn.singular_values[-16:].tolist(),
            "unseen_directions": idn.null_directions,
            "prior_determined": idn.prior_determined,
            "gauge": GAUGE,
        },
        **extra,
    }


NAMES = MARKERS["calibration"]
"""What a calibration writes into its output directory (the report last: it marks completion)."""
MARKER = Marker("calibration.json", frozenset({"parameters", "fit", "identifiability"}))
"""A calibration's report (:func:`report`): its commit marker."""


def clear(out: Path) -> None:
    """Remove an earlier calibration's files (and half-written ones) from ``out``."""
    from cdpr_twin.files.transaction import partial_of, writing

    for path in [out / n for n in NAMES] + [partial_of(out / n) for n in NAMES]:
        with writing(path):
            path.unlink(missing_ok=True)


def write(
    out: Path, source: Path, cal: Calibration, extra: dict, drum_radii: np.ndarray
) -> tuple[Path, Path]:
    """Write ``calibrated_robot.toml`` then ``calibration.json`` into ``out``.

    ``drum_radii``: the radii the recording's drives and encoders were set to (its
    :attr:`~cdpr_twin.calibrate.acquire.Recording.drum_radii`).

    Both are written whole as ``*.partial`` (``fsync``'ed) before either is renamed (renames
    need no space): a full disk leaves both partial, never a description without its report.

    Raises:
        cdpr_twin.files.transaction.OutputError: a file cannot be written (naming it).
    """
    from cdpr_twin.files.transaction import fsync_dir, json_text, write_partial, writing
    from cdpr_twin.run.interrupts import shielded

    with writing(out):
        out.mkdir(parents=True, exist_ok=True)
    robot, rep = (out / n for n in NAMES)
    files = [write_partial(robot, calibrated_description(source, cal, drum_radii, beside=out))]
    files.append(write_partial(rep, json_text(report(cal, extra))))
    with shielded():  # a signal between the renames would split the pair
        for partial in files:  # the report last: it marks completion
            partial.commit()
    fsync_dir(out)
    return robot, rep
