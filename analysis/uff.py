"""Universal File Format I/O through pyuff: dataset 58 (functions at nodal DOFs) and 55 (shapes).

Dataset 58 records written here (binary, float64, so numbers round-trip exactly):

=========  ==================  =============================================================
func type  content             ordinate / denominator specific data types
=========  ==================  =============================================================
1          time response       12 acceleration, 13 force, 11 velocity, 8 displacement; x in s
4          FRF                 numerator as above, denominator 13 (force); x in Hz
6          ordinary coherence  0 (dimensionless); x in Hz
=========  ==================  =============================================================

Node numbers and direction codes come from :func:`analysis.points.uff_node` and
:func:`analysis.points.uff_direction` (response = output point, reference = excitation point).
ID line 1 names the content, line 2 the estimator and averages, line 3 the windows, line 4 the
point labels, line 5 the source. :func:`read_uff58` reads FRFs (type 4) and matching coherence
(type 6) back into an :class:`~analysis.frf.FRFSet`, matching them by node and direction.
"""
from __future__ import annotations

import gc
import logging
import os
import warnings
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType

import numpy as np

from .errors import UFFError
from .finite_checks import describe_nonfinite
from .frf import FRFSet
from .points import parse_point, point_from_uff, uff_direction, uff_node

__all__ = ["write_uff58", "time_records", "read_uff58", "write_uff55", "read_uff55", "UFFError"]

log = logging.getLogger(__name__)

_QUANTITY_TYPE = {"accelerance": 12, "mobility": 11, "receptance": 8}
_TYPE_QUANTITY = {v: k for k, v in _QUANTITY_TYPE.items()}
_UNIT_TYPE = {"N": 13, "m/s^2": 12, "m/s2": 12, "g": 12, "m/s": 11, "m": 8}


def _pyuff() -> ModuleType:
    import pyuff

    return pyuff


def _write_sets(path: Path, sets: list) -> None:
    """pyuff's binary dataset-58 writer reopens the file and leaves that handle to the garbage
    collector (a ResourceWarning when it is released, right after the call); the data are
    complete by then. Silence only that warning, only around the call."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ResourceWarning)
        _pyuff().UFF(str(path)).write_sets(sets, "add", force_double=True)
        gc.collect()


def _id(text: str) -> str:
    return str(text)[:80] if text else "NONE"


def _entity(point: str) -> str:
    return parse_point(point).component[:10]


def _frf_set_dicts(frf: FRFSet, id_lines: Sequence[str]) -> list[dict]:
    pyuff = _pyuff()
    num = _QUANTITY_TYPE[frf.quantity]
    est = str(frf.meta.get("estimator", ""))
    navg = frf.meta.get("n_averages", "")
    ids = list(id_lines) + [""] * 5
    out = []
    for j, ref in enumerate(frf.references):
        for i, rsp in enumerate(frf.outputs):
            if np.all(np.isnan(frf.H[i, j])):
                continue  # never measured
            labels = f"out={rsp} ref={ref}"
            common = dict(
                binary=1, rsp_node=uff_node(rsp), rsp_dir=uff_direction(rsp), ref_node=uff_node(ref),
                ref_dir=uff_direction(ref), rsp_ent_name=_entity(rsp), ref_ent_name=_entity(ref),
                x=np.asarray(frf.freq_hz, float), abscissa_spacing=1, abscissa_spec_data_type=18,
                abscissa_axis_units_lab="Hz", id4=_id(labels), id5=_id(ids[2] or "impactlab"),
                id3=_id(ids[1] or "windows: none"),
            )
            navg_i = navg[j] if isinstance(navg, (list, tuple)) and j < len(navg) else navg
            out.append(pyuff.prepare_58(
                func_type=4, data=np.asarray(frf.H[i, j], complex), id1=_id(ids[0] or f"FRF {frf.quantity}"),
                id2=_id(f"estimator {est} averages {navg_i} unit {frf.unit}".strip()),
                ordinate_spec_data_type=num, orddenom_spec_data_type=13,
                ordinate_axis_units_lab=frf.unit[:20] or "NONE", **common))
            if frf.coherence is not None:
                out.append(pyuff.prepare_58(
                    func_type=6, data=np.asarray(frf.coherence[i, j], float), id1=_id("ordinary coherence"),
                    id2=_id(f"estimator {est} averages {navg_i}"), ordinate_spec_data_type=0,
                    orddenom_spec_data_type=0, **common))
    return out


def time_records(
    data: np.ndarray, fs_hz: float, points: Sequence[str], units: Sequence[str], reference: str,
    id_line: str = "", t0_s: float = 0.0,
) -> list[dict]:
    """Dataset-58 dicts (function type 1) for one hit's channels ``data[n_ch, n]`` in EU."""
    pyuff = _pyuff()
    d = np.asarray(data, float)
    out = []
    for ch in range(d.shape[0]):
        p = points[ch]
        unit = units[ch] if ch < len(units) else ""
        out.append(pyuff.prepare_58(
            binary=1, func_type=1, data=d[ch], x=t0_s + np.arange(d.shape[1]) / fs_hz, abscissa_spacing=1,
            abscissa_spec_data_type=17, abscissa_axis_units_lab="s", rsp_node=uff_node(p), rsp_dir=uff_direction(p),
            ref_node=uff_node(reference), ref_dir=uff_direction(reference), rsp_ent_name=_entity(p),
            ref_ent_name=_entity(reference), ordinate_spec_data_type=_UNIT_TYPE.get(unit, 1),
            orddenom_spec_data_type=0, ordinate_axis_units_lab=unit[:20] or "NONE",
            id1=_id(id_line or "time response"), id4=_id(f"channel {ch + 1} {p} [{unit}]"), id5=_id("impactlab"),
        ))
    return out


