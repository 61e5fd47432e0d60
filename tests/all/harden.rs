//! Files under hostile conditions (issue 17): output modes follow the
//! umask, an output never overwrites an input of the same command, special
//! files are refused by name instead of hanging, directory walks survive
//! symlink loops and unreadable entries, killed runs leave no partial file
//! that is never cleaned, and multi-file outputs are committed as a set.
//! docs/RELIABILITY.md ("Files") names each test here.

use std::os::unix::fs::{FileTypeExt, MetadataExt, PermissionsExt};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::{cdvol, dicom_series, has_all, run, snapshot};

fn ok(c: &mut Command) -> String {
    let o = run(c, Duration::from_secs(60));
    assert!(
        o.status.success(),
        "{c:?} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Runs `c` (10 s at most), requires a non-zero exit and returns stderr.
fn refused(c: &mut Command) -> String {
    let o = run(c, Duration::from_secs(10));
    assert!(
        !o.status.success(),
        "{c:?} succeeded, expected a refusal: {}",
        String::from_utf8_lossy(&o.stdout)
    );
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A small CT phantom `NAME.json` + `NAME.raw` in `dir`.
fn phantom(dir: &Path, name: &str) -> PathBuf {
    let p = dir.join(format!("{name}.json"));
    ok(cdvol()
        .args(["-q", "phantom", "ct", "--dims", "24,20,18", "-o"])
        .arg(&p));
    p
}

/// `input` prepared to `out` (8-cell bricks, iso 300).
fn prep(input: &Path, out: &Path) {
    ok(cdvol()
        .args(["-q", "prep", "--iso", "300", "--brick", "8"])
        .arg(input)
        .arg("-o")
        .arg(out));
}

fn render(file: &Path) -> Command {
    let mut c = cdvol();
    c.args(["-q", "render", "--width", "24", "--height", "20"])
        .arg(file);
    c
}

fn partials(dir: &Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".cdvol-partial-"))
        .collect()
}

// ---------------------------------------------------------------------------
// 1. Modes like every other tool
// ---------------------------------------------------------------------------

/// `cdvol ARGS` under `umask MASK` (a shell sets it, then execs cdvol).
fn cdvol_umask(mask: &str, args: &[&str], dir: &Path) -> String {
    ok(Command::new("sh")
        .current_dir(dir)
        .arg("-c")
        .arg(format!("umask {mask}; exec \"$0\" \"$@\""))
        .arg(env!("CARGO_BIN_EXE_cdvol"))
        .arg("-q")
        .args(args))
}

#[test]
fn modes_follow_the_umask() {
    for (mask, want) in [("022", 0o644), ("027", 0o640)] {
        let tmp = tempfile::tempdir().unwrap();
        let d = tmp.path();
        let run = |args: &[&str]| cdvol_umask(mask, args, d);
        run(&["phantom", "ct", "--dims", "24,20,18", "-o", "ct.json"]);
        run(&["phantom", "spheres", "--size", "16", "-o", "sp.json"]);
        run(&[
            "prep", "ct.json", "-o", "ct.cdv", "--iso", "300", "--brick", "8",
        ]);
        let small = ["--width", "24", "--height", "20"];
        let r = |extra: &[&str]| {
            let mut a = vec!["render", "ct.cdv"];
            a.extend_from_slice(&small);
            a.extend_from_slice(extra);
            run(&a);
        };
        r(&["-o", "s.png", "--stats", "s.stats.json"]);
        r(&["-o", "d.png", "--mode", "depth"]);
        r(&["-o", "t.png", "--frames", "2"]);
        r(&["-o", "p0.cdvpart", "--shard", "0/2"]);
        r(&["-o", "p1.cdvpart", "--shard", "1/2"]);
        run(&["assemble", "p0.cdvpart", "p1.cdvpart", "-o", "a.png"]);
        run(&["export", "ct.cdv", "--what", "codes", "-o", "e.json"]);
        std::fs::create_dir(d.join("in")).unwrap();
        std::fs::copy(d.join("ct.json"), d.join("in/ct.json")).unwrap();
        std::fs::copy(d.join("ct.raw"), d.join("in/ct.raw")).unwrap();
        run(&[
            "prep-batch",
            "in",
            "-o",
            "out",
            "--iso",
            "300",
            "--brick",
            "8",
        ]);
        let files = [
            "ct.json",
            "ct.raw",
            "sp.json",
            "sp.raw",
            "sp.spheres.json",
            "ct.cdv",
            "s.png",
            "s.stats.json",
            "d.png",
            "d.f32",
            "d.depth16.png",
            "t.0000.png",
            "t.0001.png",
            "p0.cdvpart",
            "a.png",
            "e.json",
            "e.raw",
            "out/ct.json.cdv",
            "out/batch.json",
        ];
        let mut bad = Vec::new();
        for f in files {
            let p = d.join(f);
            let Ok(m) = std::fs::metadata(&p) else {
                panic!("{f} was not written");
            };
            if m.permissions().mode() & 0o7777 != want {
                bad.push(format!("{f}: {:o}", m.permissions().mode() & 0o7777));
            }
        }
        assert!(
            bad.is_empty(),
            "umask {mask}: expected mode {want:o}, found {bad:?}"
        );
    }
}

// ---------------------------------------------------------------------------
// 2. Inputs are never overwritten
// ---------------------------------------------------------------------------

/// Every command whose output names one of its inputs (directly, through
/// a symlink, or as a member of a multi-file output) is refused naming
/// both, and leaves every file as it was.
#[test]
fn an_output_that_is_an_input_is_refused() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let s = phantom(d, "s");
    let r = d.join("r.cdv");
    prep(&s, &r);
    ok(render(&r)
        .args(["--shard", "0/2", "-o"])
        .arg(d.join("P0.cdvpart")));
    ok(render(&r)
        .args(["--shard", "1/2", "-o"])
        .arg(d.join("P1.cdvpart")));
    // A packed file under the names a depth render and a turntable would
    // write beside their PNG.
    std::fs::copy(&r, d.join("x.f32")).unwrap();
    std::fs::copy(&r, d.join("t.0001.png")).unwrap();
    std::os::unix::fs::symlink("s.raw", d.join("link.cdv")).unwrap();
    // The packed file under an image name (a render's output must be one:
    // `-o r.cdv` is refused for its extension before this check).
    std::fs::hard_link(&r, d.join("r-link.png")).unwrap();
    std::fs::hard_link(d.join("P0.cdvpart"), d.join("P0-link.png")).unwrap();
    let series = d.join("dcm");
    let slices = dicom_series::write_series(&series);
    let before = snapshot(d);

    let p = |n: &str| d.join(n);
    let cases: Vec<(Command, &str, &str)> = vec![
        {
            let mut c = cdvol();
            c.args(["prep", "--iso", "300"])
                .arg(&s)
                .arg("-o")
                .arg(p("s.raw"));
            (c, "s.json", "s.raw")
        },
        {
            let mut c = cdvol();
            c.args(["prep", "--iso", "300"]).arg(&s).arg("-o").arg(&s);
            (c, "s.json", "s.json")
        },
        {
            // Through a symlink to the raw data.
            let mut c = cdvol();
            c.args(["prep", "--iso", "300"])
                .arg(&s)
                .arg("-o")
                .arg(p("link.cdv"));
            (c, "link.cdv", "s.raw")
        },
        {
            // Spelled another way.
            let mut c = cdvol();
            c.current_dir(d)
                .args(["prep", "--iso", "300", "s.json", "-o", "./dcm/../s.raw"]);
            (c, "s.json", "s.raw")
        },
        {
            let mut c = cdvol();
            c.args(["prep", "--iso", "300"])
                .arg(&series)
                .arg("-o")
                .arg(&slices[3]);
            (c, "dcm", slices[3].file_name().unwrap().to_str().unwrap())
        },
        {
            let mut c = render(&r);
            c.arg("-o").arg(p("r-link.png"));
            (c, "r.cdv", "r-link.png")
        },
        {
            let mut c = render(&r);
            c.arg("-o").arg(p("ok.png")).arg("--stats").arg(&r);
            (c, "r.cdv", "r.cdv")
        },
        {
            // The depth set's raw f32 is the input.
            let mut c = render(&p("x.f32"));
            c.args(["--mode", "depth", "-o"]).arg(p("x.png"));
            (c, "x.f32", "x.f32")
        },
        {
            // Frame 1 of a turntable is the input.
            let mut c = render(&p("t.0001.png"));
            c.args(["--frames", "3", "-o"]).arg(p("t.png"));
            (c, "t.0001.png", "t.0001.png")
        },
        {
            let mut c = cdvol();
            c.args(["export", "--what", "values"])
                .arg(&r)
                .arg("-o")
                .arg(&r);
            (c, "r.cdv", "r.cdv")
        },
        {
            let mut c = cdvol();
            c.arg("assemble")
                .arg(p("P0.cdvpart"))
                .arg(p("P1.cdvpart"))
                .arg("-o")
                .arg(p("P0-link.png"));
            (c, "P0.cdvpart", "P0-link.png")
        },
        {
            let mut c = cdvol();
            c.arg("assemble")
                .arg(p("P0.cdvpart"))
                .arg(p("P1.cdvpart"))
                .arg("-o")
                .arg(p("a.png"))
                .arg("--stats")
                .arg(p("P1.cdvpart"));
            (c, "P1.cdvpart", "P1.cdvpart")
        },
    ];
    for (mut c, input, output) in cases {
        let err = refused(&mut c);
        has_all(&err, &[input, output, "input"]);
        assert_eq!(snapshot(d), before, "{c:?} changed files");
    }
}

