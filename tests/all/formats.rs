//! NRRD and NIfTI inputs prepare to the same packed volume (grid, summary
//! and every brick's payload) as a raw sidecar of the same samples; broken
//! headers and data get messages that name the file and the field.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common::{self, assert_same_volume, gz, packed, try_packed};
use cdvol::format::reader::PackedVolume;

const DIMS: [usize; 3] = [37, 30, 26];
const SPACING: [f64; 3] = [0.8, 0.9, 1.5];
const ORIGIN: [f64; 3] = [10.0, -5.0, 3.0];
const ISO: f64 = 300.0;

/// A deterministic CT-like field in HU: a shell, a blob and noise.
fn field() -> Vec<i16> {
    let [nx, ny, nz] = DIMS;
    let mut v = Vec::with_capacity(nx * ny * nz);
    let mut seed = 12345u64;
    for z in 0..nz {
        for y in 0..ny {
            for x in 0..nx {
                let p = [x as f64 - 18.0, y as f64 - 15.0, (z as f64 - 13.0) * 1.4];
                let r = (p[0] * p[0] + p[1] * p[1] + p[2] * p[2]).sqrt();
                seed = seed
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                let noise = ((seed >> 33) % 41) as f64 - 20.0;
                let shell = if (9.0..12.0).contains(&r) {
                    1200.0
                } else {
                    0.0
                };
                let blob = 800.0 * (-(((p[0] - 4.0).powi(2) + p[1].powi(2)) / 8.0)).exp();
                v.push(
                    (-1000.0 + shell + blob + if r < 9.0 { 1040.0 } else { 0.0 } + noise) as i16,
                );
            }
        }
    }
    v
}

fn bytes(v: &[i16], big: bool) -> Vec<u8> {
    v.iter()
        .flat_map(|s| {
            if big {
                s.to_be_bytes()
            } else {
                s.to_le_bytes()
            }
        })
        .collect()
}

/// The reference: a raw stack and its sidecar.
fn reference(dir: &Path, origin: [f64; 3], rescale: Option<(f64, f64)>) -> PathBuf {
    let raw = dir.join("ref.raw");
    std::fs::write(&raw, bytes(&field(), false)).unwrap();
    let mut side = serde_json::json!({
        "data": "ref.raw", "dims": DIMS, "dtype": "i16", "endian": "little",
        "x": SPACING[0], "y": SPACING[1], "z": SPACING[2], "origin": origin,
    });
    if let Some((slope, intercept)) = rescale {
        side["rescale"] = serde_json::json!({"slope": slope, "intercept": intercept});
    }
    let p = dir.join(format!("ref-{}.json", rescale.is_some()));
    std::fs::write(&p, side.to_string()).unwrap();
    p
}

fn nrrd_header(fields: &[(&str, String)]) -> String {
    let mut h = String::from("NRRD0004\n# written by tests/formats.rs\n");
    for (k, v) in fields {
        h.push_str(&format!("{k}: {v}\n"));
    }
    h
}

fn nrrd_fields(encoding: &str, endian: &str) -> Vec<(&'static str, String)> {
    let [nx, ny, nz] = DIMS;
    let [sx, sy, sz] = SPACING;
    let [ox, oy, oz] = ORIGIN;
    vec![
        ("type", "short".into()),
        ("dimension", "3".into()),
        ("space", "left-posterior-superior".into()),
        ("sizes", format!("{nx} {ny} {nz}")),
        (
            "space directions",
            format!("({sx},0,0) (0,{sy},0) (0,0,{sz})"),
        ),
        ("kinds", "domain domain domain".into()),
        ("endian", endian.into()),
        ("encoding", encoding.into()),
        ("space origin", format!("({ox},{oy},{oz})")),
    ]
}