def write_uff58(
    path: str | Path,
    frf: FRFSet | None = None,
    *,
    id_lines: Sequence[str] = (),
    extra_sets: Sequence[dict] = (),
    overwrite: bool = False,
) -> int:
    """Write FRFs (type 4), coherence (type 6) and any ``extra_sets`` (e.g. :func:`time_records`).

    ``id_lines``: (title, windows description, source). Returns the number of datasets written.
    """
    p = Path(path)
    if p.exists():
        if not overwrite:
            raise UFFError(f"{p} exists: choose another output file, or replace it (--overwrite)")
        os.remove(p)
    sets = (_frf_set_dicts(frf, id_lines) if frf is not None else []) + list(extra_sets)
    if not sets:
        raise UFFError("nothing to write: no FRFs and no time records")
    try:
        _write_sets(p, sets)
    except OSError as exc:
        raise UFFError(f"cannot write {p}: {exc}") from None
    return len(sets)


def _read_sets(path: str | Path) -> list[dict]:
    p = Path(path)
    if not p.is_file():
        raise UFFError(f"UFF file {p} not found: check the path")
    try:
        sets = _pyuff().UFF(str(p)).read_sets()
    except Exception as exc:  # pyuff raises bare Exception for malformed files
        raise UFFError(f"{p} is not a readable UFF file ({type(exc).__name__}: {exc})") from None
    if isinstance(sets, dict):
        sets = [sets]
    return sets


def read_uff58(path: str | Path) -> FRFSet:
    """Read the FRFs (type 4) of a UFF file, with coherence (type 6) where present, as one FRFSet.

    Outputs are the response node/directions, references the reference node/directions, in the
    order of first appearance; missing combinations are NaN. All FRFs must share the frequency axis.
    """
    numbered = [(k, s) for k, s in enumerate(_read_sets(path), start=1)
                if isinstance(s, dict) and s.get("type") == 58]
    if numbered:
        _require_complete_file(path)
    try:
        for _, s in numbered:
            _check_record(path, s)
        return _frfset_from_sets(path, numbered)
    except UFFError:
        raise
    except (KeyError, IndexError, ValueError, TypeError, OverflowError, AttributeError) as exc:
        raise UFFError(f"{path}: a dataset 58 record is damaged or incomplete ({type(exc).__name__}: {exc}); "
                       "export the file again") from None


