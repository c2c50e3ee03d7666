"""Validation of impactlab on real measured data, side by side with sdypy-EMA (LSCF + LSFD).

One module per dataset of ``../shared/data`` (see that folder's README for sources and terms),
each with ``load(data_dir)`` (fast: the FRFs the fit uses) and ``run(data_dir, out_dir)`` (the
whole comparison, returning a :class:`benchmarks.accuracy.validation.common.CaseReport`).
``datasets.DATASETS`` lists them all in one table (key, name in the docs, loader, band) for the studies
and tests that go over every dataset.
``python -m benchmarks.accuracy.validation.run_all`` regenerates ``docs/validation.md`` and the plots in
``docs/validation/``. Nothing here is imported by the impactlab packages.
"""
