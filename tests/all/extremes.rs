//! The traversal at the extremes, against an exact oracle.
//!
//! The oracle works in exact rational arithmetic (num-rational): a 1-cell
//! is crossed when the open interval of `t` in which the ray is inside it
//! (from `t = 0` on; along axes the ray is parallel to, the cell is
//! half-open `[S_i, S_i+1)`, the last one closed) has positive length `L`.
//!
//! Tolerance, from the error analysis in src/render/traverse.rs: the f64
//! walk computes each plane crossing as `t (1 + e)` with `|e| <= 3u`
//! (`u = 2^-53`: one rounding each for `S - o`, `1 / d` and the product;
//! the power-of-two scaling is exact) and decides only by comparing these
//! values, so its `L` is within `2 * 3u * max(|t_lo|, |t_hi|)` of the
//! exact one. Cells with `|L|` inside that band may go either way; every
//! other cell must match exactly. When the six crossings of a cell are all
//! exactly representable (and computed exactly), the band is 0: such cells
//! (rays through sample lines, edges and corners of dyadic grids) must
//! match exactly too. The band is `6.01 u max(|t|)`: 6u plus slack for
//! the `O(u^2)` terms.
//!
//! Every case also checks: no panic, finite `t`, `t` never decreasing,
//! at most `ncx + ncy + ncz - 2` steps, CD's visits equal FVT's bit for
//! bit, in both f64 and f32. f32 is only held to those invariants; where
//! it differs from f64 is counted and printed (and measured in
//! docs/TRADEOFFS.md).

use cdvol::grid::{Axis, MAX_SAMPLES_PER_AXIS};
use cdvol::render::traverse::{trace, Flow, Method, Ray, RayError, TGrid};
use cdvol::tools::corpus::{self, MemVolume, Walked};
use num_bigint::BigInt;
use num_rational::BigRational;
use num_traits::{Signed, ToPrimitive, Zero};
use proptest::prelude::*;

const U: f64 = f64::EPSILON / 2.0;
const BAND: f64 = 6.01 * U;

const METHODS: [Method; 4] = [
    Method::Fvt,
    Method::Cd { min_leap: 1 },
    Method::Cd { min_leap: 2 },
    Method::Cd { min_leap: 4 },
];

fn q(x: f64) -> BigRational {
    BigRational::from_float(x).expect("finite")
}

/// What the exact oracle says of one 1-cell.
struct ExactCell {
    cell: [u32; 3],
    /// Whether the parallel axes admit the cell at all.
    inside: bool,
    lo: BigRational,
    hi: BigRational,
    /// Half-width of the band in which the f64 walk may decide either way.
    band: f64,
}

impl ExactCell {
    fn len(&self) -> BigRational {
        &self.hi - &self.lo
    }
    /// The exact walk crosses it.
    fn crossed(&self) -> bool {
        self.inside && self.len().is_positive()
    }
    /// The f64 walk must cross it.
    fn must(&self) -> bool {
        self.crossed() && self.len().to_f64().unwrap_or(f64::INFINITY) > self.band
    }
    /// The f64 walk may cross it.
    fn may(&self) -> bool {
        self.inside
            && (self.len().is_positive() || -self.len().to_f64().unwrap_or(0.0) <= self.band)
    }
}

/// The crossing of plane `s` as the f64 walk computes it (sign aside).
fn computed_t(s: f64, o: f64, d: f64) -> f64 {
    let t = (s - o) * (1.0 / d.abs());
    if d < 0.0 {
        -t
    } else {
        t
    }
}

fn oracle(vol: &MemVolume, ray: &Ray) -> Vec<ExactCell> {
    let c: [&[f64]; 3] = std::array::from_fn(|k| vol.axes[k].coords());
    let o = ray.origin.to_array().map(q);
    let d = ray.dir.to_array().map(q);
    vol.objects
        .iter()
        .map(|&cell| {
            let mut lo = BigRational::zero();
            let mut hi: Option<BigRational> = None;
            let mut inside = true;
            let mut all_exact = true;
            for k in 0..3 {
                let i = cell[k] as usize;
                let (a, b) = (c[k][i], c[k][i + 1]);
                let ok = ray.origin[k];
                if ray.dir[k] == 0.0 {
                    let last = i + 1 == c[k].len() - 1;
                    inside &= a <= ok && (ok < b || (last && ok == b));
                    continue;
                }
                let ta = (q(a) - &o[k]) / &d[k];
                let tb = (q(b) - &o[k]) / &d[k];
                for (s, t) in [(a, &ta), (b, &tb)] {
                    let ct = computed_t(s, ok, ray.dir[k]);
                    all_exact &= ct.is_finite() && q(ct) == *t;
                }
                let (enter, exit) = if ray.dir[k] > 0.0 { (ta, tb) } else { (tb, ta) };
                if enter > lo {
                    lo = enter;
                }
                hi = Some(match hi {
                    Some(h) if h < exit => h,
                    _ => exit,
                });
            }
            let hi = hi.expect("a non-zero direction has a non-zero component");
            let mag = lo
                .abs()
                .to_f64()
                .unwrap_or(f64::INFINITY)
                .max(hi.abs().to_f64().unwrap_or(f64::INFINITY));
            ExactCell {
                cell,
                inside,
                lo,
                hi,
                band: if all_exact { 0.0 } else { BAND * mag },
            }
        })
        .collect()
}

