"""MkDocs hooks: the reference pages generated from the code at build time.

The command line comes from the parser ``cdpr-twin`` itself uses; the scenario file's option
tables from the option specs that parse the files (:mod:`cdpr_twin.options`); the campaign and
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


def _scenario() -> str:
    from cdpr_twin.plugins import registry
    from cdpr_twin.robot import realism
    from cdpr_twin.sim import events

    out = [
        "# Scenario file",
        "",
        "Generated from the option specs that parse scenario files (`cdpr_twin/options.py`): "
        "each table's keys, their kind and unit as written in the file (angles in degrees, "
        "converted to radians inside), default and bound. How to write one: "
        "[write a scenario](../how-to/write-a-scenario.md).",
        "",
    ]
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
            "## Every table in one file",
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
