"""Campaigns: validated before they run, the same table from local processes and from Ray, each
row equal to its run's own summary.json, resumable after a kill, stoppable with a valid table.

A campaign's directory is its own: a run's directory is not taken (nor a campaign's by a run),
a resume never mixes two campaigns into one table, and an empty ``--out`` is refused."""

import json
import math
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from cdpr_twin.campaign import CampaignError, load_campaign, load_table, run_campaign
from cdpr_twin.campaign.table import read_parquet
from cdpr_twin.cli import main
from cdpr_twin.files.transaction import OutputDirError
from cdpr_twin.recording.timeseries import Timeseries

ROOT = Path(__file__).resolve().parents[2]
SMALL = f"""
name = "small"
scenario = "{ROOT}/scenarios/paper_open_loop.toml"
seed = 7
samples = 3
artefacts = "csv"

[overrides]
"sensors.camera" = false
duration = 1.0

[[axes]]
key = "truth.exit_point_std"
values = [0.0, 0.012]

[[axes]]
key = "seed"
values = [1, 2]

[[axes]]
key = "truth.seed"
draw = "integers"
low = 1
high = 1000
"""


_START_AXIS = (
    'key = "seed"\nvalues = [1, 2]',
    'key = "start.pose"\nvalues = [[0.112, -0.032, 0.301, -12, -10, 0], [9, 9, 9, 0, 0, 0]]',
)


@pytest.fixture(scope="module")
def small(tmp_path_factory):
    path = tmp_path_factory.mktemp("campaign") / "small.toml"
    path.write_text(SMALL)
    campaign = load_campaign(path)
    out = path.parent / "local"
    info = run_campaign(campaign, out, workers=2)
    return campaign, out, info


def test_a_campaign_expands_its_axes_reproducibly(small):
    campaign, _, _ = small
    assert len(campaign.tasks) == 12  # 2 × 2 grid points × 3 random draws
    again = load_campaign(campaign.source)
    assert [t.run_id for t in again.tasks] == [t.run_id for t in campaign.tasks]
    assert len({t.run_id for t in campaign.tasks}) == 12
    robots = {t.params["truth.seed"] for t in campaign.tasks}
    assert len(robots) > 6 and all(1 <= r <= 1000 for r in robots)


def test_every_row_equals_its_runs_own_summary(small):
    campaign, out, info = small
    assert info["ran_now"] == 12 and info["status"] == "completed"
    rows = load_table(out).to_pylist()
    assert [r["run_id"] for r in rows] == [t.run_id for t in campaign.tasks]  # the file's order
    for row in rows:
        s = json.loads((out / "runs" / row["run_id"] / "summary.json").read_text())
        assert row["status"] == s["status"] and row["ok"]
        assert row["simulated_time_s"] == s["simulated_time_s"] and row["seed"] == s["seed"]
        for name, e in s["estimators"].items():
            assert row[f"est.{name}.max_t_m"] == e["max_translation_m"]
            assert row[f"est.{name}.rms_r_deg"] == e["rms_rotation_deg"]
            assert row[f"est.{name}.final_t_m"] == e["final_translation_m"]
        task = next(t for t in campaign.tasks if t.run_id == row["run_id"])
        assert row["param.truth.seed"] == task.params["truth.seed"] == s["truth_seed"]
    # the RMS deviation itself, recomputed from the run's timeseries
    row = rows[0]
    ts = Timeseries.load(out / "runs" / row["run_id"] / "timeseries.csv")
    dt, _ = ts.deviation("model_elastic_pulley")
    assert row["est.model_elastic_pulley.rms_t_m"] == pytest.approx(np.sqrt(np.mean(dt**2)))
    # one line of pandas, as in a notebook
    import pandas as pd

    assert len(pd.read_parquet(out / "results.parquet")) == 12


def test_a_finished_campaign_resumed_runs_nothing_and_is_refused_without_resume(small):
    campaign, out, _ = small
    assert run_campaign(campaign, out, workers=2, resume=True)["ran_now"] == 0
    code = main(["campaign", str(campaign.source), "--out", str(out)])
    assert code == 2  # holds results: refused, nothing touched
    assert len(load_table(out)) == 12
    # the command resumed: nothing runs, the report is computed from the table
    assert main(["campaign", str(campaign.source), "--out", str(out), "--resume"]) == 0
    report = (out / "report.md").read_text()
    rows = load_table(out).to_pylist()
    err = [1e3 * r["final_t_m"] for r in rows if r["param.truth.exit_point_std"] == 0.012]
    assert f"| 0.012 | 6 | median {np.median(err):.2f}" in report
    assert (out / "distribution.png").stat().st_size > 1000


