"""The study reports' explanations are computed from each robot's own numbers.

Truth: the committed reports' stored numbers (``report.json``): re-evaluating the findings from
them gives the committed texts (no drift between code and docs), and a CoGiRo report carries
none of ACROBOT's magnitudes (a 4 cm tag at 0.1–0.35 m, a 9 cm goal, centimetre errors).
"""

import json
import re

import pytest

from cdpr_twin import MODELS_DIR
from cdpr_twin.study.findings import evaluate
from cdpr_twin.study.report import rerender

DOCS = MODELS_DIR.parent / "docs"
REPORTS = {"acrobot": DOCS, "cogiro": DOCS / "cogiro"}


def _stored(robot):
    return json.loads((REPORTS[robot] / "report.json").read_text())


@pytest.mark.parametrize("robot", sorted(REPORTS))
def test_the_committed_report_is_what_the_code_writes_from_its_numbers(robot, tmp_path):
    rep = _stored(robot)
    assert evaluate({k: v for k, v in rep.items() if k != "findings"}) == rep["findings"]
    committed = (REPORTS[robot] / "report.md").read_text()
    minutes = float(re.search(r"completed \(([0-9.]+) min\)", committed).group(1))
    for fig in REPORTS[robot].glob("fig*.png"):
        (tmp_path / fig.name).write_bytes(b"")
    assert rerender(tmp_path, rep, minutes * 60).read_text() == committed


def test_a_cogiro_report_says_nothing_of_acrobots_magnitudes():
    rep = _stored("cogiro")
    words = " ".join(f["why"] + " " + f["twin"] for f in rep["findings"])
    for acrobot in ("4 cm tag", "0.1–0.35 m", "9 cm", "~1 cm", "centimetre geometry", "ACROBOT"):
        assert acrobot not in words
    robot = rep["robot"]
    assert robot["tag_size_m"] == 0.4 and robot["goal_tag_distance_m"] == pytest.approx(0.99)
    assert robot["sag_simulated"] and robot["payload_kg"]["open_loop"] == 250.0


def test_an_undefined_roughness_stored_as_null_drops_its_sentence_not_the_report():
    """report.json is strict JSON: a NaN roughness (no tick after the servo's start) is null."""
    rep = {k: v for k, v in _stored("acrobot").items() if k != "findings"}
    committed = evaluate(rep)
    late = rep["pbvs"]["control"]["others_roughness_after_start_m"]
    rep["pbvs"]["control"]["others_roughness_after_start_m"] = dict.fromkeys(late)  # all null
    texts = evaluate(rep)
    before = " ".join(f["why"] for f in committed)
    assert "after the first 0.5 s" in before
    assert "after the first 0.5 s" not in " ".join(f["why"] for f in texts)
    assert [f["finding"] for f in texts] == [f["finding"] for f in committed]
