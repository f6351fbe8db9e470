"""A campaign's limits are refused in one line, before anything is written or expanded.

Integers beyond the results table's int64, a key on two axes, two blocks of one name, more
runs than ``MAX_RUNS`` (refused at once, not after expanding them) and a description that is
not text.
"""

import time
from pathlib import Path

import pytest

from cdpr_twin.campaign import CampaignError, load_campaign
from cdpr_twin.campaign.spec import INT64, MAX_RUNS
from cdpr_twin.cli import main

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = f'scenario = "{ROOT}/scenarios/paper_open_loop.toml"\n'
FAST = '[overrides]\n"sensors.camera" = false\nduration = 0.08\n\n'
BIG = 99999999999999999999  # > 2**63 - 1


def _axis(key: str, body: str) -> str:
    return f'[[axes]]\nkey = "{key}"\n{body}\n\n'


def _block(name: str, axes: str, keys: str = "") -> str:
    fast = FAST.replace("[overrides]", "[blocks.overrides]")
    axes = axes.replace("[[axes]]", "[[blocks.axes]]")
    return f'[[blocks]]\nname = "{name}"\n{SCENARIO}{keys}\n{fast}{axes}'


def _refused(tmp_path: Path, capsys, text: str, *words: str) -> float:
    """Run the campaign ``text``: exit 2, one line on stderr naming ``words``, no ``--out``."""
    src, out = tmp_path / "bad.toml", tmp_path / "out"
    src.write_text(text)
    start = time.monotonic()
    assert main(["campaign", str(src), "--out", str(out)]) == 2
    elapsed = time.monotonic() - start
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.endswith("\n"), err
    assert str(src) in err and all(w in err for w in words), err
    assert not out.exists()
    return elapsed


BEYOND_64_BITS = {  # the axis, and where the error says it is
    "grid": (_axis("seed", f"values = [1, {BIG}]"), "axes[0].values (seed)"),
    "grid_negative": (_axis("seed", f"values = [1, -{BIG}]"), "axes[0].values (seed)"),
    "in_a_table": (_axis("truth", f"values = [{{seed = {BIG}}}]"), "axes[0].values (truth)"),
    "choice": (_axis("truth.seed", f'draw = "choice"\nvalues = [{BIG}]'), "values (truth.seed)"),
    "integers_high": (_axis("truth.seed", f'draw = "integers"\nlow = 1\nhigh = {BIG}'), "high"),
    "integers_float_low": (_axis("truth.seed", 'draw = "integers"\nlow = -1e19\nhigh = 1'), "low"),
    "normal_std": (_axis("seed", f'draw = "normal"\nmean = 0\nstd = {BIG**20}'), "std (seed)"),
}


@pytest.mark.parametrize(("axis", "where"), BEYOND_64_BITS.values(), ids=BEYOND_64_BITS.keys())
def test_an_integer_beyond_64_bits_is_refused_naming_the_axis_and_the_range(
    tmp_path, capsys, axis, where
):
    _refused(tmp_path, capsys, SCENARIO + FAST + axis, where, str(INT64[0]), str(INT64[1]))


OVERRIDES_BEYOND_64_BITS = {  # the override, and what the error says
    "seed": (f"seed = {BIG}", f'overrides."seed": {BIG} is not a 64-bit integer'),
    "dotted": (f'"truth.seed" = -{BIG}', f'overrides."truth.seed": -{BIG} is not a 64-bit'),
    "in_a_table": (f"truth = {{seed = {BIG}}}", f'overrides."truth": {BIG} is not a 64-bit'),
}


@pytest.mark.parametrize(
    ("line", "says"), OVERRIDES_BEYOND_64_BITS.values(), ids=OVERRIDES_BEYOND_64_BITS.keys()
)
@pytest.mark.parametrize("in_block", [False, True], ids=["top", "block"])
def test_an_override_beyond_64_bits_is_refused_naming_its_key(
    tmp_path, capsys, line, says, in_block
):
    # before: not checked; the runs started (and an overridden seed then failed the results
    # table with a traceback), as an axis's values are not
    axis = _axis("seed", "values = [1]")
    text = _block("a", axis) if in_block else SCENARIO + FAST + axis
    text = text.replace("duration = 0.08\n", f"duration = 0.08\n{line}\n")
    says = f"blocks[0].{says}" if in_block else f"bad.toml: {says}"
    _refused(tmp_path, capsys, text, says, str(INT64[0]), str(INT64[1]))


@pytest.mark.parametrize("values", [([1], [2]), ([1, 2], [3, 4])], ids=["one_each", "two_each"])
def test_a_key_on_two_axes_is_refused_naming_it(tmp_path, capsys, values):
    axes = "".join(_axis("seed", f"values = {v}") for v in values)
    _refused(tmp_path, capsys, SCENARIO + FAST + axes, "axes[1].key", "'seed'", "axes[0]")


