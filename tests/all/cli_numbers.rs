//! Negative numbers on the command line (issue 51, item 2): every option
//! of every command that takes a value takes a negative number, as
//! `--iso -700` and as `--iso=-700`; options whose values are lists of
//! numbers take lists that start with a minus (`--view -30,-20`). Before,
//! `render --iso -700` failed with "unexpected argument '-7' found", and
//! so did every numeric option of every command but a few.
//!
//! The test walks the clap command the binary parses with
//! (`cli::command()`, compiled here from src/cli/), so an option added
//! later is covered without a list to keep.

use clap::error::ErrorKind;

use crate::cli;

/// Options whose values are lists of numbers, with a list that starts
/// with a minus.
const LISTS: [(&str, &str); 6] = [
    ("view", "-30,-20"),
    ("eye", "-1,-2,-3"),
    ("target", "-1,-2,-3"),
    ("up", "-1,0,0"),
    ("dims", "-4,4,4"),
    ("spacing", "-1,1,1"),
];

/// Every (subcommand path, command) below `c`.
fn commands(c: &clap::Command, path: Vec<String>, out: &mut Vec<(Vec<String>, clap::Command)>) {
    out.push((path.clone(), c.clone()));
    for s in c.get_subcommands() {
        let mut p = path.clone();
        p.push(s.get_name().to_string());
        commands(s, p, out);
    }
}

/// Parses `cdvol PATH... ARGS...`: `Ok` with the value clap took for
/// `id`, or the error's kind and text.
fn parse(
    root: &clap::Command,
    path: &[String],
    args: &[String],
    id: &str,
) -> Result<Option<String>, (ErrorKind, String)> {
    let argv = std::iter::once("cdvol".to_string())
        .chain(path.iter().cloned())
        .chain(args.iter().cloned());
    let m = root
        .clone()
        .try_get_matches_from(argv)
        .map_err(|e| (e.kind(), e.to_string()))?;
    let mut m = &m;
    for p in path {
        m = m.subcommand_matches(p).expect("the subcommand matched");
    }
    Ok(m.get_raw(id)
        .and_then(|mut v| v.next())
        .map(|v| v.to_string_lossy().into_owned()))
}

#[test]
fn every_option_takes_negative_numbers_in_both_spellings() {
    let root = cli::command();
    let mut all = Vec::new();
    commands(&root, Vec::new(), &mut all);
    let mut checked = 0;
    for (path, c) in &all {
        for a in c.get_arguments() {
            let Some(long) = a.get_long() else { continue };
            if a.is_positional() || !a.get_action().takes_values() {
                continue;
            }
            let value = LISTS
                .iter()
                .find(|(n, _)| *n == long)
                .map_or("-7", |(_, v)| *v);
            let flag = format!("--{long}");
            let optional = a.is_require_equals_set();
            let spellings: Vec<Vec<String>> = if optional {
                vec![vec![format!("{flag}={value}")]]
            } else {
                vec![
                    vec![flag.clone(), value.to_string()],
                    vec![format!("{flag}={value}")],
                ]
            };
            for args in spellings {
                let id = a.get_id().as_str();
                match parse(&root, path, &args, id) {
                    Ok(got) => assert_eq!(
                        got.as_deref(),
                        Some(value),
                        "cdvol {} {}",
                        path.join(" "),
                        args.join(" ")
                    ),
                    // The value was taken and judged (a width cannot be
                    // negative), or something else is missing: fine. Not
                    // fine: the value read as a flag.
                    Err((kind, text)) => {
                        assert!(
                            !matches!(kind, ErrorKind::UnknownArgument | ErrorKind::NoEquals),
                            "cdvol {} {}: {text}",
                            path.join(" "),
                            args.join(" ")
                        );
                        if kind == ErrorKind::ValueValidation || kind == ErrorKind::InvalidValue {
                            assert!(text.contains(value), "{text}");
                        }
                    }
                }
                checked += 1;
            }
        }
    }
    // prep's --iso, render's --iso, --level, --view, phantom's --seed ...
    assert!(checked > 100, "only {checked} spellings checked");
}

#[test]
fn the_reported_cases_parse() {
    let root = cli::command();
    for (path, args, id, want) in [
        (vec!["render"], vec!["--iso", "-700"], "iso", "-700"),
        (vec!["render"], vec!["--iso=-700"], "iso", "-700"),
        (vec!["prep"], vec!["--iso", "-700"], "iso", "-700"),
        (vec!["render"], vec!["--level", "-500"], "level", "-500"),
        (
            vec!["phantom", "spheres"],
            vec!["--seed", "-3"],
            "seed",
            "-3",
        ),
    ] {
        let path: Vec<String> = path.into_iter().map(String::from).collect();
        let args: Vec<String> = args.into_iter().map(String::from).collect();
        match parse(&root, &path, &args, id) {
            Ok(got) => assert_eq!(got.as_deref(), Some(want)),
            Err((kind, text)) => assert!(
                kind == ErrorKind::MissingRequiredArgument || kind == ErrorKind::ValueValidation,
                "{path:?} {args:?}: {text}"
            ),
        }
    }
}
