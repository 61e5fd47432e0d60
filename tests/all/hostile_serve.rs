//! Hostile clients of `cdvol serve` (issue 57, item 1 and the status
//! latency): after every request below the server still answers
//! `/api/status`. Before, `GET /api/status` with `Content-Length:
//! 99999999999` got its 200 and then the process aborted ("memory
//! allocation of 99999999999 bytes failed", tiny_http 0.12 allocating
//! the declared body to drain it), and `/api/status` waited 5 s behind a
//! flood of renders.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Child, Stdio};
use std::time::{Duration, Instant};

use crate::serve::{bone, head};

/// A running `cdvol serve` under a 4 GiB address-space limit, killed
/// when dropped.
pub(super) struct Serve {
    child: Child,
    pub(super) addr: String,
}

impl Serve {
    pub(super) fn start(file: &Path) -> Serve {
        let mut c = std::process::Command::new("sh");
        c.arg("-c")
            .arg(format!(
                "ulimit -v 4194304; exec {} serve {} --bind 127.0.0.1:0 --threads 2",
                env!("CARGO_BIN_EXE_cdvol"),
                file.display()
            ))
            .stderr(Stdio::piped())
            .stdout(Stdio::null());
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
        std::thread::spawn(move || for _ in err.lines() {});
        Serve { child, addr }
    }

    /// The server is still running and answers a status request.
    pub(super) fn alive(&mut self, after: &str) {
        assert!(
            self.child.try_wait().unwrap().is_none(),
            "the server died after {after}"
        );
        let (status, _) = exchange(
            &self.addr,
            b"GET /api/status HTTP/1.0\r\nHost: localhost\r\n\r\n",
        );
        assert_eq!(status, 200, "status after {after}");
    }
}

