"""The simulated frame: FE sanity against analytic beam results, default modes, config, modes CLI."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg

from analysis.modal import synthesize
from simulator.config import ConfigError, FrameConfig, SectionConfig
from simulator.fem import (
    FrameModel,
    ModelError,
    assemble_beam,
    beam_mass_local,
    beam_stiffness_local,
    section_properties,
)

ROOT = Path(__file__).resolve().parents[1]
PAPER_POINTS = ["left:9:Y", "top:4:X", "right:4:-Z", "right:6:-X"]
E, NU, RHO = 2.1e11, 0.3, 7850.0
G = E / (2 * (1 + NU))


@pytest.fixture(scope="module")
def cfg() -> FrameConfig:
    return FrameConfig.load()


@pytest.fixture(scope="module")
def model(cfg) -> FrameModel:
    return FrameModel.from_config(cfg)


# ----------------------------------------------------------------------------- element level
def _rect(b: float, h: float) -> SectionConfig:
    return SectionConfig("rect", b, h, 0.0, 0.0, 0.0, 0.0, 0.0)


def _cantilever_freqs(direction: np.ndarray, n_el: int, roll_deg: float, L: float = 1.0) -> np.ndarray:
    sp = section_properties(_rect(0.04, 0.01))
    coords = np.outer(np.linspace(0, L, n_el + 1), direction / np.linalg.norm(direction))
    K, M = assemble_beam(coords, E, G, RHO, sp, roll_deg)
    free = np.arange(6, K.shape[0])  # clamp node 0 (all six DOFs)
    w2 = scipy.linalg.eigh(K[np.ix_(free, free)], M[np.ix_(free, free)], eigvals_only=True)
    return np.sqrt(w2) / (2 * np.pi)


def _analytic_cantilever(L: float = 1.0) -> np.ndarray:
    """Euler-Bernoulli cantilever bending (both planes), axial and torsion frequencies (Hz), sorted."""
    sp = section_properties(_rect(0.04, 0.01))
    # roots of cos(bL) cosh(bL) = -1; beyond the fourth, (2n - 1) pi / 2 to double precision
    beta_L = np.r_[1.8751040687, 4.6940911330, 7.8547574382, 10.9955407349, (2 * np.arange(5, 9) - 1) * np.pi / 2]
    f = []
    for inertia in (sp.Iy, sp.Iz):
        f += list(beta_L ** 2 / (2 * np.pi) * np.sqrt(E * inertia / (RHO * sp.A * L ** 4)))
    k = 2 * np.arange(1, 3) - 1
    f += list(k / (4 * L) * np.sqrt(E / RHO))                      # axial
    f += list(k / (4 * L) * np.sqrt(G * sp.J / (RHO * sp.Ip)))     # torsion (St-Venant, polar inertia)
    return np.sort(np.array(f))


@pytest.mark.parametrize("direction,roll", [((0, 0, 1), 0.0), ((1, 0, 0), 30.0), ((1, 2, 3), 17.0)])
def test_cantilever_matches_euler_bernoulli(direction, roll):
    # any orientation and section roll: same spectrum (tests the rotation matrices too)
    fa = _analytic_cantilever()
    fa = fa[fa < 1200]  # bending in both planes, torsion, axial: 13 modes up to 1.2 kHz
    f = _cantilever_freqs(np.array(direction, float), 40, roll)[: fa.size]
    np.testing.assert_allclose(f, fa, rtol=5e-3)
    # the first bending modes converge much tighter than 0.5 %
    np.testing.assert_allclose(f[:2], fa[:2], rtol=1e-5)


def test_cantilever_converges_with_elements():
    fa = _analytic_cantilever()[3]
    errs = [abs(_cantilever_freqs(np.array([0.0, 0, 1]), n, 0.0)[3] / fa - 1) for n in (2, 4, 8)]
    assert errs[0] > errs[1] > errs[2]
    assert errs[2] < 5e-3


def test_element_matrices_symmetric_and_rigid_body_free():
    sp = section_properties(_rect(0.05, 0.02))
    k = beam_stiffness_local(E, G, sp, 0.3)
    m = beam_mass_local(RHO, sp, 0.3)
    np.testing.assert_allclose(k, k.T, atol=0)
    np.testing.assert_allclose(m, m.T, atol=0)
    assert np.all(np.linalg.eigvalsh(m) > 0)
    w = np.linalg.eigvalsh(k)
    assert np.sum(np.abs(w) < 1e-6 * w.max()) == 6  # 6 rigid-body modes of a free element
    # mass of a translation = rho A L
    r = np.zeros(12)
    r[[1, 7]] = 1.0
    assert r @ m @ r == pytest.approx(RHO * sp.A * 0.3, rel=1e-13)


# ----------------------------------------------------------------------------- frame level
def test_total_mass_equals_physical_mass(cfg):
    phys = 0.0
    for comp in cfg.components.values():
        L = np.linalg.norm(np.subtract(comp.end_m, comp.start_m))
        phys += cfg.material.density_kg_m3 * section_properties(cfg.sections[comp.section]).A * L
    m = FrameModel.from_config(cfg)
    for axis in range(3):
        r = np.zeros(m.n_dof)
        r[axis::6] = 1.0
        assert r @ m.M @ r == pytest.approx(phys, rel=1e-12)
    loaded = FrameModel.from_config(cfg, {"left:9:Y": 0.5, "top:4": 0.25})
    assert loaded.total_mass() == pytest.approx(phys + 0.75, rel=1e-12)


def test_rigid_body_modes_without_supports(cfg):
    free = FrameModel.from_config(cfg, supports=False)
    w2, _ = free.eigen()
    scale = w2[6]
    assert scale > (2 * np.pi * 1.0) ** 2
    assert np.all(np.abs(w2[:6]) < 1e-6 * scale)
    # rigid motions: three translations and three rotations about the origin are in the null space of K
    xyz = free.node_coords
    for axis in range(3):
        t = np.zeros(free.n_dof)
        t[axis::6] = 1.0
        assert np.abs(free.K @ t).max() < 1e-6 * np.abs(free.K).max()
        rot = np.zeros(free.n_dof)
        e = np.eye(3)[axis]
        disp = np.cross(e, xyz)  # u = theta x r
        for d in range(3):
            rot[d::6] = disp[:, d]
        rot[3 + axis::6] = 1.0
        assert np.abs(free.K @ rot).max() < 1e-6 * np.abs(free.K).max()
    # with the supports back, no rigid-body mode
    assert FrameModel.from_config(cfg).eigen()[0][0] > (2 * np.pi * 1.0) ** 2


def test_default_frame_modes(model):
    f, zeta, phi = model.modes()
    band = (f >= 5) & (f <= 200)
    assert band.sum() >= 6
    assert abs(f[0] / 12.9 - 1) < 0.05
    assert np.all((zeta[band] >= 0.003) & (zeta[band] <= 0.015))
    # mass-normalised: phi^T M phi = I, phi^T K phi = diag(omega^2)
    np.testing.assert_allclose(phi.T @ model.M @ phi, np.eye(f.size), atol=1e-9)
    np.testing.assert_allclose(np.diag(phi.T @ model.K @ phi), (2 * np.pi * f) ** 2, rtol=1e-9)


def test_default_frame_near_paper_pattern(model):
    """The paper's frame has poles near 12.9, 34.9, 50.6, 81.5, 127.6, 158 Hz."""
    f = model.modes().freq_hz
    for target in (12.9, 34.9, 50.6, 81.5, 127.6, 158.0):
        assert np.min(np.abs(f / target - 1)) < 0.02, (target, f[:8])


