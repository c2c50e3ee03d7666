"""The shared containers: point labels, FRFSet validation, eq. (11) synthesis."""
from __future__ import annotations

import numpy as np
import pytest

from analysis.frf import FRFSet, convert_quantity
from analysis.modal import ModalModel, damping_ratio, natural_freq_hz, pole_from_fz, synthesize
from analysis.points import PointLabelError, parse_point, point_from_uff, uff_direction, uff_node


def test_point_round_trip():
    for s in ["left:9:Y", "top:4:X", "right:4:-Z", "right:6:-X"]:
        p = parse_point(s)
        assert str(p) == s
        assert point_from_uff(uff_node(p), uff_direction(p)) == p
    assert parse_point("right:4:-Z").sign == -1 and parse_point("right:4:-Z").axis == 2


@pytest.mark.parametrize("bad", ["left9Y", "left:x:Y", "left:9:Q", ""])
def test_point_bad_label(bad):
    with pytest.raises(PointLabelError, match="component:node:direction|direction"):
        parse_point(bad)


def test_frfset_validates_shape():
    with pytest.raises(ValueError, match="lines"):
        FRFSet(np.arange(1, 5.0), np.zeros((1, 1, 3)))
    s = FRFSet(np.arange(1, 5.0), np.ones(4))
    assert s.H.shape == (1, 1, 4)
    with pytest.raises(ValueError):
        s.H[0, 0, 0] = 2  # read-only


def test_pole_helpers_and_synthesis_single_mode():
    lam = pole_from_fz(12.9, 0.01)
    assert natural_freq_hz(lam) == pytest.approx(12.9, rel=1e-14)
    assert damping_ratio(lam) == pytest.approx(0.01, rel=1e-12)
    # receptance of an SDOF m, c, k equals the pole-residue form with R = 1/(2 j m wd)
    m, wn, z = 2.0, 2 * np.pi * 12.9, 0.01
    wd = wn * np.sqrt(1 - z**2)
    model = ModalModel([lam], [[[1 / (2j * m * wd)]]], quantity="receptance", residual_form="none")
    f = np.linspace(1, 40, 200)
    w = 2 * np.pi * f
    exact = 1 / (m * (wn**2 - w**2 + 2j * z * wn * w))
    np.testing.assert_allclose(synthesize(model, f).H[0, 0], exact, rtol=1e-12)
    acc = convert_quantity(exact, f, "receptance", "accelerance")
    np.testing.assert_allclose(acc, -(w**2) * exact, rtol=1e-12)


def test_transfer_is_the_one_synthesis_kernel_on_and_off_the_frequency_axis() -> None:
    from analysis.modal import ModalModel, synthesize, transfer

    lam = np.array([-0.8 + 2 * np.pi * 30j])
    R = np.array([[[0.3 - 0.7j]]])
    model = ModalModel(poles=lam, residues=R, quantity="receptance", residual_form="none")
    f = np.linspace(1.0, 60.0, 50)
    jw = 2j * np.pi * f
    by_hand = R[0, 0, 0] / (jw - lam[0]) + np.conj(R[0, 0, 0]) / (jw - np.conj(lam[0]))
    assert np.allclose(synthesize(model, f).H[0, 0], by_hand, rtol=1e-14, atol=0)
    # off the axis: H(j w + a) is the model with every pole moved by -a (an exponential window)
    a = 3.0
    shifted = ModalModel(poles=lam - a, residues=R, quantity="receptance", residual_form="none")
    assert np.allclose(transfer(model, jw + a), synthesize(shifted, f).H, rtol=1e-13, atol=0)


def test_the_quantity_unit_table_exists_once() -> None:
    """The SI unit of each FRF quantity is written in analysis.frf.QUANTITY_UNIT alone; the test plan, the
    simulator's FE model and the report take it from there."""
    import re
    from pathlib import Path

    from acquisition.plan import FRF_QUANTITY
    from analysis.frf import QUANTITY_UNIT

    root = Path(__file__).resolve().parents[1]
    copies = [str(p.relative_to(root)) for pkg in ("analysis", "acquisition", "simulator") for p in (root / pkg).rglob("*.py")
              if re.search(r"""["'](mobility|velocity)["']\s*:\s*\(?\s*["'](mobility["']\s*,\s*["'])?\(m/s\)/N""",
                            p.read_text(encoding="utf-8"))]
    assert copies == ["analysis/frf.py"], copies
    assert {q: u for q, u in FRF_QUANTITY.values()} == QUANTITY_UNIT


def test_line_spacing_of_a_set_and_of_a_bare_axis() -> None:
    from analysis.frf import line_spacing_hz

    f = np.array([1.0, 1.5, 2.0, 3.0, 3.5])
    frf = FRFSet(freq_hz=f, H=np.ones((1, 1, f.size), complex), quantity="receptance", outputs=["a"], references=["b"])
    assert frf.line_spacing_hz == line_spacing_hz(f) == 0.5 and line_spacing_hz(f[:1]) == 0.0
