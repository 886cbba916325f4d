"""Run by ``pvbatch`` (not by pytest): what ParaView's XDMF readers make of the zones sidecar.

    pvbatch pv_zones_probe.py RUN-zones.xdmf OUT.json OUT_DIR [ARRAY]

Opens the zoned blocks' sidecar with the Xdmf3 readers S and T and the legacy XDMF reader and
writes to ``OUT.json``, for each, at the first and last time step: the point and cell counts,
the VTK cell types, bounds, and every point and cell array in full (the test grids are small).
With each reader it renders the last step, cells coloured by ``ARRAY`` (default ``sigma1``),
to ``OUT_DIR/zones-<reader>.png`` and records how much of the image is drawn and coloured.
"""

import json
import sys

from paraview import servermanager as sm
from paraview.simple import (
    ColorBy,
    CreateView,
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
        out[a.GetName()] = {"components": a.GetNumberOfComponents(),
                            "values": vtk_to_numpy(a).tolist()}
    return out


def describe(reader, t: float) -> list[dict]:
    reader.UpdatePipeline(t)
    out = []
    for leaf in leaves(sm.Fetch(reader)):
        n = leaf.GetNumberOfPoints()
        out.append({
            "n_points": n,
            "n_cells": leaf.GetNumberOfCells(),
            "cell_types": sorted({leaf.GetCellType(c) for c in range(leaf.GetNumberOfCells())}),
            "bounds": list(leaf.GetBounds()) if n else None,
            "points": vtk_to_numpy(leaf.GetPoints().GetData()).tolist() if n else [],
            "cell_arrays": arrays(leaf.GetCellData()),
            "point_arrays": arrays(leaf.GetPointData()),
        })
    return out


def render(reader, t: float, png: str, array: str) -> dict:
    view = CreateView("RenderView")
    view.ViewSize = [640, 480]
    view.ViewTime = t
    display = Show(reader, view)
    ColorBy(display, ("CELLS", array))
    display.RescaleTransferFunctionToDataRange(False, True)
    view.CameraPosition = [4.0, -6.0, 3.0]
    view.CameraViewUp = [0.0, 0.0, 1.0]
    ResetCamera(view)
    SaveScreenshot(png, view, ImageResolution=[640, 480])
    img = vtkPNGReader()
    img.SetFileName(png)
    img.Update()
    pixels = vtk_to_numpy(img.GetOutput().GetPointData().GetScalars())[:, :3].astype(int)
    background = pixels[0]
    drawn = abs(pixels - background).sum(axis=1) > 30
    saturated = drawn & (pixels.max(axis=1) - pixels.min(axis=1) > 60)
    return {"png": png, "drawn": float(drawn.mean()), "coloured": float(saturated.mean())}


def main() -> None:
    path, out_json, out_dir = sys.argv[1:4]
    array = sys.argv[4] if len(sys.argv) > 4 else "sigma1"
    result = {}
    for kind in ("S", "T", "legacy"):
        reader = open_reader(kind, path)
        reader.UpdatePipelineInformation()
        times = [float(t) for t in reader.TimestepValues]
        result[kind] = {"times": times, "first": describe(reader, times[0]),
                        "last": describe(reader, times[-1]),
                        "render": render(reader, times[-1], f"{out_dir}/zones-{kind}.png", array)}
    with open(out_json, "w") as f:
        json.dump(result, f)


main()
