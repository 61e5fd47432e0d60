//! Patient orientation (issue 16, item 5): one asymmetric phantom, defined
//! in patient (LPS) millimetres, written as a DICOM series, a NIfTI file
//! and an NRRD file, each with its samples in a different order (a
//! permuted coronal DICOM series, a mirrored NIfTI, a flipped NRRD). In
//! an anterior view the marker on the patient's left appears on the
//! image's right (the viewer faces the patient: the radiological
//! convention), the marker on top of the head at the top, and the three
//! formats agree in every named view.

use std::path::{Path, PathBuf};

use crate::common::{cdvol, fails, ok};

/// Sample spacing (mm) on every axis.
const S: f64 = 2.0;
/// The patient box the phantom fills (LPS mm, both ends sampled).
const LO: [f64; 3] = [-50.0, -50.0, -60.0];
const HI: [f64; 3] = [50.0, 50.0, 60.0];
/// Image size, and the frame in mm (2 mm a pixel; views centre on the
/// object's box, render/view/framing.rs, and [`mask`] moves the patient origin,
/// the volume's centre, to the image's centre).
const PX: u32 = 80;
const FRAME: f64 = 160.0;

/// The phantom in LPS mm: a head (ellipsoid), a marker on the patient's
/// left, one on top of the head and a nose in front. 1000 inside, 0
/// outside.
fn phantom(p: [f64; 3]) -> u16 {
    let ball = |c: [f64; 3], r: f64| (0..3).map(|k| (p[k] - c[k]).powi(2)).sum::<f64>() < r * r;
    let head = (p[0] / 28.0).powi(2) + (p[1] / 32.0).powi(2) + (p[2] / 38.0).powi(2) < 1.0;
    let left = ball([41.0, 0.0, 0.0], 7.0);
    let top = ball([0.0, 0.0, 50.0], 6.0);
    let nose = ball([0.0, -42.0, 0.0], 6.0);
    if head || left || top || nose {
        1000
    } else {
        0
    }
}

/// A sample grid over the patient box whose axes point as `code` says
/// (`RIA`: +x to the patient's right, +y inferior, +z anterior): the LPS
/// unit direction of each sample axis, the samples per axis and the LPS
/// position of sample (0, 0, 0).
struct Lattice {
    dirs: [[f64; 3]; 3],
    dims: [usize; 3],
    origin: [f64; 3],
}

fn lattice(code: &str) -> Lattice {
    let mut dirs = [[0.0; 3]; 3];
    let mut dims = [0; 3];
    let mut origin = [0.0; 3];
    for (k, c) in code.chars().enumerate() {
        let (j, s) = match c {
            'L' => (0, 1.0),
            'R' => (0, -1.0),
            'P' => (1, 1.0),
            'A' => (1, -1.0),
            'S' => (2, 1.0),
            _ => (2, -1.0),
        };
        dirs[k][j] = s;
        dims[k] = ((HI[j] - LO[j]) / S).round() as usize + 1;
        origin[j] = if s > 0.0 { LO[j] } else { HI[j] };
    }
    Lattice { dirs, dims, origin }
}

impl Lattice {
    fn position(&self, i: [usize; 3]) -> [f64; 3] {
        std::array::from_fn(|j| {
            self.origin[j]
                + (0..3)
                    .map(|k| i[k] as f64 * S * self.dirs[k][j])
                    .sum::<f64>()
        })
    }

    /// Samples x fastest.
    fn samples(&self) -> Vec<u16> {
        let [nx, ny, nz] = self.dims;
        let mut v = Vec::with_capacity(nx * ny * nz);
        for z in 0..nz {
            for y in 0..ny {
                for x in 0..nx {
                    v.push(phantom(self.position([x, y, z])));
                }
            }
        }
        v
    }
}

