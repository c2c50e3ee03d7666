"""The real datasets of docs/validation.md in one table: a short key, the name the docs use, the loader
and the band the validation fits each in.

The table is plain data (module and attribute names); a dataset's module is imported only when it is
loaded, so importing this table is cheap (test collection, argument parsing). Used by the automatic-band
study (``benchmarks/studies/default_band_realdata.py``) and the browser test of the report
(``tests/test_report_browser.py``).
"""
from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

__all__ = ["RealDataset", "DATASETS"]


@dataclass(frozen=True)
class RealDataset:
    """One real dataset: ``key`` (short, for test ids and folder names), ``label`` (its name in the tables of
    docs/validation.md), ``module`` (its loader module in this package), ``loader`` (the function there,
    called as ``loader(data_dir, **options)``), ``band`` (the module attribute holding the band the validation
    fits it in, Hz), ``whole_range`` (the loader options that give every recorded line, for a study of the
    automatic band; empty when the loader does so by default)."""

    key: str
    label: str
    module: str
    loader: str = "load"
    band: str = "BAND"
    whole_range: dict[str, Any] = field(default_factory=dict)

    def _module(self):
        return importlib.import_module(f"{__package__}.{self.module}")

    def loader_function(self) -> Callable[..., Any]:
        """The loader, ``loader(data_dir, **options) -> FRFSet`` (imports the dataset's module)."""
        return getattr(self._module(), self.loader)

    def fit_band(self) -> tuple[float, float]:
        """The band (Hz) the validation of docs/validation.md fits this dataset in."""
        lo, hi = getattr(self._module(), self.band)
        return float(lo), float(hi)

    def load(self, data_dir: Path, **options: Any):
        """The dataset's FRFs (:class:`analysis.frf.FRFSet`) from the shared data folder ``data_dir``;
        ``options`` go to the loader (e.g. :attr:`whole_range`)."""
        return self.loader_function()(Path(data_dir), **options)


#: every real dataset of docs/validation.md, in the order of its tables
DATASETS: tuple[RealDataset, ...] = (
    RealDataset("uliege_plane", "uliege_meca0062_plane_hammer", "uliege_plane", whole_range={"band": None}),
    RealDataset("modelab_beam", "modelab_beam_roving_hammer", "modelab_beam"),
    RealDataset("ladisk_single", "ladisk_beam (1 hit)", "ladisk_beam", loader="load_single", band="BAND_SINGLE"),
    RealDataset("ladisk_multi", "ladisk_beam (4 hits)", "ladisk_beam", loader="load_multi", band="BAND_MULTI"),
    RealDataset("pyfrf_5impacts", "pyfrf_hammer_5impacts", "pyfrf_5impacts"),
    RealDataset("f16_gvt", "f16_gvt_multisine", "f16_gvt"),
    RealDataset("plate_sweep", "ladisk_plate_sweep", "plate_sweep"),
    RealDataset("pyuff_3frf", "pyuff_3frf", "pyuff_3frf"),
    RealDataset("unesp_boltedbeam", "unesp_bert_boltedbeam_subset (0.05 V)", "unesp_boltedbeam"),
)

