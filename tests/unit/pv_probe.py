"""Run by ``pvbatch`` (not by pytest): what ParaView's XDMF readers make of pdem's sidecars.

    pvbatch pv_probe.py RUN.xdmf RUN-centroids.xdmf OUT.json OUT_DIR

Opens both sidecars with the Xdmf3 readers S and T and the legacy XDMF reader and writes to
``OUT.json``, for each, at the first and last time step, every leaf dataset's point and cell
counts, bounds and arrays (components and range), and the leaves' bounds at every step. With
each reader it also renders the surfaces' last step, cells coloured by ``displacement_magnitude``,
to ``OUT_DIR/<reader>.png`` and records how much of the image is not background and how much
is coloured (saturated).
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
        comps = a.GetNumberOfComponents()
        # component -1: the magnitude of a vector, the value of a scalar
        out[a.GetName()] = {"components": comps, "range": list(a.GetRange(-1 if comps > 1 else 0))}
    return out


def describe(reader, t: float) -> list[dict]:
    reader.UpdatePipeline(t)
    out = []
    for leaf in leaves(sm.Fetch(reader)):
        n = leaf.GetNumberOfPoints()
        out.append({
            "n_points": n,
            "n_cells": leaf.GetNumberOfCells(),
            "bounds": list(leaf.GetBounds()) if n else None,
            "cell_arrays": arrays(leaf.GetCellData()),
            "point_arrays": arrays(leaf.GetPointData()),
        })
    return out


def render(reader, t: float, png: str) -> dict:
    """Save the view at time ``t``; the fractions of pixels not background, and saturated."""
    view = CreateView("RenderView")
    view.ViewSize = [640, 480]
    view.ViewTime = t
    display = Show(reader, view)
    ColorBy(display, ("CELLS", "displacement_magnitude"))
    display.RescaleTransferFunctionToDataRange(False, True)
    ResetCamera(view)
    SaveScreenshot(png, view, ImageResolution=[640, 480])
    img = vtkPNGReader()
    img.SetFileName(png)
    img.Update()
    pixels = vtk_to_numpy(img.GetOutput().GetPointData().GetScalars())[:, :3].astype(int)
    background = pixels[0]  # a corner: the camera is reset to fit the scene
    drawn = abs(pixels - background).sum(axis=1) > 30
    # grey (uncoloured) surfaces and the blue-grey background have max - min channel < 40
    saturated = drawn & (pixels.max(axis=1) - pixels.min(axis=1) > 60)
    return {"png": png, "drawn": float(drawn.mean()), "coloured": float(saturated.mean())}


def probe(reader) -> dict:
    reader.UpdatePipelineInformation()
    times = [float(t) for t in reader.TimestepValues]
    return {
        "times": times,
        "first": describe(reader, times[0]),
        "last": describe(reader, times[-1]),
        "bounds": [[x["bounds"] for x in describe(reader, t)] for t in times],
    }


def main() -> None:
    surface, centroids, out_json, out_dir = sys.argv[1:5]
    result = {}
    for kind in ("S", "T", "legacy"):
        reader = open_reader(kind, surface)
        result[kind] = {"surface": probe(reader), "centroids": probe(open_reader(kind, centroids))}
        t = result[kind]["surface"]["times"][-1]
        result[kind]["render"] = render(reader, t, f"{out_dir}/{kind}.png")
    with open(out_json, "w") as f:
        json.dump(result, f)


main()
