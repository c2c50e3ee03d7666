"""A frame with one amplitude-dependent rotational spring, simulated in the time domain.

The frame's linear FE model keeps the spring's small-amplitude stiffness ``k0`` (N m/rad: the
``[joints]`` or ``[supports]`` rotational stiffness about the configured axis, damage included). The
spring's true restoring moment ``M(theta)`` differs from ``k0 theta`` by the correction
``m(t) = M(theta) - k0 theta``, which acts on the frame as the generalised force ``-d m`` with ``d`` the
joint's relative-rotation vector (``+1`` on node a's rotation DOF, ``-1`` on node b's; a support has
only ``+1``). In modal coordinates (mass-normalised shapes, proportional damping) mode ``r`` obeys

    eta_r'' + 2 zeta_r w_r eta_r' + w_r^2 eta_r = phi_in,r F(t) - delta_r m(t),   delta_r = d^T phi_r

and the joint's rotation is ``theta = sum_r delta_r eta_r``. By superposition the response is the
linear frame's exact response to the hammer (:func:`simulator.response.simulate_segment`) plus the
response to ``-delta m``; only ``theta`` and ``m`` need stepping. On a grid ``h = 1 / (substeps fs)``
each mode's complex state is propagated exactly for an input linear between steps (the first-order
hold of :mod:`simulator.response`), so with ``theta_nl[k] = P[k] - d1 m[k-1] - d0 m[k]`` the step is
implicit in ``m[k]`` only: the scalar equation ``m = M(theta) - k0 theta`` is solved by a Newton step on the
law's tangent stiffness (exact for the piecewise-linear Iwan law unless a slider changes state within
the step). The joint's moment is then exact up to its first-order hold between steps (second order in ``h``).

Laws (``[nonlinear] law``):

* ``iwan``: micro-slip friction, a parallel bank of ``n`` Jenkins elements (spring ``k_i`` in series
  with a Coulomb slider of slip moment ``M_i``) beside a spring ``k_res`` that never slips:
  ``k_res = rho k0`` and ``k_i = (1 - rho) k0 / n``, the sliders' slip rotations spread evenly up to
  the rotation of full slip, together carrying ``slip_moment_nm`` in full slip. Below the first slip
  the joint is exactly linear; above, the secant stiffness falls and the energy lost per cycle
  (``sum M_i |slip_i|``) grows as the cube of the amplitude: frequencies fall and damping rises with
  the force, most in the modes whose shapes rotate the joint.
* ``cubic``: ``M = k0 theta + k3 theta^3`` (conservative; ``k3 > 0`` hardening).

:class:`NonlinearJointStand` is a :class:`simulator.stand.TestStand` whose strikes use this; the
factory :func:`make_stand` returns it when the configuration has an active ``[nonlinear]`` table (so
``sim://?config=FILE`` reaches it like any frame).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

import numpy as np

from .config import ConfigError, FrameConfig, NonlinearConfig
from .fem import FrameModel
from .response import foh_coefficients, simulate_segment
from .stand import StandError, StandEvent, TestStand

__all__ = ["JointLaw", "IwanJoint", "CubicJoint", "LinearJoint", "JointResult", "joint_law", "joint_dof_vector",
           "simulate_joint", "NonlinearJointStand", "JointModes", "make_stand"]

_BLOCK = 64


class JointLaw(Protocol):
    """A rotational spring law: the moment M (N m) at rotation theta (rad), with internal state."""

    k0: float

    def reset(self) -> None: ...

    def trial(self, theta: float) -> tuple[float, float]:
        """(M, dM/dtheta) at ``theta`` from the committed state, without changing it."""
        ...

    def commit(self, theta: float) -> bool:
        """Accept ``theta`` as the new state; True when the internal state changed (a slip)."""
        ...

    def potential(self, theta: float) -> float:
        """Energy (J) stored in the spring at ``theta`` (committed state)."""
        ...

    @property
    def dissipated_j(self) -> float: ...


class IwanJoint:
    """Parallel Iwan bank (module docstring): ``k0`` N m/rad small-amplitude stiffness,
    ``slip_moment_nm`` N m carried by the sliders in full slip, ``residual_fraction`` of ``k0`` never
    slips, ``n`` sliders. The state is each element's moment ``e_i`` (|e_i| <= M_i) at the rotation
    ``theta_ref`` of the last commit."""

    def __init__(self, k0: float, slip_moment_nm: float, residual_fraction: float, n: int) -> None:
        if not (k0 > 0 and slip_moment_nm > 0 and 0 <= residual_fraction < 1 and n >= 1):
            raise ValueError("IwanJoint needs k0 > 0, slip_moment_nm > 0, 0 <= residual_fraction < 1, n >= 1")
        self.k0 = float(k0)
        self.k_res = residual_fraction * self.k0
        self.k_i = (1.0 - residual_fraction) * self.k0 / n
        theta_full = 2.0 * slip_moment_nm / ((1.0 - residual_fraction) * self.k0)
        self.slip_rotation = theta_full * (np.arange(n) + 0.5) / n  # rad, at which each slider starts to slip
        self.m_i = self.k_i * self.slip_rotation                   # N m, each slider's slip moment
        self._neg = -self.m_i
        self.reset()

    @property
    def first_slip_rad(self) -> float:
        """Rotation (rad) below which the joint is exactly linear."""
        return float(self.slip_rotation[0])

    def reset(self) -> None:
        self.e = np.zeros(self.m_i.size)
        self.theta_ref = 0.0
        self._dissipated = 0.0

    def trial(self, theta: float) -> tuple[float, float]:
        raw = self.e + self.k_i * (theta - self.theta_ref)
        e = np.minimum(np.maximum(raw, self._neg), self.m_i)
        n_stuck = int(np.count_nonzero(raw == e))
        return self.k_res * theta + float(e.sum()), self.k_res + self.k_i * n_stuck

    def commit(self, theta: float) -> bool:
        raw = self.e + self.k_i * (theta - self.theta_ref)
        e = np.minimum(np.maximum(raw, self._neg), self.m_i)
        self.theta_ref = float(theta)
        slipped = bool(np.any(raw != e))
        if slipped:
            self._dissipated += float(np.dot(self.m_i, np.abs(raw - e))) / self.k_i
        self.e = e
        return slipped

    def moment(self) -> float:
        """The committed moment (N m)."""
        return self.k_res * self.theta_ref + float(self.e.sum())

    def stuck_interval(self) -> tuple[float, float, float]:
        """(lo, hi, m): no slider moves while lo <= theta <= hi (rad), and the correction moment
        ``M - k0 theta`` is then the constant m (N m)."""
        lo = self.theta_ref + float(np.max(self._neg - self.e)) / self.k_i
        hi = self.theta_ref + float(np.min(self.m_i - self.e)) / self.k_i
        return lo, hi, float(self.e.sum()) - self.m_i.size * self.k_i * self.theta_ref

    def potential(self, theta: float) -> float:
        e = self.e + self.k_i * (theta - self.theta_ref)
        return 0.5 * self.k_res * theta ** 2 + float(np.dot(e, e)) / (2.0 * self.k_i)

    @property
    def dissipated_j(self) -> float:
        return self._dissipated


class CubicJoint:
    """``M = k0 theta + k3 theta^3`` (N m; k3 in N m/rad^3)."""

    def __init__(self, k0: float, k3: float) -> None:
        self.k0, self.k3 = float(k0), float(k3)

    def reset(self) -> None:
        pass

    def trial(self, theta: float) -> tuple[float, float]:
        return self.k0 * theta + self.k3 * theta ** 3, self.k0 + 3.0 * self.k3 * theta ** 2

    def commit(self, theta: float) -> bool:
        return False

    def potential(self, theta: float) -> float:
        return 0.5 * self.k0 * theta ** 2 + 0.25 * self.k3 * theta ** 4

    @property
    def dissipated_j(self) -> float:
        return 0.0


class LinearJoint:
    """A linear spring ``M = k theta`` whose stiffness differs from the model's ``k0``: the frame then
    behaves as the linear frame with that joint stiffness (the integrator's exact reference)."""

    def __init__(self, k0: float, k: float) -> None:
        self.k0, self.k = float(k0), float(k)

    def reset(self) -> None:
        pass

    def trial(self, theta: float) -> tuple[float, float]:
        return self.k * theta, self.k

    def commit(self, theta: float) -> bool:
        return False

    def potential(self, theta: float) -> float:
        return 0.5 * self.k * theta ** 2

    @property
    def dissipated_j(self) -> float:
        return 0.0


def _springs(cfg: FrameConfig) -> list[tuple[str, str, str | None, list[float]]]:
    """(kind, node a, node b or None, six stiffnesses as the FE model stamps them) of every joint and support."""
    out: list[tuple[str, str, str | None, list[float]]] = []
    for a in cfg.supports.nodes:
        f = cfg.damage.spring_factor("support", (a,))
        out.append(("support", str(a), None, [k * f for k in cfg.nonlinear.spring_stiffness((a,), cfg.supports.stiffness)]))
    for a, b in cfg.joints.pairs:
        f = cfg.damage.spring_factor("joint", (a, b))
        out.append(("joint", str(a), str(b), [k * f for k in cfg.nonlinear.spring_stiffness((a, b), cfg.joints.stiffness)]))
    return out


def _joint_places(cfg: FrameConfig) -> tuple[str, str | None, float]:
    """(node a, node b or None for a support, linear rotational stiffness k0 N m/rad) of the nonlinear spring."""
    nl = cfg.nonlinear
    for kind, a, b, k6 in _springs(cfg):
        if nl.joint in (a, b) and (kind == "joint" or b is None):
            return a, b, k6[3 + nl.axis_index]
    raise ConfigError(f"nonlinear.joint {nl.joint!r} is neither a joint nor a support node")


def joint_law(cfg: FrameConfig) -> JointLaw:
    """The law of the configuration's ``[nonlinear]`` spring (its ``k0`` from the linear model)."""
    nl: NonlinearConfig = cfg.nonlinear
    _, _, k0 = _joint_places(cfg)
    if not k0 > 0:
        raise ConfigError(f"nonlinear.joint {nl.joint!r} has no rotational stiffness about {nl.axis}; "
                          "a nonlinear law needs a spring there")
    if nl.law == "iwan":
        return IwanJoint(k0, nl.slip_moment_nm, nl.residual_stiffness_fraction, nl.n_sliders)
    if nl.law == "cubic":
        return CubicJoint(k0, nl.cubic_nm_per_rad3)
    raise ConfigError(f"nonlinear.law = {nl.law!r} has no time-domain law; use 'iwan' or 'cubic'")


def joint_dof_vector(model: FrameModel, cfg: FrameConfig) -> np.ndarray:
    """d (n_dof,): the joint's relative rotation is ``d^T u`` (rad)."""
    a, b, _ = _joint_places(cfg)
    ax = 3 + cfg.nonlinear.axis_index
    d = np.zeros(model.n_dof)
    d[6 * model.node(a) + ax] = 1.0
    if b is not None:
        d[6 * model.node(b) + ax] = -1.0
    return d


@dataclass(frozen=True)
class JointResult:
    """One nonlinear simulation: ``theta`` (n_steps,) rad and ``moment`` (n_steps,) N m correction
    ``M - k0 theta`` on the integrator grid (``substeps`` per output sample, index 0 = output sample 0),
    ``accel`` (n_out, n) m/s^2 at the outputs, ``dissipated_j`` J lost in the joint."""

    theta: np.ndarray
    moment: np.ndarray
    accel: np.ndarray
    dissipated_j: float
    substeps: int


def _upsample_foh(seg: np.ndarray, p: int) -> np.ndarray:
    """The segment on a grid ``p`` times finer, linear between its samples (its first-order hold)."""
    if p == 1:
        return np.asarray(seg, float)
    x = np.arange(seg.size)
    return np.interp(np.arange((seg.size - 1) * p + 1) / p, x, seg)


def simulate_joint(
    law: JointLaw, poles: np.ndarray, delta: np.ndarray, phi_out: np.ndarray, phi_in: np.ndarray,
    seg: np.ndarray, seg_start: int, q: int, fs_hz: float, n_samples: int, substeps: int = 4,
    quantity: str = "acceleration",
) -> JointResult:
    """The frame's response with the joint law (module docstring).

    poles (n_modes,) rad/s; delta (n_modes,) the joint's relative rotation per unit modal coordinate;
    phi_out (n_out, n_modes), phi_in (n_modes,) mass-normalised shapes at the outputs and the input;
    seg: force (N) on the grid ``q fs_hz`` from fine index ``seg_start`` (as
    :func:`simulator.response.simulate_segment`); the record has ``n_samples`` samples at ``fs_hz``.
    ``quantity`` of ``accel``: "displacement", "velocity" or "acceleration". The law's state is reset
    first. Inputs are not modified.
    """
    p = int(substeps)
    lam = np.asarray(poles, complex)
    dl = np.asarray(delta, float)
    n_fine = n_samples * p
    # the linear frame's rotation of the joint, on the integrator grid
    seg_p = _upsample_foh(np.asarray(seg, float), p)
    theta_lin = simulate_segment(seg_p, seg_start * p, q, p * fs_hz, n_fine, lam, dl[None, :], phi_in,
                                 "displacement")[0]
    b0, b1, E = foh_coefficients(lam, p * fs_hz)
    A = 1.0 / (2j * lam.imag)
    c = A * dl                         # theta_nl = 2 Re(c . z)
    cE = c * E
    w0, w1 = -dl * b0, -dl * b1        # z[k] = E z[k-1] + w0 m[k] + w1 m[k-1]
    d0 = float(2.0 * np.real(np.sum(c * w0))) * -1.0
    d1 = float(2.0 * np.real(np.sum(c * w1))) * -1.0
    law.reset()
    k0 = law.k0
    theta = theta_lin.copy()
    moment = np.zeros(n_fine)
    nz = np.flatnonzero(theta_lin)
    i0 = int(nz[0]) if nz.size else n_fine
    z = np.zeros(lam.size, complex)
    m_prev = 0.0
    stuck_interval = getattr(law, "stuck_interval", None)
    # While no slider of the bank moves the joint is linear with a constant moment: whole blocks are then
    # advanced in closed form, z[k-1+j] = E^j z[k-1] + m (w0 + w1)(E^j - 1)/(E - 1), and checked.
    B = _BLOCK
    PB = E[:, None] ** np.arange(1, B + 1)[None, :]
    cPB = c[:, None] * PB
    wsum = (w0 + w1) / (E - 1.0)
    gB = 2.0 * np.real((c * wsum) @ (PB - 1.0))
    stuck = stuck_interval is not None
    k = i0
    while k < n_fine:
        if stuck and stuck_interval is not None:
            lo, hi, mc = stuck_interval()
            nb = min(B, n_fine - k)
            th_b = theta_lin[k:k + nb] + 2.0 * np.real(z @ cPB[:, :nb]) + mc * gB[:nb]
            ok = (th_b >= lo) & (th_b <= hi)
            j = nb if bool(ok.all()) else int(np.argmin(ok))
            if j > 0:
                theta[k:k + j] = th_b[:j]
                moment[k:k + j] = mc
                Ej = PB[:, j - 1]
                z = Ej * z + mc * wsum * (Ej - 1.0)
                m_prev = mc
                k += j
            stuck = j == nb
            continue
        base = theta_lin[k] + 2.0 * (cE @ z).real - d1 * m_prev
        # one Newton step on the law's tangent from m[k-1] (exact while no slider changes state between
        # the two rotations; d0 is of the order of h^2 / modal mass, so the step is small)
        th = base - d0 * m_prev
        M, kt = law.trial(th)
        m = m_prev - (m_prev - (M - k0 * th)) / (1.0 + d0 * (kt - k0))
        th = base - d0 * m
        stuck = not law.commit(th) and stuck_interval is not None
        theta[k] = th
        moment[k] = m
        z = E * z + (w0 * m + w1 * m_prev)
        m_prev = m
        k += 1
    lin = simulate_segment(np.asarray(seg, float), seg_start, q, fs_hz, n_samples, lam, phi_out, phi_in, quantity)
    nl = simulate_segment(moment[i0:], i0, p, fs_hz, n_samples, lam, phi_out, -dl, quantity) if i0 < n_fine else 0.0
    return JointResult(theta=theta, moment=moment, accel=lin + nl, dissipated_j=law.dissipated_j, substeps=p)


class NonlinearJointStand(TestStand):
    """The test stand whose frame has the ``[nonlinear]`` spring of its configuration: every strike is
    simulated in the time domain (:func:`simulate_joint`). ``analytic_frf`` and ``model`` are the linear
    frame at vanishing amplitude. Each strike's ``info`` adds ``joint_peak_rotation_rad`` and
    ``joint_dissipated_j``."""

    __test__ = False

    def __init__(self, config: FrameConfig | str | Path | None = None, seed: int = 0) -> None:
        super().__init__(config, seed)
        if not self.config.nonlinear.active:
            raise StandError("NonlinearJointStand needs a [nonlinear] table with law 'iwan' or 'cubic'")
        self.law = joint_law(self.config)
        self._last: JointResult | None = None

    def _frame_response(self, model: FrameModel, outputs: Sequence[str], in_point: str, seg: np.ndarray,
                        seg_start: int, q: int, fs_hz: float, n_samples: int) -> np.ndarray:
        modes = model.modes()
        flex = modes.freq_hz > 0
        phi_out = model.shape_at(list(outputs), modes)[:, flex]
        phi_in = model.shape_at([in_point], modes)[0, flex]
        delta = joint_dof_vector(model, self.config) @ modes.shapes[:, flex]
        res = simulate_joint(self.law, modes.poles[flex], delta, phi_out, phi_in, seg, seg_start, q, fs_hz,
                             n_samples, self.config.nonlinear.substeps(fs_hz))
        self._last = res
        return res.accel

    def strike(self, *args: Any, **kwargs: Any) -> StandEvent:
        self._last = None
        ev = super().strike(*args, **kwargs)
        if self._last is not None:
            ev.info["joint_peak_rotation_rad"] = float(np.max(np.abs(self._last.theta)))
            ev.info["joint_dissipated_j"] = self._last.dissipated_j
        return ev


class JointModes:
    """The frame's rotational springs as candidates of :mod:`analysis.diagnosis.joint_nonlinearity` (its
    protocol ``JointSimulation``): for every joint and support and each rotation axis with a spring, the
    share of each mode's strain energy in it. ``sensor_points``: accelerometer places (their masses load
    the frame when the configuration's ``[sensors] mass_loading`` is on)."""

    def __init__(self, config: FrameConfig | str | Path | None = None, sensor_points: Sequence[str] = ()) -> None:
        self.config = config if isinstance(config, FrameConfig) else FrameConfig.load(config)
        s = self.config.sensors
        masses = ({f"{p.split(':')[0]}:{p.split(':')[1]}": s.accelerometer.mass_kg for p in sensor_points}
                  if s.mass_loading else {})
        self.model = FrameModel.from_config(self.config, masses)

    def joint_candidates(self) -> tuple[np.ndarray, list]:
        from analysis.diagnosis.joint_nonlinearity import JointCandidate

        ms = self.model.modes()
        flex = ms.freq_hz > 0
        shapes, w2 = ms.shapes[:, flex], ms.omega[flex] ** 2
        out = []
        for kind, a, b, k6 in _springs(self.config):
            for i, axis in enumerate(("rx", "ry", "rz")):
                k = float(k6[3 + i])
                if not k > 0:
                    continue
                d = np.zeros(self.model.n_dof)
                d[6 * self.model.node(a) + 3 + i] = 1.0
                if b is not None:
                    d[6 * self.model.node(b) + 3 + i] = -1.0
                nodes = (a,) if b is None else (a, b)
                out.append(JointCandidate(name=f"{kind} {'-'.join(nodes)} {axis}", kind=kind, nodes=nodes, axis=axis,
                                          stiffness_nm_per_rad=k, shares=k * (d @ shapes) ** 2 / w2))
        return ms.freq_hz[flex], out


def make_stand(config: FrameConfig | str | Path | None = None, seed: int = 0) -> TestStand:
    """The stand of a configuration: :class:`NonlinearJointStand` when its ``[nonlinear]`` law is
    active, else the linear :class:`simulator.stand.TestStand`."""
    cfg = config if isinstance(config, FrameConfig) else FrameConfig.load(config)
    return NonlinearJointStand(cfg, seed) if cfg.nonlinear.active else TestStand(cfg, seed)
