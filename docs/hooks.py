"""MkDocs hooks: the reference pages generated from the code at build time.

The command line comes from the parser ``cdpr-twin`` itself uses; the scenario file's option
tables from the option specs that parse the files (:mod:`cdpr_twin.options`), its top-level
tables from the loader's own reads (:func:`_traced_reads`); the campaign and
robot pages from their modules' documentation and the shipped files. A page here is never
written by hand, so it cannot fall behind the code.
"""

from __future__ import annotations

import argparse
import dataclasses
import inspect
import math
import os
import re
import sys
import types
import typing
from pathlib import Path

from mkdocs.structure.files import File, Files

ROOT = Path(__file__).resolve().parent.parent


def _cli() -> str:
    from cdpr_twin.cli import _parser

    os.environ["COLUMNS"] = "100"  # argparse wraps its help to the terminal's width
    out = [
        "# Command line",
        "",
        "Generated from the parser of `cdpr-twin` (also `python -m cdpr_twin`). Exit codes: 0 "
        "done, 1 a failure while running or writing, 2 bad input (a one-line error), 3 a fault "
        "of the simulated robot, 130 Ctrl-C, 143 SIGTERM, 141 a closed pipe.",
        "",
    ]

    def walk(parser: argparse.ArgumentParser, words: list[str]) -> None:
        out.extend([f"{'#' * min(len(words) + 1, 4)} `{' '.join(words)}`", ""])
        out.extend(["```text", parser.format_help().rstrip(), "```", ""])
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    walk(sub, [*words, name])

    walk(_parser(), ["cdpr-twin"])
    return "\n".join(out)


def _attribute_docs(cls: type) -> dict[str, str]:
    """Each field's line from a class's Google-style ``Attributes:`` section."""
    doc = inspect.getdoc(cls) or ""
    found: dict[str, str] = {}
    section = doc.split("Attributes:", 1)[1] if "Attributes:" in doc else ""
    current = None
    for line in section.splitlines():
        if m := re.match(r"^    (\w+): (.*)$", line):
            current = m.group(1)
            found[current] = m.group(2)
        elif current and line.startswith("        "):
            found[current] += " " + line.strip()
        elif line.strip() and not line.startswith(" "):
            break
    return found


def _kind(hint: object, spec) -> str:
    """How a value is written in the file: its TOML kind and unit."""
    unit = f" [{spec.unit}]" if spec.unit else ""
    if spec.pose:
        return "list of poses" if typing.get_origin(hint) is tuple else "pose [x, y, z, rx, ry, rz]"
    if typing.get_origin(hint) is typing.Literal:
        return "one of " + ", ".join(f"`{a!r}`" for a in typing.get_args(hint))
    if typing.get_origin(hint) in (typing.Union, types.UnionType):
        return " or ".join(_kind(a, spec) for a in typing.get_args(hint) if a is not type(None))
    names = {float: "number", int: "integer", bool: "true/false", str: "string"}
    if hint in names:
        return names[hint] + unit
    return "list" + unit if typing.get_origin(hint) in (tuple, list) else "table"


def _default(f: dataclasses.Field, spec) -> str:
    unit = spec.unit
    if f.default is not dataclasses.MISSING:
        value = f.default
    elif f.default_factory is not dataclasses.MISSING:
        value = f.default_factory()
    else:
        return "required"
    if unit == "deg" and isinstance(value, float):
        value = round(math.degrees(value), 9)
    if dataclasses.is_dataclass(value):
        return "(table)"
    if spec.pose and hasattr(value, "shape") and value.shape == (4, 4):
        from cdpr_twin.math.se3 import vector_from_pose

        value = [round(float(v), 6) for v in vector_from_pose(value)]
    return f"`{value!r}`".replace("|", "\\|")


