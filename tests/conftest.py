"""Shared pytest set-up: single-threaded numerics so timings and results are reproducible."""

import os

for var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(var, "1")
