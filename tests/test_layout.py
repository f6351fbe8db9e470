"""The package's shape: MuJoCo only under sim, no import-time state."""

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parent.parent / "cdpr_twin"
MODULES = sorted(PACKAGE.rglob("*.py"))


@pytest.mark.parametrize("path", MODULES, ids=lambda p: str(p.relative_to(PACKAGE)))
def test_only_the_sim_layer_imports_mujoco(path):
    if path.parent.name == "sim":
        return
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        names = []
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom) and node.module:
            names = [node.module]
        assert not any(n == "mujoco" or n.startswith("mujoco.") for n in names), path


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
    modules, _ = _loaded_after("import cdpr_twin.figures")
    assert "matplotlib.pyplot" not in modules
