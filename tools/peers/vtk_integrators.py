#!/usr/bin/env python3
"""VTK's fixed-point ray caster through the integrators' accuracy harness
(issue 54; docs/TRADEOFFS.md, "Integrators"). Run with the peers venv's
python (tools/peers/install.sh); tools/integrators.sh runs it when that
venv exists.

Reads the references examples/integrators.rs exported
(INTEGRATORS_EXPORT=DIR: NN-V.f32 and NN-V.json per composite case and
view), renders each view with vtkFixedPointVolumeRayCastMapper at steps of
1, 0.5 and 0.25 mm from the raw volume the packed file was prepared from,
with the same camera and transfer function (opacity per mm, as
tools/peers/vtk_render.py sets it up, shading with cdvol's headlight), and
measures it as the harness measures cdvol's integrators: over the pixels
either image covers (VTK's image has no coverage channel: its non-black
pixels), |difference| in grey levels (the largest channel; VTK's are
rounded to 8 bits, the reference's are not), mean, RMSE, p99 and max. Cases with gradient opacity are left out (VTK's
gradient opacity takes gradients in its own scaled units).

Appends rows `function,view,integrator,seconds,mean,rmse,p99,max,pixels`
to OUT.csv and prints the summary table.

usage: vtk_integrators.py EXPORT_DIR OUT.csv [--root REPO] [--threads N]
"""
import argparse, glob, json, math, os, subprocess, sys, time

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")
os.environ.pop("DISPLAY", None)

import numpy as np
import vtk
from vtk.util import numpy_support

import sidecar

