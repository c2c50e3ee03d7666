"""Minimal reproductions of sdypy-EMA defects met during the validation (run with the peer's venv).

1. Pole bookkeeping: ``select_closest_poles`` reports ``nat_freq``/``nat_xi`` from column ``c`` of its
   stabilization matrix, which holds the poles of model ``all_poles[c + 1]`` (``_stabilization`` writes the
   poles of ``sr[n]`` to column ``n - 1``), but stores ``pole_ind = [c, k]``, so ``get_constants`` uses
   the nearest pole of the *previous* model order ``all_poles[c]``. The reported and the used poles differ;
   when the previous order lacks the mode, the used pole is another mode's, or unstable.
2. (observed on the F-16 data, not reduced to a synthetic case) with the default
   ``select_closest_poles(f_window=50)`` in a 2..15 Hz band every hint came back as 0 Hz and the
   LSFD used unstable poles; ``f_window`` scaled to the band avoids it (what :mod:`.peer` does).

:func:`reproduce` builds two exactly known modes (noise-free accelerance, 1 FRF) and returns the facts.
"""
from __future__ import annotations

import contextlib
import io
import warnings

import numpy as np

from analysis.modal import ModalModel, pole_from_fz, synthesize

F_TRUE = np.array([40.0, 95.0])
Z_TRUE = np.array([0.01, 0.02])


def _data(fmax: float = 200.0, df: float = 0.25):
    f = np.arange(0.0, fmax + df / 2, df)
    poles = pole_from_fz(F_TRUE, Z_TRUE)
    R = np.array([[[2000.0 - 500j, 1500.0 + 300j]]])
    H = synthesize(ModalModel(poles, R, quantity="accelerance", residual_form="none"), f).H[0, 0]
    return f, H


def reproduce() -> dict:
    """Run sdypy-EMA on two known modes; return the reported and the used poles and their model orders."""
    from sdypy import EMA

    f, H = _data()
    out = {}
    with contextlib.redirect_stderr(io.StringIO()), warnings.catch_warnings():
        warnings.simplefilter("ignore")
        m = EMA.Model(frf=H, freq=f, lower=10, upper=150, pol_order_high=12, frf_form="accelerance")
        m.get_poles("lscf", show_progress=False)
        m.select_closest_poles(list(F_TRUE))
        used = np.array([m.all_poles[a][b] for a, b in np.asarray(m.pole_ind)])
        out["reported_f"] = np.asarray(m.nat_freq, float)
        out["reported_zeta"] = np.asarray(m.nat_xi, float)
        out["used_f"] = np.abs(used) / (2 * np.pi)
        out["used_zeta"] = -used.real / np.abs(used)
        out["pole_ind"] = np.asarray(m.pole_ind)
        # which order do the reported values come from? find them in all_poles
        orders = []
        for fr in out["reported_f"]:
            hit = [k for k, p in enumerate(m.all_poles)
                   if np.any(np.isclose(np.abs(p) / (2 * np.pi), fr, rtol=1e-12, atol=0))]
            orders.append(hit[0] if hit else -1)
        out["reported_from_order_index"] = np.array(orders)
    return out


if __name__ == "__main__":
    for k, v in reproduce().items():
        print(f"{k}: {v}")
