//! A figure of the sampling grain of a composite render (issue 51): how
//! much more fine-scale energy a render at step `s` holds than the same
//! view at step `s / 4`.
//!
//! Samples at fixed multiples of the step put the first sample behind a
//! sharp rise of opacity at a depth that drifts slowly from ray to ray,
//! so a transfer function that is opaque from a threshold and coloured by
//! value draws bands (wood grain, moire) whose amplitude grows with the
//! step. The bands are fine-scale structure the data does not have: a
//! render at a quarter of the step shows the same anatomy with a quarter
//! of their amplitude. So [`grain`] compares the two renders' high-pass
//! energy over the object:
//!
//! ```text
//! h(x)   = x - box(x)     grey level (0-255) less its 5 x 5 box mean
//! E(X)   = mean of h(X)^2 over the pixels whose whole box is object in
//!          A and B, the largest 1 % left out, plus 0.25 (half a level, squared)
//! grain  = E(A) / E(B)    A at step s, B at step s / 4
//! ```
//!
//! A render without grain has the fine structure of the data only, the
//! same at both steps: the figure reads about 1 (1.0-1.1 on the real CT
//! with onsets refined; docs/TRADEOFFS.md, "Wood grain"). Bands add their
//! energy to A sixteen times over (the square of the amplitude ratio)
//! where they add it to B: the figure grows with how much of A's fine
//! structure they are (9-12 on the real CT with `ct-soft-tissue` before
//! onsets were refined).
//!
//! Why this form:
//!
//! * Not the energy of `A - B`: the two steps also differ smoothly (a
//!   step's worth of depth into a coloured ramp shifts grey levels a
//!   little), which a difference counts as grain; a high-pass of each
//!   image alone does not see it, and the ratio needs no threshold.
//! * A 5-pixel box rather than a 3-pixel Laplacian: the bands of a 256-
//!   to 512-pixel render of a head at the default 0.5 mm are 3 to 10
//!   pixels apart, where a Laplacian responds weakly. The box leaves out
//!   the silhouette (object against background: the same strong edge in
//!   both renders), which would pull the figure towards 1.
//! * The largest 1 % left out: grain covers the surface, while a few
//!   isolated pixels (a ray grazing a surface, whose ramp a coarse step
//!   samples coarsely) are not grain and would dominate a mean of
//!   squares.
//! * Half a grey level added: a render that is flat to within the 8-bit
//!   rounding (an opaque threshold coloured by its value, rendered
//!   exactly) has energies of a fraction of a level whose ratio means
//!   nothing.

/// A render as [`grain`] reads it: `width x height` pixels, colour over
/// black (`rgb`, 3 a pixel) and coverage (`alpha`, 1 a pixel), 8 bits
/// each (a [`Frame`](crate::render::Frame)'s `rgb` and `alpha`).
#[derive(Clone, Copy, Debug)]
pub struct Image<'a> {
    /// Pixels per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// Red, green, blue per pixel, row by row.
    pub rgb: &'a [u8],
    /// Coverage per pixel: a pixel is object where it is at least 128.
    pub alpha: &'a [u8],
}

