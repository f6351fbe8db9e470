"""A scenario's or a campaign's ``plugins`` run code: each one a command loads is named on stderr.

One line per plugin file or module, once a process, before its code runs; a campaign's workers
(which load them again) say nothing more. Truth: the command's stderr, read from the pipe of a
fresh process (in this one, a plugin already loaded is not loaded again), and the plugins
module's and the documentation's own words (the tutorial on writing an estimator).
"""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LOADING = "cdpr-twin: loading plugin "
TRUST = "a scenario or campaign that names plugins runs their code: run only files you trust"

PLUGIN = """
from cdpr_twin import plugins
from cdpr_twin.estimators.control_based import ControlEstimator


@plugins.register
class {cls}(ControlEstimator):
    name = "{name}"
"""


def _plugins(tmp_path: Path) -> Path:
    """A file plugin beside a scenario naming it twice, a module plugin; the scenario."""
    (tmp_path / "mods").mkdir()
    (tmp_path / "beside.py").write_text(PLUGIN.format(cls="Beside", name="beside"))
    (tmp_path / "mods" / "trust_mod.py").write_text(PLUGIN.format(cls="Mod", name="from_mod"))
    text = (ROOT / "scenarios" / "paper_open_loop.toml").read_text()
    text = text.replace('"../models/', f'"{ROOT}/models/')
    text = text.replace('passive = ["', 'passive = ["beside", "from_mod", "', 1)
    scenario = tmp_path / "s.toml"
    scenario.write_text('plugins = ["beside.py", "trust_mod", "./beside.py"]\n' + text)
    return scenario


def _command(tmp_path: Path, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(tmp_path / "mods")}
    command = [sys.executable, "-m", "cdpr_twin", *args]
    return subprocess.run(
        command, capture_output=True, text=True, env=env, cwd=tmp_path, timeout=600
    )


def test_a_run_names_each_plugin_it_loads_once(tmp_path):
    scenario = _plugins(tmp_path)
    args = ["--out", str(tmp_path / "out"), "--duration", "0.2", "--no-camera"]
    proc = _command(tmp_path, "run", str(scenario), *args)
    assert proc.returncode == 0, proc.stderr
    said = [line for line in proc.stderr.splitlines() if line.startswith("cdpr-twin")]
    assert said == [f"{LOADING}{tmp_path / 'beside.py'}", f"{LOADING}module trust_mod"]
    assert "from_mod" in proc.stdout and "beside" in proc.stdout  # they did run


def test_a_campaign_names_its_plugins_once_not_once_a_worker(tmp_path):
    scenario = _plugins(tmp_path)
    campaign = tmp_path / "c.toml"
    campaign.write_text(
        f'name = "c"\nscenario = "{scenario}"\n\n[overrides]\n"sensors.camera" = false\n'
        'duration = 0.2\n\n[[axes]]\nkey = "seed"\nvalues = [1, 2, 3]\n'
    )
    proc = _command(
        tmp_path, "campaign", str(campaign), "--out", str(tmp_path / "out"), "--workers", "2"
    )
    assert proc.returncode == 0, proc.stderr
    loading = [line for line in proc.stderr.splitlines() if line.startswith(LOADING)]
    assert loading == [f"{LOADING}{tmp_path / 'beside.py'}", f"{LOADING}module trust_mod"]


def test_where_plugins_are_taught_says_they_run_code():
    from cdpr_twin import plugins

    assert TRUST in " ".join(plugins.__doc__.split()).lower()
    page = ROOT / "docs" / "tutorials" / "own-estimator.md"
    assert TRUST in " ".join(page.read_text().split()).lower()
