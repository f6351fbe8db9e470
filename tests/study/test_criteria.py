"""The pre-registered criteria: every rule can give each verdict, and only the file sets them.

The thresholds are pinned here (:data:`PINNED`), copied by hand from the paper's numbers the
file's comments give: changing one in ``criteria.toml`` fails
:func:`test_verdicts_follow_the_pinned_thresholds`, which the mutation test checks on a copy.
"""

from __future__ import annotations

import ast
import inspect
import json
import math
import re
import textwrap

import numpy as np
import pytest

from cdpr_twin.study import criteria, findings, population, population_report, report
from cdpr_twin.study.criteria import (
    AGREES,
    CRITERIA_FILE,
    DISAGREES,
    INCONCLUSIVE,
    NEEDS_POPULATION,
    NOT_JUDGED,
    CriteriaError,
    judge,
    load_criteria,
    share_interval,
)

PINNED = {
    # id: (low, high) of "holds" for one robot; None: no bound
    "open_loop_miss": (0.005, 0.02),  # ≈ 1 cm, within ×2
    "estimates_follow_plan": (None, 0.25),
    "image_noisiest_open_loop": (1.0, None),
    "image_noisiest_pbvs": (1.0, None),
    "image_noise_distance": (1.0, None),
    "image_accuracy_distance": (1.0, None),
    "model_variants_agree": (None, 0.1),
    "model_better_open_loop": (0.5, 1.0),
    "control_best_pbvs": (None, 1.0),
    "pbvs_accuracy_translation": (2.5, 10.0),  # 5×, within ×2
    "pbvs_accuracy_rotation": (2.0, 8.0),  # 4×, within ×2
    "fused_beats_open_loop_translation": (1.0, None),
    "fused_beats_open_loop_rotation": (1.0, None),
    "fused_beats_pbvs_translation": (1.0, None),
    "fused_beats_pbvs_rotation": (1.0, None),
    "fused_consistent": (0.8, 1.0),
}
N = 50
"""Robots of a synthetic population (the study's)."""


EDGE = 1e-9
"""How far beside a bound the probes sit (relative): any change of a threshold moves one."""


def _probes(low: float, high: float) -> tuple[list[float], list[float]]:
    """Metric values just inside and just outside each finite bound (inside: it holds)."""
    inside, outside = [], []
    for bound, sign in ((low, 1.0), (high, -1.0)):
        if math.isfinite(bound):
            step = EDGE * max(abs(bound), 1.0)
            inside.append(bound + sign * step)
            outside.append(bound - sign * step)
    return inside, outside


