"""How a planar-target calibration leaves the camera's intrinsics errors correlated.

Repeats one Zhang-method calibration (OpenCV ``calibrateCamera``) of ACROBOT's onboard camera
(640 × 480, f = 415.69 px, the ``acrobot`` lens) from 15 views of a 9 × 6 chessboard of 25 mm
squares, 0.25–0.45 m away and tilted by ≈ 20° (1σ per axis), each time with fresh corner noise
(0.2 px), and prints the stds and the correlation matrix of the errors of
(fx, fy, cx, cy, k1, k2, p1, p2) over the repetitions: the correlations of the ``acrobot_full``
profile (``[realism.optics]``) come from it.

    python benchmarks/calibration_correlations.py [--runs 200] [--seed 0]

Takes ≈ 10 s for 200 calibrations on one core.
"""

from __future__ import annotations

import argparse

import cv2
import numpy as np

NAMES = ("fx", "fy", "cx", "cy", "k1", "k2", "p1", "p2")


def main() -> None:
    """Calibrate repeatedly and print the errors' statistics."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=200, help="calibrations")
    parser.add_argument("--seed", type=int, default=0, help="seed of views and noise")
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    width, height, f = 640, 480, 415.69
    K = np.array([[f, 0.0, 319.5], [0.0, f, 239.5], [0.0, 0.0, 1.0]])
    lens = np.array([-0.2, 0.08, 0.002, -0.002, 0.0])
    board = np.zeros((54, 3), np.float32)
    board[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2) * 0.025
    board[:, :2] -= board[:, :2].mean(axis=0)
    views = []
    for _ in range(15):
        rvec = rng.normal(0.0, 0.35, 3)
        tvec = np.array(
            [rng.uniform(-0.05, 0.05), rng.uniform(-0.04, 0.04), rng.uniform(0.25, 0.45)]
        )
        image, _ = cv2.projectPoints(board, rvec, tvec, K, lens)
        u, v = image[:, 0, 0], image[:, 0, 1]
        if u.min() > 5 and u.max() < width - 5 and v.min() > 5 and v.max() < height - 5:
            views.append(image)
    rows = []
    for _ in range(args.runs):
        seen = [(v + rng.normal(0.0, 0.2, v.shape)).astype(np.float32) for v in views]
        flags = cv2.CALIB_USE_INTRINSIC_GUESS | cv2.CALIB_FIX_K3
        _, Kc, dc, _, _ = cv2.calibrateCamera(
            [board] * len(seen),
            seen,
            (width, height),
            K.copy(),
            lens.reshape(1, 5).copy(),
            flags=flags,
        )
        rows.append([Kc[0, 0], Kc[1, 1], Kc[0, 2], Kc[1, 2], *dc.ravel()[:4]])
    e = np.array(rows) - np.mean(rows, axis=0)
    print(f"{len(views)} views, {args.runs} calibrations")
    print("std:", "  ".join(f"{n} {s:.3g}" for n, s in zip(NAMES, e.std(axis=0), strict=True)))
    print(f"relative std of fx: {e[:, 0].std() / f:.3g}")
    aspect = np.array(rows)[:, 1] / np.array(rows)[:, 0]
    print(f"relative std of fy/fx: {aspect.std() / aspect.mean():.3g}")
    print("correlations:")
    print("      " + "".join(f"{n:>7}" for n in NAMES))
    for n, row in zip(NAMES, np.corrcoef(e.T), strict=True):
        print(f"{n:>6}" + "".join(f"{c:7.2f}" for c in row))


if __name__ == "__main__":
    main()
