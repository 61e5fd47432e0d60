//! Image-space culling: the pixels whose rays can meet no 1-cell, found
//! from the brick index before any ray is cast, so their rays are never
//! traced and the bricks they would have crossed are never read.
//!
//! Every integrator but the cost map draws a pixel from the 1-cells its ray
//! visits (paper section 4: the traversal only decides which cells), and a
//! ray that visits none is drawn as a miss: no hit, no sample, no maximum.
//! A 1-cell lies inside a brick the index does not mark as holding no
//! 1-cell (for a narrowed scene, render/brick/envelope.rs, also one whose index
//! value maximum reaches the scene's iso value). So a pixel whose ray
//! passes through none of those bricks' boxes is a miss, whatever the
//! traversal, and the culled image is the traced one byte for byte
//! (tests/all/cull.rs checks it against tracing every ray).
//!
//! The test is conservative: each such brick's box (its cells' extent in
//! mm, rectilinear spacing included) is projected through the camera and
//! the bounding rectangle of its 8 projected corners, widened by a margin
//! of one pixel, is marked in a bitmap of the image. A pixel outside every
//! rectangle is culled. The cost map ([`Mode::Cost`]) traces every ray: it
//! shows what the traversal costs.
//!
//! Later frames on one cache (turntables, `cdvol serve`) know more than
//! the index: when such a cache ([`BrickCache::with_occupancy`]) first
//! decodes a brick, it notes which of the brick's [`SUB`]^3 sub-blocks (4
//! cells per edge on 32-cell bricks) hold a 1-cell of the scene
//! ([`BrickCache::occupied`]), and later covers project each run along x
//! of such sub-blocks instead of the whole brick. A 1-cell lies in its
//! sub-block's box, so the argument above holds box for box. A brick no
//! frame has decoded yet is projected whole. The bricks earlier frames
//! decoded are those their rays entered, whatever the threads and the
//! cache budget (an evicted brick keeps its mask), so a frame's cover,
//! like its image, does not depend on them. On the real CT at 1024^2 a
//! later frame traces about 110,000 fewer of the 350,000 rays the brick
//! boxes leave, most of those that pass the skull without meeting it
//! (docs/BENCHMARKS.md, "Later frames cull by sub-blocks").

use glam::DVec3;

use super::camera::{Camera, Projection};
use crate::format::reader::PackedVolume;
use crate::render::brick::SUB;
use crate::render::cache::BrickCache;
use crate::render::options::{Mode, RenderOptions};

/// The pixels whose rays may meet a 1-cell: one bit a pixel, row by row;
/// and per square of [`NEAR_PX`] pixels, where along those rays the first
/// 1-cell can begin at the earliest.
pub(crate) struct Cover {
    width: u32,
    /// `u64` words per row.
    stride: usize,
    bits: Vec<u64>,
    /// Squares per row of `near`.
    near_w: usize,
    /// Per square of [`NEAR_PX`]^2 pixels, row by row: the smallest
    /// [`Projector::rect`] lower bound on the ray parameter `t` of the
    /// boxes whose rectangles meet the square (`+inf` where none does).
    /// No 1-cell a ray of the square visits begins before it, so the ray
    /// can be traced from there ([`Cover::start`]).
    near: Vec<f64>,
}

/// The edge in pixels of the squares [`Cover`] keeps a start per: a
/// rectangle's bound is written once per square it meets rather than
/// once per pixel.
const NEAR_PX: u32 = 4;

