//! The map of docs/DESIGN.md ("Rooms: what each owns and may import"),
//! checked against the source: each room's `use` and path lines may name
//! only the rooms upstream of it. A new import across the pipeline's
//! direction fails here, with the file and line, before it becomes a
//! habit.

use std::path::{Path, PathBuf};

/// Every `.rs` file under `dir`, sorted.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display())) {
            let p = e.unwrap().path();
            if p.is_dir() {
                stack.push(p);
            } else if p.extension().is_some_and(|x| x == "rs") {
                out.push(p);
            }
        }
    }
    out.sort();
    out
}

/// The code lines of `file` (comments and doc comments dropped) with
/// their line numbers.
fn code_lines(file: &Path) -> Vec<(usize, String)> {
    let text = std::fs::read_to_string(file).unwrap();
    text.lines()
        .enumerate()
        .map(|(i, l)| (i + 1, l.trim().to_string()))
        .filter(|(_, l)| !l.starts_with("//"))
        .collect()
}

/// `(room, forbidden)`: files whose path under `src/` starts with `room`
/// may not contain any of `forbidden` on a code line.
const RULES: &[(&str, &[&str])] = &[
    (
        "input/",
        &[
            "crate::classify",
            "crate::dt",
            "crate::prep",
            "crate::format",
            "crate::render",
            "crate::batch",
            "crate::info",
            "crate::export",
        ],
    ),
    ("grid.rs", &["crate::"]),
    (
        "classify.rs",
        &[
            "crate::dt",
            "crate::prep",
            "crate::format",
            "crate::render",
            "crate::batch",
        ],
    ),
    // Label maps: their record, colour tables and the smoothed indicator;
    // read by prep, the format and the renderer, reading none of them.
    (
        "labels.rs",
        &[
            "crate::dt",
            "crate::prep",
            "crate::format",
            "crate::render",
            "crate::batch",
            "crate::info",
            "crate::export",
            "crate::input",
        ],
    ),
    // The presets are transfer functions and nothing else.
    (
        "presets.rs",
        &[
            "crate::dt",
            "crate::prep",
            "crate::format",
            "crate::render",
            "crate::batch",
            "crate::info",
            "crate::export",
            "crate::input",
        ],
    ),
    (
        "dt/",
        &[
            "crate::prep",
            "crate::format",
            "crate::render",
            "crate::batch",
        ],
    ),
    (
        "format/",
        &[
            "crate::prep",
            "crate::render",
            "crate::batch",
            "crate::info",
        ],
    ),
    ("render/", &["crate::prep", "crate::batch", "crate::export"]),
    // The viewer renders packed files it was given: never prep, batch,
    // export or raw inputs (no URL reaches an input path).
    (
        "serve/",
        &[
            "crate::prep",
            "crate::batch",
            "crate::export",
            "crate::input",
        ],
    ),
    // The walkers know the grid and nothing of bricks, caches or pixels.
    (
        "render/traverse/",
        &[
            "crate::format",
            "crate::render::cache",
            "super::cache",
            "super::super",
            "integrate",
            "crate::classify",
        ],
    ),
    // The cache serves a plain policy, never the traversal method.
    (
        "render/cache/",
        &["Method", "RenderOptions", "integrate", "tiles"],
    ),
];

/// The stages of `src/render/`, in order (docs/DESIGN.md, `render/`): a
/// file of one may import only its own and earlier ones. The frame's
/// settings and counters (options, stats, clock, error) are one stage, the
/// first that knows a frame's options.
const RENDER_STAGES: &[&[&str]] = &[
    &["traverse"],
    &["brick"],
    &["cache"],
    &["sample"],
    &["options", "clip", "stats", "clock", "error"],
    &["view"],
    &["integrate"],
    &["output"],
    &["template"],
    &["job"],
];

/// Files of the library proper (not tools/, not the binary).
fn is_library(rel: &str) -> bool {
    !(rel.starts_with("tools/") || rel.starts_with("cli/") || matches!(rel, "main.rs" | "demo.rs"))
}