/// A coronal series: rows to the patient's right, columns downwards,
/// slices from back to front (`RIA`).
fn write_dicom(dir: &Path) -> PathBuf {
    use cdvol::input::dicom::{write_slice, SliceHeader, EXPLICIT_VR_LE};
    let l = lattice("RIA");
    let [nx, ny, nz] = l.dims;
    let all = l.samples();
    let series = dir.join("series");
    for k in 0..nz {
        let [r, c] = [l.dirs[0], l.dirs[1]];
        let h = SliceHeader {
            series: "1.2.826.0.1.3680043.9.7777.16",
            instance: k + 1,
            rows: ny,
            cols: nx,
            spacing: [S, S],
            position: l.position([0, 0, k]),
            orientation: [r[0], r[1], r[2], c[0], c[1], c[2]],
            signed: false,
            rescale: cdvol::input::Rescale::IDENTITY,
            transfer_syntax: EXPLICIT_VR_LE,
        };
        // Reverse order of the files: the reader sorts by position.
        let name = series.join(format!("IM{:04}", nz - k));
        write_slice(&name, &h, &all[k * nx * ny..(k + 1) * nx * ny]).unwrap();
    }
    series
}

/// A NIfTI file whose sform (RAS) says `LAS`: mirrored sample axes.
fn write_nifti(dir: &Path) -> PathBuf {
    use nifti::writer::WriterOptions;
    use nifti::NiftiHeader;
    let l = lattice("LAS");
    let [nx, ny, nz] = l.dims;
    let data: Vec<i16> = l.samples().into_iter().map(|v| v as i16).collect();
    let data =
        ndarray::Array::from_shape_vec(ndarray::ShapeBuilder::f((nx, ny, nz)), data).unwrap();
    let ras = |v: [f64; 3]| [-v[0], -v[1], v[2]];
    let o = ras(l.origin);
    let mut h = NiftiHeader {
        xyzt_units: 2,
        sform_code: 1,
        qform_code: 0,
        ..NiftiHeader::default()
    };
    h.pixdim[1..4].copy_from_slice(&[S as f32; 3]);
    let cols = l.dirs.map(ras);
    let rows = [&mut h.srow_x, &mut h.srow_y, &mut h.srow_z];
    for (j, row) in rows.into_iter().enumerate() {
        *row = [
            (cols[0][j] * S) as f32,
            (cols[1][j] * S) as f32,
            (cols[2][j] * S) as f32,
            o[j] as f32,
        ];
    }
    let p = dir.join("phantom.nii");
    WriterOptions::new(&p)
        .reference_header(&h)
        .write_nifti(&data)
        .unwrap();
    p
}

/// An NRRD in RAS space whose directions say `RPI`.
fn write_nrrd(dir: &Path) -> PathBuf {
    let l = lattice("RPI");
    let [nx, ny, nz] = l.dims;
    let ras = |v: [f64; 3]| [-v[0], -v[1], v[2]];
    let d = l.dirs.map(|v| ras(v).map(|x| x * S));
    let o = ras(l.origin);
    let mut f = format!(
        "NRRD0004\ntype: uint16\ndimension: 3\nspace: right-anterior-superior\n\
         sizes: {nx} {ny} {nz}\n\
         space directions: ({},{},{}) ({},{},{}) ({},{},{})\n\
         endian: little\nencoding: raw\nspace origin: ({},{},{})\n\n",
        d[0][0],
        d[0][1],
        d[0][2],
        d[1][0],
        d[1][1],
        d[1][2],
        d[2][0],
        d[2][1],
        d[2][2],
        o[0],
        o[1],
        o[2]
    )
    .into_bytes();
    f.extend(l.samples().iter().flat_map(|v| v.to_le_bytes()));
    let p = dir.join("phantom.nrrd");
    std::fs::write(&p, f).unwrap();
    p
}

