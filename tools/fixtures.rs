//! `cdvol-fixtures CT.json OUT_DIR`: test inputs made from a real CT (the
//! raw stack of `tools/fetch-ct.sh`), never committed:
//!
//! * `series/`: a DICOM series (dicom-rs writer) of the CT with varying
//!   slice spacing: every 2nd slice in the lower 35 %, every slice in the
//!   middle 40 %, every 4th in the top 25 %, each at its original position;
//!   scrambled file names, a third of them in a subdirectory;
//! * `series.json` + `series.raw`: the same slices as a raw stack with
//!   listed z positions (what the series must prepare like);
//! * `dup/`, `mixed/`, `truncated/`: the series with a duplicated slice,
//!   with a second series mixed in, and with one file cut in half;
//! * `volume.nrrd` (gzip, attached) and `volume.nii.gz`: the whole CT,
//!   which must prepare like the CT's own sidecar.
//!
//! NIfTI is written here from a 348-byte NIfTI-1 header filled in by hand
//! (the `nifti` crate writes only through ndarray); cdvol reads it back
//! through the crate, which checks it independently.

use std::io::Write;
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use cdvol::input::dicom::{write_slice, SliceHeader, EXPLICIT_VR_LE};
use cdvol::input::raw::RawSource;
use cdvol::input::{Dtype, Rescale, SliceSource};

const SERIES: &str = "1.2.826.0.1.3680043.9.7777.100";
const OTHER: &str = "1.2.826.0.1.3680043.9.7777.200";

fn main() -> Result<()> {
    let args: Vec<String> = std::env::args().collect();
    if args.len() != 3 {
        bail!("usage: cdvol-fixtures CT.json OUT_DIR");
    }
    let (ct, out) = (Path::new(&args[1]), PathBuf::from(&args[2]));
    let src = RawSource::open(ct).with_context(|| format!("{}", ct.display()))?;
    let meta = src.meta().clone();
    if meta.dtype != Dtype::I16 {
        bail!("{}: expected i16 samples", ct.display());
    }
    let [nx, ny, nz] = meta.dims();
    let axes = &meta.grid.axes;
    let (sx, sy) = (
        axes[0].coords()[1] - axes[0].coords()[0],
        axes[1].coords()[1] - axes[1].coords()[0],
    );
    let (x0, y0) = (axes[0].coords()[0], axes[1].coords()[0]);
    let zs = axes[2].coords();
    std::fs::create_dir_all(&out)?;

    // Slices kept: thin in the middle, thicker below and on top.
    let (lo, hi) = ((nz as f64 * 0.35) as usize, (nz as f64 * 0.75) as usize);
    let kept: Vec<usize> = (0..nz)
        .filter(|&z| {
            if z < lo {
                z % 2 == 0
            } else if z < hi {
                true
            } else {
                (z - hi) % 4 == 0
            }
        })
        .collect();
    let mut slice = vec![0.0; nx * ny];
    let mut words = Vec::with_capacity(kept.len());
    for &z in &kept {
        src.read_slice(z, &mut slice)?;
        words.push(slice.iter().map(|&v| v as i16 as u16).collect::<Vec<u16>>());
    }
    let header = |series: &'static str, i: usize, z: usize| SliceHeader {
        series,
        instance: i + 1,
        rows: ny,
        cols: nx,
        spacing: [sy, sx],
        position: [x0, y0, zs[z]],
        orientation: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0],
        signed: true,
        rescale: meta.rescale,
        transfer_syntax: EXPLICIT_VR_LE,
    };
    let name = |i: usize| format!("IM{:08X}", (i as u64 * 2654435761) % 4294967291);
    let write_series = |dir: &Path| -> Result<Vec<PathBuf>> {
        let mut files = Vec::new();
        for (i, &z) in kept.iter().enumerate() {
            let p = if i % 3 == 1 {
                dir.join("more").join(name(i))
            } else {
                dir.join(name(i))
            };
            write_slice(&p, &header(SERIES, i, z), &words[i])?;
            files.push(p);
        }
        Ok(files)
    };
    write_series(&out.join("series"))?;
    let files = write_series(&out.join("dup"))?;
    std::fs::copy(&files[5], out.join("dup").join("IMCOPY"))?;
    write_series(&out.join("mixed"))?;
    for (i, &z) in kept.iter().take(4).enumerate() {
        write_slice(
            &out.join("mixed").join(format!("OTHER{i}")),
            &header(OTHER, i, z),
            &words[i],
        )?;
    }
    let files = write_series(&out.join("truncated"))?;
    let b = std::fs::read(&files[7])?;
    std::fs::write(&files[7], &b[..b.len() / 2])?;

    // The series' reference: the same slices as a raw stack.
    let raw: Vec<u8> = words
        .iter()
        .flatten()
        .flat_map(|w| w.to_le_bytes())
        .collect();
    std::fs::write(out.join("series.raw"), raw)?;
    let positions: Vec<f64> = kept.iter().map(|&z| zs[z]).collect();
    let side = serde_json::json!({
        "data": "series.raw", "dims": [nx, ny, kept.len()], "dtype": "i16",
        "x": sx, "y": sy, "z": {"positions": positions}, "origin": [x0, y0, 0.0],
        "rescale": {"slope": meta.rescale.slope, "intercept": meta.rescale.intercept},
    });
    std::fs::write(
        out.join("series.json"),
        serde_json::to_string_pretty(&side)?,
    )?;

    // The whole CT as NRRD (gzip) and NIfTI (.nii.gz); z must be uniform.
    let sz = zs[1] - zs[0];
    let mut all = Vec::with_capacity(nx * ny * nz * 2);
    for z in 0..nz {
        src.read_slice(z, &mut slice)?;
        all.extend(slice.iter().flat_map(|&v| (v as i16).to_le_bytes()));
    }
    let mut nrrd = format!(
        "NRRD0004\n# cdvol-fixtures from {}\ntype: short\ndimension: 3\nspace: left-posterior-superior\n\
         sizes: {nx} {ny} {nz}\nspace directions: ({sx},0,0) (0,{sy},0) (0,0,{sz})\n\
         kinds: domain domain domain\nendian: little\nencoding: gzip\nspace origin: ({x0},{y0},{})\n\n",
        ct.display(),
        zs[0]
    )
    .into_bytes();
    nrrd.extend(gzip(&all)?);
    std::fs::write(out.join("volume.nrrd"), nrrd)?;
    let mut nii = nifti1_header([nx, ny, nz], [sx, sy, sz], [x0, y0, zs[0]], meta.rescale);
    nii.extend(&all);
    std::fs::write(out.join("volume.nii.gz"), gzip(&nii)?)?;
    println!(
        "wrote {}: series of {} of {nz} slices, dup/, mixed/, truncated/, volume.nrrd, volume.nii.gz",
        out.display(),
        kept.len()
    );
    Ok(())
}

