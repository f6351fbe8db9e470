"""Campaign files: a base scenario and the axes to vary → the validated list of runs (tasks).

A campaign file (TOML) names a base scenario and how to vary it::

    name = "pbvs_gain_sweep"
    scenario = "paper_pbvs"                     # a shipped name, or a file relative to this one
    seed = 1                                    # seeds the random draws below
    samples = 1                                 # random draws per grid point
    artefacts = "none"                          # per-run files: "none", "csv" or "all"

    [overrides]                                 # every run: dotted scenario keys
    "sensors.camera" = true

    [[axes]]                                    # a grid axis: every value
    key = "controller.gain"
    values = [0.2, 0.4, 0.8]

    [[axes]]                                    # a random axis: one draw per run
    key = "truth.seed"
    draw = "integers"                           # integers | uniform | normal | choice
    low = 1
    high = 1000000

Grid axes combine as a product (file order); each grid point runs ``samples`` times, each with
its own draws of the random axes (from ``seed``, the block and the point: reproducible). A
campaign of several experiments lists them as ``[[blocks]]``, each with the keys above but
``name``/``seed``. Any scenario key can be varied by its dotted path (``truth.exit_point_std``,
``controller.gain``, ``realism.camera.exposure_s``, ``estimators.in_loop``, ``seed``); a value
may be a table (``key = "controller"`` with whole controller tables). Every run's scenario is
built and validated before any run starts; a bad key is a one-line error naming the campaign
file, the axis and the scenario field.

Each run's id is a hash of its fully resolved scenario (the base file's content with every
override applied), so a campaign can be resumed, and re-running a finished one does nothing.
"""

from __future__ import annotations

import copy
import dataclasses
import itertools
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from cdpr_twin import resources
from cdpr_twin.campaign.keys import as_read, run_id, set_dotted
from cdpr_twin.files.inputs import read_toml

DRAWS = ("integers", "uniform", "normal", "choice")
ARTEFACTS = ("none", "csv", "all")
INT64 = (-(2**63), 2**63 - 1)
"""The integers an axis (its values, its draw's bounds) or an override may give: the results
table's int64."""
MAX_RUNS = 100_000
"""The most runs a campaign may have (grid points × samples, summed over its blocks).

Refused before any run is expanded: each run's resolved scenario is built, validated and kept
in memory (about 7 ms and 50 kB a run), so 100 000 runs take some 12 min and 5 GB to load.
That is seven times the largest study planned (1 000 robots × 7 estimators × 2 controllers:
14 000 runs); a bigger study is several campaigns.
"""


class CampaignError(ValueError):
    """A campaign file is invalid (one line: file, field, fix)."""


@dataclass(frozen=True)
class Task:
    """One run of a campaign.

    Attributes:
        run_id: hash of the resolved scenario (16 hex digits).
        block: the block it belongs to.
        name: readable name (block, then the varied values).
        source: the base scenario file (relative paths in the scenario resolve beside it).
        data: the resolved scenario, as parsed TOML.
        params: the varied values by dotted key (``sample``: the draw's index).
        artefacts: which per-run files to keep (``none``, ``csv``, ``all``).
    """

    run_id: str
    block: str
    name: str
    source: str
    data: dict
    params: dict
    artefacts: str = "none"


@dataclass(frozen=True)
class Campaign:
    """A parsed campaign.

    Attributes:
        name: its name (default: the file's stem).
        source: the campaign file.
        description: free text.
        tasks: every run, validated, in a stable order.
    """

    name: str
    source: Path
    description: str
    tasks: tuple[Task, ...]


def _fail(source: Path, where: str, problem: str) -> CampaignError:
    return CampaignError(f"{source}: {where}: {problem}")


def _beyond_int64(value: Any) -> str:
    """Why an integer in ``value`` (lists and tables searched too) is refused, else ``""``."""
    if isinstance(value, dict | list):
        items = value.values() if isinstance(value, dict) else value
        return next((why for v in items if (why := _beyond_int64(v))), "")
    if isinstance(value, int) and not INT64[0] <= value <= INT64[1]:
        return f"{value} is not a 64-bit integer: use one from {INT64[0]} to {INT64[1]}"
    return ""


