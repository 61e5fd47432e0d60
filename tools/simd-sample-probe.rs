//! What SIMD across one ray's samples, or across rays, would buy the
//! composite: a probe, not cdvol code (docs/BENCHMARKS.md, "SIMD across a
//! ray's samples" and "What stands between the unmet targets and this
//! design").
//!
//! A synthetic 96^3 volume of 16-bit words read through a word -> value
//! table (as `Samples::Words16` is), a 1024-bin transfer-function table of
//! (start, slope) pairs (as `TfLut::sample32`'s), 20,000 directions, 8
//! parallel rays each, 80 samples 0.5 cells apart from around the centre.
//! Each sample: its cell and local coordinates by position (floor), 8
//! vertex loads, the trilinear value, the table, front-to-back
//! compositing. Four samplers, the same samples:
//! - `scalar`: one sample at a time;
//! - `simd-loads`: 8 samples of the ray at once in AVX2 lanes, the vertex
//!   words and values loaded one by one into the lanes, the transfer
//!   function read by AVX2 gathers;
//! - `simd-gather`: the same with the vertices read by gathers too;
//! - `packet`: SIMD across rays instead (thirty-second session): eight
//!   parallel rays of 2 x 4 neighbouring pixels, one per lane, sample `i`
//!   of all eight at once; a cell all eight share has its vertices loaded
//!   once, and the compositing is in lanes (the rays are independent).
//!
//! The compositing stays serial in the first three (the opacity of one
//! sample weights the next). All four take the same samples: every
//! sampler walks the eight rays of each packet. Standalone, no
//! dependencies (the argument is the pixel spacing in cells, 0.25 by
//! default: a 1024^2 image of the real CT):
//!
//!     rustc -C opt-level=3 tools/simd-sample-probe.rs -o /tmp/simd-probe && taskset -c 1 /tmp/simd-probe [0.25]
use std::time::Instant;

const N: usize = 96;
const BINS: usize = 1024;

struct Volume {
    words: Vec<u16>,
    /// Word -> value.
    table: Vec<f32>,
    /// Per bin: rgba at the bin's start, then rgba slope to the next.
    tf: Vec<[f32; 8]>,
    lo: f32,
    inv_bin: f32,
}

fn volume() -> Volume {
    let mut words = vec![0u16; N * N * N];
    let mut s = 12345u64;
    for (i, w) in words.iter_mut().enumerate() {
        let (x, y, z) = ((i % N) as f32, ((i / N) % N) as f32, (i / (N * N)) as f32);
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        let noise = ((s >> 33) % 200) as f32;
        let v = 1000.0 + 500.0 * ((x * 0.1).sin() + (y * 0.13).cos() + (z * 0.07).sin()) + noise;
        *w = v.clamp(0.0, 4095.0) as u16;
    }
    let table = (0..65536).map(|w| w as f32 * 0.5 - 100.0).collect();
    let at = |i: usize| {
        let f = i as f32 / BINS as f32;
        [f, 1.0 - f, 0.5 * f, 0.002 + 0.01 * f * f]
    };
    let tf = (0..BINS)
        .map(|i| {
            let (a, b) = (at(i), at(i + 1));
            [
                a[0],
                a[1],
                a[2],
                a[3],
                b[0] - a[0],
                b[1] - a[1],
                b[2] - a[2],
                b[3] - a[3],
            ]
        })
        .collect();
    Volume {
        words,
        table,
        tf,
        lo: -100.0,
        inv_bin: (BINS as f32 - 1.0) / 2100.0,
    }
}

fn lerp(a: f32, b: f32, t: f32) -> f32 {
    a + t * (b - a)
}

/// Composites sample `(r, g, b, a)` behind `acc`; `true` once opaque.
fn over(acc: &mut [f32; 4], s: [f32; 4]) -> bool {
    let w = 1.0 - acc[3];
    for c in 0..4 {
        acc[c] += w * s[c];
    }
    acc[3] > 0.99
}

fn classify(v: &Volume, value: f32) -> [f32; 4] {
    let pos = ((value - v.lo) * v.inv_bin).clamp(0.0, BINS as f32 - 1.0);
    let bin = pos as usize;
    let fr = pos - bin as f32;
    let e = &v.tf[bin];
    [
        e[0] + fr * e[4],
        e[1] + fr * e[5],
        e[2] + fr * e[6],
        e[3] + fr * e[7],
    ]
}