fn gzip(b: &[u8]) -> Result<Vec<u8>> {
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    e.write_all(b)?;
    Ok(e.finish()?)
}

/// A single-file NIfTI-1 header (little endian) for int16 data, padded to
/// the 352-byte data offset.
fn nifti1_header(dims: [usize; 3], spacing: [f64; 3], origin: [f64; 3], rs: Rescale) -> Vec<u8> {
    let mut h = vec![0u8; 352];
    let put_i16 =
        |h: &mut Vec<u8>, at: usize, v: i16| h[at..at + 2].copy_from_slice(&v.to_le_bytes());
    let put_f32 =
        |h: &mut Vec<u8>, at: usize, v: f32| h[at..at + 4].copy_from_slice(&v.to_le_bytes());
    h[0..4].copy_from_slice(&348i32.to_le_bytes()); // sizeof_hdr
    let dim = [
        3,
        dims[0] as i16,
        dims[1] as i16,
        dims[2] as i16,
        1,
        1,
        1,
        1,
    ];
    for (k, d) in dim.iter().enumerate() {
        put_i16(&mut h, 40 + 2 * k, *d);
    }
    put_i16(&mut h, 70, 4); // datatype: int16
    put_i16(&mut h, 72, 16); // bitpix
    put_f32(&mut h, 76, 1.0); // pixdim[0]: qfac
    for (k, s) in spacing.iter().enumerate() {
        put_f32(&mut h, 80 + 4 * k, *s as f32);
    }
    put_f32(&mut h, 108, 352.0); // vox_offset
    put_f32(&mut h, 112, rs.slope as f32);
    put_f32(&mut h, 116, rs.intercept as f32);
    h[123] = 2; // xyzt_units: mm
    put_i16(&mut h, 254, 1); // sform_code: scanner
    let srow = [
        [spacing[0], 0.0, 0.0, origin[0]],
        [0.0, spacing[1], 0.0, origin[1]],
        [0.0, 0.0, spacing[2], origin[2]],
    ];
    for (r, row) in srow.iter().enumerate() {
        for (c, v) in row.iter().enumerate() {
            put_f32(&mut h, 280 + 16 * r + 4 * c, *v as f32);
        }
    }
    h[344..348].copy_from_slice(b"n+1\0");
    h
}
