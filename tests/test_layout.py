"""The package's shape: its layer contracts, clean formatting, no import-time state."""

import ast
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = ROOT / "cdpr_twin"


def _tool(name: str) -> str:
    """A console script of this environment (installed with the test extras)."""
    return str(Path(sys.executable).with_name(name))


def test_the_layer_contracts_hold():
    # pyproject.toml's [tool.importlinter]: no cycle, math pure, MuJoCo only under sim,
    # estimators and controllers blind to the simulation
    out = subprocess.run([_tool("lint-imports")], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stdout[-3000:]
    assert "0 broken" in out.stdout


def test_ruff_lint_and_format_are_clean():
    lint = subprocess.run([_tool("ruff"), "check", "."], capture_output=True, text=True, cwd=ROOT)
    assert lint.returncode == 0, lint.stdout[-3000:]
    fmt = subprocess.run(
        [_tool("ruff"), "format", "--check", "."], capture_output=True, text=True, cwd=ROOT
    )
    assert fmt.returncode == 0, fmt.stdout[-3000:]


def test_no_formatting_is_switched_off_to_save_lines():
    # a `# fmt: skip` is kept only for a numeric table that reads better aligned, and says so
    for path in [*PACKAGE.rglob("*.py"), *ROOT.glob("tests/**/*.py")]:
        if path == Path(__file__):
            # this test names the markers it looks for
            continue
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1):
            if "# fmt: skip" in line or "# fmt: off" in line:
                assert "aligned" in line, f"{path.relative_to(ROOT)}:{number}"


def _loaded_after(statement: str) -> tuple[set[str], str]:
    report = "print(sorted(sys.modules)); print(os.environ.get('MUJOCO_GL'))"
    code = f"import os, sys\n{statement}\n{report}"
    env = {k: v for k, v in __import__("os").environ.items() if k != "MUJOCO_GL"}
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env
    ).stdout.splitlines()
    return set(ast.literal_eval(out[0])), out[1]


def test_estimators_and_controllers_load_no_mujoco_opencv_or_apriltags():
    modules, gl = _loaded_after(
        "import cdpr_twin.estimators, cdpr_twin.controllers, cdpr_twin.types"
    )
    heavy = {"mujoco", "cv2", "pupil_apriltags", "matplotlib", "rerun"}
    assert not heavy & {m.split(".")[0] for m in modules}
    assert gl == "None"  # importing the package sets no global state


def test_the_sim_layer_defaults_mujoco_gl_to_egl():
    _, gl = _loaded_after("import cdpr_twin.sim")
    assert gl == "egl"


def test_figures_do_not_switch_the_matplotlib_backend():
    modules, _ = _loaded_after("import cdpr_twin.study.figures")
    assert "matplotlib.pyplot" not in modules


def test_the_tests_mirror_the_package():
    # each folder of tests/ is a layer of the package, and pytest imports every test file under
    # its own name (no __init__.py): two files of one name would shadow each other
    tests = ROOT / "tests"
    layers = {p.name for p in PACKAGE.iterdir() if (p / "__init__.py").is_file()}
    folders = {p.name for p in tests.iterdir() if p.is_dir() and list(p.glob("test_*.py"))}
    assert folders <= layers, folders - layers
    names = [p.name for p in tests.rglob("test_*.py")]
    assert len(names) == len(set(names)), sorted(n for n in names if names.count(n) > 1)