impl Drop for Serve {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Sends `request`, then reads until the server closes (or 10 s): the
/// status code and the whole response.
pub(super) fn exchange(addr: &str, request: &[u8]) -> (u16, String) {
    let mut s = TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    let _ = s.write_all(request);
    let mut raw = Vec::new();
    let _ = s.read_to_end(&mut raw);
    let text = String::from_utf8_lossy(&raw).into_owned();
    let status = text
        .split(' ')
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    (status, text)
}

#[test]
fn declared_bodies_are_refused_without_reading_them() {
    let d = tempfile::tempdir().unwrap();
    let mut srv = Serve::start(&head(d.path()));
    for (what, req) in [
        (
            "Content-Length: 99999999999",
            "GET /api/status HTTP/1.1\r\nHost: localhost\r\nContent-Length: 99999999999\r\n\r\nabc",
        ),
        (
            "Content-Length: 2^64",
            "GET /api/status HTTP/1.1\r\nHost: localhost\r\nContent-Length: 18446744073709551616\r\n\r\n",
        ),
        (
            "a chunked body",
            "GET /api/status HTTP/1.1\r\nHost: localhost\r\nTransfer-Encoding: chunked\r\n\r\nffffffffffff\r\n",
        ),
        (
            "a POST with a body",
            "POST /api/image HTTP/1.1\r\nHost: localhost\r\nContent-Length: 5000000\r\n\r\n",
        ),
    ] {
        let t = Instant::now();
        let (status, text) = exchange(&srv.addr, req.as_bytes());
        assert_eq!(status, 413, "{what}: {text}");
        assert!(text.contains("request bodies are not accepted"), "{text}");
        assert!(t.elapsed() < Duration::from_secs(5), "{what}: {:?}", t.elapsed());
        srv.alive(what);
    }
}

#[test]
fn oversized_and_malformed_heads_are_refused() {
    let d = tempfile::tempdir().unwrap();
    let mut srv = Serve::start(&head(d.path()));
    let long = format!(
        "GET /api/status HTTP/1.1\r\nHost: localhost\r\nX-Pad: {}\r\n\r\n",
        "a".repeat(64 << 10)
    );
    let (status, text) = exchange(&srv.addr, long.as_bytes());
    assert_eq!(status, 431, "{text}");
    srv.alive("a 64 KiB header");
    let many: String = (0..200).map(|i| format!("X-{i}: 1\r\n")).collect();
    let req = format!("GET /api/status HTTP/1.1\r\nHost: localhost\r\n{many}\r\n");
    let (status, text) = exchange(&srv.addr, req.as_bytes());
    assert_eq!(status, 431, "{text}");
    srv.alive("200 header lines");
    let (status, text) = exchange(&srv.addr, b"\x00\x01garbage\r\n\r\n");
    assert_eq!(status, 400, "{text}");
    srv.alive("binary garbage");
}

#[test]
fn status_answers_beside_idle_connections_and_a_flood_of_renders() {
    let d = tempfile::tempdir().unwrap();
    let mut srv = Serve::start(&head(d.path()));
    // Connections that send half a head and wait.
    let idle: Vec<TcpStream> = (0..20)
        .map(|_| {
            let mut s = TcpStream::connect(&srv.addr).unwrap();
            s.write_all(b"GET /api/status HTTP/1.1\r\nHo").unwrap();
            s
        })
        .collect();
    // Twelve clients asking for shadowed 512^2 renders at once, without
    // sessions (none cancels another), so they queue for the render slot.
    let flood: Vec<_> = (0..12)
        .map(|i| {
            let addr = srv.addr.clone();
            std::thread::spawn(move || {
                let req = format!(
                    "GET /api/image?mode=surface&shadows=1&w=512&h=512&az={i} \
                     HTTP/1.0\r\nHost: localhost\r\n\r\n"
                );
                exchange(&addr, req.as_bytes()).0
            })
        })
        .collect();
    std::thread::sleep(Duration::from_millis(300));
    let t = Instant::now();
    srv.alive("a flood of renders and 20 idle connections");
    let took = t.elapsed();
    assert!(took < Duration::from_secs(1), "status took {took:?}");
    for f in flood {
        assert_eq!(f.join().unwrap(), 200, "every queued render is drawn");
    }
    drop(idle);
    srv.alive("the flood");
}

#[test]
fn too_many_connections_get_503_and_the_server_lives() {
    let d = tempfile::tempdir().unwrap();
    let mut srv = Serve::start(&head(d.path()));
    let held: Vec<TcpStream> = (0..cdvol::serve::MAX_CONNECTIONS)
        .map(|_| TcpStream::connect(&srv.addr).unwrap())
        .collect();
    std::thread::sleep(Duration::from_millis(200));
    let (status, text) = exchange(
        &srv.addr,
        b"GET /api/status HTTP/1.0\r\nHost: localhost\r\n\r\n",
    );
    assert_eq!(status, 503, "{text}");
    drop(held);
    std::thread::sleep(Duration::from_millis(300));
    srv.alive("too many connections");
}

/// Issue 51, item 10: a request is bounded by its estimated cost, not
/// only by each parameter. A 1024^2 composite at 0.05 mm (every parameter
/// within its own range) held the server for 14.6 s; it is refused at
/// once with the estimate, and the same view at the default step renders.
#[test]
fn a_costly_composite_is_refused_with_its_estimate() {
    let d = tempfile::tempdir().unwrap();
    head(d.path());
    let mut srv = Serve::start(&bone(d.path()));
    let t = Instant::now();
    let (status, text) = exchange(
        &srv.addr,
        b"GET /api/image?mode=composite&preset=ct-bone&w=1024&h=1024&step=0.05 HTTP/1.0\r\n\
          Host: localhost\r\n\r\n",
    );
    assert_eq!(status, 400, "{text}");
    for w in ["samples", "above the bound", "raise step"] {
        assert!(text.contains(w), "{w:?} not in {text}");
    }
    assert!(t.elapsed() < Duration::from_secs(1), "{:?}", t.elapsed());
    let (status, text) = exchange(
        &srv.addr,
        b"GET /api/image?mode=composite&preset=ct-bone&w=256&h=256 HTTP/1.0\r\n\
          Host: localhost\r\n\r\n",
    );
    assert_eq!(status, 200, "{text}");
    srv.alive("a costly request");
}

/// A client that drips a head one byte at a time cannot hold a
/// connection: the head must be whole within `IDLE` (10 s) of its first
/// byte, else 408 and the connection closes.
#[test]
fn a_head_dripped_byte_by_byte_is_cut_off() {
    let d = tempfile::tempdir().unwrap();
    let mut srv = Serve::start(&head(d.path()));
    let mut s = TcpStream::connect(&srv.addr).unwrap();
    s.set_read_timeout(Some(Duration::from_millis(50))).unwrap();
    s.write_all(b"GET /api/status HTTP/1.1\r\nX-Drip: ")
        .unwrap();
    let t = Instant::now();
    let mut got = Vec::new();
    while t.elapsed() < Duration::from_secs(20) {
        if s.write_all(b"a").is_err() {
            break;
        }
        let mut b = [0u8; 512];
        match s.read(&mut b) {
            Ok(0) => break,
            Ok(n) => got.extend_from_slice(&b[..n]),
            Err(_) => {}
        }
        std::thread::sleep(Duration::from_millis(950));
    }
    let text = String::from_utf8_lossy(&got);
    assert!(text.starts_with("HTTP/1.1 408"), "{text}");
    assert!(t.elapsed() < Duration::from_secs(15), "{:?}", t.elapsed());
    srv.alive("a dripped head");
}