def _check(path) -> None:
    """Each pinned rule of ``path`` gives agrees, disagrees and inconclusive as pinned."""
    rules = load_criteria(path)
    for rid, (low, high) in PINNED.items():
        low = -math.inf if low is None else low
        high = math.inf if high is None else high
        rule = rules[rid]
        inside, outside = _probes(low, high)
        for v in inside:
            assert judge(rule, [v] * N).verdict == AGREES, (rid, v)
        for v in outside:
            assert judge(rule, [v] * N).verdict == DISAGREES, (rid, v)
            # half the robots: the interval of 25/50 is about [0.36, 0.64], across 0.5
            assert judge(rule, [inside[0], v] * (N // 2)).verdict == INCONCLUSIVE, (rid, v)


def test_verdicts_follow_the_pinned_thresholds():
    _check(CRITERIA_FILE)


SHARE_BOUNDS = {"agrees_above": 0.5, "disagrees_below": 0.5, "confidence": 0.95}
"""The verdict's bounds on the share of robots, and the intervals' level, as pinned."""


def _pinned_verdict(k: int, n: int) -> str:
    """The verdict of k robots of n holding, from SciPy's beta quantiles (Clopper–Pearson)."""
    from scipy.stats import beta

    alpha = 1.0 - SHARE_BOUNDS["confidence"]
    low = beta.ppf(alpha / 2, k, n - k + 1) if k > 0 else 0.0
    high = beta.ppf(1 - alpha / 2, k + 1, n - k) if k < n else 1.0
    if low > SHARE_BOUNDS["agrees_above"]:
        return AGREES
    if high < SHARE_BOUNDS["disagrees_below"]:
        return DISAGREES
    return INCONCLUSIVE


def _check_shares(path) -> None:
    """Every judged rule of ``path`` turns k of 50 robots into the pinned verdict, k = 0…50.

    At 95 % and 0.5 the verdict turns at 33/50 (lower bound 0.512; 32/50: 0.492) and 17/50:
    any change of ``agrees_above``, ``disagrees_below`` or ``confidence`` moves a turn.
    """
    for rule in load_criteria(path).values():
        if not rule.judged:
            continue
        low, high = PINNED[rule.id]
        low = -math.inf if low is None else low
        high = math.inf if high is None else high
        (inside, *_), (outside, *_) = _probes(low, high)
        for k in range(N + 1):
            verdict = judge(rule, [inside] * k + [outside] * (N - k)).verdict
            assert verdict == _pinned_verdict(k, N), (rule.id, k)


def test_verdicts_follow_the_pinned_share_bounds():
    _check_shares(CRITERIA_FILE)


@pytest.mark.parametrize(
    ("field", "new"), [("agrees_above", "0.75"), ("disagrees_below", "0.25"), ("confidence", "0.8")]
)
def test_a_changed_share_bound_fails_the_pinned_test(tmp_path, field, new):
    text = CRITERIA_FILE.read_text(encoding="utf-8")
    changed = re.sub(rf"\n{field} = [0-9.]+", f"\n{field} = {new}", text, count=1)
    assert changed != text
    mutant = tmp_path / "criteria.toml"
    mutant.write_text(changed, encoding="utf-8")
    with pytest.raises(AssertionError):
        _check_shares(mutant)


def test_every_judged_rule_is_pinned():
    judged = {r.id for r in load_criteria().values() if r.judged}
    assert judged == set(PINNED)


@pytest.mark.parametrize(
    ("rid", "field", "new"),
    [("open_loop_miss", "high", 0.008), ("pbvs_accuracy_translation", "low", 4.0)],
)
def test_a_changed_threshold_fails_the_pinned_test(tmp_path, rid, field, new):
    text = CRITERIA_FILE.read_text(encoding="utf-8")
    entry = re.search(rf'id = "{rid}"\n(.*?)\n\n', text, re.S)
    changed = re.sub(rf"\n{field} = [0-9.]+", f"\n{field} = {new}", entry.group(0), count=1)
    assert changed != entry.group(0)
    mutant = tmp_path / "criteria.toml"
    mutant.write_text(text.replace(entry.group(0), changed), encoding="utf-8")
    with pytest.raises(AssertionError):
        _check(mutant)


def test_unjudged_finding_has_no_verdict():
    rule = load_criteria()["repeatability"]
    assert judge(rule, [1.0] * N).verdict == NOT_JUDGED
    assert rule.reason


def test_share_interval_is_clopper_pearson():
    # all or none of n robots: the exact interval's open end is (α/2)^(1/n) in closed form
    alpha = 0.05
    low, high = share_interval(N, N, 1 - alpha)
    assert high == pytest.approx(1.0) and low == pytest.approx((alpha / 2) ** (1 / N))
    low, high = share_interval(0, N, 1 - alpha)
    assert low == pytest.approx(0.0) and high == pytest.approx(1 - (alpha / 2) ** (1 / N))


def test_missing_values_are_not_robots():
    rule = load_criteria()["open_loop_miss"]
    v = judge(rule, [0.01] * 10 + [math.nan] * 5)
    assert (v.n, v.k, v.missing) == (10, 10, 5)


def test_bad_entry_is_one_line_naming_the_field(tmp_path):
    bad = tmp_path / "c.toml"
    bad.write_text(
        "[defaults]\nconfidence = 0.95\nagrees_above = 0.5\ndisagrees_below = 0.5\n"
        '[[finding]]\nid = "x"\nclaim = "c"\npaper = "p"\nmetric = "m"\npopulation = "b"\n'
        "low = 2.0\nhigh = 1.0\n",
        encoding="utf-8",
    )
    with pytest.raises(CriteriaError, match=r"finding 'x'\.high: must be ≥ low") as exc:
        load_criteria(bad)
    assert "\n" not in str(exc.value)


VERDICT_MODULES = (criteria, findings, population, population_report, report)
"""Every module that turns metrics into verdicts, or writes a verdict into a report."""
ALLOWED = {
    # the criteria file's own shares and confidence are probabilities: checked to lie in [0, 1]
    "0.0 <= v <= 1.0",
    "0.0 < shares['confidence'] < 1.0",
    # whether a variance share's interval includes 0 (said beside the share, no verdict)
    "low <= 0.0 <= high",
    # the chosen illustration robot is found by its truth seed (an id, not a metric)
    "run['truth_seed'] == ILLUSTRATION_ROBOT",
}
"""Comparisons with a number that are no threshold of a finding (exact source text)."""


def _is_count(node: ast.AST) -> bool:
    """``len(...)``: a comparison of a count of samples, not of a metric."""
    return isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "len"


def _numbers_in(node: ast.AST, names: set[str]) -> bool:
    """Whether a number (literal, or module-level numeric name) is in ``node``, indices aside."""
    if isinstance(node, ast.Subscript):
        return _numbers_in(node.value, names)
    if isinstance(node, ast.Constant):
        return isinstance(node.value, int | float) and not isinstance(node.value, bool)
    if isinstance(node, ast.Name):
        return node.id in names
    return any(_numbers_in(child, names) for child in ast.iter_child_nodes(node))


def _thresholds(source: str, names: set[str]) -> list[str]:
    """The comparisons of ``source`` that hold a number of their own (but :data:`ALLOWED`)."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.Compare):
            continue
        operands = [node.left, *node.comparators]
        if any(_is_count(o) for o in operands) or ast.unparse(node) in ALLOWED:
            continue
        if any(_numbers_in(o, names) for o in operands):
            found.append(ast.unparse(node))
    return found


def _module_numbers(module) -> set[str]:
    return {
        k for k, v in vars(module).items() if isinstance(v, int | float) and not isinstance(v, bool)
    }


def test_the_threshold_scan_finds_hard_coded_thresholds():
    source = textwrap.dedent(
        """
        LIMIT = 3.0
        def verdict(ratio, worst, miss, d, x):
            a = ratio > 1.0
            b = worst < 0.25 * miss["translation_m"]
            c = x >= LIMIT
            e = 0.005 <= d <= 0.02
            return len(x) < 3, x[-1] == d, a, b, c, e
        """
    )
    assert _thresholds(source, {"LIMIT"}) == [
        "ratio > 1.0",
        "worst < 0.25 * miss['translation_m']",
        "x >= LIMIT",
        "0.005 <= d <= 0.02",
    ]


@pytest.mark.parametrize("module", VERDICT_MODULES, ids=lambda m: m.__name__)
def test_verdict_code_holds_no_threshold_of_its_own(module):
    found = _thresholds(inspect.getsource(module), _module_numbers(module))
    assert not found, f"{module.__name__}: a number in a comparison: {found}"


def test_no_verdict_is_written_as_a_literal():
    words = {AGREES, DISAGREES, INCONCLUSIVE, NOT_JUDGED, NEEDS_POPULATION}
    for module in VERDICT_MODULES:
        tree = ast.parse(inspect.getsource(module))
        for fn in (n for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)):
            for node in ast.walk(fn):
                assert not (isinstance(node, ast.Constant) and node.value in words), (
                    f"{module.__name__}.{fn.name}: the verdict {node.value!r} as a literal"
                )


def _robot_numbers() -> dict:
    """A robot's report numbers: it misses p1 by 10.9 mm, PBVS is 3.4× / 0.19× as accurate."""
    return {
        "open_loop": {"miss_at_p1": {"translation_m": 0.0109, "rotation_deg": 0.2, "time_s": 10}},
        "ratios": {"translation_m": 3.4, "rotation_deg": 0.19},
    }


def test_one_robot_gets_no_verdict_and_its_conditions_come_from_the_file(tmp_path):
    found = {f["finding"]: f for f in findings.evaluate(_robot_numbers())}
    assert {f["verdict"] for f in found.values()} == {NEEDS_POPULATION}
    miss = found["open-loop error at p1 ≈ 1 cm"]
    rot = found["PBVS more accurate than open loop at p1 (rotation)"]
    assert (
        "`open_loop_miss`: 0.005 ≤ open_loop_miss_m ≤ 0.02; holds on this robot"
        in miss["criterion"]
    )
    assert "does not hold on this robot" in rot["criterion"]
    # the file's bound moved below the robot's 10.9 mm: the robot's condition follows it
    text = CRITERIA_FILE.read_text(encoding="utf-8")
    mutant = tmp_path / "criteria.toml"
    mutant.write_text(text.replace("low = 0.005\nhigh = 0.02", "low = 0.005\nhigh = 0.01"))
    moved = findings.evaluate(_robot_numbers(), criteria=load_criteria(mutant))
    assert "0.005 ≤ open_loop_miss_m ≤ 0.01; does not hold on this robot" in moved[0]["criterion"]


def test_vector_roughness_sees_what_the_norm_misses():
    from cdpr_twin.recording.timeseries import Timeseries

    # the image estimate jumps ±a along x about the truth: |deviation| stays a (a norm-based
    # roughness sees 0), the deviation vector changes by 2a every tick
    a, k = 0.002, 11
    cols = {"t": np.arange(k) * 0.04}
    for name, x in (("true", np.zeros(k)), ("image", a * (-1.0) ** np.arange(k))):
        cols |= {f"{name}_x": x, f"{name}_y": np.zeros(k), f"{name}_z": np.zeros(k)}
        cols |= {f"{name}_qw": np.ones(k)} | {f"{name}_q{c}": np.zeros(k) for c in "xyz"}
    ts = Timeseries(cols, np.array([""] * k), np.array([""] * k))
    assert population.vector_roughness(ts, "image") == pytest.approx(2 * a, rel=1e-12)


def test_nees_of_errors_drawn_from_the_covariance_is_chi2():
    from scipy.stats import chi2

    from cdpr_twin.math.se3 import quat_wxyz_from_matrix, se3_exp
    from cdpr_twin.recording.timeseries import COV_INDEX, Timeseries, covariance_columns

    rng = np.random.default_rng(3)
    k = 400
    A = rng.normal(size=(6, 6)) * 1e-3
    P = A @ A.T + np.diag([1e-6] * 3 + [1e-5] * 3)
    delta = rng.multivariate_normal(np.zeros(6), P, size=k)
    # the estimate is the truth moved by exp(-δ): log(T̂⁻¹ T) = δ
    T = np.array([se3_exp(-d) for d in delta])
    cols = {"t": np.arange(k) * 0.04}
    for name, poses in (("true", np.tile(np.eye(4), (k, 1, 1))), ("fused", T)):
        q = np.array([quat_wxyz_from_matrix(p[:3, :3]) for p in poses])
        cols |= {f"{name}_{c}": poses[:, i, 3] for i, c in enumerate("xyz")}
        cols |= {f"{name}_q{c}": q[:, i] for i, c in enumerate("wxyz")}
    cov = zip(COV_INDEX, covariance_columns("fused"), strict=True)
    cols |= {c: np.full(k, P[i, j]) for (i, j), c in cov}
    ts = Timeseries(cols, np.array([""] * k), np.array([""] * k))
    eps, axes = population.nees(ts)
    # the mean of k χ²(6) draws: within its own 99.9 % interval
    lo, hi = chi2.ppf([0.0005, 0.9995], 6 * k) / k
    assert lo < eps.mean() < hi
    assert np.allclose(axes.mean(axis=0), 1.0, atol=0.25)


def _run(seed: int, x: float | None) -> dict:
    return {"truth_seed": seed, "seed": 0, "ok": True, "open_loop_miss_m": x}


def test_repeatability_shares_and_spread_have_intervals_around_the_truth():
    # two normal samples with variances 4σ² and σ²: the source's true share is 3/4, the std 2σ
    rng = np.random.default_rng(5)
    sigma = 1e-4
    blocks = {
        "repeat_open_loop": [_run(1, x) for x in rng.normal(0.01, 2 * sigma, 30)],
        "repeat_open_loop_without_homing": [_run(1, x) for x in rng.normal(0.01, sigma, 30)],
    }
    (row,) = [r for r in population.repeatability(blocks, 0.95) if r["quantity"].endswith("_m")]
    low, high = row["std_ci"]
    assert low < 2 * sigma < high and high - low < 2 * sigma
    _, (low, high), n = row["shares"]["homing"]
    assert n == 30 and low < 0.75 < high and low > 0.0


def test_verdict_cell_names_population_share_interval_and_entry():
    rules = load_criteria()
    rule = rules["open_loop_miss"]
    runs = [_run(i, 0.01 if i % 5 else 0.03) for i in range(50)]
    verdict = judge(rule, population.values(runs, rule.metric))
    pop = {"blocks": {rule.population: runs}, "verdicts": [verdict]}
    (row,) = [ln for ln in population_report.verdict_table(pop, {}) if "`open_loop_miss`" in ln]
    low, high = verdict.interval
    assert f"`{rule.population}` (50 robots)" in row
    assert f"40/50 = 80 % [{low * 100:.0f}, {high * 100:.0f}] %" in row
    assert f"**{verdict.verdict}**" in row and rule.paper in row


def test_open_loop_metrics_from_a_summary(tmp_path):
    # the plan-following ratio leaves the image estimate out (the paper's claim is of the
    # control and model estimates); fused's gain is the best other RMS over its own
    def est(rms_t, rms_r):
        return {"rms_translation_m": rms_t, "rms_rotation_deg": rms_r, "max_translation_m": 0.01}

    summary = {
        "estimators": {
            "control": est(0.004, 0.3),
            "image": est(0.006, 0.9),
            "model_simple": est(0.0036, 0.35),
            "fused": est(0.002, 0.4),
        },
        "segment_ends": [
            {
                "truth_vs_waypoint": {"translation_m": 0.01, "rotation_deg": 0.5},
                "estimates_vs_plan": {
                    "control": {"translation_m": 1e-8},
                    "image": {"translation_m": 0.02},
                    "model_simple": {"translation_m": 0.002},
                    "fused": {"translation_m": 0.009},
                },
            }
        ],
    }
    (tmp_path / "summary.json").write_text(json.dumps(summary))
    m = population.open_loop_metrics(tmp_path, 0.95, whole_run=False)
    assert m["open_loop_miss_m"] == 0.01 and m["open_loop_miss_deg"] == 0.5
    assert m["follow_plan_ratio"] == pytest.approx(0.002 / 0.01)
    assert m["model_over_control_rms"] == pytest.approx(0.0036 / 0.004)
    assert m["fused_gain_t"] == pytest.approx(0.0036 / 0.002)
    assert m["fused_gain_r"] == pytest.approx(0.3 / 0.4)


def test_accuracy_ratios_pair_each_robot_with_its_own_open_loop_run():
    blocks = {
        "robots_open_loop": [
            {"truth_seed": 1, "open_loop_miss_m": 0.01, "open_loop_miss_deg": 0.4},
            {"truth_seed": 2, "open_loop_miss_m": 0.004, "open_loop_miss_deg": 2.0},
        ],
        "robots_pbvs": [
            {"truth_seed": 2, "pbvs_error_m": 0.002, "pbvs_error_deg": 1.0},
            {"truth_seed": 1, "pbvs_error_m": 0.001, "pbvs_error_deg": 0.1},
        ],
    }
    population._pair_accuracy(blocks)
    by_seed = {r["truth_seed"]: r for r in blocks["robots_pbvs"]}
    assert by_seed[1]["accuracy_ratio_t"] == pytest.approx(10.0)
    assert by_seed[1]["accuracy_ratio_r"] == pytest.approx(4.0)
    assert by_seed[2]["accuracy_ratio_t"] == pytest.approx(2.0)


def test_a_cell_says_how_many_robots_had_no_value():
    rule = load_criteria()["open_loop_miss"]
    runs = [_run(i, 0.01) for i in range(46)] + [_run(i, None) for i in range(46, 50)]
    verdict = judge(rule, population.values(runs, rule.metric))
    pop = {"blocks": {rule.population: runs}, "verdicts": [verdict]}
    (row,) = [ln for ln in population_report.verdict_table(pop, {}) if "`open_loop_miss`" in ln]
    assert "46/46 = 100 %" in row and "(4 without a value)" in row