def _axis(source: Path, where: str, axis: Any) -> dict:
    if not isinstance(axis, dict) or not isinstance(axis.get("key"), str) or not axis["key"]:
        raise _fail(source, where, 'must be a table with a key = "dotted.scenario.key"')
    known = {"key", "values", "draw", "low", "high", "mean", "std"}
    if unknown := sorted(set(axis) - known):
        raise _fail(source, f"{where}.{unknown[0]}", f"unknown field; use {sorted(known)}")
    for field in ("values", "low", "high", "mean", "std"):
        if why := _beyond_int64(axis.get(field)):
            raise _fail(source, f"{where}.{field} ({axis['key']})", why)
    if ("values" in axis) == ("draw" in axis) and axis.get("draw") != "choice":
        raise _fail(source, where, "give either values = [...] (a grid) or draw = ... (random)")
    if "draw" in axis and axis["draw"] not in DRAWS:
        raise _fail(source, f"{where}.draw", f"must be one of {', '.join(DRAWS)}")
    if "values" in axis and (not isinstance(axis["values"], list) or not axis["values"]):
        raise _fail(source, f"{where}.values", "must be a non-empty list")
    need = {"integers": ("low", "high"), "uniform": ("low", "high"), "normal": ("mean", "std")}
    for field in need.get(axis.get("draw", ""), ()):
        if not isinstance(axis.get(field), int | float) or not math.isfinite(axis[field]):
            raise _fail(source, f"{where}.{field}", "missing, or not a finite number")
    return _check_draw(source, where, axis)


def _check_draw(source: Path, where: str, axis: dict) -> dict:
    """The random draw's parameters, checked (NumPy would raise on them mid-campaign)."""
    draw = axis.get("draw")
    if draw == "choice" and "values" not in axis:
        raise _fail(source, f"{where}.values", 'draw = "choice" needs values = [...]')
    if draw in ("integers", "uniform") and not axis["low"] < axis["high"]:
        raise _fail(source, f"{where}.high", f"must exceed low = {axis['low']}")
    if draw == "uniform" and not math.isfinite(axis["high"] - axis["low"]):
        raise _fail(source, f"{where}.high", "high − low must be a finite number")
    for field in ("low", "high") if draw == "integers" else ():
        v = axis[field]
        if v != int(v) or not INT64[0] <= v <= INT64[1]:
            use = f"must be a 64-bit integer, from {INT64[0]} to {INT64[1]}, got {v!r}"
            raise _fail(source, f"{where}.{field} ({axis['key']})", use)
    if draw == "normal" and not axis["std"] > 0:
        raise _fail(source, f"{where}.std", f"must be > 0, got {axis['std']!r}")
    return axis


def _draw(axis: dict, rng: np.random.Generator) -> Any:
    kind = axis["draw"]
    if kind == "integers":
        return int(rng.integers(int(axis["low"]), int(axis["high"]), endpoint=True))
    if kind == "uniform":
        return float(rng.uniform(axis["low"], axis["high"]))
    if kind == "normal":
        return float(rng.normal(axis["mean"], axis["std"]))
    return copy.deepcopy(axis["values"][int(rng.integers(len(axis["values"])))])


def _label(value: Any) -> str:
    if isinstance(value, dict):
        return str(value.get("type", run_id(value)[:6]))
    return f"{value:g}" if isinstance(value, float) else str(value)


@dataclass(frozen=True)
class _Block:
    name: str
    index: int
    scenario: Path
    base: dict
    overrides: dict
    grid: tuple[dict, ...]
    random: tuple[dict, ...]
    samples: int
    artefacts: str


def _read_toml(path: Path, what: str) -> dict:
    return read_toml(path, what, CampaignError)


