"""Robots and scenarios by name, `cdpr-twin scenarios list|copy`, and `cdpr-twin view`."""

import os
import shlex
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from cdpr_twin import cli, resources
from cdpr_twin.cli import tools as cli_tools
from cdpr_twin.scenario.loading import ScenarioError, load_scenario

ROOT = Path(__file__).resolve().parent.parent
SHIPPED = tuple(sorted(p.stem for p in (ROOT / "scenarios").glob("*.toml")))


def _cli(*args: str, cwd: Path) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "cdpr_twin", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        env={**os.environ, "MUJOCO_GL": "egl"},
        timeout=300,
    )


def test_shipped_robots_and_scenarios_are_found_by_name():
    shipped = tuple(sorted(p.parent.name for p in (ROOT / "models").glob("*/scene.xml")))
    assert "acrobot" in shipped and resources.robots() == shipped
    assert resources.robot_scene("acrobot").samefile(ROOT / "models" / "acrobot" / "scene.xml")
    assert resources.scenarios() == SHIPPED
    by_name = load_scenario("paper_pbvs")
    assert by_name.source.samefile(ROOT / "scenarios" / "paper_pbvs.toml")
    assert by_name.model.file.samefile(ROOT / "models" / "acrobot" / "scene.xml")
    expected = "no scenario named 'paper'; choose one of " + ", ".join(SHIPPED)
    with pytest.raises(ScenarioError, match=expected):
        load_scenario("paper")
    with pytest.raises(resources.ResourceError, match="no robot named 'delta'; choose one of"):
        resources.robot_scene("delta")


def test_a_twin_is_built_by_robot_name_or_path_not_both():
    from cdpr_twin.sim import ModelError, Twin

    with Twin(robot="acrobot", camera=False) as twin:
        assert twin.model_path.samefile(ROOT / "models" / "acrobot" / "scene.xml")
        assert twin.physics.n_cables == 8
    with pytest.raises(ModelError, match="no robot named 'acrobat'; choose one of acrobot"):
        Twin(robot="acrobat", camera=False)
    with pytest.raises(ValueError, match="either model_path or robot"):
        Twin(ROOT / "models" / "acrobot" / "scene.xml", robot="acrobot", camera=False)


def test_a_scenario_names_its_robot_or_a_file_not_both(tmp_path):
    text = (ROOT / "scenarios" / "paper_open_loop.toml").read_text()
    assert 'robot = "acrobot"' in text
    path = tmp_path / "s.toml"
    path.write_text(text.replace('robot = "acrobot"', 'robot = "acrobat"', 1))
    with pytest.raises(ScenarioError, match=r"model\.robot: no robot named 'acrobat'"):
        load_scenario(path)
    scene = ROOT / "models" / "acrobot" / "scene.xml"
    path.write_text(text.replace('robot = "acrobot"', f'robot = "acrobot"\nfile = "{scene}"', 1))
    with pytest.raises(ScenarioError, match=r"model\.robot: give either robot"):
        load_scenario(path)
    path.write_text(text.replace('robot = "acrobot"', f'file = "{scene}"', 1))
    assert load_scenario(path).model.file == scene


def test_scenarios_list_and_copy_start_ones_own(tmp_path):
    listed = _cli("scenarios", "list", cwd=tmp_path)
    assert listed.returncode == 0, listed.stderr
    rows = {line.split()[0]: line for line in listed.stdout.splitlines()}
    assert set(rows) == set(SHIPPED)
    shipped = tomllib.loads((ROOT / "scenarios" / "paper_pbvs.toml").read_text())
    assert shipped["description"] in rows["paper_pbvs"]
    copied = _cli("scenarios", "copy", "paper_open_loop", "my own", cwd=tmp_path)
    assert copied.returncode == 0, copied.stderr
    hint = "(run it: cdpr-twin run 'my own/paper_open_loop.toml')"  # quoted for a shell
    assert copied.stdout.strip() == f"my own/paper_open_loop.toml {hint}"
    target = tmp_path / "my own" / "paper_open_loop.toml"
    assert target.read_bytes() == (ROOT / "scenarios" / "paper_open_loop.toml").read_bytes()
    assert load_scenario(target).model.file.samefile(resources.robot_scene("acrobot"))
    again = _cli("scenarios", "copy", "paper_open_loop", "my own", cwd=tmp_path)
    assert again.returncode == 2 and "exists; remove it" in again.stderr
    unknown = _cli("scenarios", "copy", "paper", "mine", cwd=tmp_path)
    assert unknown.returncode == 2 and len(unknown.stderr.strip().splitlines()) == 1
    assert "choose one of " + ", ".join(SHIPPED) in unknown.stderr