#[test]
fn nrrd_variants_prepare_like_the_raw_stack() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let want = packed(&reference(d, ORIGIN, None), &d.join("ref.cdv"), ISO);
    let v = field();

    // Attached, raw, little endian.
    let mut f = nrrd_header(&nrrd_fields("raw", "little")).into_bytes();
    f.push(b'\n');
    f.extend(bytes(&v, false));
    std::fs::write(d.join("a.nrrd"), &f).unwrap();
    // Attached, gzip, big endian.
    let mut f = nrrd_header(&nrrd_fields("gzip", "big")).into_bytes();
    f.push(b'\n');
    f.extend(gz(&bytes(&v, true)));
    std::fs::write(d.join("b.nrrd"), &f).unwrap();
    // Detached raw with a byte skip, and detached gzip.
    let mut fields = nrrd_fields("raw", "little");
    fields.push(("byte skip", "5".into()));
    fields.push(("data file", "c.raw".into()));
    std::fs::write(d.join("c.nhdr"), nrrd_header(&fields)).unwrap();
    let mut data = b"HELLO".to_vec();
    data.extend(bytes(&v, false));
    std::fs::write(d.join("c.raw"), data).unwrap();
    let mut fields = nrrd_fields("gz", "little");
    fields.push(("data file", "d.raw.gz".into()));
    std::fs::write(d.join("d.nhdr"), nrrd_header(&fields)).unwrap();
    std::fs::write(d.join("d.raw.gz"), gz(&bytes(&v, false))).unwrap();

    for name in ["a.nrrd", "b.nrrd", "c.nhdr", "d.nhdr"] {
        let got = packed(&d.join(name), &d.join(format!("{name}.cdv")), ISO);
        assert_same_volume(&got, &want, name);
    }

    // `spacings` instead of directions (no origin: at 0).
    let want0 = packed(&reference(d, [0.0; 3], None), &d.join("ref0.cdv"), ISO);
    let fields: Vec<_> = nrrd_fields("raw", "little")
        .into_iter()
        .filter(|(k, _)| !k.starts_with("space"))
        .chain([(
            "spacings",
            format!("{} {} {}", SPACING[0], SPACING[1], SPACING[2]),
        )])
        .chain([("data file", "c.raw".into()), ("byte skip", "5".into())])
        .collect();
    std::fs::write(d.join("e.nhdr"), nrrd_header(&fields)).unwrap();
    assert_same_volume(
        &packed(&d.join("e.nhdr"), &d.join("e.cdv"), ISO),
        &want0,
        "spacings",
    );
}

fn refused(input: &Path, out: &Path, words: &[&str]) {
    let e = match try_packed(input, out, ISO, |_| {}) {
        Ok(_) => panic!("{} was accepted", input.display()),
        Err(e) => e,
    };
    for w in words {
        assert!(e.contains(w), "{e:?} does not mention {w:?}");
    }
    assert!(!out.exists(), "no output for a refused input");
}

