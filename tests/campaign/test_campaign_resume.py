"""``--resume`` refuses to mix two versions of a file the runs read.

A run's id hashes its resolved scenario, not the files it names: before, a campaign resumed
after its ``[model] nominal`` description was replaced ran the new runs on the new robot model
and the old ones stayed on the old (0.6 mm against 9.46 mm at p1), in
one table, with the same ``nominal_model`` path and no warning.
"""

import json
from pathlib import Path

from cdpr_twin.cli import main

ROOT = Path(__file__).resolve().parents[2]


def _campaign(tmp_path: Path, seeds: str) -> Path:
    desc = (ROOT / "docs" / "calibration" / "robot_19" / "calibrated_robot.toml").read_text()
    (tmp_path / "nominal.toml").write_text(desc.replace('"../../../models/', f'"{ROOT}/models/'))
    text = (ROOT / "scenarios" / "paper_open_loop.toml").read_text()
    text = text.replace('"../models/', f'"{ROOT}/models/')
    text = text.replace("[model]\n", '[model]\nnominal = "nominal.toml"\n', 1)
    (tmp_path / "s.toml").write_text(text)
    src = tmp_path / "c.toml"
    src.write_text(
        'name = "inputs"\nscenario = "s.toml"\n[overrides]\n"sensors.camera" = false\n'
        f'duration = 0.08\n[[axes]]\nkey = "seed"\nvalues = {seeds}\n'
    )
    return src


def test_resume_after_a_named_file_changed_is_refused_and_restoring_it_resumes(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(["campaign", str(_campaign(tmp_path, "[1]")), "--out", str(out)]) == 0
    recorded = json.loads((out / "campaign.json").read_text())["inputs"]
    nominal = tmp_path / "nominal.toml"
    assert list(recorded) == [str(nominal)]
    original = nominal.read_text()
    src = _campaign(tmp_path, "[1, 2]")  # one more run, the description rewritten the same
    nominal.write_text(original.replace("[frame]", "# edited\n[frame]", 1))
    capsys.readouterr()
    assert main(["campaign", str(src), "--out", str(out), "--resume"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and f"{nominal} changed since the runs in {out}" in err
    nominal.write_text(original)  # restored: the resume runs the missing run only
    assert main(["campaign", str(src), "--out", str(out), "--resume"]) == 0
    summary = json.loads((out / "campaign.json").read_text())
    assert (summary["ran_now"], summary["skipped_done"], summary["status"]) == (1, 1, "completed")