/// Invariants any walk must keep, in any arithmetic (from `t = 0`).
fn check_invariants(vol: &MemVolume, w: &Walked, what: &str) {
    if let Err(e) = corpus::check_walk(vol, w, Some(0.0)) {
        panic!("{what}: {e}");
    }
}

/// The f64 walk against the exact oracle.
fn check_exact(vol: &MemVolume, ray: &Ray, w: &Walked, what: &str) {
    let ex = oracle(vol, ray);
    for e in &ex {
        let got = w.visits.iter().find(|v| v.cell == e.cell);
        match got {
            None => assert!(
                !e.must(),
                "{what}: missed 1-cell {:?}: exact t in [{}, {}], length {:e} > band {:e}",
                e.cell,
                e.lo.to_f64().unwrap_or(f64::NAN),
                e.hi.to_f64().unwrap_or(f64::NAN),
                e.len().to_f64().unwrap_or(f64::NAN),
                e.band
            ),
            Some(v) => {
                assert!(
                    e.may(),
                    "{what}: visited {:?} which the exact ray does not cross \
                     (length {:e}, band {:e})",
                    e.cell,
                    e.len().to_f64().unwrap_or(f64::NAN),
                    e.band
                );
                // Entry and exit within the band of the exact ones.
                for (got, want) in [(v.t_enter, &e.lo), (v.t_exit, &e.hi)] {
                    let err = (q(got) - want).abs().to_f64().unwrap_or(f64::INFINITY);
                    assert!(
                        err <= e.band,
                        "{what}: {:?} t {got} vs exact {} (error {err:e} > band {:e})",
                        e.cell,
                        want.to_f64().unwrap_or(f64::NAN),
                        e.band
                    );
                }
            }
        }
    }
}

/// Differences between the f32 and f64 walks, tallied.
#[derive(Default, Debug)]
struct F32Tally {
    rays: u64,
    differ_cells: u64,
    missed_cells: u64,
    differ_first: u64,
}

fn run_case(vol: &MemVolume, rays: &[(String, Ray)], name: &str, tally: &mut F32Tally) {
    let g64 = TGrid::<f64>::new(&vol.axes);
    let g32 = TGrid::<f32>::new(&vol.axes);
    for (rn, ray) in rays {
        let what = format!("{name} / {rn}");
        let fvt = corpus::walk(vol, &g64, ray, Method::Fvt);
        check_invariants(vol, &fvt, &what);
        check_exact(vol, ray, &fvt, &what);
        let fvt32 = corpus::walk(vol, &g32, ray, Method::Fvt);
        check_invariants(vol, &fvt32, &format!("{what} f32"));
        for m in &METHODS[1..] {
            let cd = corpus::walk(vol, &g64, ray, *m);
            check_invariants(vol, &cd, &format!("{what} {m:?}"));
            assert_eq!(cd.visits, fvt.visits, "{what}: {m:?} differs from FVT");
            let cd32 = corpus::walk(vol, &g32, ray, *m);
            check_invariants(vol, &cd32, &format!("{what} {m:?} f32"));
            assert_eq!(
                cd32.visits, fvt32.visits,
                "{what}: {m:?} f32 differs from FVT f32"
            );
        }
        tally.rays += 1;
        let cells = |w: &Walked| w.visits.iter().map(|v| v.cell).collect::<Vec<_>>();
        let (c64, c32) = (cells(&fvt), cells(&fvt32));
        if c64 != c32 {
            tally.differ_cells += 1;
            tally.missed_cells += c64.iter().filter(|c| !c32.contains(c)).count() as u64;
        }
        if c64.first() != c32.first() {
            tally.differ_first += 1;
        }
    }
}