def test_the_report_counts_each_estimators_wins_run_by_run(small):
    """The estimators' section: medians and the runs each estimator deviates least in, counted
    again here from every run's own summary.json (plain Python, no table)."""
    from cdpr_twin.campaign.report import write_report

    campaign, out, _ = small
    report = write_report(out, campaign).read_text()
    summaries = [json.loads(p.read_text()) for p in (out / "runs").glob("*/summary.json")]
    names = sorted(summaries[0]["estimators"])
    assert len(summaries) == 12 and len(names) >= 6
    wins = {n: [0, 0, 0] for n in names}
    for s in summaries:
        e = s["estimators"]
        for n in names:
            t = all(e[n]["rms_translation_m"] < e[o]["rms_translation_m"] for o in names if o != n)
            r = all(e[n]["rms_rotation_deg"] < e[o]["rms_rotation_deg"] for o in names if o != n)
            wins[n] = [wins[n][0] + t, wins[n][1] + r, wins[n][2] + (t and r)]
    assert sum(w[0] for w in wins.values()) == 12  # every run has its least deviating one
    for n in names:
        med_t = 1e3 * float(np.median([s["estimators"][n]["rms_translation_m"] for s in summaries]))
        med_r = float(np.median([s["estimators"][n]["rms_rotation_deg"] for s in summaries]))
        line = (
            f"| {n} | {med_t:.2f} mm | {med_r:.3f}° | {wins[n][0]} | {wins[n][1]} | {wins[n][2]} |"
        )
        assert line in report, line


def test_each_block_compares_the_estimators_its_runs_report():
    """A camera-off block has no image estimate: its runs still count, among the others."""
    from cdpr_twin.campaign.report import estimator_wins

    nan = np.nan
    columns = {  # 2 camera-on runs, 2 camera-off runs (image absent), 1 failed run
        "block": np.array(["on", "on", "off", "off", "off"], dtype=object),
        "est.a.rms_t_m": np.array([1.0, 3.0, 2.0, 5.0, nan]),
        "est.a.rms_r_deg": np.array([0.1, 0.1, 0.2, 0.5, nan]),
        "est.b.rms_t_m": np.array([2.0, 2.0, 3.0, 4.0, nan]),
        "est.b.rms_r_deg": np.array([0.2, 0.1, 0.1, 0.4, nan]),
        "est.image.rms_t_m": np.array([0.5, 9.0, nan, nan, nan]),
        "est.image.rms_r_deg": np.array([0.3, 0.3, nan, nan, nan]),
    }
    ok = np.array([True, True, True, True, False])
    on, off = (estimator_wins(columns, ok, b) for b in ("on", "off"))
    assert on["runs"] == 2 and sorted(on["estimators"]) == ["a", "b", "image"]
    assert off["runs"] == 2 and sorted(off["estimators"]) == ["a", "b"]
    assert [on["estimators"][n]["best_t"] for n in ("a", "b", "image")] == [0, 1, 1]
    assert [on["estimators"][n]["best_r"] for n in ("a", "b", "image")] == [1, 0, 0]  # a tie
    assert off["estimators"]["a"] | {} == {
        "rms_t_mm": 3500.0,
        "rms_r_deg": 0.35,
        "best_t": 1,
        "best_r": 0,
        "best_both": 0,
    }
    assert off["estimators"]["b"]["best_r"] == 2 and off["estimators"]["b"]["best_both"] == 1


