//! Shading normals against analytic ones (issue 15, docs/TRADEOFFS.md
//! "Normals"): rays through a sphere scene ([`super::phantom::spheres`]),
//! the first hit of each (the exact root of the interpolant, so hit error
//! does not mix into normal error), and at the hit the angle between the
//! estimated outward normal and the radial direction of the nearest
//! analytic sphere, for the cell interpolant's gradient and for the smooth
//! gradient ([`crate::render::sample::normals`]).

use glam::DVec3;

use crate::classify::Classification;
use crate::format::reader::PackedVolume;
use crate::render::brick::to_f32;
use crate::render::cache::{Accessor, BrickCache};
use crate::render::sample::hit::{find_hit, HitMethod};
use crate::render::sample::normals::vertex_gradients;
use crate::render::sample::shade::{at, CellEval};
use crate::render::traverse::{trace, Flow, Method, TGrid};
use crate::render::view::camera::Camera;

use super::phantom::Sphere;

/// Angles (degrees) between estimated and analytic normals, one per hit.
#[derive(Debug, Clone, Default)]
pub struct NormalErrors {
    /// The cell interpolant's gradient.
    pub cell: Vec<f64>,
    /// The smooth gradient.
    pub smooth: Vec<f64>,
    /// Hits whose smooth gradient used the one-sided rule at some vertex.
    pub one_sided_hits: u64,
}

