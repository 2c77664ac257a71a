"""A URDF's XML where Pinocchio's parser does not look (inertials checked, collision shapes, limits): numbers read
with a one-line error naming the file, link and attribute, and links' collision shapes placed in their link's
frame."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pinocchio as pin

from livezmp.errors import InputError


def numbers(el: ET.Element, attr: str, n: int, default: str, where: str) -> np.ndarray:
    """``n`` finite numbers from ``el``'s ``attr`` (``default`` where it is absent); InputError naming ``where``."""
    text = el.get(attr, default)
    try:
        vals = np.array([float(v) for v in text.split()])
    except ValueError:
        raise InputError(f"{where} {attr}: {text[:40]!r} is not {n} numbers") from None
    if vals.shape != (n,) or not np.all(np.isfinite(vals)):
        raise InputError(f"{where} {attr}: {text[:40]!r} is not {n} finite numbers")
    return vals


# an <inertia>'s attributes, the upper triangle of its symmetric matrix row by row (np.triu_indices(3)'s order)
INERTIA_KEYS = ("ixx", "ixy", "ixz", "iyy", "iyz", "izz")


def inertia_matrix(el: ET.Element, where: str) -> np.ndarray:
    """(3, 3) kg m^2: the symmetric matrix of an ``<inertia>`` element (its `INERTIA_KEYS`, each 0 when absent)."""
    upper = [numbers(el, k, 1, "0", where)[0] for k in INERTIA_KEYS]
    inertia = np.zeros((3, 3))
    inertia[np.triu_indices(3)] = upper
    inertia[np.tril_indices(3, -1)] = inertia.T[np.tril_indices(3, -1)]
    return inertia


def collision_shapes(root: ET.Element, path: Path, tags: tuple[str, ...], element: str = "collision"
                     ) -> Iterator[tuple[str, ET.Element, pin.SE3, str]]:
    """Each link's ``<collision>`` (or ``element``'s: ``visual``) shape of one of ``tags`` (``box``, ``cylinder``,
    ``sphere``), in the file's order: its link's name, the shape's element, its pose in the link's frame
    (``<origin>``, m and rad) and where it is (file, link, shape) for a message."""
    for link in root.findall("link"):
        for collision in link.findall(element):
            shape = next((s for s in (collision.find(f"geometry/{tag}") for tag in tags) if s is not None), None)
            if shape is None:
                continue
            where = f"{path}: link {link.get('name')!r} <{element}> <{shape.tag}>"
            origin = collision.find("origin")
            xyz, rpy = ((numbers(origin, attr, 3, "0 0 0", f"{where} <origin>") for attr in ("xyz", "rpy"))
                        if origin is not None else (np.zeros(3), np.zeros(3)))
            yield link.get("name"), shape, pin.SE3(pin.rpy.rpyToMatrix(*rpy), xyz), where
