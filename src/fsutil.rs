//! Files in and out, the one place every stage goes through (prep,
//! render, export, batch, phantoms, experiments, the CLI's JSON):
//!
//! - **Writes never leave a half-written file under an output name.**
//!   Bytes go to a temporary file beside the target
//!   (`.cdvol-partial-HOST-PID-XXXXXX`, [`temp_beside`]) that is renamed
//!   onto it when complete. Error paths drop the temporary file, which
//!   removes it. A run killed outright cannot remove its own: the next
//!   write into that directory removes partial files of this host whose
//!   process is gone and that are over a minute old ([`clean_stale`]).
//! - **Modes like every other tool.** Files are created as `0666 & !umask`
//!   (the kernel applies the umask at `open(2)`), as `touch` and `cp` do.
//! - **Multi-file outputs are committed as a set** ([`FileSet`]): every
//!   member is written first, then all are renamed; a failure while
//!   writing replaces none, and a failed rename puts back the members
//!   already renamed.
//! - **Outputs are checked before any work** ([`check_outputs`]): not an
//!   input of the command (by device and inode, so through symlinks and
//!   hard links), not a directory or special file, in a directory that
//!   exists and can be written, and no file twice.
//! - **Inputs are regular files** ([`open_regular`], [`check_regular`]):
//!   a FIFO, socket or device is refused by name without being opened for
//!   reading (opening a FIFO blocks until a writer comes).
//! - **Directory walks** ([`walk`]) visit each directory once, by device
//!   and inode, follow symlinks after the real tree, and report entries
//!   they cannot read instead of failing.

use std::collections::HashSet;
use std::fs::{File, Metadata, Permissions};
use std::io::Write;
use std::os::unix::fs::{FileTypeExt, MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, SystemTime};

use tempfile::{NamedTempFile, TempPath};

/// The name every temporary output file starts with.
pub const PARTIAL_PREFIX: &str = ".cdvol-partial-";

/// Partial files younger than this are never removed as stale, whoever
/// wrote them.
pub const STALE_AGE: Duration = Duration::from_secs(60);

/// Why a file could not be written.
#[derive(Debug, thiserror::Error)]
pub enum WriteError {
    /// No temporary file could be made in the target's directory.
    #[error("{}: cannot create a temporary file beside it: {source}", path.display())]
    Temp {
        path: PathBuf,
        source: std::io::Error,
    },
    /// Writing the bytes to the temporary file failed.
    #[error("{}: {source}", path.display())]
    Write {
        path: PathBuf,
        source: std::io::Error,
    },
    /// Renaming the complete temporary file onto the target failed.
    #[error("{}: {source}", path.display())]
    Rename {
        path: PathBuf,
        source: std::io::Error,
    },
}

/// Why an output was refused before any work ([`check_outputs`]).
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The output is a file this command reads.
    #[error(
        "{}: is {}an input of this command{}; refusing to overwrite it, \
         choose another output name",
        output.display(),
        if output == input { String::new() } else { format!("{}, ", input.display()) },
        reading.as_ref().map(|m| format!(" (reading {m})")).unwrap_or_default()
    )]
    IsInput {
        output: PathBuf,
        input: PathBuf,
        /// What the command reads `input` for, when `input` is a file
        /// named by another (the data file of a sidecar, a DICOM slice).
        reading: Option<String>,
    },
    /// The output is a file the packed file read was made from (its
    /// header's `source`, or a file that source names): replacing it would
    /// lose the scan.
    #[error(
        "{}: is {}a file of the scan {} was prepared from; refusing to overwrite it, \
         choose another output name",
        output.display(),
        if output == scan { String::new() } else { format!("{}, ", scan.display()) },
        packed.display()
    )]
    IsSource {
        output: PathBuf,
        scan: PathBuf,
        packed: PathBuf,
    },
    /// The output is a directory.
    #[error("{}: is a directory, expected a file name", path.display())]
    IsDirectory { path: PathBuf },
    /// The output exists and is not a regular file (a device, say).
    #[error("{}: is {kind}, not a regular file; refusing to replace it", path.display())]
    NotRegular { path: PathBuf, kind: &'static str },
    /// The output's directory does not exist (or is not a directory).
    #[error("{}: expected a directory at {}, found {what}", path.display(), dir.display())]
    NoDirectory {
        path: PathBuf,
        dir: PathBuf,
        what: &'static str,
    },
    /// The output's directory cannot be written.
    #[error("{}: directory {} is not writable: {source}", path.display(), dir.display())]
    NotWritable {
        path: PathBuf,
        dir: PathBuf,
        source: std::io::Error,
    },
    /// One command would write the same file twice.
    #[error("{}: written twice by this command (also as {})", path.display(), other.display())]
    Twice { path: PathBuf, other: PathBuf },
    /// The output could not be examined.
    #[error("{}: cannot check the output: {source}", path.display())]
    Stat {
        path: PathBuf,
        source: std::io::Error,
    },
}

