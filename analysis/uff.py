"""Universal File Format I/O through pyuff: dataset 58 (functions at nodal DOFs) and 55 (shapes).

Dataset 58 records written here (binary, float64, so numbers round-trip exactly):

=========  ==================  =============================================================
func type  content             ordinate / denominator specific data types
=========  ==================  =============================================================
1          time response       12 acceleration, 13 force, 11 velocity, 8 displacement; x in s
4          FRF                 numerator as above, denominator 13 (force); x in Hz
6          ordinary coherence  0 (dimensionless); x in Hz
=========  ==================  =============================================================

Node numbers and direction codes come from :func:`analysis.points.uff_dofs` (response = output
point, reference = excitation point): ``component:node:direction`` labels get
:func:`~analysis.points.uff_node` and :func:`~analysis.points.uff_direction`, any other label a node
number of its own. ID line 1 names the content, line 2 the estimator and averages, line 3 the
windows, line 4 the point labels, line 5 the source. Two ID lines are read back as ``key=value``:

- line 3 starts ``exp_window_tau_s=<tau>`` (the exponential window's time constant in s, written
  exactly; ``none`` without a window), then the windows in words;
- line 4 is ``out=<output label> ref=<reference label>`` (labels up to 76 characters together).

:func:`read_uff58` reads FRFs (type 4) and matching coherence (type 6) back into an
:class:`~analysis.frf.FRFSet`, matching them by node and direction; the labels come from line 4
(else from the node numbers) and the exponential window from line 3, so a fit corrects the damping
of the read-back FRFs as it would the recording's.
"""
from __future__ import annotations

import gc
import logging
import math
import re
import warnings
from collections.abc import Sequence
from pathlib import Path
from types import ModuleType

import numpy as np

from .atomic import atomic_path
from .disk_space import disk_full_cause
from .errors import UFFError
from .finite_checks import describe_nonfinite
from .frf import FRFSet
from .points import point_from_uff, uff_dofs

__all__ = ["write_uff58", "time_records", "read_uff58", "write_uff55", "read_uff55", "UFFError"]

log = logging.getLogger(__name__)

_QUANTITY_TYPE = {"accelerance": 12, "mobility": 11, "receptance": 8}
_TYPE_QUANTITY = {v: k for k, v in _QUANTITY_TYPE.items()}
_UNIT_TYPE = {"N": 13, "m/s^2": 12, "m/s2": 12, "g": 12, "m/s": 11, "m": 8}


def _pyuff() -> ModuleType:
    import pyuff

    return pyuff


def _write_sets(path: Path, sets: list) -> None:
    """Write ``sets`` as the whole file ``path``, atomically (:func:`analysis.atomic.atomic_path`: a
    failure, a full disk included, leaves ``path`` as it was). pyuff's binary dataset-58 writer
    reopens the file and leaves that handle open (a ResourceWarning when it is released); the data
    are complete by then. Silence only that warning, only around the call. A write that returns has
    released the handle already (its last reference went with the writer's frame); only a failed one
    can leave it to the garbage collector (held by the traceback's frames), which is then run here, still
    inside the silenced block: a full collection costs about a tenth of a second in a process holding
    many objects, too much for every file written. pyuff reports a failed write as a bare
    ``Exception``: the ``OSError`` it hides (disk full, permission) is raised instead."""
    with atomic_path(path) as tmp, warnings.catch_warnings():
        warnings.simplefilter("ignore", ResourceWarning)
        written = False
        try:
            _pyuff().UFF(str(tmp)).write_sets(sets, "add", force_double=True)
            written = True
        except Exception as exc:  # noqa: BLE001 - pyuff raises bare Exception around the real error
            cause = exc.__cause__ or exc.__context__
            if isinstance(cause, OSError):
                raise OSError(cause.errno, cause.strerror, str(path)) from None
            raise
        finally:
            if not written:
                gc.collect()


#: characters of a UFF ID line
ID_LINE_CHARS = 80
#: ID line 3's key of the exponential window's time constant (s), and ID line 4's label keys
WINDOW_KEY = "exp_window_tau_s"
_WINDOW_RE = re.compile(WINDOW_KEY + r"=([^\s;]+)")
#: the windows in words of files written before the key (``exp tau 0.25 s``, 6 digits)
_WINDOW_WORDS_RE = re.compile(r"\bexp tau ([0-9.eE+-]+) s\b")
_ESTIMATOR_RE = re.compile(r"\bestimator (\S+)")
#: the number of averages in an ID line, as a writer may put it in words: ``averages 54``, ``Averages: 54``,
#: ``averages=54``, ``54 averages`` (dataset 58 has no field for it; its ID lines are free text)
_AVERAGES_RE = re.compile(r"\baverages?\s*[:=]?\s*(\d+)\b|\b(\d+)\s+averages?\b", re.IGNORECASE)
_LABELS_RE = re.compile(r"^out=(\S.*?) ref=(\S.*)$")