def test_a_key_within_another_axis_key_is_refused_naming_both(tmp_path, capsys):
    # before: the later axis overwrote the earlier one's `seed` (or the other way round)
    axes = _axis("truth", "values = [{seed = 1}, {seed = 2}]") + _axis("truth.seed", "values = [3]")
    _refused(tmp_path, capsys, SCENARIO + FAST + axes, "axes[1].key", "'truth.seed'", "'truth'")


def test_two_blocks_of_one_name_are_refused_naming_it(tmp_path, capsys):
    blocks = _block("a", _axis("seed", "values = [1]")) + _block("a", _axis("seed", "values = [2]"))
    _refused(tmp_path, capsys, blocks, "blocks[1].name", "'a'", "blocks[0]")


RANDOM = _axis("truth.seed", 'draw = "integers"\nlow = 1\nhigh = 1000')
HALF = MAX_RUNS // 2 + 1  # two blocks of HALF samples: each under the bound, both over
GRID = "".join(_axis(k, f"values = {list(range(1, 401))}") for k in ("seed", "truth.seed"))
MANY_RUNS = {
    "samples": (SCENARIO + "samples = 100000000000\n" + FAST + RANDOM, 100000000000),
    "grid": (SCENARIO + FAST + GRID, 400**2),
    "blocks": ("".join(_block(n, RANDOM, f"samples = {HALF}\n") for n in "ab"), 2 * HALF),
}


@pytest.mark.parametrize(("text", "runs"), MANY_RUNS.values(), ids=MANY_RUNS.keys())
def test_more_runs_than_the_bound_are_refused_at_once(tmp_path, capsys, text, runs):
    elapsed = _refused(tmp_path, capsys, text, f"{runs} runs", str(MAX_RUNS))
    assert elapsed < 30.0


@pytest.mark.parametrize(
    "text",
    [
        "description = 3\n" + SCENARIO + FAST + _axis("seed", "values = [1]"),
        "description = 3\n" + _block("a", _axis("seed", "values = [1]")),
        _block("a", _axis("seed", "values = [1]"), 'description = ["x"]\n'),
    ],
    ids=["top", "top_with_blocks", "block"],
)
def test_a_description_that_is_not_text_is_refused(tmp_path, capsys, text):
    _refused(tmp_path, capsys, text, "description: must be text")


@pytest.mark.parametrize(
    ("override", "axis", "says"),
    [
        (
            '"truth.seed" = 7',
            _axis("truth", "values = [{exit_point_std = 0.001}]"),
            "overrides.\"truth.seed\": 'truth.seed' is varied by an axis ('truth')",
        ),
        ("seed = 7", _axis("seed", "values = [1, 2]"), "overrides.\"seed\": 'seed' is varied"),
    ],
)
def test_an_override_under_an_axis_is_refused_not_dropped(tmp_path, capsys, override, axis, says):
    # before: the axis replaced the whole `truth` table and the override's seed was lost (the
    # results said truth_seed 0), without a word
    text = (SCENARIO + FAST + axis).replace("duration = 0.08\n", f"duration = 0.08\n{override}\n")
    _refused(tmp_path, capsys, text, says)


@pytest.mark.parametrize(
    ("text", "says"),
    [
        ("blocks = [1, 2]\n", "blocks: must be a non-empty array of tables"),
        ('name = "a\\u0000b"\n' + SCENARIO, "name: must be a plain name"),
        ('name = "a\\u0007b"\n' + SCENARIO, "name: must be a plain name"),
        (
            SCENARIO + '[overrides]\n"model.nominal" = "/tmp/a\\u0000b"\n',
            "model.nominal: must not hold a NUL character",
        ),
    ],
)
def test_malformed_blocks_and_nul_characters_are_one_line_errors(tmp_path, capsys, text, says):
    # before: TypeError: 'int' object is not iterable; ValueError: embedded null byte (tracebacks)
    _refused(tmp_path, capsys, text, says)


def test_every_shipped_campaign_still_loads():
    from cdpr_twin.campaign import load_campaign

    for path in sorted((ROOT / "campaigns").glob("*.toml")):
        assert load_campaign(path).tasks, path


def test_a_missing_block_scenario_names_the_campaign_and_the_block(tmp_path, capsys):
    block = _block("a", _axis("seed", "values = [1]")).replace(SCENARIO, 'scenario = "nope.toml"\n')
    _refused(tmp_path, capsys, block, "bad.toml: blocks[0].scenario: ", "nope.toml: scenario file")


