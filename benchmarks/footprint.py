"""The disk footprint of installing cdpr-twin, plain and with each extra.

For each install (the package's own requirements, plus an extra's), the closure of required
distributions is resolved from the metadata of the distributions installed in the running
environment, and their installed files (each distribution's RECORD) are summed. Run it from an
environment holding every extra (``pip install -e '.[test,ray,gym,plots,docs]'``):

    python benchmarks/footprint.py [--also matplotlib]

``--also NAME`` adds a distribution to the plain install (to measure a dependency that moved
behind an extra, as it was before). Sizes are of the wheels installed for this interpreter and
platform; pip and setuptools themselves are not counted.
"""

import argparse
import importlib.metadata as md
import os
import re

from packaging.requirements import Requirement


def _name(text: str) -> str:
    return re.sub(r"[-_.]+", "-", text).lower()


def _size(dist: md.Distribution) -> int:
    total = 0
    for f in dist.files or []:
        try:
            total += os.path.getsize(f.locate())
        except OSError:
            continue
    return total


def closure(roots: list[Requirement]) -> dict[str, md.Distribution]:
    """Every installed distribution the requirements need, by normalised name."""
    found: dict[str, md.Distribution] = {}
    todo = [(r, set(r.extras)) for r in roots]
    while todo:
        req, extras = todo.pop()
        name = _name(req.name)
        try:
            dist = md.distribution(req.name)
        except md.PackageNotFoundError:
            continue
        first = name not in found
        found[name] = dist
        for text in dist.requires or []:
            sub = Requirement(text)
            wanted = [{"extra": e} for e in extras] or [{"extra": ""}]
            if sub.marker and not any(sub.marker.evaluate(env) for env in wanted):
                continue
            if first or sub.marker:
                todo.append((sub, set(sub.extras)))
    return found


def main() -> None:
    """Print the footprint of each install, in MB."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--also", action="append", default=[], help="add to the plain install")
    args = parser.parse_args()
    extras = md.metadata("cdpr-twin").get_all("Provides-Extra") or []
    base = closure([Requirement("cdpr-twin"), *map(Requirement, args.also)])
    plain = sum(_size(d) for n, d in base.items() if n != "cdpr-twin")
    label = "plain" + "".join(f" + {a}" for a in args.also)
    print(f"{label:28s} {plain / 1e6:8.0f} MB  ({len(base)} distributions)")
    for extra in extras:
        with_extra = closure([Requirement(f"cdpr-twin[{extra}]")])
        added = sum(_size(d) for n, d in with_extra.items() if n not in base)
        print(f"  + [{extra}]{'':{18 - len(extra)}s} {added / 1e6:8.0f} MB more")


if __name__ == "__main__":
    main()
