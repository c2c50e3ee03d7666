"""Masses at the outputs added to a simulation given as FRFs, by structural modification of its receptances.

A simulation read from an FRF file is a fitted modal model plus the fixed part of the file's FRFs the model
does not hold (``meta["frf_correction"]``: the residual terms of the modes outside the band and what the
fit misses). Moving the fitted modes alone leaves that part where it was, while a mass at a point changes
the whole receptance matrix; the exact change (the Woodbury identity on the dynamic stiffness
``D' = D - w^2 P M P^T``, M the diagonal of the added masses at the loaded outputs S) is

    H'(w) = H + H[:, S] (I - w^2 M H[S, S])^-1 w^2 M H[S, :]        (receptance, m/N)

for any linear structure, damping and the modes outside the band included. It needs ``H[o, s]`` for every
output o and loaded s. The file gives every FRF to its references, and by reciprocity from them
(``H[o, d] = H[d, o]``): those entries are taken from the simulated FRFs as predicted (modal part and fixed
part). The others come from the modal model's mass-normalised shapes at the outputs
(``meta["output_shapes"]``, ``sum_r phi_or phi_sr / (2 j w_d,r) [1/(jw - lambda_r) - 1/(jw - conj lambda_r)]``)
plus an estimate of the modes outside the band, a quasi-static flexibility ``G`` from the model's upper
residual at the driving point's column ``u = UR[:, d]`` (m/N): ``G_os = u_o u_s / u_d`` off the diagonal
(one mode's tail through the driving point) and ``G_ss = max(u_s^2 / u_d, u_d)`` on it (the first is the
least a positive flexibility matrix allows, the second the driving point's own: the higher modes of a
structure spread their flexibility over its points). With the mass at the driving point the result is
exact on the file's FRFs.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..frf import FRFSet, convert_quantity
from ..modal import ModalModel, transfer
from .effect_types import driving_point

__all__ = ["FRF_MASSES_KEY", "uses_frf_masses", "frf_masses_kg", "FRFMassLoading", "add_frf_masses"]

#: ``ModalModel.meta`` key of the masses to add at the FRF level: a tuple of (mass kg, outputs mask) pairs
FRF_MASSES_KEY = "frf_masses"


def uses_frf_masses(model: ModalModel) -> bool:
    """True when a mass on ``model`` is added to its FRFs (:func:`add_frf_masses`): a simulation given as FRFs
    (``meta["frf_correction"]``), in receptance, with a driving point and a shape per mode at the outputs."""
    shapes = model.meta.get("output_shapes")
    return ("frf_correction" in model.meta and shapes is not None and model.quantity == "receptance"
            and np.shape(shapes) == (len(model.outputs), model.poles.size)
            and driving_point(model) is not None)


def _output_receptances(model: ModalModel, freq_hz: np.ndarray) -> np.ndarray:
    """Receptances between the outputs (n_out, n_out, n_freq, m/N) from the shapes, plus the estimated
    flexibility of the modes outside the band (module docstring)."""
    phi = np.asarray(model.meta["output_shapes"], float)
    lam = np.asarray(model.poles, complex)
    outs = list(model.outputs)
    between = ModalModel(poles=lam, residues=phi[:, None, :] * phi[None, :, :] / (2j * lam.imag), quantity="receptance",
                         residual_form="none", outputs=tuple(outs), references=tuple(outs))
    H = transfer(between, 2j * np.pi * np.asarray(freq_hz, float))
    dp = driving_point(model)
    if dp is not None and model.upper_residual is not None:
        d, j = dp
        u = np.real(np.asarray(model.upper_residual)[:, j])
        if u[d] > 0:
            G = np.outer(u, u) / u[d]
            G[np.diag_indices_from(G)] = np.maximum(u ** 2 / u[d], u[d])
            H = H + G[:, :, None]
    return H


def frf_masses_kg(model: ModalModel) -> np.ndarray:
    """The mass added at each output by ``model.meta[FRF_MASSES_KEY]`` (kg, shape (n_out,))."""
    m = np.zeros(len(model.outputs))
    for kg, mask in model.meta.get(FRF_MASSES_KEY) or ():
        m = m + float(kg) * np.asarray(mask, float)
    return m


class FRFMassLoading:
    """``frf`` (the prediction of ``model`` with its fixed part, any quantity, without the masses) ready to
    take masses at the outputs (module docstring): what does not depend on the masses (the receptances
    and those between the outputs) is computed once, :meth:`loaded` adds a given set of masses."""

    def __init__(self, model: ModalModel, frf: FRFSet) -> None:
        self.frf = frf
        f = np.asarray(frf.freq_hz, float)
        self.keep = f > 0
        self.fk = f[self.keep]
        self.H = convert_quantity(frf.H[..., self.keep], self.fk, frf.quantity, "receptance")   # (n_out, n_ref, n_f)
        self._model = model
        self._Hoo: np.ndarray | None = None

    def _between_outputs(self) -> np.ndarray:
        if self._Hoo is None:
            Hoo = _output_receptances(self._model, self.fk)
            outs = list(self._model.outputs)
            for j, r in enumerate(self._model.references):     # the file's FRFs where it has them (reciprocity)
                if r in outs:
                    Hoo[:, outs.index(r)] = self.H[:, j]
                    Hoo[outs.index(r), :] = self.H[:, j]
            self._Hoo = Hoo
        return self._Hoo

    def loaded(self, m: np.ndarray) -> FRFSet:
        """The FRFs with the mass ``m[o]`` (kg, >= 0) at each output ``o``."""
        if not (m > 0).any() or not self.keep.any():
            return self.frf
        return replace(self.frf, H=self.loaded_H(np.asarray(m, float)[None])[0])

    def loaded_H(self, ms: np.ndarray, block: int = 32) -> np.ndarray:
        """The FRFs' ``H`` (n_sets, n_out, n_ref, n_f, in the FRFs' quantity) with the masses ``ms[i, o]``
        (kg, >= 0) at the outputs, one set per row of ``ms``; rows loading the same outputs are solved
        together, ``block`` at a time."""
        frf, fk, H = self.frf, self.fk, self.H
        out = np.repeat(np.asarray(frf.H)[None], ms.shape[0], axis=0)
        if not self.keep.any():
            return out
        loaded = ms > 0
        patterns, which = np.unique(loaded, axis=0, return_inverse=True)
        for k, pattern in enumerate(patterns):
            S = np.flatnonzero(pattern)
            if S.size == 0:
                continue
            Hoo = self._between_outputs()
            rows = np.flatnonzero(np.ravel(which) == k)
            for b in range(0, rows.size, block):
                r = rows[b:b + block]
                w2m = (2 * np.pi * fk) ** 2 * ms[np.ix_(r, S)][:, :, None]                 # (n_r, n_S, n_f)
                A = np.eye(S.size)[None, :, :, None] - w2m[:, :, None, :] * Hoo[np.ix_(S, S)][None]   # I - w^2 M H_SS
                X = np.linalg.solve(A.transpose(0, 3, 1, 2),
                                    (w2m[:, :, None, :] * H[S][None]).transpose(0, 3, 1, 2))  # (n_r, n_f, n_S, n_ref)
                dH = np.einsum("osk,gksj->gojk", Hoo[:, S], X)
                sub = out[r]
                sub[..., self.keep] = convert_quantity(H[None] + dH, fk, "receptance", frf.quantity)
                out[r] = sub
        return out


def add_frf_masses(model: ModalModel, frf: FRFSet) -> FRFSet:
    """``frf`` (the prediction of ``model`` with its fixed part, any quantity) with the masses of
    ``model.meta[FRF_MASSES_KEY]`` added at the outputs (module docstring). Lines at 0 Hz are left as they
    are (a mass has no effect there)."""
    m = frf_masses_kg(model)
    if not (m > 0).any() or not (np.asarray(frf.freq_hz, float) > 0).any():
        return frf
    return FRFMassLoading(model, frf).loaded(m)
