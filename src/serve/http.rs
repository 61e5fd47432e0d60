//! The HTTP side of `cdvol serve` (tiny_http, docs/SERVE.md says why):
//! [`HANDLERS`] threads take requests from the listener, answer the page
//! and JSON at once and hand image requests to the [`Engine`]. Routes are
//! fixed strings; no part of a URL reaches the file system. Every refusal
//! is a status with a plain-text message.

use std::io::Cursor;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::Duration;

use tiny_http::{Header, Method, Request, Response};

use super::engine::{Engine, Served};
use super::request::{ViewRequest, MAX_SIDE};
use super::{ServeConfig, ServeError, HANDLERS};

/// The viewer page, every asset inline.
const PAGE: &str = include_str!("page.html");

/// A bound server, ready to [`run`](Server::run).
pub struct Server<'v> {
    http: tiny_http::Server,
    engine: Engine<'v>,
    stop: Arc<AtomicBool>,
    addr: SocketAddr,
}

type Reply = Response<Cursor<Vec<u8>>>;

impl<'v> Server<'v> {
    /// Binds `cfg.bind` for `files` (opened by the caller, who keeps them
    /// for the server's life).
    pub fn bind(files: &'v [Served], cfg: &ServeConfig) -> Result<Server<'v>, ServeError> {
        cfg.check()?;
        let bind_err = |msg: String| ServeError::Bind {
            addr: cfg.bind,
            msg,
        };
        let listener = listen(cfg.bind).map_err(|e| bind_err(e.to_string()))?;
        let http = tiny_http::Server::from_listener(listener, None)
            .map_err(|e| bind_err(e.to_string()))?;
        let addr = http
            .server_addr()
            .to_ip()
            .ok_or_else(|| bind_err("not an IP address".into()))?;
        Ok(Server {
            http,
            engine: Engine::new(files, cfg.cache_mb << 20, cfg.threads)?,
            stop: Arc::new(AtomicBool::new(false)),
            addr,
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
            for _ in 0..HANDLERS {
                s.spawn(|| self.handle_until_stopped());
            }
        });
    }

    fn handle_until_stopped(&self) {
        while !self.stop.load(Ordering::Relaxed) {
            match self.http.recv_timeout(Duration::from_millis(100)) {
                Ok(Some(rq)) => self.handle(rq),
                Ok(None) => {}
                Err(e) => {
                    eprintln!("cdvol serve: {e}");
                    std::thread::sleep(Duration::from_millis(100));
                }
            }
        }
    }

    fn handle(&self, rq: Request) {
        let reply = self.route(&rq);
        // A client that went away is no error of ours.
        let _ = rq.respond(reply);
    }

    fn route(&self, rq: &Request) -> Reply {
        if *rq.method() != Method::Get {
            return text(405, "only GET is served");
        }
        if let Some(host) = self.foreign_host(rq) {
            return text(
                403,
                &format!(
                    "Host {host:?} refused: a server on a loopback address answers only to \
                     localhost, 127.0.0.1 or [::1] (another name may be a DNS rebinding page)"
                ),
            );
        }
        let url = rq.url();
        let (path, query) = url.split_once('?').unwrap_or((url, ""));
        match path {
            "/" | "/index.html" => {
                with_type(Response::from_string(PAGE), "text/html; charset=utf-8")
            }
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
    fn foreign_host(&self, rq: &Request) -> Option<String> {
        if !self.addr.ip().is_loopback() {
            return None;
        }
        let host = rq
            .headers()
            .iter()
            .find(|h| h.field.equiv("Host"))?
            .value
            .as_str()
            .to_ascii_lowercase();
        let name = match host.strip_prefix('[') {
            Some(v6) => v6.split(']').next().unwrap_or(""),
            None => host.split(':').next().unwrap_or(""),
        };
        (!matches!(name, "localhost" | "127.0.0.1" | "::1")).then_some(host)
    }

    fn image(&self, query: &str) -> Reply {
        let req = match ViewRequest::parse(query, self.engine.files.len()) {
            Ok(r) => r,
            Err(e) => return text(400, &e.to_string()),
        };
        match self.engine.render(&req) {
            Ok(r) => {
                let stats = serde_json::to_string(&r).unwrap_or_default();
                let resp = with_type(Response::from_data(r.bytes), r.content_type);
                match Header::from_bytes("X-Cdvol-Stats", ascii_json(&stats)) {
                    Ok(h) => resp.with_header(h),
                    Err(()) => resp,
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
                serde_json::json!({
                    "index": i,
                    "name": f.name,
                    "oriented": h.orientation.is_some(),
                    "mirrored": h.orientation.as_ref().is_some_and(|o| o.nearest().det() < 0.0),
                    "info": crate::info::Info::of(&f.vol),
                })
            })
            .collect();
        let presets: Vec<serde_json::Value> = crate::presets::all()
            .iter()
            .map(|p| {
                serde_json::json!({
                    "name": p.name, "modality": p.modality.name(),
                    "description": p.description, "iso": p.iso,
                    "window": p.window.map(|w| [w.width, w.level]),
                    "support": p.support(),
                })
            })
            .collect();
        serde_json::json!({
            "files": files,
            "presets": presets,
            "views": crate::orient::NamedView::NAMES.split(", ").collect::<Vec<_>>(),
            "max_side": MAX_SIDE,
            "cache_mb": self.engine.cache_bytes >> 20,
        })
    }
}

/// A listener on `addr` whose connections send at once: without
/// TCP_NODELAY, a keep-alive connection's response waits for the
/// client's delayed ACK of the previous one (Nagle), about 40 ms a frame
/// (measured: 44 ms against 6 ms for a 128^2 image). Linux gives accepted
/// sockets the listener's TCP_NODELAY.
fn listen(addr: SocketAddr) -> std::io::Result<std::net::TcpListener> {
    let l = std::net::TcpListener::bind(addr)?;
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

fn with_type(mut r: Reply, content_type: &str) -> Reply {
    for (k, v) in [
        ("Cache-Control", "no-store"),
        ("Content-Type", content_type),
    ] {
        if let Ok(h) = Header::from_bytes(k, v) {
            r.add_header(h);
        }
    }
    r
}

fn text(status: u16, msg: &str) -> Reply {
    with_type(
        Response::from_string(format!("{msg}\n")),
        "text/plain; charset=utf-8",
    )
    .with_status_code(status)
}

fn json(v: &impl serde::Serialize) -> Reply {
    match serde_json::to_vec(v) {
        Ok(b) => with_type(Response::from_data(b), "application/json"),
        Err(e) => text(500, &format!("cannot encode JSON: {e}")),
    }
}