/// The same phantom as a raw sidecar in LPS order, with `extra` keys.
fn write_raw(dir: &Path, name: &str, extra: serde_json::Value) -> PathBuf {
    let l = lattice("LPS");
    let bytes: Vec<u8> = l.samples().iter().flat_map(|v| v.to_le_bytes()).collect();
    std::fs::write(dir.join(format!("{name}.raw")), bytes).unwrap();
    let mut side = serde_json::json!({
        "data": format!("{name}.raw"), "dims": l.dims, "dtype": "u16",
        "x": S, "y": S, "z": S, "origin": LO,
    });
    if let (Some(s), Some(e)) = (side.as_object_mut(), extra.as_object()) {
        s.extend(e.clone());
    }
    let p = dir.join(format!("{name}.json"));
    std::fs::write(&p, side.to_string()).unwrap();
    p
}

fn prep(input: &Path, out: &Path) {
    ok(cdvol()
        .args(["prep", "-q"])
        .arg(input)
        .arg("-o")
        .arg(out)
        .args(["--iso", "500", "--brick", "16"]));
}

/// Renders `vol` (surface) with `view` (`None`: the default) and returns
/// the foreground mask, row 0 at the top, moved by whole pixels so that
/// the volume's centre (the patient origin) lies at the image's centre.
fn mask(vol: &Path, view: Option<&str>, out: &Path) -> Vec<Vec<bool>> {
    let mut c = cdvol();
    c.args(["render", "-q"]).arg(vol).arg("-o").arg(out);
    c.args(["--width", &PX.to_string(), "--height", &PX.to_string()]);
    c.args(["--frame", &FRAME.to_string()]);
    if let Some(v) = view {
        c.args(["--view", v]);
    }
    ok(&mut c);
    let img = image::open(out).unwrap().to_luma8();
    let bg = img.get_pixel(0, 0)[0];
    let [sx, sy] = origin_px(vol, view);
    let px = PX as i64;
    (0..px)
        .map(|y| {
            (0..px)
                .map(|x| {
                    let (x, y) = (x + sx, y + sy);
                    (0..px).contains(&x)
                        && (0..px).contains(&y)
                        && img.get_pixel(x as u32, y as u32)[0] != bg
                })
                .collect()
        })
        .collect()
}

/// Where the volume's centre lies in `vol`'s image with `view`, in whole
/// pixels right of and below the image's centre, the camera placed by the
/// library as `cdvol render` places it.
fn origin_px(vol: &Path, view: Option<&str>) -> [i64; 2] {
    use cdvol::render::job::{Aim, View};
    let v = cdvol::format::reader::PackedVolume::open(vol).unwrap();
    let h = v.header();
    let view = match view {
        Some(n) if cdvol::orient::NamedView::parse(n).is_some() => {
            Aim::Named(cdvol::orient::NamedView::parse(n).unwrap())
        }
        Some(a) => {
            let (az, el) = a.split_once(',').unwrap();
            Aim::Orbit {
                az_deg: az.parse().unwrap(),
                el_deg: el.parse().unwrap(),
            }
        }
        None => Aim::Orbit {
            az_deg: 0.0,
            el_deg: 0.0,
        },
    };
    let spec = View {
        aim: view,
        persp_fov_deg: None,
        frame_mm: Some(FRAME),
        width: PX,
        height: PX,
    };
    let opts = cdvol::render::RenderOptions::new(
        cdvol::render::Mode::Surface {
            hit: cdvol::render::sample::hit::HitMethod::Int,
            shadows: false,
        },
        cdvol::render::traverse::Method::Cd { min_leap: 1 },
    );
    let o = h.orientation.as_ref();
    let framing = spec.framing(&v, &opts, 1, 0.0, o).unwrap();
    let cam = spec.place(&framing, 0.0, o).unwrap();
    let (lo, hi) = cdvol::render::traverse::TGrid::<f64>::new(&h.axes).bounds();
    let c = glam::DVec3::from_array(std::array::from_fn(|k| 0.5 * (lo[k] + hi[k])));
    let p = c - cam.eye;
    let mm_px = FRAME / PX as f64;
    [
        (p.dot(cam.right) / mm_px).round() as i64,
        (-p.dot(cam.up) / mm_px).round() as i64,
    ]
}

