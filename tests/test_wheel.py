"""The built wheel works anywhere: installed outside the repository, it finds its own robot and
scenarios (by name) and runs a scenario from an empty working directory.

The wheel is built from a copy of the sources (no build files left in the checkout) without
network access (``--no-build-isolation --no-index``), and installed into a fresh virtual
environment in a temporary directory. That environment reaches the test environment's
dependencies (mujoco, numpy…) through a ``.pth`` line, which adds their directory to
``sys.path`` without running its ``.pth`` files, so the editable install of ``cdpr_twin`` is
not importable there: the test checks that ``cdpr_twin`` is imported from the new environment.

The installed package starts with the checkout's compiled Numba kernels (warmed here first): Numba
keys its on-disk cache by the source file's content, the function's bytecode and the CPU, all
the same for the installed copy of the same sources, so the environment loads them instead of
compiling them again (a minute and more of CPU; a kernel whose key differs is compiled as usual).
"""

import json
import os
import shutil
import site
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
SOURCES = (
    "pyproject.toml",
    "README.md",
    "LICENSE",
    "cdpr_twin",
    "models",
    "scenarios",
    "campaigns",
)


def _call(*command, cwd: Path, env: dict | None = None) -> subprocess.CompletedProcess:
    proc = subprocess.run(
        [str(c) for c in command], capture_output=True, text=True, cwd=cwd, env=env, timeout=300
    )
    assert proc.returncode == 0, f"{command}: {proc.stdout}\n{proc.stderr}"
    return proc


def _reuse_compiled_kernels(purelib: Path) -> None:
    """Copy the checkout's Numba cache beside the installed sources, the kernels compiled first.

    Building the shipped scenario's estimators compiles (or loads) every kernel its runs use.
    """
    from cdpr_twin.run.runner import prepare
    from cdpr_twin.scenario.loading import load_scenario

    prepare(load_scenario("paper_open_loop").with_overrides(camera=False)).close()
    for cached in (ROOT / "cdpr_twin").rglob("__pycache__/*.nb[ci]"):
        target = purelib / cached.relative_to(ROOT)
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(cached, target)


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """(venv, wheel, environment, empty working directory) with the wheel installed."""
    tmp = tmp_path_factory.mktemp("wheel")
    src = tmp / "src"
    src.mkdir()
    for name in SOURCES:
        if (ROOT / name).is_dir():
            ignore = shutil.ignore_patterns("__pycache__", "*.pyc")
            shutil.copytree(ROOT / name, src / name, ignore=ignore)
        else:
            shutil.copy2(ROOT / name, src / name)
    pip = [sys.executable, "-m", "pip", "--disable-pip-version-check", "-q"]
    _call(*pip, "wheel", "--no-deps", "--no-build-isolation", "--no-index", "-w", tmp, src, cwd=tmp)
    (wheel,) = tmp.glob("cdpr_twin-*.whl")
    venv = tmp / "venv"
    _call(sys.executable, "-m", "venv", "--without-pip", venv, cwd=tmp)
    python = venv / "bin" / "python"
    _call(*pip, "--python", python, "install", "--no-deps", "--no-index", wheel, cwd=tmp)
    purelib = _call(python, "-c", "import sysconfig; print(sysconfig.get_path('purelib'))", cwd=tmp)
    deps = [p for p in site.getsitepackages() if Path(p).is_dir()]
    (Path(purelib.stdout.strip()) / "_test_env_deps.pth").write_text("\n".join(deps) + "\n")
    _reuse_compiled_kernels(Path(purelib.stdout.strip()))
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    env["MUJOCO_GL"] = env.get("MUJOCO_GL", "egl")
    work = tmp / "elsewhere"
    work.mkdir()
    return venv, wheel, env, work


def test_the_wheel_carries_every_package_the_robots_and_the_scenarios(installed):
    _, wheel, _, _ = installed
    names = set(zipfile.ZipFile(wheel).namelist())
    packages = {
        p.parent.relative_to(ROOT).as_posix() for p in (ROOT / "cdpr_twin").rglob("__init__.py")
    }
    missing = {p for p in packages if f"{p}/__init__.py" not in names}
    assert not missing, f"add {sorted(missing)} to [tool.setuptools] packages in pyproject.toml"
    for path in (ROOT / "models").rglob("*"):
        if path.is_file() and "__pycache__" not in path.parts:
            assert f"cdpr_twin/models/{path.relative_to(ROOT / 'models').as_posix()}" in names
    for path in (ROOT / "scenarios").glob("*.toml"):
        assert f"cdpr_twin/scenarios/{path.name}" in names
    for path in (ROOT / "campaigns").glob("*.toml"):
        assert f"cdpr_twin/campaigns/{path.name}" in names


