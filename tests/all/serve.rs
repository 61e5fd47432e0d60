//! `cdvol serve` end to end (issue 18): the built binary listens on an
//! ephemeral port, a tiny HTTP client below asks it for pages and images,
//! and the images are compared byte for byte with what `cdvol render`
//! writes for the same view. Bad requests, path traversal, concurrent
//! clients, per-session cancellation and SIGTERM are checked too.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use cdvol::progress::NoProgress;
use cdvol::tools::phantom;

use crate::common::{self, cdvol};

/// A running `cdvol serve`, killed when dropped.
struct Serve {
    child: Child,
    addr: String,
}

impl Serve {
    fn start(files: &[&Path], extra: &[&str]) -> Serve {
        let mut c = cdvol();
        c.arg("serve").args(files).args(["--bind", "127.0.0.1:0"]);
        c.args(extra).stderr(Stdio::piped()).stdout(Stdio::null());
        let mut child = c.spawn().unwrap();
        let mut err = BufReader::new(child.stderr.take().unwrap());
        let mut line = String::new();
        err.read_line(&mut line).unwrap();
        let addr = line
            .split("http://")
            .nth(1)
            .unwrap_or_else(|| panic!("no address in {line:?}"))
            .trim()
            .trim_end_matches('/')
            .to_string();
        // Keep draining stderr so the server never blocks on it.
        std::thread::spawn(move || for _ in err.lines() {});
        Serve { child, addr }
    }
}

impl Drop for Serve {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A response: status, headers (lower-case names) and body.
struct Reply {
    status: u16,
    headers: Vec<(String, String)>,
    body: Vec<u8>,
}

impl Reply {
    fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(k, _)| k == name)
            .map(|(_, v)| v.as_str())
    }
    fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }
    fn stats(&self) -> serde_json::Value {
        serde_json::from_str(self.header("x-cdvol-stats").expect("stats header")).unwrap()
    }
}

/// GET `target` (path and query, sent as is) over HTTP/1.0.
fn get(addr: &str, target: &str) -> Reply {
    get_as(addr, target, addr)
}

/// [`get`] with `host` as the Host header.
fn get_as(addr: &str, target: &str, host: &str) -> Reply {
    let mut s = TcpStream::connect(addr).unwrap();
    write!(s, "GET {target} HTTP/1.0\r\nHost: {host}\r\n\r\n").unwrap();
    let mut raw = Vec::new();
    s.read_to_end(&mut raw).unwrap();
    let split = raw
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .expect("end of headers");
    let head = String::from_utf8_lossy(&raw[..split]).into_owned();
    let mut lines = head.lines();
    let status = lines
        .next()
        .unwrap()
        .split(' ')
        .nth(1)
        .unwrap()
        .parse()
        .unwrap();
    let headers = lines
        .filter_map(|l| l.split_once(':'))
        .map(|(k, v)| (k.trim().to_ascii_lowercase(), v.trim().to_string()))
        .collect();
    Reply {
        status,
        headers,
        body: raw[split + 4..].to_vec(),
    }
}

/// The CT-like phantom prepared at iso 100 (so the bone preset's iso
/// value, 226, renders from it), in `dir`.
pub(super) fn head(dir: &Path) -> PathBuf {
    let side = dir.join("head.json");
    phantom::ct(
        &side,
        &phantom::CtOptions {
            dims: [64, 60, 48],
            dtype: phantom::CtDtype::I16,
            seed: 2,
            ..Default::default()
        },
        &NoProgress,
    )
    .unwrap();
    let out = dir.join("head.cdv");
    common::packed(&side, &out, 100.0);
    out
}

/// The phantom of [`head`] (made first) prepared with the ct-bone
/// preset's transfer function, for composite renders.
pub(super) fn bone(dir: &Path) -> PathBuf {
    let out = dir.join("head-bone.cdv");
    common::ok(
        cdvol()
            .arg("prep")
            .arg(dir.join("head.json"))
            .args(["--preset", "ct-bone", "--brick", "16", "-o"])
            .arg(&out),
    );
    out
}

/// Runs `command` (a `cdvol render ... -o view.png` line from the server)
/// with the binary under test in `dir`, returning view.png's bytes.
fn run_command(command: &str, dir: &Path) -> Vec<u8> {
    let rest = command.strip_prefix("cdvol ").expect("starts with cdvol");
    let bin = env!("CARGO_BIN_EXE_cdvol");
    let out = Command::new("sh")
        .arg("-c")
        .arg(format!("'{bin}' {rest}"))
        .current_dir(dir)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{command}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    std::fs::read(dir.join("view.png")).unwrap()
}