/// Foreground pixels whose centre lies beyond `mm` from the image centre
/// on each side: `[left, right, top, bottom]`.
fn beyond(m: &[Vec<bool>], mm: f64) -> [usize; 4] {
    let at = |i: usize| (i as f64 + 0.5 - PX as f64 / 2.0) * FRAME / PX as f64;
    let mut n = [0; 4];
    for (y, row) in m.iter().enumerate() {
        for (x, &f) in row.iter().enumerate() {
            if !f {
                continue;
            }
            let (ix, iy) = (at(x), -at(y));
            n[0] += (ix < -mm) as usize;
            n[1] += (ix > mm) as usize;
            n[2] += (iy > mm) as usize;
            n[3] += (iy < -mm) as usize;
        }
    }
    n
}

fn differing(a: &[Vec<bool>], b: &[Vec<bool>]) -> usize {
    a.iter()
        .flatten()
        .zip(b.iter().flatten())
        .filter(|(x, y)| x != y)
        .count()
}

#[test]
fn anterior_view_puts_the_patients_left_on_the_images_right_in_every_format() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let inputs = [
        (
            "DICOM",
            write_dicom(d),
            "RIA from DICOM ImageOrientationPatient",
        ),
        ("NIfTI", write_nifti(d), "LAS from NIfTI sform"),
        ("NRRD", write_nrrd(d), "RPI from NRRD space directions"),
        (
            "raw",
            write_raw(d, "lps", serde_json::json!({"orientation": "LPS"})),
            "LPS from sidecar orientation",
        ),
    ];
    let mut first: Option<(&str, Vec<Vec<Vec<bool>>>)> = None;
    for (what, input, orientation) in &inputs {
        let vol = d.join(format!("{what}.cdv"));
        prep(input, &vol);
        let info = ok(cdvol().arg("info").arg(&vol));
        assert!(
            info.contains(&format!("orientation  {orientation}")),
            "{what}: {info}"
        );
        let png = d.join(format!("{what}.png"));
        let views = [
            "anterior",
            "posterior",
            "left",
            "right",
            "superior",
            "inferior",
        ];
        let masks: Vec<_> = views.iter().map(|v| mask(&vol, Some(v), &png)).collect();
        let [anterior, posterior, left, right, superior, inferior] = [0, 1, 2, 3, 4, 5];
        // Left marker (41 mm left of the midline) and top marker (50 mm
        // up); the head reaches 28 mm sideways and 38 mm up.
        let a = beyond(&masks[anterior], 33.0);
        assert!(
            a[1] > 10 && a[0] == 0,
            "{what} anterior: left marker on the right: {a:?}"
        );
        let a = beyond(&masks[anterior], 42.0);
        assert!(a[2] > 10 && a[3] == 0, "{what} anterior: head up: {a:?}");
        let p = beyond(&masks[posterior], 33.0);
        assert!(
            p[0] > 10 && p[1] == 0,
            "{what} posterior: left marker on the left: {p:?}"
        );
        // From the left side, head up, the face (nose, 42 mm in front)
        // points to the image's left; from the right, to its right.
        let l = beyond(&masks[left], 37.0);
        assert!(
            l[0] > 10 && l[1] == 0,
            "{what} left: nose on the left: {l:?}"
        );
        let r = beyond(&masks[right], 37.0);
        assert!(
            r[1] > 10 && r[0] == 0,
            "{what} right: nose on the right: {r:?}"
        );
        for (v, m) in [("left", &masks[left]), ("right", &masks[right])] {
            let t = beyond(m, 42.0);
            assert!(t[2] > 10 && t[3] == 0, "{what} {v}: head up: {t:?}");
        }
        // Along the body axis the face is at the top; from the feet the
        // patient's left is on the right (as in radiological axial
        // slices), from above on the left.
        for (v, m, side) in [
            ("superior", &masks[superior], 0),
            ("inferior", &masks[inferior], 1),
        ] {
            let t = beyond(m, 37.0);
            assert!(t[2] > 10 && t[3] == 0, "{what} {v}: face up: {t:?}");
            let s = beyond(m, 33.0);
            assert!(
                s[side] > 10 && s[1 - side] == 0,
                "{what} {v}: left marker on side {side}: {s:?}"
            );
        }
        // The default view and 0,0 are anterior.
        assert_eq!(mask(&vol, None, &png), masks[anterior], "{what}: default");
        assert_eq!(
            mask(&vol, Some("0,0"), &png),
            masks[anterior],
            "{what}: 0,0"
        );
        assert_eq!(mask(&vol, Some("90,0"), &png), masks[left], "{what}: 90,0");
        // Every format shows the same patient (up to a pixel's rounding at
        // the edges).
        match &first {
            None => first = Some((what, masks)),
            Some((w0, m0)) => {
                for (i, v) in views.iter().enumerate() {
                    let n = differing(&masks[i], &m0[i]);
                    assert!(n <= 40, "{what} and {w0} differ in {n} pixels of {v}");
                }
            }
        }
    }
}