#[test]
fn broken_nrrd_inputs_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("o.cdv");
    let v = bytes(&field(), false);
    let attached = |name: &str, fields: &[(&str, String)], data: &[u8]| {
        let mut f = nrrd_header(fields).into_bytes();
        f.push(b'\n');
        f.extend_from_slice(data);
        let p = d.join(name);
        std::fs::write(&p, f).unwrap();
        p
    };
    let with = |k: &str, v: &str| {
        let mut f: Vec<_> = nrrd_fields("raw", "little")
            .into_iter()
            .filter(|(x, _)| *x != k)
            .collect();
        if !v.is_empty() {
            f.push((k.to_string().leak(), v.to_string()));
        }
        f
    };
    let p = attached(
        "oblique.nrrd",
        &with("space directions", "(0.8,0.1,0) (0,0.9,0) (0,0,1.5)"),
        &v,
    );
    refused(
        &p,
        &out,
        &["oblique.nrrd", "space directions", "not along axis 0"],
    );
    let p = attached("nosizes.nrrd", &with("sizes", ""), &v);
    refused(&p, &out, &["nosizes.nrrd", "field `sizes`", "missing"]);
    let p = attached("ascii.nrrd", &with("encoding", "ascii"), &v);
    refused(&p, &out, &["ascii.nrrd", "encoding", "not supported"]);
    let p = attached("u64.nrrd", &with("type", "uint64"), &v);
    refused(&p, &out, &["u64.nrrd", "type", "uint64"]);
    let p = attached("dim4.nrrd", &with("dimension", "4"), &v);
    refused(&p, &out, &["dim4.nrrd", "dimension", "expected 3"]);
    let p = attached(
        "short.nrrd",
        &nrrd_fields("raw", "little"),
        &v[..v.len() - 10],
    );
    refused(&p, &out, &["short.nrrd", "expected at least"]);
    let p = attached(
        "shortgz.nrrd",
        &nrrd_fields("gzip", "little"),
        &gz(&v[..v.len() / 2]),
    );
    refused(&p, &out, &["shortgz.nrrd", "gzip stream ends"]);
    let p = attached("nogz.nrrd", &nrrd_fields("gzip", "little"), &v);
    refused(&p, &out, &["nogz.nrrd", "gzip"]);
    let p = d.join("magic.nrrd");
    std::fs::write(&p, "P5\n2 2\n").unwrap();
    refused(&p, &out, &["magic.nrrd", "NRRD0001"]);
    let mut fields = nrrd_fields("raw", "little");
    fields.push(("data file", "nowhere.raw".into()));
    std::fs::write(d.join("gone.nhdr"), nrrd_header(&fields)).unwrap();
    refused(&d.join("gone.nhdr"), &out, &["nowhere.raw", "cannot open"]);
}

fn nifti_file(path: &Path, slope: f32, inter: f32) {
    use nifti::writer::WriterOptions;
    use nifti::NiftiHeader;
    let [nx, ny, nz] = DIMS;
    let data =
        ndarray::Array::from_shape_vec(ndarray::ShapeBuilder::f((nx, ny, nz)), field()).unwrap();
    let mut h = NiftiHeader {
        scl_slope: slope,
        scl_inter: inter,
        xyzt_units: 2,
        sform_code: 1,
        ..NiftiHeader::default()
    };
    h.pixdim[1..4].copy_from_slice(&SPACING.map(|s| s as f32));
    h.srow_x[3] = ORIGIN[0] as f32;
    h.srow_y[3] = ORIGIN[1] as f32;
    h.srow_z[3] = ORIGIN[2] as f32;
    // The crate writes the header and samples (x fastest, little endian
    // here) but resets scl_slope/scl_inter to 1/0, so they are patched in
    // at their offsets (112, 116), and .nii.gz is the gzipped .nii.
    let plain = path.parent().unwrap().join("writer-tmp.nii");
    WriterOptions::new(&plain)
        .reference_header(&h)
        .write_nifti(&data)
        .unwrap();
    let mut b = std::fs::read(&plain).unwrap();
    std::fs::remove_file(&plain).unwrap();
    assert_eq!(&b[344..348], b"n+1\0");
    b[112..116].copy_from_slice(&slope.to_le_bytes());
    b[116..120].copy_from_slice(&inter.to_le_bytes());
    let gzipped = path.to_string_lossy().ends_with(".gz");
    std::fs::write(path, if gzipped { gz(&b) } else { b }).unwrap();
}

#[test]
fn nifti_prepares_like_the_raw_stack() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let want = packed(
        &reference(d, ORIGIN, Some((1.0, -24.0))),
        &d.join("ref.cdv"),
        ISO,
    );
    for name in ["h.nii", "h.nii.gz"] {
        nifti_file(&d.join(name), 1.0, -24.0);
        let got = packed(&d.join(name), &d.join(format!("{name}.cdv")), ISO);
        assert_same_volume(&got, &want, name);
    }
    // scl_slope 0 means no rescale.
    let want1 = packed(&reference(d, ORIGIN, None), &d.join("ref1.cdv"), ISO);
    nifti_file(&d.join("n.nii"), 0.0, 5.0);
    assert_same_volume(
        &packed(&d.join("n.nii"), &d.join("n.cdv"), ISO),
        &want1,
        "slope 0",
    );

    // Truncated files.
    let out = d.join("o.cdv");
    let b = std::fs::read(d.join("h.nii")).unwrap();
    std::fs::write(d.join("t.nii"), &b[..b.len() - 100]).unwrap();
    refused(&d.join("t.nii"), &out, &["t.nii", "expected at least"]);
    let b = std::fs::read(d.join("h.nii.gz")).unwrap();
    std::fs::write(d.join("t.nii.gz"), &b[..b.len() / 2]).unwrap();
    refused(&d.join("t.nii.gz"), &out, &["t.nii.gz"]);
    std::fs::write(d.join("junk.nii"), b"not a nifti file at all").unwrap();
    refused(&d.join("junk.nii"), &out, &["junk.nii", "header"]);
}

