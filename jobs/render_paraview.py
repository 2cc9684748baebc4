"""Render the XDMF files of `contactgrid detect --xdmf` (or `generate --xdmf`) to a PNG with ParaView.

    pvpython jobs/render_paraview.py BASE OUT.png [--width 1600 --height 1000] [--clip F]

BASE is the output path without .h5 (detect wrote BASE.spheres.xmf, BASE.ellipsoids.xmf, BASE.xmf).
Spheres become sphere glyphs scaled by radius (factor 2: the glyph's unit is a diameter), ellipsoids
sphere tensor glyphs of their shape tensor R·diag(a, b, c)·Rᵀ, contacts small arrows along normal_on_b
coloured by distance. --clip F keeps the bodies whose x lies in the lowest fraction F of the box, so
that the contacts inside a dense scene show. Needs Debian's `paraview` and `python3-paraview`; without
a display, an X server of its own (`Xvfb :7 -screen 0 1920x1200x24 &`, then `DISPLAY=:7`).
"""
import argparse
import os

from paraview import simple as pv


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("base")
    ap.add_argument("png")
    ap.add_argument("--width", type=int, default=1600)
    ap.add_argument("--height", type=int, default=1000)
    ap.add_argument("--clip", type=float, default=1.0, help="keep the lowest fraction of x")
    args = ap.parse_args()
    args.base = os.path.abspath(args.base)  # the XDMF reader resolves its HDF5 paths from an absolute one

    view = pv.CreateView("RenderView")
    view.ViewSize = [args.width, args.height]
    if hasattr(view, "UseColorPaletteForBackground"):
        view.UseColorPaletteForBackground = 0
    view.Background = [1.0, 1.0, 1.0]
    view.OrientationAxesVisibility = 0
    bounds = None

    def clipped(source):
        if args.clip >= 1.0:
            return source
        source.UpdatePipeline()
        b = source.GetDataInformation().GetBounds()
        clip = pv.Clip(Input=source, ClipType="Plane")
        clip.ClipType.Origin = [b[0] + args.clip * (b[1] - b[0]), 0, 0]
        clip.ClipType.Normal = [1, 0, 0]
        clip.Invert = 1
        return clip

    spheres_file = args.base + ".spheres.xmf"
    if os.path.exists(spheres_file):
        spheres = clipped(pv.Xdmf3ReaderS(FileName=[spheres_file]))
        glyph = pv.Glyph(Input=spheres, GlyphType="Sphere")
        glyph.ScaleArray = ["POINTS", "radius"]
        glyph.ScaleFactor = 2.0
        glyph.GlyphMode = "All Points"
        glyph.GlyphType.ThetaResolution = 16
        glyph.GlyphType.PhiResolution = 12
        shown = pv.Show(glyph, view)
        pv.ColorBy(shown, ("POINTS", "radius"))
        shown.LookupTable = pv.GetColorTransferFunction("radius")
        shown.LookupTable.ApplyPreset("Cool to Warm", True)
        shown.Opacity = 0.35
        spheres.UpdatePipeline()
        bounds = spheres.GetDataInformation().GetBounds()

    ellipsoids_file = args.base + ".ellipsoids.xmf"
    if os.path.exists(ellipsoids_file):
        ellipsoids = clipped(pv.Xdmf3ReaderS(FileName=[ellipsoids_file]))
        glyph = pv.TensorGlyph(Input=ellipsoids, GlyphType="Sphere")
        glyph.Tensors = ["POINTS", "shape"]
        glyph.ScaleFactor = 2.0
        glyph.ExtractEigenvalues = 1
        shown = pv.Show(glyph, view)
        shown.DiffuseColor = [0.35, 0.55, 0.8]
        shown.Opacity = 0.35
        ellipsoids.UpdatePipeline()
        bounds = bounds or ellipsoids.GetDataInformation().GetBounds()

    contacts_file = args.base + ".xmf"
    if os.path.exists(contacts_file):
        contacts = clipped(pv.Xdmf3ReaderS(FileName=[contacts_file]))
        arrows = pv.Glyph(Input=contacts, GlyphType="Arrow")
        arrows.OrientationArray = ["POINTS", "normal_on_b"]
        arrows.ScaleArray = ["POINTS", "No scale array"]
        arrows.GlyphMode = "All Points"
        if bounds:
            arrows.ScaleFactor = 0.1 * (bounds[1] - bounds[0])
        shown = pv.Show(arrows, view)
        pv.ColorBy(shown, ("POINTS", "distance"))
        shown.LookupTable = pv.GetColorTransferFunction("distance")
        shown.LookupTable.ApplyPreset("Inferno (matplotlib)", True)

    view.CameraPosition = [1.6, -0.9, 0.8]  # toward the cut face of --clip
    view.CameraFocalPoint = [0.0, 0.0, 0.0]
    view.CameraViewUp = [0.0, 0.0, 1.0]
    view.ResetCamera()
    pv.Render(view)
    pv.SaveScreenshot(args.png, view, ImageResolution=[args.width, args.height])
    print(f"render_paraview: {args.png} ({args.width}x{args.height})")


if __name__ == "__main__":
    main()
