"""pdem: parallel distinct element method for 3D polyhedral blocks.

The Python API (docs/python-api.md): ``pdem.Scene``, ``pdem.run``, ``pdem.open`` and
``pdem.run_study``. They load numba, h5py and MPI when first used, so ``import pdem`` (and
``pdem --help``) stays light.
"""

__version__ = "0.1.0"

# name -> the module that defines it, imported on first use (PEP 562)
_API = {"Scene": "pdem.api", "run": "pdem.api", "open": "pdem.api", "Results": "pdem.io.results",
        "run_study": "pdem.study.runner", "open_study": "pdem.io.study_table"}

__all__ = ["__version__", *_API]


def __getattr__(name: str):
    if name in _API:
        import importlib

        return getattr(importlib.import_module(_API[name]), name)
    raise AttributeError(f"module 'pdem' has no attribute {name!r}")
