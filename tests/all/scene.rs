//! Render-time classification (`render --iso`, issue 16): a file prepared
//! at iso E renders any iso V >= E exactly. Surface and depth images are
//! byte-identical to those of a file prepared at V, for every traversal,
//! both normals, shadows, on the real CT and the phantoms, plain, halo and
//! transfer-function files; outside the envelope it is refused with the
//! prep command that covers it.

use std::path::Path;

use crate::common::{self, cdvol, fails, ok, orbit, packed_with, same_frame, white_tf};

use cdvol::classify::Classification;
use cdvol::format::reader::PackedVolume;
use cdvol::prep::{prep, PrepOptions};
use cdvol::progress::NoProgress;
use cdvol::render::brick::{Planes, RBrick};
use cdvol::render::cache::{BrickCache, CacheCounters};
use cdvol::render::sample::hit::HitMethod;
use cdvol::render::traverse::{Method, OBJECT};
use cdvol::render::{render, Mode, Normals, RenderOptions};
use cdvol::tools::phantom;

/// The modes whose images must match: surface (both normals, with and
/// without shadows) and depth.
fn modes() -> Vec<(Mode, Normals)> {
    let surface = |shadows| Mode::Surface {
        hit: HitMethod::Int,
        shadows,
    };
    vec![
        (surface(false), Normals::Smooth),
        (surface(true), Normals::Smooth),
        (surface(false), Normals::Cell),
        (
            Mode::Depth {
                hit: HitMethod::Newton,
            },
            Normals::Smooth,
        ),
    ]
}

/// Renders `envelope` at scene iso `v` and `own` (prepared at `v`) with
/// each traversal, mode and view, and requires the same bytes. Returns
/// the CD steps of each (envelope, own), summed.
fn same_as_own(envelope: &PackedVolume, own: &PackedVolume, v: f64, what: &str) -> (u64, u64) {
    let mut steps = (0, 0);
    for view in [[30.0, 20.0], [200.0, -40.0], [90.0, 0.0]] {
        let cam = orbit(own, view, None, 48, 48);
        for method in [Method::Fvt, Method::Cd { min_leap: 1 }] {
            for (mode, normals) in modes() {
                let base = RenderOptions {
                    tile: 16,
                    cache_bytes: 64 << 20,
                    cd_lazy_min: Some(4),
                    normals,
                    ..RenderOptions::new(mode.clone(), method)
                };
                let (want, sw) = render(own, &cam, &base, &NoProgress).unwrap();
                let o = RenderOptions {
                    iso: Some(v),
                    ..base.clone()
                };
                let (got, sg) = render(envelope, &cam, &o, &NoProgress).unwrap();
                assert!(
                    same_frame(&got, &want),
                    "{what}: iso {v} from the envelope differs from a file prepared at {v} \
                     ({mode:?}, {normals:?}, {method:?}, view {view:?})"
                );
                assert!(sw.hits > 0, "{what}: the scene at {v} shows nothing");
                if method != Method::Fvt {
                    steps.0 += sg.steps;
                    steps.1 += sw.steps;
                }
            }
        }
    }
    steps
}

fn ct_phantom(dir: &Path) -> std::path::PathBuf {
    let side = dir.join("head.json");
    phantom::ct(
        &side,
        &phantom::CtOptions {
            dims: [56, 52, 40],
            seed: 5,
            ..Default::default()
        },
        &NoProgress,
    )
    .unwrap();
    side
}

#[test]
fn iso_inside_the_envelope_matches_a_file_prepared_for_it() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let ct = common::real_ct();
    let head = ct_phantom(d);
    for (name, input, envelope_iso, isos) in [
        ("real CT", &ct, 300.0, &[300.0, 500.0, 1000.0][..]),
        ("CT phantom", &head, -200.0, &[0.0, 400.0][..]),
    ] {
        for halo in [false, true] {
            let env = packed_with(
                input,
                &d.join(format!("env{halo}.cdv")),
                envelope_iso,
                |o| o.gradient_halo = halo,
            );
            for &v in isos {
                let own = packed_with(input, &d.join(format!("own{halo}{v}.cdv")), v, |o| {
                    o.gradient_halo = halo
                });
                same_as_own(&env, &own, v, &format!("{name}, halo {halo}"));
            }
        }
    }
}

