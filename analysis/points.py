"""Measurement point labels in the paper's notation ``component:node:direction``.

Examples: ``left:9:Y``, ``top:4:X``, ``right:4:-Z``, ``right:6:-X`` (the paper's
excitation point). The direction is one of X, Y, Z with an optional leading sign.

UFF files label a point by a node number and a direction code (1=+X, 2=+Y, 3=+Z,
negative for the opposite sense). :func:`uff_node` maps a component and node to a
single node number: known components get a base (left=1000, top=2000, right=3000),
a component ``n`` or ``node`` maps to the bare node number, any other component
gets a stable base from its name.

Labels of other shapes (e.g. ``view0:acc:Z`` or ``f16:shaker:Z`` from other tools' files) still
get a UFF degree of freedom (:func:`uff_dofs`): the direction from the label's last ``:`` part when
it is a signed X/Y/Z (else +Z), and a node number of their own from ``FREE_NODE_BASE`` on.
"""
from __future__ import annotations

import re
import zlib
from collections.abc import Iterable
from dataclasses import dataclass

from .errors import PointLabelError

__all__ = ["Point", "PointLabelError", "parse_point", "uff_node", "uff_direction", "point_from_uff",
           "label_direction", "uff_dofs", "FREE_NODE_BASE"]

_DIRECTIONS = {"X": 1, "Y": 2, "Z": 3}
_COMPONENT_BASE = {"left": 1000, "top": 2000, "right": 3000}
#: first UFF node number of labels that are not ``component:node:direction`` (and of a label whose
#: degree of freedom another label of the same file took); above every number :func:`uff_node` gives
#: a component's nodes below 1 000 000
FREE_NODE_BASE = 2_000_000
#: how many node numbers the free labels spread over (a label's number is stable: from its name)
_FREE_NODE_SPAN = 1_000_000
_PATTERN = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*:\s*(\d+)\s*:\s*([+-]?)([XYZxyz])\s*$")


@dataclass(frozen=True, order=True)
class Point:
    """A measurement point: structure component, node number and signed direction."""

    component: str
    node: int
    direction: str  # "X", "-Y", ...

    def __post_init__(self) -> None:
        d = self.direction.upper().lstrip("+")
        if d.lstrip("-") not in _DIRECTIONS or d.count("-") > 1:
            raise PointLabelError(f"bad direction {self.direction!r}: expected X, Y or Z, optionally signed")
        object.__setattr__(self, "direction", d)
        if self.node < 0:
            raise PointLabelError(f"bad node {self.node}: must be >= 0")

    @property
    def axis(self) -> int:
        """0, 1 or 2 for X, Y, Z."""
        return _DIRECTIONS[self.direction.lstrip("-")] - 1

    @property
    def sign(self) -> int:
        """+1 or -1."""
        return -1 if self.direction.startswith("-") else 1

    def __str__(self) -> str:
        return f"{self.component}:{self.node}:{self.direction}"


def parse_point(label: str | Point) -> Point:
    """Parse ``component:node:direction`` into a :class:`Point`."""
    if isinstance(label, Point):
        return label
    m = _PATTERN.match(str(label))
    if not m:
        raise PointLabelError(
            f"bad point label {label!r}: expected component:node:direction, e.g. 'left:9:Y' or 'right:4:-Z'"
        )
    comp, node, sign, axis = m.groups()
    return Point(comp, int(node), ("-" if sign == "-" else "") + axis.upper())


def uff_node(point: str | Point) -> int:
    """UFF node number of a point (see module docstring)."""
    p = parse_point(point)
    if p.component in ("n", "node"):
        return p.node
    base = _COMPONENT_BASE.get(p.component)
    if base is None:
        base = 10000 * (1 + zlib.crc32(p.component.encode()) % 100)
    return base + p.node


def uff_direction(point: str | Point) -> int:
    """UFF direction code of a point: +-1, +-2, +-3 for X, Y, Z."""
    p = parse_point(point)
    return p.sign * (p.axis + 1)


def point_from_uff(node: int, direction: int) -> Point:
    """Inverse of :func:`uff_node`/:func:`uff_direction` for the known bases."""
    if direction == 0 or abs(direction) > 3:
        raise PointLabelError(f"UFF direction {direction} is not a translation (expected +-1, +-2, +-3)")
    axis = "XYZ"[abs(direction) - 1]
    d = ("-" if direction < 0 else "") + axis
    for comp, base in _COMPONENT_BASE.items():
        if base <= node < base + 1000:
            return Point(comp, node - base, d)
    return Point("n", int(node), d)


def label_direction(label: str | Point) -> int:
    """UFF direction code (+-1, +-2, +-3 for X, Y, Z) of any point label: that of a
    ``component:node:direction`` label, else the label's last ``:`` part when it is a signed X, Y
    or Z (``view0:acc:-Y`` -> -2), else +3 (+Z)."""
    try:
        return uff_direction(label)
    except PointLabelError:
        last = str(label).rsplit(":", 1)[-1].strip().upper()
        axis = last.lstrip("+-")
        if axis in _DIRECTIONS and len(last) - len(axis) <= 1:
            return -_DIRECTIONS[axis] if last.startswith("-") else _DIRECTIONS[axis]
        return _DIRECTIONS["Z"]


def _free_node(label: str) -> int:
    """A stable node number for a label :func:`uff_node` cannot number: from its name without the
    direction part, so the directions of one location share a node."""
    stem = str(label)
    last = stem.rsplit(":", 1)
    if len(last) == 2 and last[1].strip().upper().lstrip("+-") in _DIRECTIONS:
        stem = last[0]
    return FREE_NODE_BASE + zlib.crc32(stem.encode("utf-8", "surrogatepass")) % _FREE_NODE_SPAN


def uff_dofs(labels: Iterable[str | Point]) -> dict[str, tuple[int, int]]:
    """``{label: (UFF node number, direction code)}`` for every label, distinct labels on distinct
    degrees of freedom. ``component:node:direction`` labels get :func:`uff_node` and
    :func:`uff_direction`; any other label (e.g. ``view0:acc:Z``) gets :func:`label_direction` and
    a node number of its own from ``FREE_NODE_BASE`` on; a label whose degree of freedom an earlier
    label took moves to the next free node number. UFF records hold only the numbers: a writer keeps
    the labels themselves beside them (the ID lines, :mod:`analysis.uff`) to read them back."""
    out: dict[str, tuple[int, int]] = {}
    taken: set[tuple[int, int]] = set()
    for item in labels:
        label = str(item)
        if label in out:
            continue
        try:
            node, direction = uff_node(label), uff_direction(label)
        except PointLabelError:
            node, direction = _free_node(label), label_direction(label)
        if (node, direction) in taken:
            node = max(node, FREE_NODE_BASE)
            while (node, direction) in taken:
                node += 1
        taken.add((node, direction))
        out[label] = (node, direction)
    return out
