//! The HTTP side of `cdvol serve`: a listener, one thread a connection (at
//! most [`MAX_CONNECTIONS`]), request heads parsed by `httparse`, routes
//! answered at once and image requests handed to the [`Engine`]. Routes
//! are fixed strings; no part of a URL reaches the file system. Every
//! refusal is a status with a plain-text message.
//!
//! Every request is bounded before anything is allocated for it (issue
//! 57; docs/SERVE.md says why this is not tiny_http any more): a head is
//! at most [`MAX_HEAD`] bytes and [`MAX_HEADERS`] lines; a request that
//! announces a body (`Content-Length` above 0 or any
//! `Transfer-Encoding`) is answered 413 and its connection closed without
//! reading the body, since no route takes one; a connection idle for
//! [`IDLE`], or whose head is not whole within [`IDLE`] of its first
//! byte, is closed, and a response that cannot be written within
//! [`WRITE_TIMEOUT`] is dropped. Status and page requests have threads of
//! their own, so they are answered while renders queue for the render
//! slot.

use std::io::{ErrorKind, Read, Write};
use std::net::{SocketAddr, TcpListener, TcpStream};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::Arc;
use std::time::Duration;

use super::engine::{Engine, Served};
use super::request::{ViewRequest, MAX_SIDE};
use super::{ServeConfig, ServeError};

/// The viewer page, every asset inline.
const PAGE: &str = include_str!("page.html");

/// Largest request head (request line and headers), bytes.
pub const MAX_HEAD: usize = 16 << 10;

/// Most header lines a request may have.
pub const MAX_HEADERS: usize = 64;

/// Most connections served at once; one more is answered 503 and closed.
pub const MAX_CONNECTIONS: usize = 64;

/// A connection with no request in progress for this long is closed.
pub const IDLE: Duration = Duration::from_secs(10);

/// A response not written within this long is dropped with its
/// connection (a client that stopped reading).
pub const WRITE_TIMEOUT: Duration = Duration::from_secs(30);

/// How often a waiting connection looks at the stop flag.
const POLL: Duration = Duration::from_millis(100);

/// A bound server, ready to [`run`](Server::run).
pub struct Server<'v> {
    listener: TcpListener,
    engine: Engine<'v>,
    stop: Arc<AtomicBool>,
    addr: SocketAddr,
    open: AtomicUsize,
}