impl Cover {
    /// The cover of `vol`'s object bricks seen by `camera` (of the
    /// sub-blocks `cache` knows, [`BrickCache::occupied`]), or `None` when
    /// every ray is to be traced: culling off, the cost map, or a camera
    /// inside or behind some object brick (perspective only), where the
    /// projection of its box is unbounded.
    pub(crate) fn of(
        vol: &PackedVolume,
        cache: &BrickCache,
        camera: &Camera,
        opts: &RenderOptions,
    ) -> Option<Cover> {
        if !opts.cull || matches!(opts.mode, Mode::Cost) {
            return None;
        }
        let h = vol.header();
        let narrow = crate::render::options::narrowing(h, opts);
        let (w, hh) = (camera.width, camera.height);
        let stride = (w as usize).div_ceil(64);
        let near_w = w.div_ceil(NEAR_PX) as usize;
        let mut cover = Cover {
            width: w,
            stride,
            bits: vec![0; stride * hh as usize],
            near_w,
            near: vec![f64::INFINITY; near_w * hh.div_ceil(NEAR_PX) as usize],
        };
        let coords = [h.axes[0].coords(), h.axes[1].coords(), h.axes[2].coords()];
        let proj = Projector::new(camera);
        for (id, e) in vol.index().iter().enumerate() {
            if e.has_no_object() {
                continue;
            }
            if let (Some(iso), Some(m)) = (narrow, e.value_max()) {
                // As render/brick/envelope.rs judges a brick: no scene 1-cell.
                if crate::render::brick::to_f32(m) < iso {
                    continue;
                }
            }
            let b = h.brick_coords(id as u64);
            let range: [(u64, u64); 3] = std::array::from_fn(|k| h.brick_cells(k, b[k]));
            let lo = DVec3::from_array(std::array::from_fn(|k| coords[k][range[k].0 as usize]));
            let hi = DVec3::from_array(std::array::from_fn(|k| coords[k][range[k].1 as usize]));
            // A brick the clip keeps nothing of is never read: no ray
            // starts for it.
            if !opts.clip.keeps_box(lo, hi) {
                continue;
            }
            let Some(mask) = cache.occupied(id as u64) else {
                cover.fill(proj.rect(lo, hi)?);
                continue;
            };
            // Each run along x of sub-blocks with a 1-cell: its cells' box.
            let e = h.brick_size.div_ceil(SUB) as u64;
            let at = |k: usize, s: u64| coords[k][(range[k].0 + s * e).min(range[k].1) as usize];
            let n = SUB as u64;
            for z in 0..n {
                for y in 0..n {
                    let bit = |x: u64| {
                        let i = ((z * n + y) * n + x) as usize;
                        mask[i / 64] >> (i % 64) & 1 == 1
                    };
                    let mut x = 0;
                    while x < n {
                        if !bit(x) {
                            x += 1;
                            continue;
                        }
                        let x0 = x;
                        while x < n && bit(x) {
                            x += 1;
                        }
                        let lo = DVec3::new(at(0, x0), at(1, y), at(2, z));
                        let hi = DVec3::new(at(0, x), at(1, y + 1), at(2, z + 1));
                        cover.fill(proj.rect(lo, hi)?);
                    }
                }
            }
        }
        Some(cover)
    }

    /// Whether pixel `(x, y)`'s ray may meet a 1-cell.
    #[inline]
    pub(crate) fn covered(&self, x: u32, y: u32) -> bool {
        let i = y as usize * self.stride + (x / 64) as usize;
        self.bits[i] >> (x % 64) & 1 == 1
    }

    /// Where pixel `(x, y)`'s ray (covered) can be traced from: a `t` at
    /// or before the start of every 1-cell it can meet, at least 0. The
    /// cells before it are 0-cells, so every exact traversal visits the
    /// same 1-cells with the same `t` from there as from 0 (module
    /// traverse), and the image is the same; only the leaps up to it are
    /// saved.
    #[inline]
    pub(crate) fn start(&self, x: u32, y: u32) -> f64 {
        let i = (y / NEAR_PX) as usize * self.near_w + (x / NEAR_PX) as usize;
        // A covered pixel's square has a bound (the rectangle that covered
        // the pixel lowered it); 0 for one without, should one be asked.
        let t = self.near[i];
        if t.is_finite() {
            t.max(0.0)
        } else {
            0.0
        }
    }

    /// Whether some pixel of the `w` x `h` rectangle at `(x0, y0)` (inside
    /// the image) is covered: a tile none of whose pixels is covered is a
    /// miss as a whole.
    pub(crate) fn any_in(&self, x0: u32, y0: u32, w: u32, h: u32) -> bool {
        if w == 0 {
            return false;
        }
        let (w0, w1, first, last) = row_words(x0, x0 + w - 1);
        (y0..y0 + h).any(|y| {
            let row = &self.bits[y as usize * self.stride..][..self.stride];
            match w0 == w1 {
                true => row[w0] & first & last != 0,
                false => {
                    row[w0] & first != 0
                        || row[w0 + 1..w1].iter().any(|&x| x != 0)
                        || row[w1] & last != 0
                }
            }
        })
    }

    /// Pixels covered.
    #[cfg(test)]
    fn count(&self) -> u64 {
        self.bits.iter().map(|w| w.count_ones() as u64).sum()
    }

