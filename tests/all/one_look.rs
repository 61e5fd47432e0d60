//! One place for each decision (issue 52, item 4): `cdvol render` and
//! `cdvol serve` resolve a preset, an iso value, a window, the composite
//! look and the default traversal through the same library function
//! (`cdvol::look::resolve`, `cdvol::render::default_method`), so the same
//! request gives the same render options in both.

use std::path::Path;

use clap::FromArgMatches;

use cdvol::format::reader::PackedVolume;
use cdvol::render::RenderOptions;
use cdvol::serve::request::ViewRequest;

use crate::cli;
use crate::common::prepared_ct_phantom;

/// The render options `cdvol render FILE -o x.png ARGS` would use.
fn cli_options(vol: &PackedVolume, file: &Path, args: &[&str]) -> RenderOptions {
    let argv = ["cdvol", "render"]
        .iter()
        .map(|s| s.to_string())
        .chain([file.display().to_string(), "-o".into(), "x.png".into()])
        .chain(args.iter().map(|s| s.to_string()));
    let m = cli::command().try_get_matches_from(argv).unwrap();
    match cli::Cli::from_arg_matches(&m).unwrap().command {
        cli::Command::Render(a) => a.job(vol).unwrap().options,
        c => panic!("{c:?}"),
    }
}

/// The render options `serve` uses for query `q`.
fn serve_options(vol: &PackedVolume, q: &str) -> RenderOptions {
    let req = ViewRequest::parse(q, 1).unwrap();
    let cli_cache = RenderOptions::new(
        cdvol::render::Mode::Mip,
        cdvol::render::default_method(vol.header()),
    )
    .cache_bytes;
    req.options(vol.header(), cli_cache).unwrap()
}

/// What a look decides, for comparison.
fn decided(o: &RenderOptions) -> String {
    format!(
        "{:?} | {:?} | {:?} | {:?} | {:?}",
        o.mode, o.iso, o.window, o.look, o.method
    )
}

#[test]
fn render_and_serve_resolve_a_look_alike() {
    let d = tempfile::tempdir().unwrap();
    // A file prepared with a preset (its look), with octant codes (its
    // default traversal is cd-aniso).
    let looked = prepared_ct_phantom(d.path(), "looked", &["--preset", "ct-bone", "--aniso"]);
    let plain = prepared_ct_phantom(d.path(), "plain", &["--envelope", "auto"]);
    let cases: [(&Path, &[&str], &str); 9] = [
        (&looked, &[], "mode=composite"),
        (&looked, &["--mode", "composite"], "mode=composite"),
        (
            &looked,
            &["--preset", "ct-bone"],
            "mode=surface&preset=ct-bone",
        ),
        (
            &looked,
            &["--mode", "cost", "--preset", "ct-skin"],
            "mode=cost&preset=ct-skin",
        ),
        (
            &plain,
            &["--mode", "composite", "--preset", "ct-soft-tissue"],
            "mode=composite&preset=ct-soft-tissue",
        ),
        (
            &plain,
            &["--mode", "mip", "--preset", "ct-mip"],
            "mode=mip&preset=ct-mip",
        ),
        (
            &plain,
            &["--mode", "mip", "--window", "400", "--level", "40"],
            "mode=mip&window=400&level=40",
        ),
        (&plain, &["--iso", "-300"], "mode=surface&iso=-300"),
        (&plain, &["--mode", "mip"], "mode=mip"),
    ];
    for (file, args, q) in cases {
        let vol = PackedVolume::open(file).unwrap();
        let a = decided(&cli_options(&vol, file, args));
        let b = decided(&serve_options(&vol, q));
        assert_eq!(a, b, "render {args:?} against serve {q:?}");
    }
}

/// `--tf` without `--mode` keeps the file's look out, as `--iso` does: the
/// render is a surface, as before the look was resolved in one place.
#[test]
fn a_tf_without_a_mode_keeps_the_files_look_out() {
    let d = tempfile::tempdir().unwrap();
    let looked = prepared_ct_phantom(d.path(), "looked", &["--preset", "ct-bone"]);
    let tf = d.path().join("tf.json");
    let bone = cdvol::presets::get("ct-bone").unwrap();
    std::fs::write(&tf, serde_json::to_string(&bone.tf).unwrap()).unwrap();
    let vol = PackedVolume::open(&looked).unwrap();
    let tf_arg = tf.display().to_string();
    let o = cli_options(&vol, &looked, &["--tf", &tf_arg]);
    assert_eq!(o.mode.name(), "surface");
    let o = cli_options(&vol, &looked, &["--tf", &tf_arg, "--mode", "composite"]);
    assert_eq!(o.mode.name(), "composite");
    let o = cli_options(&vol, &looked, &[]);
    assert_eq!(o.mode.name(), "composite", "the file's look");
}