/// A response: status, content type, extra headers, body.
struct Reply {
    status: u16,
    content_type: &'static str,
    headers: Vec<(&'static str, String)>,
    body: Vec<u8>,
}

/// What the routes need of a request head, owned.
struct Head {
    method: String,
    target: String,
    host: Option<String>,
    /// The client asked to close, or spoke HTTP/1.0 without keep-alive.
    close: bool,
    /// `Content-Length` above 0 or a `Transfer-Encoding`.
    body: bool,
}

impl<'v> Server<'v> {
    /// Binds `cfg.bind` for `files` (opened by the caller, who keeps them
    /// for the server's life).
    pub fn bind(files: &'v [Served], cfg: &ServeConfig) -> Result<Server<'v>, ServeError> {
        cfg.check()?;
        let bind_err = |e: std::io::Error| ServeError::Bind {
            addr: cfg.bind,
            msg: e.to_string(),
        };
        let listener = listen(cfg.bind).map_err(bind_err)?;
        let addr = listener.local_addr().map_err(bind_err)?;
        Ok(Server {
            listener,
            engine: Engine::new(files, cfg.cache_mb << 20, cfg.threads)?,
            stop: Arc::new(AtomicBool::new(false)),
            addr,
            open: AtomicUsize::new(0),
        })
    }

    /// The address listened on (the port chosen when it was 0).
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// Setting this flag stops [`Server::run`] within a tenth of a second
    /// of the requests in hand finishing.
    pub fn stop_flag(&self) -> Arc<AtomicBool> {
        self.stop.clone()
    }

    /// Answers requests until the stop flag is set.
    pub fn run(&self) {
        std::thread::scope(|s| {
            // accept() blocks: once the flag is set, a connection of our
            // own wakes it.
            s.spawn(|| {
                while !self.stop.load(Ordering::Relaxed) {
                    std::thread::sleep(POLL);
                }
                let _ = TcpStream::connect_timeout(&wake_addr(self.addr), Duration::from_secs(1));
            });
            loop {
                let accepted = self.listener.accept();
                if self.stop.load(Ordering::Relaxed) {
                    break;
                }
                let stream = match accepted {
                    Ok((stream, _)) => stream,
                    Err(e) => {
                        eprintln!("cdvol serve: {e}");
                        std::thread::sleep(POLL);
                        continue;
                    }
                };
                if self.open.fetch_add(1, Ordering::AcqRel) >= MAX_CONNECTIONS {
                    self.open.fetch_sub(1, Ordering::AcqRel);
                    let busy = text(
                        503,
                        &format!("busy: {MAX_CONNECTIONS} connections are open, try again"),
                    );
                    let _ = stream.set_write_timeout(Some(Duration::from_secs(1)));
                    let _ = send(&stream, &busy, true);
                    continue;
                }
                s.spawn(move || {
                    self.connection(stream);
                    self.open.fetch_sub(1, Ordering::AcqRel);
                });
            }
        });
    }

    /// Serves one connection's requests in order until it closes, idles
    /// past [`IDLE`], breaks a bound, or the server stops.
    fn connection(&self, mut stream: TcpStream) {
        if stream.set_read_timeout(Some(POLL)).is_err()
            || stream.set_write_timeout(Some(WRITE_TIMEOUT)).is_err()
        {
            return;
        }
        let mut buf: Vec<u8> = Vec::with_capacity(1024);
        let mut idle = Duration::ZERO;
        // When the head in hand began: a head must be whole within IDLE of
        // its first byte, so a client sending a byte every few seconds
        // cannot hold a connection.
        let mut head_since: Option<std::time::Instant> = None;
        loop {
            match parse_head(&buf) {
                Ok(Some((len, head))) => {
                    buf.drain(..len);
                    head_since = (!buf.is_empty()).then(std::time::Instant::now);
                    let (reply, close) = if head.body {
                        let r = text(
                            413,
                            "request bodies are not accepted: every route is a GET without one",
                        );
                        (r, true)
                    } else {
                        (self.route(&head), head.close)
                    };
                    if send(&stream, &reply, close).is_err() || close {
                        return;
                    }
                    idle = Duration::ZERO;
                    continue;
                }
                Ok(None) => {}
                Err(reply) => {
                    let _ = send(&stream, &reply, true);
                    return;
                }
            }
            if self.stop.load(Ordering::Relaxed) {
                return;
            }
            if head_since.is_some_and(|t| t.elapsed() >= IDLE) {
                let late = text(408, &format!("no whole request head within {IDLE:?}"));
                let _ = send(&stream, &late, true);
                return;
            }
            let mut chunk = [0u8; 4096];
            let room = (MAX_HEAD - buf.len()).min(chunk.len());
            match stream.read(&mut chunk[..room]) {
                Ok(0) => return,
                Ok(n) => {
                    buf.extend_from_slice(&chunk[..n]);
                    idle = Duration::ZERO;
                    head_since.get_or_insert_with(std::time::Instant::now);
                }
                Err(e) if matches!(e.kind(), ErrorKind::WouldBlock | ErrorKind::TimedOut) => {
                    idle += POLL;
                    if idle >= IDLE {
                        return;
                    }
                }
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(_) => return,
            }
        }
    }

    fn route(&self, rq: &Head) -> Reply {
        if rq.method != "GET" {
            return text(405, "only GET is served");
        }
        if let Some(host) = self.foreign_host(rq) {
            return text(
                403,
                &format!(
                    "Host {host} refused: a server on a loopback address answers only to \
                     localhost, 127.0.0.1 or [::1] (another name may be a DNS rebinding page)"
                ),
            );
        }
        let url = rq.target.as_str();
        let (path, query) = url.split_once('?').unwrap_or((url, ""));
        match path {
            "/" | "/index.html" => Reply {
                status: 200,
                content_type: "text/html; charset=utf-8",
                headers: Vec::new(),
                body: PAGE.as_bytes().to_vec(),
            },
            "/api/info" => json(&self.info()),
            "/api/status" => json(&self.engine.counters),
            "/api/image" => self.image(query),
            _ => text(
                404,
                &format!(
                    "not found: {}; routes: /, /api/info, /api/image?..., /api/status",
                    path.chars().take(200).collect::<String>()
                ),
            ),
        }
    }

    /// The request's `Host` when the server listens on a loopback
    /// address and the name is not a loopback one: a page from elsewhere
    /// whose name was rebound to 127.0.0.1 could otherwise read the
    /// images.
    fn foreign_host(&self, rq: &Head) -> Option<String> {
        if !self.addr.ip().is_loopback() {
            return None;
        }
        let host = rq.host.as_deref()?.to_ascii_lowercase();
        let name = match host.strip_prefix('[') {
            Some(v6) => v6.split(']').next().unwrap_or(""),
            None => host.split(':').next().unwrap_or(""),
        };
        (!matches!(name, "localhost" | "127.0.0.1" | "::1"))
            .then(|| host.chars().take(200).collect())
    }

    fn image(&self, query: &str) -> Reply {
        let req = match ViewRequest::parse(query, self.engine.files.len()) {
            Ok(r) => r,
            Err(e) => return text(400, &e.to_string()),
        };
        match self.engine.render(&req) {
            Ok(r) => {
                let stats = serde_json::to_string(&r).unwrap_or_default();
                Reply {
                    status: 200,
                    content_type: r.content_type,
                    headers: vec![("X-Cdvol-Stats", ascii_json(&stats))],
                    body: r.bytes,
                }
            }
            Err(e) => text(e.status(), &e.to_string()),
        }
    }

    /// The files (with their summaries and histograms), presets and
    /// limits the page offers.
    fn info(&self) -> serde_json::Value {
        let files: Vec<serde_json::Value> = self
            .engine
            .files
            .iter()
            .enumerate()
            .map(|(i, f)| {
                let h = f.vol.header();
                let m = h.modality();
                let offered: Vec<serde_json::Value> =
                    crate::look::offered(h).iter().map(preset_json).collect();
                serde_json::json!({
                    "modality": m.modality.name(),
                    "modality_source": m.source,
                    "look": h.look,
                    "presets": offered,
                    "index": i,
                    "name": f.name,
                    "oriented": h.orientation.is_some(),
                    "mirrored": h.orientation.as_ref().is_some_and(|o| o.nearest().det() < 0.0),
                    "info": crate::info::Info::of(&f.vol),
                })
            })
            .collect();
        let presets: Vec<serde_json::Value> =
            crate::presets::all().iter().map(preset_json).collect();
        serde_json::json!({
            "files": files,
            "presets": presets,
            "views": crate::orient::NamedView::NAMES.split(", ").collect::<Vec<_>>(),
            "max_side": MAX_SIDE,
            "cache_mb": self.engine.cache_bytes >> 20,
        })
    }
}

/// A preset as the page reads it: `iso` is its surface iso
/// ([`crate::presets::Preset::surface_iso`]), `window` `[width, level]`.
fn preset_json(p: &crate::presets::Preset) -> serde_json::Value {
    serde_json::json!({
        "name": p.name, "modality": p.modality.name(),
        "description": p.description, "iso": p.surface_iso(),
        "window": p.window.map(|w| [w.width, w.level]),
        "support": p.support(),
    })
}

/// The request head at the start of `buf` and its length, `None` while
/// it is incomplete, or the reply that refuses it.
fn parse_head(buf: &[u8]) -> Result<Option<(usize, Head)>, Reply> {
    let mut headers = [httparse::EMPTY_HEADER; MAX_HEADERS];
    let mut rq = httparse::Request::new(&mut headers);
    let len = match rq.parse(buf) {
        Ok(httparse::Status::Complete(len)) => len,
        Ok(httparse::Status::Partial) if buf.len() >= MAX_HEAD => {
            return Err(text(431, &format!("request head over {MAX_HEAD} bytes")))
        }
        Ok(httparse::Status::Partial) => return Ok(None),
        Err(httparse::Error::TooManyHeaders) => {
            return Err(text(431, &format!("more than {MAX_HEADERS} header lines")))
        }
        Err(e) => return Err(text(400, &format!("malformed request: {e}"))),
    };
    let value = |name: &str| {
        rq.headers
            .iter()
            .find(|h| h.name.eq_ignore_ascii_case(name))
            .map(|h| String::from_utf8_lossy(h.value).trim().to_string())
    };
    let connection = value("Connection").unwrap_or_default().to_ascii_lowercase();
    let http10 = rq.version == Some(0);
    let body = value("Transfer-Encoding").is_some()
        || rq.headers.iter().any(|h| {
            h.name.eq_ignore_ascii_case("Content-Length")
                && String::from_utf8_lossy(h.value).trim() != "0"
        });
    let head = Head {
        method: rq.method.unwrap_or("").to_string(),
        target: rq.path.unwrap_or("/").to_string(),
        host: value("Host"),
        close: connection.contains("close") || (http10 && !connection.contains("keep-alive")),
        body,
    };
    Ok(Some((len, head)))
}

/// Writes `reply` (with `Connection: close` when `close`) in one write.
fn send(mut stream: &TcpStream, reply: &Reply, close: bool) -> std::io::Result<()> {
    let mut out = format!(
        "HTTP/1.1 {} {}\r\nContent-Type: {}\r\nContent-Length: {}\r\nCache-Control: no-store\r\n\
         Connection: {}\r\n",
        reply.status,
        reason(reply.status),
        reply.content_type,
        reply.body.len(),
        if close { "close" } else { "keep-alive" },
    )
    .into_bytes();
    for (k, v) in &reply.headers {
        out.extend_from_slice(format!("{k}: {v}\r\n").as_bytes());
    }
    out.extend_from_slice(b"\r\n");
    out.extend_from_slice(&reply.body);
    stream.write_all(&out)?;
    stream.flush()
}

fn reason(status: u16) -> &'static str {
    match status {
        200 => "OK",
        400 => "Bad Request",
        403 => "Forbidden",
        404 => "Not Found",
        405 => "Method Not Allowed",
        408 => "Request Timeout",
        409 => "Conflict",
        413 => "Content Too Large",
        431 => "Request Header Fields Too Large",
        500 => "Internal Server Error",
        503 => "Service Unavailable",
        _ => "",
    }
}

/// Where a connection of our own reaches the listener: its own address,
/// or loopback when it listens on every address.
fn wake_addr(addr: SocketAddr) -> SocketAddr {
    let mut a = addr;
    if a.ip().is_unspecified() {
        a.set_ip(match a {
            SocketAddr::V4(_) => std::net::Ipv4Addr::LOCALHOST.into(),
            SocketAddr::V6(_) => std::net::Ipv6Addr::LOCALHOST.into(),
        });
    }
    a
}

/// A listener on `addr` whose connections send at once: without
/// TCP_NODELAY, a keep-alive connection's response waits for the
/// client's delayed ACK of the previous one (Nagle), about 40 ms a frame
/// (measured: 44 ms against 6 ms for a 128^2 image). Linux gives accepted
/// sockets the listener's TCP_NODELAY.
fn listen(addr: SocketAddr) -> std::io::Result<TcpListener> {
    let l = TcpListener::bind(addr)?;
    no_delay(&l)?;
    Ok(l)
}

#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn no_delay(l: &std::net::TcpListener) -> std::io::Result<()> {
    use std::os::fd::AsRawFd;
    let one: libc::c_int = 1;
    // SAFETY: the descriptor is the listener's, open for the call; the
    // option value points at a live c_int whose size is passed with it.
    let r = unsafe {
        libc::setsockopt(
            l.as_raw_fd(),
            libc::IPPROTO_TCP,
            libc::TCP_NODELAY,
            (&one as *const libc::c_int).cast(),
            std::mem::size_of::<libc::c_int>() as libc::socklen_t,
        )
    };
    if r == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

/// Elsewhere frames may wait for a delayed ACK (docs/SERVE.md).
#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn no_delay(_: &std::net::TcpListener) -> std::io::Result<()> {
    Ok(())
}

/// `s` with every non-ASCII character escaped (`\uXXXX`), so JSON fits
/// in a header.
fn ascii_json(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        if c.is_ascii() && !c.is_ascii_control() {
            out.push(c);
        } else {
            let mut b = [0u16; 2];
            for u in c.encode_utf16(&mut b) {
                out.push_str(&format!("\\u{u:04x}"));
            }
        }
    }
    out
}

fn text(status: u16, msg: &str) -> Reply {
    Reply {
        status,
        content_type: "text/plain; charset=utf-8",
        headers: Vec::new(),
        body: format!("{msg}\n").into_bytes(),
    }
}

fn json(v: &impl serde::Serialize) -> Reply {
    match serde_json::to_vec(v) {
        Ok(body) => Reply {
            status: 200,
            content_type: "application/json",
            headers: Vec::new(),
            body,
        },
        Err(e) => text(500, &format!("cannot encode JSON: {e}")),
    }
}