// ---------------------------------------------------------------------------
// Inputs: regular files only
// ---------------------------------------------------------------------------

/// What a file that is not regular is, for messages.
pub fn kind_of(m: &Metadata) -> &'static str {
    let t = m.file_type();
    if t.is_file() {
        "a regular file"
    } else if t.is_dir() {
        "a directory"
    } else if t.is_fifo() {
        "a FIFO"
    } else if t.is_socket() {
        "a socket"
    } else if t.is_char_device() {
        "a character device"
    } else if t.is_block_device() {
        "a block device"
    } else if t.is_symlink() {
        "a symbolic link"
    } else {
        "a special file"
    }
}

fn not_regular(m: &Metadata) -> std::io::Error {
    std::io::Error::new(
        std::io::ErrorKind::InvalidInput,
        format!("{}, not a regular file", kind_of(m)),
    )
}

/// The metadata of `path` (through symlinks) if it is a regular file; an
/// error saying what it is otherwise. Never opens the file.
pub fn check_regular(path: &Path) -> std::io::Result<Metadata> {
    let m = std::fs::metadata(path)?;
    if m.is_file() {
        Ok(m)
    } else {
        Err(not_regular(&m))
    }
}

/// Opens `path` for reading if it is a regular file. The type is checked
/// before opening (`stat` never blocks; opening a FIFO does) and again on
/// the file opened, which on Linux is opened non-blocking in case it was
/// swapped in between (regular files ignore the flag).
pub fn open_regular(path: &Path) -> std::io::Result<File> {
    check_regular(path)?;
    let mut o = std::fs::OpenOptions::new();
    o.read(true);
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        use std::os::unix::fs::OpenOptionsExt;
        o.custom_flags(libc::O_NONBLOCK);
    }
    let f = o.open(path)?;
    let m = f.metadata()?;
    if !m.is_file() {
        return Err(not_regular(&m));
    }
    Ok(f)
}

/// The whole of the regular file `path`.
pub fn read_regular(path: &Path) -> std::io::Result<Vec<u8>> {
    use std::io::Read;
    let mut f = open_regular(path)?;
    let mut b = Vec::new();
    f.read_to_end(&mut b)?;
    Ok(b)
}

/// The whole of the regular file `path` as UTF-8 text.
pub fn read_regular_to_string(path: &Path) -> std::io::Result<String> {
    String::from_utf8(read_regular(path)?)
        .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, e.utf8_error()))
}

// ---------------------------------------------------------------------------
// Directory walks
// ---------------------------------------------------------------------------