    /// Marks the pixels of `r` (inclusive, already clipped to the image)
    /// and lowers the start of the squares it meets to its bound.
    fn fill(&mut self, r: Option<([u32; 4], f64)>) {
        let Some(([x0, y0, x1, y1], near)) = r else {
            return;
        };
        debug_assert!(x1 < self.width);
        for sy in y0 / NEAR_PX..=y1 / NEAR_PX {
            let row = &mut self.near[sy as usize * self.near_w..][..self.near_w];
            for t in &mut row[(x0 / NEAR_PX) as usize..=(x1 / NEAR_PX) as usize] {
                *t = t.min(near);
            }
        }
        let (w0, w1, first, last) = row_words(x0, x1);
        for y in y0..=y1 {
            let row = &mut self.bits[y as usize * self.stride..][..self.stride];
            if w0 == w1 {
                row[w0] |= first & last;
            } else {
                row[w0] |= first;
                for word in &mut row[w0 + 1..w1] {
                    *word = !0;
                }
                row[w1] |= last;
            }
        }
    }
}

/// The words of a row that hold pixels `x0..=x1`, and the masks of those
/// pixels in the first and the last of them.
fn row_words(x0: u32, x1: u32) -> (usize, usize, u64, u64) {
    let (w0, w1) = ((x0 / 64) as usize, (x1 / 64) as usize);
    (w0, w1, !0u64 << (x0 % 64), !0u64 >> (63 - x1 % 64))
}

/// A point's pixel position under a camera: the inverse of
/// [`Camera::ray`], `px = (sx + 1) w / 2 - 1/2` from the screen
/// coordinate `sx` the ray of pixel `px` is cast at.
struct Projector {
    eye: DVec3,
    forward: DVec3,
    right: DVec3,
    up: DVec3,
    /// [`Camera::half_extents`].
    half_w: f64,
    half_h: f64,
    persp: bool,
    w: f64,
    h: f64,
}

impl Projector {
    fn new(c: &Camera) -> Projector {
        let (half_w, half_h) = c.half_extents();
        Projector {
            eye: c.eye,
            forward: c.forward,
            right: c.right,
            up: c.up,
            half_w,
            half_h,
            persp: matches!(c.projection, Projection::Persp { .. }),
            w: c.width as f64,
            h: c.height as f64,
        }
    }