def test_paper_points_exist_and_respond(model):
    for p in PAPER_POINTS:
        dof, sign = model.dof(p)
        assert 0 <= dof < model.n_dof and sign in (1, -1)
    S = np.abs(model.shape_at(PAPER_POINTS)[:, model.modes().freq_hz < 250])
    # the lateral points move in several of the modes below 250 Hz; right:4:-Z is the column's axial
    # direction (Z is vertical): it moves, but little
    assert np.all(np.sum(S[[0, 1, 3]] > 1e-2, axis=1) >= 3)
    assert S[2].max() > 1e-3
    with pytest.raises(ModelError, match="not on the frame"):
        model.dof("left:11:Y")
    with pytest.raises(ModelError, match="not on the frame"):
        model.dof("middle:1:X")


def test_sign_of_direction(model):
    np.testing.assert_allclose(model.shape_at(["right:4:-Z"]), -model.shape_at(["right:4:Z"]))


@pytest.mark.parametrize("quantity", ["receptance", "mobility", "accelerance"])
def test_modal_model_matches_analytic_frf(model, quantity):
    f = np.linspace(1, 300, 2000)
    mm = model.modal_model(PAPER_POINTS[:3], ["right:6:-X"], quantity)
    assert mm.quantity == quantity
    np.testing.assert_allclose(mm.freq_hz, model.modes().freq_hz, rtol=1e-12)
    H_pr = synthesize(mm, f).H
    H_an = model.analytic_frf(PAPER_POINTS[:3], ["right:6:-X"], f, quantity).H
    np.testing.assert_allclose(H_pr, H_an, rtol=1e-8, atol=1e-10 * np.abs(H_an).max())
    if quantity == "receptance":  # R_ijr = phi_i phi_j / (2 j w_d)
        S = model.shape_at(["left:9:Y", "right:6:-X"])
        wd = np.imag(model.modes().poles)
        np.testing.assert_allclose(mm.residues[0, 0], S[0] * S[1] / (2j * wd), rtol=1e-12)


