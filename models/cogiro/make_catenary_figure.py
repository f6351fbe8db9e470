"""Draw catenary_convergence.png: a discretised MuJoCo cable's end forces → Irvine's catenary.

CoGiRo's Ø 4 mm steel cable (0.064 kg/m, E·S = 8.61e5 N) over a 17 m span with a 9 m rise,
unstretched length 0.01 % under the chord (≈ 130 N horizontal tension, 0.12 m sag). Run from the
repository root: python models/cogiro/make_catenary_figure.py (≈ 15 s).
"""

import math
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from cdpr_twin.math.catenary import end_forces, solve_catenary
from cdpr_twin.sim.cable_chain import chain_end_forces

RHO, ES = 0.064, 68.5e9 * math.pi * 0.002**2
LOW, HIGH = np.zeros(3), np.array([12.0, 5.0, 9.0])
L0 = float(np.linalg.norm(HIGH)) * (1 - 1e-4)
SEGMENTS = (2, 4, 8, 16, 32, 64)


def main() -> None:
    cat = solve_catenary(L0, ES, RHO * 9.81, math.hypot(*HIGH[:2]), HIGH[2])
    on_low, on_high = end_forces(cat, HIGH, LOW)
    err_low, err_high = [], []
    for n in SEGMENTS:
        chain = chain_end_forces(L0, ES, RHO, LOW, HIGH, n)
        err_low.append(np.linalg.norm(chain.force_low - on_low) / np.linalg.norm(on_low))
        err_high.append(np.linalg.norm(chain.force_high - on_high) / np.linalg.norm(on_high))
        print(f"N = {n:3d}: end-force error {err_low[-1]:.2e} / {err_high[-1]:.2e}")
    fig = Figure(figsize=(5.5, 4))
    ax = fig.add_subplot()
    ax.loglog(SEGMENTS, err_low, "o-", label="platform end")
    ax.loglog(SEGMENTS, err_high, "s--", label="pulley end")
    ax.loglog(
        SEGMENTS,
        [err_low[0] * (SEGMENTS[0] / n) ** 2 for n in SEGMENTS],
        ":",
        color="grey",
        label="∝ 1/N²",
    )
    ax.axhline(0.01, color="red", lw=0.8, label="1 %")
    ax.set(xlabel="segments N of the MuJoCo cable", ylabel="|F_MuJoCo − F_catenary| / |F_catenary|")
    ax.set_title(
        f"Ø4 mm steel, 17 m span: H = {cat.horizontal:.0f} N, sag {cat.sag * 1e3:.0f} mm",
        fontsize=9,
    )
    ax.set_xticks(SEGMENTS, [str(n) for n in SEGMENTS])
    ax.minorticks_off()
    ax.legend(fontsize=8)
    fig.tight_layout()
    out = Path(__file__).parent / "catenary_convergence.png"
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


if __name__ == "__main__":
    main()
