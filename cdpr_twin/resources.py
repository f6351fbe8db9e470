"""The robots, scenarios and campaigns shipped with the package, by name or by path.

They live at the top of the repository (``models/<robot>/scene.xml``, ``scenarios/*.toml``,
``campaigns/*.toml``) and are mapped into the package at build time as ``cdpr_twin.models``,
``cdpr_twin.scenarios`` and ``cdpr_twin.campaigns`` (``pyproject.toml``), so
:mod:`importlib.resources` finds them in a wheel and in an editable install alike. Only the
standard library is imported here.

>>> robot_scene("acrobot")            # …/models/acrobot/scene.xml
>>> scenario_file("paper_open_loop")  # …/scenarios/paper_open_loop.toml
>>> campaign_file("pbvs_gain_sweep")  # …/campaigns/pbvs_gain_sweep.toml
"""

from __future__ import annotations

import importlib.resources
from pathlib import Path

_CHECKOUT = Path(__file__).resolve().parent.parent
SCENE_FILE = "scene.xml"
"""The file a robot directory is loaded from (its MJCF scene)."""
DESCRIPTION_FILE = "robot.toml"
"""A robot directory's description, from which ``cdpr-twin model build`` writes the scene."""


class ResourceError(ValueError):
    """A robot or scenario name that is not shipped, or a copy that cannot be made."""


def _root(package: str) -> Path:
    """The directory of a shipped resource package (the checkout's when not installed)."""
    try:
        root = importlib.resources.files(f"cdpr_twin.{package}")
    except ModuleNotFoundError:  # a bare checkout on sys.path, never installed
        return _CHECKOUT / package
    if not isinstance(root, Path):
        raise ResourceError(
            f"cdpr_twin.{package} is not a directory ({root!r}); install cdpr-twin unzipped"
        )
    return root


def models_dir() -> Path:
    """The directory holding one subdirectory per shipped robot."""
    return _root("models")


def scenarios_dir() -> Path:
    """The directory holding the shipped scenario files."""
    return _root("scenarios")


def campaigns_dir() -> Path:
    """The directory holding the shipped campaign files."""
    return _root("campaigns")


def robots() -> tuple[str, ...]:
    """Names of the shipped robots (directories with a ``scene.xml``), sorted."""
    return tuple(sorted(p.parent.name for p in models_dir().glob(f"*/{SCENE_FILE}")))


def scenarios() -> tuple[str, ...]:
    """Names of the shipped scenarios (file stems), sorted."""
    return tuple(sorted(p.stem for p in scenarios_dir().glob("*.toml")))


def campaigns() -> tuple[str, ...]:
    """Names of the shipped campaigns (file stems), sorted."""
    return tuple(sorted(p.stem for p in campaigns_dir().glob("*.toml")))


def robot_description(ref: str | Path) -> Path:
    """A robot description: a shipped robot's name, or a ``robot.toml`` path as given.

    Raises:
        ResourceError: for a bare name that is neither a file nor a shipped robot.
    """
    from cdpr_twin.files.paths import path_kind

    if is_name(ref) and path_kind(Path(ref), ResourceError) != "file":
        return robot_scene(str(ref)).parent / DESCRIPTION_FILE
    return Path(ref)


def campaign_file(ref: str | Path) -> Path:
    """A campaign file: a shipped campaign's name, or a path returned as given.

    Raises:
        ResourceError: for a bare name that is neither a file nor a shipped campaign.
    """
    from cdpr_twin.files.paths import path_kind

    path = Path(ref)
    if not is_name(ref) or path_kind(path, ResourceError) == "file":
        return path
    if str(ref) not in campaigns():
        raise ResourceError(
            f"no campaign named {str(ref)!r}; choose one of {', '.join(campaigns())} or give a "
            ".toml file"
        )
    return campaigns_dir() / f"{ref}.toml"


def robot_scene(name: str) -> Path:
    """The MJCF scene of a shipped robot.

    Raises:
        ResourceError: for a name that is not shipped, listing those that are.
    """
    path = models_dir() / name / SCENE_FILE
    if "/" in name or "\\" in name or name not in robots():  # (a name too long is not one)
        raise ResourceError(
            f"no robot named {name!r}; choose one of {', '.join(robots())} or give a model file"
        )
    return path


