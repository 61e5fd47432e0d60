//! `--help` is for users (issue 52, item 3): `render -h` shows the options
//! a user needs in groups (input, view, mode and look, output,
//! performance); the traversal comparators, hit methods, precisions and
//! the other tuning and paper-experiment switches sit under their own
//! heading, shown by `--help` and `--help-all` only. `--no-switch-fvt`,
//! which draws wrong images, is refused by `render` and offered by
//! `cdvol experiment render`.

use clap::FromArgMatches;

use crate::cli;
use crate::common::{cdvol, fails, ok};

const USER: [&str; 5] = ["Input", "View", "Mode and look", "Output", "Performance"];
const TUNING: &str = "Tuning and paper experiments";

/// Switches a user does not need: left out of `render -h`.
const RENDER_TUNING: [&str; 15] = [
    "--traversal",
    "--min-leap",
    "--switch-fvt-at",
    "--hit",
    "--bisect-iters",
    "--newton-iters",
    "--newton-tol",
    "--precision",
    "--sample-precision",
    "--sample-batches",
    "--early-stop",
    "--tile",
    "--cd-lazy-min",
    "--no-cull",
    "--shard-layout",
];

/// The headings of a help text (lines `Name:` at the margin), in order.
fn headings(help: &str) -> Vec<&str> {
    help.lines()
        .filter(|l| !l.starts_with(' ') && !l.starts_with("Usage"))
        .filter_map(|l| l.strip_suffix(':'))
        .collect()
}

/// The long options a help text lists (`  -o, --output <OUTPUT>`,
/// `      --persp`), each with the heading it sits under.
fn listed(help: &str) -> Vec<(String, String)> {
    let mut heading = String::new();
    let mut out = Vec::new();
    for l in help.lines() {
        if let Some(h) = l.strip_suffix(':').filter(|_| !l.starts_with(' ')) {
            heading = h.to_string();
            continue;
        }
        let t = l.trim_start();
        // Options sit 2 or 6 columns in; their descriptions further.
        if ![2, 6].contains(&(l.len() - t.len())) {
            continue;
        }
        let t = match t.strip_prefix('-').and_then(|t| t.get(1..)) {
            Some(rest) if !t.starts_with("--") => rest.trim_start_matches(", "),
            _ => t,
        };
        if let Some(name) = t.strip_prefix("--") {
            let name: String = name
                .chars()
                .take_while(|c| c.is_ascii_alphanumeric() || *c == '-')
                .collect();
            out.push((format!("--{name}"), heading.clone()));
        }
    }
    out
}

fn help(args: &[&str]) -> String {
    ok(cdvol().args(args))
}

#[test]
fn render_short_help_shows_the_user_groups_only() {
    let h = help(&["render", "-h"]);
    let lines = h.lines().count();
    assert!(lines < 80, "render -h runs to {lines} lines:\n{h}");
    let heads = headings(&h);
    assert_eq!(heads, [&["Options"][..], &USER[..]].concat(), "{h}");
    let opts = listed(&h);
    for t in RENDER_TUNING.iter().chain(&["--no-switch-fvt"]) {
        assert!(
            opts.iter().all(|(o, _)| o != t),
            "render -h lists {t}:\n{h}"
        );
    }
    // The everyday options, each in its group.
    for (o, group) in [
        ("--view", "View"),
        ("--persp", "View"),
        ("--mode", "Mode and look"),
        ("--preset", "Mode and look"),
        ("--iso", "Mode and look"),
        ("--output", "Output"),
        ("--width", "Output"),
        ("--threads", "Performance"),
        ("--mem-limit", "Performance"),
    ] {
        assert!(
            opts.iter().any(|(n, g)| n == o && g == group),
            "render -h: {o} not under {group}:\n{h}"
        );
    }
    assert!(h.contains("<FILE>"), "{h}");
    // Its last line says where the rest is.
    let last = h.trim_end().lines().last().unwrap_or_default();
    assert!(
        last.contains("--help-all") && last.contains(TUNING),
        "{last}"
    );
}

#[test]
fn render_long_help_and_help_all_list_the_tuning_heading_last() {
    let long = help(&["render", "--help"]);
    let all = help(&["render", "--help-all"]);
    assert_eq!(long, all, "--help-all is --help");
    let heads = headings(&long);
    assert_eq!(
        heads,
        [&["Options"][..], &USER[..], &[TUNING][..]].concat(),
        "{long}"
    );
    let opts = listed(&long);
    for t in RENDER_TUNING {
        assert!(
            opts.iter().any(|(o, g)| o == t && g == TUNING),
            "render --help: {t} not under {TUNING}"
        );
    }
    assert!(opts.iter().all(|(o, _)| o != "--no-switch-fvt"), "{long}");
    // Nothing but -q, -h and --help-all outside the groups.
    let loose: Vec<_> = opts
        .iter()
        .filter(|(_, g)| g == "Options")
        .map(|(o, _)| o.as_str())
        .collect();
    assert_eq!(loose, ["--quiet", "--help-all", "--help"], "{long}");
}

