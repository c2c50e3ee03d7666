"""``python -m analysis diagnose --measured M --simulated S --json OUT.json [--report DIR]``.

M is a recording (``.h5``) or a UFF 58 file. S is a recording or UFF 58 file with the same points
(matched by ``component:node:direction`` labels of outputs and references), or a simulator
configuration (``.toml``), simulated on the fly at M's points and lines; then the physical causes
(:mod:`simulator.physical`: added mass, support and joint stiffness, member mass and stiffness,
accelerometer mass, modulus) are fitted by re-running the FE model. A simulated FRF file is
first turned into a modal model by the automatic fit (:func:`analysis.pipeline.fit_auto`), so the
modal effects can act on it. Exit codes: 0 done, 2 bad input (message on stderr).
"""
from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path
from typing import Optional, Sequence

import numpy as np

from .command_line import with_examples
from .command_line import Parser as _Parser, check_out_dir, parse_args, add_estimator, add_threads, cli_entry

__all__ = ["main", "build_parser", "load_simulation"]

log = logging.getLogger(__name__)



def _json_default(x):
    if isinstance(x, (np.floating, np.integer, np.bool_)):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    raise TypeError(f"{type(x).__name__} is not JSON serialisable")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="python -m analysis diagnose",
                description="Compare a measurement with a simulation, name the physical cause of the "
                            "difference from a catalogue of effects, extend the model and measure the gain.")
    with_examples(p)
    p.add_argument("--measured", required=True, metavar="M", help="recording (.h5) or UFF 58 file")
    p.add_argument("--simulated", required=True, metavar="S",
                   help="recording or UFF 58 file with the same points, or a simulator config (.toml)")
    p.add_argument("--json", required=True, metavar="OUT.json", help="write the diagnosis as JSON")
    p.add_argument("--report", metavar="DIR", help="write report.md and plots into DIR")
    p.add_argument("--band", metavar="LO:HI",
                   help="frequency band in Hz (default: from the data: the analyser's band, the hammer's "
                        "excitation band and the coherence)")
    p.add_argument("--effects", metavar="A,B,...", help="only these effects of the catalogue")
    add_estimator(p)
    add_threads(p)
    return p


def load_simulation(path: str, measured, estimator: Optional[str] = None):
    """The simulation as a :class:`ModalModel` at the measured points (outputs, references order)."""
    return load_simulations(path, measured, estimator)[0]


def load_simulations(path: str, measured, estimator: Optional[str] = None):
    """(model, physical): the simulation as a :class:`ModalModel` at the measured points, and for a
    simulator config its FE model split by physical cause (:class:`simulator.physical.FrameVariants`,
    None for an FRF file)."""
    from .inputs import InputError, load_input
    from .diagnosis.compare import common_points

    p = Path(path)
    if p.suffix.lower() == ".toml":
        from simulator.config import ConfigError
        from simulator.fem import ModelError
        from simulator.physical import FrameVariants

        try:
            variants = FrameVariants(p, measured.outputs, measured.references)
            return variants.model(None, {}), variants
        except (ConfigError, ModelError, OSError) as exc:
            raise InputError(f"simulator config {p}: {exc}") from None
    sim = load_input(p, estimator=estimator)
    outs, refs = common_points(measured, sim)
    if len(outs) != measured.n_outputs or len(refs) != measured.n_references:
        raise InputError(f"{p} lacks some measured points: it has outputs {list(sim.outputs)} and references "
                         f"{list(sim.references)}; measured {list(measured.outputs)} / {list(measured.references)}")
    sim = sim.select(outs, refs)
    from .pipeline import FitError, fit_auto

    try:
        result = fit_auto(sim).lsfd
    except FitError as exc:
        raise InputError(f"cannot build a modal model of the simulated FRFs in {p}: {exc}") from None
    return model_with_correction(result.model, sim), None