def test_an_override_of_a_table_an_axis_varies_within_keeps_both(tmp_path):
    """The override is applied first, the axis's value lands inside it: nothing is dropped."""
    from cdpr_twin.campaign import load_campaign

    text = (
        SCENARIO
        + FAST.replace(
            "duration = 0.08\n",
            "duration = 0.08\n"
            '"realism.camera" = {focal_error_std = 0.003, center_error_std_px = 0.5}\n',
        )
        + _axis("realism.camera.exposure_s", "values = [0.004, 0.008]")
    )
    path = tmp_path / "c.toml"
    path.write_text(text)
    tasks = load_campaign(path).tasks
    cams = [t.data["realism"]["camera"] for t in tasks]
    assert [c["exposure_s"] for c in cams] == [0.004, 0.008]
    assert all(c["focal_error_std"] == 0.003 and c["center_error_std_px"] == 0.5 for c in cams)


def test_a_waypoint_outside_the_frame_through_an_axis_is_refused_before_any_run(tmp_path):
    from cdpr_twin.campaign import CampaignError

    p1, p0 = [0.284, -0.197, 0.08, 0, 0, 0], [0.1, 0.0, 0.3, 0, 0, 0]
    good, bad = [p1, [0.284, -0.197, 0.25, 0, 0, 0], p0], [p1, [0.284, -0.197, 2.5, 0, 0, 0], p0]
    path = tmp_path / "axis.toml"
    path.write_text(
        f'name = "axis"\nscenario = "{ROOT}/scenarios/paper_open_loop.toml"\n\n'
        f'[[axes]]\nkey = "controller.waypoints"\nvalues = [{good}, {bad}]\n'
    )
    with pytest.raises(CampaignError, match=r"waypoints\[1\].* is outside the frame"):
        load_campaign(path)  # was: a failed row, after the runs before it had run


@pytest.mark.parametrize(
    ("text", "where"),
    [  # each was a traceback (KeyError, ValueError, OverflowError) while drawing
        ('[[axes]]\nkey = "seed"\ndraw = "choice"\n', r"axes\[0\]\.values: .*needs values"),
        ('[[axes]]\nkey = "seed"\ndraw = "normal"\nmean = 1\nstd = -1\n', r"std: must be > 0"),
        (
            '[[axes]]\nkey = "seed"\ndraw = "integers"\nlow = 1\nhigh = 1e20\n',
            r"high \(seed\): .*64-bit",
        ),
        (
            '[[axes]]\nkey = "seed"\ndraw = "integers"\nlow = 0.5\nhigh = 9\n',
            r"low \(seed\): .*64-bit",
        ),
        (
            '[[axes]]\nkey = "truth.exit_point_std"\n'
            'draw = "uniform"\nlow = -1e308\nhigh = 1e308\n',
            r"high: high − low must be a finite",
        ),
    ],
)
def test_a_random_axis_that_cannot_be_drawn_is_a_one_line_error(tmp_path, text, where):
    from cdpr_twin.campaign import CampaignError

    path = tmp_path / "c.toml"
    path.write_text('name = "c"\n' + SCENARIO + text)
    with pytest.raises(CampaignError, match=where):
        load_campaign(path)


@pytest.mark.parametrize(
    "key", ["samples = 3", "smaples = 3", 'artefacts = "bogus"', SCENARIO.strip()]
)
def test_top_level_run_keys_beside_blocks_are_refused_not_ignored(tmp_path, key):
    """They were ignored: a typo'd ``samples`` ran one run where three were meant."""
    from cdpr_twin.campaign import CampaignError

    path = tmp_path / "c.toml"
    path.write_text(f'name = "c"\n{key}\n\n[[blocks]]\nname = "b"\n{SCENARIO}')
    with pytest.raises(CampaignError, match="not allowed beside"):
        load_campaign(path)


@pytest.mark.parametrize("name", ["..", ".", "a\\\\b"])
def test_a_campaign_name_that_is_not_a_plain_directory_name_is_refused(tmp_path, name):
    """``..`` was accepted: the default output runs/.. is the current directory."""
    from cdpr_twin.campaign import CampaignError

    path = tmp_path / "c.toml"
    path.write_text(f'name = "{name}"\n' + SCENARIO)
    with pytest.raises(CampaignError, match="plain name"):
        load_campaign(path)


def test_a_campaign_refuses_what_its_runs_would_before_any_starts(tmp_path):
    scenario = ROOT / "scenarios" / "paper_open_loop.toml"
    base = f'scenario = "{scenario}"\n[overrides]\nduration = 0.2\n'
    for axis, match in (
        ('key = "realism.camera.exposure_s"\nvalues = [0.004, 0.05]', "exposure_s: 0.05 s"),
        ('key = "truth.exit_point_std"\nvalues = [0, 0.0]', "are identical"),
        ('key = "controller.durations"\nvalues = [[10, 5, 10], [10.0, 5.0, 10.0]]', "identical"),
    ):
        path = tmp_path / "c.toml"
        path.write_text(base + "\n[[axes]]\n" + axis + "\n")
        with pytest.raises(CampaignError, match=match):
            load_campaign(path)