/// What [`walk`] found under a directory.
#[derive(Debug, Default)]
pub struct Walk {
    /// Regular files, each once (by device and inode), under the first
    /// path that reached it.
    pub files: Vec<PathBuf>,
    /// Entries that are neither regular files nor directories (FIFOs,
    /// sockets, devices), never opened, with what they are.
    pub special: Vec<(PathBuf, &'static str)>,
    /// Directories that could not be listed.
    pub unlistable: Vec<(PathBuf, std::io::Error)>,
    /// Entries whose type could not be found (a dangling symlink, say).
    pub unreadable: Vec<(PathBuf, std::io::Error)>,
}

/// Walks the tree under `root`: the real directories first, then the
/// directories and files that symlinks lead to, each directory once
/// (by device and inode), so links to `.` or `..` add nothing. Errors
/// below the root are recorded in the [`Walk`]; only a root that cannot
/// be listed is an error.
pub fn walk(root: &Path) -> std::io::Result<Walk> {
    let mut w = Walk::default();
    let m = std::fs::metadata(root)?;
    if !m.is_dir() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("{}, not a directory", kind_of(&m)),
        ));
    }
    let mut dirs: HashSet<(u64, u64)> = HashSet::from([(m.dev(), m.ino())]);
    let mut files: HashSet<(u64, u64)> = HashSet::new();
    // Read the root now: failing to list it fails the walk.
    let first = list(root)?;
    let mut links: std::collections::VecDeque<PathBuf> = Default::default();
    let mut pending: Vec<(PathBuf, Vec<(PathBuf, std::fs::FileType)>)> =
        vec![(root.to_path_buf(), first)];
    loop {
        // Depth-first over real directories; symlinks wait.
        while let Some((_, entries)) = pending.pop() {
            let mut subdirs = Vec::new();
            for (p, t) in entries {
                if t.is_symlink() {
                    links.push_back(p);
                } else if t.is_dir() {
                    match std::fs::symlink_metadata(&p) {
                        Ok(m) if dirs.insert((m.dev(), m.ino())) => subdirs.push(p),
                        Ok(_) => {}
                        Err(e) => w.unreadable.push((p, e)),
                    }
                } else {
                    match std::fs::symlink_metadata(&p) {
                        Ok(m) => add_file(&mut w, &mut files, p, &m),
                        Err(e) => w.unreadable.push((p, e)),
                    }
                }
            }
            // Pushed in reverse so that they pop in sorted order.
            for d in subdirs.into_iter().rev() {
                match list(&d) {
                    Ok(entries) => pending.push((d, entries)),
                    Err(e) => w.unlistable.push((d, e)),
                }
            }
        }
        let Some(link) = links.pop_front() else {
            break;
        };
        match std::fs::metadata(&link) {
            Ok(m) if m.is_dir() => {
                if dirs.insert((m.dev(), m.ino())) {
                    match list(&link) {
                        Ok(entries) => pending.push((link, entries)),
                        Err(e) => w.unlistable.push((link, e)),
                    }
                }
            }
            Ok(m) => add_file(&mut w, &mut files, link, &m),
            Err(e) => w.unreadable.push((link, e)),
        }
    }
    Ok(w)
}

fn add_file(w: &mut Walk, seen: &mut HashSet<(u64, u64)>, p: PathBuf, m: &Metadata) {
    if !m.is_file() {
        w.special.push((p, kind_of(m)));
    } else if seen.insert((m.dev(), m.ino())) {
        w.files.push(p);
    }
}

/// The entries of `dir`, sorted by name, with their own types (symlinks
/// not followed).
fn list(dir: &Path) -> std::io::Result<Vec<(PathBuf, std::fs::FileType)>> {
    let mut v = Vec::new();
    for e in std::fs::read_dir(dir)? {
        let e = e?;
        v.push((e.path(), e.file_type()?));
    }
    v.sort_by(|a, b| a.0.cmp(&b.0));
    Ok(v)
}

// ---------------------------------------------------------------------------
// Outputs: checks before work
// ---------------------------------------------------------------------------