def _id(text: str) -> str:
    return str(text)[:ID_LINE_CHARS] if text else "NONE"


def _entity(point: str) -> str:
    return str(point).split(":", 1)[0].strip()[:10] or "NONE"


def window_id_line(exp_window_tau_s: float | None, words: str = "") -> str:
    """ID line 3: ``exp_window_tau_s=<tau s, exact>`` (``none`` without a window), then ``words``
    (the windows in words), cut to the line's 80 characters (the key is never cut)."""
    tau = "none" if not exp_window_tau_s else repr(float(exp_window_tau_s))
    return _id(f"{WINDOW_KEY}={tau}" + (f"; {words}" if words else ""))


def _labels_id_line(rsp: str, ref: str) -> str:
    """ID line 4: ``out=<label> ref=<label>``; when the two do not fit the line, the labels are
    left out (they read back from the node numbers) and a warning is logged."""
    line = f"out={rsp} ref={ref}"
    if len(line) <= ID_LINE_CHARS and not any(c in line for c in "\r\n"):
        return line
    log.warning("point labels %r and %r do not fit a UFF ID line (%d characters): they read back as node "
                "numbers", rsp, ref, ID_LINE_CHARS)
    return "labels: see the node numbers"


def _frf_set_dicts(frf: FRFSet, id_lines: Sequence[str]) -> list[dict]:
    pyuff = _pyuff()
    num = _QUANTITY_TYPE[frf.quantity]
    est = str(frf.meta.get("estimator", ""))
    navg = frf.meta.get("n_averages", "")
    ids = list(id_lines) + [""] * 5
    dofs = uff_dofs(list(frf.outputs) + list(frf.references))
    out = []
    for j, ref in enumerate(frf.references):
        for i, rsp in enumerate(frf.outputs):
            if np.all(np.isnan(frf.H[i, j])):
                continue  # never measured
            common = dict(
                binary=1, rsp_node=dofs[rsp][0], rsp_dir=dofs[rsp][1], ref_node=dofs[ref][0],
                ref_dir=dofs[ref][1], rsp_ent_name=_entity(rsp), ref_ent_name=_entity(ref),
                x=np.asarray(frf.freq_hz, float), abscissa_spacing=1, abscissa_spec_data_type=18,
                abscissa_axis_units_lab="Hz", id4=_id(_labels_id_line(rsp, ref)), id5=_id(ids[2] or "impactlab"),
                id3=window_id_line(frf.exp_window_tau_s, ids[1] or "windows: none"),
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
    dofs = uff_dofs(list(points[:d.shape[0]]) + [reference])
    out = []
    for ch in range(d.shape[0]):
        p = points[ch]
        unit = units[ch] if ch < len(units) else ""
        out.append(pyuff.prepare_58(
            binary=1, func_type=1, data=d[ch], x=t0_s + np.arange(d.shape[1]) / fs_hz, abscissa_spacing=1,
            abscissa_spec_data_type=17, abscissa_axis_units_lab="s", rsp_node=dofs[p][0], rsp_dir=dofs[p][1],
            ref_node=dofs[reference][0], ref_dir=dofs[reference][1], rsp_ent_name=_entity(p),
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
    if p.exists() and not overwrite:
        raise UFFError(f"{p} exists: choose another output file, or replace it (--overwrite)")
    sets = (_frf_set_dicts(frf, id_lines) if frf is not None else []) + list(extra_sets)
    if not sets:
        raise UFFError("nothing to write: no FRFs and no time records")
    try:
        _write_sets(p, sets)
    except OSError as exc:
        if disk_full_cause(exc) is not None:
            raise  # a runtime failure (exit 1), not a bad request
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
            "id3": frfs[0].get("id3", ""), **_estimator_from_ids(frfs, refs)}
    out_labels, ref_labels = _labels_from_ids(path, frfs, outs, refs)
    return FRFSet(
        freq_hz=f, H=H, quantity=quantity, outputs=out_labels, references=ref_labels,
        unit="" if unit == "NONE" else unit, coherence=coh, exp_window_tau_s=_window_from_ids(path, frfs), meta=meta,
    )


def _labels_from_ids(path: str | Path, frfs: list[dict], outs: list, refs: list) -> tuple[tuple, tuple]:
    """The output and reference labels of the (node, direction) keys ``outs``/``refs``: from the
    records' ID line 4 (``out=<label> ref=<label>``) when every record has one and they name each
    degree of freedom by one label and each label one degree of freedom; else, for all of them, from
    the node numbers (:func:`analysis.points.point_from_uff`)."""
    named: dict[tuple[int, int], str] = {}
    consistent = True
    for s in frfs:
        m = _LABELS_RE.match(str(s.get("id4", "")).strip())
        if m is None:
            consistent = False
            break
        o, r = ((int(s["rsp_node"]), int(s["rsp_dir"])), (int(s["ref_node"]), int(s["ref_dir"])))
        for dof, label in ((o, m.group(1).strip()), (r, m.group(2).strip())):
            if named.setdefault(dof, label) != label:
                consistent = False
    labels = list(named.values())
    if consistent and len(set(labels)) == len(labels):
        return tuple(named[k] for k in outs), tuple(named[k] for k in refs)
    if named:
        log.info("%s: the ID lines' point labels are missing or do not match the node numbers; labels from the "
                 "node numbers", path)
    return (tuple(str(point_from_uff(n, d)) for n, d in outs), tuple(str(point_from_uff(n, d)) for n, d in refs))


def _averages_in(record: dict) -> int | None:
    """The number of averages an FRF record's ID lines (1-5) state in words (``_AVERAGES_RE``), or None."""
    for k in range(1, 6):
        m = _AVERAGES_RE.search(str(record.get(f"id{k}", "")))
        if m is not None:
            return int(m.group(1) or m.group(2))
    return None


def _estimator_from_ids(frfs: list[dict], refs: list) -> dict:
    """``{"estimator": ..., "n_averages": [per reference]}`` from the FRF records' ID lines: the estimator
    from line 2 as this module writes it (``estimator H1 averages 3 ...``), the number of averages from any
    ID line that states it in words (``_AVERAGES_RE``; this module's line 2, or another writer's ``Averages:
    54``): the fit trusts a coherence by the number of averages behind it. Each key is left out when a
    reference's records do not say (or say differently): the count is then unknown."""
    estimators: dict[tuple[int, int], str] = {}
    averages: dict[tuple[int, int], int] = {}
    for s in frfs:
        ref = (int(s["ref_node"]), int(s["ref_dir"]))
        m = _ESTIMATOR_RE.search(str(s.get("id2", "")))
        if m is not None:
            estimators.setdefault(ref, m.group(1))
        n = _averages_in(s)
        if n is not None:
            averages.setdefault(ref, n)
    out: dict = {}
    if refs and all(r in estimators for r in refs) and len({estimators[r] for r in refs}) == 1:
        out["estimator"] = estimators[refs[0]]
    if refs and all(r in averages for r in refs):
        out["n_averages"] = [averages[r] for r in refs]
    return out


def _window_from_ids(path: str | Path, frfs: list[dict]) -> float | None:
    """The exponential window's time constant (s) from the FRF records' ID line 3
    (``exp_window_tau_s=<tau>|none``; in files without the key, the words ``exp tau <tau> s``);
    None when no record names one. UFFError when a value is not a positive time or the records
    name different windows (one FRF set has one window)."""
    found: set[float | None] = set()
    for s in frfs:
        line = str(s.get("id3", ""))
        m = _WINDOW_RE.search(line) or _WINDOW_WORDS_RE.search(line)
        if m is None:
            found.add(None)
            continue
        text = m.group(1)
        if text.lower() == "none":
            found.add(None)
            continue
        try:
            tau = float(text)
        except ValueError:
            tau = math.nan
        if not (math.isfinite(tau) and tau > 0):
            raise UFFError(f"{path}: ID line 3 gives the exponential window {WINDOW_KEY}={text!r}, not a positive "
                           f"time in s; correct it (or write {WINDOW_KEY}=none) and read the file again")
        found.add(tau)
    if len(found) > 1:
        taus = ", ".join("none" if t is None else f"{t:.6g} s" for t in sorted(found, key=lambda t: t or 0.0))
        raise UFFError(f"{path}: its FRFs were measured with different exponential windows ({taus}); one FRF set has "
                       "one window: export the FRFs of each window to a file of their own")
    return found.pop() if found else None


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
    dofs = uff_dofs(points)
    nodes: list[int] = []
    for pt in points:
        n = dofs[str(pt)][0]
        if n not in nodes:
            nodes.append(n)
    p = Path(path)
    if p.exists() and not overwrite:
        raise UFFError(f"{p} exists: choose another output file, or replace it (--overwrite)")
    sets = []
    for r in range(lam.size):
        xyz = np.zeros((len(nodes), 3), complex)
        for k, pt in enumerate(points):
            node, direction = dofs[str(pt)]
            xyz[nodes.index(node), abs(direction) - 1] += np.sign(direction) * phi[k, r]
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