def _require_complete_file(path: str | Path) -> None:
    """Refuse a file cut short: every UFF dataset ends with the delimiter ``-1``, so the file must
    (the reader library silently leaves out a dataset cut short)."""
    p = Path(path)
    try:
        size = p.stat().st_size
        with p.open("rb") as fh:
            fh.seek(max(0, size - 256))
            tail = fh.read()
    except OSError as exc:
        raise UFFError(f"cannot read {p}: {exc.strerror or exc}") from None
    end = tail.rstrip()
    if size and not (end.endswith(b"-1") and (len(end) == 2 or end[-3:-2].isspace())):
        raise UFFError(f"{p} ends inside a dataset (its last line is not the closing '-1'): the file was cut short; "
                       "copy or export it again")


def _check_record(path: str | Path, s: dict) -> None:
    """A dataset-58 record's declared point count, abscissa and values are consistent and finite."""
    where = (f"{path}: dataset 58 response {s.get('rsp_node')}:{s.get('rsp_dir')} reference "
             f"{s.get('ref_node')}:{s.get('ref_dir')} (function type {s.get('func_type')})")
    data = np.asarray(s.get("data", []))
    n = int(s.get("num_pts", -1))
    if n != data.size or n < 1:
        raise UFFError(f"{where}: its header claims {n} points but it holds {data.size}; the file is damaged, "
                       "export it again")
    for key, values in (("abscissa", s.get("x", [])), ("values", data)):
        what = describe_nonfinite(np.asarray(values, dtype=complex if key == "values" else float))
        if what is not None:
            raise UFFError(f"{where}: {key} {what}; measured values must be finite: fix or re-export the file")


def _pair(s: dict) -> tuple[tuple[int, int], tuple[int, int]]:
    """((response node, direction), (reference node, direction)) of a dataset-58 record."""
    return (int(s["rsp_node"]), int(s["rsp_dir"])), (int(s["ref_node"]), int(s["ref_dir"]))


def _one_record_per_pair(path: str | Path, numbered: list, what: str) -> list[tuple[int, dict]]:
    """The records of ``numbered`` ((dataset number in the file, record)), one per response/reference
    pair: a record repeated exactly is read once; two different records for one pair raise
    :class:`UFFError` naming both (keeping either would drop the other silently)."""
    seen: dict = {}
    out = []
    for k, s in numbered:
        pair = _pair(s)
        if pair in seen:
            k0, s0 = seen[pair]
            if np.array_equal(np.asarray(s0["x"]), np.asarray(s["x"])) and np.array_equal(
                    np.asarray(s0["data"]), np.asarray(s["data"])):
                continue
            o, r = (point_from_uff(*pt) for pt in pair)
            raise UFFError(f"{path}: records {k0} and {k} are both the {what} of response {o} reference {r} and they "
                           "differ; keep the one to use (export the file again, or split it) and read it again")
        seen[pair] = (k, s)
        out.append((k, s))
    return out


def _frfset_from_sets(path: str | Path, numbered: list) -> FRFSet:
    """One FRFSet from ``numbered`` dataset-58 records ((dataset number in the file, record))."""
    numbered_frfs = _one_record_per_pair(path, [(k, s) for k, s in numbered if int(s.get("func_type", -1)) == 4],
                                         "FRF")
    if not numbered_frfs:
        raise UFFError(f"{path} holds no dataset-58 FRF (function type 4)")
    k0, s0 = numbered_frfs[0]
    for k, s in numbered_frfs[1:]:
        for field in ("ordinate_spec_data_type", "ordinate_axis_units_lab"):
            if str(s.get(field, "")).strip() != str(s0.get(field, "")).strip():
                raise UFFError(f"{path}: records {k0} and {k} are FRFs of different kinds ({field} "
                               f"{s0.get(field)!r} and {s.get(field)!r}); one FRF set holds one quantity in one unit: "
                               "split the file by quantity")
    frfs = [s for _, s in numbered_frfs]
    outs: list = []
    refs: list = []
    for s in frfs:
        o, r = _pair(s)
        if o not in outs:
            outs.append(o)
        if r not in refs:
            refs.append(r)
    f = np.asarray(frfs[0]["x"], float)
    H = np.full((len(outs), len(refs), f.size), np.nan + 0j)
    for s in frfs:
        if np.asarray(s["x"]).size != f.size or not np.allclose(s["x"], f, rtol=1e-9, atol=0):
            raise UFFError(f"{path}: FRFs have different frequency axes; read them one by one")
        o, r = _pair(s)
        H[outs.index(o), refs.index(r)] = np.asarray(s["data"], complex)
    coh = None
    cohs = [s for _, s in _one_record_per_pair(path, [(k, s) for k, s in numbered
                                                      if int(s.get("func_type", -1)) == 6], "coherence")]
    if cohs:
        C = np.full(H.shape, np.nan)
        for s in cohs:
            o, r = _pair(s)
            if o in outs and r in refs and np.asarray(s["data"]).size == f.size:
                C[outs.index(o), refs.index(r)] = np.real(np.asarray(s["data"]))
        coh = C
    qt = int(frfs[0].get("ordinate_spec_data_type", 12))
    quantity = _TYPE_QUANTITY.get(qt, "accelerance")
    unit = str(frfs[0].get("ordinate_axis_units_lab", ""))
    meta = {"source": str(path), "id1": frfs[0].get("id1", ""), "id2": frfs[0].get("id2", ""),
            "id3": frfs[0].get("id3", "")}
    return FRFSet(
        freq_hz=f, H=H, quantity=quantity,
        outputs=tuple(str(point_from_uff(n, d)) for n, d in outs),
        references=tuple(str(point_from_uff(n, d)) for n, d in refs),
        unit="" if unit == "NONE" else unit, coherence=coh, meta=meta,
    )


