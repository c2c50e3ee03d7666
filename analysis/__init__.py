"""impactlab.analysis: FRF containers, the recording format, FRF estimation, initial poles, the
nonlinear LSFD fitter, stabilization, diagnosis and the test report.

The bottom layer: pure numerics and file formats over plain containers (:class:`FRFSet`,
:class:`ModalModel`); nothing here touches an instrument or the simulator. The common names are
exported here (``from analysis import FRFSet, fit_auto``); each lives in a small module of its own.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from ._lazy import lazy_exports

#: public name -> the module that defines it (imported on first use)
_EXPORTS = {
    "FRFSet": ".frf",
    "QUANTITIES": ".frf",
    "convert_quantity": ".frf",
    "ModalModel": ".modal",
    "synthesize": ".modal",
    "cmif": ".mif",
    "mif": ".mif",
    "fit_lsfd": ".lsfd",
    "LSFDResult": ".lsfd",
    "fit_auto": ".pipeline",
    "default_band": ".pipeline",
    "stabilization": ".stabilization",
    "StabilizationResult": ".stabilization",
    "lscf_poles": ".lscf",
    "lsce_poles": ".lsce",
    "WindowSettings": ".spectra",
    "Hit": ".hit",
    "Recording": ".recording",
    "RecordingWriter": ".recording_writer",
    "load_input": ".inputs",
    "read_uff58": ".uff",
    "write_uff58": ".uff",
    "read_uff55": ".uff",
    "write_uff55": ".uff",
    "Geometry": ".geometry",
    "ImpactlabError": ".errors",
    "RecordingError": ".errors",
    "UsageError": ".errors",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

if TYPE_CHECKING:  # for type checkers and IDEs; at run time the names load lazily
    from .errors import ImpactlabError, RecordingError, UsageError  # noqa: F401
    from .frf import QUANTITIES, FRFSet, convert_quantity  # noqa: F401
    from .geometry import Geometry  # noqa: F401
    from .hit import Hit  # noqa: F401
    from .inputs import load_input  # noqa: F401
    from .lsce import lsce_poles  # noqa: F401
    from .lscf import lscf_poles  # noqa: F401
    from .lsfd import LSFDResult, fit_lsfd  # noqa: F401
    from .mif import cmif, mif  # noqa: F401
    from .modal import ModalModel, synthesize  # noqa: F401
    from .pipeline import default_band, fit_auto  # noqa: F401
    from .recording import Recording  # noqa: F401
    from .recording_writer import RecordingWriter  # noqa: F401
    from .spectra import WindowSettings  # noqa: F401
    from .stabilization import StabilizationResult, stabilization  # noqa: F401
    from .uff import read_uff55, read_uff58, write_uff55, write_uff58  # noqa: F401
