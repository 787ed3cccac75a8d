"""Parameter sweeps and Monte Carlo studies over a scenario (``eha-hil sweep``).

A sweep is a list of points; each point is a scenario run on the base configuration with a
few keys overridden (grid values, a noise seed, values drawn within a tolerance). A point is
a pure function of its configuration: :func:`hil.sweep.point.evaluate` runs it anywhere
(in-process, a local process pool, a Dask worker) and returns a plain record, so the table
does not depend on the backend, the number of workers or the order points finish in.

* :mod:`hil.sweep.space` — ``--param``/``--tolerance``/``--seeds`` -> the points (a plan);
* :mod:`hil.sweep.point` — one point: configuration -> scenario -> record;
* :mod:`hil.sweep.backends` — where points run: serial, local pool, Dask;
* :mod:`hil.sweep.journal` — finished points on disk, for ``--resume``;
* :mod:`hil.sweep.engine` — runs a plan on a backend, journal and progress;
* :mod:`hil.sweep.requirements` — ``--require``: the user's bound on a metric;
* :mod:`hil.sweep.table`, :mod:`hil.sweep.summary`, :mod:`hil.sweep.plots` — the results;
* :mod:`hil.bench.sweep` — the local pool against a serial sweep (``bench sweep``);
* :mod:`hil.cli.sweep` — the ``sweep`` and ``bench sweep`` verbs.
"""