def robot_model(ref: str | Path | None = None) -> Path:
    """A robot's MJCF scene: a shipped robot's name, or a model file's path as given.

    Args:
        ref: a name (``"acrobot"``), a path, or ``None`` for the default robot ``acrobot``.

    Raises:
        ResourceError: for a bare name that is neither a file nor a shipped robot.
    """
    if ref is None:
        return robot_scene("acrobot")
    from cdpr_twin.files.paths import path_kind

    if is_name(ref) and path_kind(Path(ref), ResourceError) != "file":
        return robot_scene(str(ref))
    return Path(ref)


def is_name(ref: str | Path) -> bool:
    """Whether a reference is a bare name (no directory part, no suffix) rather than a path."""
    text = str(ref)
    return bool(text) and "/" not in text and "\\" not in text and not Path(text).suffix


def scenario_file(ref: str | Path) -> Path:
    """A scenario file: a shipped scenario's name, or a path returned as given.

    A bare name (``paper_open_loop``) that is not a file in the working directory is looked up
    among the shipped scenarios.

    Raises:
        ResourceError: for a bare name that is neither a file nor a shipped scenario.
    """
    from cdpr_twin.files.paths import path_kind

    path = Path(ref)
    if not is_name(ref) or path_kind(path, ResourceError) == "file":
        return path
    try:
        return _shipped_scenario(str(ref))
    except ResourceError as exc:
        raise ResourceError(f"{exc} or give a .toml file") from None


def _shipped_scenario(name: str) -> Path:
    shipped = scenarios_dir() / f"{name}.toml"
    if not is_name(name) or name not in scenarios():  # (a name too long is not one)
        raise ResourceError(f"no scenario named {name!r}; choose one of {', '.join(scenarios())}")
    return shipped


def copy_scenario(name: str, dest: str | Path) -> Path:
    """Copy a shipped scenario into a directory (created if needed) to start one's own.

    Returns:
        The new file's path.

    Raises:
        ResourceError: for an unknown name, an existing file, or an unusable directory.
        cdpr_twin.files.transaction.OutputError: the copy cannot be written (disk full); nothing is
            left.
    """
    source = _shipped_scenario(name)
    return _copy({source: Path(dest) / source.name})[0]


def copy_campaign(name: str, dest: str | Path) -> Path:
    """Copy a shipped campaign into a directory (created if needed) to start one's own.

    The shipped campaigns name their scenarios by shipped name, so the copy runs from anywhere.

    Returns:
        The new file's path.

    Raises:
        ResourceError: for an unknown name, an existing file, or an unusable directory.
        cdpr_twin.files.transaction.OutputError: the copy cannot be written; nothing is left.
    """
    if not is_name(name) or name not in campaigns():
        raise ResourceError(f"no campaign named {name!r}; choose one of {', '.join(campaigns())}")
    source = campaigns_dir() / f"{name}.toml"
    return _copy({source: Path(dest) / source.name})[0]


def copy_robot(name: str, dest: str | Path) -> Path:
    """Copy a shipped robot's directory into ``dest`` (created if needed) to start one's own.

    What its description needs comes along (``robot.toml``, the textures it names), with the
    built scene and the README of its sources; the scripts that made its figures and textures
    are left behind.

    Returns:
        The copied ``robot.toml``.

    Raises:
        ResourceError: for an unknown name, an existing file, or an unusable directory.
        cdpr_twin.files.transaction.OutputError: a file cannot be written; nothing is left.
    """
    folder = robot_scene(name).parent
    files = {
        p: Path(dest) / p.relative_to(folder)
        for p in sorted(folder.rglob("*"))
        if p.is_file() and p.suffix not in (".py", ".pyc") and "__pycache__" not in p.parts
    }
    copied = _copy(files)
    return copied[[p.name for p in files].index(DESCRIPTION_FILE)]


def _copy(files: dict[Path, Path]) -> list[Path]:
    """Copy shipped files (source → target), whole or not at all; the targets, in order."""
    from cdpr_twin.files.paths import path_kind
    from cdpr_twin.files.transaction import write_whole

    for target in files.values():
        if path_kind(target.parent, ResourceError) not in (None, "dir"):
            raise ResourceError(f"{target.parent} is not a directory; give a directory")
        if path_kind(target, ResourceError):
            raise ResourceError(f"{target} exists; remove it or copy into another directory")
    data: dict[Path, str | bytes] = {t: s.read_bytes() for s, t in files.items()}
    for directory in dict.fromkeys(target.parent for target in files.values()):
        try:
            directory.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ResourceError(
                f"cannot create {directory}: {exc.strerror or exc}; copy into another directory"
            ) from None
    write_whole(data)  # whole or not at all: a failed copy can be retried
    return list(files.values())
