//! Tests of refine.rs.
use super::{ceil, cell_near, first_sample, part, Ramps};
use crate::classify::{TfPoint, TransferFunction};
use crate::render::sample::lut::exact_sample;
use crate::render::traverse::Ray;
use glam::DVec3;

/// A ramp's top is the end of the segment holding the onset's value
/// towards which the opacity rises, either way, when its opacity is
/// not faint; none on a flat segment or outside the points.
#[test]
fn ramp_tops() {
    let p = |value: f64, opacity: f64| TfPoint {
        value,
        opacity,
        color: [1.0; 3],
    };
    let tf = TransferFunction {
        points: vec![
            p(-1000.0, 0.0),
            p(-167.0, 0.0),
            p(-160.0, 1.0),
            p(240.0, 1.0),
            p(300.0, 0.3),
            p(400.0, 0.01),
            p(500.0, 0.0),
        ],
    };
    let step = 0.5;
    let r = Ramps::new(&tf, step);
    assert!((r.faint() - (1.0 - 0.875f64.sqrt())).abs() < 1e-12);
    let need = |v: f64| (1.0 - 1e-3) * exact_sample(&tf, step, v).1;
    assert_eq!(r.top(-165.0), Some(need(-160.0)));
    assert_eq!(r.top(0.0), None, "flat");
    assert_eq!(r.top(260.0), Some(need(240.0)), "falling: the lower end");
    assert_eq!(r.top(350.0), Some(need(300.0)));
    assert_eq!(r.top(450.0), None, "a faint top");
    assert_eq!(r.top(-2000.0), None);
    assert_eq!(r.top(600.0), None);
}

/// A partial sample's opacity is that of its fraction of a step, its
/// colour in proportion; a whole step is the sample itself.
#[test]
fn partial_samples() {
    let s = [0.3, 0.15, 0.0, 0.75];
    assert_eq!(part(s, 1.0), s);
    let h = part(s, 0.5);
    assert!((h[3] - 0.5).abs() < 1e-12, "1 - 0.25^0.5");
    assert!((h[0] - 0.2).abs() < 1e-12 && (h[1] - 0.1).abs() < 1e-12);
    assert_eq!(part([0.0; 4], 0.3), [0.0; 4]);
    assert_eq!(part([0.0, 0.0, 0.0, 1.0], 0.25)[3], 1.0);
}

#[test]
fn ceil_and_first_sample_match_the_division() {
    for x in [
        0.0,
        -0.0,
        0.5,
        -0.5,
        1.0,
        -1.0,
        2.5,
        -2.5,
        1e15,
        4503599627370495.5,
        1e300,
    ] {
        assert_eq!(ceil(x), x.ceil(), "{x}");
    }
    assert!(ceil(f64::NAN).is_nan());
    assert_eq!(ceil(f64::INFINITY), f64::INFINITY);
    // Entry points on, next to and between sample positions.
    for step in [0.5, 0.3, 0.7, 1.3, 1e-4, 0.1] {
        let inv = 1.0 / step;
        for i in 0..20_000 {
            let k = i as f64;
            for t in [
                k * step,
                (k * step).next_up(),
                (k * step).next_down(),
                (k + 0.5) * step,
            ] {
                assert_eq!(
                    first_sample(t, step, inv),
                    (t / step).ceil(),
                    "{t} / {step}"
                );
            }
        }
    }
}

/// `cell_near` assigns a position the cell whose planes the marcher
/// has crossed, from any starting cell, both ways along each axis,
/// and nothing outside the volume.
#[test]
fn cell_near_finds_the_marchers_cell() {
    let x: Vec<f64> = vec![0.0, 1.0, 1.5, 3.0, 4.0];
    let y: Vec<f64> = vec![-2.0, 0.0, 2.0];
    let z: Vec<f64> = vec![0.0, 0.5, 1.0, 1.5];
    let coords = [&x[..], &y[..], &z[..]];
    for dir in [DVec3::new(1.0, 0.2, 0.3), DVec3::new(-0.7, 0.1, -0.2)] {
        let origin = DVec3::new(2.0, -1.0, 0.75) - 10.0 * dir;
        let ray = Ray { origin, dir };
        for i in 0..=400 {
            let t = i as f64 * 0.05;
            // The oracle: per axis the cell whose span [enter, exit)
            // in t holds t.
            let want: Option<[u32; 3]> = (|| {
                let mut c = [0u32; 3];
                for a in 0..3 {
                    let s = coords[a];
                    let span = |j: usize| {
                        let (u, v) = ((s[j] - origin[a]) / dir[a], (s[j + 1] - origin[a]) / dir[a]);
                        (u.min(v), u.max(v))
                    };
                    c[a] = (0..s.len() - 1).find(|&j| {
                        let (e, x) = span(j);
                        e <= t && t < x
                    })? as u32;
                }
                Some(c)
            })();
            for from in [[0, 0, 0], [3, 1, 2], [1, 0, 1]] {
                assert_eq!(
                    cell_near(coords, &ray, from, t),
                    want,
                    "t {t} from {from:?}"
                );
            }
        }
    }
}
