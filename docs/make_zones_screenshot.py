"""Render the zoned blocks of a run's last snapshot, cut open and coloured by the vertical zone
stress, inside the translucent rigid blocks: docs/figures/pillar-stress.png (docs/output.md,
docs/deformable.md).

A documentation tool run by ParaView's ``pvbatch`` (run/setup installs it), not by pdem's Python:

    .venv/bin/pdem run configs/pillar.yaml --steps 8000 -o /tmp/pillar.h5     # ~35 s warm
    xvfb-run -a pvbatch docs/make_zones_screenshot.py /tmp/pillar.xdmf

It opens ``pillar.xdmf`` and ``pillar-zones.xdmf`` with the Xdmf3 Reader T, as a user would.
The rigid surfaces of the zoned blocks (``run.xdmf`` has them too) are left out: the blocks
named by the zones' ``block_id``.
"""

import os
import sys

import numpy as np
from paraview import servermanager as sm
from paraview.simple import (
    Clip,
    ColorBy,
    CreateView,
    GetColorTransferFunction,
    GetScalarBar,
    MergeBlocks,
    ResetCamera,
    SaveScreenshot,
    Show,
    Threshold,
    Xdmf3ReaderT,
)
from vtkmodules.util.numpy_support import vtk_to_numpy

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "figures", "pillar-stress.png")


def main(xdmf: str, out: str = OUT) -> None:
    xdmf = os.path.abspath(xdmf)
    zones = Xdmf3ReaderT(FileName=[xdmf[:-len(".xdmf")] + "-zones.xdmf"])
    zones.UpdatePipelineInformation()
    t = zones.TimestepValues[-1]
    zoned = MergeBlocks(Input=zones)
    zoned.UpdatePipeline(t)
    gids = np.unique(vtk_to_numpy(sm.Fetch(zoned).GetCellData().GetArray("block_id")))
    view = CreateView("RenderView")
    view.ViewSize = [900, 900]
    view.ViewTime = t
    surface = Xdmf3ReaderT(FileName=[xdmf])
    # the rigid blocks: the gid ranges between the zoned blocks
    edges = [-1, *gids.tolist(), 1 << 40]
    for lo, hi in zip(edges[:-1], edges[1:], strict=True):
        if hi - lo < 2:
            continue
        rigid = Threshold(Input=surface, Scalars=["CELLS", "block_id"])
        rigid.LowerThreshold, rigid.UpperThreshold = lo + 1, hi - 1
        display = Show(rigid, view)
        display.Opacity = 0.25
        ColorBy(display, None)
    cut = Clip(Input=zones, ClipType="Plane")  # the half y > centre, whole zones
    cut.ClipType.Normal = [0.0, 1.0, 0.0]
    cut.Crinkleclip = 1
    display = Show(cut, view)
    display.Representation = "Surface With Edges"
    ColorBy(display, ("CELLS", "stress", "ZZ"))
    lut = GetColorTransferFunction("stress")
    lut.VectorMode = "Component"
    lut.VectorComponent = 2
    display.RescaleTransferFunctionToDataRange(False, True)
    display.SetScalarBarVisibility(view, True)
    bar = GetScalarBar(lut, view)
    bar.Title = "zone stress zz (Pa, tension +)"
    bar.ComponentTitle = ""
    view.OrientationAxesVisibility = 1
    view.CameraPosition = [5.0, -7.0, 3.5]
    view.CameraViewUp = [0.0, 0.0, 1.0]
    ResetCamera(view)
    SaveScreenshot(out, view, ImageResolution=[900, 900])
    print(f"wrote {out}")


main(*sys.argv[1:3])
