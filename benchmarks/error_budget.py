"""The error budget's table and figure, from the ``error_budget`` campaign's results.

Runs the campaign (unless its table is there) and writes, beside the campaign's own report,
``budget.md`` (effect → each estimator's RMS deviation over the open-loop and the PBVS run,
the open-loop error at p1, the PBVS final error) and ``budget.png``:

    python benchmarks/error_budget.py [--out docs/error_budget] [--workers 1]

The campaign is ``campaigns/error_budget.toml`` (26 runs: 22.5 CPU-min, 23 min on one worker of
a 2-core machine shared with other jobs).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import pandas as pd
from matplotlib.figure import Figure

ROOT = Path(__file__).resolve().parents[1]
CAMPAIGN = ROOT / "campaigns" / "error_budget.toml"
ESTIMATORS = (
    "control",
    "image",
    "model_simple",
    "model_elastic",
    "model_pulley",
    "model_elastic_pulley",
    "fused",
)


def effect_name(params: str) -> str:
    """A short name of one ``realism`` axis value (a JSON table)."""
    table = json.loads(params)
    base = table.pop("profile")
    if base != "acrobot" or not table:
        return {
            "ideal": "none (ideal)",
            "acrobot": "acrobot",
            "acrobot_full": "all (acrobot_full)",
        }[base]
    table.pop("homing", None)  # (per-drum homing replaces the pose offset)
    fields = [k for part in table.values() for k in part]
    names = {
        "focal_correlation": "calibration correlations",
        "helix_pitch": "helical groove",
        "winding_compliance": "force-dependent winding",
        "backlash": "gearbox backlash",
        "friction_rate": "motor friction",
        "zero_error_std": "homing per drum",
        "defocus": "defocus",
        "vignetting_power": "vignetting",
        "flicker_depth": "light flicker",
        "line_time": "rolling shutter",
    }
    return "+ " + next(names[f] for f in fields if f in names)


def main() -> None:
    """Run the campaign if needed, then write the budget's table and figure."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default=str(ROOT / "docs" / "error_budget"), help="directory")
    parser.add_argument("--workers", default="1", help="parallel runs")
    args = parser.parse_args()
    out = Path(args.out)
    if not (out / "results.parquet").exists():
        cmd = ["cdpr-twin", "campaign", str(CAMPAIGN), "--out", str(out)]
        subprocess.run([*cmd, "--workers", args.workers], check=True)
    d = pd.read_parquet(out / "results.parquet")
    d["effect"] = d["param.realism"].map(effect_name)
    order = list(dict.fromkeys(d.sort_values("name")["effect"]))
    order = sorted(
        order, key=lambda e: (e != "none (ideal)", e != "acrobot", e.startswith("all"), e)
    )
    rows = []
    for effect in order:
        ol = d[(d.effect == effect) & (d.block == "open_loop")].iloc[0]
        pb = d[(d.effect == effect) & (d.block == "pbvs")].iloc[0]
        rows.append(
            {
                "effect": effect,
                "open loop at p1 [mm]": 1e3 * ol["cp1.t_m"],
                "PBVS final [mm]": 1e3 * pb["final_t_m"],
                "PBVS final [°]": pb["final_r_deg"],
                **{f"{e} OL [mm]": 1e3 * ol[f"est.{e}.rms_t_m"] for e in ESTIMATORS},
                **{f"{e} PBVS [mm]": 1e3 * pb[f"est.{e}.rms_t_m"] for e in ESTIMATORS},
                "faults": ", ".join(str(f) for f in (ol["fault"], pb["fault"]) if f),
            }
        )
    t = pd.DataFrame(rows)
    lines = [
        "# Error budget of the drives' and optics' effects",
        "",
        f"From `{CAMPAIGN.relative_to(ROOT)}` (the paper's two experiments, camera on, the paper",
        "study's robot, truth seed 19, one noise draw; `benchmarks/error_budget.py` writes this",
        "page). Each `+` row is the `acrobot` profile with that effect of `acrobot_full` alone.",
        "One robot and one draw each: a difference below the run-to-run spread of the paper study",
        "(open loop ≈ 1 mm at p1) says nothing; PBVS repeatability needs repetitions and is not",
        "in this table. `+ homing per drum` also drops `acrobot`'s rigid homing offset of the",
        "pose (1 mm, 0.2° per axis): its 10 µm per drum leaves a smaller start error, which the",
        "control-based and fused estimates then carry.",
        "",
        "| effect | open loop at p1 [mm] | PBVS final [mm / °] | "
        + " | ".join(f"{e} RMS OL / PBVS [mm]" for e in ESTIMATORS)
        + " |",
        "|---|---|---|" + "---|" * len(ESTIMATORS),
    ]
    for r in rows:
        cells = [
            r["effect"],
            f"{r['open loop at p1 [mm]']:.2f}",
            f"{r['PBVS final [mm]']:.2f} / {r['PBVS final [°]']:.3f}",
        ]
        cells += [f"{r[f'{e} OL [mm]']:.2f} / {r[f'{e} PBVS [mm]']:.2f}" for e in ESTIMATORS]
        lines.append("| " + " | ".join(cells) + " |")
    (out / "budget.md").write_text("\n".join(lines) + "\n")
    # (a Figure saved directly: no pyplot, no backend switched)
    fig = Figure(figsize=(12, 5))
    axes = fig.subplots(1, 2, sharey=True)
    y = range(len(t))
    for ax, block in zip(axes, ("OL", "PBVS"), strict=True):
        for k, e in enumerate(ESTIMATORS):
            ax.plot(t[f"{e} {block} [mm]"], y, "o", label=e, alpha=0.8, ms=4 + (k == 6) * 3)
        ax.set_xlabel(f"RMS translation deviation, {'open loop' if block == 'OL' else 'PBVS'} [mm]")
        ax.grid(alpha=0.3)
    axes[0].set_yticks(list(y), t["effect"])
    axes[0].invert_yaxis()
    axes[1].legend(fontsize=8)
    fig.suptitle("Error budget: each estimator's deviation, effect by effect (robot 19)")
    fig.tight_layout()
    fig.savefig(out / "budget.png", dpi=110)
    print(f"wrote {out / 'budget.md'} and {out / 'budget.png'}")
    sys.exit(0)


if __name__ == "__main__":
    main()
