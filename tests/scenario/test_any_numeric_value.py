"""Any number in any numeric field of a scenario: refused in one line, or a run whose files hold
only finite numbers.

Hypothesis draws values (huge, tiny, negative, -0.0, nan, ±inf, integers where floats go and
floats where integers go) into a copy of ``paper_open_loop`` (its top level, [model], [truth],
[sensors], [start], [controller] and [estimators.*] numbers, every numeric field of each
``[realism.<part>]``, and two fault events) and runs ``cdpr-twin run`` on it. Whatever the value,
the exit code is 0 (done), 2 (refused) or 3 (the robot's fault); no numpy warning is printed;
a refusal is exactly one line on stderr; a run's ``timeseries.csv`` and ``summary.json`` hold no
non-finite number. The examples are derandomized: the same scenario gives the same draws.
"""

import dataclasses
import json
import math
import tomllib
import typing
import warnings
from pathlib import Path

from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from cdpr_twin.cli import main
from cdpr_twin.plugins import spec_of
from cdpr_twin.robot.realism import PARTS

ROOT = Path(__file__).resolve().parents[2]
EVENTS = [  # fault events, so that their numbers are drawn too
    {"kind": "tension_sensor_fail", "at": 0.04, "cable": 2, "value": 5.0},
    {"kind": "encoder_glitch", "at": 0.04, "cable": 3, "jump": 0.001},
]


def _base() -> dict:
    data = tomllib.loads((ROOT / "scenarios" / "paper_open_loop.toml").read_text())
    data["events"] = [dict(e) for e in EVENTS]
    return data


def _numeric_fields(node, path=()) -> list[tuple[tuple, str]]:
    """Every number in the scenario, as (path, kind): ``number`` or ``numbers`` (a flat list)."""
    if isinstance(node, dict):
        return [f for k, v in node.items() for f in _numeric_fields(v, (*path, k))]
    if isinstance(node, list) and node and all(isinstance(x, (dict, list)) for x in node):
        return [f for i, v in enumerate(node) for f in _numeric_fields(v, (*path, i))]
    if isinstance(node, list) and node and all(isinstance(x, (int, float)) for x in node):
        return [(path, "numbers")]
    if isinstance(node, (int, float)) and not isinstance(node, bool):
        return [(path, "number")]
    return []


def _realism_fields() -> list[tuple[tuple, str]]:
    """Every numeric field of every ``[realism.<part>]`` table (none is set in the file)."""
    out = []
    for part, cls in PARTS.items():
        hints = typing.get_type_hints(cls)
        for f in dataclasses.fields(cls):
            key = ("realism", part, spec_of(f).file_key(f.name))
            if hints[f.name] in (float, int):
                out.append((key, "number"))
            elif (
                typing.get_origin(hints[f.name]) is tuple
                and typing.get_args(hints[f.name])[0] is float
            ):
                out.append((key, "numbers"))
    return out


FIELDS = _numeric_fields(_base()) + _realism_fields()

EDGES = [0.0, -0.0, 1e308, -1e308, 5e-324, -5e-324, 1e-300, 1e300, -1.0, 1.0, 1e15]
EDGES += [math.nan, math.inf, -math.inf, 0, -1, 1, 2**63 - 1, -(2**63)]
NUMBERS = st.one_of(
    st.sampled_from(EDGES),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(2**63), max_value=2**63 - 1),
)
"""What TOML can hold in a number's place: 64-bit integers and doubles, nan and ±inf too."""


@st.composite
def _changes(draw) -> list[tuple[tuple, object]]:
    """One to three fields, each given a drawn value (a list: a drawn list, or one item), under
    either realism profile (the ideal one reads [sensors]' noise, the acrobot one its own)."""
    out = [(("realism", "profile"), draw(st.sampled_from(["ideal", "acrobot"])))]
    for path, kind in draw(st.lists(st.sampled_from(FIELDS), min_size=1, max_size=3)):
        if kind == "numbers" and draw(st.booleans()):
            value = draw(st.lists(NUMBERS, min_size=0, max_size=6))
        elif kind == "numbers":
            path = (*path, draw(st.integers(min_value=0, max_value=5)))  # one item of it
            value = draw(NUMBERS)
        else:
            value = draw(NUMBERS)
        out.append((path, value))
    return out