#[test]
fn rooms_import_only_upstream() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut bad = Vec::new();
    for file in rust_files(&src) {
        let rel = file
            .strip_prefix(&src)
            .unwrap()
            .to_string_lossy()
            .replace('\\', "/");
        for (n, line) in code_lines(&file) {
            for (room, forbidden) in RULES {
                if !rel.starts_with(room) {
                    continue;
                }
                for f in forbidden.iter().filter(|f| line.contains(*f)) {
                    bad.push(format!("src/{rel}:{n}: {room} may not use {f}: {line}"));
                }
            }
            if is_library(&rel) {
                // Nothing in the library uses the tooling, anyhow,
                // plotters (but the plots of `plot/`, feature `plots`),
                // clap or indicatif, or returns bare strings as errors.
                for f in ["crate::tools", "anyhow", "plotters", "clap", "indicatif"] {
                    if line.contains(f) && !(f == "plotters" && rel.starts_with("plot/")) {
                        bad.push(format!(
                            "src/{rel}:{n}: the library may not use {f}: {line}"
                        ));
                    }
                }
                let result = line.find("Result<").map(|i| &line[i..]);
                if result.is_some_and(|r| r.contains(", String>")) {
                    bad.push(format!(
                        "src/{rel}:{n}: a typed error, not Result<_, String>: {line}"
                    ));
                }
            }
        }
    }
    assert!(
        bad.is_empty(),
        "imports against docs/DESIGN.md's map:\n{}",
        bad.join("\n")
    );
}

/// The rule checker itself: a forbidden import on a code line is found,
/// the same text in a comment is not.
#[test]
fn rule_check_sees_code_not_comments() {
    let dir = std::env::temp_dir().join(format!("cdvol-layout-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let f = dir.join("x.rs");
    std::fs::write(
        &f,
        "//! uses crate::render in prose\nuse crate::render::cache;\n",
    )
    .unwrap();
    let lines = code_lines(&f);
    std::fs::remove_dir_all(&dir).unwrap();
    assert_eq!(lines, vec![(2, "use crate::render::cache;".to_string())]);
}

/// The folders of `src/`, relative to it, sorted.
fn src_folders() -> Vec<String> {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let mut out = Vec::new();
    let mut stack = vec![src.clone()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                out.push(p.strip_prefix(&src).unwrap().display().to_string());
                stack.push(p);
            }
        }
    }
    out.sort();
    out
}

/// docs/DESIGN.md's map (its first code block) names every folder of
/// `src/` (as `name/`), so that a newcomer finds each one there (issue 52).
#[test]
fn the_design_map_names_every_folder() {
    let design =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("docs/DESIGN.md"))
            .unwrap();
    let map = design
        .split("```")
        .nth(1)
        .expect("a code block in docs/DESIGN.md");
    let named = |name: &str| {
        map.lines().any(|l| {
            l.split(|c: char| c.is_whitespace() || "(),".contains(c))
                .any(|w| w == format!("{name}/"))
        })
    };
    let missing: Vec<String> = src_folders()
        .into_iter()
        .filter(|f| !named(f.rsplit('/').next().unwrap_or(f)))
        .collect();
    assert!(
        missing.is_empty(),
        "folders of src/ that docs/DESIGN.md's map does not name: {missing:?}"
    );
}

/// No source file of the library or the binary is over 800 lines
/// (issue 52): a file that grows past it is split by what it owns.
#[test]
fn no_source_file_is_over_800_lines() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let long: Vec<String> = rust_files(&src)
        .into_iter()
        .filter_map(|f| {
            let n = std::fs::read_to_string(&f).unwrap().lines().count();
            (n > 800).then(|| format!("{} ({n} lines)", f.display()))
        })
        .collect();
    assert!(long.is_empty(), "source files over 800 lines: {long:?}");
}

/// The module of a source file under `src/` (`render/cache/mod.rs` ->
/// `render::cache`, `render/sample/hit.rs` -> `render::hit`).
fn module_of(rel: &str) -> Vec<String> {
    let mut parts: Vec<String> = rel
        .trim_end_matches(".rs")
        .split('/')
        .map(String::from)
        .collect();
    if parts
        .last()
        .is_some_and(|p| p == "mod" || p == "lib" || p == "main")
    {
        parts.pop();
    }
    parts
}

