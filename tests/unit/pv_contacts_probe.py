"""Run by ``pvbatch`` (not by pytest): what ParaView's XDMF readers make of the contact sidecars.

    pvbatch pv_contacts_probe.py RUN-contacts.xdmf RUN-subcontacts.xdmf OUT.json OUT_DIR [READERS]

For each of the Xdmf3 readers S and T and the legacy XDMF reader (or those of READERS, e.g.
``S,T``): the number of points of both grids at every time step and the contacts' point arrays
(components, range) at the first and the last step;
then, as docs/output.md tells a user to, a Glyph (arrows) on the contacts' ``normal`` coloured
by ``normal_force`` at the first step, rendered to ``OUT_DIR/contacts-<reader>.png``, with the
glyph's point count and how much of the image is coloured.
"""

import json
import sys

from paraview import servermanager as sm
from paraview.simple import (
    ColorBy,
    CreateView,
    Glyph,
    ResetCamera,
    SaveScreenshot,
    Show,
)
from pv_common import leaves, open_reader
from vtkmodules.util.numpy_support import vtk_to_numpy
from vtkmodules.vtkIOImage import vtkPNGReader


def arrays(data) -> dict:
    out = {}
    for i in range(data.GetNumberOfArrays()):
        a = data.GetArray(i)
        comps = a.GetNumberOfComponents()
        out[a.GetName()] = {"components": comps, "range": list(a.GetRange(-1 if comps > 1 else 0))}
    return out


def probe(reader) -> dict:
    reader.UpdatePipelineInformation()
    times = [float(t) for t in reader.TimestepValues]
    points, first, last = [], None, None
    for t in times:
        reader.UpdatePipeline(t)
        ls = leaves(sm.Fetch(reader))
        points.append(sum(x.GetNumberOfPoints() for x in ls))
        if first is None:
            first = arrays(ls[0].GetPointData())
        last = arrays(ls[0].GetPointData())
    return {"times": times, "points": points, "arrays": first, "last": last}


def glyphs(reader, t: float, png: str) -> dict:
    glyph = Glyph(Input=reader, GlyphType="Arrow")
    glyph.OrientationArray = ["POINTS", "normal"]
    glyph.ScaleArray = ["POINTS", "No scale array"]
    glyph.ScaleFactor = 0.5
    glyph.GlyphMode = "All Points"
    glyph.UpdatePipeline(t)
    n = sum(x.GetNumberOfPoints() for x in leaves(sm.Fetch(glyph)))
    view = CreateView("RenderView")
    view.ViewSize = [640, 480]
    view.ViewTime = t
    display = Show(glyph, view)
    ColorBy(display, ("POINTS", "normal_force"))
    display.RescaleTransferFunctionToDataRange(False, True)
    ResetCamera(view)
    SaveScreenshot(png, view, ImageResolution=[640, 480])
    img = vtkPNGReader()
    img.SetFileName(png)
    img.Update()
    pixels = vtk_to_numpy(img.GetOutput().GetPointData().GetScalars())[:, :3].astype(int)
    background = pixels[0]
    drawn = abs(pixels - background).sum(axis=1) > 30
    saturated = drawn & (pixels.max(axis=1) - pixels.min(axis=1) > 60)
    return {"glyph_points": n, "png": png, "drawn": float(drawn.mean()),
            "coloured": float(saturated.mean())}


def main() -> None:
    contacts, subcontacts, out_json, out_dir = sys.argv[1:5]
    kinds = sys.argv[5].split(",") if len(sys.argv) > 5 else ("S", "T", "legacy")
    result = {}
    for kind in kinds:
        reader = open_reader(kind, contacts)
        result[kind] = {"contacts": probe(reader),
                        "subcontacts": probe(open_reader(kind, subcontacts))}
        t = result[kind]["contacts"]["times"][0]
        result[kind].update(glyphs(reader, t, f"{out_dir}/contacts-{kind}.png"))
    with open(out_json, "w") as f:
        json.dump(result, f)


main()