#[test]
fn images_are_the_bytes_cdvol_render_writes() {
    let dir = tempfile::tempdir().unwrap();
    let file = head(dir.path());
    let srv = Serve::start(&[&file], &["--cache-mb", "64"]);

    // Independently of the server's command line: a plain orbit.
    let r = get(&srv.addr, "/api/image?az=30&el=20&w=96&h=80");
    assert_eq!(r.status, 200, "{}", r.text());
    assert_eq!(r.header("content-type"), Some("image/png"));
    let png = dir.path().join("own.png");
    common::ok(
        cdvol()
            .arg("render")
            .arg(&file)
            .arg("-o")
            .arg(&png)
            .args(["--view", "30,20", "--width", "96", "--height", "80"]),
    );
    assert!(r.body == std::fs::read(&png).unwrap(), "orbit differs");

    // The server's own command line, over modes, scene and camera.
    for q in [
        "mode=surface&hit=bisect&shadows=1&az=-40&el=35&w=64&h=64",
        "mode=surface&iso=900&az=10&el=5&frame=120&w=72&h=60",
        "mode=mip&window=1500&level=400&az=90&el=0&w=64&h=48",
        "mode=mip&az=200&el=-30&w=50&h=50",
        "mode=cost&az=45&el=45&w=64&h=64",
        "az=20&el=10&frame=90&pan=12.5,-7&w=80&h=64",
        "mode=surface&preset=ct-bone&az=0&el=60&w=64&h=64",
    ] {
        let r = get(&srv.addr, &format!("/api/image?{q}"));
        assert_eq!(r.status, 200, "{q}: {}", r.text());
        let stats = r.stats();
        let command = stats["command"].as_str().unwrap().to_string();
        let want = run_command(&command, dir.path());
        assert!(r.body == want, "{q}: served image differs from `{command}`");
        assert!(stats["rays"].as_u64().unwrap() > 0, "{q}: {stats}");
    }

    // Composite on a file classified by the preset's transfer function.
    let tf_file = dir.path().join("head-bone.cdv");
    common::ok(
        cdvol()
            .arg("prep")
            .arg(dir.path().join("head.json"))
            .args(["--preset", "ct-bone", "--brick", "16", "-o"])
            .arg(&tf_file),
    );
    let srv2 = Serve::start(&[&file, &tf_file], &["--cache-mb", "64"]);
    let r = get(
        &srv2.addr,
        "/api/image?file=1&mode=composite&preset=ct-bone&step=0.7&az=60&el=20&w=64&h=56",
    );
    assert_eq!(r.status, 200, "{}", r.text());
    let command = r.stats()["command"].as_str().unwrap().to_string();
    assert!(command.contains("head-bone.cdv"), "{command}");
    assert!(
        r.body == run_command(&command, dir.path()),
        "composite differs: {command}"
    );

    // JPEG and WebP are real images of the asked size.
    for (fmt, ty) in [("jpeg", "image/jpeg"), ("webp", "image/webp")] {
        let r = get(&srv.addr, &format!("/api/image?w=40&h=30&format={fmt}"));
        assert_eq!((r.status, r.header("content-type")), (200, Some(ty)));
        let img = image::load_from_memory(&r.body).unwrap();
        assert_eq!((img.width(), img.height()), (40, 30));
    }
}

