//! Colouring where the pixels are made. When a mode's colour scale is
//! known before any ray is cast (surface and composite colours, a MIP
//! with a given window), each tile colours its pixels into the frame's
//! planes as soon as it has rendered them, while they are still in its
//! thread's cache, and no pass over the whole image's pixels follows
//! (docs/BENCHMARKS.md, "Tiles colour their own pixels"). The other
//! colourings (the cost map, depth, the automatic MIP window) need the
//! whole image first and go through
//! [`colour_blocks`](super::colour::colour_blocks), as do the tiles of
//! sharded renders. Both write a pixel with [`put`], so a frame has the
//! same bytes either way (tests/all/shard.rs assembles parts through
//! `colour_blocks` and compares them with whole renders).

use std::sync::{Mutex, PoisonError};

use super::colour::{put, Colouring, Scale};
use super::Frame;
use crate::render::integrate::Px;

/// The planes of a frame being painted by its tiles.
pub(crate) struct Planes {
    w: u32,
    h: u32,
    scale: Scale,
    rgb: Vec<u8>,
    alpha: Vec<u8>,
    linear: Vec<f32>,
    steps: Vec<u32>,
    /// A MIP's maxima, NaN where a ray misses ([`Frame::values`]).
    values: Option<Vec<f32>>,
}

impl Planes {
    /// Blank planes of a `w` x `h` frame coloured by `kind` (with
    /// [`Frame::linear`] when `unrounded`): every pixel a miss. `None`
    /// when `kind` needs the whole image before it can colour a pixel.
    pub(crate) fn new(kind: &Colouring, w: u32, h: u32, unrounded: bool) -> Option<Planes> {
        let scale = kind.fixed_scale()?;
        let n = w as usize * h as usize;
        Some(Planes {
            w,
            h,
            scale,
            rgb: vec![0; 3 * n],
            alpha: vec![0; n],
            linear: vec![0.0; if unrounded { 4 * n } else { 0 }],
            steps: vec![0; n],
            values: matches!(kind, Colouring::Mip { .. }).then(|| vec![f32::NAN; n]),
        })
    }

    /// The planes cut into bands of `ts` rows, one lock each, for tiles
    /// of at most `ts` rows that start on a multiple of `ts`.
    pub(crate) fn canvas(&mut self, ts: u32) -> Canvas<'_> {
        let band = self.w.max(1) as usize * ts.max(1) as usize;
        let mut linear = (!self.linear.is_empty()).then(|| self.linear.chunks_mut(4 * band));
        let mut values = self.values.as_mut().map(|v| v.chunks_mut(band));
        let bands = self
            .rgb
            .chunks_mut(3 * band)
            .zip(self.alpha.chunks_mut(band))
            .zip(self.steps.chunks_mut(band))
            .map(|((rgb, alpha), steps)| {
                Mutex::new(Band {
                    rgb,
                    alpha,
                    steps,
                    linear: linear.as_mut().and_then(Iterator::next),
                    values: values.as_mut().and_then(Iterator::next),
                })
            })
            .collect();
        Canvas {
            w: self.w,
            ts: ts.max(1),
            scale: self.scale,
            bands,
        }
    }

    /// The painted frame.
    pub(crate) fn into_frame(self) -> Frame {
        Frame {
            width: self.w,
            height: self.h,
            rgb: self.rgb,
            alpha: self.alpha,
            linear: self.linear,
            depth: None,
            values: self.values,
            steps: self.steps,
        }
    }
}

/// [`Planes`] as bands of rows that tiles paint into, each behind its own
/// lock: a tile holds its band's lock only while it writes its pixels.
pub(crate) struct Canvas<'a> {
    w: u32,
    ts: u32,
    scale: Scale,
    bands: Vec<Mutex<Band<'a>>>,
}

/// `ts` rows of each plane.
struct Band<'a> {
    rgb: &'a mut [u8],
    alpha: &'a mut [u8],
    steps: &'a mut [u32],
    linear: Option<&'a mut [f32]>,
    values: Option<&'a mut [f32]>,
}

impl Canvas<'_> {
    /// Colours `px`, rows of `w` pixels whose first is at `(x0, y0)` (a
    /// tile: `y0` a multiple of the bands' height, at most that many rows,
    /// inside the image), into the planes. A miss leaves the planes as
    /// they are, as [`colour_blocks`](super::colour::colour_blocks) does.
    pub(crate) fn paint(&self, x0: u32, y0: u32, w: u32, px: &[Px]) {
        debug_assert!(y0.is_multiple_of(self.ts) && px.len() <= (w * self.ts) as usize);
        let Some(band) = self.bands.get((y0 / self.ts) as usize) else {
            return;
        };
        let mut b = band.lock().unwrap_or_else(PoisonError::into_inner);
        let b = &mut *b;
        let wu = self.w as usize;
        for (ly, row) in px.chunks_exact(w.max(1) as usize).enumerate() {
            let start = ly * wu + x0 as usize;
            for (x, p) in (start..).zip(row) {
                if p.is_miss() {
                    continue;
                }
                put(
                    self.scale,
                    p,
                    x,
                    b.rgb,
                    b.alpha,
                    b.steps,
                    b.linear.as_deref_mut(),
                );
                if let (Some(v), true) = (b.values.as_deref_mut(), p.hit) {
                    v[x] = p.rgb[0];
                }
            }
        }
    }
}
