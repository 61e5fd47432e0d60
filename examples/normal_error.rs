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

use cdvol::format::reader::PackedVolume;
use cdvol::tools::normals::{sphere_normal_errors, summary};
use cdvol::tools::phantom::load_spheres;

fn main() -> anyhow::Result<()> {
    let mut args = std::env::args().skip(1);
    let (Some(file), Some(list)) = (args.next(), args.next()) else {
        anyhow::bail!("usage: normal_error FILE.cdv SPHERES.json [PIXELS]");
    };
    let px: u32 = args.next().map_or(Ok(256), |s| s.parse())?;
    let vol = PackedVolume::open(file.as_ref())?;
    let (_, spheres) = load_spheres(list.as_ref())?;
    let views = [[30.0, 20.0], [120.0, -35.0], [210.0, 50.0], [300.0, 5.0]];
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
