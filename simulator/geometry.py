"""The simulated frame's wireframe as an :class:`analysis.geometry.Geometry`.

Nodes are the finite-element nodes ``component:node`` of every component of a
:class:`simulator.config.FrameConfig` (xyz in m, evenly spaced from ``start_m`` to ``end_m``),
lines join consecutive nodes of a component and the node pairs of ``[joints]``; the nodes of
``[supports]`` are the geometry's supports.
"""
from __future__ import annotations

from collections.abc import Iterable

import numpy as np

from analysis.geometry import Geometry

from .config import FrameConfig

__all__ = ["frame_geometry", "device_geometry", "check_device_points"]


def frame_geometry(config: FrameConfig | None = None) -> Geometry:
    """Wireframe of the frame of ``config`` (default: ``FrameConfig.load()``)."""
    cfg = config if config is not None else FrameConfig.load()
    labels: list[str] = []
    xyz: list[np.ndarray] = []
    lines: list[tuple[str, str]] = []
    for name, comp in cfg.components.items():
        start, end = np.asarray(comp.start_m, float), np.asarray(comp.end_m, float)
        n = int(comp.n_elements)
        for i in range(n + 1):
            labels.append(f"{name}:{i}")
            xyz.append(start + (i / n) * (end - start))
            if i:
                lines.append((f"{name}:{i - 1}", f"{name}:{i}"))
    for a, b in cfg.joints.pairs:
        lines.append((str(a), str(b)))
    return Geometry(tuple(labels), np.asarray(xyz), tuple(lines), name=f"simulated frame ({cfg.source})",
                    supports=tuple(str(n) for n in cfg.supports.nodes))


def device_geometry(url: str) -> Geometry | None:
    """The frame a simulated device URL (``sim://``, ``usbsim://``, with its ``config=``) holds; None for
    any other device and for a recording played back (``replay=``), which holds no frame of its own."""
    from acquisition.urls import SimURL, UsbSimURL, parse_device_url

    parsed = parse_device_url(url)
    if not isinstance(parsed, (SimURL, UsbSimURL)) or parsed.options.get("replay"):
        return None
    return frame_geometry(FrameConfig.load(parsed.options.get("config")))


def check_device_points(url: str, points: Iterable[str]) -> None:
    """Raise :class:`analysis.geometry.GeometryError` naming the first of ``points`` that is not on the
    frame of the simulated device ``url`` and the frame's nodes (nothing to check for other devices)."""
    geometry = device_geometry(url)
    if geometry is not None:
        geometry.check_points(points)
