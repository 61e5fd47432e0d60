//! Progress reporting from the library. The library only calls this
//! trait; the binary turns it into indicatif bars on stderr.

/// Receives progress of long operations. All methods default to nothing.
pub trait Progress: Sync {
    /// A stage with `total` units of work starts.
    fn begin(&self, _stage: &str, _total: u64) {}
    /// `n` more units are done.
    fn advance(&self, _n: u64) {}
    /// The current stage is finished.
    fn end(&self) {}
    /// A line of output (a finished item of a batch): printed to stdout,
    /// above the bar where one is shown.
    fn println(&self, line: &str) {
        println!("{line}");
    }
}

/// Reports nothing.
pub struct NoProgress;

impl Progress for NoProgress {}
