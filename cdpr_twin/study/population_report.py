"""The population's sections of ``report.md``: verdicts, sensitivity, repeatability, NEES.

Every verdict cell names its population, the share of robots on which the finding holds with
its interval, and its entry of the criteria file; the words come from the criteria file.
"""

from __future__ import annotations

import math

from cdpr_twin.study.criteria import Verdict

TOLERANCE_BLOCKS = {"tolerances_half": "×0.5", "tolerances_double": "×2"}
"""The sensitivity populations: every tolerance of ``[truth]`` scaled."""
PROFILE_BLOCK = "profile_full"
"""The sensitivity population at the same tolerances with every effect of ``acrobot_full``."""
ENTRY = "cdpr_twin/study/criteria.toml"
"""How the report names the criteria file."""


def _share(v: Verdict) -> str:
    # robots without the metric (a fault stopped the run) are in neither k nor n: say how many
    lacking = f" ({v.missing} without a value)" if v.missing else ""
    if not v.n:
        return "no robots" + lacking
    low, high = v.interval
    return f"{v.k}/{v.n} = {v.share * 100:.0f} % [{low * 100:.0f}, {high * 100:.0f}] %{lacking}"


def _number(x: float) -> str:
    return "—" if not math.isfinite(x) else f"{x:.3g}"


def _population(block: str, blocks: dict) -> str:
    runs = blocks.get(block, [])
    robots = len({r["truth_seed"] for r in runs})
    return f"`{block}` ({robots} robots)"


def _convergence(blocks: dict) -> list[str]:
    """How many PBVS runs converged (the others end at the time limit, still counted)."""
    runs = [r for b, rs in blocks.items() if "pbvs" in b for r in rs if "converged" in r]
    if not runs:
        return []
    k = sum(bool(r["converged"]) for r in runs)
    return [
        f"PBVS runs: {k} of {len(runs)} converged; a run that did not is judged on its pose "
        "at the time limit.",
        "",
    ]


