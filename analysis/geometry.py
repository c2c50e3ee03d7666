"""Test geometry: labelled nodes (xyz in m) and trace lines, for drawing and animating mode shapes.

Node labels are ``component:node`` (the first two parts of a point label ``component:node:direction``,
see :mod:`analysis.points`). Files: UFF data set 15 (nodes) and 82 (trace lines) through pyuff; a
UFF node number maps to a label with :func:`analysis.points.point_from_uff` and back with
:func:`analysis.points.uff_dofs`. Without a geometry, :func:`points_on_a_line` puts the measured
points on a line, 0.1 m apart, joined in order.
"""
from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .errors import GeometryError
from .points import point_from_uff, uff_dofs

__all__ = ["Geometry", "GeometryError", "node_label", "points_on_a_line", "read_uff_geometry",
           "write_uff_geometry"]


@dataclass(frozen=True)
class Geometry:
    """Nodes and trace lines of a test structure.

    labels : node labels ``component:node``, one per row of ``xyz``.
    xyz : (n_nodes, 3) float, m.
    lines : pairs of node labels joined by a trace line.
    name : a short description (where the geometry came from).
    supports : labels of nodes held still (a drawing's interpolation of unmeasured nodes keeps them at rest).
    """

    labels: tuple
    xyz: np.ndarray
    lines: tuple = ()
    name: str = ""
    meta: dict = field(default_factory=dict)
    supports: tuple = ()

    def __post_init__(self) -> None:
        labels = tuple(str(s) for s in self.labels)
        xyz = np.asarray(self.xyz, dtype=float).reshape(-1, 3)
        if len(labels) != xyz.shape[0]:
            raise GeometryError(f"{len(labels)} node labels for {xyz.shape[0]} node coordinates")
        if len(set(labels)) != len(labels):
            raise GeometryError("node labels must be unique")
        if not np.all(np.isfinite(xyz)):
            raise GeometryError("node coordinates must be finite numbers (m)")
        known = set(labels)
        lines = tuple((str(a), str(b)) for a, b in self.lines)
        bad = [f"{a}-{b}" for a, b in lines if a not in known or b not in known]
        if bad:
            raise GeometryError(f"trace lines name unknown nodes: {', '.join(bad[:5])}")
        supports = tuple(str(x) for x in self.supports)
        bad = [x for x in supports if x not in known]
        if bad:
            raise GeometryError(f"supports name unknown nodes: {', '.join(bad[:5])}")
        xyz.setflags(write=False)
        object.__setattr__(self, "supports", supports)
        object.__setattr__(self, "labels", labels)
        object.__setattr__(self, "xyz", xyz)
        object.__setattr__(self, "lines", lines)

    def index(self, label: str) -> int:
        """Row of node ``label`` in ``xyz``; GeometryError when absent."""
        try:
            return self.labels.index(label)
        except ValueError:
            raise GeometryError(f"node {label!r} is not in the geometry {self.name!r}") from None

    def covers(self, points: Iterable[str]) -> list[str]:
        """The point labels whose node is *not* in the geometry (empty: all are drawn)."""
        known = set(self.labels)
        return [p for p in points if node_label(p) not in known]

    def describe_nodes(self) -> str:
        """The nodes in a line for messages: ``top:0..12, left:0..9`` (ranges of each component)."""
        comps: dict[str, list[str]] = {}
        for label in self.labels:
            comp, _, node = label.partition(":")
            comps.setdefault(comp, []).append(node)
        parts = []
        for comp, nodes in comps.items():
            nums = sorted(int(n) for n in nodes if n.isdigit())
            if len(nums) == len(nodes) and nums == list(range(nums[0], nums[-1] + 1)):
                parts.append(f"{comp}:{nums[0]}..{nums[-1]}" if len(nums) > 1 else f"{comp}:{nums[0]}")
            else:
                parts.append(", ".join(f"{comp}:{n}" for n in nodes))
        return ", ".join(parts)

    def check_points(self, points: Iterable[str]) -> None:
        """Raise :class:`GeometryError` naming the first point whose node is not in the geometry and
        the geometry's nodes."""
        missing = self.covers(points)
        if missing:
            where = f" {self.name}" if self.name else " geometry"
            raise GeometryError(f"point {missing[0]}: node {node_label(missing[0])} is not on the{where}; its "
                                f"nodes are {self.describe_nodes()}: choose points among them")

    def to_dict(self) -> dict:
        """JSON-ready: labels, xyz (m, rounded to 0.1 mm), lines as index pairs, name, supports as indices."""
        idx = {s: i for i, s in enumerate(self.labels)}
        return {"name": self.name, "labels": list(self.labels),
                "xyz": np.round(self.xyz, 4).tolist(),
                "lines": [[idx[a], idx[b]] for a, b in self.lines],
                "supports": [idx[s] for s in self.supports]}