    /// The pixel rectangle `[x0, y0, x1, y1]` (inclusive, clipped) that
    /// holds the projection of the box `[lo, hi]`, widened by the margin,
    /// and a lower bound on the `t` at which a ray of [`Camera::ray`]
    /// meets a point of the box; `Some(None)` when it lies outside the
    /// image, `None` when it cannot be bounded (perspective: a corner at
    /// or behind the eye plane).
    ///
    /// The bound: a ray's point `p = o + t d` has `t = (p - eye) . d`
    /// for an orthographic ray (`d` the unit forward vector, `o - eye`
    /// across it) and `t = |p - eye| >= (p - eye) . forward` for a
    /// perspective one (`o` the eye, `d` a unit vector). Either way `t`
    /// is at least `(p - eye) . forward`, linear in `p`, so at least its
    /// smallest value at the box's corners. Less a margin for the
    /// rounding of the rays' and the traversal's arithmetic (about 1e-15
    /// of the distance; here 1e-9 of it).
    fn rect(&self, lo: DVec3, hi: DVec3) -> Option<Option<([u32; 4], f64)>> {
        let (mut x0, mut y0) = (f64::INFINITY, f64::INFINITY);
        let (mut x1, mut y1) = (f64::NEG_INFINITY, f64::NEG_INFINITY);
        let mut far = 0.0f64;
        let mut near = f64::INFINITY;
        for i in 0..8 {
            let p = DVec3::new(
                if i & 1 == 0 { lo.x } else { hi.x },
                if i & 2 == 0 { lo.y } else { hi.y },
                if i & 4 == 0 { lo.z } else { hi.z },
            );
            let d = p - self.eye;
            far = far.max(d.length());
            near = near.min(d.dot(self.forward));
            let (mut sx, mut sy) = (d.dot(self.right), d.dot(self.up));
            if self.persp {
                let z = d.dot(self.forward);
                if !(z > 1e-9 * d.length()) {
                    return None;
                }
                sx /= z;
                sy /= z;
            }
            let px = (sx / self.half_w + 1.0) * 0.5 * self.w - 0.5;
            let py = (1.0 - sy / self.half_h) * 0.5 * self.h - 0.5;
            if !(px.is_finite() && py.is_finite()) {
                return None;
            }
            x0 = x0.min(px);
            x1 = x1.max(px);
            y0 = y0.min(py);
            y1 = y1.max(py);
        }
        // One pixel, plus the rounding of the rays' own arithmetic: about
        // 1e-15 of the distance, in pixels here 1e-9 of it.
        let pixel = if self.persp {
            2.0 * self.half_h / self.h * far
        } else {
            2.0 * self.half_h / self.h
        };
        let m = 1.0 + 1e-9 * far / pixel;
        let (x0, y0) = ((x0 - m).floor().max(0.0), (y0 - m).floor().max(0.0));
        let (x1, y1) = (
            (x1 + m).ceil().min(self.w - 1.0),
            (y1 + m).ceil().min(self.h - 1.0),
        );
        if !(x0 <= x1 && y0 <= y1) {
            return Some(None);
        }
        let near = near - 1e-9 * far;
        if !near.is_finite() {
            return None;
        }
        Some(Some(([x0 as u32, y0 as u32, x1 as u32, y1 as u32], near)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bare(width: u32, height: u32) -> Cover {
        let stride = (width as usize).div_ceil(64);
        let near_w = width.div_ceil(NEAR_PX) as usize;
        Cover {
            width,
            stride,
            bits: vec![0; stride * height as usize],
            near_w,
            near: vec![f64::INFINITY; near_w * height.div_ceil(NEAR_PX) as usize],
        }
    }

    /// Rectangles filled word by word mark exactly their pixels, at every
    /// position against the 64-pixel words.
    #[test]
    fn fill_marks_exactly_the_rectangle() {
        let (w, h) = (150u32, 5u32);
        for x0 in [0u32, 1, 63, 64, 65, 127, 128, 149] {
            for x1 in [x0, x0 + 1, 63, 64, 100, 127, 128, 149] {
                if x1 < x0 || x1 >= w {
                    continue;
                }
                let mut c = bare(w, h);
                c.fill(Some(([x0, 1, x1, 3], 0.0)));
                for y in 0..h {
                    for x in 0..w {
                        let want = (1..=3).contains(&y) && (x0..=x1).contains(&x);
                        assert_eq!(c.covered(x, y), want, "{x0}..={x1}: ({x}, {y})");
                    }
                }
                assert_eq!(c.count(), 3 * (x1 - x0 + 1) as u64);
                // Every rectangle: covered somewhere exactly when it
                // meets the filled one.
                for (rx0, rw) in [
                    (0u32, 1u32),
                    (0, 150),
                    (x0, 1),
                    (x1, 1),
                    (63, 2),
                    (64, 64),
                    (x1 + 1, 149 - x1),
                ] {
                    for (ry0, rh) in [(0u32, 1u32), (0, 5), (1, 1), (3, 2), (4, 1)] {
                        let want =
                            (rw > 0 && rx0 <= x1 && x0 < rx0 + rw) && (ry0 <= 3 && 1 < ry0 + rh);
                        let brute =
                            (ry0..ry0 + rh).any(|y| (rx0..rx0 + rw).any(|x| c.covered(x, y)));
                        assert_eq!(
                            c.any_in(rx0, ry0, rw, rh),
                            want,
                            "{x0}..={x1}: {rx0}+{rw}, {ry0}+{rh}"
                        );
                        assert_eq!(brute, want);
                    }
                }
            }
        }
    }

    /// The projection inverts `Camera::ray`: a point on pixel (x, y)'s ray
    /// projects into that pixel, orthographic and perspective.
    #[test]
    fn projection_inverts_the_rays() {
        let cams = [
            Camera::look_at(
                [300.0, -80.0, 120.0],
                [50.0, 40.0, 30.0],
                [0.0, 0.0, 1.0],
                Projection::Ortho { frame_mm: 180.0 },
                97,
                61,
            )
            .unwrap(),
            Camera::look_at(
                [300.0, -80.0, 120.0],
                [50.0, 40.0, 30.0],
                [0.0, 0.0, 1.0],
                Projection::Persp { fov_deg: 40.0 },
                97,
                61,
            )
            .unwrap(),
        ];
        for cam in cams {
            let p = Projector::new(&cam);
            for (x, y) in [(0, 0), (96, 60), (13, 47), (50, 30)] {
                let r = cam.ray(x, y);
                for t in [1.0, 200.0, 350.0] {
                    let q = r.origin + t * r.dir;
                    let (rect, near) = p.rect(q, q).unwrap().unwrap();
                    // The point's own `t` is at or after the bound.
                    assert!(near <= t, "{:?} {near} > {t}", cam.projection);
                    assert!(
                        rect[0] <= x && x <= rect[2],
                        "{:?} {x} {rect:?}",
                        cam.projection
                    );
                    assert!(
                        rect[1] <= y && y <= rect[3],
                        "{:?} {y} {rect:?}",
                        cam.projection
                    );
                    // A point is widened by the margin only: at most 2
                    // pixels a side once rounded out.
                    assert!(rect[2] - rect[0] <= 4 && rect[3] - rect[1] <= 4, "{rect:?}");
                }
            }
        }
    }

    /// The near bound of [`Projector::rect`] against the oracle: for
    /// random boxes, cameras (orthographic and perspective) and pixels of
    /// the rectangle, where the pixel's ray enters the box by the slab
    /// test is at or after the bound; and the bound is not loose by more
    /// than the box's diagonal for a ray through the box's middle.
    #[test]
    fn the_near_bound_is_at_or_before_every_entry() {
        use proptest::prelude::*;
        let cfg = ProptestConfig {
            cases: 256,
            ..ProptestConfig::default()
        };
        let met_box = std::cell::Cell::new(0u32);
        proptest!(cfg, |(
            lo in prop::array::uniform3(-50.0f64..50.0),
            size in prop::array::uniform3(0.01f64..40.0),
            eye in prop::array::uniform3(-400.0f64..400.0),
            fov in prop_oneof![Just(None), (10.0f64..120.0).prop_map(Some)],
            zoom in 0.3f64..3.0,
            aim in prop::array::uniform3(-0.5f64..0.5),
            (w, h) in (1u32..48, 1u32..48),
        )| {
            let (lo, hi) = (DVec3::from_array(lo), DVec3::from_array(lo) + DVec3::from_array(size));
            // Looking at a point near the box, which fills about `1 / zoom`
            // of the frame.
            let target = 0.5 * (lo + hi) + DVec3::from_array(aim) * (hi - lo);
            let projection = match fov {
                None => Projection::Ortho { frame_mm: zoom * (hi - lo).length() },
                Some(f) => Projection::Persp { fov_deg: f },
            };
            let Ok(cam) =
                Camera::look_at(eye, target.to_array(), [0.1, 0.2, 1.0], projection, w, h)
            else {
                return Ok(());
            };
            let p = Projector::new(&cam);
            let Some(Some(([x0, y0, x1, y1], near))) = p.rect(lo, hi) else {
                return Ok(());
            };
            let mut met = false;
            for y in y0..=y1 {
                for x in x0..=x1 {
                    let r = cam.ray(x, y);
                    // The slab test: the ray's interval inside the box.
                    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
                    for k in 0..3 {
                        let (o, d) = (r.origin[k], r.dir[k]);
                        if d == 0.0 {
                            if o < lo[k] || o > hi[k] {
                                t0 = f64::INFINITY;
                            }
                            continue;
                        }
                        let (a, b) = ((lo[k] - o) / d, (hi[k] - o) / d);
                        t0 = t0.max(a.min(b));
                        t1 = t1.min(a.max(b));
                    }
                    if t0 <= t1 && t1 >= 0.0 {
                        met = true;
                        prop_assert!(near <= t0.max(0.0) + 1e-9, "{near} > {t0} at ({x}, {y})");
                    }
                }
            }
            // Orthographic, the bound is the nearest corner's depth: within
            // the box's diagonal of every entry.
            if fov.is_none() {
                let m = 0.5 * (lo + hi);
                let t_mid = (m - cam.eye).dot(cam.forward);
                prop_assert!(t_mid - near <= (hi - lo).length() + 1e-6);
            }
            if met {
                met_box.set(met_box.get() + 1);
            }
        });
        // Most cases test some ray, so the test cannot pass vacuously.
        assert!(
            met_box.get() > 128,
            "{} of 256 cases met their box",
            met_box.get()
        );
    }

    /// Perspective boxes at or behind the eye plane cannot be bounded;
    /// boxes beside the image are empty.
    #[test]
    fn unbounded_and_outside() {
        let cam = Camera::look_at(
            [0.0, 0.0, 0.0],
            [0.0, 100.0, 0.0],
            [0.0, 0.0, 1.0],
            Projection::Persp { fov_deg: 30.0 },
            64,
            64,
        )
        .unwrap();
        let p = Projector::new(&cam);
        assert!(p
            .rect(DVec3::new(-1.0, -1.0, -1.0), DVec3::new(1.0, 1.0, 1.0))
            .is_none());
        assert_eq!(
            p.rect(DVec3::new(500.0, 10.0, 0.0), DVec3::new(510.0, 20.0, 5.0)),
            Some(None)
        );
    }
}
