"""impactlab.analysis: FRF estimation, initial poles, nonlinear LSFD fitting, stabilization, diagnosis.

The package is pure numerics over plain containers (:class:`analysis.frf.FRFSet`,
:class:`analysis.modal.ModalModel`); nothing here touches an instrument.
"""
