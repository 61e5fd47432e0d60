//! `cdvol serve`: a browser viewer over the tile renderer. The packed
//! files named on the command line are opened once; a page (embedded,
//! nothing fetched from elsewhere) asks for images by view and options,
//! and every request renders through one shared brick cache, so frames
//! after the first are warm. docs/SERVE.md has the endpoints, the choice
//! of HTTP crate and the measurements.
//!
//! ```text
//! request.rs  query string -> checked ViewRequest -> camera, options,
//!             the equivalent `cdvol render` command
//! engine.rs   the files, the shared cache, one render at a time,
//!             per-session cancellation, PNG/JPEG/WebP encoding
//! http.rs     connections (httparse heads, bounded), routes, 400s with
//!             messages
//! page.html   the viewer (orbit, zoom, pan, modes, presets, readouts)
//! ```

mod engine;
mod http;
pub mod request;

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::sync::Arc;

pub use engine::{encode, open_files, Engine, Failure, Rendered, Served};
pub use http::{Server, IDLE, MAX_CONNECTIONS, MAX_HEAD, MAX_HEADERS};

/// Largest `--cache-mb`.
pub const MAX_CACHE_MB: usize = 1 << 20;

/// How `cdvol serve` runs.
#[derive(Debug, Clone)]
pub struct ServeConfig {
    pub files: Vec<PathBuf>,
    /// Address to listen on; port 0 picks a free one.
    pub bind: SocketAddr,
    /// Brick cache budget, MiB, shared by all requests.
    pub cache_mb: usize,
    /// Render worker threads (0: one per core).
    pub threads: usize,
}

/// Why the server could not start or stopped.
#[derive(Debug, thiserror::Error)]
pub enum ServeError {
    /// A packed file could not be opened.
    #[error(transparent)]
    Open(#[from] crate::format::FormatError),
    #[error("no files: name at least one packed file to serve")]
    NoFiles,
    /// Binding the address failed (in use, not local, ...).
    #[error("cannot listen on {addr}: {msg}")]
    Bind { addr: SocketAddr, msg: String },
    #[error("cache_mb {0}, expected 1..={MAX_CACHE_MB}")]
    CacheMb(usize),
    #[error("threads {0}, expected 0..={max}", max = crate::render::job::MAX_THREADS)]
    Threads(usize),
    #[error("cannot start the render threads: {0}")]
    Pool(#[from] rayon::ThreadPoolBuildError),
    #[error("cannot install the Ctrl-C/SIGTERM handler: {0}")]
    Signal(#[from] ctrlc::Error),
}

impl ServeConfig {
    /// The checks before anything is opened.
    pub fn check(&self) -> Result<(), ServeError> {
        if self.files.is_empty() {
            return Err(ServeError::NoFiles);
        }
        if !(1..=MAX_CACHE_MB).contains(&self.cache_mb) {
            return Err(ServeError::CacheMb(self.cache_mb));
        }
        if self.threads > crate::render::job::MAX_THREADS {
            return Err(ServeError::Threads(self.threads));
        }
        Ok(())
    }
}

/// Sets `stop` on Ctrl-C or SIGTERM (once per process): the server then
/// finishes the requests in hand and [`Server::run`] returns.
pub fn stop_on_signals(stop: Arc<AtomicBool>) -> Result<(), ServeError> {
    ctrlc::set_handler(move || stop.store(true, std::sync::atomic::Ordering::Relaxed))?;
    Ok(())
}