def _set(data: dict, path: tuple, value) -> None:
    node = data
    for part in path[:-1]:
        node = node.setdefault(part, {}) if isinstance(node, dict) else node[part]
    last = path[-1]
    if isinstance(node, list):
        if last < len(node):
            node[last] = value
    else:
        node[last] = value


def _toml(value) -> str:
    """A value as TOML (tables inline), nan and inf as TOML writes them."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return json.dumps(value)
    if isinstance(value, float):
        return "nan" if math.isnan(value) else repr(value)  # inf, -inf, -0.0 as TOML has them
    if isinstance(value, int):
        return str(value)
    if isinstance(value, list):
        return "[" + ", ".join(_toml(x) for x in value) + "]"
    return "{" + ", ".join(f"{json.dumps(k)} = {_toml(v)}" for k, v in value.items()) + "}"


def _finite_csv(text: str) -> list[str]:
    """The cells of a CSV text that are numbers and not finite."""
    bad = []
    for line in text.splitlines()[1:]:
        for cell in line.split(","):
            try:
                number = float(cell)
            except ValueError:
                continue  # text (status, event) or an empty cell
            if not math.isfinite(number):
                bad.append(cell)
    return bad


def _strict_json(text: str):
    def refuse(constant):
        raise AssertionError(f"summary.json holds {constant}")

    return json.loads(text, parse_constant=refuse)


@settings(
    max_examples=100,
    deadline=None,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(changes=_changes())
@example(changes=[(("controller", "waypoints", 2, 0), 1e308)])  # was numpy's overflow warning
@example(changes=[(("model", "control_rate"), 5e-324)])  # was an OverflowError traceback
@example(changes=[(("events", 1, "at"), 1e308)])  # was "the run failed: OverflowError"
@example(  # was ±inf tensions, exit 0
    changes=[(("realism", "profile"), "ideal"), (("sensors", "tension_noise_std"), 1e308)]
)
@example(changes=[(("truth", "exit_point_std"), -0.0)])  # was "model: scale < 0"
@example(  # was numpy's "overflow encountered in divide", nine times, in a completed run
    changes=[(("realism", "profile"), "acrobot"), (("realism", "winch", "max_accel"), 5e-324)]
)
def test_any_number_in_any_numeric_field_is_refused_in_one_line_or_runs_finite(
    changes, tmp_path_factory, capsys
):
    tmp = tmp_path_factory.mktemp("value")
    data = _base()
    data["model"]["file"] = str(ROOT / "models" / "acrobot" / "scene.xml")
    del data["model"]["robot"]
    for path, value in changes:
        _set(data, path, value)
    scenario = tmp / "s.toml"
    scenario.write_text("\n".join(f"{json.dumps(k)} = {_toml(v)}" for k, v in data.items()))
    out = tmp / "out"
    capsys.readouterr()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        code = main(["run", str(scenario), "--out", str(out), "--no-camera", "--duration", "0.12"])
    err = capsys.readouterr().err
    assert code in (0, 2, 3), (changes, err)
    numpy_warnings = [str(w.message) for w in caught if issubclass(w.category, RuntimeWarning)]
    assert not numpy_warnings, (changes, numpy_warnings)  # (printed on stderr, before us)
    if code == 2:
        assert err.endswith("\n") and err.count("\n") == 1 and err.strip(), (changes, err)
        assert not [str(w.message) for w in caught], (changes, err)
        assert not out.exists(), changes
        return
    assert not _finite_csv((out / "timeseries.csv").read_text()), changes
    _strict_json((out / "summary.json").read_text())