#[test]
fn iso_on_sphere_phantoms_and_rectilinear_grids() {
    let dir = tempfile::tempdir().unwrap();
    for (n, spacing) in [(2, "1"), (5, "0.8,1,0.5:2")] {
        let side = dir.path().join(format!("s{n}.json"));
        let info = phantom::spheres(
            &side,
            &phantom::SpheresOptions {
                size: 40,
                per_axis: n,
                seed: 3,
                spacing: phantom::parse_spacing3(spacing).unwrap(),
            },
            &NoProgress,
        )
        .unwrap();
        // The spheres are a distance field: an envelope well below the
        // surface, and scenes up to it and past it.
        let env = packed_with(&side, &dir.path().join("env.cdv"), info.iso * 0.5, |_| {});
        for v in [info.iso * 0.75, info.iso] {
            let own = packed_with(&side, &dir.path().join(format!("own{v}.cdv")), v, |_| {});
            let (e, o) = same_as_own(&env, &own, v, &format!("spheres N={n}"));
            // Tightened codes still leap: far fewer steps than single
            // cells would take, if more than the scene's own codes.
            assert!(
                e >= o,
                "N={n} iso {v}: {e} steps from the envelope, {o} own"
            );
        }
    }
}

/// A file classified by a transfer function renders surfaces at any iso
/// where the function is non-zero from there up.
#[test]
fn iso_inside_a_transfer_function_envelope() {
    let dir = tempfile::tempdir().unwrap();
    let head = ct_phantom(dir.path());
    let tf = white_tf(&[(-300.0, 0.0), (-250.0, 0.1), (2000.0, 0.9)]);
    let src = cdvol::input::open(&head).unwrap();
    let mut o = PrepOptions::new(Classification::TransferFunction { tf });
    o.brick_size = 16;
    let out = dir.path().join("tf.cdv");
    prep(src.as_ref(), &out, &o, &NoProgress).unwrap();
    let env = PackedVolume::open(&out).unwrap();
    for v in [-250.0, 100.0] {
        let own = packed_with(&head, &dir.path().join(format!("own{v}.cdv")), v, |_| {});
        same_as_own(&env, &own, v, "transfer-function file");
    }
    // At -300 the function is zero: a cell reaching only -300 was 0-cell.
    let cam = orbit(&env, [30.0, 20.0], None, 16, 16);
    let o = RenderOptions {
        iso: Some(-300.0),
        ..RenderOptions::new(
            Mode::Surface {
                hit: HitMethod::Int,
                shadows: false,
            },
            Method::Cd { min_leap: 1 },
        )
    };
    let e = render(&env, &cam, &o, &NoProgress).unwrap_err().to_string();
    assert!(e.contains("outside the file's envelope"), "{e}");
}

#[test]
fn iso_outside_the_envelope_is_refused_with_the_prep_command() {
    let dir = tempfile::tempdir().unwrap();
    let head = ct_phantom(dir.path());
    let cdv = dir.path().join("head.cdv");
    ok(cdvol()
        .args(["prep", "-q", "--iso", "300"])
        .arg(&head)
        .arg("-o")
        .arg(&cdv));
    let png = dir.path().join("x.png");
    // Below the envelope: refused, nothing written, the command named.
    let e = fails(
        cdvol()
            .args([
                "render", "-q", "--iso", "250", "--width", "16", "--height", "16",
            ])
            .arg(&cdv)
            .arg("-o")
            .arg(&png),
    );
    let want = format!("cdvol prep --iso 250 {}", head.display());
    assert!(e.contains(&want), "{e}");
    assert!(!png.exists());
    // Composite takes its transfer function, not an iso value.
    let tf = dir.path().join("tf.json");
    std::fs::write(
        &tf,
        r#"{"points": [{"value": 300, "opacity": 0}, {"value": 900, "opacity": 0.5}]}"#,
    )
    .unwrap();
    let e = fails(
        cdvol()
            .args([
                "render",
                "-q",
                "--iso",
                "400",
                "--mode",
                "composite",
                "--tf",
            ])
            .arg(&tf)
            .arg(&cdv)
            .arg("-o")
            .arg(&png),
    );
    assert!(e.contains("iso") && e.contains("composite"), "{e}");
    // Inside: written, and the same bytes as a file prepared there.
    ok(cdvol()
        .args([
            "render", "-q", "--iso", "600", "--width", "40", "--height", "40",
        ])
        .arg(&cdv)
        .arg("-o")
        .arg(&png));
    let own = dir.path().join("own.cdv");
    ok(cdvol()
        .args(["prep", "-q", "--iso", "600"])
        .arg(&head)
        .arg("-o")
        .arg(&own));
    let png2 = dir.path().join("y.png");
    ok(cdvol()
        .args(["render", "-q", "--width", "40", "--height", "40"])
        .arg(&own)
        .arg("-o")
        .arg(&png2));
    assert_eq!(std::fs::read(&png).unwrap(), std::fs::read(&png2).unwrap());
}