/// An output that is a directory, or in a directory that does not exist
/// or cannot be written, is refused before any work (no partial file, no
/// "wrote", an error naming the path).
#[test]
fn output_directory_is_checked_before_work() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let s = phantom(d, "s");
    std::fs::create_dir(d.join("dir.cdv")).unwrap();
    std::fs::create_dir(d.join("d.depth16.png")).unwrap();
    let before = snapshot(d);
    let err = refused(
        cdvol()
            .args(["prep", "--iso", "300"])
            .arg(&s)
            .arg("-o")
            .arg(d.join("dir.cdv")),
    );
    has_all(&err, &["dir.cdv", "is a directory"]);
    let err = refused(
        cdvol()
            .args(["prep", "--iso", "300"])
            .arg(&s)
            .arg("-o")
            .arg(d.join("nowhere/x.cdv")),
    );
    has_all(&err, &["nowhere", "does not exist"]);
    // A member of the depth set.
    let r = d.join("r.cdv");
    prep(&s, &r);
    let before_render = snapshot(d);
    let err = refused(
        render(&r)
            .args(["--mode", "depth", "-o"])
            .arg(d.join("d.png")),
    );
    has_all(&err, &["d.depth16.png", "is a directory"]);
    assert_eq!(snapshot(d), before_render);
    assert!(partials(d).is_empty(), "{:?}", partials(d));
    drop(before);

    // Not writable (as an unprivileged user: root may write anywhere).
    let ro = d.join("ro");
    std::fs::create_dir(&ro).unwrap();
    std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o555)).unwrap();
    if let Some(mut c) = unprivileged() {
        let err = refused(
            c.args(["prep", "--iso", "300"])
                .arg(&s)
                .arg("-o")
                .arg(ro.join("x.cdv")),
        );
        has_all(&err, &["ro", "not writable"]);
    } else {
        eprintln!("skipped the unwritable-directory case: cannot drop privileges");
    }
    std::fs::set_permissions(&ro, std::fs::Permissions::from_mode(0o755)).unwrap();
}