/// Mean, median and 95th percentile of `v` (degrees); zeros when empty.
pub fn summary(v: &[f64]) -> [f64; 3] {
    if v.is_empty() {
        return [0.0; 3];
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let q = |f: f64| s[((s.len() - 1) as f64 * f).round() as usize];
    [s.iter().sum::<f64>() / s.len() as f64, q(0.5), q(0.95)]
}

/// Angle in degrees between the outward normal `-grad` and `want`.
fn angle(grad: DVec3, want: DVec3) -> f64 {
    let n = -grad.normalize();
    n.dot(want).clamp(-1.0, 1.0).acos().to_degrees()
}

/// Casts `size x size` orthographic rays for each orbit view `(azimuth,
/// elevation)` over `vol` (classified by iso value) and measures both
/// normals at every hit against `spheres`. `None` when the file is not
/// classified by an iso value.
pub fn sphere_normal_errors(
    vol: &PackedVolume,
    spheres: &[Sphere],
    views: &[[f64; 2]],
    size: u32,
) -> Option<NormalErrors> {
    let h = vol.header();
    let iso = match h.classification {
        Classification::Iso { iso } => to_f32(iso) as f64,
        Classification::TransferFunction { .. } => return None,
    };
    let grid = TGrid::<f64>::new(&h.axes);
    let coords: [&[f64]; 3] = std::array::from_fn(|k| h.axes[k].coords());
    let cache = BrickCache::new(vol, 256 << 20);
    let mut acc = Accessor::new(&cache);
    let mut out = NormalErrors::default();
    for &[az, el] in views {
        let cam = Camera::orbit(grid.bounds(), az, el, None, None, size, size).ok()?;
        for py in 0..size {
            for px in 0..size {
                let ray = cam.ray(px, py);
                let mut found = None;
                trace(&grid, &ray, 0.0, Method::Fvt, &mut acc, |v, acc| {
                    let c = CellEval::new(coords, v.cell, acc.vertices(v.cell));
                    match find_hit(&ray, v, &c, iso, HitMethod::Exact) {
                        Some(t) => {
                            found = Some((t, c, v.cell));
                            Flow::Stop
                        }
                        None => Flow::Continue,
                    }
                });
                let Some((t, c, cell)) = found else {
                    continue;
                };
                let p = at(&ray, t);
                let Some(s) = spheres.iter().min_by(|a, b| {
                    let da = (p - DVec3::from_array(a.center)).length() - a.radius;
                    let db = (p - DVec3::from_array(b.center)).length() - b.radius;
                    da.abs().total_cmp(&db.abs())
                }) else {
                    continue;
                };
                let want = (p - DVec3::from_array(s.center)).normalize();
                let vg = vertex_gradients(&mut acc, coords, cell);
                out.cell.push(angle(c.gradient(p), want));
                out.smooth.push(angle(vg.at(p), want));
                out.one_sided_hits += (vg.one_sided > 0) as u64;
            }
        }
    }
    Some(out)
}

/// Angles (degrees) between the smooth normals of two files of the same
/// samples and iso value (a file with and one without gradient halo) at
/// the first hits of `size x size` orthographic rays per orbit view, and
/// how many hits used a one-sided difference in each. The hits are the
/// same in both files (the same 1-cells and vertex values); `None` when
/// `a` is not classified by an iso value.
pub fn compare_smooth(
    a: &PackedVolume,
    b: &PackedVolume,
    views: &[[f64; 2]],
    size: u32,
) -> Option<(Vec<f64>, [u64; 2])> {
    let h = a.header();
    let iso = match h.classification {
        Classification::Iso { iso } => to_f32(iso) as f64,
        Classification::TransferFunction { .. } => return None,
    };
    let grid = TGrid::<f64>::new(&h.axes);
    let coords: [&[f64]; 3] = std::array::from_fn(|k| h.axes[k].coords());
    let (ca, cb) = (BrickCache::new(a, 256 << 20), BrickCache::new(b, 256 << 20));
    let (mut aa, mut ab) = (Accessor::new(&ca), Accessor::new(&cb));
    let mut out = Vec::new();
    let mut one_sided = [0, 0];
    for &[az, el] in views {
        let cam = Camera::orbit(grid.bounds(), az, el, None, None, size, size).ok()?;
        for py in 0..size {
            for px in 0..size {
                let ray = cam.ray(px, py);
                let mut found = None;
                trace(&grid, &ray, 0.0, Method::Fvt, &mut aa, |v, acc| {
                    let c = CellEval::new(coords, v.cell, acc.vertices(v.cell));
                    match find_hit(&ray, v, &c, iso, HitMethod::Exact) {
                        Some(t) => {
                            found = Some((t, v.cell));
                            Flow::Stop
                        }
                        None => Flow::Continue,
                    }
                });
                let Some((t, cell)) = found else {
                    continue;
                };
                let p = at(&ray, t);
                let (ga, gb) = (
                    vertex_gradients(&mut aa, coords, cell),
                    vertex_gradients(&mut ab, coords, cell),
                );
                one_sided[0] += (ga.one_sided > 0) as u64;
                one_sided[1] += (gb.one_sided > 0) as u64;
                out.push(angle(ga.at(p), -gb.at(p).normalize()));
            }
        }
    }
    Some((out, one_sided))
}

/// Nanoseconds per hit of the cell gradient (with the 8 vertex values
/// read, as the surface mode does) and of the smooth gradient, over the
/// first hits of `size x size` orthographic rays per orbit view, each
/// evaluated `reps` times in a loop (the cache warm): the cost smooth
/// normals add per hit, apart from the noise of whole frames. Returns
/// `(cell ns, smooth ns, hits)`; `None` when `vol` is not classified by an
/// iso value.
pub fn time_gradients(
    vol: &PackedVolume,
    views: &[[f64; 2]],
    size: u32,
    reps: u32,
) -> Option<(f64, f64, usize)> {
    let h = vol.header();
    let iso = match h.classification {
        Classification::Iso { iso } => to_f32(iso) as f64,
        Classification::TransferFunction { .. } => return None,
    };
    let grid = TGrid::<f64>::new(&h.axes);
    let coords: [&[f64]; 3] = std::array::from_fn(|k| h.axes[k].coords());
    let cache = BrickCache::new(vol, 256 << 20);
    let mut acc = Accessor::new(&cache);
    let mut hits = Vec::new();
    for &[az, el] in views {
        let cam = Camera::orbit(grid.bounds(), az, el, None, None, size, size).ok()?;
        for py in 0..size {
            for px in 0..size {
                let ray = cam.ray(px, py);
                trace(&grid, &ray, 0.0, Method::Fvt, &mut acc, |v, acc| {
                    let c = CellEval::new(coords, v.cell, acc.vertices(v.cell));
                    match find_hit(&ray, v, &c, iso, HitMethod::Int) {
                        Some(t) => {
                            hits.push((v.cell, at(&ray, t)));
                            Flow::Stop
                        }
                        None => Flow::Continue,
                    }
                });
            }
        }
    }
    let mut sink = DVec3::ZERO;
    let t0 = std::time::Instant::now();
    for _ in 0..reps {
        for &(cell, p) in &hits {
            sink += CellEval::new(coords, cell, acc.vertices(cell)).gradient(p);
        }
    }
    let cell_ns = t0.elapsed().as_nanos() as f64;
    let t0 = std::time::Instant::now();
    for _ in 0..reps {
        for &(cell, p) in &hits {
            sink += vertex_gradients(&mut acc, coords, cell).at(p);
        }
    }
    let smooth_ns = t0.elapsed().as_nanos() as f64;
    std::hint::black_box(sink);
    let n = (hits.len() as f64 * reps as f64).max(1.0);
    Some((cell_ns / n, smooth_ns / n, hits.len()))
}

#[cfg(test)]
mod tests {
    /// `cell_gradients` (render/sample/normals.rs) equals [`vertex_gradients`]
    /// (in f32) bit for bit on every 1-cell and its 0-cell neighbours of a
    /// rectilinear sphere scene, read from bricks with the gradient plane,
    /// in two passes. Bricks of 8 cells, so most cells touch a brick
    /// face: in the first pass such a cell computes (unless its neighbours
    /// filled its vertices) and fills the plane's outer layer; in the
    /// second every 1-cell reads the plane.
    #[test]
    fn plane_vertex_gradients_are_the_computed_ones() {
        use crate::format::reader::PackedVolume;
        use crate::input::raw::RawSource;
        use crate::prep::{prep, PrepOptions};
        use crate::progress::NoProgress;
        use crate::render::brick::Planes;
        use crate::render::cache::{Accessor, BrickCache};
        use crate::render::sample::normals::{cell_gradients, vertex_gradients};
        use crate::tools::phantom;
        let dir = tempfile::tempdir().unwrap();
        let side = dir.path().join("s.json");
        let so = phantom::SpheresOptions {
            size: 40,
            per_axis: 3,
            seed: 7,
            spacing: phantom::parse_spacing3("1,0.6:1.7,0.5:2").unwrap(),
        };
        let info = phantom::spheres(&side, &so, &NoProgress).unwrap();
        // The spheres' iso, then 0: every u16 sample is >= 0, so every cell,
        // those at the volume's border included, is a 1-cell, and the
        // one-sided rule at the border is compared too.
        for (scene, iso) in [info.iso, 0.0].into_iter().enumerate() {
            let packed = dir.path().join(format!("s{scene}.cdv"));
            let mut po = PrepOptions::new(crate::classify::Classification::Iso { iso });
            po.brick_size = 8;
            prep(&RawSource::open(&side).unwrap(), &packed, &po, &NoProgress).unwrap();
            let vol = PackedVolume::open(&packed).unwrap();
            let h = vol.header();
            let coords: [&[f64]; 3] = std::array::from_fn(|k| h.axes[k].coords());
            let n: [u32; 3] = std::array::from_fn(|k| coords[k].len() as u32 - 1);
            let plain = BrickCache::new(&vol, 64 << 20);
            let with_plane = BrickCache::with_planes(
                &vol,
                64 << 20,
                Planes {
                    grads: true,
                    ..Planes::FILE
                },
            );
            let mut acc = Accessor::new(&plain);
            let mut pacc = Accessor::new(&with_plane);
            let (mut checked, mut from_plane, mut at_faces) = ([0; 2], [0; 2], [0; 2]);
            let mut at_border = 0;
            for pass in 0..2 {
                for z in 0..n[2] {
                    for y in 0..n[1] {
                        for x in 0..n[0] {
                            let c = [x, y, z];
                            let (b, l) = pacc.brick(c);
                            if !matches!(b.code(l), 0 | crate::render::traverse::OBJECT) {
                                continue;
                            }
                            let inner = (0..3).all(|k| l[k] >= 1 && l[k] + 2 <= b.cells[k]);
                            assert_eq!(b.grads.is_empty(), b.values.is_empty(), "brick of {c:?}");
                            let set = b.grads.cell_set(b.cell_index(l));
                            let object = b.code(l) == crate::render::traverse::OBJECT;
                            if pass == 1 && object {
                                assert_eq!(set, !b.grads.is_empty(), "cell {c:?} not filled");
                            }
                            let border = (0..3).any(|k| c[k] == 0 || c[k] + 1 == n[k]);
                            at_border += usize::from(object && border && pass == 1);
                            from_plane[pass] += usize::from(set);
                            at_faces[pass] += usize::from(set && !inner);
                            let want = vertex_gradients(&mut acc, coords, c).g.map(|g| g.as_vec3());
                            let got = cell_gradients(&mut pacc, coords, c);
                            for v in 0..8 {
                                let same = want[v]
                                    .to_array()
                                    .iter()
                                    .zip(got[v].to_array())
                                    .all(|(a, b)| a.to_bits() == b.to_bits());
                                assert!(
                                    same,
                                    "cell {c:?} vertex {v}: {:?} vs {:?}",
                                    want[v], got[v]
                                );
                            }
                            checked[pass] += 1;
                        }
                    }
                }
            }
            // Both paths were taken, many times: in the second pass the outer
            // layer filled in the first answers many more cells.
            assert!(checked[0] > 1000, "{checked:?} cells");
            assert!(
                from_plane[0] > 100 && from_plane[0] < checked[0],
                "{from_plane:?} of {checked:?} from the plane"
            );
            assert!(
                at_faces[1] > at_faces[0] + 1000,
                "{at_faces:?} at faces from the plane"
            );
            // The second scene's 1-cells reach the volume's border.
            assert_eq!(
                at_border > 0,
                scene == 1,
                "{at_border} 1-cells at the border"
            );
            assert!(pacc.error.is_none());
        }
    }
}