def _table(cls: type) -> list[str]:
    """A Markdown table of an options dataclass: file key, kind, default, bound, meaning."""
    from cdpr_twin.options import spec_of

    hints = typing.get_type_hints(cls)
    docs = _attribute_docs(cls)
    rows = ["| key | kind | default | bound | meaning |", "|---|---|---|---|---|"]
    for f in dataclasses.fields(cls):
        if not f.init or f.name.startswith("_"):
            continue
        spec = spec_of(f)
        bound = ""
        if spec.minimum is not None:
            bound = f"{'>' if spec.exclusive else '≥'} {spec.minimum:g}"
        if spec.infinite:
            bound += " (inf allowed)"
        meaning = (spec.doc or docs.get(f.name, "")).replace("``", "`").replace("|", "\\|")
        kind = _kind(hints.get(f.name), spec).replace("|", "\\|")
        rows.append(
            f"| `{spec.file_key(f.name)}` | {kind} | {_default(f, spec)} | {bound} | {meaning} |"
        )
    return rows


_TYPED_READS = ("number", "integer", "string", "boolean", "pose")
"""The scenario loader's typed reads of a key (``OptionReader``'s methods)."""


def _traced_reads() -> dict[str, dict[str, tuple[str, tuple, dict]]]:
    """Every key the scenario loader reads, by table: ``{table: {key: (read, args, kwargs)}}``.

    The loader reads its top-level tables key by key (``OptionReader.number("timestep", 0.0005,
    minimum=…, unit="s")``…): the reads themselves are the schema. They are recorded while the
    loader reads every shipped scenario; a key it only asks about (``has``) is then given to it
    alone, to record its read too (an invalid probe's error is expected and ignored).
    """
    from unittest import mock

    from cdpr_twin import resources
    from cdpr_twin.files.inputs import read_toml
    from cdpr_twin.scenario import loading
    from cdpr_twin.scenario.loading import ScenarioError
    from cdpr_twin.scenario.toml_reading import OptionReader

    found: dict[str, dict[str, tuple[str, tuple, dict]]] = {}
    defaults: dict[tuple[str, str], set[str]] = {}
    asked: set[tuple[str, str]] = set()
    rank = {"has": 0, "raw": 1, **{m: 2 for m in _TYPED_READS}}
    loader = str(Path(loading.__file__).resolve())

    def traced(method: str):
        original = getattr(OptionReader, method)

        def read(self, key, *args, **kwargs):
            # the loader's own reads (a plugin's options are read by parse_options: their
            # own pages; a typed read's inner raw() is the same read)
            if str(Path(sys._getframe(1).f_code.co_filename).resolve()) == loader:
                table = found.setdefault(self.where, {})
                if method == "has":
                    asked.add((self.where, key))
                if rank[method] >= rank[table.get(key, ("has",))[0]]:
                    table[key] = (method, args, kwargs)
                if method != "has":
                    default = args[0] if args else kwargs.get("default", ...)
                    defaults.setdefault((self.where, key), set()).add(repr(default))
            return original(self, key, *args, **kwargs)

        return read

    patches = [mock.patch.object(OptionReader, m, traced(m)) for m in rank]
    shipped = sorted(resources.scenarios_dir().glob("*.toml"))
    for patch in patches:
        patch.start()
    try:
        for path in shipped:
            loading.scenario_from_data(read_toml(path, "scenario file", ScenarioError), path)
        base = read_toml(shipped[0], "scenario file", ScenarioError)
        for table, key in sorted(asked):
            if found[table][key][0] != "has":
                continue
            data = dict(base)
            others = {k for t, k in asked if t == table and k != key}
            section = {k: v for k, v in data.get(table, {}).items() if k not in others}
            data[table] = {**section, key: "probe"}
            try:
                loading.scenario_from_data(data, shipped[0])
            except ScenarioError:
                pass
    finally:
        for patch in patches:
            patch.stop()
    for (table, key), seen in defaults.items():
        method, args, kwargs = found[table][key]
        if (table, key) in asked and not args and "default" not in kwargs:
            # read only when the file gives it
            found[table][key] = (method, ("optional", *args[1:]), kwargs)
        elif len(seen) > 1:
            # a default that depends on the file
            found[table][key] = (method, ("from the file", *args[1:]), kwargs)
    return found


