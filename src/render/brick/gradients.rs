//! The gradient plane of a decoded brick: each sample's three-point
//! derivative (the rectilinear rule of [`crate::render::sample::normals`]),
//! computed once at decode for the samples whose neighbours all lie in the
//! brick. The same rule serves the render-time normals
//! ([`three_point`]), so a gradient read from the plane equals the one
//! computed at a hit.

use glam::{DVec3, Vec3};

/// Per sample of a brick, its vertex gradient as [`vertex_gradients`](crate::render::sample::normals::vertex_gradients)
/// computes it, in f32: the shaded composite's gradient plane
/// ([`Planes::grads`](crate::render::brick::Planes::grads)), built once when the
/// brick is decoded. `values` are the brick's samples (`cells + 1` per
/// axis, x fastest), `first` its first sample's global index.
///
/// Only samples strictly inside the brick's samples get a gradient (NaN on
/// the outer layer): their 6 neighbours are in this brick, which
/// [`vertex_gradients`](crate::render::sample::normals::vertex_gradients) reads them from whichever of their cells asks, and
/// the gaps and weights along each axis are the sample's own, so the
/// gradient is a function of the sample alone. A sample on the outer
/// layer has neighbours in other bricks; the plane ([`GradPlane`]) takes
/// its gradient when a 1-cell first computes it ([`outer_cell_gradients`](crate::render::sample::normals::outer_cell_gradients)).
///
/// [`GradPlane`]: crate::render::brick::GradPlane
pub(crate) fn brick_gradients(
    values: &[f32],
    first: [u32; 3],
    cells: [u32; 3],
    coords: [&[f64]; 3],
) -> Vec<Vec3> {
    let s = cells.map(|c| c as usize + 1);
    let mut out = vec![Vec3::NAN; values.len()];
    if s.iter().any(|&k| k < 3) {
        return out;
    }
    // Per axis and inner local sample: the inverse gaps before and after
    // and the weight `h- / (h- + h+)`, the same expressions as
    // [`vertex_gradients`](crate::render::sample::normals::vertex_gradients)' per-cell ones.
    let axis: [Vec<([f64; 2], f64)>; 3] = std::array::from_fn(|k| {
        let x = coords[k];
        (0..s[k])
            .map(|ls| {
                let g = first[k] as usize + ls;
                if ls == 0 || ls + 1 == s[k] {
                    return ([f64::NAN; 2], f64::NAN);
                }
                let (hm, hp) = (x[g] - x[g - 1], x[g + 1] - x[g]);
                ([1.0 / hm, 1.0 / hp], hm / (hm + hp))
            })
            .collect()
    });
    let stride = [1, s[0], s[0] * s[1]];
    for z in 1..s[2] - 1 {
        for y in 1..s[1] - 1 {
            let row = (z * s[1] + y) * s[0];
            for x in 1..s[0] - 1 {
                let i = row + x;
                let at = [x, y, z];
                let f0 = values[i] as f64;
                out[i] = DVec3::from_array(std::array::from_fn(|k| {
                    let fm = values[i - stride[k]] as f64;
                    let fp = values[i + stride[k]] as f64;
                    let (inv, lam) = axis[k][at[k]];
                    three_point(f0, fm, fp, inv, lam).0
                }))
                .as_vec3();
            }
        }
    }
    out
}

/// The derivative at a sample `f0` from its neighbours `fm` before and
/// `fp` after (module docs: three-point rule, one-sided where a neighbour
/// is NaN), and whether it was one-sided; `inv` the inverse gaps before
/// and after, `lam` the weight `h- / (h- + h+)`
/// (module docs). The one rule of [`vertex_gradients`](crate::render::sample::normals::vertex_gradients) and
/// [`brick_gradients`].
#[inline(always)]
pub(crate) fn three_point(f0: f64, fm: f64, fp: f64, inv: [f64; 2], lam: f64) -> (f64, bool) {
    // Slopes before and after the vertex (NaN where missing).
    let sm = (f0 - fm) * inv[0];
    let sp = (fp - f0) * inv[1];
    match (sm.is_nan(), sp.is_nan()) {
        (false, false) => (sm + lam * (sp - sm), false),
        (true, false) => (sp, true),
        (false, true) => (sm, true),
        (true, true) => (f64::NAN, false),
    }
}