#[test]
fn cli_prep_reads_nrrd() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let mut f = nrrd_header(&nrrd_fields("gzip", "little")).into_bytes();
    f.push(b'\n');
    f.extend(gz(&bytes(&field(), false)));
    std::fs::write(d.join("v.nrrd"), &f).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_cdvol"))
        .args(["prep", "-q", "--iso", "300"])
        .arg(d.join("v.nrrd"))
        .arg("-o")
        .arg(d.join("v.cdv"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let want = packed(&reference(d, ORIGIN, None), &d.join("ref.cdv"), ISO);
    let got = PackedVolume::open(&d.join("v.cdv")).unwrap();
    assert_eq!(got.header().axes, want.header().axes);
    assert_eq!(
        got.header().summary.one_cells,
        want.header().summary.one_cells
    );
}

/// The image format follows `-o`'s extension; an unknown one is refused
/// before any work and writes nothing (issue 16: `-o x.jpg` used to hold
/// PNG bytes).
#[test]
fn render_output_format_follows_the_extension() {
    let dir = tempfile::tempdir().unwrap();
    let cdv = small_head(dir.path(), "24,24,16", "300", "head");
    let render = |name: &str, extra: &[&str]| {
        let out = dir.path().join(name);
        let mut c = common::cdvol();
        c.args(["render", "-q", "--width", "20", "--height", "16"])
            .args(extra)
            .arg(&cdv)
            .arg("-o")
            .arg(&out);
        (c, out)
    };
    for (name, magic) in [
        ("a.png", &b"\x89PNG"[..]),
        ("a.TIF", &b"II*\0"[..]),
        ("a.tiff", &b"II*\0"[..]),
        ("a.jpg", &b"\xff\xd8\xff"[..]),
    ] {
        let (mut c, out) = render(name, &[]);
        common::ok(&mut c);
        let bytes = std::fs::read(&out).unwrap();
        assert!(bytes.starts_with(magic), "{name}: {:?}", &bytes[..4]);
        let img = image::open(&out).unwrap();
        assert_eq!((img.width(), img.height()), (20, 16), "{name}");
    }
    for (name, extra, want) in [
        (
            "a.bmp",
            &[][..],
            "expected .png, .tif, .tiff, .jpg or .jpeg",
        ),
        ("noext", &[][..], "expected .png"),
        (
            "d.tiff",
            &["--mode", "depth"][..],
            "depth mode writes a PNG",
        ),
    ] {
        let (mut c, out) = render(name, extra);
        let e = common::fails(&mut c);
        assert!(e.contains(want) && e.contains(name), "{name}: {e}");
        assert!(!out.exists(), "{name} was written");
    }
}

/// `render r.cdv -o r.cdv` is refused (by its extension) and the packed
/// file is untouched.
#[test]
fn render_onto_its_packed_file_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let cdv = small_head(dir.path(), "16,16,12", "300", "r");
    let before = std::fs::read(&cdv).unwrap();
    let e = common::fails(
        common::cdvol()
            .args(["render", "-q"])
            .arg(&cdv)
            .arg("-o")
            .arg(&cdv),
    );
    assert!(e.contains("r.cdv"), "{e}");
    assert_eq!(std::fs::read(&cdv).unwrap(), before);
}

