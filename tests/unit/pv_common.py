"""What the ParaView probes (``pv_*probe.py``, run by pvbatch from this directory) share:
opening an XDMF file with each of ParaView's readers and walking a composite dataset."""

from paraview.simple import Xdmf3ReaderS, Xdmf3ReaderT, XDMFReader


def open_reader(kind: str, path: str):
    """The file in ParaView's Xdmf3 reader S, T or the legacy XDMF reader (``kind``)."""
    if kind == "S":
        return Xdmf3ReaderS(FileName=[path])
    if kind == "T":
        return Xdmf3ReaderT(FileName=[path])
    return XDMFReader(FileNames=[path])


def leaves(data) -> list:
    """The non-composite datasets of ``data``, depth first."""
    if not data.IsA("vtkCompositeDataSet"):
        return [data]
    found = []
    it = data.NewIterator()
    it.InitTraversal()
    while not it.IsDoneWithTraversal():
        found.append(it.GetCurrentDataObject())
        it.GoToNextItem()
    return found