/// `cdvol` run without the power to ignore file permissions: as is for a
/// normal user; for root, with CAP_DAC_OVERRIDE and CAP_DAC_READ_SEARCH
/// dropped from the bounding set (setpriv), if that works here.
fn unprivileged() -> Option<Command> {
    let uid = std::fs::metadata("/proc/self")
        .map(|m| m.uid())
        .unwrap_or(0);
    if uid != 0 {
        return Some(cdvol());
    }
    let drop = "--bounding-set=-dac_override,-dac_read_search";
    let probe = tempfile::tempdir().unwrap();
    std::fs::set_permissions(probe.path(), std::fs::Permissions::from_mode(0o555)).unwrap();
    let works = Command::new("setpriv")
        .args([drop, "touch"])
        .arg(probe.path().join("x"))
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| !s.success());
    std::fs::set_permissions(probe.path(), std::fs::Permissions::from_mode(0o755)).unwrap();
    if !works {
        return None;
    }
    let mut c = Command::new("setpriv");
    c.arg(drop).arg(env!("CARGO_BIN_EXE_cdvol"));
    Some(c)
}

// ---------------------------------------------------------------------------
// 3. Regular files only
// ---------------------------------------------------------------------------

fn mkfifo(p: &Path) {
    let s = Command::new("mkfifo").arg(p).status().unwrap();
    assert!(s.success(), "mkfifo {}", p.display());
    assert!(std::fs::metadata(p).unwrap().file_type().is_fifo());
}