/// Every option of `render` and `prep` has a heading; those under the
/// tuning heading, and only those, are left out of `-h`.
#[test]
fn every_option_has_a_group_and_only_tuning_is_hidden() {
    let root = cli::command();
    for name in ["render", "prep", "prep-batch"] {
        let c = root.find_subcommand(name).unwrap();
        for a in c.get_arguments() {
            let id = a.get_id().as_str();
            if ["help_all", "help", "quiet", "version"].contains(&id) {
                continue;
            }
            let h = a.get_help_heading();
            assert!(
                h.is_some_and(|h| USER.contains(&h) || h == TUNING || h == "Classification"),
                "{name} {id}: heading {h:?}"
            );
            assert_eq!(
                a.is_hide_short_help_set(),
                h == Some(TUNING),
                "{name} {id}: hidden from -h only when under {TUNING}"
            );
        }
    }
}

#[test]
fn render_refuses_no_switch_fvt_and_experiment_render_takes_it() {
    let err = fails(cdvol().args(["render", "f.cdv", "-o", "x.png", "--no-switch-fvt"]));
    assert!(
        err.contains("unexpected argument '--no-switch-fvt'"),
        "{err}"
    );
    let h = help(&["experiment", "render", "-h"]);
    assert!(
        listed(&h)
            .iter()
            .any(|(o, g)| o == "--no-switch-fvt" && g == TUNING),
        "{h}"
    );
    assert!(h.contains("wrong images"), "{h}");

    let parse = |extra: &[&str]| {
        let argv = ["cdvol", "experiment", "render", "f.cdv", "-o", "x.png"]
            .iter()
            .chain(extra);
        let m = cli::command().try_get_matches_from(argv).unwrap();
        match cli::Cli::from_arg_matches(&m).unwrap().command {
            cli::Command::Experiment(cli::ExperimentCmd::Render(a)) => a.into_render(),
            c => panic!("{c:?}"),
        }
    };
    assert!(parse(&["--no-switch-fvt"]).no_switch_fvt);
    let plain = parse(&["--traversal", "dda-cityblock"]);
    assert!(!plain.no_switch_fvt);
    assert_eq!(format!("{:?}", plain.traversal), "Some(DdaCityblock)");
}

#[test]
fn prep_help_is_grouped_too() {
    let short = help(&["prep", "-h"]);
    let long = help(&["prep", "--help"]);
    let groups = ["Input", "Classification", "Output", "Performance"];
    assert_eq!(headings(&short), [&["Options"][..], &groups[..]].concat());
    assert_eq!(
        headings(&long),
        [&["Options"][..], &groups[..], &[TUNING][..]].concat()
    );
    for t in ["--brick", "--zstd-level", "--format-version", "--dda"] {
        assert!(listed(&short).iter().all(|(o, _)| o != t), "{short}");
        assert!(
            listed(&long).iter().any(|(o, g)| o == t && g == TUNING),
            "{long}"
        );
    }
}

/// The inexact traversals (they miss 1-cells) are refused by `render`,
/// naming `cdvol experiment render`, which takes them; `render --help`
/// does not offer them.
#[test]
fn inexact_traversals_are_experiment_render_only() {
    use crate::common::write_stack;
    let d = tempfile::tempdir().unwrap();
    let v: Vec<f64> = (0..8 * 8 * 8).map(|i| ((i * 37) % 101) as f64).collect();
    write_stack(d.path(), "v", [8, 8, 8], "u8", &v, ["1", "1", "1"], "");
    ok(cdvol().current_dir(d.path()).args([
        "prep", "-q", "v.json", "-o", "v.cdv", "--iso", "90", "--dda",
    ]));
    let run = |pre: &[&str], t: &str| {
        let mut c = cdvol();
        c.current_dir(d.path()).args(pre).args([
            "v.cdv",
            "-o",
            "x.png",
            "--width",
            "16",
            "--height",
            "16",
            "--traversal",
            t,
        ]);
        c
    };
    for t in ["dda-cityblock", "dda-chamfer", "template"] {
        let e = fails(&mut run(&["render", "-q"], t));
        for w in [t, "not exact", "cdvol experiment render"] {
            assert!(e.contains(w), "{w:?} not in {e}");
        }
        ok(&mut run(&["experiment", "render", "-q"], t));
    }
    for t in ["cd", "fvt", "octree", "dda-chessboard"] {
        ok(&mut run(&["render", "-q"], t));
    }
    let long = help(&["render", "--help"]);
    for t in ["dda-cityblock", "dda-chamfer", "template"] {
        assert!(!long.contains(t), "{t} offered by render --help");
    }
}
