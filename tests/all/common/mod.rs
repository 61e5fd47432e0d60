//! Shared helpers of the integration tests: writing raw stacks, oracles
//! that do not share code with the library, reading packed files back into
//! dense arrays, preparing and rendering with the tests' settings, and
//! running the `cdvol` binary. Each helper is written once here.
#![allow(dead_code)]

pub mod dicom_series;

use std::collections::VecDeque;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::Command;

use cdvol::classify::{Classification, TfPoint, TransferFunction};
use cdvol::format::reader::{BrickData, CellClass, PackedVolume, Sample};
use cdvol::prep::{prep, PrepOptions};
use cdvol::progress::NoProgress;
use cdvol::render::traverse::TGrid;
use cdvol::render::view::camera::Camera;
use cdvol::render::Frame;

/// Writes `values` (x fastest) as a raw stack of `dtype` plus a sidecar
/// with the given axis JSON snippets; returns the sidecar path.
pub fn write_stack(
    dir: &Path,
    name: &str,
    dims: [usize; 3],
    dtype: &str,
    values: &[f64],
    axes_json: [&str; 3],
    extra: &str,
) -> PathBuf {
    let mut bytes = Vec::new();
    for &v in values {
        match dtype {
            "u8" => bytes.push(v as u8),
            "i8" => bytes.push(v as i8 as u8),
            "u16" => bytes.extend_from_slice(&(v as u16).to_le_bytes()),
            "i16" => bytes.extend_from_slice(&(v as i16).to_le_bytes()),
            "u32" => bytes.extend_from_slice(&(v as u32).to_le_bytes()),
            "i32" => bytes.extend_from_slice(&(v as i32).to_le_bytes()),
            "f32" => bytes.extend_from_slice(&(v as f32).to_le_bytes()),
            "f64" => bytes.extend_from_slice(&v.to_le_bytes()),
            _ => panic!("dtype {dtype}"),
        }
    }
    std::fs::write(dir.join(format!("{name}.raw")), &bytes).unwrap();
    let json = format!(
        r#"{{"data": "{name}.raw", "dims": [{}, {}, {}], "dtype": "{dtype}",
            "x": {}, "y": {}, "z": {} {extra}}}"#,
        dims[0], dims[1], dims[2], axes_json[0], axes_json[1], axes_json[2]
    );
    let p = dir.join(format!("{name}.json"));
    std::fs::write(&p, json).unwrap();
    p
}

/// A sidecar axis of sample positions (mm), as `write_stack` takes it.
pub fn axis_json(positions: &[f64]) -> String {
    let p: Vec<String> = positions.iter().map(|x| format!("{x:?}")).collect();
    format!("{{\"positions\": [{}]}}", p.join(", "))
}

/// Iso classification oracle: 1 when the largest non-NaN vertex value of a
/// cell is >= iso.
pub fn classify_iso(values: &[f64], dims: [usize; 3], iso: f64) -> Vec<u8> {
    let [nx, ny, nz] = dims;
    let (cx, cy, cz) = (nx - 1, ny - 1, nz - 1);
    let mut out = vec![0u8; cx * cy * cz];
    for z in 0..cz {
        for y in 0..cy {
            for x in 0..cx {
                let mut hit = false;
                for i in 0..8 {
                    let v = values[((z + (i >> 2)) * ny + y + (i >> 1 & 1)) * nx + x + (i & 1)];
                    hit |= v >= iso;
                }
                out[(z * cy + y) * cx + x] = hit as u8;
            }
        }
    }
    out
}

/// Chessboard distance oracle by multi-source breadth-first search over
/// 26-neighbours (a chessboard ball of radius r is exactly the set of
/// cells r 26-steps away), saturated at 255. Independent of the library's
/// two-pass recurrence.
pub fn chessboard_bfs(obj: &[u8], cells: [usize; 3]) -> Vec<u8> {
    let [cx, cy, cz] = cells;
    let mut d = vec![255u8; obj.len()];
    let mut q = VecDeque::new();
    for (i, &o) in obj.iter().enumerate() {
        if o != 0 {
            d[i] = 0;
            q.push_back(i);
        }
    }
    while let Some(i) = q.pop_front() {
        let (x, y, z) = (i % cx, i / cx % cy, i / cx / cy);
        let nd = d[i].saturating_add(1);
        if nd == 255 {
            continue;
        }
        for dz in -1i64..=1 {
            for dy in -1i64..=1 {
                for dx in -1i64..=1 {
                    let (a, b, c) = (x as i64 + dx, y as i64 + dy, z as i64 + dz);
                    if a < 0 || b < 0 || c < 0 || a >= cx as i64 || b >= cy as i64 || c >= cz as i64
                    {
                        continue;
                    }
                    let j = ((c as usize * cy) + b as usize) * cx + a as usize;
                    if d[j] > nd {
                        d[j] = nd;
                        q.push_back(j);
                    }
                }
            }
        }
    }
    d
}