/// FIFOs, sockets and devices given to prep, info, render and prep-batch
/// (directly, or as the data file of a sidecar) are refused by name at
/// once; before, each of these hung for ever.
#[test]
fn special_files_are_refused_without_hanging() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let s = phantom(d, "s");
    let r = d.join("r.cdv");
    prep(&s, &r);
    let fifo = d.join("f.json");
    mkfifo(&fifo);
    let fifo_cdv = d.join("f.cdv");
    mkfifo(&fifo_cdv);
    let nrrd = d.join("f.nhdr");
    mkfifo(&nrrd);
    let sock_path = d.join("sock.cdv");
    let _sock = std::os::unix::net::UnixListener::bind(&sock_path).unwrap();
    // A sidecar whose data file is a FIFO.
    let data_fifo = d.join("df.json");
    let text = std::fs::read_to_string(&s)
        .unwrap()
        .replace("\"s.raw\"", "\"df.raw\"");
    std::fs::write(&data_fifo, text).unwrap();
    mkfifo(&d.join("df.raw"));

    let out = d.join("o.cdv");
    let prep_of = |input: &Path| {
        let mut c = cdvol();
        c.args(["prep", "--iso", "300"])
            .arg(input)
            .arg("-o")
            .arg(&out);
        c
    };
    for (mut c, name) in [
        (prep_of(&fifo), "f.json"),
        (prep_of(&nrrd), "f.nhdr"),
        (prep_of(Path::new("/dev/null")), "/dev/null"),
        (prep_of(&data_fifo), "df.raw"),
        (prep_of(&sock_path), "sock.cdv"),
    ] {
        let err = refused(&mut c);
        has_all(&err, &[name, "not a regular file"]);
    }
    for f in [&fifo_cdv, &sock_path, Path::new("/dev/zero")] {
        let name = f.file_name().unwrap().to_str().unwrap();
        let err = refused(cdvol().arg("info").arg(f));
        has_all(&err, &[name, "not a regular file"]);
        let err = refused(render(f).arg("-o").arg(d.join("x.png")));
        has_all(&err, &[name, "not a regular file"]);
    }
    let err = refused(
        cdvol()
            .args(["assemble", "-o"])
            .arg(d.join("a.png"))
            .arg(&fifo_cdv),
    );
    has_all(&err, &["f.cdv", "not a regular file"]);

    // prep-batch: a FIFO with a volume's name fails as one input; one
    // without (it could only be a DICOM file) is not opened; the good
    // input is still prepared.
    let input = d.join("in");
    std::fs::create_dir_all(input.join("sub")).unwrap();
    phantom(&input, "good");
    mkfifo(&input.join("sub/vol.nrrd"));
    mkfifo(&input.join("sub/IM0001"));
    let o = run(
        cdvol()
            .args(["prep-batch", "-q", "--iso", "300", "--brick", "8"])
            .arg(&input)
            .arg("-o")
            .arg(d.join("out")),
        Duration::from_secs(20),
    );
    assert!(!o.status.success());
    let rows: Vec<serde_json::Value> =
        serde_json::from_slice(&std::fs::read(d.join("out/batch.json")).unwrap()).unwrap();
    assert_eq!(rows.len(), 2, "{rows:#?}");
    let row = |name: &str| rows.iter().find(|r| r["input"] == name).unwrap().clone();
    assert_eq!(row("good.json")["status"], "done");
    assert_eq!(row("sub/vol.nrrd")["status"], "failed");
    has_all(
        row("sub/vol.nrrd")["error"].as_str().unwrap(),
        &["vol.nrrd", "not a regular file"],
    );
    // The batch's input itself.
    let err = refused(
        cdvol()
            .args(["prep-batch", "--iso", "300"])
            .arg(&fifo)
            .arg("-o")
            .arg(d.join("out2")),
    );
    has_all(&err, &["f.json"]);
}

// ---------------------------------------------------------------------------
// 3b. Directory walks
// ---------------------------------------------------------------------------