def test_an_axis_effect_is_shown_within_each_cell_of_the_other_factors():
    """Interactions: the axis's medians per block and per value of the other grid axes, each
    computed here from the runs by hand; a failed run is left out, and a block without an axis
    has its own cell ("–")."""
    from cdpr_twin.campaign.report import axis_cells

    nan = np.nan
    columns = {  # block a varies f, g and h; block b varies f only; run 7 failed
        "block": np.array(["a"] * 6 + ["b"] * 3, dtype=object),
        "param.f": np.array([0.0, 0.0, 0.1, 0.1, 0.0, 0.1, 0.0, 0.1, 0.1]),
        "param.g": np.array(["x", "x", "x", "x", "y", "y", None, None, None], dtype=object),
        "param.h": np.array([1.0, 1.0, 1.0, 1.0, 1.0, 1.0, nan, nan, nan]),  # as from Parquet
        "final_t_m": np.array([1.0, 3.0, 5.0, 7.0, 2.0, 4.0, 6.0, 100.0, 8.0]) * 1e-3,
        "final_r_deg": np.array([0.1, 0.3, 0.5, 0.7, 0.2, 0.4, 0.6, 10.0, 0.8]),
    }
    ok = np.array([True] * 7 + [False, True])
    by_g = axis_cells(columns, ok, "f", ["block", "param.g"], "final_t_m")
    assert by_g.keys() == {("a", "x"), ("a", "y"), ("b", None)}
    assert by_g[("a", "x")] == {0.0: (2.0, 0.2, 2), 0.1: (6.0, 0.6, 2)}
    assert by_g[("a", "y")] == {0.0: (2.0, 0.2, 1), 0.1: (4.0, 0.4, 1)}
    assert by_g[("b", None)] == {0.0: (6.0, 0.6, 1), 0.1: (8.0, 0.8, 1)}  # not the failed 100
    by_h = axis_cells(columns, ok, "f", ["block", "param.h"], "final_t_m")
    assert by_h.keys() == {("a", 1.0), ("b", None)}
    assert by_h[("a", 1.0)][0.1] == (pytest.approx(5.0), pytest.approx(0.5), 3)


def test_the_report_says_why_runs_failed():
    from cdpr_twin.campaign.report import _failure_section

    columns = {
        "name": np.array(["r1", "r2", "r3", "r4", "r5", "r6"], dtype=object),
        "error": np.array(["", "E: a|b", "E: c", "E: a|b", "E: a|b", "E: a|b"], dtype=object),
    }
    lines = _failure_section(columns, np.array([True, False, False, False, False, False]))
    assert lines[4] == "| 4 | E: a/b | `r2`, `r4`, `r5`, … |"  # most frequent first
    assert lines[5] == "| 1 | E: c | `r3` |" and len(lines) == 7
    assert _failure_section(columns, np.ones(6, bool)) == []


def test_a_part_keeps_every_rows_columns_when_a_failed_run_comes_first(tmp_path):
    """A failed run has no metrics; the runs written in the same part keep theirs."""
    from cdpr_twin.campaign.table import ResultTable, flatten

    fields = [
        {"run_id": f"r{i}", "block": "b", "name": f"n{i}", "params": {"seed": i}} for i in (1, 2)
    ]
    est = {
        "max_translation_m": 1.0,
        "max_rotation_deg": 2.0,
        "rms_translation_m": 3.0,
        "rms_rotation_deg": 4.0,
        "final_translation_m": 5.0,
        "final_rotation_deg": 6.0,
        "invalid_updates": 7,
    }
    goal = {"translation_m": 0.5, "rotation_deg": 1.5}
    ran = {"status": "converged", "final_error_vs_goal": goal, "estimators": {"control": est}}
    table = ResultTable(tmp_path, every=10)
    table.add(flatten(fields[0], None, error="ScenarioError: refused"))
    table.add(flatten(fields[1], ran))
    table.gather()
    rows = load_table(tmp_path).to_pylist()
    assert [r["ok"] for r in rows] == [False, True]
    assert rows[1]["final_t_m"] == 0.5 and rows[1]["est.control.rms_r_deg"] == 4.0
    assert rows[1]["est.control.invalid"] == 7 and rows[0]["est.control.rms_t_m"] is None


def test_an_axis_of_ints_and_floats_gathers_into_one_column(tmp_path):
    """values = [0, 0.5]: parts typed int64 and double, one float column in the table."""
    from cdpr_twin.campaign.table import ResultTable, flatten

    table = ResultTable(tmp_path, every=1)
    for i, v in enumerate((0, 0.5)):
        table.add(flatten({"run_id": f"r{i}", "block": "b", "name": "n", "params": {"g": v}}, {}))
    table.gather()
    assert load_table(tmp_path).column("param.g").to_pylist() == [0.0, 0.5]