@pytest.mark.parametrize("name", ["run", "my run's 'copy'"])  # printed quoted for a shell
def test_view_opens_the_run_recording_in_the_rerun_viewer(name, tmp_path, monkeypatch, capsys):
    run_dir = tmp_path / name
    run_dir.mkdir()
    assert cli.main(["view", str(run_dir)]) == 2
    assert "no recording; give a run directory" in capsys.readouterr().err
    (run_dir / "recording.rrd").write_bytes(b"")
    started = []

    class FakeViewer:
        def __init__(self, command):
            started.append(command)

        def wait(self):
            return 0

    monkeypatch.setattr(cli_tools.subprocess, "Popen", FakeViewer)
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    if sys.platform.startswith("linux"):  # before: Rerun's own multi-line error, exit 1
        assert cli.main(["view", str(run_dir)]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "no display here" in err and "--print-command" in err
        assert started == []
    monkeypatch.setenv("DISPLAY", ":0")
    assert cli.main(["view", str(run_dir)]) == 0
    assert started == [[sys.executable, "-m", "rerun", str(run_dir / "recording.rrd")]]
    assert cli.main(["view", str(run_dir), "--print-command"]) == 0
    assert shlex.split(capsys.readouterr().out) == started[0]
    assert len(started) == 1
    monkeypatch.undo()
    # the printed command is the viewer of this environment's rerun-sdk
    version = subprocess.run(
        [*started[0][:3], "--version"], capture_output=True, text=True, timeout=60
    )
    import rerun

    assert version.returncode == 0 and rerun.__version__ in version.stdout


@pytest.mark.parametrize(
    ("given", "url"),
    [
        ("9876", "rerun+http://127.0.0.1:9876/proxy"),
        ("robot-pc:9000", "rerun+http://robot-pc:9000/proxy"),
        ("rerun+http://10.0.0.2:9876/proxy", "rerun+http://10.0.0.2:9876/proxy"),
        ("rerun+https://[::1]:443/proxy", "rerun+https://[::1]:443/proxy"),
    ],
)
def test_connect_addresses(given, url):
    assert cli_tools.live_url(given) == url


@pytest.mark.parametrize(
    "address",
    [
        "http://x/y",
        "rerun+http://",  # before: the URLs were kept as given, the run streamed nowhere, exit 0
        "rerun+http://garbage with spaces",
        "rerun+http://garbage with spaces:9876/proxy",
        "rerun+http://robot-pc/proxy",  # no port
        "rerun+http://:9876/proxy",  # no host
        "rerun+http://robot-pc:9876",  # no /proxy: the SDK refuses it, the run said nothing
        "rerun+http://robot-pc:9876/proxy?x=1",
    ],
)
def test_a_bad_connect_address_is_a_one_line_error(address, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)
    assert cli.main(["run", "paper_open_loop", "--connect", address]) == 2
    assert capsys.readouterr().err.strip() == (
        f"cdpr-twin: error: --connect {address!r}: give a port, host:port or a URL "
        "rerun+http://host:port/proxy"
    )
    assert list(tmp_path.iterdir()) == []


def test_spawn_and_connect_together_is_a_one_line_error(tmp_path):
    proc = _cli("run", "paper_open_loop", "--spawn", "--connect", "9876", cwd=tmp_path)
    assert proc.returncode == 2
    assert proc.stderr.strip() == (
        "cdpr-twin: error: give --spawn (a new viewer) or --connect ADDR, not both"
    )
    assert not (tmp_path / "runs").exists()


def test_campaigns_and_robots_are_shipped_by_name_and_copy_whole(tmp_path):
    from cdpr_twin.campaign import load_campaign

    shipped = tuple(sorted(p.stem for p in (ROOT / "campaigns").glob("*.toml")))
    assert resources.campaigns() == shipped and "pbvs_gain_sweep" in shipped
    listed = _cli("campaigns", "list", cwd=tmp_path)
    assert listed.returncode == 0 and [r.split()[0] for r in listed.stdout.splitlines()] == list(
        shipped
    )
    # a copied campaign names its scenario by shipped name: it loads from anywhere, and its
    # runs are the shipped file's (same run ids: each hashes the resolved scenario)
    copied = _cli("campaigns", "copy", "pbvs_gain_sweep", "c", cwd=tmp_path)
    assert copied.returncode == 0, copied.stderr
    mine = load_campaign(tmp_path / "c" / "pbvs_gain_sweep.toml")
    by_name = load_campaign("pbvs_gain_sweep")
    assert [t.run_id for t in mine.tasks] == [t.run_id for t in by_name.tasks]
    assert len(by_name.tasks) == 18  # 3 gains x 6 estimators, as the file says
    # a robot's copy holds what its description needs: the built scene loads with its texture
    robot = _cli("robots", "copy", "acrobot", "r", cwd=tmp_path)
    assert robot.returncode == 0, robot.stderr
    source = ROOT / "models" / "acrobot"
    for name in ("robot.toml", "scene.xml", "acrobot.xml", "assets/tag36h11_00000.png"):
        assert (tmp_path / "r" / name).read_bytes() == (source / name).read_bytes(), name
    assert not list((tmp_path / "r").glob("*.py"))
    built = _cli("model", "build", "acrobot", cwd=tmp_path)  # by name: into ./acrobot
    assert built.returncode == 0, built.stderr
    import mujoco

    for scene in (tmp_path / "r" / "scene.xml", tmp_path / "acrobot" / "scene.xml"):
        model = mujoco.MjModel.from_xml_path(str(scene))
        # the tag's texture and the floor's grid; 8 cables as tendons
        assert model.ntex == 2 and model.ntendon == 8
    unknown = _cli("campaigns", "copy", "nosuch", "x", cwd=tmp_path)
    assert unknown.returncode == 2 and len(unknown.stderr.strip().splitlines()) == 1