/// `--background`: a colour under the image where rays cover less than the
/// pixel, or transparency (RGBA, alpha = coverage); black leaves the image
/// as rendered; sharded and whole renders agree; JPEG cannot be
/// transparent.
#[test]
fn render_backgrounds() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cdv = small_head(d, "24,24,16", "-500", "head");
    let tf = d.join("tf.json");
    std::fs::write(
        &tf,
        r#"{"points": [{"value": -500, "opacity": 0}, {"value": 0, "opacity": 0.05}, {"value": 1000, "opacity": 0.6}]}"#,
    )
    .unwrap();
    let render = |name: &str, extra: &[&str]| {
        let out = d.join(name);
        common::ok(
            common::cdvol()
                .args([
                    "render", "-q", "--width", "32", "--height", "28", "--view", "30,20",
                ])
                .args(extra)
                .arg(&cdv)
                .arg("-o")
                .arg(&out),
        );
        image::open(&out).unwrap()
    };
    for (mode, extra) in [
        ("surface", vec![]),
        ("composite", vec!["--tf", tf.to_str().unwrap()]),
    ] {
        let mut args = vec!["--mode", mode];
        args.extend(extra.iter().copied());
        let black = render(&format!("{mode}-black.png"), &args).to_rgb8();
        let plain = render(
            &format!("{mode}-plain.png"),
            &[&args[..], &["--background", "black"]].concat(),
        )
        .to_rgb8();
        assert_eq!(black, plain, "{mode}: --background black changed the image");
        let white = render(
            &format!("{mode}-white.png"),
            &[&args[..], &["--background", "white"]].concat(),
        )
        .to_rgb8();
        let rgba = render(
            &format!("{mode}-t.png"),
            &[&args[..], &["--background", "transparent"]].concat(),
        );
        let rgba = rgba.as_rgba8().expect("an RGBA image").clone();
        let (mut empty, mut full, mut partial) = (0, 0, 0);
        for ((b, w), t) in black.pixels().zip(white.pixels()).zip(rgba.pixels()) {
            let a = t[3] as u32;
            match a {
                0 => {
                    empty += 1;
                    assert_eq!((b.0, w.0), ([0; 3], [255; 3]), "{mode}: uncovered pixel");
                }
                255 => {
                    full += 1;
                    assert_eq!(
                        (b.0, w.0),
                        ([t[0], t[1], t[2]], [t[0], t[1], t[2]]),
                        "{mode}"
                    );
                }
                _ => {
                    partial += 1;
                    for k in 0..3 {
                        // Straight colour times alpha is the premultiplied one.
                        let pre = (t[k] as u32 * a + 127) / 255;
                        assert!(
                            pre.abs_diff(b[k] as u32) <= 1,
                            "{mode}: {t:?} over black {b:?}"
                        );
                        let over = b[k] as u32 + ((255 - a) * 255 + 127) / 255;
                        assert_eq!(w[k] as u32, over.min(255), "{mode}: {b:?} {t:?} {w:?}");
                    }
                }
            }
        }
        assert!(
            empty > 0 && full + partial > 0,
            "{mode}: {empty} {full} {partial}"
        );
        if mode == "composite" {
            assert!(partial > 0, "a composite has partly covered pixels");
        }
    }
    // Parts assemble to the same image over the same background.
    let whole = render("w.png", &["--background", "#336699"]).to_rgb8();
    for k in 0..2 {
        common::ok(
            common::cdvol()
                .args([
                    "render", "-q", "--width", "32", "--height", "28", "--view", "30,20",
                ])
                .args(["--shard", &format!("{k}/2")])
                .arg(&cdv)
                .arg("-o")
                .arg(d.join(format!("p{k}.cdvpart"))),
        );
    }
    let asm = d.join("asm.png");
    common::ok(
        common::cdvol()
            .args(["assemble", "--background", "51,102,153"])
            .arg(d.join("p0.cdvpart"))
            .arg(d.join("p1.cdvpart"))
            .arg("-o")
            .arg(&asm),
    );
    assert_eq!(image::open(&asm).unwrap().to_rgb8(), whole);
    let e = common::fails(
        common::cdvol()
            .args(["render", "-q", "--background", "transparent"])
            .arg(&cdv)
            .arg("-o")
            .arg(d.join("t.jpg")),
    );
    assert!(e.contains("JPEG has no alpha"), "{e}");
    assert!(!d.join("t.jpg").exists());
    let e = common::fails(
        common::cdvol()
            .args(["render", "-q", "--background", "pink"])
            .arg(&cdv)
            .arg("-o")
            .arg(d.join("x.png")),
    );
    assert!(e.contains("\"pink\""), "{e}");
}