/// `render --preset`: the preset's iso value in surface mode, its window
/// in MIP mode (the image's own for the MIP presets), its transfer
/// function in composite mode; a preset without an iso value draws the
/// surface where its transfer function's opacity begins.
#[test]
fn render_presets_are_their_settings() {
    let dir = tempfile::tempdir().unwrap();
    let head = ct_phantom(dir.path());
    let cdv = dir.path().join("head.cdv");
    ok(cdvol()
        .args(["prep", "-q", "--iso", "-1000"])
        .arg(&head)
        .arg("-o")
        .arg(&cdv));
    let bone = cdvol::presets::get("ct-bone").unwrap();
    let w = bone.window.unwrap();
    let render = |name: &str, args: &[String]| {
        let out = dir.path().join(name);
        ok(cdvol()
            .args(["render", "-q", "--width", "40", "--height", "40"])
            .args(args)
            .arg(&cdv)
            .arg("-o")
            .arg(&out));
        std::fs::read(&out).unwrap()
    };
    let s = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();
    assert_eq!(
        render("p.png", &s(&["--preset", "ct-bone"])),
        render("i.png", &s(&["--iso", &bone.iso.unwrap().to_string()]))
    );
    assert_eq!(
        render("pm.png", &s(&["--mode", "mip", "--preset", "ct-mip"])),
        render("am.png", &s(&["--mode", "mip"]))
    );
    assert_eq!(
        render("bm.png", &s(&["--mode", "mip", "--preset", "ct-bone"])),
        render(
            "wm.png",
            &s(&[
                "--mode",
                "mip",
                "--window",
                &w.width.to_string(),
                "--level",
                &w.level.to_string()
            ])
        )
    );
    let tf = dir.path().join("bone.json");
    std::fs::write(&tf, serde_json::to_string(&bone.tf).unwrap()).unwrap();
    let mut comp = s(&["--mode", "composite", "--tf"]);
    comp.push(tf.display().to_string());
    let mut shaded = comp.clone();
    if bone.shade {
        shaded.push("--shade".into());
    }
    assert_eq!(
        render(
            "pc.png",
            &s(&["--mode", "composite", "--preset", "ct-bone"])
        ),
        render("tc.png", &shaded)
    );
    let lung = cdvol::presets::get("ct-lung").unwrap();
    assert_eq!(lung.iso, None);
    assert_eq!(
        render("pl.png", &s(&["--preset", "ct-lung"])),
        render(
            "il.png",
            &s(&["--iso", &lung.tf.iso_floor().unwrap().to_string()])
        )
    );
}