fn ray_scalar(v: &Volume, p0: [f32; 3], d: [f32; 3], k: usize) -> [f32; 4] {
    let mut acc = [0.0; 4];
    for i in 0..k {
        let p: [f32; 3] = std::array::from_fn(|a| p0[a] + i as f32 * d[a]);
        let c = p.map(|x| x as usize);
        let u: [f32; 3] = std::array::from_fn(|a| p[a] - c[a] as f32);
        let b = c[0] + (c[1] + c[2] * N) * N;
        let (sy, sz) = (N, N * N);
        // One bounds check for the 8 vertices, as cdvol's `gather8`.
        let words = &v.words[b..=b + sz + sy + 1];
        // SAFETY: `o <= sz + sy + 1`, checked by the slice; words index the table.
        let f = |o: usize| unsafe { *v.table.get_unchecked(*words.get_unchecked(o) as usize) };
        let x00 = lerp(f(0), f(1), u[0]);
        let x10 = lerp(f(sy), f(sy + 1), u[0]);
        let x01 = lerp(f(sz), f(sz + 1), u[0]);
        let x11 = lerp(f(sz + sy), f(sz + sy + 1), u[0]);
        let value = lerp(lerp(x00, x10, u[1]), lerp(x01, x11, u[1]), u[2]);
        if over(&mut acc, classify(v, value)) {
            break;
        }
    }
    acc
}

#[cfg(target_arch = "x86_64")]
mod avx2 {
    use super::{over, Volume, BINS, N};
    use std::arch::x86_64::*;

    /// Eight samples' local coordinates in their cells, and each cell's
    /// first vertex (word index).
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn cells(p: [__m256; 3]) -> ([__m256; 3], __m256i) {
        let c = p.map(|x| _mm256_cvttps_epi32(x));
        let u = std::array::from_fn(|a| _mm256_sub_ps(p[a], _mm256_cvtepi32_ps(c[a])));
        let row = _mm256_mullo_epi32(c[1], _mm256_set1_epi32(N as i32));
        let slice = _mm256_mullo_epi32(c[2], _mm256_set1_epi32((N * N) as i32));
        (u, _mm256_add_epi32(c[0], _mm256_add_epi32(row, slice)))
    }