def _block(source: Path, table: dict, index: int, where: str) -> _Block:
    known = {"name", "scenario", "overrides", "axes", "samples", "artefacts", "description"}
    if unknown := sorted(set(table) - known - {"seed", "blocks"}):
        raise _fail(source, f"{where}{unknown[0]}", f"unknown field; use {sorted(known)}")
    if not isinstance(table.get("scenario"), str):
        raise _fail(source, f"{where}scenario", "missing: a scenario file or a shipped name")
    scenario = (source.parent / table["scenario"]).resolve()
    if resources.is_name(table["scenario"]) and not scenario.is_file():
        try:  # a shipped scenario by name, as `cdpr-twin run` takes it
            scenario = resources.scenario_file(table["scenario"])
        except resources.ResourceError as exc:
            raise _fail(source, f"{where}scenario", str(exc)) from None
    overrides = table.get("overrides", {})
    if not isinstance(overrides, dict):
        raise _fail(source, f"{where}overrides", 'must be a table of "dotted.key" = value')
    for key, value in overrides.items():  # as an axis's values (the results table's int64)
        if why := _beyond_int64(value):
            raise _fail(source, f'{where}overrides."{key}"', why)
    if not isinstance(table.get("description", ""), str):
        raise _fail(source, f"{where}description", 'must be text: description = "..."')
    axes = _axes(source, table.get("axes", []), where)
    for axis in axes:  # an axis varying a table would drop an override inside it, unsaid
        for key in overrides:  # (an override of a table an axis varies within: applied first)
            a = axis["key"]
            if a == key or key.startswith(f"{a}."):
                use = f"{key!r} is varied by an axis ({a!r}) too: set it in one place"
                raise _fail(source, f'{where}overrides."{key}"', use)
    samples, artefacts = table.get("samples", 1), table.get("artefacts", "none")
    if isinstance(samples, bool) or not isinstance(samples, int) or samples < 1:
        raise _fail(source, f"{where}samples", f"must be an integer ≥ 1, got {samples!r}")
    if artefacts not in ARTEFACTS:
        raise _fail(source, f"{where}artefacts", f"must be one of {', '.join(ARTEFACTS)}")
    random = tuple(a for a in axes if "draw" in a)
    if samples > 1 and not random:
        raise _fail(source, f"{where}samples", "> 1 repeats identical runs: add a random axis")
    try:
        base = _read_toml(scenario, "scenario file")
    except CampaignError as exc:  # the campaign's field too: which block names it
        raise _fail(source, f"{where}scenario", str(exc)) from None
    return _Block(
        str(table.get("name", "main" if not where else f"block{index}")),
        index,
        scenario,
        base,
        overrides,
        tuple(a for a in axes if "draw" not in a),
        random,
        samples,
        artefacts,
    )


def _axes(source: Path, axes: Any, where: str) -> list[dict]:
    """A block's axes, each checked, each varying its own key (not one within another's)."""
    if not isinstance(axes, list):
        raise _fail(source, f"{where}axes", "must be an array of tables [[axes]]")
    axes = [_axis(source, f"{where}axes[{i}]", a) for i, a in enumerate(axes)]
    for i, axis in enumerate(axes):
        for j, other in enumerate(axes[:i]):  # `truth` and `truth.seed` would overwrite too
            a, b = axis["key"], other["key"]
            if a == b or a.startswith(f"{b}.") or b.startswith(f"{a}."):
                use = f"{a!r} is varied by axes[{j}] ({b!r}) too: vary each value on one axis"
                raise _fail(source, f"{where}axes[{i}].key", use)
    return axes


def _check_blocks(source: Path, blocks: list[_Block]) -> None:
    """Refuse two blocks of one name, and more than :data:`MAX_RUNS` runs (before expanding)."""
    names: dict[str, int] = {}
    for block in blocks:
        if (i := names.setdefault(block.name, block.index)) != block.index:
            use = f"{block.name!r} names blocks[{i}] too: give each block its own name"
            raise _fail(source, f"blocks[{block.index}].name", use)
    runs = sum(math.prod(len(a["values"]) for a in b.grid) * b.samples for b in blocks)
    if runs > MAX_RUNS:
        where = "blocks" if len(blocks) > 1 else "samples" if blocks[0].samples > 1 else "axes"
        use = f"{runs} runs, more than the {MAX_RUNS} allowed: use fewer samples or values,"
        raise _fail(source, where, f"{use} or split it into several campaigns")


IN_LOOP = "estimators.in_loop"


def _swap_in_loop(data: dict, base: dict) -> None:
    """Vary the in-loop estimator as ``cdpr-twin run --in-loop`` does.

    The file's in-loop estimator stays, passive, and the new one leaves the passive list, so
    every run of an ``estimators.in_loop`` axis computes the same estimators.
    """
    est, old = data["estimators"], base.get("estimators", {})
    names = [*([old["in_loop"]] if "in_loop" in old else []), *old.get("passive", [])]
    est["passive"] = [n for n in names if n != est["in_loop"]]