/// The modules a code line names through `crate::` or `super::` paths,
/// each cut to the longest prefix that is a module of `modules`.
fn named_modules(line: &str, here: &[String], modules: &[Vec<String>]) -> Vec<Vec<String>> {
    let mut out = Vec::new();
    let words: Vec<&str> = line
        .split(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':' || c == '{' || c == ','))
        .collect();
    for w in words {
        let child = |seg: &str| {
            let mut c = here.to_vec();
            c.push(seg.to_string());
            modules.contains(&c)
        };
        let (mut base, rest) = if let Some(r) = w.strip_prefix("crate::") {
            (Vec::new(), r)
        } else if let Some(r) = w.strip_prefix("self::") {
            (here.to_vec(), r)
        } else if w
            .split("::")
            .next()
            .is_some_and(|s| w.contains("::") && child(s))
        {
            // A path from a child module (`brick::RBrick` in a mod.rs).
            (here.to_vec(), w)
        } else if w.starts_with("super::") {
            let mut b = here.to_vec();
            let mut r = w;
            while let Some(x) = r.strip_prefix("super::") {
                b.pop();
                r = x;
            }
            (b, r)
        } else {
            continue;
        };
        // `a::b::{c, d::e}`: the path up to the brace, then each item.
        let (head, items) = match rest.split_once('{') {
            Some((h, i)) => (h, i.split(',').map(|s| s.trim()).collect::<Vec<_>>()),
            None => (rest, vec![""]),
        };
        base.extend(head.split("::").filter(|s| !s.is_empty()).map(String::from));
        for item in items {
            let mut p = base.clone();
            p.extend(item.split("::").filter(|s| !s.is_empty()).map(String::from));
            while !p.is_empty() && !modules.contains(&p) {
                p.pop();
            }
            if !p.is_empty() {
                out.push(p);
            }
        }
    }
    out
}

/// Every source file under `src` (its path relative to `src`, with `/`)
/// and its module.
fn source_modules(src: &Path) -> Vec<(String, Vec<String>)> {
    rust_files(src)
        .into_iter()
        .map(|f| {
            let rel = f
                .strip_prefix(src)
                .unwrap()
                .to_string_lossy()
                .replace('\\', "/");
            let m = module_of(&rel);
            (rel, m)
        })
        .collect()
}

/// No two modules of `src/` import each other, directly or round a
/// circle (issue 52). A child naming its parent is not counted (the
/// parent declares it; what the parent re-exports from another child is
/// then not seen); a parent naming a child is. A circle fails here with
/// its modules named.
#[test]
fn no_import_circles() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let files = source_modules(&src);
    let modules: Vec<Vec<String>> = files.iter().map(|(_, m)| m.clone()).collect();
    let index = |m: &Vec<String>| modules.iter().position(|x| x == m);
    let mut edges: Vec<Vec<usize>> = vec![Vec::new(); modules.len()];
    for (i, (rel, here)) in files.iter().enumerate() {
        for (_, line) in code_lines(&src.join(rel)) {
            for m in named_modules(&line, here, &modules) {
                // A child naming its parent (or itself) is not counted:
                // the parent declares it. A parent naming a child is.
                if let (Some(j), false) = (index(&m), here.starts_with(&m)) {
                    edges[i].push(j);
                }
            }
        }
    }
    // Tarjan's strongly connected components.
    struct T<'a> {
        e: &'a [Vec<usize>],
        idx: Vec<Option<usize>>,
        low: Vec<usize>,
        on: Vec<bool>,
        stack: Vec<usize>,
        n: usize,
        out: Vec<Vec<usize>>,
    }
    fn visit(t: &mut T, v: usize) {
        t.idx[v] = Some(t.n);
        t.low[v] = t.n;
        t.n += 1;
        t.stack.push(v);
        t.on[v] = true;
        for &w in &t.e[v].clone() {
            match t.idx[w] {
                None => {
                    visit(t, w);
                    t.low[v] = t.low[v].min(t.low[w]);
                }
                Some(iw) if t.on[w] => t.low[v] = t.low[v].min(iw),
                _ => {}
            }
        }
        if Some(t.low[v]) == t.idx[v] {
            let mut c = Vec::new();
            while let Some(w) = t.stack.pop() {
                t.on[w] = false;
                c.push(w);
                if w == v {
                    break;
                }
            }
            t.out.push(c);
        }
    }
    let n = modules.len();
    let mut t = T {
        e: &edges,
        idx: vec![None; n],
        low: vec![0; n],
        on: vec![false; n],
        stack: Vec::new(),
        n: 0,
        out: Vec::new(),
    };
    for v in 0..n {
        if t.idx[v].is_none() {
            visit(&mut t, v);
        }
    }
    let circles: Vec<Vec<String>> = t
        .out
        .iter()
        .filter(|c| c.len() > 1)
        .map(|c| {
            let mut names: Vec<String> = c.iter().map(|&i| modules[i].join("::")).collect();
            names.sort();
            names
        })
        .collect();
    assert!(
        circles.is_empty(),
        "modules that import each other: {circles:?}"
    );
}