def node_label(point: str) -> str:
    """``component:node`` of a point label ``component:node:direction`` (or of a node label)."""
    parts = str(point).split(":")
    return ":".join(parts[:2])


def points_on_a_line(points: Sequence[str], spacing_m: float = 0.1) -> Geometry:
    """The measured points' nodes on the X axis, ``spacing_m`` apart in order, joined in order."""
    nodes: list[str] = []
    for p in points:
        n = node_label(p)
        if n not in nodes:
            nodes.append(n)
    xyz = np.zeros((len(nodes), 3))
    xyz[:, 0] = spacing_m * np.arange(len(nodes))
    return Geometry(tuple(nodes), xyz, tuple(zip(nodes[:-1], nodes[1:])), name="points on a line")


def _label_of_uff(node: int) -> str:
    p = point_from_uff(int(node), 3)
    return f"{p.component}:{p.node}"


def _uff_of_label(label: str) -> int:
    """The UFF node number of a node label ``component:node``: that of its points in UFF 55/58
    records (:func:`analysis.points.uff_dofs`, also for labels of other tools such as ``view0:acc``)."""
    point = f"{label}:Z"
    return uff_dofs([point])[point][0]


def read_uff_geometry(path: str | Path) -> Geometry:
    """Nodes (data set 15, coordinates converted to m with the file's units when given) and trace
    lines (data set 82) of a UFF file; GeometryError when the file holds no data set 15."""
    import pyuff

    from .input_limits import check_input_file, text_data_limit_bytes

    p = Path(path)
    if not p.exists():
        raise GeometryError(f"geometry file {p} not found: check the path")
    check_input_file(p, "--geometry file", text_data_limit_bytes(), GeometryError)
    try:
        sets = pyuff.UFF(str(p)).read_sets()
    except (OSError, ValueError, KeyError, IndexError, TypeError, UnicodeDecodeError, AttributeError) as exc:
        raise GeometryError(f"cannot read UFF file {p}: {exc}") from None
    if isinstance(sets, dict):
        sets = [sets]
    scale = 1.0
    for s in sets:
        if s.get("type") == 164 and s.get("length"):
            scale = float(s["length"])  # units data set: metres per file length unit
    labels: list[str] = []
    xyz: list = []
    lines: list = []
    for s in sets:
        if s.get("type") == 15:
            for n, x, y, z in zip(s["node_nums"], s["x"], s["y"], s["z"]):
                labels.append(_label_of_uff(int(n)))
                xyz.append((float(x) / scale, float(y) / scale, float(z) / scale))
    for s in sets:
        if s.get("type") == 82:
            nodes = [int(n) for n in s["nodes"]]
            for a, b in zip(nodes[:-1], nodes[1:]):
                if a != 0 and b != 0:  # 0 lifts the pen
                    lines.append((_label_of_uff(a), _label_of_uff(b)))
    if not labels:
        raise GeometryError(f"{p} holds no node coordinates (UFF data set 15): give a geometry file with nodes")
    return Geometry(tuple(labels), np.asarray(xyz), tuple(lines), name=p.name)


def write_uff_geometry(path: str | Path, geometry: Geometry, *, overwrite: bool = True) -> Path:
    """Write data set 15 (nodes, m) and one data set 82 per trace line of ``geometry``."""
    import pyuff

    from .atomic import atomic_path

    p = Path(path)
    if p.exists() and not overwrite:
        raise GeometryError(f"{p} exists: choose another output file, or replace it")
    nums = [_uff_of_label(s) for s in geometry.labels]
    x = geometry.xyz
    with atomic_path(p) as tmp:
        uff = pyuff.UFF(str(tmp))
        uff.write_sets(pyuff.prepare_15(node_nums=nums, def_cs=[0] * len(nums), disp_cs=[0] * len(nums),
                                        color=[1] * len(nums), x=x[:, 0].tolist(), y=x[:, 1].tolist(),
                                        z=x[:, 2].tolist()), mode="add")
        for k, (a, b) in enumerate(geometry.lines, start=1):
            uff.write_sets(pyuff.prepare_82(trace_num=k, n_nodes=2, color=1, id=f"line {k}",
                                            nodes=np.array([_uff_of_label(a), _uff_of_label(b)])), mode="add")
    return p


