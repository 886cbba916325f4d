"""pdem.io: run output (HDF5 + XDMF sidecars) and its summary."""

from .info import summarise
from .writer import FORMAT_VERSION, OutputWriter, quat_to_matrix
from .xdmf import centroids_path, contacts_path, read_xdmf, subcontacts_path, write_xdmf, zones_path

__all__ = [
    "FORMAT_VERSION",
    "centroids_path",
    "contacts_path",
    "OutputWriter",
    "quat_to_matrix",
    "read_xdmf",
    "subcontacts_path",
    "summarise",
    "write_xdmf",
    "zones_path",
]