#[test]
fn unoriented_files_keep_sample_axes_and_refuse_named_views() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let raw = write_raw(d, "plain", serde_json::json!({}));
    let vol = d.join("plain.cdv");
    prep(&raw, &vol);
    let info = ok(cdvol().arg("info").arg(&vol));
    assert!(info.contains("orientation  unknown"), "{info}");
    let json = ok(cdvol().args(["info", "--json"]).arg(&vol));
    assert!(json.contains("\"orientation\": \"unknown\""), "{json}");
    let png = d.join("v.png");
    let e = fails(
        cdvol()
            .args(["render", "-q"])
            .arg(&vol)
            .arg("-o")
            .arg(&png)
            .args(["--view", "anterior"]),
    );
    assert!(e.contains("--view") && e.contains("orientation"), "{e}");
    assert!(!png.exists());
    // The default is 0,0 in sample axes: for these LPS-ordered samples
    // the same image as the anterior view of the oriented copy.
    let oriented = write_raw(d, "lps", serde_json::json!({"orientation": "LPS"}));
    let ovol = d.join("lps.cdv");
    prep(&oriented, &ovol);
    assert_eq!(
        mask(&vol, None, &png),
        mask(&ovol, Some("anterior"), &d.join("o.png"))
    );
    let e = fails(
        cdvol()
            .args(["render", "-q"])
            .arg(&vol)
            .arg("-o")
            .arg(&png)
            .args(["--view", "front"]),
    );
    assert!(e.contains("anterior, posterior"), "{e}");
}

#[test]
fn sidecar_orientation_keys_are_checked_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (name, value, words) in [
        (
            "code",
            serde_json::json!("LPP"),
            &["orientation", "LPP", "three letters"][..],
        ),
        ("kind", serde_json::json!(3), &["orientation", "LPS"][..]),
        (
            "skew",
            serde_json::json!({"lps": [[1, 0, 0], [1, 1, 0], [0, 0, 1]]}),
            &["orientation", "not orthogonal"][..],
        ),
        (
            "short",
            serde_json::json!({"ras": [[1, 0, 0], [0, 1], [0, 0, 1]]}),
            &["orientation.ras[1]", "[x, y, z]"][..],
        ),
    ] {
        let p = write_raw(d, name, serde_json::json!({ "orientation": value }));
        let out = d.join(format!("{name}.cdv"));
        let e = fails(
            cdvol()
                .args(["prep", "-q"])
                .arg(&p)
                .arg("-o")
                .arg(&out)
                .args(["--iso", "1"]),
        );
        assert!(e.contains(&format!("{name}.json")), "{e}");
        for w in words {
            assert!(e.contains(w), "{name}: {e:?} does not mention {w:?}");
        }
    }
    // A RAS matrix is converted to LPS.
    let p = write_raw(
        d,
        "m",
        serde_json::json!({"orientation": {"ras": [[-1, 0, 0], [0, -1, 0], [0, 0, 1]]}}),
    );
    let src = cdvol::input::open(&p).unwrap();
    let o = src.meta().orientation.clone().unwrap();
    assert_eq!(o.nearest().code(), "LPS");
}

