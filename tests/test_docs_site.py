"""The documentation site builds with ``mkdocs build --strict``: a broken link, a missing page of
the navigation or an API name mkdocstrings cannot find is a warning, and strict makes it fail.

The reference pages are generated at build time (``docs/hooks.py``) from the command's parser
and the option specs; the test also checks that they, and a page for each guide the site
promises, came out of the build.
"""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

PAGES = (
    "tutorials/first-run",
    "tutorials/own-estimator",
    "tutorials/campaign",
    "how-to/write-a-scenario",
    "how-to/add-a-robot",
    "how-to/events-and-faults",
    "how-to/calibrate",
    "how-to/ray",
    "how-to/rerun",
    "how-to/gymnasium",
    "concepts/physics",
    "concepts/truth-vs-nominal",
    "concepts/realism",
    "concepts/outputs",
    "concepts/architecture",
    "concepts/frames",
    "reference/cli",
    "reference/scenario",
    "reference/campaign",
    "reference/robot",
    "reference/api",
    "results/paper-study",
    "results/calibration",
    "results/open-loop-1000",
    "results/cogiro",
    "results/benchmarks",
    "install",
)


def test_the_site_builds_strict_with_every_page(tmp_path):
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "-q", "-d", str(tmp_path / "site")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )
    assert proc.returncode == 0, proc.stdout + proc.stderr
    missing = [p for p in PAGES if not (tmp_path / "site" / p / "index.html").is_file()]
    assert not missing, missing
    cli = (tmp_path / "site" / "reference" / "cli" / "index.html").read_text()
    # every subcommand of the parser has its section (the page is generated from it)
    for command in ("run", "reproduce", "campaign", "campaigns", "robots", "model", "calibrate"):
        assert f"cdpr-twin {command}" in cli, command
    scenario = (tmp_path / "site" / "reference" / "scenario" / "index.html").read_text()
    assert "max_linear_speed" in scenario and "exposure_s" in scenario
    # the top-level tables, from the loader's own reads: every key a shipped scenario writes
    # there, and the keys it reads only when a file gives them (no shipped file does)
    import tomllib

    for path in sorted((ROOT / "scenarios").glob("*.toml")):
        data = tomllib.loads(path.read_text(encoding="utf-8"))
        for table in ("model", "truth", "sensors", "start", "monitor"):
            for key in data.get(table, {}):
                assert f"<code>{key}</code>" in scenario, (path.name, table, key)
    assert "<code>nominal</code>" in scenario and "<code>file</code>" in scenario
    # every part of the realism profiles, the cables' and pulleys' too, and their profile
    for part in ("camera", "winch", "tension", "homing", "cable", "pulley"):
        assert f"[realism.{part}]" in scenario, part
    assert "acrobot_full" in cli and "acrobot_full" in scenario
