"""A recording that cannot be written is one line on stderr: Rerun's own log is quiet unless asked.

Before: on a full disk Rerun's logger (Rust's, set up when Rerun is imported) printed two or
three ANSI-coloured lines beside the command's one, even when stderr was not a terminal. The
recording is written here to ``/dev/full`` (every write fails with ENOSPC), by ``python -c``
running the command's entry point after pointing Rerun's sink, the name of our own
``recording.rrd.partial``, there. Truth: the exit code, and stderr's lines, read from the pipe.
"""

import os
import subprocess
import sys
from pathlib import Path

DRIVER = """
import sys

from cdpr_twin.recording import rerun as record

real = record.Partial.name_of_fd


def full(self):
    return "/dev/full" if self.partial.name == "recording.rrd.partial" else real(self)


record.Partial.name_of_fd = full

from cdpr_twin.entry import main

sys.exit(main())
"""


def _run_onto_a_full_disk(tmp_path: Path, rust_log: str | None) -> tuple[int, list[str]]:
    out = tmp_path / f"out-{rust_log}"
    env = {k: v for k, v in os.environ.items() if k != "RUST_LOG"}
    if rust_log is not None:
        env["RUST_LOG"] = rust_log
    argv = ["run", "paper_open_loop", "--out", str(out), "--duration", "1", "--no-camera"]
    command = [sys.executable, "-c", DRIVER, *argv]
    proc = subprocess.run(command, capture_output=True, text=True, env=env, timeout=300)
    progress = "paper_open_loop: "  # its progress, a line per 10 % (stderr is not a terminal)
    return proc.returncode, [line for line in proc.stderr.splitlines() if progress not in line]


def test_a_recording_on_a_full_disk_is_one_plain_line(tmp_path):
    code, err = _run_onto_a_full_disk(tmp_path, None)
    assert code == 1
    assert len(err) == 1, err
    assert err[0].startswith("cdpr-twin: cannot write ") and "No space left on device" in err[0]
    assert "\x1b" not in err[0]


def test_rerun_logs_again_when_the_user_asks_for_it(tmp_path):
    # truth that the failure above does make Rerun log: the same run with RUST_LOG set
    code, err = _run_onto_a_full_disk(tmp_path, "warn")
    assert code == 1
    assert any("re_sdk" in line for line in err), err
    assert sum(line.startswith("cdpr-twin: cannot write ") for line in err) == 1
