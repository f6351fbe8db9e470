"""A plugin that calls ``sys.exit()`` fails its run, not the command with the plugin's code.

An estimator written outside the package calls ``sys.exit(5)`` at its third update, or at its
import. The command must not end silently with the plugin's code (3 is the command's *fault*
code) nor leave ``summary.json`` saying ``running``: the run is recorded as failed and the
command says why in one line; a campaign records the failed run as a row.
"""

import json
from pathlib import Path

import pyarrow.parquet as pq
import pytest

from cdpr_twin.cli import main

ROOT = Path(__file__).resolve().parent.parent

PLUGIN = """
import sys

from cdpr_twin import plugins
from cdpr_twin.estimators.control_based import ControlEstimator

{at_import}

@plugins.register
class Exiting(ControlEstimator):
    name = "exiting"

    def __init__(self, geometry, options):
        super().__init__(geometry, options)
        if {at_build}:
            sys.exit(4)

    def update(self, measurement, inputs=None):
        self.calls = getattr(self, "calls", 0) + 1
        if self.calls == 3:
            sys.exit(5)
        return super().update(measurement)
"""


def _scenario(tmp_path: Path, at_import: bool = False, at_build: bool = False) -> Path:
    """The paper's open loop with the plugin (one file for all tests: it registers once)."""
    stem = "exiting_at_import" if at_import else "exiting_at_build" if at_build else "exiting"
    plugin = tmp_path.parent / f"{stem}.py"
    if not plugin.exists():
        text = PLUGIN.replace('name = "exiting"', f'name = "{stem}"')
        plugin.write_text(
            text.format(at_import="sys.exit(3)" if at_import else "", at_build=at_build)
        )
    text = (ROOT / "scenarios" / "paper_open_loop.toml").read_text()
    text = text.replace('"../models/', f'"{ROOT}/models/')
    text = text.replace('passive = ["', f'passive = ["{stem}", "', 1)
    path = tmp_path / "s.toml"
    path.write_text(f'plugins = ["{plugin}"]\n' + text)
    return path


LOADING = "cdpr-twin: loading plugin "


def _error_lines(err: str) -> list[str]:
    """The command's lines (not progress), but the plugins' names as they load."""
    lines = [line for line in err.splitlines() if line.startswith("cdpr-twin")]
    return [line for line in lines if not line.startswith(LOADING)]


def _argv(path: Path, out: Path) -> list[str]:
    return ["run", str(path), "--out", str(out), "--duration", "0.4", "--no-camera"]


def test_a_plugins_exit_mid_run_fails_the_run_in_one_line(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(_argv(_scenario(tmp_path), out)) == 1  # was: 5, silently
    (err,) = _error_lines(capsys.readouterr().err)
    assert "sys.exit(5)" in err
    status = json.loads((out / "summary.json").read_text())["status"]
    assert status == "failed: SystemExit: 5"  # was: "running"
    assert not list(out.glob("*.partial")) and not (out / ".lock").exists()


def test_a_plugins_exit_at_import_refuses_the_scenario(tmp_path, capsys):
    out = tmp_path / "out"
    assert main(_argv(_scenario(tmp_path, at_import=True), out)) == 2  # was: 3, silently
    printed = capsys.readouterr().err
    (err,) = _error_lines(printed)
    assert "called sys.exit(3) while loading" in err
    # named before it ran (a failed load is not cached: named each time it is tried)
    assert printed.startswith(f"{LOADING}{tmp_path.parent / 'exiting_at_import.py'}\n")
    assert not out.exists()


@pytest.mark.parametrize("at_build", [False, True])
def test_a_campaign_records_a_plugins_exit_as_a_failed_run(tmp_path, at_build):
    """Mid-run, or while the estimator is built (that one ended the campaign "completed")."""
    campaign = tmp_path / "c.toml"
    campaign.write_text(
        f'name = "c"\nscenario = "{_scenario(tmp_path, at_build=at_build)}"\n\n'
        '[overrides]\n"sensors.camera" = false\nduration = 0.4\n\n'
        '[[axes]]\nkey = "seed"\nvalues = [1, 2]\n'
    )
    out = tmp_path / "campaign"
    main(["campaign", str(campaign), "--out", str(out), "--workers", "1"])
    rows = pq.read_table(out / "results.parquet").to_pylist()
    assert len(rows) == 2  # was: no table, and campaign.json saying "completed"
    why = "estimators.exiting_at_build: SystemExit: 4" if at_build else "RuntimeError: sys.exit(5)"
    assert all(r["status"].startswith("failed") and why in r["status"] for r in rows), rows
