//! Memory is checked before allocating (issue 17, item 7): prep plans its
//! peak from a documented formula (`cdvol::prep::prep_memory`) and refuses,
//! with the figure and the limit, a prep above `--mem-limit` (default 3/4
//! of RAM) before it allocates. A sidecar of 1048576 x 1048576 x 2 u8
//! samples aborted the process (SIGABRT) before this.
//! docs/RELIABILITY.md ("Memory") names the tests.

use std::process::Command;

use crate::common::{fails, ok};

#[test]
fn a_prep_past_the_memory_limit_is_refused_with_the_figure() {
    let d = tempfile::tempdir().unwrap();
    // 2 TiB of samples, sparse: no disk is used.
    let raw = std::fs::File::create(d.path().join("huge.raw")).unwrap();
    raw.set_len(1 << 41).unwrap();
    std::fs::write(
        d.path().join("huge.json"),
        r#"{"data": "huge.raw", "dims": [1048576, 1048576, 2], "dtype": "u8", "x": 1, "y": 1, "z": 1}"#,
    )
    .unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_cdvol"))
        .current_dir(d.path())
        .args(["prep", "-q", "huge.json", "-o", "huge.cdv", "--iso", "100"])
        .output()
        .unwrap();
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "a named error, not a signal: {e}");
    for w in [
        "huge.json",
        "needs about",
        "TiB",
        "1048576 x 1048576",
        "memory limit",
    ] {
        assert!(e.contains(w), "{w:?} not in {e}");
    }
    assert!(!d.path().join("huge.cdv").exists());

    // A small prep under an explicit limit of 1 MiB: refused, naming it.
    // One sample at the iso value, so the classification selects cells.
    let mut s = vec![0u8; 16 * 16 * 4];
    s[16 * 16 + 16 + 1] = 9;
    std::fs::write(d.path().join("s.raw"), s).unwrap();
    std::fs::write(
        d.path().join("s.json"),
        r#"{"data": "s.raw", "dims": [16, 16, 4], "dtype": "u8", "x": 1, "y": 1, "z": 1}"#,
    )
    .unwrap();
    let prep = |limit: &str| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_cdvol"));
        c.current_dir(d.path())
            .args(["prep", "-q", "s.json", "-o", "s.cdv", "--iso", "1"])
            .args(["--mem-limit", limit]);
        c
    };
    let e = fails(&mut prep("1"));
    for w in ["s.json", "needs about", "1.0 MiB (--mem-limit)"] {
        assert!(e.contains(w), "{w:?} not in {e}");
    }
    ok(&mut prep("100"));
}

#[test]
fn the_prep_memory_formula_is_the_documented_one() {
    use cdvol::classify::Classification;
    use cdvol::prep::{prep_memory, PrepOptions};
    let d = tempfile::tempdir().unwrap();
    std::fs::write(d.path().join("s.raw"), vec![0u8; 512 * 512 * 2 * 20]).unwrap();
    std::fs::write(
        d.path().join("s.json"),
        r#"{"data": "s.raw", "dims": [512, 512, 20], "dtype": "u16", "x": 1, "y": 1, "z": 1}"#,
    )
    .unwrap();
    let src = cdvol::input::open(&d.path().join("s.json")).unwrap();
    let opts = PrepOptions::new(Classification::Iso { iso: 1.0 });
    let (per_sample, total) = prep_memory(src.meta(), &opts);
    // s = min(32, 19) + 1 = 20 slices; u16 words, widened to i32; pass 2
    // (backward planes, distances, words, compressed bricks, a slice as
    // f64) outweighs pass 1 (slice, flags, object plane, forward planes).
    let pass1 = 8 + 2 + 1 + 2;
    let pass2 = 2 + 20 + 20 * 4 + 20 * 2 + 8;
    assert_eq!(per_sample, pass1.max(pass2));
    assert!(total > per_sample * 512 * 512);
}

#[test]
fn a_render_past_the_memory_limit_is_refused_with_the_figure() {
    let d = tempfile::tempdir().unwrap();
    std::fs::write(d.path().join("s.raw"), vec![200u8; 16 * 16 * 4]).unwrap();
    std::fs::write(
        d.path().join("s.json"),
        r#"{"data": "s.raw", "dims": [16, 16, 4], "dtype": "u8", "x": 1, "y": 1, "z": 1}"#,
    )
    .unwrap();
    ok(Command::new(env!("CARGO_BIN_EXE_cdvol"))
        .current_dir(d.path())
        .args(["prep", "-q", "s.json", "-o", "s.cdv", "--iso", "1"]));
    let render = |side: &str, limit: &str, extra: &[&str]| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_cdvol"));
        c.current_dir(d.path())
            .args(["render", "-q", "s.cdv", "-o", "r.png"])
            .args(["--width", side, "--height", side, "--mem-limit", limit])
            .args(extra);
        c
    };
    // 16384^2 pixels of a surface in 8 bits, which the tiles colour
    // themselves, at 24 bytes: 6 GiB, refused before any ray.
    let e = fails(&mut render("16384", "4096", &[]));
    for w in ["--mem-limit", "16384 x 16384", "24 bytes", "4.0 GiB"] {
        assert!(e.contains(w), "{w:?} not in {e}");
    }
    // A depth map and a 16-bit image keep their pixels until the whole
    // image is made: 64 bytes.
    for extra in [&["--mode", "depth"][..], &["--bit-depth", "16"]] {
        let e = fails(&mut render("16384", "4096", extra));
        assert!(e.contains("64 bytes"), "{extra:?}: {e}");
    }
    assert!(!d.path().join("r.png").exists());
    // 2048^2 pixels under 200 MiB: a surface (96 MiB of pixels + 64 MiB)
    // fits, a depth map (256 MiB of pixels) does not.
    ok(&mut render("2048", "200", &[]));
    assert!(d.path().join("r.png").exists());
    let e = fails(&mut render("2048", "200", &["--mode", "depth"]));
    assert!(e.contains("64 bytes"), "{e}");
    // A small render of a small file fits 100 MiB: the cache counts at
    // most the whole volume decoded, not its 512 MiB budget.
    ok(&mut render("64", "100", &[]));
}
