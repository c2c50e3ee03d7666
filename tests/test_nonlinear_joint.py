"""The frame with a nonlinear joint (simulator.nonlinear_joint): the integrator against exact linear
solutions and energy balance, the Iwan law's physics, the configuration and the sim:// stand."""
from __future__ import annotations

import numpy as np
import pytest

from simulator.config import ConfigError, FrameConfig
from simulator.nonlinear_joint import (
    CubicJoint,
    IwanJoint,
    LinearJoint,
    NonlinearJointStand,
    joint_dof_vector,
    joint_law,
    make_stand,
    simulate_joint,
)
from simulator.response import simulate_segment
from simulator.stand import TestStand

JOINT = {"law": "iwan", "joint": "right:10", "axis": "ry", "slip_moment_nm": 20.0, "stiffness_nm_per_rad": 2e4}


def _undamped(max_freq_hz: float = 400.0, law: str = "iwan") -> FrameConfig:
    return FrameConfig.from_dict({"nonlinear": {**JOINT, "law": law, "cubic_nm_per_rad3": 1e9},
                                  "damping": {"zeta": [0.0] * 6, "zeta_default": 0.0},
                                  "modes": {"max_freq_hz": max_freq_hz}, "sensors": {"mass_loading": False}})


def _modal(cfg: FrameConfig, outputs=("left:9:Y", "top:4:X"), inp="right:6:-X"):
    from simulator.fem import FrameModel

    model = FrameModel.from_config(cfg)
    ms = model.modes()
    delta = joint_dof_vector(model, cfg) @ ms.shapes
    return ms, delta, model.shape_at(list(outputs), ms), model.shape_at([inp], ms)[0]


def _pulse(fs: float, width_s: float, peak_n: float) -> np.ndarray:
    t = np.arange(int(round(width_s * fs)) + 1) / fs
    return peak_n * np.sin(np.pi * t / width_s)


def test_a_linear_law_matches_the_exact_modal_solution_of_the_changed_stiffness():
    cfg = _undamped()
    ms, delta, po, pi = _modal(cfg)
    fs, n = 2048.0, 2048
    seg = _pulse(16 * fs, 0.0012, 100.0)
    k0 = joint_law(cfg).k0
    k = 0.6 * k0
    res = simulate_joint(LinearJoint(k0, k), ms.poles, delta, po, pi, seg, 16 * 40, 16, fs, n, substeps=4)
    # exact: the modal stiffness diag(w^2) plus (k - k0) delta delta^T, diagonalised
    w2, V = np.linalg.eigh(np.diag(ms.omega ** 2) + (k - k0) * np.outer(delta, delta))
    ref = simulate_segment(seg, 16 * 40, 16, fs, n, 1j * np.sqrt(w2), po @ V, V.T @ pi, "acceleration")
    lin = simulate_segment(seg, 16 * 40, 16, fs, n, ms.poles, po, pi, "acceleration")
    err = np.max(np.abs(res.accel - ref)) / np.max(np.abs(ref))
    assert np.max(np.abs(lin - ref)) / np.max(np.abs(ref)) > 0.3  # the change matters
    assert err < 0.04  # a 40 % stiffness change over 1 s without damping (phase drift of the step)
    # second order in the step: halving it quarters the error
    res8 = simulate_joint(LinearJoint(k0, k), ms.poles, delta, po, pi, seg, 16 * 40, 16, fs, n, substeps=8)
    err8 = np.max(np.abs(res8.accel - ref)) / np.max(np.abs(ref))
    assert err8 < 0.3 * err


def test_vanishing_amplitude_gives_the_linear_frame():
    cfg = _undamped(law="cubic")
    ms, delta, po, pi = _modal(cfg)
    fs, n = 2048.0, 1024
    lin = simulate_segment(_pulse(16 * fs, 0.0012, 1.0), 16 * 20, 16, fs, n, ms.poles, po, pi, "acceleration")
    errs = []
    for peak in (1.0, 10.0):
        seg = _pulse(16 * fs, 0.0012, peak)
        res = simulate_joint(CubicJoint(joint_law(cfg).k0, 1e9), ms.poles, delta, po, pi, seg, 16 * 20, 16, fs, n)
        errs.append(np.max(np.abs(res.accel / peak - lin)) / np.max(np.abs(lin)))
    # the cubic term's effect falls as the amplitude squared
    assert errs[0] < 1e-3 and errs[1] / errs[0] == pytest.approx(100.0, rel=0.1)
    # the Iwan joint below its first slip is the linear frame exactly
    law = joint_law(_undamped())
    seg = _pulse(16 * fs, 0.0012, 0.05)
    res = simulate_joint(law, ms.poles, delta, po, pi, seg, 16 * 20, 16, fs, n)
    assert np.max(np.abs(res.theta)) < law.first_slip_rad  # type: ignore[attr-defined]
    np.testing.assert_allclose(res.accel / 0.05, lin, rtol=0, atol=1e-12 * np.max(np.abs(lin)))