#[test]
fn bad_requests_are_refused_with_a_message() {
    let dir = tempfile::tempdir().unwrap();
    let file = head(dir.path());
    let srv = Serve::start(&[&file], &["--cache-mb", "16"]);
    for (target, status, says) in [
        ("/api/image?w=5000", 400, "w="),
        ("/api/image?w=0", 400, "w="),
        ("/api/image?az=nan", 400, "az="),
        ("/api/image?file=1", 400, "file="),
        ("/api/image?file=../../etc/passwd", 400, "file="),
        ("/api/image?path=/etc/passwd", 400, "unknown parameter"),
        ("/api/image?preset=../x", 400, "preset="),
        ("/api/image?mode=depth", 400, "mode="),
        ("/api/image?iso=-5000", 400, "iso"),
        (
            "/api/image?mode=composite&preset=ct-bone",
            400,
            "transfer function",
        ),
        ("/api/image?mode=composite", 400, "preset"),
        ("/api/image?w=8&w=9", 400, "twice"),
        ("/api/image?window=100", 400, "level"),
        ("/api/image?quality=10", 400, "jpeg"),
        ("/api/image?session=%2F..", 400, "session="),
        ("/api/image?view=sideways", 400, "view="),
        ("/../../etc/passwd", 404, "not found"),
        ("/head.cdv", 404, "not found"),
        ("/api/image/../../../etc/passwd", 404, "not found"),
    ] {
        let r = get(&srv.addr, target);
        assert_eq!(r.status, status, "{target}: {}", r.text());
        assert!(r.text().contains(says), "{target}: {:?}", r.text());
        assert!(!r.text().contains("root:"), "{target} leaked a file");
    }
    // DNS rebinding: a foreign name for the loopback server is refused.
    let port = srv.addr.rsplit(':').next().unwrap();
    let r = get_as(&srv.addr, "/api/info", &format!("evil.example:{port}"));
    assert_eq!(r.status, 403, "{}", r.text());
    assert!(r.text().contains("rebinding"), "{}", r.text());
    let local = format!("localhost:{port}");
    assert_eq!(get_as(&srv.addr, "/api/info", &local).status, 200);
    let long = format!("/api/image?session={}", "a".repeat(3000));
    assert_eq!(get(&srv.addr, &long).status, 400);
    // The server still answers after all that.
    assert_eq!(get(&srv.addr, "/api/image?w=16&h=16").status, 200);
}

#[test]
fn page_and_info_are_self_contained() {
    let dir = tempfile::tempdir().unwrap();
    let file = head(dir.path());
    let srv = Serve::start(&[&file, &file], &[]);
    let page = get(&srv.addr, "/");
    assert_eq!(page.status, 200);
    let html = page.text();
    assert!(
        html.contains("<canvas") || html.contains("<img"),
        "no image"
    );
    for remote in [
        "src=\"http",
        "href=\"http",
        "url(http",
        "import(\"http",
        "//cdn",
    ] {
        assert!(!html.contains(remote), "the page fetches {remote}...");
    }
    let info: serde_json::Value =
        serde_json::from_slice(&get(&srv.addr, "/api/info").body).unwrap();
    assert_eq!(info["files"].as_array().unwrap().len(), 2);
    assert_eq!(info["files"][1]["index"], 1);
    assert!(info["files"][0]["info"]["histogram"]["counts"].is_array());
    assert!(info["presets"].as_array().unwrap().len() > 3);
    assert_eq!(get(&srv.addr, "/api/image?file=1&w=8&h=8").status, 200);
}

#[test]
fn concurrent_clients_get_the_same_images() {
    let dir = tempfile::tempdir().unwrap();
    let file = head(dir.path());
    let srv = Serve::start(&[&file], &["--cache-mb", "8", "--threads", "2"]);
    let queries: Vec<String> = (0..6)
        .map(|i| format!("/api/image?az={}&el=15&w=64&h=64", i * 60))
        .collect();
    let alone: Vec<Vec<u8>> = queries.iter().map(|q| get(&srv.addr, q).body).collect();
    let addr = srv.addr.clone();
    std::thread::scope(|s| {
        for c in 0..4 {
            let (queries, alone, addr) = (&queries, &alone, &addr);
            s.spawn(move || {
                for k in 0..queries.len() {
                    let i = (k + c) % queries.len();
                    let r = get(addr, &queries[i]);
                    assert_eq!(r.status, 200, "client {c}: {}", r.text());
                    assert!(r.body == alone[i], "client {c}, {}", queries[i]);
                }
            });
        }
    });
}