def _read_kind(method: str, args: tuple, kwargs: dict) -> tuple[str, str, str]:
    """A traced read as (kind, default, bound) for the reference table."""
    default = args[0] if args else kwargs.get("default", ...)
    unit = kwargs.get("unit", "")
    if method == "raw":
        kind = args[1] if len(args) > 1 else kwargs.get("kind", "")
    elif method == "string" and kwargs.get("choices"):
        kind = "one of " + ", ".join(f"`{c!r}`" for c in kwargs["choices"])
    elif method == "pose":
        kind, default = "pose [x, y, z, rx, ry, rz] (m, deg)", ...
    else:
        names = {"number": "number", "integer": "integer", "boolean": "true/false"}
        kind = names.get(method, "string") + (f" [{unit}]" if unit else "")
    bound = ""
    if kwargs.get("minimum") is not None:
        bound = f"{'>' if kwargs.get('exclusive') else '≥'} {kwargs['minimum']:g}"
    if default is ...:
        shown = "required"
    elif default in ("optional", "from the file"):
        shown = default
    else:
        shown = f"`{default!r}`"
    return kind.replace("|", "\\|"), shown.replace("|", "\\|"), bound


def _top_level() -> list[str]:
    """The top-level tables' reference, from the loader's own reads (:func:`_traced_reads`)."""
    from cdpr_twin.robot.deviations import DeviationSpec
    from cdpr_twin.scenario import loading

    meanings = {
        "": loading.Scenario,
        "model": loading.ModelConfig,
        "truth": DeviationSpec,
        "sensors": loading.SensorConfig,
        "start": loading.Scenario,
        "monitor": loading.MonitorConfig,
        "controller": loading.ControllerConfig,
        "estimators": loading.EstimatorConfig,
    }
    # a key whose attribute has another name
    aliases = {("start", "pose"): "start_pose", ("model", "robot"): "file"}
    reads = _traced_reads()
    out = [
        "## Top-level tables",
        "",
        "Generated from the scenario loader's own reads (`cdpr_twin/scenario/loading.py` reads "
        "these tables key by key, each read naming its kind, default, unit and lower bound): "
        "they are recorded while it loads every shipped scenario. Meanings are the loaded "
        "values' documented attributes (angles in degrees in the file, radians inside). "
        "`[controller]` takes `type` and the options of that "
        "controller, `[estimators]` takes `in_loop`, `passive` and an `[estimators.<name>]` "
        "table of options per estimator ([below](#controllers)); upper bounds are named in the "
        "error a value beyond them gets.",
        "",
    ]
    for table, cls in meanings.items():
        keys = reads.get(table, {})
        docs = _attribute_docs(cls)
        title = "The file's top level" if not table else f"`[{table}]`"
        out.extend([f"### {title}", ""])
        out.extend(["| key | kind | default | bound | meaning |", "|---|---|---|---|---|"])
        for key, (method, args, kwargs) in keys.items():
            if method == "has":
                continue
            kind, default, bound = _read_kind(method, args, kwargs)
            name = aliases.get((table, key), key)
            candidates = [name, *(name.removesuffix(u) for u in ("_kg", "_m", "_deg", "_s"))]
            meaning = next((docs[c] for c in candidates if c in docs), "")
            meaning = meaning.replace("``", "`").replace("|", "\\|")
            out.append(f"| `{key}` | {kind} | {default} | {bound} | {meaning} |")
        out.append("")
    return out