def test_energy_balance_with_friction():
    cfg = _undamped(max_freq_hz=300.0)
    ms, delta, po, pi = _modal(cfg)
    fs, n = 20480.0, 4096
    seg = _pulse(fs, 0.004, 400.0)
    law = joint_law(cfg)
    eye = np.eye(ms.poles.size)
    disp = simulate_joint(law, ms.poles, delta, eye, pi, seg, 10, 1, fs, n, 1, "displacement")
    vel = simulate_joint(law, ms.poles, delta, eye, pi, seg, 10, 1, fs, n, 1, "velocity")
    # modal coordinates are phi_in,r y_r for unit participation rows: the identity outputs give eta_r directly
    eta, deta = disp.accel[:, -1], vel.accel[:, -1]
    e_modal = 0.5 * np.sum(deta ** 2 + ms.omega ** 2 * eta ** 2)
    th = disp.theta[-1]
    e_joint = law.potential(th) - 0.5 * law.k0 * th ** 2
    f = np.zeros(n)
    f[10:10 + seg.size] = seg
    v_in = pi @ vel.accel
    w_in = float(np.sum(0.5 * (f[1:] * v_in[1:] + f[:-1] * v_in[:-1])) / fs)
    assert disp.dissipated_j > 0.02 * w_in  # friction matters here
    assert e_modal + e_joint + disp.dissipated_j == pytest.approx(w_in, rel=2e-3)


def test_iwan_law_softens_and_dissipates_more_with_amplitude():
    law = IwanJoint(1e4, 10.0, 0.3, 24)
    secant, loss = [], []
    for amp in (2e-4, 6e-4, 1.2e-3):
        law.reset()
        for th in amp * np.sin(np.linspace(0, 4 * np.pi, 801)):
            law.trial(th)
            law.commit(th)
        d0 = law.dissipated_j
        for th in amp * np.sin(np.linspace(0, 2 * np.pi, 401)):
            law.commit(th)
        loss.append((law.dissipated_j - d0) / (0.5 * law.k0 * amp ** 2))
        law.commit(amp)
        secant.append(law.trial(amp)[0] / amp)
    assert secant[0] > secant[1] > secant[2] > 0.3e4
    assert 0 < loss[0] < loss[1] < loss[2]
    # uniform micro-slip: the loss per cycle grows as the amplitude cubed
    assert loss[1] / loss[0] == pytest.approx(3.0, rel=0.15)


def test_nonlinear_config_is_validated_with_clear_messages():
    with pytest.raises(ConfigError, match="nonlinear.joint .* neither a node"):
        FrameConfig.from_dict({"nonlinear": {**JOINT, "joint": "top:3"}})
    with pytest.raises(ConfigError, match="nonlinear.law"):
        FrameConfig.from_dict({"nonlinear": {**JOINT, "law": "hysteresis"}})
    with pytest.raises(ConfigError, match="slip_moment_nm"):
        FrameConfig.from_dict({"nonlinear": {**JOINT, "slip_moment_nm": 0.0}})
    with pytest.raises(ConfigError, match="nonlinear.axis"):
        FrameConfig.from_dict({"nonlinear": {**JOINT, "axis": "y"}})
    cfg = FrameConfig.from_dict({"nonlinear": JOINT})
    assert joint_law(cfg).k0 == 2e4
    assert isinstance(make_stand(cfg), NonlinearJointStand)
    assert type(make_stand(None)) is TestStand


def test_hits_of_different_force_soften_the_modes_that_rotate_the_joint(tmp_path):
    cfg_path = tmp_path / "joint.toml"
    cfg_path.write_text('[nonlinear]\nlaw = "iwan"\njoint = "right:10"\naxis = "ry"\nslip_moment_nm = 20.0\n'
                        'stiffness_nm_per_rad = 2e4\n')
    from simulator.analyser import _build_stand

    st = _build_stand({"config": str(cfg_path), "seed": 3})
    assert isinstance(st, NonlinearJointStand)
    lin = TestStand(st.config, seed=3)
    out = []
    for s in (st, lin):
        s.next_strike(amplitude_scale=4.0, double_hit=False, neighbour=False)
        out.append(s.strike(2048.0, 4096, 128, noise=False))
    assert out[0].info["joint_dissipated_j"] > 0
    d = np.max(np.abs(out[0].response[1:] - out[1].response[1:])) / np.max(np.abs(out[1].response[1:]))
    assert 1e-3 < d < 0.5