def verdict_table(pop: dict, illustration: dict) -> list[str]:
    """The findings, each judged over its population by its criteria entry."""
    blocks = pop["blocks"]
    lines = [
        "## Findings over populations of robots",
        "",
        "Each finding is judged over robots drawn to the tolerances, each with its own homing "
        "offset and sensor noise (`campaigns/paper_population.toml`), by the rule of its entry "
        f"in `{ENTRY}`, fixed before these results: *holds* is what the finding means for one "
        "robot; *share* the robots on which it holds, with its exact 95 % interval "
        "(Clopper–Pearson); the verdict is **agrees** when the whole interval lies above the "
        "entry's `agrees_above`, **disagrees** when it lies below `disagrees_below`, "
        "**inconclusive** otherwise. A robot without a value (its run stopped by a fault, such "
        "as fewer than six taut cables, or the metric undefined on it) counts in neither the "
        "share nor its robots; the cell says how many. *Robot 19* is the study's illustration "
        "robot (chosen, for its ≈ 1 cm miss): its value and its percentile in the population.",
        "",
        *_convergence(blocks),
        "| finding | paper | population | holds on one robot | share [95 %] | median | verdict |"
        " robot 19 (percentile) | entry |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for v in pop["verdicts"]:
        r = v.rule
        ill = illustration.get(r.id)
        ill_text = "—" if ill is None else f"{_number(ill[0])} (percentile {ill[1]:.0f})"
        holds = r.reason if not r.judged else f"{r.holds} (`{r.bounds()}`)"
        lines.append(
            f"| {r.claim} | “{r.paper}” | {_population(r.population, blocks)} | {holds} | "
            f"{_share(v) if r.judged else '—'} | {_number(v.median)} | **{v.verdict}** | "
            f"{ill_text} | `{r.id}` |"
        )
    return lines


def sensitivity_table(pop: dict) -> list[str]:
    """Each finding's share with every tolerance halved and doubled, and under ``acrobot_full``."""
    if not pop["sensitivity"]:
        return []
    base = {v.rule.id: v for v in pop["verdicts"]}
    rows: dict[str, dict[str, Verdict]] = {}
    for rule, block, v in pop["sensitivity"]:
        rows.setdefault(rule.id, {})[block] = v
    lines = [
        "",
        "## Sensitivity to the tolerances and to the truth's physics",
        "",
        "The same rule over 50 robots drawn with every tolerance of `[truth]` halved, and "
        "doubled (E·S's 10 % stays: the loader refuses 20 %, which could make a cable's E·S "
        "negative); and over the 50 robots of ×1 with every effect of the `acrobot_full` "
        "profile (ropes, sheaves and swivels with friction, grooved drums, backlash, motor "
        "friction, homing per drum). Open-loop findings only: those populations run without the "
        "camera (an open-loop motion does not use it); the PBVS and camera findings were not "
        "rerun at other tolerances or with `acrobot_full`.",
        "",
        "| finding | ×0.5 | ×1 | ×2 | ×1, `acrobot_full` |",
        "|---|---|---|---|---|",
    ]
    for rid, by_block in rows.items():
        cells = [
            f"{_share(by_block[b])} **{by_block[b].verdict}**" if b in by_block else "—"
            for b in (*TOLERANCE_BLOCKS, PROFILE_BLOCK)
        ]
        main = f"{_share(base[rid])} **{base[rid].verdict}**"
        lines.append(f"| {base[rid].rule.claim} | {cells[0]} | {main} | {cells[1]} | {cells[2]} |")
    return lines


def _mm_or_deg(quantity: str, x: float) -> str:
    return f"{x * 1e3:.3f} mm" if quantity.endswith("_m") else f"{x:.4f}°"


def repeatability_table(pop: dict) -> list[str]:
    """The spread over repetitions per robot, and each per-run source's share of its variance."""
    rows = pop["repeatability"]
    if not rows:
        return []
    lines = [
        "",
        "## Repeatability and its sources",
        "",
        "30 repetitions on each of a few robots (truth seeds fixed before the runs), each with "
        "its own run seed (homing offset, noise). Final error at p1: open loop at the end of "
        "p0 → p1, PBVS (control in the loop, converged runs) at convergence. The spread is the "
        "sample standard deviation with its 95 % bootstrap interval (BCa, SciPy); a source's "
        "*share* is 1 − Var(without it) / Var(all), from 30 more runs with that source off, "
        "its 95 % interval a two-sample bootstrap. A share whose interval includes 0 is not "
        "told apart from no effect (marked *includes 0*). Open-loop repetitions run without "
        "the camera, which changes nothing of an open-loop motion: pixel noise has no share "
        "there by construction.",
        "",
        "| controller | robot | quantity | n | mean | std [95 %] | shares [95 %] |",
        "|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        q = r["quantity"]
        shares = []
        for source, (s, (low, high), _n) in r["shares"].items():
            # report.json stores NaN as null
            low, high = (math.nan if v is None else v for v in (low, high))
            if not (math.isfinite(low) and math.isfinite(high)):
                # no interval: without the source every run ends in the same pose
                shares.append(f"{source} {s * 100:.0f} % (no spread left without it)")
                continue
            zero = ", *includes 0*" if low <= 0.0 <= high else ""
            shares.append(f"{source} {s * 100:.0f} % [{low * 100:.0f}, {high * 100:.0f}]{zero}")
        lo, hi = r["std_ci"]
        lines.append(
            f"| {r['controller']} | {r['truth_seed']} | "
            f"{'translation' if q.endswith('_m') else 'rotation'} | {r['n']} | "
            f"{_mm_or_deg(q, r['mean'])} | {_mm_or_deg(q, r['std'])} "
            f"[{_mm_or_deg(q, lo)}, {_mm_or_deg(q, hi)}] | {'; '.join(shares) or '—'} |"
        )
    return lines


AXES = ("x", "y", "z", "rx", "ry", "rz")


def nees_section(pop: dict) -> list[str]:
    """The fused filter's consistency over the open-loop population (camera on, deviated robots)."""
    n = pop.get("nees")
    if not n:
        return []
    low, high = n["bounds"]
    axes = ", ".join(f"{a} {v:.2f}" for a, v in zip(AXES, n["axes"], strict=True))
    return [
        "",
        "## fused's consistency where it is used",
        "",
        f"NEES of `fused` over {n['runs']} open-loop runs (p0 → p1, {n['ticks']} ticks each), "
        "camera on, the acrobot profile, each robot with its own deviations, homing and noise. "
        f"The average ε̄ over the runs lies inside its 95 % interval [{low:.2f}, {high:.2f}] "
        f"(χ²(6N)/N) at {n['inside'] * 100:.0f} % of the ticks, above it at "
        f"{n['above'] * 100:.0f} % (errors larger than the filter believes), below at "
        f"{n['below'] * 100:.0f} % (smaller); the mean ε is {n['mean']:.2f} against 6 for a "
        f"consistent filter. Each axis's mean δ²/σ² (1 when consistent; F_p, m and rad): "
        f"{axes}: above 1 the filter is overconfident on that axis (its errors exceed its "
        "σ), below 1 cautious.",
    ]


TOLERANCES = (
    # (field of [truth], label, unit, scale to the unit, the assumption's basis)
    (
        "exit_point_std",
        "exit points, per axis",
        "mm",
        1e3,
        "frame assembly and pulley mounts; "
        "chosen with the paper's ≈ 1 cm miss in view, so the open-loop-miss finding leans on it",
    ),
    ("anchor_point_std", "anchor points, per axis", "mm", 1e3, "platform machining"),
    (
        "es_scale_std",
        "E·S, relative",
        "%",
        1e2,
        "Dyneema's modulus varies between batches and with load history",
    ),
    ("pulley_radius_std", "sheave radii", "mm", 1e3, "machining"),
    ("camera_position_std", "camera mount position, per axis", "mm", 1e3, "hand-eye calibration"),
    (
        "camera_rotation_std",
        "camera mount rotation, per axis",
        "°",
        math.degrees(1.0),
        "hand-eye calibration",
    ),
    ("tag_position_std", "tag position, per axis", "mm", 1e3, "a printed tag placed by hand"),
    (
        "tag_rotation_std",
        "tag rotation, per axis",
        "°",
        math.degrees(1.0),
        "a printed tag placed by hand",
    ),
)
"""The robots' tolerances as the report states them (values read from the scenario file)."""


def tolerance_section(scenario: str) -> list[str]:
    """The tolerances the robots are drawn to, stated as the assumptions they are.

    Args:
        scenario: the shipped scenario file's name the robots are drawn from.
    """
    from cdpr_twin import SCENARIOS_DIR
    from cdpr_twin.scenario.loading import load_scenario

    truth = load_scenario(SCENARIOS_DIR / scenario).truth
    lines = [
        "",
        "## The tolerances are assumptions",
        "",
        "The paper gives no tolerance of its robot. The robots are drawn to these standard "
        f"deviations (`[truth]` of `scenarios/{scenario}`), the "
        "twin's assumptions, none from a source that states it for ACROBOT; how much each "
        "verdict leans on them is in *Sensitivity to the tolerances*.",
        "",
        "| tolerance | std | basis (an assumption, no source) |",
        "|---|---|---|",
    ]
    for field, label, unit, scale, basis in TOLERANCES:
        lines.append(f"| {label} | {getattr(truth, field) * scale:g} {unit} | {basis} |")
    return lines


def population_markdown(data: dict, scenario_file=None) -> list[str]:
    """Every population section of ``report.md``, from ``report.json``'s ``population``.

    The verdicts are the criteria file's rules applied to the stored metrics.
    """
    from cdpr_twin.study.calibration_gauge import calibration_section
    from cdpr_twin.study.population import population_from_json

    pop = population_from_json(data)
    lines = population_sections(pop, pop["illustration"], scenario_file)
    if data.get("calibration"):
        confidence = next(iter(pop["rules"].values())).confidence
        lines += calibration_section(data["calibration"], confidence)
    return [*lines, "", f"The criteria: `{ENTRY}`."]


def population_sections(pop: dict, illustration: dict, scenario_file=None) -> list[str]:
    """Every population section of ``report.md`` but the calibration's."""
    lines = verdict_table(pop, illustration)
    if scenario_file is not None:
        lines += tolerance_section(str(scenario_file))
    lines += sensitivity_table(pop) + repeatability_table(pop) + nees_section(pop)
    return lines
