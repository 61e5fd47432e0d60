//! No Debug text in messages meant for people (issue 51, item 9): `info`,
//! the errors of the command line and the error bodies of `serve` are
//! scanned for what Rust's `{:?}` prints: `None`, `Some(`, braces, and the
//! names of the types behind them. Before, `info` printed `codes
//! IntRange { base: -32768, max: 254 }` and the classification as JSON,
//! and serve answered `view="anterior az=0 el=0 frame=None pan=None"` and
//! "expected unknown preset".

use std::path::Path;

use crate::common::{cdvol, ok};
use crate::hostile_serve::{exchange, Serve};
use crate::serve::head;

/// Words `{:?}` leaves in text.
const DEBUG: [&str; 12] = [
    "None",
    "Some(",
    "{",
    "}",
    "IntRange",
    "NanPayload",
    "DVec3",
    "Error {",
    "Os {",
    "kind:",
    "expected unknown",
    "Custom {",
];

fn plain(what: &str, text: &str) {
    for w in DEBUG {
        assert!(!text.contains(w), "{what}: Debug text {w:?} in:\n{text}");
    }
}

fn stderr_of(dir: &Path, args: &[&str]) -> String {
    let o = cdvol().current_dir(dir).args(args).output().unwrap();
    assert!(!o.status.success(), "{args:?} succeeded");
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn info_errors_and_serve_answers_are_plain_text() {
    let d = tempfile::tempdir().unwrap();
    let packed = head(d.path());
    let bone = d.path().join("bone.cdv");
    ok(cdvol()
        .arg("prep")
        .arg(d.path().join("head.json"))
        .args(["-q", "--preset", "ct-bone", "--brick", "16", "-o"])
        .arg(&bone));
    for f in [&packed, &bone] {
        let text = ok(cdvol().arg("info").arg(f));
        plain("info", &text);
        assert!(text.contains("codes        integer words"), "{text}");
    }
    std::fs::write(d.path().join("picture.png"), b"\x89PNG\r\n\x1a\n0000").unwrap();
    for args in [
        vec!["render", "head.cdv", "-o", "x.png", "--preset", "no-such"],
        vec!["render", "head.cdv", "-o", "x.png", "--iso=-5000"],
        vec!["render", "head.cdv", "-o", "x.png", "--view", "sideways"],
        vec!["render", "head.cdv", "-o", "x.png", "--background", "plaid"],
        vec!["render", "head.cdv", "-o", "x.bmp"],
        vec![
            "render", "head.cdv", "-o", "x.png", "--eye", "1,2,3", "--target", "1,2,3",
        ],
        vec!["info", "picture.png"],
        vec!["info", "missing.cdv"],
        vec!["prep", "missing.json", "-o", "x.cdv", "--iso", "1"],
        vec!["export", "head.cdv", "--what", "values", "-o", "head.json"],
    ] {
        plain(&args.join(" "), &stderr_of(d.path(), &args));
    }
    let mut srv = Serve::start(&packed);
    for q in [
        "/api/image?preset=no-such",
        "/api/image?view=anterior",
        "/api/image?view=anterior&frame=5&pan=1,2",
        "/api/image?w=0",
        "/api/image?iso=-5000",
        "/api/image?nonsense=1",
        "/nowhere",
    ] {
        let (status, text) = exchange(
            &srv.addr,
            format!("GET {q} HTTP/1.0\r\nHost: localhost\r\n\r\n").as_bytes(),
        );
        if status == 200 {
            continue;
        }
        let body = text.split("\r\n\r\n").nth(1).unwrap_or("");
        plain(q, body);
    }
    srv.alive("the requests above");
}
