"""MJCF text from an ``MjSpec`` that compiles to the spec's model bit for bit.

MuJoCo's XML writer (``MjSpec.to_xml``, MuJoCo 4.0) prints numbers with 6 significant digits,
which moves an E·S of 348 716.8 N to 348 717 N and a 45° quaternion by 5e-7. :func:`to_xml`
keeps the writer's document and rewrites every number of a named element (and of each explicit
``<inertial>``) at full precision from the spec itself (colours, stored as float32, excepted).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET

import mujoco
import numpy as np

_GETTERS = {
    "body": "body",
    "geom": "geom",
    "site": "site",
    "camera": "camera",
    "numeric": "numeric",
    "general": "actuator",
    "key": "key",
    "spatial": "tendon",
    "light": "light",
    "texture": "texture",
    "material": "material",
    "actuatorfrc": "sensor",
}


def _number(v: float) -> str:
    s = repr(float(v))
    return s[:-2] if s.endswith(".0") else s


def _exact(elem: ET.Element, obj: object) -> None:
    """Rewrite ``elem``'s numeric attributes from the spec object ``obj`` at full precision."""
    for attr, text in elem.attrib.items():
        value = getattr(obj, attr, None)
        if value is None or isinstance(value, str):
            continue
        try:
            n = len([float(x) for x in text.split()])
            arr = np.asarray(value)
            flat = np.ravel(arr.astype(float))
        except (TypeError, ValueError):
            continue
        if arr.dtype == np.float32:  # colours: six digits round-trip a float32
            continue
        if n and flat.size >= n:
            elem.set(attr, " ".join(_number(v) for v in flat[:n]))


def to_xml(spec: mujoco.MjSpec) -> str:
    """The spec as MJCF text, every number of a named element at full precision.

    Args:
        spec: a spec (compiled by MuJoCo's writer on the way).

    Returns:
        The XML text; it compiles to the same model as ``spec`` bit for bit.
    """
    text = spec.to_xml()
    root = ET.fromstring(text, parser=ET.XMLParser(target=ET.TreeBuilder(insert_comments=True)))
    for elem in root.iter():
        if elem.tag == "option":
            _exact(elem, spec.option)
        name = elem.get("name")
        getter = _GETTERS.get(elem.tag)
        if getter and name:
            obj = getattr(spec, getter)(name)
            if obj is not None:
                _exact(elem, obj)
    for elem in root.iter("body"):
        inertial = elem.find("inertial")
        if inertial is not None:  # the writer prints the compiled principal axes (6 digits)
            _inertial(inertial, spec.body(elem.get("name")))
    ET.indent(root, "  ")
    return ET.tostring(root, encoding="unicode") + "\n"


def _inertial(elem: ET.Element, body: mujoco.MjsBody) -> None:
    """An explicit ``<inertial>`` as the spec states it, at full precision."""
    elem.attrib.clear()
    elem.set("pos", " ".join(map(_number, body.ipos)))
    elem.set("mass", _number(body.mass))
    if np.all(np.isfinite(body.fullinertia)) and np.any(body.fullinertia):
        elem.set("fullinertia", " ".join(map(_number, body.fullinertia)))
    else:
        elem.set("quat", " ".join(map(_number, body.iquat)))
        elem.set("diaginertia", " ".join(map(_number, body.inertia)))