def _scenario() -> str:
    from cdpr_twin.plugins import registry
    from cdpr_twin.robot import realism
    from cdpr_twin.sim import events

    out = [
        "# Scenario file",
        "",
        "Generated from the code that reads scenario files: the top-level tables from the "
        "loader's reads, the plugins', events' and realism's from their option specs "
        "(`cdpr_twin/options.py`): each table's keys, their kind and unit as written in the "
        "file (angles in degrees, converted to radians inside), default and bound. How to "
        "write one: "
        "[write a scenario](../how-to/write-a-scenario.md).",
        "",
    ]
    out.extend(_top_level())
    for kind, title in (("controller", "Controllers"), ("estimator", "Estimators")):
        out.extend([f"## {title}", ""])
        table = "[controller]" if kind == "controller" else "[estimators.<name>]"
        for name, cls in registry(kind).items():
            doc = (inspect.getdoc(cls) or "").split("\n\n")[0].replace("\n", " ")
            out.extend([f"### `{name}`", "", doc, "", f"Options, in `{table}`:", ""])
            if dataclasses.fields(cls.Options):
                out.extend([*_table(cls.Options), ""])
            else:
                out.extend(["none.", ""])
    out.extend(["## Events (`[[events]]`)", ""])
    for cls in sorted(_subclasses(events.Event), key=lambda c: c.kind):
        if cls.kind:
            doc = (inspect.getdoc(cls) or "").split("\n\n")[0].replace("\n", " ")
            out.extend([f'### `kind = "{cls.kind}"`', "", doc, "", *_table(cls), ""])
    out.extend(["## Realism (`[realism.<part>]`)", ""])
    profiles = " and ".join(f'`profile = "{p}"`' for p in realism.PROFILES if p != "ideal")
    parts = typing.get_type_hints(realism.Realism)
    for f in dataclasses.fields(realism.Realism):
        cls = parts[f.name]
        if not dataclasses.is_dataclass(cls):
            continue
        doc = (inspect.getdoc(cls) or "").split("\n\n")[0].replace("\n", " ")
        out.extend([f"### `[realism.{f.name}]`", "", doc, "", *_table(cls), ""])
        out.append(f"Defaults are the `ideal` profile's; {profiles} set their own.")
        out.append("")
    shipped = (ROOT / "scenarios" / "paper_open_loop.toml").read_text(encoding="utf-8")
    out.extend(
        [
            "## An example",
            "",
            "The shipped `paper_open_loop` (`cdpr-twin scenarios copy paper_open_loop DIR`), "
            "with why each value is what it is:",
            "",
            "```toml",
            shipped.rstrip(),
            "```",
        ]
    )
    return "\n".join(out)


def _subclasses(cls: type) -> list[type]:
    found = []
    for sub in cls.__subclasses__():
        found.extend([sub, *_subclasses(sub)])
    return found


def _fenced(doc: str, language: str) -> str:
    """A module docstring's ``::`` literal blocks as fenced code."""
    parts = re.split(r"::\n\n((?:    .*\n|\n)+)", doc + "\n")
    text = []
    for i, part in enumerate(parts):
        if i % 2:
            block = "\n".join(line[4:] for line in part.rstrip().splitlines())
            text.append(f":\n\n```{language}\n{block}\n```\n\n")
        else:
            text.append(part.replace("``", "`"))
    return "".join(text)


def _campaign() -> str:
    from cdpr_twin.campaign import spec

    shipped = (ROOT / "campaigns" / "estimators_over_robots.toml").read_text(encoding="utf-8")
    return "\n".join(
        [
            "# Campaign file",
            "",
            "Generated from `cdpr_twin/campaign/spec.py`, which reads campaign files.",
            "",
            _fenced(inspect.getdoc(spec) or "", "toml"),
            "",
            f"Random draws: {', '.join(f'`{d}`' for d in spec.DRAWS)}. Per-run files "
            f"(`artefacts`): {', '.join(f'`{a}`' for a in spec.ARTEFACTS)}. At most "
            f"{spec.MAX_RUNS:,} runs a campaign.".replace(",", " "),
            "",
            "## A shipped campaign",
            "",
            "`estimators_over_robots` (`cdpr-twin campaigns copy estimators_over_robots DIR`):",
            "",
            "```toml",
            shipped.rstrip(),
            "```",
        ]
    )


def _robot() -> str:
    from cdpr_twin.robot import description

    shipped = (ROOT / "models" / "acrobot" / "robot.toml").read_text(encoding="utf-8")
    return "\n".join(
        [
            "# Robot description file",
            "",
            "Generated from `cdpr_twin/robot/description.py`, which reads descriptions.",
            "",
            _fenced(inspect.getdoc(description) or "", "toml"),
            "",
            "## A shipped description",
            "",
            "ACROBOT's (`cdpr-twin robots copy acrobot DIR`; the source of every number: "
            "`models/acrobot/README.md`):",
            "",
            "```toml",
            shipped.rstrip(),
            "```",
        ]
    )


PAGES = {
    "reference/cli.md": _cli,
    "reference/scenario.md": _scenario,
    "reference/campaign.md": _campaign,
    "reference/robot.md": _robot,
}


def on_files(files: Files, config) -> Files:
    """Add the generated reference pages to the site."""
    for uri, make in PAGES.items():
        files.append(File.generated(config, uri, content=make()))
    return files