/// The rank of a module's stage in [`RENDER_STAGES`] (`render::cache::held`
/// -> 2), or None outside `render`'s stages (and for `render` itself).
fn render_stage(module: &[String]) -> Option<usize> {
    match module {
        [r, stage, ..] if r == "render" => RENDER_STAGES
            .iter()
            .position(|s| s.contains(&stage.as_str())),
        _ => None,
    }
}

/// Each stage of `src/render/` imports only its own and earlier stages
/// (issue 52): a file that names a later stage fails here with both files
/// named. `render/mod.rs`, the hub that re-exports the public names, is
/// not a stage.
#[test]
fn render_stages_import_one_way() {
    let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("src");
    let files = source_modules(&src);
    let modules: Vec<Vec<String>> = files.iter().map(|(_, m)| m.clone()).collect();
    let file_of = |m: &Vec<String>| {
        files
            .iter()
            .find(|(_, x)| x == m)
            .map_or_else(|| m.join("::"), |(rel, _)| format!("src/{rel}"))
    };
    let mut bad = Vec::new();
    for (rel, here) in &files {
        let Some(rank) = render_stage(here) else {
            continue;
        };
        for (n, line) in code_lines(&src.join(rel)) {
            for m in named_modules(&line, here, &modules) {
                if render_stage(&m).is_some_and(|r| r > rank) {
                    bad.push(format!(
                        "src/{rel}:{n} ({}) imports {} ({}): {line}",
                        RENDER_STAGES[rank].join("/"),
                        file_of(&m),
                        RENDER_STAGES[render_stage(&m).unwrap()].join("/"),
                    ));
                }
            }
        }
    }
    assert!(
        bad.is_empty(),
        "render stages importing later ones (docs/DESIGN.md, render/):\n{}",
        bad.join("\n")
    );
}

/// The stage check sees a later stage named through `super::` as well as
/// through `crate::`, and maps each module to its stage.
#[test]
fn the_stage_check_resolves_paths() {
    let m = |s: &str| s.split("::").map(String::from).collect::<Vec<_>>();
    let modules = vec![
        m("render"),
        m("render::brick"),
        m("render::brick::decode"),
        m("render::cache"),
        m("render::job"),
    ];
    let here = m("render::brick::decode");
    let named = named_modules("use super::super::cache::Accessor;", &here, &modules);
    assert_eq!(named, vec![m("render::cache")]);
    assert!(render_stage(&named[0]) > render_stage(&here));
    let named = named_modules("let j = crate::render::job::run(x);", &here, &modules);
    assert_eq!(render_stage(&named[0]), Some(RENDER_STAGES.len() - 1));
    assert_eq!(render_stage(&m("render")), None);
    assert_eq!(render_stage(&m("format::brick")), None);
}