ap = argparse.ArgumentParser()
ap.add_argument("export")
ap.add_argument("out")
ap.add_argument("--root", default=os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", ".."))
ap.add_argument("--threads", type=int, default=2)
ap.add_argument("--steps", default="1,0.5,0.25")
ap.add_argument("--png", help="also write each VTK image and its reference side by side here")
a = ap.parse_args()
root = os.path.abspath(a.root)
steps = [float(s) for s in a.steps.split(",")]
vtk.vtkMultiThreader.SetGlobalMaximumNumberOfThreads(a.threads)
vtk.vtkSMPTools.Initialize(a.threads)


def source_of(packed):
    """The raw sidecar `packed` was prepared from (`cdvol info --json`)."""
    cdvol = os.path.join(root, "target", "release", "cdvol")
    info = json.loads(subprocess.run([cdvol, "info", "--json", packed], check=True,
                                     capture_output=True, text=True).stdout)
    src = info["source"]
    return src if os.path.isabs(src) else os.path.join(root, src)


def load(path):
    meta, arr = sidecar.read(path)
    nx, ny, nz = meta["dims"]
    img = vtk.vtkImageData()
    img.SetDimensions(nx, ny, nz)
    img.SetSpacing(meta["x"], meta["y"], meta["z"])
    img.SetOrigin(*meta.get("origin", [0, 0, 0]))
    img.GetPointData().SetScalars(numpy_support.numpy_to_vtk(arr, deep=1))
    return img


class Scene:
    """One volume, mapper and offscreen window, reused across views."""

    def __init__(self, img, size):
        self.mapper = vtk.vtkFixedPointVolumeRayCastMapper()
        self.mapper.SetInputData(img)
        self.mapper.SetNumberOfThreads(a.threads)
        self.mapper.SetAutoAdjustSampleDistances(0)
        self.mapper.SetLockSampleDistanceToInputSpacing(0)
        self.mapper.SetImageSampleDistance(1.0)
        self.mapper.SetBlendModeToComposite()
        self.prop = vtk.vtkVolumeProperty()
        self.prop.SetInterpolationTypeToLinear()
        self.prop.SetScalarOpacityUnitDistance(1.0)  # opacity per mm, like cdvol
        self.vol = vtk.vtkVolume()
        self.vol.SetMapper(self.mapper)
        self.vol.SetProperty(self.prop)
        self.ren = vtk.vtkRenderer()
        self.ren.SetBackground(0, 0, 0)
        self.ren.AddVolume(self.vol)
        light = vtk.vtkLight()  # cdvol's headlight (tools/peers/vtk_render.py)
        light.SetLightTypeToHeadlight()
        light.SetAmbientColor(1.0, 1.0, 1.0)
        self.ren.AddLight(light)
        self.win = vtk.vtkRenderWindow()
        self.win.SetOffScreenRendering(1)
        self.win.SetSize(size, size)
        self.win.AddRenderer(self.ren)
        self.size = size

    def look(self, m):
        col, op = vtk.vtkColorTransferFunction(), vtk.vtkPiecewiseFunction()
        for p in m["points"]:
            col.AddRGBPoint(p["value"], *p["color"])
            op.AddPoint(p["value"], p["opacity"])
        self.prop.SetColor(col)
        self.prop.SetScalarOpacity(op)
        if m["shade"]:
            self.prop.ShadeOn()
            self.prop.SetAmbient(0.12)
            self.prop.SetDiffuse(0.75)
            self.prop.SetSpecular(0.25)
            self.prop.SetSpecularPower(32.0)
        else:
            self.prop.ShadeOff()

    def render(self, cam, step):
        self.mapper.SetSampleDistance(step)
        c = self.ren.GetActiveCamera()
        c.ParallelProjectionOn()
        c.SetParallelScale(cam["frame_mm"] / 2)
        c.SetPosition(*cam["eye"])
        fwd = [cam["target"][k] - cam["eye"][k] for k in range(3)]
        c.SetFocalPoint(*[cam["eye"][k] + 500.0 * fwd[k] for k in range(3)])
        c.SetViewUp(*cam["up"])
        self.ren.ResetCameraClippingRange()
        self.win.Render()  # the first render of a look sets the mapper up
        t0 = time.perf_counter()
        c.Modified()
        self.win.Render()
        dt = time.perf_counter() - t0
        w2i = vtk.vtkWindowToImageFilter()
        w2i.SetInput(self.win)
        w2i.ReadFrontBufferOff()
        w2i.Update()
        o = w2i.GetOutput()
        px = numpy_support.vtk_to_numpy(o.GetPointData().GetScalars())
        px = px.reshape(self.size, self.size, -1)[::-1, :, :3]  # VTK's rows go up
        return px.astype(np.float64), dt


def metrics(vtk_px, ref):
    """As examples/integrators.rs: pixels either covers, largest channel."""
    cover = (ref[:, :, 3] > 0.5 / 255) | (vtk_px.max(axis=2) > 0)
    d = np.abs(vtk_px - 255.0 * ref[:, :, :3]).max(axis=2)[cover]
    if d.size == 0:
        return [0.0] * 4 + [0]
    d.sort()
    n = d.size
    return [d.mean(), math.sqrt((d * d).mean()), d[min(int(n * 0.99), n - 1)], d[-1], n]


scenes, rows, summary = {}, [], {}
for meta_path in sorted(glob.glob(os.path.join(a.export, "*.json"))):
    m = json.load(open(meta_path))
    if m["gradient_opacity"]:
        print(f"{m['case']}: gradient opacity, left out", file=sys.stderr)
        continue
    size = m["size"]
    if m["file"] not in scenes:
        scenes[m["file"]] = Scene(load(source_of(m["file"])), size)
    sc = scenes[m["file"]]
    sc.look(m)
    ref = np.fromfile(meta_path[:-5] + ".f32", dtype="<f4").reshape(size, size, 4)
    az, el = m["view"]
    for step in steps:
        px, dt = sc.render(m["camera"], step)
        mt = metrics(px, ref)
        if a.png:
            from PIL import Image
            both = np.concatenate([px, 255.0 * ref[:, :, :3]], axis=1).clip(0, 255).astype(np.uint8)
            stem = os.path.basename(meta_path)[:-5]
            Image.fromarray(both).save(os.path.join(a.png, f"{stem}-{step:g}.png"))
        name = f"vtk step {step:g} mm"
        rows.append(f"{m['case']},{az:g}/{el:g},{name},{dt:.5f},{mt[0]:.4f},{mt[1]:.4f},"
                    f"{mt[2]:.3f},{mt[3]:.3f},{mt[4]}")
        s = summary.setdefault((m["case"], name), [0.0, 0.0, 0.0, 0.0, 0.0, 0])
        s[0] += dt
        s[1] += mt[0]
        s[2] += mt[1] ** 2
        s[3] = max(s[3], mt[2])
        s[4] = max(s[4], mt[3])
        s[5] += 1

new = not os.path.exists(a.out)
with open(a.out, "a") as f:
    if new:
        f.write("function,view,integrator,seconds,mean,rmse,p99,max,pixels\n")
    f.write("\n".join(rows) + ("\n" if rows else ""))
print("| function | integrator | frame s (mean of views) | mean | RMSE | p99 (worst view) | max |")
print("|---|---|---|---|---|---|---|")
for (case, name), s in summary.items():
    n = s[5]
    print(f"| {case} | {name} | {s[0] / n:.4f} | {s[1] / n:.3f} | {math.sqrt(s[2] / n):.3f} | "
          f"{s[3]:.2f} | {s[4]:.1f} |")