/// The directory a file `target` is created in.
pub fn dir_of(target: &Path) -> PathBuf {
    match target.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// The (device, inode) of each of `paths` that exists, with its path:
/// what names the same file however it is spelled (symlinks, hard links).
pub fn identities(paths: &[PathBuf]) -> Vec<((u64, u64), &Path)> {
    paths
        .iter()
        .filter_map(|p| {
            std::fs::metadata(p)
                .ok()
                .map(|m| ((m.dev(), m.ino()), p.as_path()))
        })
        .collect()
}

/// Checks, before any work, that every one of `outputs` can be written
/// and replaces none of the command's `inputs` (every file it reads;
/// `source` describes the volume they make, for the message).
/// An output must not be an input (same device and inode, which sees
/// through symlinks and hard links), a directory, or an existing special
/// file; its directory must exist and take a new file (a temporary file
/// is made and removed); and no file may be named twice.
pub fn check_outputs(
    outputs: &[PathBuf],
    inputs: &[PathBuf],
    source: Option<&str>,
) -> Result<(), OutputError> {
    let ids = identities(inputs);
    let mut names: Vec<(PathBuf, &Path)> = Vec::new();
    let mut probed: HashSet<PathBuf> = HashSet::new();
    for out in outputs {
        let stat = |source| OutputError::Stat {
            path: out.clone(),
            source,
        };
        match std::fs::symlink_metadata(out) {
            Ok(own) => {
                // Through a symlink: its target's identity and type.
                let m = match std::fs::metadata(out) {
                    Ok(m) => Some(m),
                    Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
                    Err(e) => return Err(stat(e)),
                };
                if let Some(m) = &m {
                    if let Some((_, input)) = ids.iter().find(|(id, _)| *id == (m.dev(), m.ino())) {
                        return Err(OutputError::IsInput {
                            output: out.clone(),
                            input: input.to_path_buf(),
                            reading: source
                                .filter(|s| *s != input.display().to_string())
                                .map(str::to_string),
                        });
                    }
                    if m.is_dir() {
                        return Err(OutputError::IsDirectory { path: out.clone() });
                    }
                }
                if !own.is_file() && !own.file_type().is_symlink() {
                    return Err(OutputError::NotRegular {
                        path: out.clone(),
                        kind: kind_of(&own),
                    });
                }
            }
            // Nothing there (or a file where a directory should be: the
            // directory check below says so).
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::NotFound | std::io::ErrorKind::NotADirectory
                ) => {}
            Err(e) => return Err(stat(e)),
        }
        let dir = dir_of(out);
        match std::fs::metadata(&dir) {
            Ok(m) if m.is_dir() => {}
            Ok(m) => {
                return Err(OutputError::NoDirectory {
                    path: out.clone(),
                    dir,
                    what: kind_of(&m),
                })
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(OutputError::NoDirectory {
                    path: out.clone(),
                    dir,
                    what: "nothing: it does not exist",
                })
            }
            Err(e) => return Err(stat(e)),
        }
        // The name as the file system will see it: the directory resolved.
        let canon = std::fs::canonicalize(&dir).map_err(stat)?;
        let key = canon.join(out.file_name().unwrap_or_default());
        if let Some((_, other)) = names.iter().find(|(k, _)| *k == key) {
            return Err(OutputError::Twice {
                path: out.clone(),
                other: other.to_path_buf(),
            });
        }
        names.push((key, out));
        if probed.insert(canon) {
            temp_beside(out).map_err(|source| OutputError::NotWritable {
                path: out.clone(),
                dir: dir.clone(),
                source,
            })?;
        }
    }
    Ok(())
}

// ---------------------------------------------------------------------------
// Writes: temporary files, modes, stale partial files
// ---------------------------------------------------------------------------