def write_uff55(
    path: str | Path,
    poles: np.ndarray,
    shapes: np.ndarray,
    points: Sequence[str],
    *,
    title: str = "impactlab mode shapes",
    overwrite: bool = False,
) -> int:
    """Write complex mode shapes as UFF 55 (complex eigenvalue analysis, 3 DOF per node).

    poles : (n_modes,) complex poles lambda_r (rad/s); shapes : (n_points, n_modes) complex, the
    shape value of each mode at each point along that point's signed direction. Points on one
    node are combined into that node's (x, y, z) record. Returns the number of datasets written.
    """
    pyuff = _pyuff()
    lam = np.atleast_1d(np.asarray(poles, complex))
    phi = np.asarray(shapes, complex)
    if phi.ndim != 2 or phi.shape != (len(points), lam.size):
        raise UFFError(f"shapes must have shape (n_points={len(points)}, n_modes={lam.size}); got {phi.shape}")
    nodes: list[int] = []
    for pt in points:
        n = uff_node(pt)
        if n not in nodes:
            nodes.append(n)
    p = Path(path)
    if p.exists():
        if not overwrite:
            raise UFFError(f"{p} exists: choose another output file, or replace it (--overwrite)")
        os.remove(p)
    sets = []
    for r in range(lam.size):
        xyz = np.zeros((len(nodes), 3), complex)
        for k, pt in enumerate(points):
            q = parse_point(pt)
            xyz[nodes.index(uff_node(q)), q.axis] += q.sign * phi[k, r]
        sets.append(pyuff.prepare_55(
            id1=_id(title), id2=_id(f"mode {r + 1}"), id3="NONE", id4="NONE", id5="NONE",
            model_type=1, analysis_type=3, data_ch=2, spec_data_type=8, data_type=5, n_data_per_node=3,
            load_case=1, mode_n=r + 1, eig=complex(lam[r]), modal_a=0j, modal_b=0j,
            node_nums=np.asarray(nodes, dtype=int), r1=xyz[:, 0], r2=xyz[:, 1], r3=xyz[:, 2],
        ))
    _write_sets(p, sets)
    return len(sets)


def read_uff55(path: str | Path) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Read complex UFF 55 shapes: (poles (n_modes,), node numbers (n_nodes,), shapes (n_nodes, 3, n_modes))."""
    sets = [s for s in _read_sets(path) if s.get("type") == 55]
    if not sets:
        raise UFFError(f"{path} holds no dataset 55 (mode shapes)")
    nodes = np.asarray(sets[0]["node_nums"], float).astype(int)
    lam = np.array([complex(s.get("eig", 0j)) for s in sets])
    shapes = np.stack([np.stack([np.asarray(s[k], complex) for k in ("r1", "r2", "r3")], axis=1) for s in sets],
                      axis=2)
    return lam, nodes, shapes
