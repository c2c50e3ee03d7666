"""Batch analysis of many recordings on Dask, and the fleet's outlier statistics.

Modules (data flows one way): :mod:`.task` (fit one input; runs on a worker), :mod:`.unit_modes`
(a fit's modes as arrays), :mod:`.fleet` (pairing modes across units, robust statistics, outlier
flags; pure numpy), :mod:`.outputs` (modes.parquet, fleet.json, fleet.png), :mod:`.run` (the Dask
client: submit, collect, restart by content hash), :mod:`.diagnose` (a flagged unit's diagnosis on a
worker, stored and reused like the fits; the SIM's structure checks). The face is
:mod:`analysis.cli_batch`.
Importing this package imports none of them (Dask and pyarrow are an optional extra: ``.[batch]``).
"""