/// `prep --envelope ct`: one file from which every CT preset renders, in
/// composite and (where it has an iso value) surface mode, with no second
/// prep; `info` lists them; an unknown item is refused by name.
#[test]
fn one_envelope_prep_serves_every_ct_preset() {
    let dir = tempfile::tempdir().unwrap();
    let head = ct_phantom(dir.path());
    let cdv = dir.path().join("env.cdv");
    ok(cdvol()
        .args(["prep", "-q", "--envelope", "ct"])
        .arg(&head)
        .arg("-o")
        .arg(&cdv));
    let (iso, covers) =
        cdvol::presets::envelope(&["ct".to_string()], cdvol::presets::all()).unwrap();
    let ct: Vec<_> = cdvol::presets::all()
        .iter()
        .filter(|p| p.modality == cdvol::presets::Modality::Ct)
        .collect();
    assert_eq!(covers.len(), ct.len());
    for p in &ct {
        assert!(p.tf.iso_floor().unwrap() >= iso && p.iso.is_none_or(|v| v >= iso));
        let mut modes = vec!["composite"];
        if p.iso.is_some() {
            modes.push("surface");
        }
        for mode in modes {
            ok(cdvol()
                .args([
                    "render", "-q", "--width", "24", "--height", "24", "--mode", mode,
                ])
                .args(["--preset", &p.name])
                .arg(&cdv)
                .arg("-o")
                .arg(dir.path().join(format!("{}-{mode}.png", p.name))));
        }
    }
    let info: serde_json::Value =
        serde_json::from_str(&ok(cdvol().args(["info", "--json"]).arg(&cdv))).unwrap();
    let listed = info["envelope"]["composite_presets"].as_array().unwrap();
    for p in &ct {
        assert!(listed.iter().any(|x| x == p.name.as_str()), "{}", p.name);
    }
    // A file prepared at bone's iso does not cover the skin preset.
    let bone = dir.path().join("bone.cdv");
    ok(cdvol()
        .args(["prep", "-q", "--envelope", "ct-bone"])
        .arg(&head)
        .arg("-o")
        .arg(&bone));
    fails(
        cdvol()
            .args(["render", "-q", "--mode", "composite", "--preset", "ct-skin"])
            .arg(&bone)
            .arg("-o")
            .arg(dir.path().join("x.png")),
    );
    let e = fails(
        cdvol()
            .args(["prep", "-q", "--envelope", "ct,bogus"])
            .arg(&head)
            .arg("-o")
            .arg(dir.path().join("y.cdv")),
    );
    assert!(e.contains("\"bogus\"") && e.contains("ct-bone"), "{e}");
}

/// `prep-batch --envelope auto`: per input, the envelope of its modality
/// (CT for the phantom in HU, MR for non-negative intensities), recorded
/// in batch.json; a re-run skips both.
#[test]
fn batch_envelope_auto_picks_each_inputs_modality() {
    let dir = tempfile::tempdir().unwrap();
    let inp = dir.path().join("in");
    std::fs::create_dir(&inp).unwrap();
    ct_phantom(&inp);
    let mr: Vec<u8> = (0..24 * 20 * 16)
        .flat_map(|i: u32| (((i * 7919) % 131) as u16).to_le_bytes())
        .collect();
    std::fs::write(inp.join("mr.raw"), mr).unwrap();
    std::fs::write(
        inp.join("mr.json"),
        r#"{"data": "mr.raw", "dims": [24, 20, 16], "dtype": "u16", "x": 1, "y": 1, "z": 1}"#,
    )
    .unwrap();
    let out = dir.path().join("out");
    let run = || {
        ok(cdvol()
            .args(["prep-batch", "-q", "--envelope", "auto"])
            .arg(&inp)
            .arg("-o")
            .arg(&out));
        let j: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("batch.json")).unwrap())
                .unwrap();
        j
    };
    let first = run();
    let rows = first
        .as_array()
        .or_else(|| first["inputs"].as_array())
        .unwrap()
        .clone();
    for (name, modality, group) in [("head.json", "CT", "ct"), ("mr.json", "MR", "mr")] {
        let row = rows.iter().find(|r| r["input"] == name).unwrap();
        let m = row["modality"].as_str().unwrap();
        assert!(m.starts_with(modality), "{name}: {m}");
        let vol =
            PackedVolume::open(std::path::Path::new(row["output"].as_str().unwrap())).unwrap();
        // MR presets are placed on the landmarks prep recorded.
        let placed = cdvol::look::placed(vol.header());
        let (iso, _) = cdvol::presets::envelope(&[group.into()], &placed).unwrap();
        assert_eq!(
            vol.header().classification,
            Classification::Iso { iso },
            "{name}"
        );
    }
    let again = run();
    let rows = again
        .as_array()
        .or_else(|| again["inputs"].as_array())
        .unwrap();
    assert!(rows.iter().all(|r| r["status"] == "skipped"), "{again}");
}

