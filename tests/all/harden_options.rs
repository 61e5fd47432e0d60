//! Every numeric option is bounded (issue 17, item 9): a value past its
//! bound is refused at once, naming the flag and the bound, instead of
//! running for minutes (`--bisect-iters 4000000000`), running 58x slower
//! (`--cache-mb 0`) or being reported under another flag (`--orbit inf`).
//! docs/RELIABILITY.md ("Option bounds") names the test.

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use cdvol::progress::NoProgress;
use cdvol::tools::phantom;

/// Runs `c` for 20 s at most; requires a non-zero exit and returns stderr.
fn refused_quickly(c: &mut Command) -> String {
    let o = crate::common::run(c, Duration::from_secs(20));
    assert!(
        !o.status.success(),
        "{c:?} succeeded, expected a refusal: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn setup(dir: &Path) {
    phantom::ct(
        &dir.join("in/ct.json"),
        &phantom::CtOptions {
            dims: [16, 14, 12],
            ..Default::default()
        },
        &NoProgress,
    )
    .unwrap();
    crate::common::packed(&dir.join("in/ct.json"), &dir.join("ct.cdv"), 300.0);
}

#[test]
fn numeric_options_past_their_bounds_are_refused_naming_flag_and_bound() {
    let dir = tempfile::tempdir().unwrap();
    setup(dir.path());
    let render = |extra: &[&str]| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_cdvol"));
        c.current_dir(dir.path())
            .args(["render", "-q", "ct.cdv", "-o", "r.png", "--width", "32"])
            .args(["--height", "32"])
            .args(extra);
        c
    };
    let mut failures = Vec::new();
    let cases: &[(&[&str], &[&str])] = &[
        (
            &["--hit", "bisect", "--bisect-iters", "4000000000"],
            &["--bisect-iters", "4000000000", "at most 200"],
        ),
        (
            &["--hit", "newton", "--newton-iters", "4000000000"],
            &["--newton-iters", "at most 200"],
        ),
        (&["--cache-mb", "0"], &["--cache-mb", "0", "at least 1"]),
        (&["--threads", "0"], &["--threads", "0", "1..=1024"]),
        (
            &["--threads", "100000"],
            &["--threads", "100000", "1..=1024"],
        ),
        (&["--frames", "2", "--orbit", "inf"], &["--orbit", "finite"]),
    ];
    for (args, want) in cases {
        let e = refused_quickly(&mut render(args));
        if let Some(w) = want.iter().find(|w| !e.contains(*w)) {
            failures.push(format!("{args:?}: {w:?} not in {e}"));
        }
    }
    for (jobs, want) in [("0", "1..=256"), ("100000", "1..=256")] {
        let e = refused_quickly(
            Command::new(env!("CARGO_BIN_EXE_cdvol"))
                .current_dir(dir.path())
                .args(["prep-batch", "-q", "in", "-o", "out", "--iso", "300"])
                .args(["--jobs", jobs]),
        );
        if !(e.contains("--jobs") && e.contains(want)) {
            failures.push(format!("--jobs {jobs}: {want:?} not in {e}"));
        }
    }
    assert!(failures.is_empty(), "{failures:#?}");
}