    /// The trilinear value in eight lanes from the vertices `vertex(o)`,
    /// `o` each vertex's word offset from the cell's first.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn trilinear(u: [__m256; 3], mut vertex: impl FnMut(i32) -> __m256) -> __m256 {
        let lerp = |a: __m256, b: __m256, t: __m256| _mm256_fmadd_ps(t, _mm256_sub_ps(b, a), a);
        let (sy, sz) = (N as i32, (N * N) as i32);
        let x00 = lerp(vertex(0), vertex(1), u[0]);
        let x10 = lerp(vertex(sy), vertex(sy + 1), u[0]);
        let x01 = lerp(vertex(sz), vertex(sz + 1), u[0]);
        let x11 = lerp(vertex(sz + sy), vertex(sz + sy + 1), u[0]);
        lerp(lerp(x00, x10, u[1]), lerp(x01, x11, u[1]), u[2])
    }

    /// The vertex at word offset `o` from the cells `idx` of the eight
    /// lanes, loaded into the lanes one by one.
    ///
    /// # Safety
    /// Every `idx[j] + o` is a word of the volume.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn lane_loads(v: &Volume, idx: &[i32; 8], o: i32) -> __m256 {
        let f = |j: usize| {
            *v.table
                .get_unchecked(*v.words.get_unchecked((idx[j] + o) as usize) as usize)
        };
        _mm256_setr_ps(f(0), f(1), f(2), f(3), f(4), f(5), f(6), f(7))
    }

    /// The transfer function of eight values, by gathers: r, g, b, a.
    #[inline]
    #[target_feature(enable = "avx2,fma")]
    unsafe fn classify(v: &Volume, value: __m256) -> [__m256; 4] {
        let pos = _mm256_mul_ps(
            _mm256_sub_ps(value, _mm256_set1_ps(v.lo)),
            _mm256_set1_ps(v.inv_bin),
        );
        let top = _mm256_set1_ps(BINS as f32 - 1.0);
        let pos = _mm256_min_ps(_mm256_max_ps(pos, _mm256_setzero_ps()), top);
        let bin = _mm256_cvttps_epi32(pos);
        let fr = _mm256_sub_ps(pos, _mm256_cvtepi32_ps(bin));
        let base = _mm256_slli_epi32(bin, 3);
        let tf = v.tf.as_ptr() as *const f32;
        std::array::from_fn(|ch| {
            let at = |o: usize| _mm256_add_epi32(base, _mm256_set1_epi32(o as i32));
            let start = _mm256_i32gather_ps::<4>(tf, at(ch));
            let slope = _mm256_i32gather_ps::<4>(tf, at(ch + 4));
            _mm256_fmadd_ps(fr, slope, start)
        })
    }

    /// # Safety
    /// The CPU has AVX2 and FMA; every sample lies inside the volume.
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn ray<const GATHER: bool>(
        v: &Volume,
        p0: [f32; 3],
        d: [f32; 3],
        k: usize,
    ) -> [f32; 4] {
        let mut acc = [0.0f32; 4];
        let lane = _mm256_setr_ps(0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0);
        let mut i = 0;
        while i < k {
            let fi = _mm256_add_ps(_mm256_set1_ps(i as f32), lane);
            let (u, b) = cells(std::array::from_fn(|a| {
                _mm256_fmadd_ps(fi, _mm256_set1_ps(d[a]), _mm256_set1_ps(p0[a]))
            }));
            let mut idx = [0i32; 8];
            _mm256_storeu_si256(idx.as_mut_ptr() as *mut __m256i, b);
            let value = trilinear(u, |o| {
                if GATHER {
                    let off = _mm256_slli_epi32(_mm256_add_epi32(b, _mm256_set1_epi32(o)), 1);
                    let w = _mm256_i32gather_epi32::<1>(v.words.as_ptr() as *const i32, off);
                    let w = _mm256_and_si256(w, _mm256_set1_epi32(0xffff));
                    _mm256_i32gather_ps::<4>(v.table.as_ptr(), w)
                } else {
                    // SAFETY: in the volume (the caller's contract).
                    lane_loads(v, &idx, o)
                }
            });
            // The table by gathers in both variants (one vector per channel).
            let mut rgba = [[0f32; 8]; 4];
            for (out, x) in rgba.iter_mut().zip(classify(v, value)) {
                _mm256_storeu_ps(out.as_mut_ptr(), x);
            }
            for j in 0..(k - i).min(8) {
                if over(&mut acc, [rgba[0][j], rgba[1][j], rgba[2][j], rgba[3][j]]) {
                    return acc;
                }
            }
            i += 8;
        }
        acc
    }

    /// Eight parallel rays in lockstep, one per lane (a packet of 2 x 4
    /// neighbouring pixels): sample `i` of every lane at `p0[lane] + i d`.
    /// Where all eight lanes are in the same cell, its 8 vertices are
    /// loaded once and broadcast; elsewhere lane by lane, as `simd-loads`.
    /// The rays are independent, so the compositing is in lanes too. Adds
    /// to `shared` the samples whose cell all lanes shared.
    ///
    /// # Safety
    /// The CPU has AVX2 and FMA; every sample lies inside the volume.
    #[target_feature(enable = "avx2,fma")]
    pub unsafe fn packet(
        v: &Volume,
        p0: &[[f32; 3]; 8],
        d: [f32; 3],
        k: usize,
        shared: &mut usize,
    ) -> [[f32; 4]; 8] {
        let start: [__m256; 3] = std::array::from_fn(|a| {
            _mm256_setr_ps(
                p0[0][a], p0[1][a], p0[2][a], p0[3][a], p0[4][a], p0[5][a], p0[6][a], p0[7][a],
            )
        });
        let one = _mm256_set1_ps(1.0);
        // r, g, b, a of the eight rays.
        let mut acc = [_mm256_setzero_ps(); 4];
        // Lanes still compositing: all ones until the lane passes 0.99.
        let mut live = _mm256_castsi256_ps(_mm256_set1_epi32(-1));
        let stop = _mm256_set1_ps(0.99);
        for i in 0..k {
            let fi = _mm256_set1_ps(i as f32);
            let (u, b) = cells(std::array::from_fn(|a| {
                _mm256_fmadd_ps(fi, _mm256_set1_ps(d[a]), start[a])
            }));
            let b0 = _mm256_permutevar8x32_epi32(b, _mm256_setzero_si256());
            let same = _mm256_movemask_epi8(_mm256_cmpeq_epi32(b, b0)) == -1;
            let mut idx = [0i32; 8];
            _mm256_storeu_si256(idx.as_mut_ptr() as *mut __m256i, b);
            *shared += same as usize * 8;
            let value = trilinear(u, |o| {
                if same {
                    // SAFETY: in the volume (the caller's contract).
                    let w = *v.words.get_unchecked((idx[0] + o) as usize);
                    _mm256_set1_ps(*v.table.get_unchecked(w as usize))
                } else {
                    // SAFETY: as above.
                    lane_loads(v, &idx, o)
                }
            });
            // `over` in lanes: w = 1 - a, zero in lanes already opaque.
            let w = _mm256_and_ps(_mm256_sub_ps(one, acc[3]), live);
            for (a, x) in acc.iter_mut().zip(classify(v, value)) {
                *a = _mm256_fmadd_ps(w, x, *a);
            }
            live = _mm256_andnot_ps(_mm256_cmp_ps::<_CMP_GT_OQ>(acc[3], stop), live);
            if _mm256_movemask_ps(live) == 0 {
                break;
            }
        }
        let mut out = [[0f32; 8]; 4];
        for (o, x) in out.iter_mut().zip(acc) {
            _mm256_storeu_ps(o.as_mut_ptr(), x);
        }
        std::array::from_fn(|j| [out[0][j], out[1][j], out[2][j], out[3][j]])
    }
}

