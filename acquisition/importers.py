"""Turn measured impact time data from other systems into recordings: the public names in one place.

Each step is a module with one job; this module gathers their public names:

* parsing, :mod:`acquisition.importers_parse`: the readers below return an :class:`ImportedTest`
  (the file's float time histories in engineering units, one array per hit);
* the container and its checks, :mod:`acquisition.importers_data` (:func:`combine_imports` joins
  the files of one test);
* roles, :mod:`acquisition.importers_roles`: :func:`channel_roles` fixes the force and response
  channels and their point labels;
* quantisation, :mod:`acquisition.importers_quantise`: :func:`imported_hits` makes the
  :class:`analysis.hit.Hit` of each block (int16 counts, trigger, channel roles);
* writing, :mod:`acquisition.importers_write`: :func:`write_imported` writes them as a schema-v1
  recording with FRFs computed by the same code path as a capture.

Which reader reads which file is the import registry's (:mod:`acquisition.importers_registry`).

Formats
-------
* LabVIEW ``.lvm`` text (:func:`read_lvm`): header keys ``Separator``, ``Decimal_Separator``
  (``,`` or ``.``; not both a comma), each segment (= one hit) with its own channel header
  (``Channels``, ``Samples``, ``Y_Unit_Label``, ``Delta_X``) and a data table whose first column is
  the X value (possibly empty) and a trailing ``Comment`` column. Every segment must share the first
  one's ``Delta_X`` and column headings; columns in another order are matched by heading.
* DataPhysics SignalCalc ``.mat`` exports (:func:`read_dataphysics_mat`): ``X1..Xn`` raw blocks
  ``[t, value]`` (``t < 0`` is the pre-trigger), ``W1..Wn`` the analyser-windowed blocks,
  ``Sensitivity`` (mV/EU), ``Unit``.
* SEP005 JSON (:func:`read_sep005_test`): one ``group`` per hit, channels matched by name.
* numpy arrays (:func:`read_numpy`): ``.npy`` files, one per hit, shaped ``(n_ch, n)`` or
  ``(n, n_ch)``, with a description (JSON or TOML, :func:`load_description`)::

      sample_rate_hz = 25600          # or time_row = 0: a row holding the time (s)
      layout = "channels_first"       # or "samples_first"
      time_row = 0                    # optional: index of a time channel to drop
      [[channels]]                    # one per (remaining) channel, in order
      name = "force"; quantity = "force"; unit = "N"; point = "n:1:Z"
      [[channels]]
      name = "acc"; quantity = "acceleration"; unit = "m/s^2"; point = "n:2:Z"

* CSV tables (:func:`read_csv_table`): a heading row, one column per signal; the description's
  ``columns`` name (by heading) the columns that are its channels, in order.
* HDF5 datasets (:func:`read_hdf5_dataset`): ``dataset`` names the 2-D dataset, ``columns`` the
  signal indices to keep, ``sample_rate_hz`` a number or the name of a one-value dataset.

A shaker's continuous excitation (periodic, random, swept) is described with ``excitation =
"continuous"``: the record is cut into blocks of ``block_samples`` after ``skip_blocks`` (the
transient), every block is kept (no hammer pulse to check) and no hammer window is applied.

Quantisation (:mod:`acquisition.importers_quantise`): each hit and channel gets ``eu_per_count =
max|x| / 32767``; a hit whose counts would lose part of a channel is refused. ``volts_per_count =
eu_per_count * sensitivity`` when the sensitivity is known (NaN otherwise; infinite or zero
sensitivities are refused).

Nothing is stored altered: what cannot be read as the file holds it (complex time values,
channels that change order or sampling between hits, two different records for one channel) is
refused with :class:`ImportDataError` naming the file, the field and what to do.
"""
from __future__ import annotations

from .errors import ImportDataError, NonFiniteSamples
from .importers_data import (
    MAX_SAMPLE_RATE_HZ,
    ImportedTest,
    combine_imports,
    drop_nonfinite_hits,
    read_dropping_nonfinite,
    source_files,
)
from .importers_parse import (
    LOADMAT_TIMEOUT_S,
    LVM_SEPARATORS,
    load_description,
    read_csv_table,
    read_dataphysics_mat,
    read_hdf5_dataset,
    read_lvm,
    read_numpy,
    read_sep005_test,
)
from .importers_quantise import (
    INT16_MAX_PEAK,
    INT16_MAX_REST_CHANGE,
    INT16_MIN_PEAK,
    INT16_REST_FRACTION,
    detect_trigger,
    imported_hits,
    int16_rest_change,
    quantize,
)
from .importers_roles import ChannelRoles, channel_roles
from .importers_write import write_imported

__all__ = [
    "ImportDataError",
    "NonFiniteSamples",
    "drop_nonfinite_hits",
    "read_dropping_nonfinite",
    "ImportedTest",
    "MAX_SAMPLE_RATE_HZ",
    "source_files",
    "read_lvm",
    "read_dataphysics_mat",
    "read_sep005_test",
    "read_numpy",
    "read_csv_table",
    "read_hdf5_dataset",
    "load_description",
    "LVM_SEPARATORS",
    "LOADMAT_TIMEOUT_S",
    "quantize",
    "int16_rest_change",
    "INT16_REST_FRACTION",
    "INT16_MAX_REST_CHANGE",
    "INT16_MIN_PEAK",
    "INT16_MAX_PEAK",
    "detect_trigger",
    "write_imported",
    "imported_hits",
    "combine_imports",
    "ChannelRoles",
    "channel_roles",
]
