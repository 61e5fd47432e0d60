#!/usr/bin/env bash
# Installs cdvol's peers (tools/peers/run.sh) when missing:
#  * Debian's libopenvdb-tools (vdb_render, vdb_tool) and python3-openvdb
#    (pyopenvdb: the raw CT -> .vdb step, since vdb_tool reads no raw volumes);
#  * a venv with the `vtk` wheel (+ numpy, pillow); it renders offscreen
#    through EGL (Mesa), so libegl1/libegl-mesa0 come from Debian.
# Not part of CI.
#
# usage: tools/peers/install.sh VENV_DIR      (VTK_SPEC=vtk==9.7.2 by default)
set -euo pipefail
venv=${1:?usage: install.sh VENV_DIR}
sudo=; [ "$(id -u)" = 0 ] || sudo=sudo
debs=(libopenvdb-tools python3-openvdb python3-numpy python3-venv libegl1 libegl-mesa0 libgl1 time util-linux)
missing=()
for p in "${debs[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q 'install ok installed' || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
    echo "installing: ${missing[*]}" >&2
    $sudo apt-get -o DPkg::Lock::Timeout=600 update -qq
    DEBIAN_FRONTEND=noninteractive $sudo apt-get -o DPkg::Lock::Timeout=600 install -y -qq "${missing[@]}" >&2
fi
for b in vdb_render vdb_tool taskset; do command -v "$b" >/dev/null || { echo "missing $b" >&2; exit 1; }; done
/usr/bin/python3 -c 'import pyopenvdb, numpy' || { echo "pyopenvdb/numpy not importable by /usr/bin/python3" >&2; exit 1; }

if ! "$venv/bin/python" -c 'import vtk, numpy, PIL' 2>/dev/null; then
    echo "creating $venv with ${VTK_SPEC:-vtk==9.7.2}" >&2
    /usr/bin/python3 -m venv "$venv"
    "$venv/bin/pip" install -q "${VTK_SPEC:-vtk==9.7.2}" numpy pillow >&2
fi
# Offscreen check: a 16x16 render with no display.
env -u DISPLAY VTK_DEFAULT_OPENGL_WINDOW=vtkEGLRenderWindow "$venv/bin/python" -c '
import vtk
w = vtk.vtkRenderWindow(); w.SetOffScreenRendering(1); w.SetSize(16, 16)
w.AddRenderer(vtk.vtkRenderer()); w.Render()
print("vtk", vtk.vtkVersion.GetVTKVersion(), "renders offscreen with", w.GetClassName())' >&2