#[test]
fn a_newer_request_of_a_session_cancels_the_older() {
    let dir = tempfile::tempdir().unwrap();
    head(dir.path());
    let file = bone(dir.path());
    let srv = Serve::start(&[&file], &["--threads", "1"]);
    // Slow: a 1024^2 composite with short steps on one thread (0.8 s here),
    // within serve's bound on estimated samples (0.05 mm is above it).
    let slow = "/api/image?mode=composite&preset=ct-bone&step=0.2&w=1024&h=1024&session=";
    let addr = srv.addr.clone();
    let older = std::thread::spawn(move || {
        let r = get(&addr, &format!("{slow}s1"));
        (r, Instant::now())
    });
    // Wait until the older request is rendering (no fixed sleep: a loaded
    // machine may take long to get there).
    let status = |addr: &str| -> serde_json::Value {
        serde_json::from_slice(&get(addr, "/api/status").body).unwrap()
    };
    let t0 = Instant::now();
    while status(&srv.addr)["rendering"].as_u64() != Some(1) {
        assert!(
            !older.is_finished(),
            "the older request ended before rendering"
        );
        assert!(
            t0.elapsed() < Duration::from_secs(60),
            "never started rendering"
        );
        std::thread::sleep(Duration::from_millis(5));
    }
    let sent = Instant::now();
    let newer = get(&srv.addr, "/api/image?session=s1&w=32&h=32&mode=mip");
    let other = get(&srv.addr, "/api/image?session=s2&w=32&h=32&mode=mip");
    let (older, ended) = older.join().unwrap();
    let short = |r: &Reply| format!("{} {:?}", r.status, r.header("content-type"));
    assert_eq!(older.status, 409, "older: {}", short(&older));
    assert!(older.text().contains("cancelled"), "{}", older.text());
    assert_eq!(newer.status, 200, "{}", newer.text());
    // Another session's request is never cancelled by s1.
    assert_eq!(other.status, 200, "{}", other.text());
    let st = status(&srv.addr);
    assert_eq!(st["cancelled"].as_u64(), Some(1), "{st}");
    assert_eq!(st["rendering"].as_u64(), Some(0), "{st}");
    // The cancelled render stopped early: it ended well within the time a
    // whole render of the same view takes (its own render seconds).
    let whole = get(&srv.addr, &format!("{slow}s3"));
    assert_eq!(whole.status, 200, "{}", short(&whole));
    let render = whole.stats()["seconds_render"].as_f64().unwrap();
    let stopped = ended.saturating_duration_since(sent).as_secs_f64();
    assert!(
        stopped * 2.0 < render,
        "cancelled {stopped:.3} s after the newer request, a whole render took {render:.3} s"
    );
}

#[test]
fn sigterm_stops_the_server_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let file = head(dir.path());
    let mut srv = Serve::start(&[&file], &[]);
    assert_eq!(get(&srv.addr, "/api/image?w=16&h=16").status, 200);
    let pid = srv.child.id().to_string();
    assert!(Command::new("kill")
        .args(["-TERM", &pid])
        .status()
        .unwrap()
        .success());
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = srv.child.try_wait().unwrap() {
            break s;
        }
        assert!(t0.elapsed() < Duration::from_secs(10), "still running");
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(status.success(), "{status:?}");
}

/// The address line reaches stderr in one write. CI's browser test once
/// matched `http://127.0.` in a first chunk, because the line went out in
/// 14 writes, and opened a page on 127.0.0.0. A reader blocked on the pipe
/// may wake at the first write, so with a split line the first read can
/// hold only its first piece; with one write it always holds the whole
/// line. Against the 14-write binary this failed 1 run in 5 here: it
/// catches the split sometimes, never passes a split line it saw.
#[test]
fn the_address_line_is_one_write() {
    let dir = tempfile::tempdir().unwrap();
    let file = head(dir.path());
    let mut child = cdvol()
        .arg("serve")
        .arg(&file)
        .args(["--bind", "127.0.0.1:0"])
        .stderr(Stdio::piped())
        .stdout(Stdio::null())
        .spawn()
        .unwrap();
    let mut err = child.stderr.take().unwrap();
    let mut buf = [0u8; 4096];
    let n = err.read(&mut buf).unwrap();
    let _ = child.kill();
    let _ = child.wait();
    let first = String::from_utf8_lossy(&buf[..n]);
    assert!(
        first.starts_with("cdvol serve: listening on http://127.0.0.1:") && first.ends_with("/\n"),
        "first read from stderr: {first:?}"
    );
}

#[test]
fn refuses_bad_command_lines() {
    let dir = tempfile::tempdir().unwrap();
    let file = head(dir.path());
    let e = common::fails(cdvol().arg("serve").arg(&file).args(["--cache-mb", "0"]));
    assert!(e.contains("cache_mb 0"), "{e}");
    let e = common::fails(cdvol().arg("serve").arg(dir.path().join("none.cdv")));
    assert!(e.contains("none.cdv"), "{e}");
}