/// Expected per-cell codes export: 255 for 1-cells, else min(d - 1, max).
pub fn expected_codes(dist: &[u8], max_code: u32) -> Vec<u8> {
    dist.iter()
        .map(|&d| {
            if d == 0 {
                255
            } else {
                ((d - 1) as u32).min(max_code) as u8
            }
        })
        .collect()
}

/// Everything read back from a packed file, densely.
pub struct ReadBack {
    /// 255 for 1-cells, else the code.
    pub codes: Vec<u8>,
    /// Number of 1-cells whose 8 vertex values were checked.
    pub checked_one_cells: usize,
}

/// Reads every brick, checks that every 1-cell's 8 vertex words are exact
/// values equal to `values` (rescale not applied), and returns the codes.
pub fn read_back(vol: &PackedVolume, values: &[f64]) -> ReadBack {
    let h = vol.header();
    let [nx, ny, _] = h.dims.map(|d| d as usize);
    let [cx, cy, cz] = h.cells().map(|c| c as usize);
    let mut codes = vec![0u8; cx * cy * cz];
    let mut seen = vec![false; cx * cy * cz];
    let mut checked = 0;
    for id in 0..h.brick_count() {
        let b = vol.read_brick(id).unwrap();
        let no_object = vol.index()[id as usize].has_no_object();
        let mut brick_min_code = u32::MAX;
        let [sx, sy, sz] = b.samples;
        for lz in 0..sz - 1 {
            for ly in 0..sy - 1 {
                for lx in 0..sx - 1 {
                    let g = [
                        b.first[0] as usize + lx,
                        b.first[1] as usize + ly,
                        b.first[2] as usize + lz,
                    ];
                    let ci = (g[2] * cy + g[1]) * cx + g[0];
                    assert!(!seen[ci], "cell {g:?} in two bricks");
                    seen[ci] = true;
                    match vol.cell_class(&b, [lx, ly, lz]) {
                        CellClass::Object => {
                            assert!(
                                !no_object,
                                "brick {id} is flagged without 1-cells but has {g:?}"
                            );
                            codes[ci] = 255;
                            let v = b.vertices([lx, ly, lz]).unwrap();
                            for (i, s) in v.iter().enumerate() {
                                let want = values[((g[2] + (i >> 2)) * ny + g[1] + (i >> 1 & 1))
                                    * nx
                                    + g[0]
                                    + (i & 1)];
                                match s {
                                    Sample::Value(got) => assert!(
                                        *got == want || (got.is_nan() && want.is_nan()),
                                        "cell {g:?} vertex {i}: {got} stored, {want} in the input"
                                    ),
                                    Sample::Code(c) => {
                                        panic!("1-cell {g:?} vertex {i} carries code {c}")
                                    }
                                }
                            }
                            checked += 1;
                        }
                        CellClass::Empty(c) => {
                            codes[ci] = c.min(254) as u8;
                            brick_min_code = brick_min_code.min(c);
                        }
                    }
                }
            }
        }
        let e = vol.index()[id as usize];
        if no_object && !e.is_uniform() {
            assert_eq!(e.uniform_code, brick_min_code, "brick {id}: index min code");
        }
        if let BrickData::Uniform(_) = b.data {
            assert!(h.summary.uniform_bricks > 0);
        }
    }
    assert!(seen.iter().all(|&s| s), "some cell is in no brick");
    ReadBack {
        codes,
        checked_one_cells: checked,
    }
}

/// The real CT (Debian's invesalius-examples), fetched once into
/// target/ct by tools/fetch-ct.sh. Fails loudly when it cannot be fetched.
pub fn real_ct() -> PathBuf {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = root.join("target").join("ct");
    let sidecar = dir.join("cranium.json");
    // Tests run in parallel: one fetches, the others wait for it.
    static FETCH: std::sync::Mutex<()> = std::sync::Mutex::new(());
    let _guard = FETCH.lock().unwrap_or_else(|e| e.into_inner());
    if !sidecar.exists() {
        let st = std::process::Command::new("bash")
            .arg(root.join("tools/fetch-ct.sh"))
            .arg(&dir)
            .status()
            .expect("run tools/fetch-ct.sh");
        assert!(
            st.success() && sidecar.exists(),
            "the real CT could not be fetched: tools/fetch-ct.sh {} failed ({st}). \
             It needs `apt-get download invesalius-examples` to work (Debian archive reachable).",
            dir.display()
        );
    }
    sidecar
}

