"""pdem.io: run output (HDF5 + XDMF sidecar) and its summary."""

from .info import summarise
from .writer import FORMAT_VERSION, OutputWriter, quat_to_matrix
from .xdmf import read_xdmf, write_xdmf

__all__ = [
    "FORMAT_VERSION",
    "OutputWriter",
    "quat_to_matrix",
    "read_xdmf",
    "summarise",
    "write_xdmf",
]
