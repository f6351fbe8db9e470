"""The study's outputs: Fig. 5/7/8 and ``report.md`` (the numbers come from :mod:`.analysis`)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from cdpr_twin.files.transaction import write_atomic, write_json_atomic
from cdpr_twin.recording.timeseries import Timeseries
from cdpr_twin.run.metrics import sample_std
from cdpr_twin.study.analysis import figure_runs, segment_ends
from cdpr_twin.study.output_dir import FIGURES
from cdpr_twin.study.results import load_summary, model_estimators

PAPER_PBVS = {
    "control": "≤ 0.9 cm / 2°",
    "model_simple": "≤ 1.29 cm / 2°",
    "model_elastic": "≤ 1.29 cm / 2°",
    "model_pulley": "≤ 1.56 cm",
    "model_elastic_pulley": "≤ 1.56 cm",
    "image": "noisiest",
}
"""The paper's max deviation with each estimator in the PBVS loop (§IV-C, Fig. 7)."""
NOT_IN_PAPER = "—"
"""The paper's value of a quantity it does not have (e.g. an estimator it did not test)."""


def make_figures(out: Path, rep: dict, records: list[dict]) -> list[Path]:
    """Fig. 5a/5b, 7a/7b and 8 into ``out``, from the seed-1 runs and the report's accuracy.

    Each is written whole (``<name>.png.partial``, then renamed: :mod:`cdpr_twin.study.figures`).

    Raises:
        OutputError: a figure cannot be written (it is left ``*.partial``).
    """
    from cdpr_twin.study import figures
    from cdpr_twin.study.plan import with_dirs_in

    open_loop, pbvs = figure_runs(with_dirs_in(out, records))
    paths: list[Path] = []
    if open_loop is not None:
        ts = Timeseries.load(open_loop / "timeseries.csv")
        ends = segment_ends(load_summary(open_loop / "summary.json"))
        # the segment ends inside the run; one at its last row would only draw the right edge
        marks = tuple(e.time_s for e in ends if e.time_s < ts.t[-1])
        paths += figures.open_loop_figures(ts, out, marks=marks)
    if pbvs:
        runs = {n: Timeseries.load(d / "timeseries.csv") for n, d in pbvs.items()}
        paths += figures.pbvs_figures(runs, out)
    if rep.get("accuracy"):
        paths.append(figures.accuracy_bars(rep["accuracy"], out / "fig8.png"))
    return paths


def _mm(v: float) -> str:
    return f"{v * 1e3:.2f} mm"


def _intro(rep: dict, wall_time_s: float) -> list[str]:
    lines = [
        "# cdpr-twin: the paper's study, reproduced",
        "",
        f"{rep['runs']['ok']} of {rep['runs']['total']} runs completed "
        f"({wall_time_s / 60:.1f} min). Every number below is computed from the runs' "
        "`timeseries.csv` and `summary.json` files (also in `report.json`).",
        "",
    ]
    if "population" in rep:
        runs = {b: len(r) for b, r in rep["population"]["metrics"].items()}
        lines[2] += (
            f" The verdicts come from {sum(runs.values())} more runs of "
            "`campaigns/paper_population.toml` ("
            + ", ".join(f"{b} {n}" for b, n in runs.items())
            + f"); realism profile `{rep.get('realism', {}).get('profile', 'ideal')}`. Made by "
            "`cdpr-twin reproduce --population DIR`: the population's runs already in DIR are "
            "kept, the missing ones run (on Ray: `cdpr-twin campaign "
            "campaigns/paper_population.toml --out DIR --resume --ray` first)."
        )
    if rep["runs"]["failed"]:
        lines += ["Failed runs:", ""]
        lines += [f"- `{f['name']}`: {f['status']}" for f in rep["runs"]["failed"]]
        lines += [""]
    return lines


def _findings(rep: dict) -> list[str]:
    lines = [
        "## Findings",
        "",
        "One robot: its numbers, each finding's criteria (the criteria file's entries, which "
        "judge a population's share of robots) and whether their per-robot condition holds on "
        "this robot. The verdicts are the population's: `cdpr-twin reproduce --population DIR`.",
        "",
        "| finding | paper | twin | criterion | verdict | why |",
        "|---|---|---|---|---|---|",
    ]
    return lines + [
        f"| {f['finding']} | {f['paper']} | {f['twin']} | {f['criterion']} | **{f['verdict']}** "
        f"| {f['why']} |"
        for f in rep["findings"]
    ]