#[test]
fn oblique_dicom_is_stated_with_its_angle() {
    use cdvol::input::dicom::{write_slice, SliceHeader, EXPLICIT_VR_LE};
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path().join("oblique");
    let (c, s) = (20f64.to_radians().cos(), 20f64.to_radians().sin());
    let (n, m) = (12usize, 10usize);
    for k in 0..6 {
        let h = SliceHeader {
            series: "1.2.826.0.1.3680043.9.7777.17",
            instance: k + 1,
            rows: m,
            cols: n,
            spacing: [1.0, 1.0],
            position: [0.0, 0.0, 2.0 * k as f64],
            orientation: [c, s, 0.0, -s, c, 0.0],
            signed: false,
            rescale: cdvol::input::Rescale::IDENTITY,
            transfer_syntax: EXPLICIT_VR_LE,
        };
        let px: Vec<u16> = (0..n * m)
            .map(|i| if i % 7 == 0 { 1000 } else { 0 })
            .collect();
        write_slice(&d.join(format!("s{k}")), &h, &px).unwrap();
    }
    let vol = dir.path().join("o.cdv");
    prep(&d, &vol);
    let info = ok(cdvol().arg("info").arg(&vol));
    assert!(
        info.contains("orientation  oblique, 20.0 degrees from LPS (rendered as LPS) from DICOM"),
        "{info}"
    );
    ok(cdvol()
        .args(["render", "-q"])
        .arg(&vol)
        .arg("-o")
        .arg(dir.path().join("o.png"))
        .args(["--view", "left", "--width", "16", "--height", "16"]));
}

#[test]
fn header_orientation_is_optional_and_checked() {
    use cdvol::format::reader::PackedVolume;
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let raw = write_raw(d, "lps", serde_json::json!({"orientation": "LPS"}));
    let vol = d.join("lps.cdv");
    prep(&raw, &vol);
    let bytes = std::fs::read(&vol).unwrap();
    let h = PackedVolume::open(&vol).unwrap().header().clone();
    let o = h.orientation.expect("recorded");
    assert_eq!(
        o.axes_lps,
        [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    );
    assert_eq!(o.source, "sidecar orientation");
    // Older files have no key: they read, with the orientation unknown.
    let old = d.join("old.cdv");
    std::fs::write(
        &old,
        crate::common::rewrite_header(&bytes, |h| {
            h.as_object_mut().unwrap().remove("orientation");
        }),
    )
    .unwrap();
    assert!(PackedVolume::open(&old)
        .unwrap()
        .header()
        .orientation
        .is_none());
    // Crafted directions are refused by field.
    for (name, axes) in [
        ("zero", serde_json::json!([[1, 0, 0], [0, 0, 0], [0, 0, 1]])),
        ("long", serde_json::json!([[2, 0, 0], [0, 1, 0], [0, 0, 1]])),
        (
            "skew",
            serde_json::json!([[1, 0, 0], [0.6, 0.8, 0], [0, 0, 1]]),
        ),
    ] {
        let p = d.join(format!("{name}.cdv"));
        std::fs::write(
            &p,
            crate::common::rewrite_header(&bytes, |h| h["orientation"]["axes_lps"] = axes.clone()),
        )
        .unwrap();
        let e = PackedVolume::open(&p).err().expect(name).to_string();
        assert!(
            e.contains("orientation.axes_lps") && e.contains(&format!("{name}.cdv")),
            "{e}"
        );
    }
}
