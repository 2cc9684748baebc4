"""Render a state of a `contactgrid simulate` run directory to a PNG with ParaView, from its run.xdmf.

    pvpython jobs/render_run.py RUN OUT.png [--time last|T] [--width 1200 --height 900] [--walls SPEC]

The XDMF time series (docs/FORMAT.md §6) is read at the last time (or T); spheres and ellipsoids become
one tensor glyph each: a sphere of the shape tensor R·diag(a, b, c)·Rᵀ (spheres: r·I), so ellipsoids
show their orientation and semi-axes. Coloured by speed. --walls draws the run's cylinder
(`cylinder:CX,CY,R` or `hopper:CX,CY,R,Z,H`: its plate with the hole) translucent; with a hopper, the
bodies that fell through are shown down to two cylinder radii below the plate.
Needs Debian's `paraview` and `python3-paraview`; without a display an X server of its own
(`Xvfb :7 -screen 0 1920x1200x24 &`, then `DISPLAY=:7 pvpython ...`). The plain projection without
ParaView is the run's own final.png (contactgrid simulate, gnuplot).
"""
import argparse
import builtins
import os

from paraview import simple as pv

SHAPE_TENSOR = r"""
import numpy as np
from vtk.numpy_interface import dataset_adapter as dsa
from vtkmodules.vtkCommonDataModel import vtkMultiBlockDataSet
inp = self.GetInputDataObject(0, 0)
blocks = []
it = inp.NewIterator() if isinstance(inp, vtkMultiBlockDataSet) else None
if it is None:
    blocks = [inp]
else:
    it.InitTraversal()
    while not it.IsDoneWithTraversal():
        blocks.append(it.GetCurrentDataObject())
        it.GoToNextItem()
pts, tensors, speed = [], [], []
for b in blocks:
    d = dsa.WrapDataObject(b)
    if d.GetNumberOfPoints() == 0:
        continue
    p = np.asarray(d.Points)
    v = np.asarray(d.PointData["velocity"])
    if "radius" in d.PointData.keys():
        r = np.asarray(d.PointData["radius"])
        t = np.zeros((len(p), 3, 3))
        for k in range(3):
            t[:, k, k] = r
    else:
        a = np.asarray(d.PointData["semi_axes"])
        q = np.asarray(d.PointData["orientation"]).reshape(len(p), 4)
        w, x, y, z = q[:, 0], q[:, 1], q[:, 2], q[:, 3]
        rot = np.stack([
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1)], 1)
        t = np.einsum("nij,nj,nkj->nik", rot, a, rot)
    keep = p[:, 2] >= ZMIN
    pts.append(p[keep])
    tensors.append(t.reshape(len(p), 9)[keep])
    speed.append(np.linalg.norm(v, axis=1)[keep])
out = self.GetPolyDataOutput()
from vtkmodules.vtkCommonCore import vtkPoints
from vtkmodules.vtkCommonDataModel import vtkCellArray
from vtkmodules.util.numpy_support import numpy_to_vtk
P = np.concatenate(pts) if pts else np.zeros((0, 3))
vp = vtkPoints()
vp.SetData(numpy_to_vtk(np.ascontiguousarray(P), deep=1))
out.SetPoints(vp)
T = numpy_to_vtk(np.ascontiguousarray(np.concatenate(tensors) if tensors else np.zeros((0, 9))), deep=1)
T.SetName("shape")
out.GetPointData().SetTensors(T)
S = numpy_to_vtk(np.ascontiguousarray(np.concatenate(speed) if speed else np.zeros(0)), deep=1)
S.SetName("speed")
out.GetPointData().AddArray(S)
"""


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("run")
    ap.add_argument("png")
    ap.add_argument("--time", default="last")
    ap.add_argument("--width", type=int, default=1200)
    ap.add_argument("--height", type=int, default=900)
    ap.add_argument("--walls", default="")
    args = ap.parse_args()
    xdmf = os.path.join(os.path.abspath(args.run), "run.xdmf")  # absolute: the reader resolves the frames from it

    reader = pv.Xdmf3ReaderT(FileName=[xdmf])
    reader.UpdatePipelineInformation()
    times = list(reader.TimestepValues) if reader.TimestepValues else [0.0]
    t = times[-1] if args.time == "last" else float(args.time)
    view = pv.CreateView("RenderView")
    view.ViewSize = [args.width, args.height]
    if hasattr(view, "UseColorPaletteForBackground"):
        view.UseColorPaletteForBackground = 0
    view.Background = [1.0, 1.0, 1.0]
    view.OrientationAxesVisibility = 0
    view.ViewTime = t

    bodies = pv.ProgrammableFilter(Input=reader)
    bodies.OutputDataSetType = "vtkPolyData"
    zmin = -1e300
    if args.walls.startswith("hopper:"):  # the bodies that fell through, down to a cylinder's width
        w = [float(x) for x in args.walls.split(":")[1].split(",")]
        zmin = w[3] - 2 * w[2]
    bodies.Script = f"ZMIN = {zmin!r}\n" + SHAPE_TENSOR
    bodies.UpdatePipeline(t)
    glyph = pv.TensorGlyph(Input=bodies, GlyphType="Sphere")
    glyph.Tensors = ["POINTS", "shape"]
    glyph.ScaleFactor = 2.0  # the sphere glyph's radius is 0.5
    glyph.ExtractEigenvalues = 0
    glyph.GlyphType.ThetaResolution = 16
    glyph.GlyphType.PhiResolution = 12
    shown = pv.Show(glyph, view)
    pv.ColorBy(shown, ("POINTS", "speed"))
    lut = pv.GetColorTransferFunction("speed")
    lut.ApplyPreset("Viridis (matplotlib)", True)
    shown.SetScalarBarVisibility(view, True)
    bar = pv.GetScalarBar(lut, view)
    bar.Title = "speed"
    bar.ComponentTitle = ""
    bar.TitleColor = [0.1, 0.1, 0.1]
    bar.LabelColor = [0.1, 0.1, 0.1]

    if args.walls:
        kind, _, numbers = args.walls.partition(":")
        v = [float(x) for x in numbers.split(",")]
        if kind in ("cylinder", "hopper"):
            b = bodies.GetDataInformation().GetBounds()
            lo = v[3] if kind == "hopper" else b[4]
            height = builtins.max(b[5], lo) - lo + 0.4 * v[2]
            cyl = pv.Cylinder(Radius=v[2], Height=height, Resolution=64, Capping=0)
            tr = pv.Transform(Input=cyl)
            tr.Transform.Rotate = [90, 0, 0]  # the source's axis is y
            tr.Transform.Translate = [v[0], v[1], lo + 0.5 * height]
            wall = pv.Show(tr, view)
            wall.DiffuseColor = [0.6, 0.6, 0.6]
            wall.Opacity = 0.15
            if kind == "hopper":
                plate = pv.Disk(InnerRadius=v[4], OuterRadius=v[2], CircumferentialResolution=64)
                pt = pv.Transform(Input=plate)
                pt.Transform.Translate = [v[0], v[1], v[3]]
                shown_plate = pv.Show(pt, view)
                shown_plate.DiffuseColor = [0.4, 0.4, 0.4]
                shown_plate.Opacity = 0.5

    view.CameraPosition = [1.0, -1.6, 0.5]
    view.CameraFocalPoint = [0.0, 0.0, 0.0]
    view.CameraViewUp = [0.0, 0.0, 1.0]
    view.ResetCamera()
    pv.Render(view)
    pv.SaveScreenshot(args.png, view, ImageResolution=[args.width, args.height])
    print(f"render_run: {args.png} ({args.width}x{args.height}, t = {t:.4g} s of {len(times)} frames)")


if __name__ == "__main__":
    main()