def _illustration(rep: dict) -> list[str]:
    """The single robot's findings, as an illustration: its numbers and why, no verdict."""
    lines = [
        "## Illustration: one robot (truth seed 19, chosen)",
        "",
        "The figures and the tables below are of one robot, truth seed 19, chosen for its "
        "≈ 1 cm open-loop miss at p1, the paper's; run seed 1 for the figures. Its percentile "
        "in each metric of the populations is in the table above (*robot 19*). What one robot "
        "shows is not a verdict: the verdicts are the populations'.",
        "",
        "| finding | paper | robot 19 | why |",
        "|---|---|---|---|",
    ]
    return lines + [
        f"| {f['finding']} | {f['paper']} | {f['twin']} | {f['why']} |" for f in rep["findings"]
    ]


def _open_loop_rows(ol: dict) -> list[str]:
    """The open-loop rows of the paper-beside-twin table."""
    lines = []
    e = ol.get("estimators", {})
    if "control" in e:
        c = e["control"]
        lines.append(
            f"| open loop, control-based: max deviation | 1.4 cm / 1.6° | "
            f"{c['max_translation_m'] * 100:.2f} cm / {c['max_rotation_deg']:.2f}° |"
        )
        lines.append(
            f"| open loop, control-based: final deviation | 1.3 mm / 0.55° | "
            f"{_mm(c['final_translation_m'])} / {c['final_rotation_deg']:.2f}° |"
        )
    models = model_estimators(e)
    if models:
        worst = max(e[n]["max_translation_m"] for n in models)
        lines.append(
            f"| open loop, model-based: max translational deviation | 1.21 cm | "
            f"{worst * 100:.2f} cm |"
        )
    if "miss_at_p1" in ol:
        lines.append(
            f"| open loop: MP error at p1 | ≈ 1 cm | "
            f"{ol['miss_at_p1']['translation_m'] * 100:.2f} cm |"
        )
    return lines


def _paper_table(rep: dict) -> list[str]:
    lines = [
        "",
        "## The paper's numbers beside the twin's",
        "",
        "| quantity | paper | twin |",
        "|---|---|---|",
        *_open_loop_rows(rep.get("open_loop", {})),
    ]
    for n, v in rep.get("pbvs", {}).items():
        lines.append(
            f"| PBVS, {n} in the loop: max deviation | {PAPER_PBVS.get(n, NOT_IN_PAPER)} | "
            f"{v['max_translation_m'] * 100:.2f} cm / {v['max_rotation_deg']:.2f}° |"
        )
    if "ratios" in rep:
        lines.append(
            f"| PBVS / open-loop accuracy at p1, translation | 5× | "
            f"{rep['ratios']['translation_m']:.1f}× |"
        )
        lines.append(
            f"| PBVS / open-loop accuracy at p1, rotation | 4× | "
            f"{rep['ratios']['rotation_deg']:.1f}× |"
        )
    return lines


def _accuracy(rep: dict) -> list[str]:
    if not rep.get("accuracy"):
        return []
    lines = [
        "",
        "## Accuracy at p1 (Fig. 8)",
        "",
        "| runs | n | translation mean ± std | rotation mean ± std |",
        "|---|---|---|---|",
    ]
    for k, g in rep["accuracy"].items():
        t, r = np.array(g["translation_m"]), np.array(g["rotation_deg"])
        lines.append(
            f"| {k} | {len(t)} | {_mm(t.mean())} ± {_mm(sample_std(t))} | "
            f"{r.mean():.3f}° ± {sample_std(r):.3f}° |"
        )
    return lines


def _spread(rep: dict) -> list[str]:
    """Repeatability per controller, with each per-run source switched off, and other goals."""
    sp = rep.get("spread", {})
    if not sp:
        return []
    profile = rep.get("realism", {}).get("profile", "ideal")
    lines = [
        "",
        "## Repeatability and its sources",
        "",
        f"Realism profile `{profile}`. Final error at p1 (open loop at the end of p0 → p1, PBVS "
        "with control in the loop at convergence); *share* is the part of the variance that "
        "disappears when that source is switched off (1 − Var without / Var all).",
        "",
        "| controller | runs | n | translation mean ± std | rotation mean ± std | share |",
        "|---|---|---|---|---|---|",
    ]
    for kind, groups in sp.items():
        for name, st in groups.items():
            share = st.get("variance_share_translation_m")
            lines.append(
                f"| {kind} | {name} | {st['n']} | {_mm(st['mean_translation_m'])} ± "
                f"{st['std_translation_m'] * 1e6:.1f} µm | {st['mean_rotation_deg']:.3f}° ± "
                f"{st['std_rotation_deg']:.4f}° | "
                f"{'—' if share is None else f'{share * 100:.0f} %'} |"
            )
    return lines