/// `--bit-depth 16`: PNG and TIFF at 16 bits per channel, the same image
/// as the 8-bit one to within rounding, with finer steps where the 8-bit
/// one has few (a MIP window); JPEG refused.
#[test]
fn render_sixteen_bit_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cdv = small_head(d, "32,32,20", "-500", "head");
    let render =
        |name: &str, extra: &[&str]| image::open(render_40x36(&cdv, &d.join(name), extra)).unwrap();
    for (mode, name) in [("surface", "s"), ("mip", "m"), ("depth", "d")] {
        let a8 = render(&format!("{name}8.png"), &["--mode", mode]).to_rgb8();
        // The depth mode writes PNG only (with its .f32 and .depth16.png).
        let exts: &[&str] = if mode == "depth" {
            &["png"]
        } else {
            &["png", "tif"]
        };
        for ext in exts {
            let img = render(
                &format!("{name}16.{ext}"),
                &["--mode", mode, "--bit-depth", "16"],
            );
            let a16 = img.as_rgb16().expect("16-bit RGB").clone();
            let mut finer = false;
            for (p8, p16) in a8.pixels().zip(a16.pixels()) {
                for k in 0..3 {
                    let down = (p16[k] as f64 / 257.0).round() as i32;
                    assert!(
                        (down - p8[k] as i32).abs() <= 1,
                        "{mode} {ext}: {p8:?} {p16:?}"
                    );
                    finer |= p16[k] % 257 != 0;
                }
            }
            if mode != "surface" {
                assert!(finer, "{mode} {ext}: no level between the 8-bit ones");
            }
        }
    }
    let t = render(
        "t16.png",
        &["--bit-depth", "16", "--background", "transparent"],
    );
    assert!(t.as_rgba16().is_some());
    let e = common::fails(
        common::cdvol()
            .args(["render", "-q", "--bit-depth", "16"])
            .arg(&cdv)
            .arg("-o")
            .arg(d.join("x.jpg")),
    );
    assert!(e.contains("8 bits per channel"), "{e}");
}

/// `cdvol render` of `cdv` at 40 x 36, view 30,20, with `extra`, into
/// `out`; `out`.
fn render_40x36(cdv: &Path, out: &Path, extra: &[&str]) -> PathBuf {
    common::ok(
        common::cdvol()
            .args([
                "render", "-q", "--width", "40", "--height", "36", "--view", "30,20",
            ])
            .args(extra)
            .arg(cdv)
            .arg("-o")
            .arg(out),
    );
    out.to_path_buf()
}

/// One channel of float32 TIFF `path` (`--bit-depth 32` in the depth,
/// MIP and cost modes), read by the tiff crate.
fn gray_f32(path: &Path) -> (u32, u32, Vec<f32>) {
    let mut dec = tiff::decoder::Decoder::new(std::fs::File::open(path).unwrap()).unwrap();
    assert_eq!(dec.colortype().unwrap(), tiff::ColorType::Gray(32));
    let (w, h) = dec.dimensions().unwrap();
    match dec.read_image().unwrap() {
        tiff::decoder::DecodingResult::F32(v) => (w, h, v),
        _ => panic!("{}: not float32", path.display()),
    }
}