def test_analytic_frf_forms_and_reciprocity(model):
    f = np.linspace(2, 250, 500)
    rec = model.analytic_frf(["left:9:Y"], ["right:6:-X"], f, "receptance")
    acc = model.analytic_frf(["left:9:Y"], ["right:6:-X"], f, "accelerance")
    np.testing.assert_allclose(acc.H, -(2 * np.pi * f) ** 2 * rec.H, rtol=1e-12)
    back = model.analytic_frf(["right:6:-X"], ["left:9:Y"], f, "accelerance")
    np.testing.assert_allclose(back.H, acc.H, rtol=1e-12)
    assert acc.unit == "(m/s^2)/N" and acc.outputs == ("left:9:Y",)


def test_added_mass_lowers_frequencies(cfg):
    f0 = FrameModel.from_config(cfg).modes().freq_hz[:6]
    f1 = FrameModel.from_config(cfg, {"top:4": 1.0}).modes().freq_hz[:6]
    assert np.all(f1 <= f0 + 1e-9) and np.any(f1 < f0 * 0.995)


def test_rayleigh_damping(cfg):
    c = cfg.with_overrides({"damping": {"model": "rayleigh", "rayleigh_alpha": 1.0, "rayleigh_beta": 2e-5}})
    f, zeta, _ = FrameModel.from_config(c).modes()
    w = 2 * np.pi * f
    np.testing.assert_allclose(zeta, 1.0 / (2 * w) + 2e-5 * w / 2, rtol=1e-12)


# ----------------------------------------------------------------------------- configuration
def test_config_merge_and_unknown_keys(tmp_path):
    p = tmp_path / "user.toml"
    p.write_text('[material]\ndensity_kg_m3 = 7800.0\n[hammer]\ntip = "hard"\n')
    c = FrameConfig.load(p)
    assert c.material.density_kg_m3 == 7800.0 and c.material.youngs_modulus_pa == 2.1e11
    assert c.hammer.width_s == c.hammer.tips["hard"]
    p.write_text("[material]\ndensity = 7800.0\n")
    with pytest.raises(ConfigError, match=r"unknown key 'material.density'.*density_kg_m3"):
        FrameConfig.load(p)
    p.write_text('[damping]\nmodel = "viscous"\n')
    with pytest.raises(ConfigError, match="modal.*rayleigh"):
        FrameConfig.load(p)
    p.write_text("[supports]\nnodes = ['left:99']\n")
    with pytest.raises(ConfigError, match="left:99"):
        FrameConfig.load(p)
    p.write_text("[material]\ndensity_kg_m3 = 'heavy'\n")
    with pytest.raises(ConfigError, match="density_kg_m3.*float"):
        FrameConfig.load(p)
    with pytest.raises(ConfigError, match="not found"):
        FrameConfig.load(tmp_path / "missing.toml")


def test_config_new_named_component(cfg):
    c = cfg.with_overrides({"components": {"brace": {"start_m": [0.0, 0.0, 0.3], "end_m": [0.0, 0.3, 0.3],
                                                     "n_elements": 3}}})
    m = FrameModel.from_config(c)
    assert ("brace", 3) in m.node_index
    assert m.n_dof == FrameModel.from_config(cfg).n_dof + 6 * 4


def test_config_is_not_modified_by_overrides(cfg):
    before = cfg.raw["damping"]["zeta"]
    cfg.with_overrides({"damping": {"zeta": [0.01]}})
    assert cfg.raw["damping"]["zeta"] == before


# ----------------------------------------------------------------------------- CLI
def test_modes_cli_json_schema():
    out = subprocess.run([sys.executable, "-m", "simulator", "modes", "--json"], cwd=ROOT,
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 0, out.stderr
    doc = json.loads(out.stdout)
    modes = doc["modes"]
    assert len(modes) >= 6
    for m in modes:
        assert set(m) == {"freq_hz", "damping", "shape"}
        assert isinstance(m["freq_hz"], float) and isinstance(m["damping"], float)
        assert set(m["shape"]) == set(PAPER_POINTS)
    f = [m["freq_hz"] for m in modes]
    assert f == sorted(f) and abs(f[0] / 12.9 - 1) < 0.05


def test_modes_cli_table_and_bad_config(tmp_path, capsys):
    from simulator.cli_modes import main

    assert main(["--max-freq", "100"]) == 0
    text = capsys.readouterr().out
    assert "f [Hz]" in text and "left:9:Y" in text
    bad = tmp_path / "bad.toml"
    bad.write_text("[frame]\nheight = 2\n")
    assert main(["--config", str(bad)]) == 2
    err = capsys.readouterr().err
    assert "unknown key 'frame'" in err and "Traceback" not in err
