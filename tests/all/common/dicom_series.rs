//! A CT-like DICOM series written with dicom-rs, for the dicom, batch and
//! real_data tests.
#![allow(dead_code)]

use std::path::{Path, PathBuf};

use cdvol::input::dicom::SliceHeader;
use cdvol::input::Rescale;

pub const NX: usize = 33;
pub const NY: usize = 28;
pub const SERIES: &str = "1.2.826.0.1.3680043.9.7777.1";
pub const EXPLICIT_LE: &str = "1.2.840.10008.1.2.1";

/// Slice positions: 2 mm gaps low, 1 mm in the middle, 4 mm on top.
pub fn z_positions() -> Vec<f64> {
    let mut z = vec![-40.0];
    for i in 0..19 {
        let g = if i < 6 {
            2.0
        } else if i < 14 {
            1.0
        } else {
            4.0
        };
        z.push(z[i] + g);
    }
    z
}

/// Stored u16 values (HU + 1024) of slice `k`: a sphere and noise.
pub fn slice(k: usize) -> Vec<u16> {
    let z = z_positions()[k];
    let mut v = Vec::with_capacity(NX * NY);
    for y in 0..NY {
        for x in 0..NX {
            let (px, py, pz) = (x as f64 * 0.7 - 11.0, y as f64 * 0.8 - 11.0, z + 25.0);
            let r = (px * px + py * py + pz * pz).sqrt();
            let noise = ((x * 7 + y * 13 + k * 31) % 17) as f64;
            let hu = if r < 9.0 { 700.0 } else { -1000.0 } + noise;
            v.push((hu + 1024.0) as u16);
        }
    }
    v
}

pub struct Slice<'a> {
    pub k: usize,
    pub series: &'a str,
    pub rows: usize,
    pub position: [f64; 3],
    pub ts: &'a str,
}

pub fn write_slice(path: &Path, s: &Slice) {
    let mut px = slice(s.k);
    px.resize(NX * s.rows, 0);
    let h = SliceHeader {
        series: s.series,
        instance: s.k + 1,
        rows: s.rows,
        cols: NX,
        spacing: [0.8, 0.7],
        position: s.position,
        orientation: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
        signed: false,
        rescale: Rescale {
            slope: 1.0,
            intercept: -1024.0,
        },
        transfer_syntax: s.ts,
    };
    cdvol::input::dicom::write_slice(path, &h, &px).unwrap();
}

/// The series in `dir` under scrambled names, some nested; returns the
/// file of each slice.
pub fn write_series(dir: &Path) -> Vec<PathBuf> {
    (0..z_positions().len())
        .map(|k| {
            let name = format!("{:08x}", (k as u64 * 2654435761) % 4294967291);
            let p = if k % 3 == 0 {
                dir.join("sub").join(name)
            } else {
                dir.join(format!("{name}.dcm"))
            };
            write_slice(
                &p,
                &Slice {
                    k,
                    series: SERIES,
                    rows: NY,
                    position: [10.0, -5.0, z_positions()[k]],
                    ts: EXPLICIT_LE,
                },
            );
            p
        })
        .collect()
}

/// The error a broken series gets: from opening it, or else from
/// preparing it into `out` (pixel data are read only then). Panics if
/// the series is accepted.
pub fn series_error(dir: &Path, series: Option<&str>, out: &Path) -> String {
    use cdvol::classify::Classification;
    use cdvol::prep::{prep, PrepOptions};
    let src = match cdvol::input::dicom::open_dir(dir, series) {
        Ok(src) => src,
        Err(e) => return e.to_string(),
    };
    let opts = PrepOptions::new(Classification::Iso { iso: 300.0 });
    match prep(&src, out, &opts, &cdvol::progress::NoProgress) {
        Ok(_) => panic!("{} was accepted", dir.display()),
        Err(e) => e.to_string(),
    }
}
