"""The redesign changed no output: short paper runs equal runs recorded before it, byte for byte.

The fixtures (``tests/fixtures/golden``) were written by the version before the issue-8 redesign
(commit 7645b83); see their README. Only ``summary.json``'s ``source`` (the path the scenario
was given by) is ignored.
"""

import gzip
import json
from pathlib import Path

import pytest

from cdpr_twin.runner import run
from cdpr_twin.scenario import load_scenario

ROOT = Path(__file__).resolve().parent.parent
GOLDEN = Path(__file__).resolve().parent / "fixtures" / "golden"

CASES = {
    "open_loop": ("paper_open_loop.toml", {"duration": 2.0, "seed": 3}),
    "pbvs": (
        "paper_pbvs.toml",
        {"duration": 2.0, "seed": 3, "in_loop": "model_elastic_pulley"},
    ),
    "open_loop_nocam": ("paper_open_loop.toml", {"duration": 11.0, "seed": 5, "camera": False}),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_outputs_byte_identical_to_the_version_before_the_redesign(case, tmp_path):
    file, overrides = CASES[case]
    scenario = load_scenario(ROOT / "scenarios" / file).with_overrides(**overrides)
    run(scenario, tmp_path, record_rrd=False)
    expected_csv = gzip.decompress((GOLDEN / case / "timeseries.csv.gz").read_bytes())
    assert (tmp_path / "timeseries.csv").read_bytes() == expected_csv
    got = json.loads((tmp_path / "summary.json").read_text(encoding="utf-8"))
    want = json.loads((GOLDEN / case / "summary.json").read_text(encoding="utf-8"))
    got.pop("source")
    want.pop("source")
    assert got == want
    # and the files' text too (key order, number formatting)
    assert json.dumps(got, indent=2) == json.dumps(want, indent=2)
