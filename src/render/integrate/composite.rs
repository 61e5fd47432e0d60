//! Composite mode: front-to-back compositing of a transfer function
//! (tabulated for the step by lut.rs) at samples `t = k * step_mm` along
//! the ray, stopping once the ray is 99% opaque. Cells the ray only clips
//! between two samples are not read.

use super::{Ctx, Px};
use crate::render::cache::Accessor;
use crate::render::lut::TfLut;
use crate::render::shade::AlongRay;
use crate::render::traverse::{trace, Flow, Ray, Real, StepCounts};

/// Composites `ray` into `px.rgb`; `px.hit` when anything is opaque.
pub(super) fn composite<T: Real>(
    ctx: &Ctx<T>,
    ray: &Ray,
    acc: &mut Accessor,
    lut: &TfLut,
    step: f64,
    px: &mut Px,
) -> StepCounts {
    let coords = ctx.coords;
    let inv_step = 1.0 / step;
    let mut col = [0.0f64; 3];
    let mut alpha = 0.0f64;
    let counts = trace(ctx.grid, ray, 0.0, ctx.opts.method, acc, |v, acc| {
        // Samples at t = k * step inside [t_enter, t_exit); a cell the ray
        // only clips between two samples is not read.
        let mut k = first_sample(v.t_enter, step, inv_step);
        if !(k * step < v.t_exit) {
            return Flow::Continue;
        }
        let c = AlongRay::new(coords, v.cell, acc.vertices(v.cell), ray);
        while k * step < v.t_exit {
            let val = c.value(k * step);
            let [r, gr, b, a] = lut.sample(val);
            k += 1.0;
            if a == 0.0 {
                // Transparent: adds nothing.
                continue;
            }
            let w = 1.0 - alpha;
            col[0] += w * r;
            col[1] += w * gr;
            col[2] += w * b;
            alpha += w * a;
            if alpha > 0.99 {
                return Flow::Stop;
            }
        }
        Flow::Continue
    });
    px.hit = alpha > 0.0;
    px.rgb = col.map(|x| x as f32);
    counts
}

/// `ceil(t / step)`, the first composite sample at or after `t`, with a
/// multiplication by `inv_step = 1 / step` instead of the division where
/// that cannot change the result: the two quotients differ by a few ulps,
/// so only when `t / step` is within 1e-12 (relative) of an integer does
/// the division decide.
#[inline]
fn first_sample(t: f64, step: f64, inv_step: f64) -> f64 {
    let q = t * inv_step;
    let k = ceil(q);
    // Distance to the nearest integer (no libm `round`).
    if (k - q).min(q - (k - 1.0)) <= 1e-12 * q.abs().max(1.0) {
        ceil(t / step)
    } else {
        k
    }
}

/// `x.ceil()` without a libm call (the default x86-64 target has no
/// rounding instruction); the same value for every `x`.
#[inline]
fn ceil(x: f64) -> f64 {
    const BIG: f64 = (1u64 << 52) as f64;
    if x.abs() < BIG {
        // |x| < 2^52: truncation is exact in i64, and so is adding 1.
        let t = x as i64 as f64;
        if t < x {
            t + 1.0
        } else {
            t
        }
    } else {
        // Already an integer, infinite or NaN.
        x
    }
}

#[cfg(test)]
mod tests {
    use super::{ceil, first_sample};

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
}
