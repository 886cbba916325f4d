"""Render the rock bolts of a run's last snapshot, coloured by their axial force, inside the
translucent blocks around the tunnel: docs/figures/tunnel-bolts.png (docs/reinforcement.md).

A documentation tool run by ParaView's ``pvbatch`` (run/setup installs it), not by pdem's Python:

    .venv/bin/mpiexec -n 2 .venv/bin/pdem run configs/tunnel-bolted.yaml      # in /tmp: ~2 min
    xvfb-run -a pvbatch docs/make_reinforcement_screenshot.py /tmp/tunnel-bolted.xdmf

It opens ``tunnel-bolted.xdmf`` and ``tunnel-bolted-reinforcement.xdmf`` with the Xdmf3 Reader
T, as a user would; the blocks shown are those within ``REACH`` m of the tunnel's axis.
"""

import os
import sys

from paraview.simple import (
    Clip,
    ColorBy,
    CreateView,
    ExtractSurface,
    GetColorTransferFunction,
    GetScalarBar,
    ResetCamera,
    SaveScreenshot,
    Show,
    Tube,
    Xdmf3ReaderT,
)

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "figures", "tunnel-bolts.png")
AXIS = (15.0, 13.0)  # x, z of the tunnel's axis (along y)
REACH = 8.0


def main(xdmf: str, out: str = OUT) -> None:
    xdmf = os.path.abspath(xdmf)
    bolts = Xdmf3ReaderT(FileName=[xdmf[:-len(".xdmf")] + "-reinforcement.xdmf"])
    bolts.UpdatePipelineInformation()
    t = bolts.TimestepValues[-1]
    view = CreateView("RenderView")
    view.ViewSize = [1000, 800]
    view.ViewTime = t
    blocks = Xdmf3ReaderT(FileName=[xdmf])
    near = Clip(Input=blocks, ClipType="Sphere")  # the rock round the crown
    near.ClipType.Center = [AXIS[0], 5.0, AXIS[1] + 2.0]
    near.ClipType.Radius = REACH
    near.Invert = 1
    half = Clip(Input=near, ClipType="Plane")  # the near half (y < 5) cut away: the bolts show
    half.ClipType.Origin = [AXIS[0], 5.0, AXIS[1]]
    half.ClipType.Normal = [0.0, 1.0, 0.0]
    display = Show(half, view)
    display.Opacity = 0.35
    ColorBy(display, None)
    tubes = Tube(Input=ExtractSurface(Input=bolts))  # (the polylines as polydata)
    tubes.Radius = 0.06
    shown = Show(tubes, view)
    ColorBy(shown, ("CELLS", "axial"))
    shown.RescaleTransferFunctionToDataRange(False, True)
    shown.SetScalarBarVisibility(view, True)
    bar = GetScalarBar(GetColorTransferFunction("axial"), view)
    bar.Title = "bolt axial force (N, tension +)"
    bar.ComponentTitle = ""
    view.OrientationAxesVisibility = 1
    view.CameraPosition = [AXIS[0] + 6.0, -14.0, AXIS[1] + 7.0]
    view.CameraFocalPoint = [AXIS[0], 5.0, AXIS[1] + 2.0]
    view.CameraViewUp = [0.0, 0.0, 1.0]
    ResetCamera(view)
    SaveScreenshot(out, view, ImageResolution=[1000, 800])
    print(f"wrote {out}")


main(*sys.argv[1:3])
