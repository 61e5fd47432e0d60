//! Angle error of the shading normals against the analytic spheres of a
//! sphere scene (docs/TRADEOFFS.md, "Normals (issue 15)"):
//!
//! `cargo run --release --example normal_error -- FILE.cdv SPHERES.json
//! [PIXELS]`
//!
//! FILE.cdv is the scene prepared at its iso value (1000), SPHERES.json
//! the `<stem>.spheres.json` that `cdvol phantom spheres` wrote beside it.
//! Casts PIXELS x PIXELS orthographic rays (default 256) from each of four
//! views and prints, per normal estimate, the mean, median and 95th
//! percentile of the angle (degrees) at the hits.
//!
//! `cargo run --release --example normal_error -- --compare A.cdv B.cdv
//! [PIXELS]` compares the smooth normals of two files of the same samples
//! (with and without `--gradient-halo`) at the same hits instead: the angle
//! between them, for data without analytic normals such as the CT.
//!
//! `... -- --time FILE.cdv [PIXELS]` times the cell and the smooth
//! gradient per hit (nanoseconds, 5 passes over the hits of four views).

use cdvol::format::reader::PackedVolume;
use cdvol::tools::normals::{compare_smooth, sphere_normal_errors, summary, time_gradients};
use cdvol::tools::phantom::load_spheres;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1).peekable();
    let views = [[30.0, 20.0], [120.0, -35.0], [210.0, 50.0], [300.0, 5.0]];
    if args.peek().is_some_and(|a| a == "--time") {
        args.next();
        let Some(file) = args.next() else {
            anyhow::bail!("usage: normal_error --time FILE.cdv [PIXELS]");
        };
        let px: u32 = args.next().map_or(Ok(256), |s| s.parse())?;
        let vol = PackedVolume::open(file.as_ref())?;
        let Some((c, s, n)) = time_gradients(&vol, &views, px, 5) else {
            anyhow::bail!("{file}: not classified by an iso value");
        };
        println!("{file}: {n} hits; per hit: cell {c:.1} ns, smooth {s:.1} ns");
        return Ok(());
    }
    if args.peek().is_some_and(|a| a == "--compare") {
        args.next();
        let (Some(a), Some(b)) = (args.next(), args.next()) else {
            anyhow::bail!("usage: normal_error --compare A.cdv B.cdv [PIXELS]");
        };
        let px: u32 = args.next().map_or(Ok(256), |s| s.parse())?;
        let (va, vb) = (
            PackedVolume::open(a.as_ref())?,
            PackedVolume::open(b.as_ref())?,
        );
        let Some((d, one)) = compare_smooth(&va, &vb, &views, px) else {
            anyhow::bail!("{a}: not classified by an iso value");
        };
        let [m, med, p95] = summary(&d);
        println!(
            "{} hits, one-sided in {a}: {}, in {b}: {}",
            d.len(),
            one[0],
            one[1]
        );
        println!("angle between smooth normals: mean {m:.3} median {med:.3} p95 {p95:.3} deg");
        let over = |x: f64| d.iter().filter(|&&a| a > x).count() as f64 / d.len().max(1) as f64;
        println!(
            "share of hits over 1 / 5 / 10 deg: {:.4} / {:.4} / {:.4}",
            over(1.0),
            over(5.0),
            over(10.0)
        );
        return Ok(());
    }
    let (Some(file), Some(list)) = (args.next(), args.next()) else {
        anyhow::bail!("usage: normal_error FILE.cdv SPHERES.json [PIXELS]");
    };
    let px: u32 = args.next().map_or(Ok(256), |s| s.parse())?;
    let vol = PackedVolume::open(file.as_ref())?;
    let (_, spheres) = load_spheres(list.as_ref())?;
    let Some(e) = sphere_normal_errors(&vol, &spheres, &views, px) else {
        anyhow::bail!("{file}: not classified by an iso value");
    };
    println!(
        "{file}: {} hits, {} with a one-sided difference",
        e.cell.len(),
        e.one_sided_hits
    );
    println!("normals   mean   median  p95  (degrees)");
    for (name, v) in [("cell", &e.cell), ("smooth", &e.smooth)] {
        let [m, med, p95] = summary(v);
        println!("{name:8} {m:6.3} {med:6.3} {p95:6.3}");
    }
    Ok(())
}