/// `--bit-depth 32`: float32 TIFFs holding the data of the depth (mm),
/// MIP (data units) and cost (steps) modes, NaN where rays miss, and the
/// unrounded colour of surface and composite, each checked against an
/// independent output of the same render: the depth mode's raw `.f32`,
/// a 16-bit MIP through a known window, `--stats` steps, the 8-bit image.
#[test]
fn render_float_outputs() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cdv = small_head(d, "32,32,20", "-500", "head");
    let render = |name: &str, extra: &[&str]| render_40x36(&cdv, &d.join(name), extra);
    // Depth: the TIFF holds exactly the raw .f32 beside a PNG render, and
    // is written alone.
    let png = render("d.png", &["--mode", "depth"]);
    let raw: Vec<f32> = std::fs::read(png.with_extension("f32"))
        .unwrap()
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    let tif = render("dt.tif", &["--mode", "depth", "--bit-depth", "32"]);
    let (w, h, v) = gray_f32(&tif);
    assert_eq!((w, h), (40, 36));
    assert_eq!(v.len(), raw.len());
    for (a, b) in v.iter().zip(&raw) {
        assert!(a.to_bits() == b.to_bits(), "depth {a} vs .f32 {b}");
    }
    assert!(v.iter().any(|x| x.is_nan()) && v.iter().any(|x| x.is_finite()));
    assert!(!tif.with_extension("f32").exists());
    // MIP: data values; a 16-bit image through the window 0..4000 gives
    // each hit pixel's value to within 4000 / 65535 (plus f32 rounding),
    // and misses (alpha 0 over transparent) are NaN.
    let m16 = render(
        "m16.png",
        &[
            "--mode",
            "mip",
            "--window",
            "4000",
            "--level",
            "2000",
            "--bit-depth",
            "16",
            "--background",
            "transparent",
        ],
    );
    let m16 = image::open(&m16).unwrap().to_rgba16();
    let (_, _, mv) = gray_f32(&render("m.tif", &["--mode", "mip", "--bit-depth", "32"]));
    let mut hits = 0;
    for (p, &x) in m16.pixels().zip(&mv) {
        if p[3] == 0 {
            assert!(x.is_nan(), "miss holds {x}");
            continue;
        }
        hits += 1;
        let from16 = p[0] as f64 / 65535.0 * 4000.0;
        if p[0] > 0 && p[0] < 65535 {
            assert!(
                (x as f64 - from16).abs() <= 0.07,
                "MIP {x} vs 16-bit {from16}"
            );
        }
    }
    assert!(hits > 100, "{hits} hits");
    // Cost: steps per pixel, summing to the statistics' steps.
    let stats = d.join("c.json");
    let c = render(
        "c.tif",
        &[
            "--mode",
            "cost",
            "--bit-depth",
            "32",
            "--stats",
            stats.to_str().unwrap(),
        ],
    );
    let (_, _, cv) = gray_f32(&c);
    let json: serde_json::Value = serde_json::from_slice(&std::fs::read(&stats).unwrap()).unwrap();
    let sum: f64 = cv.iter().map(|&x| x as f64).sum();
    assert_eq!(sum, json["steps"].as_f64().unwrap());
    // Surface: RGB float within half a level of the 8-bit PNG; RGBA over
    // a transparent background.
    let s8 = image::open(render("s.png", &[])).unwrap().to_rgb8();
    let sf = image::open(render("s.tif", &["--bit-depth", "32"])).unwrap();
    let sf = sf.as_rgb32f().expect("float RGB").clone();
    for (p8, pf) in s8.pixels().zip(sf.pixels()) {
        for k in 0..3 {
            assert!(
                (pf[k] * 255.0 - p8[k] as f32).abs() <= 0.5 + 1e-3,
                "{p8:?} {pf:?}"
            );
        }
    }
    let t = image::open(render(
        "t.tif",
        &["--bit-depth", "32", "--background", "transparent"],
    ))
    .unwrap();
    assert!(t.as_rgba32f().is_some());
    // Refused before any ray: float outside TIFF; a depth TIFF at 8 bits.
    let e = common::fails(
        common::cdvol()
            .args(["render", "-q", "--bit-depth", "32"])
            .arg(&cdv)
            .arg("-o")
            .arg(d.join("x.png")),
    );
    assert!(e.contains("TIFF only"), "{e}");
    let e = common::fails(
        common::cdvol()
            .args(["render", "-q", "--mode", "depth"])
            .arg(&cdv)
            .arg("-o")
            .arg(d.join("x.tif")),
    );
    assert!(e.contains("--bit-depth 32"), "{e}");
}

