"""Render the default scene's last snapshot, blocks coloured by displacement, with ParaView:
docs/figures/default-displacement.png (the screenshot of README.md and docs/output.md).

A documentation tool run by ParaView's ``pvbatch`` (Debian: ``apt-get install paraview
python3-paraview xvfb``; run/setup installs them), not by pdem's Python:

    .venv/bin/mpiexec -n 2 .venv/bin/pdem run configs/default.yaml -o /tmp/pile.h5    # ~1 min
    xvfb-run -a pvbatch docs/make_screenshot.py /tmp/pile.xdmf
    xvfb-run -a pvbatch docs/make_screenshot.py /tmp/slope.xdmf docs/figures/slope.png
    xvfb-run -a pvbatch docs/make_screenshot.py /tmp/slope.xdmf docs/figures/slope-safety.png \
        block_safety

With an output path, the camera looks from the south-east and above, fitted to the model
(configs/slope.yaml, configs/tunnel.yaml).

It opens the sidecar with the Xdmf3 Reader T, as a user would (docs/output.md), so the picture
is also a check that the file reads right.
"""

import os
import sys

from paraview.simple import (
    ColorBy,
    CreateView,
    GetColorTransferFunction,
    GetScalarBar,
    SaveScreenshot,
    Show,
    Threshold,
    Xdmf3ReaderT,
)

OUT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "figures", "default-displacement.png")


def main(xdmf: str, out: str | None = None, field: str = "displacement_magnitude") -> None:
    reader = Xdmf3ReaderT(FileName=[os.path.abspath(xdmf)])
    reader.UpdatePipelineInformation()
    t = reader.TimestepValues[-1]
    view = CreateView("RenderView")
    view.ViewSize = [1200, 800]
    view.ViewTime = t
    view.OrientationAxesVisibility = 0
    view.Background = [1.0, 1.0, 1.0]
    view.UseColorPaletteForBackground = 0
    # moving blocks coloured, fixed ones (floor, walls) faint so they do not hide the pile
    # blocks taken out of the model (excavated, left the domain) keep their last pose: hidden
    present = Threshold(Input=reader, Scalars=["CELLS", "removed"], LowerThreshold=0,
                        UpperThreshold=0)
    moving = Threshold(Input=present, Scalars=["CELLS", "fixed"], LowerThreshold=0, UpperThreshold=0)
    fixed = Threshold(Input=reader, Scalars=["CELLS", "fixed"], LowerThreshold=1, UpperThreshold=1)
    box = Show(fixed, view)
    ColorBy(box, None)
    box.AmbientColor = box.DiffuseColor = [0.75, 0.75, 0.75]
    box.Opacity = 0.25
    display = Show(moving, view)
    ColorBy(display, ("CELLS", field))
    display.RescaleTransferFunctionToDataRange(False, True)
    lut = GetColorTransferFunction(field)
    lut.ApplyPreset("Viridis (matplotlib)", True)
    display.SetScalarBarVisibility(view, True)
    bar = GetScalarBar(lut, view)
    bar.Title = {"displacement_magnitude": "displacement (m)",
                 "block_safety": "largest stable F"}.get(field, field)
    bar.ComponentTitle = ""
    bar.TitleColor = bar.LabelColor = [0.1, 0.1, 0.1]
    bar.TitleFontSize = bar.LabelFontSize = 20
    view.CameraViewUp = [0.0, 0.0, 1.0]
    view.CameraViewAngle = 30
    if out is None:
        # oblique view from above one corner of the box, so the pile and the walls both show
        view.CameraPosition = [8.0, -11.0, 13.0]
        view.CameraFocalPoint = [0.0, 0.0, 0.6]
    else:
        view.CameraPosition = [1.0, -1.2, 0.8]
        view.CameraFocalPoint = [0.0, 0.0, 0.0]
        view.ResetCamera()
    out = out or OUT
    SaveScreenshot(out, view, ImageResolution=[1200, 800])
    print(f"t = {t:.3g} s -> {out}")


if __name__ == "__main__":
    if len(sys.argv) not in (2, 3, 4):
        sys.exit(__doc__)
    main(*sys.argv[1:])