def model_with_correction(model, sim):
    """The fitted model plus, in ``meta["frf_correction"]``, what it misses of the simulated FRFs,
    so that the prediction without effects is the simulated FRFs themselves (modal effects move
    only the fitted modes)."""
    from dataclasses import replace

    from .modal import synthesize

    syn = synthesize(model, sim.freq_hz)
    same = sim if sim.quantity == syn.quantity else sim.as_quantity(syn.quantity)
    corr = replace(same, H=same.H - syn.H, coherence=None)
    meta = dict(model.meta)
    meta["frf_correction"] = corr
    return replace(model, outputs=tuple(sim.outputs), references=tuple(sim.references), meta=meta)


def time_data_causes(path: str, band: tuple, base=None) -> list:
    """Time-data causes (:mod:`analysis.diagnosis.timedata`) of a recording's accepted hits (those its
    FRFs were made from; rejected hits changed nothing), per reference point; [] when the file is not
    a recording or holds no accepted hits. With ``base`` (the simulation as a receptance
    pole-residue model holding the hits' points), each cause also gets its held-out ``gain_db``,
    ``error_before_db``, ``error_after_db``, ``significant`` and ``counts`` from
    :func:`analysis.diagnosis.timedata_gain.diagnose_time_effects` (re-simulated or hits excluded)."""
    from .inputs import detect_format
    from .diagnosis.timedata import diagnose_hits

    if detect_format(path) != "recording":
        return []
    from analysis.recording import Recording, RecordingError

    groups: dict = {}
    try:
        with Recording(path) as rec:
            for h in rec.hits(accepted_only=True, skip_damaged=True):
                groups.setdefault((h.reference, h.sample_rate_hz, h.data.shape), []).append(h)
    except (RecordingError, OSError) as exc:
        log.warning("time data of %s not read: %s", path, exc)
        return []
    out = []
    for (ref, fs, _), hits in groups.items():
        if len(hits) < 2:
            continue
        force = np.array([h.data[h.force_channel] for h in hits])
        resp = np.array([h.data[h.response_channels] for h in hits])
        flags = np.array([h.overload for h in hits])
        gains = _time_gains(force, resp, fs, band, base, hits[0].outputs, ref, flags) if base is not None else {}
        for c in diagnose_hits(force, resp, fs, band, overload_flags=flags):
            c["reference"] = ref
            c.update(gains.get(c["effect"], {}))
            out.append(c)
    return sorted(out, key=lambda c: (not c["present"], -c.get("gain_db", 0.0)))


def _time_gains(force, resp, fs, band, base, outputs, ref, flags) -> dict:
    """Held-out gains of the time-data effects per effect name ({} when the simulation cannot be used)."""
    from dataclasses import replace

    from .diagnosis.timedata_gain import diagnose_time_effects

    try:
        oi = [list(base.outputs).index(o) for o in outputs]
        ri = list(base.references).index(ref)
        sub = replace(base, residues=base.residues[oi][:, [ri]], outputs=tuple(outputs), references=(ref,))
        d = diagnose_time_effects(force, resp, fs, sub, band, overload_flags=flags, outputs=outputs, reference=ref)
    except (ValueError, IndexError) as exc:
        log.info("time-data gains of %s not measured: %s", ref, exc)
        return {}
    keys = ("gain_db", "error_before_db", "error_after_db", "z", "significant", "counts", "kind")
    return {c["effect"]: {k: c[k] for k in keys} for c in d["causes"]}


def _hit_noise(path: str, measured) -> dict:
    """``{"hits": dB}``: the noise of a recording's FRFs from the scatter of its hits ({} otherwise)."""
    from .diagnosis.compare import line_weights
    from .diagnosis.hit_noise import hit_scatter_noise_db
    from .inputs import detect_format

    if detect_format(path) != "recording":
        return {}
    level = hit_scatter_noise_db(path, measured, line_weights(measured))
    return {} if level is None else {"hits": level}