/// `file` (format version 2) as format version 1 wrote it: no index value
/// maxima, version 1 in preamble, header and footer, the CRC rewritten.
fn as_version(file: &[u8], version: u32) -> Vec<u8> {
    use cdvol::format::INDEX_ENTRY_LEN;
    let mut f = file.to_vec();
    let (trailer, hlen, ilen) = common::footer(&f);
    if version == 1 {
        for e in f[trailer + hlen..trailer + hlen + ilen].chunks_exact_mut(INDEX_ENTRY_LEN) {
            let flags = u32::from_le_bytes(e[16..20].try_into().unwrap()) & !4;
            e[16..20].copy_from_slice(&flags.to_le_bytes());
            e[24..32].fill(0);
        }
    }
    f[8..12].copy_from_slice(&version.to_le_bytes());
    let mut f = common::rewrite_header(&f, |h| h["format_version"] = version.into());
    let n = f.len();
    f[n - 12..n - 8].copy_from_slice(&version.to_le_bytes());
    f
}

/// Format version 2's index value maxima: a render at an iso above a
/// brick's maximum reads it for its codes only. At an iso exactly equal to
/// one brick's maximum (the boundary: a vertex at the iso value makes a
/// 1-cell), images still match a file prepared at that iso, and so do
/// those of the same file rewritten as format version 1, which has no
/// maxima; version 4 is refused by name.
#[test]
fn index_value_maxima_skip_values_and_version_1_still_reads() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let ct = common::real_ct();
    // Version 2 (no byte planes), so that it can be rewritten as version
    // 1 below by its header and index alone.
    let env = packed_with(&ct, &d.join("env.cdv"), 300.0, |o| o.format_version = 2);
    let mut maxima: Vec<f64> = env.index().iter().filter_map(|e| e.value_max()).collect();
    maxima.sort_by(f64::total_cmp);
    assert!(maxima.len() > 10, "{} bricks with maxima", maxima.len());
    let v = maxima[maxima.len() / 2];
    assert!(v > 300.0 && maxima[0] < v, "maxima {maxima:?}");
    let own = packed_with(&ct, &d.join("own.cdv"), v, |_| {});
    same_as_own(&env, &own, v, "version 2, iso at a brick maximum");
    // Brick by brick, the scene's 1-cells in the narrowed envelope are
    // those prep found for `v` (a cell with a vertex exactly at `v` is
    // one: images alone would not show a brick wrongly skipped there).
    let narrowed = BrickCache::with_planes(
        &env,
        64 << 20,
        Planes {
            narrow: Some(v as f32),
            ..Planes::NONE
        },
    );
    let plain = BrickCache::with_planes(&own, 64 << 20, Planes::NONE);
    let mut c = CacheCounters::default();
    let mut at_max = 0;
    for id in 0..env.index().len() as u64 {
        let (a, b) = (
            narrowed.get(id, None, &mut c).unwrap(),
            plain.get(id, None, &mut c).unwrap(),
        );
        let objects = |r: &RBrick| -> Vec<[u32; 3]> {
            let [x, y, z] = r.cells;
            (0..z)
                .flat_map(|k| (0..y).flat_map(move |j| (0..x).map(move |i| [i, j, k])))
                .filter(|&l| r.code(l) == OBJECT)
                .collect()
        };
        assert_eq!(objects(&a), objects(&b), "brick {id}: the scene's 1-cells");
        at_max += usize::from(env.index()[id as usize].value_max() == Some(v));
    }
    assert!(at_max >= 1);

    let bytes = std::fs::read(d.join("env.cdv")).unwrap();
    let v1 = d.join("v1.cdv");
    std::fs::write(&v1, as_version(&bytes, 1)).unwrap();
    let old = PackedVolume::open(&v1).unwrap();
    assert_eq!(old.header().format_version, 1);
    assert!(old.index().iter().all(|e| e.value_max().is_none()));
    same_as_own(&old, &own, v, "version 1");

    let v4 = d.join("v4.cdv");
    std::fs::write(&v4, as_version(&bytes, 4)).unwrap();
    let e = PackedVolume::open(&v4).err().unwrap().to_string();
    assert!(
        e.contains("format version 4") && e.contains("versions 1 to 3"),
        "{e}"
    );
}