#[test]
fn named_corpus_matches_the_exact_oracle() {
    let mut tally = F32Tally::default();
    let mut cases = 0;
    for g in corpus::grids(false) {
        let n = g.axes.each_ref().map(|a| a.cells() as u32);
        let rays = corpus::rays(&g.axes);
        for (on, objs) in corpus::objects(n) {
            let vol = MemVolume::new(g.axes.clone(), objs);
            run_case(&vol, &rays, &format!("{} / {on}", g.name), &mut tally);
            cases += rays.len();
        }
    }
    eprintln!("corpus: {cases} rays x 4 methods in f64 and f32; f32 vs f64: {tally:?}");
    assert!(cases > 500, "the corpus shrank to {cases} rays");
}

#[test]
fn thin_slab_at_the_format_maximum() {
    // MAX_SAMPLES_PER_AXIS samples along x (2^20), so indices, the uniform
    // Locate and the step bound are exercised at the limit.
    let g = corpus::grids(true).pop().expect("huge grid");
    assert_eq!(g.axes[0].samples(), MAX_SAMPLES_PER_AXIS);
    let n = g.axes.each_ref().map(|a| a.cells() as u32);
    let (_, objs) = corpus::objects(n).pop().expect("sparse objects");
    let vol = MemVolume::new(g.axes.clone(), objs);
    let rays: Vec<(String, Ray)> = corpus::rays(&g.axes)
        .into_iter()
        .filter(|(name, _)| {
            ["+x", "-x-0", "1e-30", "huge", "min-subnormal", "skew"]
                .iter()
                .any(|d| name.ends_with(&format!("/{d}")))
        })
        .collect();
    let g64 = TGrid::<f64>::new(&vol.axes);
    for (rn, ray) in &rays {
        let fvt = corpus::walk(&vol, &g64, ray, Method::Fvt);
        check_invariants(&vol, &fvt, rn);
        check_exact(&vol, ray, &fvt, rn);
        let cd = corpus::walk(&vol, &g64, ray, Method::Cd { min_leap: 1 });
        check_invariants(&vol, &cd, rn);
        assert_eq!(cd.visits, fvt.visits, "{rn}");
    }
    // Along +x from outside: all five 1-cells, the last in the last cell.
    let along = Ray::new([-5.0, 1.0 - 1e-3, 1.5], [1.0, 0.0, 0.0]).unwrap();
    let w = corpus::walk(&vol, &g64, &along, Method::Cd { min_leap: 1 });
    assert_eq!(w.visits.len(), 5, "{:?}", w.visits);
    assert_eq!(w.visits[4].cell[0], n[0] - 1);
    // Codes are capped at 254, so CD needs about n / 255 leaps here.
    assert!(
        w.steps <= (n[0] / 255 + 64) as u64,
        "CD took {} steps over the slab",
        w.steps
    );
}

#[test]
fn bad_rays_are_refused_and_visit_nothing() {
    for (dir, want) in [
        ([0.0, 0.0, 0.0], "zero"),
        ([-0.0, 0.0, -0.0], "zero"),
        ([1e-200, 0.0, 0.0], "too short"),
        ([f64::NAN, 1.0, 0.0], "not finite"),
        ([f64::INFINITY, 1.0, 0.0], "not finite"),
    ] {
        let e = Ray::new([0.5, 0.5, 0.5], dir).unwrap_err();
        assert!(e.to_string().contains(want), "{e}");
        let vol = MemVolume::new(
            corpus::grids(false).remove(0).axes,
            vec![[0, 0, 0], [4, 4, 4]],
        );
        let g = TGrid::<f64>::new(&vol.axes);
        let ray = Ray {
            origin: [0.5, 0.5, 0.5].into(),
            dir: dir.into(),
        };
        let mut src = &vol;
        let mut n = 0;
        let c = trace(&g, &ray, 0.0, Method::Fvt, &mut src, |_, _| {
            n += 1;
            Flow::Continue
        });
        assert_eq!((n, c.steps), (0, 0), "{dir:?}");
    }
    assert!(matches!(
        Ray::new([f64::NAN, 0.0, 0.0], [1.0, 0.0, 0.0]),
        Err(RayError::NotFinite { what: "origin", .. })
    ));
}

// ---- random grids, objects and rays ----