def test_ray_runs_the_same_campaign_to_the_same_numbers(small, tmp_path):
    ray = pytest.importorskip("ray", reason="Ray has no wheel for this platform")
    campaign, out, _ = small
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        info = run_campaign(campaign, tmp_path / "ray", ray_address=True)
    finally:
        ray.shutdown()
    assert info["executor"] == "ray" and info["ran_now"] == 12
    local = {r["run_id"]: r for r in load_table(out).to_pylist()}
    for row in load_table(tmp_path / "ray").to_pylist():
        want = local[row["run_id"]]
        for key in want:
            if key not in ("wall_time_s", "summary"):
                assert row[key] == want[key], key  # same seeds ⇒ the same numbers


def test_resume_after_a_killed_campaign_reruns_only_the_missing_runs(small, tmp_path):
    campaign, _, _ = small
    out = tmp_path / "killed"
    cmd = [
        sys.executable,
        "-m",
        "cdpr_twin",
        "campaign",
        str(campaign.source),
        "--out",
        str(out),
        "--workers",
        "1",
    ]
    proc = subprocess.Popen(
        cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True
    )
    deadline = time.monotonic() + 300
    while not list((out / "parts").glob("part-*.parquet")) and time.monotonic() < deadline:
        time.sleep(0.2)
    # no chance to clean up: the campaign and its workers killed at once, as a job is (killing
    # the parent alone left its spawned worker running after the test)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    done = {
        r
        for p in (out / "parts").glob("part-*.parquet")
        for r in pq.read_table(p).column("run_id").to_pylist()
    }
    assert 0 < len(done) < 12
    info = run_campaign(campaign, out, workers=2, resume=True)  # takes over the stale lock
    assert info["ran_now"] == 12 - len(done) and info["skipped_done"] == len(done)
    ids = load_table(out).column("run_id").to_pylist()
    assert sorted(ids) == sorted(t.run_id for t in campaign.tasks)