fn main() {
    #[cfg(target_arch = "x86_64")]
    if !(is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")) {
        eprintln!("this CPU lacks AVX2 or FMA");
        return;
    }
    // Pixel spacing in cells for the packets (argument 1; 0.25 is a
    // 1024^2 image of the real CT, whose cells are about 4 pixels wide).
    let pix: f32 = std::env::args()
        .nth(1)
        .and_then(|a| a.parse().ok())
        .unwrap_or(0.25);
    // The samplers' loads are unchecked: keep every ray inside.
    assert!(pix.abs() <= 1.0, "pixel spacing at most 1 cell");
    let v = volume();
    let mut s = 99u64;
    let mut rnd = || {
        s = s
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (s >> 40) as f32 / (1u64 << 24) as f32 - 0.5
    };
    let dirs: Vec<[f32; 3]> = (0..20_000)
        .map(|_| {
            let d = [rnd(), rnd(), rnd()];
            let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            d.map(|x| 0.5 * x / l)
        })
        .collect();
    let k = 80;
    // Per direction, a packet of 2 x 4 parallel rays `pix` apart across
    // it, around the centre (an orthographic camera's neighbouring pixels).
    let packets: Vec<[[f32; 3]; 8]> = dirs
        .iter()
        .map(|d| {
            let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let t = d.map(|x| x / n);
            let a = if t[0].abs() < 0.9 {
                [1.0, 0.0, 0.0]
            } else {
                [0.0, 1.0, 0.0]
            };
            let cross = |u: [f32; 3], w: [f32; 3]| {
                [
                    u[1] * w[2] - u[2] * w[1],
                    u[2] * w[0] - u[0] * w[2],
                    u[0] * w[1] - u[1] * w[0],
                ]
            };
            let e1 = cross(t, a);
            let l1 = (e1[0] * e1[0] + e1[1] * e1[1] + e1[2] * e1[2]).sqrt();
            let e1 = e1.map(|x| x / l1);
            let e2 = cross(t, e1);
            std::array::from_fn(|j| {
                let (x, y) = ((j % 4) as f32 * pix, (j / 4) as f32 * pix);
                std::array::from_fn(|c| N as f32 / 2.0 + x * e1[c] + y * e2[c])
            })
        })
        .collect();
    type Sampler<'a> = Box<dyn Fn(&[[f32; 3]; 8], [f32; 3], &mut usize) -> f64 + 'a>;
    let each = |f: &dyn Fn([f32; 3], [f32; 3]) -> [f32; 4], p: &[[f32; 3]; 8], d| {
        p.iter().map(|&p0| f(p0, d)[3] as f64).sum::<f64>()
    };
    let samplers: Vec<(&str, Sampler)> = vec![
        (
            "scalar",
            Box::new(|p, d, _| each(&|p0, d| ray_scalar(&v, p0, d, k), p, d)),
        ),
        // SAFETY: AVX2 and FMA checked above; the rays stay inside
        // (80 x 0.5 + 4 pix < 48).
        (
            "simd-loads",
            Box::new(|p, d, _| each(&|p0, d| unsafe { avx2::ray::<false>(&v, p0, d, k) }, p, d)),
        ),
        (
            "simd-gather",
            Box::new(|p, d, _| each(&|p0, d| unsafe { avx2::ray::<true>(&v, p0, d, k) }, p, d)),
        ),
        // SAFETY: as above.
        (
            "packet",
            Box::new(|p, d, sh| {
                unsafe { avx2::packet(&v, p, d, k, sh) }
                    .iter()
                    .map(|a| a[3] as f64)
                    .sum()
            }),
        ),
    ];
    let mut best = vec![f64::MAX; samplers.len()];
    let mut sums = vec![0.0f64; samplers.len()];
    let mut shared = 0;
    for _ in 0..7 {
        for (i, (_, f)) in samplers.iter().enumerate() {
            shared = 0;
            let t = Instant::now();
            let sum: f64 = packets
                .iter()
                .zip(&dirs)
                .map(|(p, &d)| f(p, d, &mut shared))
                .sum();
            best[i] = best[i].min(t.elapsed().as_secs_f64());
            sums[i] = sum;
        }
    }
    let n = (packets.len() * 8 * k) as f64;
    for (i, (name, _)) in samplers.iter().enumerate() {
        println!(
            "{name:12} {:6.2} ns/sample  scalar/this {:.2}  (sum of opacities {:.3})",
            best[i] / n * 1e9,
            best[0] / best[i],
            sums[i]
        );
    }
    println!(
        "packet: {:.1} % of samples in a cell all 8 lanes share (pixels {pix} cells apart)",
        100.0 * shared as f64 / n
    );
}