/// Gaps with spacing ratios up to 1e4 between neighbours and axes.
fn gaps(n: usize) -> impl Strategy<Value = Vec<f64>> {
    let gap = prop_oneof![
        3 => 0.05f64..4.0,
        1 => Just(1e-4),
        1 => Just(1e4),
        1 => Just(1.0),
        1 => 1e-3f64..1e-2,
    ];
    prop_oneof![
        2 => gap.clone().prop_map(move |g| vec![g; n - 1]),
        3 => proptest::collection::vec(gap, n - 1),
    ]
}

fn axis(n: usize) -> impl Strategy<Value = Axis> {
    (
        prop_oneof![3 => -10.0f64..10.0, 1 => Just(1e6), 1 => Just(-1e6), 1 => Just(0.0)],
        gaps(n),
    )
        .prop_map(|(o, g)| {
            let mut c = vec![o];
            for x in g {
                let last = *c.last().expect("non-empty");
                c.push(last + x);
            }
            Axis::from_coords(c).expect("increasing")
        })
}

/// A component: random, zero of either sign, tiny, subnormal or huge.
fn component() -> impl Strategy<Value = f64> {
    prop_oneof![
        8 => -1.0f64..1.0,
        1 => Just(0.0),
        1 => Just(-0.0),
        1 => prop_oneof![Just(1e-30), Just(-1e-30), Just(5e-324), Just(-2.5e-310)],
        1 => prop_oneof![Just(4e180), Just(-7e179)],
    ]
}

/// Origin coordinate along an axis: a sample, inside a cell, or far out.
fn coord(a: &Axis) -> impl Strategy<Value = f64> {
    let c = a.coords().to_vec();
    let (lo, hi) = (c[0], c[c.len() - 1]);
    let span = hi - lo;
    let c2 = c.clone();
    prop_oneof![
        3 => lo - span..hi + span,
        2 => (0..c.len()).prop_map(move |i| c[i]),
        1 => (0..c2.len() - 1, 0.0f64..1.0).prop_map(move |(i, f)| c2[i] + f * (c2[i + 1] - c2[i])),
        1 => Just(lo - 1e9),
    ]
}

fn case() -> impl Strategy<Value = (MemVolume, Vec<Ray>)> {
    (2usize..8, 2usize..8, 2usize..8, 0u32..40)
        .prop_flat_map(|(x, y, z, pct)| {
            (
                [axis(x), axis(y), axis(z)],
                proptest::collection::vec(0u32..100, (x - 1) * (y - 1) * (z - 1)),
                Just(pct),
            )
        })
        .prop_flat_map(|(axes, r, pct)| {
            let n = axes.each_ref().map(|a| a.cells() as u32);
            let objects: Vec<[u32; 3]> = r
                .iter()
                .enumerate()
                .filter(|(_, &v)| v < pct)
                .map(|(i, _)| {
                    let i = i as u32;
                    [i % n[0], i / n[0] % n[1], i / (n[0] * n[1])]
                })
                .collect();
            let origin = [coord(&axes[0]), coord(&axes[1]), coord(&axes[2])];
            let rays =
                proptest::collection::vec((origin, [component(), component(), component()]), 12);
            (Just(MemVolume::new(axes, objects)), rays)
        })
        .prop_map(|(vol, rays)| {
            let rays = rays
                .into_iter()
                .filter_map(|(o, d)| Ray::new(o, d).ok())
                .collect();
            (vol, rays)
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(
        std::env::var("CDVOL_EXTREME_CASES").ok().and_then(|s| s.parse().ok()).unwrap_or(192)
    ))]
    #[test]
    fn random_extremes_match_the_exact_oracle((vol, rays) in case()) {
        let named: Vec<(String, Ray)> = rays.iter().map(|r| (format!("{r:?}"), *r)).collect();
        run_case(&vol, &named, "random", &mut F32Tally::default());
    }
}

#[test]
fn oracle_self_check_on_a_known_ray() {
    // The oracle itself: a ray along the diagonal of a unit grid crosses
    // the diagonal cells with length exactly 1 and grazes the others.
    let vol = MemVolume::new(
        corpus::grids(false).remove(0).axes,
        vec![[1, 1, 1], [2, 1, 1], [3, 3, 3]],
    );
    let ray = Ray::new([0.0, 0.0, 0.0], [1.0, 1.0, 1.0]).unwrap();
    let ex = oracle(&vol, &ray);
    let crossed: Vec<[u32; 3]> = ex.iter().filter(|e| e.crossed()).map(|e| e.cell).collect();
    assert_eq!(crossed, vec![[1, 1, 1], [3, 3, 3]]);
    assert!(ex.iter().all(|e| e.band == 0.0));
    assert_eq!(ex[0].len(), BigRational::from_integer(BigInt::from(1)));
}