@cli_entry
def main(argv: Optional[Sequence[str]] = None) -> int:
    """Run the command; returns the exit code (0 done, 2 bad input)."""
    from .bands import FitError, default_band
    from .inputs import InputError, load_input, parse_band_text
    from .diagnosis import EFFECTS, EffectError, diagnose
    from .diagnosis.compare import common_points

    parser = build_parser()
    args = parse_args(parser, argv)
    if isinstance(args, int):
        return args
    try:
        check_out_dir(args.json, error=InputError)
        effects = None
        if args.effects:
            effects = [e.strip() for e in args.effects.split(",") if e.strip()]
            bad = [e for e in effects if e not in EFFECTS]
            if bad:
                raise InputError(f"unknown effect(s) {bad}; the catalogue has {', '.join(EFFECTS)}")
        measured = load_input(args.measured, estimator=args.estimator)
        band = parse_band_text(args.band)
        lo, hi = band if band is not None else default_band(measured)
        measured = measured.band(lo, hi)
        finite = np.all(np.isfinite(measured.H), axis=(0, 1))
        if not finite.all():
            raise InputError(f"{args.measured} holds NaN/inf lines at {np.count_nonzero(~finite)} frequencies; "
                             "give --band to exclude them")
        base, physical = load_simulations(args.simulated, measured, args.estimator)
        if physical is not None and band is None:
            top = physical.converged_below_hz()
            if top < measured.freq_hz[-1]:
                print(f"band {measured.freq_hz[0]:.4g}-{top:.4g} Hz: the simulation's mesh is converged only below "
                      f"{top:.4g} Hz (give --band to override)", file=sys.stderr)
                measured = measured.band(float(measured.freq_hz[0]), top)
        outs, refs = common_points(measured, base)
        measured = measured.select(outs, refs)
        diag = diagnose(measured, base, effects=effects, physical=physical,
                        extra_noise_db=_hit_noise(args.measured, measured))
    except (InputError, EffectError, ValueError, FitError) as exc:
        print(f"analysis diagnose: {exc}", file=sys.stderr)
        return 2
    doc = diag.to_json()
    try:
        timed = time_data_causes(args.measured, (float(measured.freq_hz[0]), float(measured.freq_hz[-1])), base)
    except ValueError as exc:
        timed = []
        log.warning("time data not analysed: %s", exc)
    if timed:
        doc["time_data"] = timed
        present = [c for c in timed if c["present"]]
        counted = sorted((c for c in present if c.get("counts")), key=lambda c: -c.get("gain_db", 0.0))
        doc["time_data_verdict"] = counted[0]["effect"] if counted else "none"
        if doc["verdict"] == "unexplained" and counted:
            doc["verdict"] = counted[0]["effect"]
        elif doc["verdict"] == "unexplained" and any(c["effect"] == "amplitude_nonlinearity" for c in present):
            doc["verdict"] = "amplitude_nonlinearity"
    from .cli_linearity import level_dependence

    levels = level_dependence(args.measured, args.simulated, (float(measured.freq_hz[0]), float(measured.freq_hz[-1])))
    if levels is not None:
        doc["level_dependence"] = levels
        if levels.get("cause", {}).get("present"):
            doc["linear_verdict"], doc["verdict"] = doc["verdict"], "joint_nonlinearity"
    Path(args.json).write_text(json.dumps(doc, indent=1, default=_json_default))
    if args.report:
        from .diagnosis.report import write_report

        write_report(diag, args.report)
    for c in timed:
        if c["present"]:
            print(f"  time data ({c['reference']}): {c['evidence']}")
    if levels is not None and "cause" in levels:
        print(f"  level dependence: {levels['cause']['evidence']}")
    print(f"verdict: {doc['verdict']}" + (f" ({diag.reason})" if diag.reason else ""))
    print(f"error before {diag.error_before_db:.1f} dB, after {diag.error_after_db:.1f} dB "
          f"(noise {max(diag.noise_db.values()):.1f} dB)")
    for c in diag.causes[:5]:
        print(f"  {'*' if c['significant'] else ' '} {c['evidence']}")
    return 0