def test_ctrl_c_stops_with_a_valid_table(small, tmp_path):
    campaign, _, _ = small
    out = tmp_path / "stopped"

    def stop(done, total, row):
        if done == 4:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_campaign(campaign, out, workers=2, progress=stop)
    info = json.loads((out / "campaign.json").read_text())
    assert info["status"] == "interrupted" and info["ran_now"] == 4
    assert len(pq.read_table(out / "results.parquet")) == 4


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (('key = "seed"', 'key = "sede"'), "sede: unknown field"),
        (('key = "truth.exit_point_std"', 'key = "truth.exit_pont_std"'), "exit_pont_std"),
        (("values = [0.0, 0.012]", "values = [0.0, -1.0]"), "exit_point_std"),
        (('draw = "integers"', 'draw = "gaussian"'), "axes[2].draw: must be one of"),
        (("samples = 3", "samples = 0"), "samples: must be an integer ≥ 1"),
        # a start pose the run would refuse: refused before any run, as `run` refuses it
        (_START_AXIS, "start.pose: start.pose at position [9.0, 9.0, 9.0] m puts"),
        (
            (_START_AXIS[0], _START_AXIS[1].replace("9, 9, 9", "0.5, 0.5, 0.0")),
            "start.pose is outside the wrench-feasible workspace",
        ),
    ],
)
def test_a_bad_campaign_is_a_one_line_error_before_anything_runs(tmp_path, capsys, change, message):
    path = tmp_path / "bad.toml"
    path.write_text(SMALL.replace(*change))
    with pytest.raises(CampaignError, match=message.replace("[", r"\[").replace("]", r"\]")):
        load_campaign(path)
    assert main(["campaign", str(path), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and str(path) in err and message.split(":")[0] in err
    assert not (tmp_path / "out").exists()


def _canonical(value):
    """A scenario's content for comparison: arrays as lists, dataclasses as dicts, names out."""
    import dataclasses

    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        skip = {"name", "source", "description", "overrides"}
        return {
            f.name: _canonical(getattr(value, f.name))
            for f in dataclasses.fields(value)
            if f.name not in skip
        }
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, dict | tuple | list) or hasattr(value, "items"):
        if hasattr(value, "items"):
            return {k: _canonical(v) for k, v in value.items()}
        return [_canonical(v) for v in value]
    return value


def test_the_paper_study_campaign_is_what_reproduce_runs():
    """campaigns/paper_study.toml and ``reproduce``'s plan: the same runs, scenario for scenario
    (each campaign task's resolved scenario equals the plan's file with its run's overrides)."""
    from cdpr_twin.scenario.loading import scenario_from_data
    from cdpr_twin.study.plan import plan, spec_scenario

    tasks = load_campaign(
        Path(__file__).resolve().parents[2] / "campaigns" / "paper_study.toml"
    ).tasks
    specs = plan()
    assert len(tasks) == len(specs) == 45
    planned = {(s.kind, s.in_loop, s.seed): _canonical(spec_scenario(s)) for s in specs}
    for t in tasks:
        key = (t.block, t.params.get("estimators.in_loop"), t.params["seed"])
        assert _canonical(scenario_from_data(t.data, t.source)) == planned.pop(key), key
    assert not planned


def _committed_studies() -> list[str]:
    """The campaign studies committed under docs/ (a run's untracked output is not one)."""
    try:
        out = subprocess.run(
            ["git", "ls-files", "docs/*/campaign.json"],
            cwd=ROOT,
            capture_output=True,
            text=True,
            check=True,
        ).stdout
        paths = [ROOT / p for p in out.split()]
    except (OSError, subprocess.CalledProcessError):  # not a git checkout: what is there
        paths = list((ROOT / "docs").rglob("campaign.json"))
    # (a study may sit inside another's folder: docs/error_budget/pbvs_repeatability)
    return sorted(p.parent.relative_to(ROOT / "docs").as_posix() for p in paths)


@pytest.mark.parametrize("study", _committed_studies())
def test_a_committed_campaign_report_is_what_its_table_gives(study, tmp_path):
    """The reports under docs/ are recomputed from their committed tables by today's code."""
    from cdpr_twin.campaign.report import write_report

    committed = ROOT / "docs" / study
    info = json.loads((committed / "campaign.json").read_text())
    assert info["status"] == "completed" and info["table"] == f"docs/{study}/results.parquet"
    copy = tmp_path / study  # the table only: the report is computed from it
    shutil.copytree(committed / "parts", copy / "parts")
    shutil.copy(committed / "results.parquet", copy)
    report = write_report(copy, load_campaign(ROOT / info["source"]))
    assert report.read_text() == (committed / "report.md").read_text()


def test_the_table_follows_the_campaign_order_whatever_order_runs_end_in(tmp_path):
    from cdpr_twin.campaign.table import ResultTable, flatten

    ids = [f"{i:016x}" for i in (5, 3, 9, 1)]  # the campaign's order
    table = ResultTable(tmp_path, every=1)
    for run_id in ("0000000000000009", "0000000000000001", "0000000000000005", "000000000000000a"):
        task = {"run_id": run_id, "block": "b", "name": run_id, "params": {}}
        table.add(flatten(task, None, "not run"))  # one part each, as the workers ended them
    table.gather(ids)
    got = load_table(tmp_path).column("run_id").to_pylist()
    assert got == [ids[0], ids[2], ids[3], "000000000000000a"]  # (3: not run yet; a: last)


def test_a_damaged_part_of_a_campaign_table_is_a_one_line_error(tmp_path):
    parts = tmp_path / "parts"
    parts.mkdir()
    (parts / "part-00000.parquet").write_bytes(b"PAR1 not really parquet")
    with pytest.raises(OutputDirError, match=r"part-00000\.parquet is not a readable Parquet"):
        load_table(tmp_path)
    with pytest.raises(OutputDirError, match="delete it and run with --resume"):
        read_parquet(parts / "part-00000.parquet", ["run_id"])


def test_a_campaign_names_a_shipped_scenario_as_run_does(tmp_path):
    from cdpr_twin.campaign import CampaignError, load_campaign

    axes = '[[axes]]\nkey = "controller.gain"\nvalues = [0.2, 0.4]\n'
    by_path = tmp_path / "by_path.toml"
    by_path.write_text(f'name = "g"\nscenario = "{ROOT}/scenarios/paper_pbvs.toml"\n{axes}')
    by_name = tmp_path / "by_name.toml"
    by_name.write_text(f'name = "g"\nscenario = "paper_pbvs"\n{axes}')
    ids = [[t.run_id for t in load_campaign(p).tasks] for p in (by_path, by_name)]
    assert ids[0] == ids[1] and len(ids[0]) == 2  # the same runs
    by_name.write_text(f'name = "g"\nscenario = "paper_pbv"\n{axes}')
    with pytest.raises(CampaignError, match=r"scenario: no scenario named 'paper_pbv'; choose one"):
        load_campaign(by_name)


def _campaign(tmp_path: Path, name: str, duration: float, camera: bool, seeds=(1,)) -> Path:
    path = tmp_path / f"{name}.toml"
    path.write_text(
        f'name = "{name}"\nscenario = "{ROOT}/scenarios/paper_open_loop.toml"\n\n'
        f'[overrides]\n"sensors.camera" = {str(camera).lower()}\nduration = {duration}\n\n'
        f'[[axes]]\nkey = "seed"\nvalues = {list(seeds)}\n'
    )
    return path


def _run_files(directory: Path) -> dict[str, bytes]:
    directory.mkdir(parents=True, exist_ok=True)
    files = {"summary.json": b'{"status": "completed"}\n', "timeseries.csv": b"time\n0\n"}
    for name, content in files.items():
        (directory / name).write_bytes(content)
    return files


def test_a_campaign_refuses_a_runs_directory_and_leaves_the_run_intact(tmp_path, capsys):
    files = _run_files(tmp_path / "a_run")
    src = _campaign(tmp_path, "tiny", 0.2, camera=False)
    for extra in ([], ["--resume"]):
        assert main(["campaign", str(src), "--out", str(tmp_path / "a_run"), *extra]) == 2
        err = capsys.readouterr().err.strip()
        assert "holds another command's outputs" in err and "\n" not in err
    assert {p.name: p.read_bytes() for p in (tmp_path / "a_run").iterdir()} == files


def test_a_run_refuses_a_campaigns_directory(tmp_path, capsys):
    out = tmp_path / "a_campaign"
    out.mkdir()
    (out / "campaign.json").write_text('{"campaign": "x"}\n')
    argv = ["run", "paper_open_loop", "--out", str(out), "--duration", "0.08", "--no-camera"]
    assert main(argv) == 2
    assert "holds another command's outputs (campaign.json)" in capsys.readouterr().err
    assert [p.name for p in out.iterdir()] == ["campaign.json"]


def test_resuming_with_another_campaign_is_refused_and_the_table_kept(tmp_path):
    first = load_campaign(_campaign(tmp_path, "first", 0.2, camera=False))
    out = tmp_path / "out"
    assert run_campaign(first, out, workers=1)["ran_now"] == 1
    table = load_table(out).to_pylist()
    other = load_campaign(_campaign(tmp_path, "other", 0.12, camera=False, seeds=(1, 2)))
    assert {t.run_id for t in other.tasks}.isdisjoint(t.run_id for t in first.tasks)
    with pytest.raises(OutputDirError, match=r"does not have .* mix them into one table"):
        run_campaign(other, out, workers=1, resume=True)
    assert load_table(out).to_pylist() == table
    # the same campaign with one more run resumes: the old rows are its own
    grown = load_campaign(_campaign(tmp_path, "first", 0.2, camera=False, seeds=(1, 2)))
    assert run_campaign(grown, out, workers=1, resume=True)["ran_now"] == 1
    assert len(pq.read_table(out / "results.parquet")) == 2


def test_an_empty_out_is_refused_not_taken_for_the_current_directory(tmp_path, capsys, monkeypatch):
    src = _campaign(tmp_path, "tiny", 0.2, camera=False)
    monkeypatch.chdir(tmp_path)  # were it taken, the campaign would write here
    with pytest.raises(SystemExit) as exit_:
        main(["campaign", str(src), "--out", ""])
    assert exit_.value.code == 2 and "--out: is empty" in capsys.readouterr().err


NAN_ESTIMATOR = """
import numpy as np
from cdpr_twin import plugins
from cdpr_twin.estimators.base import NO_INPUTS, Estimator
from cdpr_twin.types import PoseEstimate


@plugins.register
class Broken(Estimator):
    name = "broken"

    def update(self, measurement, inputs=NO_INPUTS):
        self._check_reset()
        return PoseEstimate(measurement.time, np.full((4, 4), np.nan))
"""


def test_an_estimator_that_never_estimates_has_no_deviation_and_wins_nothing(tmp_path):
    # before: max and RMS deviations of 0 over no estimate at all, and in a campaign's report
    # the broken estimator "deviated least" in every run
    (tmp_path / "broken.py").write_text(NAN_ESTIMATOR)
    text = (ROOT / "scenarios" / "paper_open_loop.toml").read_text()
    text = text.replace('name = "paper_open_loop"', 'name = "broken"\nplugins = ["broken.py"]')
    text = text.replace('passive = ["image", ', 'passive = ["broken", "image", ')
    (tmp_path / "broken.toml").write_text(text)
    src = tmp_path / "c.toml"
    src.write_text(
        f'name = "c"\nscenario = "{tmp_path / "broken.toml"}"\n\n[overrides]\n'
        '"sensors.camera" = false\nduration = 0.2\n\n[[axes]]\nkey = "seed"\nvalues = [1, 2]\n'
    )
    out = tmp_path / "out"
    assert main(["campaign", str(src), "--out", str(out)]) == 0
    rows = load_table(out).to_pylist()
    for row in rows:
        broken = json.loads(row["summary"])["estimators"]["broken"]
        assert broken["invalid_updates"] == 6  # the start and five ticks, none finite
        assert broken["max_translation_m"] is None and broken["rms_translation_m"] is None
        assert math.isnan(row["est.broken.rms_t_m"]) and row["est.model_simple.rms_t_m"] > 0
    report = (out / "report.md").read_text()
    assert "| model_simple |" in report and "| broken |" not in report


def test_a_resume_that_cannot_write_its_table_leaves_no_stale_table(tmp_path, monkeypatch):
    """A full disk at the end of a resume left results.parquet (and campaign.json) describing
    the runs before it under their final names; now they go when new runs start, and the next
    --resume writes them from the parts."""
    from cdpr_twin.campaign import table as table_mod
    from cdpr_twin.files.transaction import OutputError

    out = tmp_path / "out"
    two = load_campaign(_campaign(tmp_path, "grow", 0.2, camera=False, seeds=(1, 2)))
    assert run_campaign(two, out, workers=1)["ran_now"] == 2
    (out / "report.md").write_text("the report of 2 runs\n")
    three = load_campaign(_campaign(tmp_path, "grow", 0.2, camera=False, seeds=(1, 2, 3)))

    def disk_full(self, order=()):
        raise OutputError(out / "results.parquet.partial", "No space left on device")

    with monkeypatch.context() as m:
        m.setattr(table_mod.ResultTable, "gather", disk_full)
        with pytest.raises(OutputError):
            run_campaign(three, out, workers=1, resume=True)
    assert not (out / "results.parquet").exists() and not (out / "report.md").exists()
    assert json.loads((out / "campaign.json").read_text())["status"] == "running"
    again = run_campaign(three, out, workers=1, resume=True)
    assert again["ran_now"] == 0 and again["status"] == "completed"
    assert sorted(load_table(out).column("seed").to_pylist()) == [1, 2, 3]


@pytest.mark.parametrize("study", _committed_studies())
def test_a_reports_variance_shares_add_up_to_its_fit(study):
    """Deviation groups drawn independently of each other: their shares sum to the fit's R².

    The cross terms of the fitted parts vanish up to sampling error (≈ regressors / robots, 0.09
    for 90 deviations over 1 000 robots); a fit over a mixture of populations (other
    tolerances, repetitions of a few robots) breaks this, with shares far above 100 %.
    """
    text = (ROOT / "docs" / study / "report.md").read_text()
    for section in text.split("## Which calibration error drives the error at p1")[1:]:
        r2 = float(re.search(r"R² = ([0-9.]+)", section).group(1))
        shares = [float(s) for s in re.findall(r"^\| [^|]+ \| ([0-9.]+) %[^|]*\|", section, re.M)]
        assert len(shares) >= 4
        assert sum(shares) / 100 == pytest.approx(r2, abs=0.1)