/// `ln -s . in/loop` once gave 41 outputs for one input. Now a directory
/// is walked once whatever the links to it, a linked directory holding
/// other inputs is still walked, and a file reached twice is one input.
#[test]
fn batch_walk_survives_symlink_loops() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let input = d.join("in");
    std::fs::create_dir_all(input.join("a")).unwrap();
    phantom(&input.join("a"), "vol");
    std::os::unix::fs::symlink(".", input.join("loop")).unwrap();
    std::os::unix::fs::symlink("..", input.join("a/up")).unwrap();
    std::os::unix::fs::symlink("a", input.join("0first")).unwrap();
    std::os::unix::fs::symlink("a/vol.json", input.join("again.json")).unwrap();
    // A linked directory outside the tree is followed (once).
    let other = d.join("other");
    std::fs::create_dir(&other).unwrap();
    phantom(&other, "ext");
    std::os::unix::fs::symlink(&other, input.join("ext")).unwrap();
    std::os::unix::fs::symlink(&other, input.join("ext2")).unwrap();
    let out = d.join("out");
    let o = run(
        cdvol()
            .args(["prep-batch", "-q", "--iso", "300", "--brick", "8"])
            .arg(&input)
            .arg("-o")
            .arg(&out),
        Duration::from_secs(60),
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let rows: Vec<serde_json::Value> =
        serde_json::from_slice(&std::fs::read(out.join("batch.json")).unwrap()).unwrap();
    let names: Vec<&str> = rows.iter().map(|r| r["input"].as_str().unwrap()).collect();
    assert_eq!(names, ["a/vol.json", "ext/ext.json"], "{rows:#?}");
    let cdvs = std::fs::read_dir(&out)
        .unwrap()
        .filter(|e| {
            e.as_ref()
                .unwrap()
                .path()
                .extension()
                .is_some_and(|x| x == "cdv")
        })
        .count();
    assert_eq!(cdvs, 2);
}

/// An unreadable subdirectory (and an unreadable sidecar) fail as one
/// input each, named in the summary; the rest of the batch is prepared.
#[test]
fn batch_unreadable_entries_fail_alone() {
    let Some(mut c) = unprivileged() else {
        eprintln!("skipped: cannot drop privileges");
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    std::fs::set_permissions(d, std::fs::Permissions::from_mode(0o755)).unwrap();
    let input = d.join("in");
    std::fs::create_dir_all(input.join("locked")).unwrap();
    std::fs::create_dir_all(input.join("open")).unwrap();
    phantom(&input.join("open"), "vol");
    phantom(&input.join("locked"), "hidden");
    phantom(&input, "secret");
    std::fs::set_permissions(
        input.join("secret.json"),
        std::fs::Permissions::from_mode(0o000),
    )
    .unwrap();
    std::fs::set_permissions(input.join("locked"), std::fs::Permissions::from_mode(0o000)).unwrap();
    let out = d.join("out");
    let o = run(
        c.args(["prep-batch", "-q", "--iso", "300", "--brick", "8"])
            .arg(&input)
            .arg("-o")
            .arg(&out),
        Duration::from_secs(60),
    );
    std::fs::set_permissions(input.join("locked"), std::fs::Permissions::from_mode(0o755)).unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success(), "{stderr}");
    has_all(&stderr, &["2 of 3 inputs failed"]);
    let rows: Vec<serde_json::Value> =
        serde_json::from_slice(&std::fs::read(out.join("batch.json")).unwrap()).unwrap();
    let row = |name: &str| {
        rows.iter()
            .find(|r| r["input"] == name)
            .unwrap_or_else(|| panic!("{name} not in {rows:#?}"))
            .clone()
    };
    assert_eq!(row("open/vol.json")["status"], "done");
    assert_eq!(row("locked")["status"], "failed");
    has_all(
        row("locked")["error"].as_str().unwrap(),
        &["locked", "cannot list"],
    );
    assert_eq!(row("secret.json")["status"], "failed");
    has_all(
        row("secret.json")["error"].as_str().unwrap(),
        &["secret.json"],
    );
}

// ---------------------------------------------------------------------------
// 4. No partial files left behind
// ---------------------------------------------------------------------------