def _estimator_table(rep: dict) -> list[str]:
    """Each estimator's deviation from the truth in both controllers, and the cable effects."""
    ol = rep.get("open_loop", {})
    est, pb = ol.get("estimators", {}), rep.get("pbvs", {})
    if not est and not pb:
        return []
    lines = [
        "",
        "## Each estimator against the truth",
        "",
        "Open loop: passive, over the seed-1 run. PBVS: the estimator in the loop, over its "
        "seed-1 run (max), and passive beside control in the loop (RMS).",
        "",
        "| estimator | open loop max | open loop RMS | PBVS in the loop: max | PBVS passive: RMS |",
        "|---|---|---|---|---|",
    ]
    passive = pb.get("control", {}).get("others_rms", {})
    for n in dict.fromkeys([*est, *pb]):
        cells = [
            f"{_mm(v['max_translation_m'])} / {v['max_rotation_deg']:.2f}°" if v else "—"
            for v in (est.get(n), pb.get(n))
        ]
        rms = [
            f"{_mm(v['rms_translation_m'])} / {v['rms_rotation_deg']:.2f}°" if v else "—"
            for v in (est.get(n), passive.get(n))
        ]
        lines.append(f"| {n} | {cells[0]} | {rms[0]} | {cells[1]} | {rms[1]} |")
    return lines + _cable_effects(ol.get("model_variants"), rep.get("robot", {}))


def _cable_effects(mv: dict | None, robot: dict) -> list[str]:
    """Stretch, pulley wrap and sag along the open-loop run, in metres."""
    if not mv:
        return []
    sag = mv.get("max_sag_m", float("nan"))
    how = "in the physics" if robot.get("sag_simulated") else "if the cables had their mass"
    return [
        "",
        f"Cable effects along the open-loop run (payload "
        f"{robot.get('payload_kg', {}).get('open_loop', 0.0):g} kg): "
        f"stretch τ·l/(E·S) ≤ {mv['max_stretch_m']:.3g} m; pulley wrap l_pulley − l_straight "
        f"{mv['wrap_min_m']:.3g}–{mv['wrap_max_m']:.3g} m (changes by ≤ "
        f"{mv['wrap_change_max_m']:.3g} m); mid-span sag ({how}, Irvine's catenary at the "
        f"measured tension) ≤ {sag:.3g} m" + _excess(mv) + ".",
    ]


def _excess(mv: dict) -> str:
    excess = mv.get("max_sag_excess_m")
    return "" if excess is None else f", its arc longer than the chord by ≤ {excess:.3g} m"


def _error_budget(rep: dict) -> list[str]:
    """Where the error budget of ACROBOT's realism effects is (written by its own command).

    Only for a study run with one of ACROBOT's realism profiles: the budget is that robot's.
    """
    if not str(rep.get("realism", {}).get("profile", "ideal")).startswith("acrobot"):
        return []
    return [
        "",
        "## Error budget",
        "",
        "What each effect of the fullest realism profile (`acrobot_full`: drives, optics, cables",
        "and pulleys as they are) does to each estimator, alone, all together and none, over",
        "robots built to the same tolerances, with the PBVS repeatability of the fullest",
        "profile: [docs/error_budget/budget.md](error_budget/budget.md)",
        "(`python benchmarks/error_budget.py`).",
    ]


def write_report(out: Path, rep: dict, figures: list[Path], wall_time_s: float) -> Path:
    """``report.md``: the paper's numbers beside the twin's, and the findings with verdicts.

    Written whole (``report.md.partial``, then renamed), after everything else of the study.
    With the population's numbers (``rep["population"]``), the verdicts are the criteria's
    over them (:mod:`.population_report`); the single robot's findings follow as an
    illustration, without verdicts.

    Raises:
        OutputError: it cannot be written (it is left ``*.partial``).
    """
    lines = [*_intro(rep, wall_time_s)]
    if "population" in rep:
        from cdpr_twin.study.population_report import population_markdown

        scenario = rep["population"].get("scenario")
        lines += [*population_markdown(rep["population"], scenario), "", *_illustration(rep)]
    else:
        lines += _findings(rep)
    lines += [*_paper_table(rep), *_accuracy(rep)]
    lines += _estimator_table(rep) + _spread(rep) + _error_budget(rep)
    lines += ["", "## Figures", ""] + [f"![{p.stem}]({p.name})" for p in figures]
    return write_atomic(out / "report.md", "\n".join(lines) + "\n")


def rerender(out: Path, rep: dict, wall_time_s: float) -> Path:
    """Re-evaluate the findings of stored report numbers and rewrite ``report.md`` beside them.

    For an explanation changed after the runs: the numbers stay, the findings in
    ``report.json`` are rewritten with their new texts; the figures already in ``out`` are
    listed again.
    """
    from cdpr_twin.study.findings import evaluate

    rep = {**rep, "findings": evaluate({k: v for k, v in rep.items() if k != "findings"})}
    write_json_atomic(out / "report.json", rep)  # the findings' texts, as report.md now says them
    figures = [out / f"{n}.png" for n in FIGURES if (out / f"{n}.png").is_file()]
    return write_report(out, rep, figures, wall_time_s)
