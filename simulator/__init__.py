"""impactlab.simulator: a simulated steel frame (FE model, hammer, accelerometers) and a simulated
SigLab-like analyser that answers the driver's protocol (the ``sim://`` and ``usbsim://`` doors).
"""
from __future__ import annotations

from typing import TYPE_CHECKING

from analysis._lazy import lazy_exports

#: public name -> the module that defines it (imported on first use)
_EXPORTS = {
    "FrameConfig": ".config",
    "TestStand": ".stand",
    "create_analyser": ".analyser",
    "Firmware": ".firmware",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)

if TYPE_CHECKING:  # for type checkers and IDEs; at run time the names load lazily
    from .analyser import create_analyser  # noqa: F401
    from .config import FrameConfig  # noqa: F401
    from .firmware import Firmware  # noqa: F401
    from .stand import TestStand  # noqa: F401