impl<'a> Image<'a> {
    /// The image of a rendered frame.
    pub fn of(frame: &'a crate::render::Frame) -> Image<'a> {
        Image {
            width: frame.width as usize,
            height: frame.height as usize,
            rgb: &frame.rgb,
            alpha: &frame.alpha,
        }
    }

    /// Whether the buffers hold `width x height` pixels.
    fn consistent(&self) -> bool {
        let n = self.width.checked_mul(self.height);
        n.and_then(|n| n.checked_mul(3)) == Some(self.rgb.len()) && n == Some(self.alpha.len())
    }

    /// Grey level (0-255) of each pixel: the mean of its channels.
    fn grey(&self) -> Vec<f64> {
        self.rgb
            .chunks_exact(3)
            .map(|p| (p[0] as f64 + p[1] as f64 + p[2] as f64) / 3.0)
            .collect()
    }
}

/// Half the width of [`grain`]'s box, in pixels.
pub const BOX_RADIUS: usize = 2;

/// The share of pixels with the largest high-pass energy [`grain`] leaves
/// out.
pub const TRIM: f64 = 0.01;

/// What [`grain`] adds to each energy, in grey levels squared.
pub const FLOOR: f64 = 0.25;

/// Coverage from which a pixel counts as object.
const OBJECT_ALPHA: u8 = 128;

/// The grain figure of render `a` (step `s`) against render `b` (same
/// view and size, step `s / 4`): the ratio of their high-pass energies
/// over the pixels whose whole box is object in both (module doc). About
/// 1 for a render without grain, clearly more with it. `None` when the
/// images differ in size, their buffers do not match their size, or no
/// pixel's box is all object.
pub fn grain(a: Image, b: Image) -> Option<f64> {
    let (w, h) = (a.width, a.height);
    if (b.width, b.height) != (w, h) || !a.consistent() || !b.consistent() {
        return None;
    }
    let object: Vec<bool> = (0..w * h)
        .map(|i| a.alpha[i] >= OBJECT_ALPHA && b.alpha[i] >= OBJECT_ALPHA)
        .collect();
    let inside = all_in_box(&object, w, h);
    let ea = energy(&a.grey(), &inside, w, h)?;
    let eb = energy(&b.grey(), &inside, w, h)?;
    Some(ea / eb)
}

/// Per pixel, whether every pixel of its box lies in the image and is
/// `object`.
fn all_in_box(object: &[bool], w: usize, h: usize) -> Vec<bool> {
    let r = BOX_RADIUS;
    let mut out = vec![false; w * h];
    for y in r..h.saturating_sub(r) {
        for x in r..w.saturating_sub(r) {
            let row = |v: usize| &object[v * w + x - r..=v * w + x + r];
            out[y * w + x] = (y - r..=y + r).all(|v| row(v).iter().all(|&o| o));
        }
    }
    out
}

/// The high-pass energy of grey levels `g` (0-255) over the pixels `at`:
/// the mean of `(g - box mean)^2` without the largest [`TRIM`], plus
/// [`FLOOR`]; `None` without pixels.
fn energy(g: &[f64], at: &[bool], w: usize, h: usize) -> Option<f64> {
    let r = BOX_RADIUS;
    let cells = ((2 * r + 1) * (2 * r + 1)) as f64;
    let mut e: Vec<f64> = Vec::new();
    for y in 0..h {
        for x in 0..w {
            if !at[y * w + x] {
                continue;
            }
            let row = |v: usize| g[v * w + x - r..=v * w + x + r].iter().sum::<f64>();
            let mean = (y - r..=y + r).map(row).sum::<f64>() / cells;
            let d = g[y * w + x] - mean;
            e.push(d * d);
        }
    }
    if e.is_empty() {
        return None;
    }
    e.sort_by(f64::total_cmp);
    let kept = ((e.len() as f64 * (1.0 - TRIM)).ceil() as usize).max(1);
    Some(e[..kept].iter().sum::<f64>() / kept as f64 + FLOOR)
}

#[cfg(test)]
mod tests {
    use super::{grain, Image};

    /// A `w x w` grey image from `f(x, y)` in [0, 1], all object but a
    /// black border of 3 pixels.
    fn image(w: usize, f: impl Fn(usize, usize) -> f64) -> (Vec<u8>, Vec<u8>) {
        let mut rgb = Vec::new();
        let mut alpha = Vec::new();
        for y in 0..w {
            for x in 0..w {
                let inside = (3..w - 3).contains(&x) && (3..w - 3).contains(&y);
                let g = if inside {
                    (f(x, y) * 255.0).round() as u8
                } else {
                    0
                };
                rgb.extend([g; 3]);
                alpha.push(if inside { 255 } else { 0 });
            }
        }
        (rgb, alpha)
    }

    fn of(w: usize, p: &(Vec<u8>, Vec<u8>)) -> Image<'_> {
        Image {
            width: w,
            height: w,
            rgb: &p.0,
            alpha: &p.1,
        }
    }

