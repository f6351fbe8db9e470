"""The study's pre-registered criteria (``criteria.toml``) and the verdicts they give.

Every threshold of a verdict lives in the criteria file; this module only reads them and
applies them: a metric value holds when ``low ≤ value ≤ high`` (:func:`holds`), a population's
share of robots on which it holds gets its exact 95 % interval (Clopper–Pearson, SciPy's
``binomtest``), and the interval's place against ``agrees_above`` / ``disagrees_below`` gives
the verdict (:func:`judge`).

>>> rules = load_criteria()
>>> judge(rules["open_loop_miss"], values).verdict
'agrees'
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Sequence
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

CRITERIA_FILE = Path(str(resources.files("cdpr_twin.study") / "criteria.toml"))
"""The shipped criteria (package data)."""
AGREES, DISAGREES, INCONCLUSIVE, NOT_JUDGED = "agrees", "disagrees", "inconclusive", "not judged"
"""The verdicts."""
NEEDS_POPULATION = "not judged: needs the population (reproduce --population DIR)"
"""The verdict of a finding on one robot: the criteria judge populations only."""
_FIELDS = {
    "id",
    "claim",
    "paper",
    "metric",
    "population",
    "low",
    "high",
    "holds",
    "sensitivity",
    "judged",
    "reason",
    "agrees_above",
    "disagrees_below",
    "confidence",
}
_NEEDED = ("id", "claim", "paper", "metric", "population")


class CriteriaError(ValueError):
    """The criteria file is invalid (one line: file, entry, field, fix)."""


@dataclass(frozen=True)
class Rule:
    """One finding's criterion.

    Attributes:
        id: the entry's name (``[[finding]] id``).
        claim: the finding in a few words.
        paper: the paper's sentence, quoted.
        metric: the per-robot metric it is judged on.
        population: the campaign block of the robots.
        low: the metric's lower bound for the finding to hold (``-inf``: none).
        high: its upper bound (``inf``: none).
        holds: what "the finding holds" means for one robot, in words.
        agrees_above: the share's interval must lie above this to agree.
        disagrees_below: ... below this to disagree.
        judged: ``False`` for a finding the paper gives nothing to hold to.
        reason: why it is not judged.
        sensitivity: the populations (tolerances changed) its share is also given on.
        confidence: the level of the share's interval (and of every interval the study gives).
    """

    id: str
    claim: str
    paper: str
    metric: str
    population: str
    low: float = -math.inf
    high: float = math.inf
    holds: str = ""
    agrees_above: float = math.nan
    disagrees_below: float = math.nan
    judged: bool = True
    reason: str = ""
    sensitivity: tuple[str, ...] = ()
    confidence: float = math.nan

    def bounds(self) -> str:
        """The per-robot condition as text, e.g. ``0.005 ≤ open_loop_miss_m ≤ 0.02``."""
        low = "" if math.isinf(self.low) else f"{self.low:g} ≤ "
        high = "" if math.isinf(self.high) else f" ≤ {self.high:g}"
        return f"{low}{self.metric}{high}"


@dataclass(frozen=True)
class Verdict:
    """A rule applied to a population.

    Attributes:
        rule: the criterion.
        n: robots with the metric (the others' runs failed or lack it).
        k: robots on which the finding holds.
        share: k / n (NaN without robots).
        interval: the share's exact interval (``rule.confidence``, e.g. 95 %).
        verdict: :data:`AGREES`, :data:`DISAGREES`, :data:`INCONCLUSIVE` or :data:`NOT_JUDGED`.
        median: the metric's median over the robots.
        missing: robots of the population without the metric (a run a fault stopped, or a
            metric undefined on it): in neither ``k`` nor ``n``.
    """

    rule: Rule
    n: int
    k: int
    share: float
    interval: tuple[float, float]
    verdict: str
    median: float
    missing: int = 0


def _number(path: Path, where: str, table: dict, field: str, default: float) -> float:
    value = table.get(field, default)
    if isinstance(value, bool) or not isinstance(value, int | float) or math.isnan(value):
        raise CriteriaError(f"{path}: {where}.{field}: must be a number, got {value!r}")
    return float(value)


def _rule(path: Path, i: int, entry: dict, defaults: dict) -> Rule:
    where = f"finding[{i}]"
    if not isinstance(entry, dict):
        raise CriteriaError(f"{path}: {where}: must be a table [[finding]]")
    if unknown := sorted(set(entry) - _FIELDS):
        raise CriteriaError(f"{path}: {where}.{unknown[0]}: unknown field; use {sorted(_FIELDS)}")
    for field in _NEEDED:
        if not isinstance(entry.get(field), str) or not entry[field]:
            raise CriteriaError(f'{path}: {where}.{field}: missing; give {field} = "..."')
    where = f"finding {entry['id']!r}"
    low = _number(path, where, entry, "low", -math.inf)
    high = _number(path, where, entry, "high", math.inf)
    if not low <= high:
        raise CriteriaError(f"{path}: {where}.high: must be ≥ low = {low:g}, got {high:g}")
    judged = entry.get("judged", True)
    if not isinstance(judged, bool):
        raise CriteriaError(f"{path}: {where}.judged: must be true or false, got {judged!r}")
    if judged and math.isinf(low) and math.isinf(high):
        raise CriteriaError(f"{path}: {where}: give low and/or high (or judged = false)")
    if not judged and not entry.get("reason"):
        raise CriteriaError(f'{path}: {where}.reason: judged = false needs reason = "..."')
    shares = {
        f: _number(path, where, entry, f, _number(path, "defaults", defaults, f, math.nan))
        for f in ("agrees_above", "disagrees_below", "confidence")
    }
    for f in ("agrees_above", "disagrees_below"):
        v = shares[f]
        if not 0.0 <= v <= 1.0:
            raise CriteriaError(f"{path}: {where}.{f}: must be a share in [0, 1], got {v:g}")
    if not 0.0 < shares["confidence"] < 1.0:
        raise CriteriaError(f"{path}: {where}.confidence: must be in (0, 1), e.g. 0.95")
    if shares["disagrees_below"] > shares["agrees_above"]:
        raise CriteriaError(f"{path}: {where}.disagrees_below: must be ≤ agrees_above")
    sensitivity = entry.get("sensitivity", [])
    if not isinstance(sensitivity, list) or not all(isinstance(s, str) for s in sensitivity):
        raise CriteriaError(f'{path}: {where}.sensitivity: must be a list of block names ["…"]')
    return Rule(
        entry["id"],
        entry["claim"],
        entry["paper"],
        entry["metric"],
        entry["population"],
        low,
        high,
        str(entry.get("holds", "")),
        shares["agrees_above"],
        shares["disagrees_below"],
        judged,
        str(entry.get("reason", "")),
        tuple(sensitivity),
        shares["confidence"],
    )


def load_criteria(path: str | Path = CRITERIA_FILE) -> dict[str, Rule]:
    """The criteria file's rules by id, in file order.

    Raises:
        CriteriaError: the file is missing, not TOML, or an entry is invalid.
    """
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (OSError, tomllib.TOMLDecodeError) as exc:
        raise CriteriaError(f"{path}: cannot read the criteria: {exc}") from None
    defaults = data.get("defaults", {})
    entries = data.get("finding")
    if not isinstance(entries, list) or not entries:
        raise CriteriaError(f"{path}: finding: missing; give one [[finding]] table per finding")
    rules: dict[str, Rule] = {}
    for i, entry in enumerate(entries):
        rule = _rule(path, i, entry, defaults)
        if rule.id in rules:
            raise CriteriaError(f"{path}: finding[{i}].id: {rule.id!r} is used twice")
        rules[rule.id] = rule
    return rules


def holds(rule: Rule, values: Sequence[float]) -> np.ndarray:
    """Whether the finding holds on each robot: ``low ≤ value ≤ high`` (NaN: no value)."""
    v = np.asarray(values, dtype=float)
    return (v >= rule.low) & (v <= rule.high)


def share_interval(k: int, n: int, confidence: float) -> tuple[float, float]:
    """The exact (Clopper–Pearson) interval of a share k / n; (0, 1) without robots."""
    from scipy.stats import binomtest

    if not n:
        return (0.0, 1.0)
    ci = binomtest(k, n).proportion_ci(confidence_level=confidence, method="exact")
    return (float(ci.low), float(ci.high))


def judge(rule: Rule, values: Sequence[float] | np.ndarray) -> Verdict:
    """The verdict of a rule over a population's metric values (one per robot; NaN: none)."""
    v = np.asarray(values, dtype=float)
    missing = int(np.count_nonzero(np.isnan(v)))
    v = v[~np.isnan(v)]
    n = len(v)
    k = int(np.count_nonzero(holds(rule, v)))
    low, high = share_interval(k, n, rule.confidence)
    median = float(np.median(v)) if n else math.nan
    share = k / n if n else math.nan
    if not rule.judged:
        verdict = NOT_JUDGED
    elif low > rule.agrees_above:
        verdict = AGREES
    elif high < rule.disagrees_below:
        verdict = DISAGREES
    else:
        verdict = INCONCLUSIVE
    return Verdict(rule, n, k, share, (low, high), verdict, median, missing)
