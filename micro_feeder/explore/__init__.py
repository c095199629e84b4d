"""Exploring the model at scale: sweep designs, per-run evaluation, runners (local processes or a Dask
cluster), optimisation and calibration against logs. A library: no argparse here (the ``cli`` modules
parse options and call it).

* :mod:`.designs`: which runs (full grids, Latin-hypercube or random samples, Monte Carlo perturbations).
* :mod:`.evaluate`: one run -> one table row (distance, settled flag, regime, counts).
* :mod:`.runners`: ordered, bounded, interruptible maps over local processes or a Dask scheduler.
* :mod:`.sweep`: a design through a runner into a streamed table, and Monte Carlo summaries.
* :mod:`.optimize`, :mod:`.calibrate`: scipy.optimize over the same evaluation.
"""
