//! The every-bit flip sweep CI runs (issue 17): every single-bit flip of
//! the JSON header and the brick index of a small packed file must give a
//! named error (the file's name in the message) on open or render, or a
//! byte-identical render; never a panic, never a silently different image.
//!
//! A second sweep flips the same bits and then rewrites the trailer CRC as
//! the writer computes it, as a hostile or buggy writer would: only the
//! reader's semantic checks and the per-brick payload CRCs stand between
//! such a file and the renderer. It must never panic and every error must
//! name the file; its outcome counts are printed (run with `--nocapture`)
//! and recorded in docs/RELIABILITY.md ("Flip sweep").

use std::path::Path;

use cdvol::format::reader::PackedVolume;
use cdvol::format::FOOTER_LEN;
use cdvol::progress::NoProgress;
use cdvol::render::sample::hit::HitMethod;
use cdvol::render::traverse::Method;
use cdvol::render::{render, Frame, Mode, RenderOptions};
use cdvol::tools::phantom;

use crate::common::{orbit, packed_with, same_frame};

#[derive(Debug, Default)]
struct Counts {
    flips: usize,
    refused_open: usize,
    refused_render: usize,
    identical: usize,
    different: usize,
}

/// Opens and renders `file`: Ok(frame), or Err((at open?, message)).
fn try_render(file: &Path) -> Result<Frame, (bool, String)> {
    let vol = PackedVolume::open(file).map_err(|e| (true, e.to_string()))?;
    let cam = orbit(&vol, [30.0, 20.0], None, 16, 16);
    let opts = RenderOptions {
        tile: 8,
        cache_bytes: 1 << 20,
        ..RenderOptions::new(
            Mode::Surface {
                hit: HitMethod::Int,
                shadows: false,
            },
            Method::Cd { min_leap: 1 },
        )
    };
    render(&vol, &cam, &opts, &NoProgress)
        .map(|(f, _)| f)
        .map_err(|e| (false, e.to_string()))
}

/// Rewrites the footer's CRC-32 over header and index, as the writer does.
fn fix_crc(file: &mut [u8]) {
    let (t, h, i) = crate::common::footer(file);
    let crc = crc32fast::hash(&file[t..t + h + i]);
    let at = file.len() - FOOTER_LEN as usize + 24;
    file[at..at + 4].copy_from_slice(&crc.to_le_bytes());
}

fn sweep(dir: &Path, good: &[u8], want: &Frame, recrc: bool) -> (Counts, Vec<String>) {
    let (t, h, i) = crate::common::footer(good);
    let p = dir.join(if recrc { "recrc.cdv" } else { "flip.cdv" });
    let mut c = Counts::default();
    let mut bad = Vec::new();
    let mut b = good.to_vec();
    for byte in t..t + h + i {
        for bit in 0..8 {
            b[byte] ^= 1 << bit;
            if recrc {
                fix_crc(&mut b);
            }
            std::fs::write(&p, &b).unwrap();
            c.flips += 1;
            match try_render(&p) {
                Err((at_open, m)) => {
                    if at_open {
                        c.refused_open += 1;
                    } else {
                        c.refused_render += 1;
                    }
                    if !m.contains("cdv") {
                        bad.push(format!("byte {byte} bit {bit}: unnamed error {m}"));
                    }
                }
                Ok(f) if same_frame(&f, want) => c.identical += 1,
                Ok(_) => {
                    if std::env::var("FLIP_DEBUG").is_ok() {
                        let at = if byte < t + h {
                            let j = byte - t;
                            String::from_utf8_lossy(
                                &good[t + j.saturating_sub(20)..t + (j + 5).min(h)],
                            )
                            .into_owned()
                        } else {
                            format!("index entry byte {}", (byte - t - h) % 32)
                        };
                        eprintln!("DIFF byte {byte} bit {bit}: {at}");
                    }
                    c.different += 1;
                    if !recrc {
                        bad.push(format!("byte {byte} bit {bit}: a different image"));
                    }
                }
            }
            b[byte] ^= 1 << bit;
        }
    }
    if recrc {
        fix_crc(&mut b);
    }
    assert_eq!(b, good);
    (c, bad)
}

#[test]
fn every_bit_flip_of_header_and_index_is_refused_or_harmless() {
    let dir = tempfile::tempdir().unwrap();
    let ct = dir.path().join("ct.json");
    phantom::ct(
        &ct,
        &phantom::CtOptions {
            dims: [10, 9, 8],
            ..Default::default()
        },
        &NoProgress,
    )
    .unwrap();
    let cdv = dir.path().join("ct.cdv");
    // A low iso: the skin, so bricks hold payloads and rays hit.
    packed_with(&ct, &cdv, -500.0, |o| o.brick_size = 4);
    let good = std::fs::read(&cdv).unwrap();
    let want = try_render(&cdv).unwrap();
    assert!(
        want.rgb.iter().any(|&x| x > 0),
        "the render shows the surface"
    );
    let (t, h, i) = crate::common::footer(&good);
    assert!(t > 16, "bricks with payloads");
    let t0 = std::time::Instant::now();
    println!("flip sweep: header {h} bytes, index {i} bytes, trailer at {t}");

    let (raw, bad) = sweep(dir.path(), &good, &want, false);
    println!(
        "flip sweep, raw: {raw:?} in {:.2} s",
        t0.elapsed().as_secs_f64()
    );
    let t0 = std::time::Instant::now();
    assert!(bad.is_empty(), "{bad:#?}");
    assert_eq!(raw.flips, 8 * (h + i));

    let (fixed, bad) = sweep(dir.path(), &good, &want, true);
    println!(
        "flip sweep, CRC rewritten: {fixed:?} in {:.2} s",
        t0.elapsed().as_secs_f64()
    );
    assert!(bad.is_empty(), "{bad:#?}");
}