/// Who writes partial files here: the host name and, on Linux, the PID
/// namespace (two containers may share a host name, not their PIDs).
/// `None` where that cannot be told: then no partial file is ever
/// judged stale.
fn host_tag() -> Option<&'static str> {
    static TAG: OnceLock<Option<String>> = OnceLock::new();
    TAG.get_or_init(|| {
        if !cfg!(target_os = "linux") {
            return None;
        }
        let host = std::fs::read_to_string("/proc/sys/kernel/hostname").ok()?;
        let host: String = host
            .trim()
            .chars()
            .take(64)
            .map(|c| {
                if c.is_ascii_alphanumeric() || c == '.' || c == '-' {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        let ns = std::fs::read_link("/proc/self/ns/pid").ok()?;
        let ns: String = ns
            .to_string_lossy()
            .chars()
            .filter(char::is_ascii_digit)
            .collect();
        (!host.is_empty() && !ns.is_empty()).then(|| format!("{host}.{ns}"))
    })
    .as_deref()
}

/// `.cdvol-partial-HOST-PID-`: the start of this process's partial files
/// (a random suffix follows).
fn partial_prefix() -> String {
    format!(
        "{PARTIAL_PREFIX}{}-{}-",
        host_tag().unwrap_or("unknown"),
        std::process::id()
    )
}

/// The host tag and process id a partial file's name records.
fn parse_partial(name: &str) -> Option<(&str, u32)> {
    let rest = name.strip_prefix(PARTIAL_PREFIX)?;
    let mut it = rest.rsplitn(3, '-');
    let _random = it.next()?;
    let pid = it.next()?.parse().ok()?;
    let host = it.next()?;
    Some((host, pid))
}

/// Whether process `pid` of this PID namespace is alive (or may be: any
/// doubt counts as alive).
fn maybe_alive(pid: u32) -> bool {
    if !Path::new("/proc/self").exists() {
        return true;
    }
    Path::new("/proc").join(pid.to_string()).exists()
}

/// Removes the partial files in `dir` left by killed runs: those whose
/// name says they were written on this host (and PID namespace) by a
/// process that is gone, and that were last modified over [`STALE_AGE`]
/// ago. Files of other hosts, of live processes, young files, and files
/// of other names are never touched. Each directory is cleaned once per
/// process. Returns the files removed.
pub fn clean_stale(dir: &Path) -> Vec<PathBuf> {
    static DONE: Mutex<Option<HashSet<PathBuf>>> = Mutex::new(None);
    let Some(tag) = host_tag() else {
        return Vec::new();
    };
    let key = std::fs::canonicalize(dir).unwrap_or_else(|_| dir.to_path_buf());
    {
        let mut done = DONE.lock().unwrap_or_else(|e| e.into_inner());
        if !done.get_or_insert_with(HashSet::new).insert(key) {
            return Vec::new();
        }
    }
    let Ok(rd) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let me = std::process::id();
    let now = SystemTime::now();
    let mut removed = Vec::new();
    for e in rd.flatten() {
        let name = e.file_name();
        let Some((host, pid)) = name.to_str().and_then(parse_partial) else {
            continue;
        };
        if host != tag || pid == me || maybe_alive(pid) {
            continue;
        }
        let p = e.path();
        let old = std::fs::symlink_metadata(&p).is_ok_and(|m| {
            m.is_file()
                && m.modified()
                    .ok()
                    .and_then(|t| now.duration_since(t).ok())
                    .is_some_and(|age| age > STALE_AGE)
        });
        if old && std::fs::remove_file(&p).is_ok() {
            removed.push(p);
        }
    }
    removed
}

/// A new, empty temporary file beside `target` (same directory, so the
/// rename is atomic), created with mode `0666 & !umask` and named after
/// this host and process; stale partial files of the directory are
/// cleaned first ([`clean_stale`]). Dropping it removes it.
pub fn temp_beside(target: &Path) -> std::io::Result<NamedTempFile> {
    let dir = dir_of(target);
    clean_stale(&dir);
    tempfile::Builder::new()
        .prefix(&partial_prefix())
        .permissions(Permissions::from_mode(0o666))
        .tempfile_in(&dir)
}

/// Renames the complete temporary file `tmp` onto `target`.
pub fn commit(tmp: NamedTempFile, target: &Path) -> Result<(), WriteError> {
    tmp.persist(target).map_err(|e| WriteError::Rename {
        path: target.to_path_buf(),
        source: e.error,
    })?;
    Ok(())
}

/// `bytes` in a temporary file beside `target`, not yet renamed.
fn staged(target: &Path, bytes: &[u8]) -> Result<NamedTempFile, WriteError> {
    let mut tmp = temp_beside(target).map_err(|source| WriteError::Temp {
        path: target.to_path_buf(),
        source,
    })?;
    tmp.write_all(bytes)
        .and_then(|_| tmp.flush())
        .map_err(|source| WriteError::Write {
            path: target.to_path_buf(),
            source,
        })?;
    Ok(tmp)
}

/// Writes `bytes` to `target` through a temporary file beside it, renamed
/// when complete.
pub fn write_atomic(target: &Path, bytes: &[u8]) -> Result<(), WriteError> {
    commit(staged(target, bytes)?, target)
}

/// Files written as one set: each member goes to its temporary file as it
/// comes ([`FileSet::add`]), holding no descriptor after that; nothing is
/// renamed until [`FileSet::commit`]. Dropped uncommitted, it removes
/// every temporary file and no target changes.
#[derive(Default)]
pub struct FileSet {
    members: Vec<(TempPath, PathBuf)>,
}

impl FileSet {
    pub fn new() -> FileSet {
        FileSet::default()
    }

    /// Adds `bytes` as the next version of `target`.
    pub fn add_bytes(&mut self, target: &Path, bytes: &[u8]) -> Result<(), WriteError> {
        let tmp = staged(target, bytes)?;
        self.add(tmp, target);
        Ok(())
    }

    /// Adds a complete temporary file (from [`temp_beside`]) as the next
    /// version of `target`.
    pub fn add(&mut self, tmp: NamedTempFile, target: &Path) {
        self.members
            .push((tmp.into_temp_path(), target.to_path_buf()));
    }

    /// The targets, in the order added.
    pub fn targets(&self) -> Vec<PathBuf> {
        self.members.iter().map(|(_, t)| t.clone()).collect()
    }

    /// Renames every member onto its target. Before that, each existing
    /// target is kept under a partial name (a hard link); if a rename
    /// fails, the targets already replaced get their old files back (or
    /// are removed if they had none) and the error is returned.
    pub fn commit(self) -> Result<Vec<PathBuf>, WriteError> {
        let targets = self.targets();
        if self.members.len() == 1 {
            let (tmp, target) = self.members.into_iter().next().expect("one member");
            tmp.persist(&target).map_err(|e| WriteError::Rename {
                path: target.clone(),
                source: e.error,
            })?;
            return Ok(targets);
        }
        // Old versions, kept until every rename has succeeded; dropping a
        // backup removes it.
        let mut backups: Vec<Option<TempPath>> = Vec::with_capacity(self.members.len());
        for (_, target) in &self.members {
            let backup = if std::fs::symlink_metadata(target).is_ok_and(|m| m.is_file()) {
                tempfile::Builder::new()
                    .prefix(&partial_prefix())
                    .make_in(dir_of(target), |p| std::fs::hard_link(target, p))
                    .ok()
                    .map(NamedTempFile::into_temp_path)
            } else {
                None
            };
            backups.push(backup);
        }
        let mut done: Vec<usize> = Vec::new();
        for (i, (tmp, target)) in self.members.into_iter().enumerate() {
            if let Err(e) = tmp.persist(&target) {
                // Put back what was replaced (best effort).
                for &j in done.iter().rev() {
                    let t = &targets[j];
                    match backups[j].take() {
                        Some(b) => {
                            let _ = b.persist(t);
                        }
                        None => {
                            let _ = std::fs::remove_file(t);
                        }
                    }
                }
                return Err(WriteError::Rename {
                    path: targets[i].clone(),
                    source: e.error,
                });
            }
            done.push(i);
        }
        Ok(targets)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn partials(dir: &Path) -> Vec<String> {
        std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with(PARTIAL_PREFIX))
            .collect()
    }

    #[test]
    fn partial_names_parse_back() {
        let p = partial_prefix();
        let name = format!("{p}a1B2c3");
        let (host, pid) = parse_partial(&name).unwrap();
        assert_eq!(pid, std::process::id());
        assert_eq!(Some(host), host_tag().or(Some("unknown")));
        assert_eq!(
            parse_partial(".cdvol-partial-my-host.1-2.4026-77-xyzXYZ"),
            Some(("my-host.1-2.4026", 77))
        );
        assert_eq!(parse_partial(".cdvol-partial-w7y111"), None);
        assert_eq!(parse_partial("other"), None);
    }

    /// A set whose last rename fails puts the first members back: the
    /// old files are as they were, and no temporary file is left.
    #[test]
    fn a_set_whose_rename_fails_changes_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("a");
        let b = dir.path().join("b");
        let c = dir.path().join("c");
        std::fs::write(&a, b"old a").unwrap();
        // `c` cannot be replaced by a file: a directory with an entry.
        std::fs::create_dir_all(c.join("x")).unwrap();
        let mut set = FileSet::new();
        set.add_bytes(&a, b"new a").unwrap();
        set.add_bytes(&b, b"new b").unwrap();
        set.add_bytes(&c, b"new c").unwrap();
        let err = set.commit().unwrap_err();
        assert!(err.to_string().contains("/c"), "{err}");
        assert_eq!(std::fs::read(&a).unwrap(), b"old a");
        assert!(!b.exists());
        assert!(c.join("x").is_dir());
        assert!(
            partials(dir.path()).is_empty(),
            "{:?}",
            partials(dir.path())
        );
    }

    /// A set dropped before its commit removes its temporary files and
    /// leaves the targets alone; a committed one replaces them all.
    #[test]
    fn a_set_is_all_or_nothing() {
        let dir = tempfile::tempdir().unwrap();
        let a = dir.path().join("a");
        std::fs::write(&a, b"old").unwrap();
        let mut set = FileSet::new();
        set.add_bytes(&a, b"new").unwrap();
        set.add_bytes(&dir.path().join("b"), b"b").unwrap();
        assert_eq!(partials(dir.path()).len(), 2);
        drop(set);
        assert!(partials(dir.path()).is_empty());
        assert_eq!(std::fs::read(&a).unwrap(), b"old");
        let mut set = FileSet::new();
        set.add_bytes(&a, b"new").unwrap();
        set.add_bytes(&dir.path().join("b"), b"b").unwrap();
        set.commit().unwrap();
        assert_eq!(std::fs::read(&a).unwrap(), b"new");
        assert_eq!(std::fs::read(dir.path().join("b")).unwrap(), b"b");
        assert!(partials(dir.path()).is_empty());
    }

    #[test]
    fn walk_visits_each_directory_once() {
        let dir = tempfile::tempdir().unwrap();
        let r = dir.path();
        std::fs::create_dir_all(r.join("a/b")).unwrap();
        std::fs::write(r.join("a/b/f"), b"x").unwrap();
        std::os::unix::fs::symlink(".", r.join("loop")).unwrap();
        std::os::unix::fs::symlink("../..", r.join("a/b/up")).unwrap();
        std::os::unix::fs::symlink("a", r.join("0a")).unwrap();
        std::os::unix::fs::symlink("nowhere", r.join("dangling")).unwrap();
        let w = walk(r).unwrap();
        assert_eq!(w.files, [r.join("a/b/f")]);
        assert_eq!(w.unreadable.len(), 1);
        assert!(w.unlistable.is_empty());
    }
}