    /// Smooth shading with some anatomy-like detail (about 8 grey levels),
    /// and bands of period `period` pixels and amplitude `amp` on top
    /// (0.04: 10 levels; the real CT's grain before onsets were refined
    /// had a high-pass RMS of 18-25 levels).
    fn scene(x: usize, y: usize, amp: f64, period: f64) -> f64 {
        let (x, y) = (x as f64, y as f64);
        let smooth = 0.4 + 0.2 * (x / 40.0).sin() * (y / 55.0).cos();
        let detail = 0.03 * ((x * 0.9).sin() * (y * 0.7).cos());
        // Rings around a point off the image, as the lattice draws them.
        let r = ((x + 30.0).powi(2) + (y - 20.0).powi(2)).sqrt();
        let bands = amp * (std::f64::consts::TAU * r / period).sin();
        smooth + detail + bands
    }

    /// Two clean renders (the same detail, a smooth shift between them)
    /// read about 1; bands in the coarse render read clearly more, more
    /// for stronger bands, also against a quarter of their amplitude at
    /// four times the density in the fine render (the lattice's grain at
    /// s / 4); straight stripes too. A few isolated bright pixels are
    /// not grain.
    #[test]
    fn stripes_read_high_and_smooth_images_about_one() {
        let w = 96;
        let clean_a = image(w, |x, y| scene(x, y, 0.0, 6.0) + 0.02);
        let clean_b = image(w, |x, y| scene(x, y, 0.0, 6.0));
        let g = grain(of(w, &clean_a), of(w, &clean_b)).unwrap();
        assert!((0.9..1.1).contains(&g), "clean: {g}");
        let fine_grain = image(w, |x, y| scene(x, y, 0.0125, 1.5));
        let mut last = g;
        for amp in [0.04, 0.08, 0.16] {
            let banded = image(w, |x, y| scene(x, y, amp, 6.0));
            let g = grain(of(w, &banded), of(w, &clean_b)).unwrap();
            assert!(g > 2.0 && g > last, "bands of {amp}: {g}");
            last = g;
            let g4 = grain(of(w, &banded), of(w, &fine_grain)).unwrap();
            assert!(g4 > 1.5, "bands of {amp} against fine grain: {g4}");
        }
        let stripes = image(w, |x, y| {
            scene(x, y, 0.0, 6.0) + 0.08 * ((x + y) % 4 < 2) as u8 as f64
        });
        let g = grain(of(w, &stripes), of(w, &clean_b)).unwrap();
        assert!(g > 4.0, "stripes: {g}");
        let specks = image(w, |x, y| {
            scene(x, y, 0.0, 6.0)
                + if (x * 31 + y * 17) % 601 == 0 {
                    0.5
                } else {
                    0.0
                }
        });
        let g = grain(of(w, &specks), of(w, &clean_b)).unwrap();
        assert!(g < 1.2, "specks: {g}");
    }

    /// Two images flat to within the rounding read about 1, however
    /// different their last bits; mismatched sizes and images without
    /// object have no figure.
    #[test]
    fn degenerate_inputs() {
        let w = 16;
        let flat = image(w, |_, _| 0.5);
        assert_eq!(grain(of(w, &flat), of(w, &flat)), Some(1.0));
        // A level of rounding noise in each, in different patterns.
        let level = 1.0 / 255.0;
        let checks = image(w, |x, y| 0.5 + ((x + y) % 2) as f64 * level);
        let rows = image(w, |x, y| {
            0.5 + ((x * 7 + y * 3) % 5 == 0) as u8 as f64 * level
        });
        let g = grain(of(w, &checks), of(w, &rows)).unwrap();
        assert!((0.6..1.7).contains(&g), "rounding: {g}");
        let none = (vec![0u8; w * w * 3], vec![0u8; w * w]);
        assert_eq!(grain(of(w, &none), of(w, &none)), None);
        let short = Image {
            width: w,
            height: w,
            rgb: &flat.0[..30],
            alpha: &flat.1,
        };
        assert_eq!(grain(short, of(w, &flat)), None);
        let other = image(20, |_, _| 0.5);
        assert_eq!(grain(of(w, &flat), of(20, &other)), None);
    }
}
