"""One registry for estimators and controllers, and self-describing options (numpy only).

A plugin is a class with a ``name``, a ``kind`` (``"estimator"`` or ``"controller"``) and an
``Options`` frozen dataclass whose fields, with their defaults, *are* its scenario-file schema:
:mod:`cdpr_twin.scenario.loading` parses them generically from each field's type and the metadata
that
:func:`option` attaches (unit, bounds, file key). Register a plugin with :func:`register`; a
scenario file can import modules that register more (``plugins = ["my_module", "file.py"]``).

A scenario or campaign that names plugins runs their code: run only files you trust. Each plugin
file or module a process loads is named once on stderr (``cdpr-twin: loading plugin
/abs/path/file.py``) before its code runs.

Installed packages add plugins by entry point, found by the same registry when it is first
read: in the package's ``pyproject.toml``,

.. code-block:: toml

    [project.entry-points."cdpr_twin.estimators"]
    my_estimator = "my_package.estimators:MyEstimator"   # the entry-point name is its name

(group ``cdpr_twin.controllers`` for controllers). The class needs no :func:`register`; an
entry point may also name a module that registers the plugin when imported. One that fails to
load is skipped with a warning, and naming it says why.

>>> @register
... class Mean(Estimator):
...     name = "mean"
...     Options = MeanOptions
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import importlib
import importlib.metadata
import importlib.util
import inspect
import math
import sys
import warnings
from collections.abc import Iterator, Mapping
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, ClassVar, Literal, Protocol, TypeVar, cast, overload

from cdpr_twin.files.paths import path_kind
from cdpr_twin.options import NoOptions, OptionError, OptionSpec, option, spec_of

if TYPE_CHECKING:
    # (for the types only: the bases import this module)
    from cdpr_twin.controllers.base import Controller
    from cdpr_twin.estimators.base import Estimator

KINDS = ("estimator", "controller")
RESERVED_NAMES = frozenset({"t", "true", "plan", "tag", "status", "tension", "length", "rate"})
"""Column prefixes of ``timeseries.csv`` that no plugin may take as its name."""
ENTRY_POINT_GROUPS = {"estimator": "cdpr_twin.estimators", "controller": "cdpr_twin.controllers"}
"""The entry-point group of each kind of plugin."""
BUILTINS: dict[str, tuple[tuple[str, str], ...]] = {
    "estimator": (
        # the paper's six (Est. 1 … Est. 6), in its order, then those beyond it
        ("control", "cdpr_twin.estimators.control_based:ControlEstimator"),
        ("image", "cdpr_twin.estimators.image_based:ImageEstimator"),
        ("model_simple", "cdpr_twin.estimators.model_based:SimpleModelEstimator"),
        ("model_elastic", "cdpr_twin.estimators.model_based:ElasticModelEstimator"),
        ("model_pulley", "cdpr_twin.estimators.model_based:PulleyModelEstimator"),
        ("model_elastic_pulley", "cdpr_twin.estimators.model_based:ElasticPulleyModelEstimator"),
        ("fused", "cdpr_twin.estimators.fused:FusedEstimator"),
        ("model_catenary", "cdpr_twin.estimators.catenary:CatenaryModelEstimator"),
    ),
    "controller": (
        ("open_loop", "cdpr_twin.controllers.open_loop:OpenLoopController"),
        ("pbvs", "cdpr_twin.controllers.pbvs:PbvsController"),
    ),
}
"""The built-in plugins, by kind: name → ``"module:Class"``, in listing order. A class is
imported when it is first looked up (its module, and what it needs, only then)."""
_REGISTRY: dict[str, dict[str, type[Plugin] | str]] = {kind: dict(BUILTINS[kind]) for kind in KINDS}
"""The registered plugins by kind and name: a class, or a built-in's ``"module:Class"`` until
it is first looked up."""
_ORIGIN: dict[str, dict[str, str]] = {kind: {} for kind in KINDS}
"""Where entry-point plugins came from (``"<name> from <distribution>"``), by kind and name."""
_BROKEN: dict[str, dict[str, str]] = {kind: {} for kind in KINDS}
"""Entry points that failed to load: why, by kind and name."""
_ENTRY_POINTS_LOADED = False
_ANNOUNCE = [True]

C = TypeVar("C", bound=type)


class Plugin(Protocol):
    """A registered class as the registry knows it (an estimator or a controller).

    Attributes:
        name: its name in scenario files.
        kind: ``"estimator"`` or ``"controller"``.
        Options: its frozen options dataclass (the scenario file's schema of its table).
    """

    name: ClassVar[str]
    kind: ClassVar[str]
    Options: ClassVar[type[Any]]

    def __init__(self, geometry: Any, options: Any = None) -> None: ...


__all__ = [
    "BUILTINS",
    "NoOptions",
    "OptionError",
    "OptionSpec",
    "PluginWarning",
    "build",
    "installed",
    "load_modules",
    "lookup",
    "make_controller",
    "make_estimator",
    "names",
    "option",
    "register",
    "registry",
    "spec_of",
    "unannounced",
]
"""Plugin authors import :func:`option`, :class:`NoOptions`, :class:`OptionError` from here as
well (their home is the leaf module :mod:`cdpr_twin.options`)."""


class PluginWarning(UserWarning):
    """An installed plugin could not be loaded (it is skipped; naming it is an error)."""


def register(cls: C) -> C:
    """Class decorator: add an estimator or controller to the registry under ``cls.name``.

    Raises:
        TypeError: when the class has no name, no known kind, no dataclass ``Options``, is not
            an :class:`~cdpr_twin.estimators.base.Estimator` or
            :class:`~cdpr_twin.controllers.base.Controller`, or leaves an abstract method out.
        ValueError: when another class already has that name.
    """
    kind, name = getattr(cls, "kind", ""), getattr(cls, "name", "")
    if kind not in KINDS or not name:
        raise TypeError(f"{cls.__name__}: set class attributes kind (one of {KINDS}) and name")
    checked = _check(cls, kind)
    known = _REGISTRY[kind].get(name)
    here = f"{cls.__module__}:{cls.__qualname__}"
    if known is not None and here != (known if isinstance(known, str) else _ref(known)):
        where = known.split(":")[0] if isinstance(known, str) else known.__module__
        raise ValueError(f"{_a(kind)} named {name!r} is already registered ({where})")
    _REGISTRY[kind][name] = checked
    return cls


def _ref(cls: type) -> str:
    """``"module:Class"`` of a class."""
    return f"{cls.__module__}:{cls.__qualname__}"


def _check(cls: type, kind: str) -> type[Plugin]:
    """Refuse a class that cannot be a plugin of ``kind`` (see :func:`register`).

    Returns:
        ``cls``, checked to be a :class:`Plugin`.
    """
    base = _base(kind)
    if not (isinstance(cls, type) and issubclass(cls, base)):
        raise TypeError(f"{cls!r}: {_a(kind)} must subclass {base.__module__}.{base.__name__}")
    if inspect.isabstract(cls):
        missing = ", ".join(sorted(getattr(cls, "__abstractmethods__", ())))
        raise TypeError(f"{cls.__name__}: implement {missing} (abstract in {base.__name__})")
    options = getattr(cls, "Options", None)
    params = getattr(options, "__dataclass_params__", None)
    if not (dataclasses.is_dataclass(options) and params is not None and params.frozen):
        raise TypeError(f"{cls.__name__}: Options must be a frozen dataclass")
    name = getattr(cls, "name", "")
    if name in RESERVED_NAMES or not name.isidentifier():
        raise ValueError(
            f"{cls.__name__}: {name!r} cannot name {_a(kind)} (a column prefix of run files, or "
            f"not an identifier); reserved: {', '.join(sorted(RESERVED_NAMES))}"
        )
    # every attribute of the protocol was checked above
    return cast("type[Plugin]", cls)


def _resolve(kind: str, name: str) -> type[Plugin]:
    """The class registered under ``name``, a built-in's imported now if it was not yet."""
    entry = _REGISTRY[kind][name]
    if isinstance(entry, str):
        module, _, attr = entry.partition(":")
        cls = getattr(importlib.import_module(module), attr)
        if getattr(cls, "name", None) != name or getattr(cls, "kind", None) != kind:
            raise TypeError(f"{entry} is not the {kind} named {name!r}")
        _REGISTRY[kind][name] = entry = _check(cls, kind)
    return entry


def _a(kind: str) -> str:
    """``kind`` with its article: "an estimator", "a controller"."""
    return f"{'an' if kind[0] in 'aeiou' else 'a'} {kind}"


def _base(kind: str) -> type:
    """The class a plugin of ``kind`` subclasses (imported here: the bases import this module)."""
    if kind == "estimator":
        from cdpr_twin.estimators.base import Estimator

        return Estimator
    from cdpr_twin.controllers.base import Controller

    return Controller


def _load_entry_points() -> None:
    """Register the installed packages' plugins (their entry points), once a process."""
    global _ENTRY_POINTS_LOADED
    if not _ENTRY_POINTS_LOADED:
        _ENTRY_POINTS_LOADED = True
        for kind in KINDS:
            for ep in importlib.metadata.entry_points(group=ENTRY_POINT_GROUPS[kind]):
                _load_entry_point(kind, ep)


def _load_entry_point(kind: str, ep: importlib.metadata.EntryPoint) -> None:
    """Register the plugin an entry point names; a broken one is remembered and skipped."""
    dist = getattr(ep.dist, "name", None) or "an unknown distribution"
    known = _REGISTRY[kind].get(ep.name)
    try:
        obj = ep.load()
        if isinstance(obj, type) and (known is None or known is not obj):
            if getattr(obj, "kind", "") != kind or getattr(obj, "name", "") != ep.name:
                raise TypeError(
                    f"{ep.value} must be a {kind} class whose name is {ep.name!r} "
                    f"(kind {getattr(obj, 'kind', None)!r}, name {getattr(obj, 'name', None)!r})"
                )
            register(obj)
        if ep.name not in _REGISTRY[kind]:
            raise TypeError(f"{ep.value} registered no {kind} named {ep.name!r}")
    except (Exception, SystemExit) as exc:  # SystemExit: a sys.exit() at its import
        what = f"sys.exit({exc.code!r})" if isinstance(exc, SystemExit) else exc
        why = f"entry point {ep.name} = {ep.value!r} of {dist} failed to load: {what}"
        _BROKEN[kind][ep.name] = why
        # one line, blamed on no source line (it is read whatever a command is doing)
        warnings.warn_explicit(
            f"{why}; fix or uninstall {dist}", PluginWarning, "cdpr_twin plugins", 0
        )
        return
    _ORIGIN[kind][ep.name] = f"{ep.name} (from {dist})"


def installed(kind: str) -> str:
    """The registered names of one kind, entry-point plugins with their distribution."""
    return ", ".join(_ORIGIN[kind].get(n, n) for n in names(kind))


def registry(kind: str) -> Mapping[str, type[Plugin]]:
    """The registered classes of one kind, by name, every built-in imported (a copy)."""
    return MappingProxyType({name: _resolve(kind, name) for name in names(kind)})


def names(kind: str) -> tuple[str, ...]:
    """Registered names of one kind, in registration order (nothing is imported for them)."""
    _load_entry_points()
    return tuple(_REGISTRY[kind])


@overload
def lookup(kind: Literal["estimator"], name: str) -> type[Estimator]: ...
@overload
def lookup(kind: Literal["controller"], name: str) -> type[Controller]: ...
@overload
def lookup(kind: str, name: str) -> type[Plugin]: ...


def lookup(kind: str, name: str) -> type[Plugin]:
    """The class registered under a name.

    Raises:
        ValueError: for an unknown name, listing the known ones.
    """
    if name not in names(kind):
        if name in _BROKEN[kind]:
            raise ValueError(f"{kind} {name!r}: {_BROKEN[kind][name]}") from None
        raise ValueError(
            f"unknown {kind} {name!r}; choose one of {installed(kind)} (installed; more come from "
            f"packages' {ENTRY_POINT_GROUPS[kind]!r} entry points or a scenario's plugins list)"
        ) from None
    return _resolve(kind, name)


def build(kind: str, name: str, geometry: Any, **options: Any) -> Any:
    """Instantiate a registered plugin with keyword options (SI units).

    Raises:
        ValueError: for an unknown name, an unknown option or an invalid value.
    """
    cls = lookup(kind, name)
    try:
        opts = cls.Options(**options)
    except TypeError as exc:
        known = ", ".join(f.name for f in dataclasses.fields(cls.Options)) or "none"
        raise ValueError(
            f"{kind} {name!r}: bad options {sorted(options)} ({exc}); known: {known}"
        ) from None
    except OptionError as exc:
        raise ValueError(f"{name}: {exc}") from None
    for f in dataclasses.fields(opts):  # the bounds a scenario file's reader checks
        if (problem := _below_minimum(spec_of(f), getattr(opts, f.name))) is not None:
            raise ValueError(f"{name}: {f.name}: {problem}")
    return cls(geometry, opts)


def make_estimator(name: str, geometry: Any, **options: Any) -> Any:
    """Build a registered estimator by name (:func:`build`).

    Args:
        name: a registered estimator name (:func:`names`).
        geometry: the nominal :class:`~cdpr_twin.math.geometry.CdprGeometry`.
        **options: fields of the estimator's ``Options`` (e.g. ``reference="first"`` for
            ``image``, ``backend="scipy"`` for ``model_*``).

    Raises:
        ValueError: for an unknown name or option.
    """
    return build("estimator", name, geometry, **options)


def make_controller(name: str, geometry: Any, **options: Any) -> Any:
    """Build a registered controller by name with keyword options (SI units; :func:`build`).

    Raises:
        ValueError: for an unknown name or bad options.
    """
    return build("controller", name, geometry, **options)


def _below_minimum(spec: OptionSpec, value: Any) -> str | None:
    """Why ``value`` (SI; a number or a tuple of them) breaks ``spec.minimum``, or ``None``."""
    if spec.minimum is None:
        return None
    low = math.radians(spec.minimum) if spec.unit == "deg" else spec.minimum
    for v in value if isinstance(value, tuple) else (value,):
        if isinstance(v, (int, float)) and not (v > low if spec.exclusive else v >= low):
            return f"must be {'>' if spec.exclusive else '≥'} {low:g} (SI units), got {v!r}"
    return None


@contextlib.contextmanager
def unannounced() -> Iterator[None]:
    """Within: plugins are loaded without their line on stderr.

    A campaign's workers load them again: the campaign named them when it read its runs.
    """
    said, _ANNOUNCE[0] = _ANNOUNCE[0], False
    try:
        yield
    finally:
        _ANNOUNCE[0] = said


def _announce(what: str) -> None:
    """Name on stderr a plugin about to be loaded: its code runs (once a process, as it loads)."""
    if _ANNOUNCE[0]:
        print(f"cdpr-twin: loading plugin {what}", file=sys.stderr, flush=True)


def load_modules(refs: list[str], base_dir: Path) -> None:
    """Import plugin modules: dotted module names, or ``.py`` files relative to ``base_dir``.

    Each one not yet loaded in this process is named on stderr first (its code is about to run).

    Raises:
        ImportError: when one cannot be imported (with the reason).
    """
    for ref in refs:
        if ref.endswith(".py"):
            path = Path(ref) if Path(ref).is_absolute() else (base_dir / ref).resolve()
            if (kind := path_kind(path, ImportError)) != "file":
                why = "a directory, not a Python file" if kind == "dir" else "plugin file not found"
                raise ImportError(f"{path}: {why}")
            digest = hashlib.sha1(str(path).encode()).hexdigest()[:12]
            mod_name = f"cdpr_twin_plugin_{path.stem}_{digest}"  # one module per file path
            if mod_name in sys.modules:
                continue
            spec = importlib.util.spec_from_file_location(mod_name, path)
            assert spec is not None and spec.loader is not None
            module = importlib.util.module_from_spec(spec)
            _announce(str(path))
            sys.modules[mod_name] = module
            try:
                spec.loader.exec_module(module)
            except BaseException as exc:
                del sys.modules[mod_name]  # a failed import is not cached half-built
                _no_exit(exc, f"plugin file {path}")
                raise
        else:
            if ref not in sys.modules:
                _announce(f"module {ref}")
            try:
                importlib.import_module(ref)
            except SystemExit as exc:
                _no_exit(exc, f"plugin module {ref}")
            except ModuleNotFoundError as exc:
                beside = base_dir / f"{ref.replace('.', '/')}.py"
                if exc.name != ref.split(".")[0] or not beside.is_file():
                    raise
                raise ModuleNotFoundError(  # the file is there: name it as a file
                    f"{exc}; {beside.name} beside the scenario is named with its .py: "
                    f'"{ref.replace(".", "/")}.py"'
                ) from None


def _no_exit(exc: BaseException, what: str) -> None:
    """A plugin's ``sys.exit()`` at its import as an ImportError: not its exit code to choose."""
    if isinstance(exc, SystemExit):
        raise ImportError(f"{what} called sys.exit({exc.code!r}) while loading") from None