@pytest.mark.slow
def test_the_installed_wheel_runs_everything_by_name_from_an_empty_directory(installed):
    """A scenario, a campaign and a robot build by name, --version, the README's example."""
    import re

    venv, _, env, work = installed
    cli = venv / "bin" / "cdpr-twin"
    version = _call(cli, "--version", cwd=work, env=env).stdout
    # an installed wheel is no checkout: no commit to name
    assert re.fullmatch(r"cdpr-twin 0\.1\.0 \(MuJoCo [\d.]+, Python [\d.]+\)\n", version), version
    proc = _call(cli, "run", "paper_open_loop", "--duration", "1", "--no-camera", cwd=work, env=env)
    summary = json.loads((work / "runs" / "paper_open_loop" / "summary.json").read_text())
    assert summary["status"] == "completed" and summary["simulated_time_s"] == pytest.approx(1.0)
    assert "paper_open_loop: completed after 1.00 s simulated" in proc.stdout, proc.stdout
    assert Path(summary["source"]).resolve().is_relative_to(venv.resolve()), summary["source"]
    assert summary["software"]["cdpr_twin"] == "0.1.0" and summary["software"]["git_commit"] is None
    listed = _call(cli, "scenarios", "list", cwd=work, env=env).stdout
    shipped = sorted(p.stem for p in (ROOT / "scenarios").glob("*.toml"))
    assert [line.split()[0] for line in listed.splitlines()] == shipped
    # a shipped campaign by name, each run cut to one control tick (18 runs)
    _call(
        cli,
        "campaign",
        "pbvs_gain_sweep",
        "--duration",
        "0.04",
        "--workers",
        "2",
        cwd=work,
        env=env,
    )
    campaign = json.loads((work / "runs" / "pbvs_gain_sweep" / "campaign.json").read_text())
    assert campaign["status"] == "completed" and campaign["ran_now"] == 18
    # a shipped robot's description built by name, into ./acrobot (never into the package)
    _call(cli, "model", "build", "acrobot", cwd=work, env=env)
    assert (work / "acrobot" / "scene.xml").is_file() and (
        work / "acrobot" / "acrobot.xml"
    ).is_file()
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    (example,) = re.findall(r"^```python\n(.*?)^```", readme, flags=re.S | re.M)
    out = _call(venv / "bin" / "python", "-c", example, cwd=work, env=env).stdout
    assert out.startswith("completed"), out
    quick = json.loads((work / "runs" / "quick" / "summary.json").read_text())
    assert quick["simulated_time_s"] == pytest.approx(2.0)


def test_the_installed_wheel_builds_the_acrobot_by_name(installed):
    venv, _, env, work = installed
    code = (
        "import cdpr_twin, numpy as np\n"
        "from cdpr_twin.math import se3\n"
        "from cdpr_twin.sim import Twin\n"
        "with Twin(robot='acrobot') as twin:\n"
        "    twin.reset(se3.pose_from_vector([0.284, -0.197, 0.08, 0, 0, 0]))\n"
        "    m = twin.sense()\n"
        "    print(cdpr_twin.__file__)\n"
        "    print(twin.model_path)\n"
        "    print(len(m.tensions), m.tag is not None, float(np.min(m.tensions)))\n"
    )
    lines = _call(venv / "bin" / "python", "-c", code, cwd=work, env=env).stdout.splitlines()
    package, model, sensed = lines[-3:]
    assert Path(package).resolve().is_relative_to(venv.resolve()), package
    assert Path(model).resolve().is_relative_to(venv.resolve()), model
    assert not Path(package).resolve().is_relative_to(ROOT)
    n, tag_seen, tau_min = sensed.split()
    assert n == "8" and tag_seen == "True"  # the tag texture came with the wheel
    assert float(tau_min) > 1.0  # all cables taut at p1
