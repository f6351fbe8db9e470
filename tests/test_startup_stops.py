"""A Ctrl-C or SIGTERM at start-up, while the command imports numpy, MuJoCo, SciPy…, is a stop.

Before: ``cdpr-twin run paper_open_loop & sleep 0.2; kill -INT $!`` printed a
``KeyboardInterrupt`` traceback from numpy's import, as the console script imported the CLI
before any handler existed. The start-up is made to wait at a chosen import (a
``sitecustomize`` on ``PYTHONPATH`` holds the import of one module: it writes a marker file and
sleeps), so the signal lands there, every time. Truth: the process's exit code, its stderr's
lines, and the output directory (never made). And at the other end: a signal while the
interpreter ends, after the command has its exit code, changes nothing.
"""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

COMMAND = Path(sys.executable).parent / "cdpr-twin"
"""The installed console script (``[project.scripts]``), as a user runs it."""

HOLD = """
import os
import sys
import time

class _Hold:
    def find_spec(self, name, path=None, target=None):
        if name == os.environ["HOLD_IMPORT_OF"]:
            sys.meta_path.remove(self)
            open(os.environ["HOLD_MARKER"], "w").close()
            time.sleep(120)  # the signal ends it
        return None

sys.meta_path.insert(0, _Hold())
"""


def _stopped_at(tmp_path: Path, module: str, signum: int, argv: list[str]):
    """Start ``argv`` held at the import of ``module``; send ``signum`` there; its result."""
    (tmp_path / "hook").mkdir()
    (tmp_path / "hook" / "sitecustomize.py").write_text(HOLD)
    marker = tmp_path / "held"
    env = {
        **os.environ,
        "PYTHONPATH": str(tmp_path / "hook"),
        "HOLD_IMPORT_OF": module,
        "HOLD_MARKER": str(marker),
    }
    env.pop("RUST_LOG", None)
    proc = subprocess.Popen(
        argv,
        cwd=tmp_path,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        # as from a terminal: Ctrl-C not ignored (a script's background job ignores it)
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    deadline = time.monotonic() + 120
    while not marker.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    assert marker.exists(), f"never reached the import of {module}: {proc.communicate()}"
    proc.send_signal(signum)
    out, err = proc.communicate(timeout=120)
    return proc.returncode, out, err


@pytest.mark.parametrize(
    ("module", "said"),
    [
        ("cdpr_twin.cli", "cdpr-twin: interrupted while starting"),  # before any heavy import
        ("numpy.linalg", "cdpr-twin: interrupted while starting"),  # inside numpy's import
        ("cdpr_twin.cli.campaign", "cdpr-twin: interrupted while starting"),
        ("cdpr_twin.run.runner", "cdpr-twin run: interrupted"),  # the command's own imports
        ("mujoco", "cdpr-twin: interrupted before this run saved any output in {out}"),
    ],
)
def test_ctrl_c_during_start_up_exits_130_in_one_line(tmp_path, module, said):
    assert COMMAND.is_file(), f"{COMMAND}: install the package (pip install -e .)"
    out = tmp_path / "out"
    argv = [str(COMMAND), "run", "paper_open_loop", "--no-camera", "--out", str(out)]
    code, _, err = _stopped_at(tmp_path, module, signal.SIGINT, argv)
    assert code == 130, err
    assert "Traceback" not in err
    assert err.splitlines() == [said.format(out=out)]
    assert not out.exists()


@pytest.mark.parametrize("module", ["numpy.linalg", "cdpr_twin.run.runner"])
def test_sigterm_during_start_up_exits_143_in_one_line(tmp_path, module):
    out = tmp_path / "out"
    argv = [sys.executable, "-m", "cdpr_twin", "run", "paper_open_loop", "--out", str(out)]
    code, _, err = _stopped_at(tmp_path, module, signal.SIGTERM, argv)
    assert code == 143, err
    assert "Traceback" not in err
    assert len(err.splitlines()) == 1 and "terminated" in err
    assert not out.exists()


def test_the_console_script_and_python_m_use_the_entry_point_that_handles_stops_first():
    # truth: the installed script's own text (what pip generated from pyproject.toml)
    assert "from cdpr_twin.entry import main" in COMMAND.read_text()
    main = Path(__file__).resolve().parent.parent / "cdpr_twin" / "__main__.py"
    assert "from cdpr_twin.entry import main" in main.read_text()


HOLD_AT_EXIT = """
import os
import sys
import time


class _HeldAtExit:
    def __del__(self):  # collected as the interpreter ends, after its signal handling did
        open(os.environ["HOLD_MARKER"], "w").close()
        time.sleep(2.0)


sys.modules["_held_at_exit"] = _HeldAtExit()
"""


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_a_signal_while_the_interpreter_ends_does_not_change_the_exit_code(tmp_path, signum):
    # before: Python puts back the default action as it ends, and a SIGTERM then ended a
    # command that had printed its result with 143 (a run that said "interrupted" too)
    (tmp_path / "hook").mkdir()
    (tmp_path / "hook" / "sitecustomize.py").write_text(HOLD_AT_EXIT)
    marker = tmp_path / "held"
    env = {**os.environ, "PYTHONPATH": str(tmp_path / "hook"), "HOLD_MARKER": str(marker)}
    proc = subprocess.Popen(
        [str(COMMAND), "scenarios", "list"],
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    deadline = time.monotonic() + 120
    while not marker.exists() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.01)
    assert marker.exists(), proc.communicate()
    proc.send_signal(signum)
    out, err = proc.communicate(timeout=120)
    assert proc.returncode == 0, err
    assert "paper_open_loop" in out and err == ""


def test_ctrl_c_while_a_command_starts_is_one_line_not_a_traceback(monkeypatch, capsys):
    """Ctrl-C before a command's own handling (its imports, reading the scenario) printed a
    KeyboardInterrupt traceback."""
    from cdpr_twin.cli import main
    from cdpr_twin.scenario import loading as scenario

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(scenario, "load_scenario", interrupted)
    assert main(["run", "paper_open_loop", "--duration", "0.2"]) == 130
    assert capsys.readouterr().err == "cdpr-twin run: interrupted\n"
