"""The window options of the capture, station, replay and import commands as settings: the texts
``--force-window 10ms,2ms`` and ``--exp-window 1%`` (or ``0.3s``) and their defaults."""
from __future__ import annotations

from analysis.spectra import WindowSettings, parse_duration

from .errors import UsageError

__all__ = ["parse_windows", "DEFAULT_FORCE_WINDOW", "DEFAULT_EXP_WINDOW"]

DEFAULT_FORCE_WINDOW = "20ms,5ms"
#: the responses (and force) decay to 5 % at the block end: the default 1.28 s record is shorter than
#: the slowest modes' ringing (the frame's 12.9 Hz mode keeps 40 % at the end), whose peaks would
#: leak; the window's decay is recorded with the FRFs and removed by the fit
DEFAULT_EXP_WINDOW = "5%"


def parse_windows(force: str | None, exp: str | None, fs_hz: float | None,
                  base: WindowSettings | None = None) -> WindowSettings:
    """Window settings from the ``--force-window`` and ``--exp-window`` texts (None: keep ``base``)."""
    b = base or WindowSettings()
    fw, ft = b.force_width_s, b.force_taper_s
    tau, end_fraction = b.exp_window_tau_s, b.exp_window_end_fraction
    try:
        if force is not None:
            t = force.strip().lower()
            if t in ("none", "off", ""):
                fw, ft = None, 0.0
            else:
                parts = [x for x in t.split(",")]
                if len(parts) > 2:
                    raise UsageError(f"--force-window {force!r}: give WIDTH or WIDTH,TAPER (e.g. 10ms,2ms)")
                fw = parse_duration(parts[0], fs_hz)
                ft = parse_duration(parts[1], fs_hz) if len(parts) == 2 else 0.0
                if fw <= 0:
                    raise UsageError(f"--force-window {force!r}: the width must be positive")
        if exp is not None:
            t = exp.strip().lower()
            if t in ("none", "off", ""):
                tau, end_fraction = None, None
            elif t.endswith("%"):
                end_fraction = float(t[:-1]) / 100.0
                tau = None
                if not 0 < end_fraction < 1:
                    raise UsageError(f"--exp-window {exp!r}: the end value must lie between 0 and 100 %")
            else:
                tau = parse_duration(t[4:] if t.startswith("tau=") else t, fs_hz)
                end_fraction = None
                if tau <= 0:
                    raise UsageError(f"--exp-window {exp!r}: tau must be positive")
        return WindowSettings(fw, ft, tau, end_fraction, b.exp_on_force)
    except UsageError:
        raise
    except ValueError as exc:
        raise UsageError(f"bad window option: {exc}") from None