/// Two packed files hold the same volume: dims, axes, types, rescale,
/// summary and every brick's payload bytes (the source names differ).
pub fn assert_same_volume(got: &PackedVolume, want: &PackedVolume, what: &str) {
    let (g, w) = (got.header(), want.header());
    assert_eq!(g.dims, w.dims, "{what}: dims");
    assert_eq!(g.axes, w.axes, "{what}: axes");
    assert_eq!((g.dtype, g.storage), (w.dtype, w.storage), "{what}: types");
    assert_eq!(g.rescale, w.rescale, "{what}: rescale");
    assert_eq!(g.summary, w.summary, "{what}: summary");
    assert!(w.summary.one_cells > 0, "{what}: the fixture has 1-cells");
    for id in 0..w.brick_count() {
        assert_eq!(
            got.read_payload(id).unwrap(),
            want.read_payload(id).unwrap(),
            "{what}: brick {id}"
        );
    }
}

/// Random small volumes for prep tests: dims below `max` per axis (at least
/// 2), values 200 (above the tests' iso of 100) with probability `per_mille
/// < pct`, else 0..99; brick size 4 or 8.
pub fn random_volume(
    max: [usize; 3],
    max_pct: u32,
) -> impl proptest::strategy::Strategy<Value = ([usize; 3], Vec<f64>, usize)> {
    use proptest::prelude::*;
    (
        2usize..max[0],
        2usize..max[1],
        2usize..max[2],
        0u32..max_pct,
        prop_oneof![Just(4usize), Just(8)],
    )
        .prop_flat_map(|(x, y, z, pct, brick)| {
            (
                Just([x, y, z]),
                proptest::collection::vec(
                    (0u32..1000).prop_map(move |r| if r < pct { 200.0 } else { (r % 100) as f64 }),
                    x * y * z,
                ),
                Just(brick),
            )
        })
}

/// Render options of the render tests: 16-pixel tiles, a 64 MiB cache and
/// a low lazy threshold (so small test volumes exercise unread bricks).
pub fn test_opts(
    mode: cdvol::render::Mode,
    method: cdvol::render::traverse::Method,
) -> cdvol::render::RenderOptions {
    cdvol::render::RenderOptions {
        tile: 16,
        cache_bytes: 64 << 20,
        cd_lazy_min: Some(4),
        ..cdvol::render::RenderOptions::new(mode, method)
    }
}

/// The `cdvol` binary under test.
pub fn cdvol() -> Command {
    Command::new(env!("CARGO_BIN_EXE_cdvol"))
}