/// A prep killed with SIGKILL leaves its `.cdvol-partial-*` file; the next
/// write into that directory removes it once it is a minute old (its
/// process is gone), but never a partial file of a live process or of
/// another host.
#[test]
fn killed_runs_leave_no_stale_partial() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let big = d.join("big.json");
    ok(cdvol()
        .args(["-q", "phantom", "ct", "--dims", "200,200,160", "-o"])
        .arg(&big));
    let out = d.join("out");
    std::fs::create_dir(&out).unwrap();
    // Kill prep while its partial file is there: one that stays across
    // two looks 20 ms apart (the output check's probe file lives for
    // microseconds). If prep finishes first, try again.
    let (stale, pid) = (0..5)
        .find_map(|_| {
            let mut child = cdvol()
                .args(["-q", "prep", "--iso", "300", "--brick", "8"])
                .arg(&big)
                .arg("-o")
                .arg(out.join("big.cdv"))
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .unwrap();
            let t0 = Instant::now();
            loop {
                let seen = partials(&out);
                if !seen.is_empty() {
                    std::thread::sleep(Duration::from_millis(20));
                    if partials(&out) == seen {
                        break;
                    }
                }
                if child.try_wait().unwrap().is_some() {
                    break;
                }
                assert!(t0.elapsed() < Duration::from_secs(30), "no partial file");
                std::thread::sleep(Duration::from_millis(2));
            }
            child.kill().unwrap(); // SIGKILL (or nothing, if it is done)
            child.wait().unwrap();
            let _ = std::fs::remove_file(out.join("big.cdv"));
            match partials(&out).as_slice() {
                [one] => Some((one.clone(), child.id())),
                [] => None,
                more => panic!("{more:?}"),
            }
        })
        .expect("prep was never caught with its partial file");
    let write_into = |name: &str| {
        ok(cdvol()
            .args(["-q", "phantom", "ct", "--dims", "8,8,8", "-o"])
            .arg(out.join(name)));
    };
    let age = |name: &str| {
        std::fs::File::options()
            .write(true)
            .open(out.join(name))
            .unwrap()
            .set_modified(std::time::SystemTime::now() - Duration::from_secs(120))
            .unwrap();
    };
    // A young stale file is left alone (its writer may be on a clock a
    // little behind, or between two writes); an old one goes.
    write_into("w1.json");
    assert!(out.join(&stale).exists(), "a young stale file was removed");
    age(&stale);
    write_into("w2.json");
    assert!(
        !out.join(&stale).exists(),
        "{stale}: the stale partial file of a killed run is still there"
    );
    // Never the partial file of a live process (this test) or of another
    // host, however old.
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| h.trim().to_string())
        .unwrap_or_default();
    let live = stale.replacen(&format!("-{pid}-"), &format!("-{}-", std::process::id()), 1);
    assert_ne!(live, stale, "the partial's name holds its pid");
    let elsewhere = stale.replacen(&host, "another-host", 1);
    assert_ne!(elsewhere, stale, "the partial's name holds the host");
    for n in [&live, &elsewhere] {
        std::fs::write(out.join(n), b"not mine").unwrap();
        age(n);
    }
    write_into("w3.json");
    let mut left = partials(&out);
    left.sort();
    let mut want = vec![live, elsewhere];
    want.sort();
    assert_eq!(left, want);
}

/// A depth render (three files) or a turntable that fails part-way
/// replaces none of the old files: here its last member cannot be
/// written, and the old set is as it was.
#[test]
fn multi_file_outputs_are_committed_as_a_set() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let s = phantom(d, "s");
    let r = d.join("r.cdv");
    prep(&s, &r);
    ok(render(&r)
        .args(["--mode", "depth", "-o"])
        .arg(d.join("d.png")));
    ok(render(&r)
        .args(["--frames", "3", "-o"])
        .arg(d.join("t.png")));
    // The last member becomes something a file cannot replace.
    for n in ["d.depth16.png", "t.0002.png"] {
        std::fs::remove_file(d.join(n)).unwrap();
        std::fs::create_dir_all(d.join(n).join("x")).unwrap();
    }
    let before = snapshot(d);
    refused(
        render(&r)
            .args(["--mode", "depth", "--view", "30,10", "-o"])
            .arg(d.join("d.png")),
    );
    refused(
        render(&r)
            .args(["--frames", "3", "--view", "30,10", "-o"])
            .arg(d.join("t.png")),
    );
    assert_eq!(snapshot(d), before, "a failed set replaced some files");
    assert!(partials(d).is_empty(), "{:?}", partials(d));
}

/// A file that is not special but is an input read in place: the sidecar
/// export's data name meeting the packed file is refused too.
#[test]
fn export_never_writes_over_its_packed_file() {
    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path();
    let s = phantom(d, "s");
    let r = d.join("e.raw");
    prep(&s, &r);
    let before = snapshot(d);
    let err = refused(
        cdvol()
            .args(["export", "--what", "codes"])
            .arg(&r)
            .arg("-o")
            .arg(d.join("e.json")),
    );
    has_all(&err, &["e.raw", "input"]);
    assert_eq!(snapshot(d), before);
}
