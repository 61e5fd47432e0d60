//! `cdvol experiment all` end to end on small scenes: every section and
//! file is written, every generator ran on every scene, and the counts
//! have the shape the paper's comparisons rest on (timings are not
//! asserted: they live in docs/EXPERIMENTS.md).

use crate::common;

use cdvol::progress::NoProgress;
use cdvol::tools::experiment::paper::{name, run, sweep_methods, Job, PaperOptions, Which};

#[test]
fn all_experiments_write_their_sections_and_files() {
    let dir = tempfile::tempdir().unwrap();
    let ct = Some(common::real_ct());
    let job = Job {
        which: Which::All,
        out: dir.path().join("EXPERIMENTS.md"),
        opts: PaperOptions {
            dir: dir.path().join("experiments"),
            ns: vec![2, 4],
            size: 48,
            rays: 40,
            runs: 1,
            ct: ct.clone(),
        },
    };
    run(&job, &NoProgress).unwrap();
    let md = std::fs::read_to_string(&job.out).unwrap();
    for s in [
        "Fig. 16", "Fig. 18", "Fig. 20", "Table 2", "Fig. 22", "Table 1", "Fig. 17",
    ] {
        assert!(md.contains(&format!("## {s}")), "no section {s}");
    }
    let e = &job.opts.dir;
    for f in [
        "fig16.svg",
        "fig18a.svg",
        "fig18b.svg",
        "fig20.svg",
        "sweep.csv",
        "table2.csv",
        "fig22.csv",
    ] {
        assert!(
            e.join(f).metadata().unwrap().len() > 100,
            "{f} missing or empty"
        );
    }
    // Every generator on every scene; CD and the octree take fewer steps
    // than FVT, and every ray of the fig22 scene hits with every setting.
    let csv = std::fs::read_to_string(e.join("sweep.csv")).unwrap();
    let rows: Vec<Vec<&str>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    assert_eq!(rows.len(), 2 * sweep_methods().len());
    for n in ["2", "4"] {
        let steps = |m: &str| -> u64 {
            rows.iter()
                .find(|r| r[0] == n && r[3] == m)
                .unwrap_or_else(|| panic!("no row {n} {m}"))[5]
                .parse()
                .unwrap()
        };
        for m in sweep_methods() {
            assert!(steps(&name(m)) > 0);
        }
        assert!(steps("cd") < steps("fvt"), "N = {n}");
        assert!(steps("octree") < steps("fvt"), "N = {n}");
    }
    let f22 = std::fs::read_to_string(e.join("fig22.csv")).unwrap();
    for l in f22.lines().skip(1) {
        let c: Vec<&str> = l.split(',').collect();
        assert_eq!(c[2], "1600", "{l}: every ray must hit");
    }
    let png = image::open(e.join("fig17.png")).unwrap();
    assert_eq!((png.width(), png.height()), (4 * 80, 80));
    let t1 = std::fs::read_to_string(e.join("table1.csv")).unwrap();
    let steps: Vec<u64> = t1
        .lines()
        .skip(1)
        .map(|l| l.rsplit(',').next().unwrap().parse().unwrap())
        .collect();
    assert!(steps[1] < steps[0], "macro-region steps {steps:?}");
}