/// A CT phantom of `dims` (`X,Y,Z`) in `dir`, prepared at `iso` as
/// `NAME.cdv`; its path.
fn small_head(dir: &Path, dims: &str, iso: &str, name: &str) -> PathBuf {
    let head = dir.join("head.json");
    common::ok(
        common::cdvol()
            .args(["phantom", "ct", "-q", "--dims", dims, "-o"])
            .arg(&head),
    );
    let cdv = dir.join(format!("{name}.cdv"));
    common::ok(
        common::cdvol()
            .args(["prep", "-q", "--iso", iso])
            .arg(&head)
            .arg("-o")
            .arg(&cdv),
    );
    cdv
}

/// `--scale-bar`: the bar is exactly `mm / (frame / height)` pixels long,
/// white, outlined in black, on the bottom margin; nothing outside its box
/// and label changes; views and outputs without a single scale are refused
/// before any file is written.
#[test]
fn render_scale_bar() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cdv = small_head(d, "32,32,20", "300", "head");
    // 400 x 300 pixels over a 60 mm frame: 0.2 mm a pixel; margin 6.
    let render = |name: &str, extra: &[&str]| {
        let out = d.join(name);
        common::ok(
            common::cdvol()
                .args([
                    "render", "-q", "--width", "400", "--height", "300", "--frame", "60",
                ])
                .args(["--view", "30,20", "--background", "128,128,128"])
                .args(extra)
                .arg(&cdv)
                .arg("-o")
                .arg(&out),
        );
        image::open(&out).unwrap().to_rgb8()
    };
    let plain = render("plain.png", &[]);
    for (extra, bar_px) in [(&["--scale-bar"][..], 100u32), (&["--scale-bar=5"][..], 25)] {
        let img = render("bar.png", extra);
        // Auto: a quarter of 400 px is 20 mm, a 1-2-5 length: 100 px.
        let row = 292; // the middle of the bar's rows 291..294
        for x in 0..400 {
            let want = if (6..6 + bar_px).contains(&x) {
                Some(255)
            } else if x == 5 || x == 6 + bar_px {
                Some(0)
            } else {
                None
            };
            if let Some(v) = want {
                assert_eq!(img.get_pixel(x, row).0, [v; 3], "{extra:?}: x {x}");
            }
        }
        // The label: white pixels in its rows (282..289) above the bar.
        let label = (282..289)
            .flat_map(|y| (6..60).map(move |x| (x, y)))
            .filter(|&(x, y)| img.get_pixel(x, y).0 == [255; 3])
            .count();
        assert!(label > 20, "{extra:?}: {label} label pixels");
        for (x, y, p) in img.enumerate_pixels() {
            let inside = (5..=6 + bar_px.max(60)).contains(&x) && (281..=294).contains(&y);
            assert!(
                inside || p == plain.get_pixel(x, y),
                "{extra:?}: ({x}, {y}) changed"
            );
        }
    }
    // Refused, naming the option, with no output written.
    for (extra, words) in [
        (&["--persp"][..], "perspective"),
        (&["--mode", "depth", "--bit-depth", "32"][..], "float32"),
        (&["--scale-bar=1000"][..], "does not fit"),
    ] {
        let out = d.join("refused.tif");
        let mut c = common::cdvol();
        c.args([
            "render", "-q", "--width", "400", "--height", "300", "--frame", "60",
        ])
        .args(extra);
        if !extra.iter().any(|a| a.starts_with("--scale-bar")) {
            c.arg("--scale-bar");
        }
        let err = common::fails(c.arg(&cdv).arg("-o").arg(&out));
        assert!(
            err.contains("--scale-bar") && err.contains(words),
            "{extra:?}: {err}"
        );
        assert!(!out.exists());
    }
}