def _tasks(source: Path, block: _Block, seed: int, where: str) -> list[Task]:
    from cdpr_twin.scenario.loading import ScenarioError, scenario_from_data
    from cdpr_twin.scenario.preflight import check_task

    out: list[Task] = []
    nominals: dict = {}  # the nominal robots check_task builds, by model (built once each)
    checked = set()
    points = itertools.product(*(a["values"] for a in block.grid))
    for p, point in enumerate(points):
        for sample in range(block.samples):
            rng = np.random.default_rng([seed, block.index, p, sample])
            params = {a["key"]: v for a, v in zip(block.grid, point, strict=True)}
            params |= {a["key"]: _draw(a, rng) for a in block.random}
            data = copy.deepcopy(block.base)
            changes = {**block.overrides, **params}
            for key, value in changes.items():
                try:
                    set_dotted(data, key, value)
                except KeyError as exc:
                    raise _fail(source, f"{where}{key}", str(exc.args[0])) from None
            if IN_LOOP in changes and "estimators.passive" not in changes:
                _swap_in_loop(data, block.base)
            try:
                scenario = scenario_from_data(data, block.scenario)
                checks = ("model", "controller", "start", "realism", "sensors", "duration")
                task_key = json.dumps([data.get(k) for k in checks], default=str)
                if task_key not in checked:  # the robot and the task: the twin's own checks
                    check_task(scenario, nominals)  # (truth draws and seeds do not change them)
                    checked.add(task_key)
            except ScenarioError as exc:
                varied = ", ".join(f"{k} = {_label(v)}" for k, v in params.items()) or "none"
                raise _fail(source, f"{where.rstrip('.') or 'run'} ({varied})", str(exc)) from None
            if block.samples > 1:
                params["sample"] = sample
            label = "_".join(f"{k.rsplit('.', 1)[-1]}{_label(v)}" for k, v in params.items())
            out.append(
                Task(
                    run_id(data),
                    block.name,
                    f"{block.name}_{label}".rstrip("_"),
                    str(block.scenario),
                    data,
                    params,
                    block.artefacts,
                )
            )
    return out


def load_campaign(path: str | Path) -> Campaign:
    """Read a campaign file and build and validate every run's scenario.

    Args:
        path: a campaign file, or a shipped campaign's name (``pbvs_gain_sweep``).

    Raises:
        CampaignError: naming the file and the field (and the scenario's own error).
    """
    try:
        source = resources.campaign_file(path)
    except resources.ResourceError as exc:
        raise CampaignError(str(exc)) from None
    top = _read_toml(source, "campaign file")
    seed = top.get("seed", 0)
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise _fail(source, "seed", f"must be an integer ≥ 0, got {seed!r}")
    name, description = top.get("name", source.stem), top.get("description", "")
    if not isinstance(description, str):
        raise _fail(source, "description", 'must be text: description = "..."')
    if (
        not isinstance(name, str)
        or name in ("", ".", "..")
        or any(c in name for c in "/\\")
        or not name.isprintable()  # a NUL or a control character: no directory's name
    ):
        raise _fail(source, "name", f"must be a plain name usable as a directory, got {name!r}")
    blocks = top.get("blocks")
    if blocks is None:
        parsed = [_block(source, top, 0, "")]
    elif not isinstance(blocks, list) or not blocks or not all(isinstance(b, dict) for b in blocks):
        raise _fail(source, "blocks", "must be a non-empty array of tables [[blocks]]")
    elif extra := sorted(set(top) - {"name", "seed", "description", "blocks"}):
        raise _fail(source, extra[0], "not allowed beside [[blocks]] (give it in each block)")
    else:
        parsed = [_block(source, b, i, f"blocks[{i}].") for i, b in enumerate(blocks)]
    _check_blocks(source, parsed)
    tasks = [
        t
        for i, b in enumerate(parsed)
        for t in _tasks(source, b, seed, f"blocks[{i}]." if blocks else "")
    ]
    seen: dict[str, str] = {}
    for t in tasks:
        key = run_id(as_read(t.data))  # 0 and 0.0: one value, as the scenario reads both
        if key in seen:
            raise _fail(source, "axes", f"runs {seen[key]} and {t.name} are identical")
        seen[key] = t.name
    return Campaign(name, source, description, tuple(tasks))


def shortened(campaign: Campaign, duration: float) -> Campaign:
    """The campaign with every run's duration capped at ``duration`` [s] (quick checks).

    A capped run is another scenario, so it gets another id: its row never mixes with the full
    runs' in a table (``--resume`` in a directory of the full campaign refuses).

    Raises:
        CampaignError: ``duration`` is not a finite time > 0 s.
    """
    if not (isinstance(duration, float | int) and math.isfinite(duration) and duration > 0):
        raise CampaignError(f"--duration must be a time > 0 s, got {duration!r}")
    tasks = []
    for task in campaign.tasks:
        data = copy.deepcopy(task.data)
        data["duration"] = min(float(data.get("duration", duration)), float(duration))
        tasks.append(dataclasses.replace(task, data=data, run_id=run_id(data)))
    return dataclasses.replace(campaign, tasks=tuple(tasks))