/// Runs `c`, requires it to succeed and returns its standard output.
pub fn ok(c: &mut Command) -> String {
    let out = c.output().unwrap();
    assert!(
        out.status.success(),
        "{c:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// A 48 x 48 x 32 CT phantom (`dir/ct.json`, written once) prepared by
/// `cdvol prep` with `prep` into `dir/NAME.cdv`.
pub fn prepared_ct_phantom(dir: &Path, name: &str, prep: &[&str]) -> PathBuf {
    let input = dir.join("ct.json");
    if !input.exists() {
        ok(cdvol()
            .args(["-q", "phantom", "ct", "--dims", "48,48,32", "-o"])
            .arg(&input));
    }
    let out = dir.join(format!("{name}.cdv"));
    ok(cdvol()
        .args(["-q", "prep"])
        .arg(&input)
        .arg("-o")
        .arg(&out)
        .args(prep));
    out
}

/// Runs `c`, requires it to fail (non-zero exit) and returns its standard
/// error.
pub fn fails(c: &mut Command) -> String {
    let out = c.output().unwrap();
    assert!(
        !out.status.success(),
        "{c:?} succeeded: {}",
        String::from_utf8_lossy(&out.stdout)
    );
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Prepares `input` (any format `cdvol::input::open` reads) with iso
/// classification at `iso` and 16-sample bricks, `tweak` setting anything
/// else; the error text of the step that refused.
pub fn try_packed(
    input: &Path,
    out: &Path,
    iso: f64,
    tweak: impl FnOnce(&mut PrepOptions),
) -> Result<PackedVolume, String> {
    let src = cdvol::input::open(input).map_err(|e| e.to_string())?;
    let mut o = PrepOptions::new(Classification::Iso { iso });
    o.brick_size = 16;
    tweak(&mut o);
    prep(src.as_ref(), out, &o, &NoProgress).map_err(|e| e.to_string())?;
    Ok(PackedVolume::open(out).unwrap())
}

/// [`try_packed`] that must succeed.
pub fn packed_with(
    input: &Path,
    out: &Path,
    iso: f64,
    tweak: impl FnOnce(&mut PrepOptions),
) -> PackedVolume {
    try_packed(input, out, iso, tweak).unwrap_or_else(|e| panic!("{}: {e}", input.display()))
}

/// `input` prepared at `iso` with 16-sample bricks and nothing else.
pub fn packed(input: &Path, out: &Path, iso: f64) -> PackedVolume {
    packed_with(input, out, iso, |_| {})
}

/// An orbit camera around the whole volume: `view` is (azimuth,
/// elevation) in degrees, `fov` a perspective field of view in degrees
/// (`None`: orthographic).
pub fn orbit(vol: &PackedVolume, view: [f64; 2], fov: Option<f64>, w: u32, h: u32) -> Camera {
    let g = TGrid::<f64>::new(&vol.header().axes);
    Camera::orbit(g.bounds(), view[0], view[1], fov, None, w, h).unwrap()
}

/// Two frames are the same image: size, colour bytes and depth bits.
pub fn same_frame(a: &Frame, b: &Frame) -> bool {
    let bits = |f: &Frame| {
        f.depth
            .as_ref()
            .map(|d| d.iter().map(|x| x.to_bits()).collect::<Vec<_>>())
    };
    a.width == b.width && a.height == b.height && a.rgb == b.rgb && bits(a) == bits(b)
}

/// A white transfer function through (value, opacity) points.
pub fn white_tf(points: &[(f64, f64)]) -> TransferFunction {
    TransferFunction {
        points: points
            .iter()
            .map(|&(value, opacity)| TfPoint {
                value,
                opacity,
                color: [1.0; 3],
            })
            .collect(),
    }
}

/// splitmix64: a deterministic stream of test values.
pub fn mix(i: u64) -> u64 {
    let mut z = i.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// `b` gzip-compressed.
pub fn gz(b: &[u8]) -> Vec<u8> {
    let mut e = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    e.write_all(b).unwrap();
    e.finish().unwrap()
}

/// Where a packed file's header and index lie, from its footer:
/// `(trailer offset, header length, index length)`.
pub fn footer(bytes: &[u8]) -> (usize, usize, usize) {
    let foot = &bytes[bytes.len() - 40..];
    let u64_at = |i: usize| u64::from_le_bytes(foot[i..i + 8].try_into().unwrap()) as usize;
    (u64_at(0), u64_at(8), u64_at(16))
}

/// Rewrites the JSON header of a packed file and fixes up the trailer
/// checksum and footer, so only the reader's header checks can refuse it.
pub fn rewrite_header(bytes: &[u8], f: impl Fn(&mut serde_json::Value)) -> Vec<u8> {
    let n = bytes.len();
    let foot = &bytes[n - 40..];
    let (trailer, hlen, ilen) = footer(bytes);
    let mut header: serde_json::Value =
        serde_json::from_slice(&bytes[trailer..trailer + hlen]).unwrap();
    f(&mut header);
    let json = serde_json::to_vec(&header).unwrap();
    let index = &bytes[trailer + hlen..trailer + hlen + ilen];
    let mut out = bytes[..trailer].to_vec();
    out.extend_from_slice(&json);
    out.extend_from_slice(index);
    let mut crc = crc32fast::Hasher::new();
    crc.update(&json);
    crc.update(index);
    out.extend_from_slice(&(trailer as u64).to_le_bytes());
    out.extend_from_slice(&(json.len() as u64).to_le_bytes());
    out.extend_from_slice(&(ilen as u64).to_le_bytes());
    out.extend_from_slice(&crc.finalize().to_le_bytes());
    out.extend_from_slice(&foot[28..40]);
    out
}

/// Runs `c` with a time limit: a command that hangs (reading a FIFO, say)
/// is killed and the test fails naming it.
pub fn run(c: &mut Command, limit: std::time::Duration) -> std::process::Output {
    use std::process::Stdio;
    let mut child = c
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let t0 = std::time::Instant::now();
    loop {
        if child.try_wait().unwrap().is_some() {
            return child.wait_with_output().unwrap();
        }
        if t0.elapsed() > limit {
            child.kill().unwrap();
            let _ = child.wait();
            panic!("{c:?} still running after {limit:?}: it hangs");
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
}

/// Every file's bytes under `dir` (recursively), to compare before/after.
pub fn snapshot(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            let m = std::fs::symlink_metadata(&p).unwrap();
            if m.is_dir() {
                stack.push(p);
            } else if m.is_file() {
                out.push((p.clone(), std::fs::read(&p).unwrap()));
            }
        }
    }
    out.sort();
    out
}

/// Requires every one of `words` in `text`.
pub fn has_all(text: &str, words: &[&str]) {
    for w in words {
        assert!(text.contains(w), "expected {w:?} in: {text}");
    }
}
