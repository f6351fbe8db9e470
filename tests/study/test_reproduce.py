"""`cdpr-twin reproduce`, scaled down, end to end: artefacts exist and every report number is
recomputed from the runs' own files."""

import csv
import json
import os
from pathlib import Path

import numpy as np
import pytest

from cdpr_twin.study import reproduce
from cdpr_twin.study.results import PAPER_ESTIMATORS

ROOT = Path(__file__).resolve().parents[2]
P1 = np.array([0.284, -0.197, 0.08])


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    out = tmp_path_factory.mktemp("reproduce")
    rep = reproduce(out, workers=2, runs_scale=0.1, duration=11.0)
    return out, rep


def _rows(run_dir: Path) -> list[dict]:
    with (run_dir / "timeseries.csv").open() as f:
        return list(csv.DictReader(f))


def _xyz(row: dict, prefix: str) -> np.ndarray:
    return np.array([float(row[f"{prefix}_{k}"]) for k in "xyz"])


@pytest.mark.slow
def test_reproduce_writes_every_artefact(small):
    import cv2

    out, rep = small
    records = json.loads((out / "runs.json").read_text())
    assert len(records) == 1 + 7 and all(r["ok"] for r in records)  # PBVS: the six and fused
    assert rep["runs"] == {"total": 8, "ok": 8, "failed": []}
    for name in ("fig5a", "fig5b", "fig7a", "fig7b", "fig8"):
        img = cv2.imread(str(out / f"{name}.png"))
        assert img is not None and img.shape == (600, 1200, 3), name
        assert img.std() > 10, f"{name} looks blank"
    report = (out / "report.md").read_text()
    assert all(f"({n}.png)" in report for n in ("fig5a", "fig5b", "fig7a", "fig7b", "fig8"))
    assert (out / "runs" / "open_loop_seed1" / "recording.rrd").exists()
    assert not list(out.glob("*.partial")) and not (out / ".lock").exists()  # whole, released


@pytest.mark.slow
def test_report_numbers_are_recomputed_from_the_run_files(small):
    out, _ = small
    rep = json.loads((out / "report.json").read_text())
    report_md = (out / "report.md").read_text()
    # open loop: each estimator's max translational deviation, and the miss at p1 (t = 10 s)
    rows = _rows(out / "runs" / "open_loop_seed1")
    for name, e in rep["open_loop"]["estimators"].items():
        dev = [np.linalg.norm(_xyz(r, name) - _xyz(r, "true")) for r in rows]
        assert e["max_translation_m"] == pytest.approx(max(dev), abs=1e-12)
    at10 = min(rows, key=lambda r: abs(float(r["t"]) - 10.0))
    miss = np.linalg.norm(_xyz(at10, "true") - _xyz(at10, "plan"))
    assert rep["open_loop"]["miss_at_p1"]["translation_m"] == pytest.approx(miss, abs=1e-12)
    assert f"{miss * 100:.2f} cm" in report_md
    # accuracy at p1: open loop at t = 10 s, PBVS at the end of each run
    expected = {"open loop": [np.linalg.norm(_xyz(at10, "true") - P1)]}
    for name in (*PAPER_ESTIMATORS, "fused"):  # the PBVS file's estimators, each in the loop
        run_dir = out / "runs" / f"pbvs_{name}_seed1"
        summary = json.loads((run_dir / "summary.json").read_text())
        if summary["status"] != "converged":
            continue
        err = np.linalg.norm(_xyz(_rows(run_dir)[-1], "true") - P1)
        expected.setdefault("PBVS (all)", []).append(err)
        expected[f"PBVS {name}"] = [err]
        assert rep["pbvs"][name]["status"] == "converged"
    for key, values in expected.items():
        np.testing.assert_allclose(rep["accuracy"][key]["translation_m"], values, atol=1e-12)
    if "ratios" in rep:
        ratio = np.mean(expected["open loop"]) / np.mean(expected["PBVS (all)"])
        assert rep["ratios"]["translation_m"] == pytest.approx(ratio, rel=1e-12)
        assert f"{ratio:.1f}×" in report_md
    # every finding's verdict is in the report as computed
    for f in rep["findings"]:
        assert f"| {f['finding']} |" in report_md and f"**{f['verdict']}**" in report_md


@pytest.mark.slow
def test_notebook_executes_against_the_output(small):
    import nbformat
    from nbclient import NotebookClient

    out, _ = small
    nb = nbformat.read(ROOT / "notebooks" / "paper_figures.ipynb", as_version=4)
    assert all(not c.get("outputs") for c in nb.cells if c.cell_type == "code")  # committed bare
    os.environ["CDPR_TWIN_RESULTS"] = str(out)
    try:
        NotebookClient(
            nb,
            timeout=600,
            kernel_name="python3",
            resources={"metadata": {"path": str(ROOT / "notebooks")}},
        ).execute()
    finally:
        del os.environ["CDPR_TWIN_RESULTS"]
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert not [o for o in outputs if o["output_type"] == "error"]
    images = [o for o in outputs if "image/png" in o.get("data", {})]
    assert len(images) == 5


def test_the_plan_follows_the_pbvs_scenario_estimators(tmp_path):
    from cdpr_twin.study import plan

    text = (ROOT / "scenarios" / "paper_pbvs.toml").read_text()
    text = text.replace('"../models/', f'"{ROOT}/models/')
    text = text.replace('passive = ["image", "model_simple", ', "passive = [")
    pbvs = tmp_path / "pbvs.toml"
    pbvs.write_text(text)
    specs = plan(0.4, pbvs=pbvs)
    assert [s.name for s in specs if s.kind == "open_loop"] == [
        "open_loop_seed1",
        "open_loop_seed2",
        "open_loop_seed3",
        "open_loop_seed4",
    ]
    in_loop = [s.in_loop for s in specs if s.kind == "pbvs"]
    assert in_loop == [
        n
        for n in (*PAPER_ESTIMATORS, "fused")
        if n not in ("image", "model_simple")
        for _ in range(2)
    ]
    assert all(s.record_rrd == (s.seed == 1) for s in specs)


def test_findings_and_report_take_any_estimator(tmp_path):
    from cdpr_twin.study import evaluate, write_report

    run = {"status": "converged", "max_translation_m": 0.002, "max_rotation_deg": 0.1}
    rep = {
        "runs": {"total": 2, "ok": 2, "failed": []},
        "pbvs": {"control": {**run, "max_translation_m": 0.003}, "fused": run},
    }
    rep["findings"] = evaluate(rep)
    (best,) = rep["findings"]
    assert best["verdict"] == "disagrees" and "fused 2.0 mm" in best["twin"]
    assert set(best) == {"finding", "paper", "twin", "threshold", "verdict", "why"}
    report = write_report(tmp_path, rep, [], 1.0).read_text()
    assert "| PBVS, fused in the loop: max deviation | — | 0.20 cm / 0.10° |" in report
