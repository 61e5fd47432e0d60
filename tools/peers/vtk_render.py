#!/usr/bin/env python3
"""VTK's CPU ray caster (vtkFixedPointVolumeRayCastMapper) on a cdvol raw
sidecar, offscreen through EGL. Run with the venv's python (tools/peers/install.sh).

Prints one JSON line: load_s (raw -> vtkImageData), first_s (first Render(),
which includes the mapper's one-time setup), render_s (each further Render()
of the same view, data already in memory), and the image written.

usage: vtk_render.py SIDECAR MODE(composite|mip) OUT.png --eye X,Y,Z --target X,Y,Z
       --up X,Y,Z --frame MM [--tf TF.json] [--step MM] [--iso T] [--size N]
       [--threads N] [--renders K] [--shade]
"""
import argparse, json, os, sys, time

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
os.environ.pop("DISPLAY", None)

import numpy as np
import vtk
from vtk.util import numpy_support

import sidecar

ap = argparse.ArgumentParser()
ap.add_argument("sidecar")
ap.add_argument("mode", choices=["composite", "mip"])
ap.add_argument("out")
vec = lambda s: [float(x) for x in s.split(",")]
ap.add_argument("--eye", type=vec, required=True)
ap.add_argument("--target", type=vec, required=True)
ap.add_argument("--up", type=vec, required=True)
ap.add_argument("--frame", type=float, required=True)
ap.add_argument("--tf")
ap.add_argument("--step", type=float, default=0.5)
ap.add_argument("--iso", type=float, default=300.0)
ap.add_argument("--size", type=int, default=512)
ap.add_argument("--threads", type=int, default=1)
ap.add_argument("--renders", type=int, default=3)
ap.add_argument("--shade", action="store_true",
                help="composite: ShadeOn with cdvol's light (headlight; ambient 0.12, "
                     "diffuse 0.75, specular 0.25, power 32)")
a = ap.parse_args()

vtk.vtkMultiThreader.SetGlobalMaximumNumberOfThreads(a.threads)
vtk.vtkMultiThreader.SetGlobalDefaultNumberOfThreads(a.threads)
vtk.vtkSMPTools.Initialize(a.threads)

# --- load: raw -> vtkImageData (sample (i,j,k) at origin + (i*sx, j*sy, k*sz) mm)
t0 = time.perf_counter()
meta, arr = sidecar.read(a.sidecar)
nx, ny, nz = meta["dims"]
img = vtk.vtkImageData()
img.SetDimensions(nx, ny, nz)
img.SetSpacing(meta["x"], meta["y"], meta["z"])
img.SetOrigin(*meta.get("origin", [0, 0, 0]))
img.GetPointData().SetScalars(numpy_support.numpy_to_vtk(arr, deep=1))  # x fastest, like the raw
load_s = time.perf_counter() - t0
lo, hi = float(arr.min()), float(arr.max())

# --- transfer functions
col = vtk.vtkColorTransferFunction()
op = vtk.vtkPiecewiseFunction()
prop = vtk.vtkVolumeProperty()
prop.SetInterpolationTypeToLinear()
if a.shade:
    # cdvol render --shade: its surface light, a headlight, two-sided (the
    # renderer's default). The light is added below, with a white ambient
    # colour: VTK's shading table scales Ambient by the light's ambient
    # colour, which is black by default, so with the renderer's automatic
    # light SetAmbient had no effect (docs/peers/PEERS.md, "What is
    # compared", shaded composite).
    prop.ShadeOn()
    prop.SetAmbient(0.12)
    prop.SetDiffuse(0.75)
    prop.SetSpecular(0.25)
    prop.SetSpecularPower(32.0)
else:
    prop.ShadeOff()
if a.mode == "composite":
    pts = json.load(open(a.tf))["points"]
    for p in pts:
        col.AddRGBPoint(p["value"], *p["color"])
        op.AddPoint(p["value"], p["opacity"])  # clamped beyond the ends, like cdvol
    prop.SetScalarOpacityUnitDistance(1.0)  # opacity per mm, like cdvol
else:
    # cdvol's MIP of an --iso T file: rays that meet no value >= T are black;
    # the maximum maps linearly from the volume's [min, max] to black..white.
    col.AddRGBPoint(lo, 0, 0, 0)
    col.AddRGBPoint(a.iso - 1e-3, 0, 0, 0)
    g = (a.iso - lo) / (hi - lo)
    col.AddRGBPoint(a.iso, g, g, g)
    col.AddRGBPoint(hi, 1, 1, 1)
    op.AddPoint(lo, 1.0)
    op.AddPoint(hi, 1.0)
prop.SetColor(col)
prop.SetScalarOpacity(op)

mapper = vtk.vtkFixedPointVolumeRayCastMapper()
mapper.SetInputData(img)
mapper.SetNumberOfThreads(a.threads)
mapper.SetAutoAdjustSampleDistances(0)
mapper.SetLockSampleDistanceToInputSpacing(0)
mapper.SetSampleDistance(a.step)
mapper.SetImageSampleDistance(1.0)
if a.mode == "mip":
    mapper.SetBlendModeToMaximumIntensity()
else:
    mapper.SetBlendModeToComposite()
vol = vtk.vtkVolume()
vol.SetMapper(mapper)
vol.SetProperty(prop)

ren = vtk.vtkRenderer()
ren.SetBackground(0, 0, 0)
ren.AddVolume(vol)
if a.shade:
    light = vtk.vtkLight()
    light.SetLightTypeToHeadlight()
    light.SetAmbientColor(1.0, 1.0, 1.0)  # diffuse and specular colours: white by default
    ren.AddLight(light)  # a renderer with a light creates none of its own
win = vtk.vtkRenderWindow()
win.SetOffScreenRendering(1)
win.SetSize(a.size, a.size)
win.AddRenderer(ren)
cam = ren.GetActiveCamera()
cam.ParallelProjectionOn()
cam.SetParallelScale(a.frame / 2)  # half the frame height, in mm
cam.SetPosition(*a.eye)
cam.SetFocalPoint(*a.target)
cam.SetViewUp(*a.up)
ren.ResetCameraClippingRange()

t0 = time.perf_counter()
win.Render()
first_s = time.perf_counter() - t0
renders = []
for _ in range(a.renders):
    cam.Modified()
    t0 = time.perf_counter()
    win.Render()
    renders.append(time.perf_counter() - t0)

w2i = vtk.vtkWindowToImageFilter()
w2i.SetInput(win)
w2i.ReadFrontBufferOff()
w2i.Update()
png = vtk.vtkPNGWriter()
png.SetFileName(a.out)
png.SetInputConnection(w2i.GetOutputPort())
png.Write()
print(json.dumps({"load_s": load_s, "first_s": first_s, "render_s": renders,
                  "threads": mapper.GetNumberOfThreads(), "vtk": vtk.vtkVersion.GetVTKVersion(),
                  "out": a.out}))
