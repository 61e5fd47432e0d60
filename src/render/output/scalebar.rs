//! A scale bar in mm for orthographic images (`render --scale-bar`,
//! issue 16): a white bar with its length written above it, both outlined
//! in black so that they read on any background, in the lower left corner.
//!
//! Only an orthographic view has one scale over the whole image: a pixel
//! is `frame_mm / height` mm wide at every depth. A perspective view has
//! none and is refused, and so are the float32 TIFFs of the depth, MIP
//! and cost modes, which hold data rather than a picture (module job).

use super::Frame;

/// How long the bar is.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ScaleBar {
    /// The longest of 1, 2 or 5 times a power of ten mm that spans at
    /// most a quarter of the image's width.
    Auto,
    /// This many mm.
    Mm(f64),
}

impl ScaleBar {
    /// `auto`, or a length in mm (finite, above 0).
    pub fn parse(s: &str) -> Result<ScaleBar, ScaleBarParseError> {
        if s == "auto" {
            return Ok(ScaleBar::Auto);
        }
        match s.parse::<f64>() {
            Ok(mm) if mm > 0.0 && mm.is_finite() => Ok(ScaleBar::Mm(mm)),
            _ => Err(ScaleBarParseError {
                found: s.to_string(),
            }),
        }
    }

    /// The bar's length in mm for an image `width` pixels wide at
    /// `mm_per_px`.
    pub fn length_mm(self, width: u32, mm_per_px: f64) -> f64 {
        match self {
            ScaleBar::Mm(mm) => mm,
            ScaleBar::Auto => {
                let most = 0.25 * width as f64 * mm_per_px;
                let decade = 10f64.powi(most.log10().floor() as i32);
                [5.0, 2.0, 1.0]
                    .into_iter()
                    .map(|m| m * decade)
                    .find(|&l| l <= most)
                    .unwrap_or(decade)
            }
        }
    }
}

/// A `--scale-bar` length that is neither `auto` nor a length in mm.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{found:?}: expected auto or a length in mm above 0")]
pub struct ScaleBarParseError {
    pub found: String,
}

/// Why a scale bar cannot be drawn.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ScaleBarError {
    #[error("--scale-bar: a perspective view has no single scale; use the orthographic camera (no --persp)")]
    Perspective,
    #[error("--scale-bar: a float32 TIFF of the {mode} mode holds data, not a picture; use --bit-depth 8 or 16")]
    Data { mode: &'static str },
    #[error("--scale-bar: a bar of {mm} mm is {px:.0} pixels, which does not fit a {width} x {height} image with its label")]
    TooLarge {
        mm: f64,
        px: f64,
        width: u32,
        height: u32,
    },
}

/// Glyphs 5 pixels wide and 7 high, a row a byte (bit 4 at the left).
fn glyph(c: char) -> [u8; 7] {
    match c {
        '0' => [0x0e, 0x11, 0x13, 0x15, 0x19, 0x11, 0x0e],
        '1' => [0x04, 0x0c, 0x04, 0x04, 0x04, 0x04, 0x0e],
        '2' => [0x0e, 0x11, 0x01, 0x02, 0x04, 0x08, 0x1f],
        '3' => [0x1e, 0x01, 0x01, 0x0e, 0x01, 0x01, 0x1e],
        '4' => [0x02, 0x06, 0x0a, 0x12, 0x1f, 0x02, 0x02],
        '5' => [0x1f, 0x10, 0x1e, 0x01, 0x01, 0x11, 0x0e],
        '6' => [0x06, 0x08, 0x10, 0x1e, 0x11, 0x11, 0x0e],
        '7' => [0x1f, 0x01, 0x02, 0x04, 0x08, 0x08, 0x08],
        '8' => [0x0e, 0x11, 0x11, 0x0e, 0x11, 0x11, 0x0e],
        '9' => [0x0e, 0x11, 0x11, 0x0f, 0x01, 0x02, 0x0c],
        '.' => [0, 0, 0, 0, 0, 0x0c, 0x0c],
        'm' => [0, 0, 0x1a, 0x15, 0x15, 0x15, 0x15],
        _ => [0; 7],
    }
}

/// The label of a bar `mm` long: `20 mm`, `0.5 mm`.
pub fn label(mm: f64) -> String {
    format!("{mm} mm")
}

/// Where the bar lands in an image: its pixel length and the rectangles
/// drawn (before the outline).
#[derive(Debug, Clone, PartialEq)]
pub struct Layout {
    /// The bar's length in pixels, `mm / mm_per_px` rounded.
    pub bar_px: u32,
    /// The bar: `[x0, y0, x1, y1)`.
    pub bar: [u32; 4],
    /// Font scale (pixels per glyph pixel) and the label's top left.
    pub scale: u32,
    pub text_at: [u32; 2],
}

/// The layout of a bar `mm` long at `mm_per_px` in a `width` x `height`
/// image: margin `max(4, height / 50)`, font scale `max(1, height / 300)`,
/// the bar `3 * scale` thick on the bottom margin, the label `2 * scale`
/// above it.
pub fn layout(mm: f64, mm_per_px: f64, width: u32, height: u32) -> Result<Layout, ScaleBarError> {
    let px = mm / mm_per_px;
    let margin = (height / 50).max(4);
    let scale = (height / 300).max(1);
    let chars = label(mm).chars().count() as u32;
    let text_w = chars * 6 * scale;
    let too_large = ScaleBarError::TooLarge {
        mm,
        px,
        width,
        height,
    };
    let bar_px = px.round();
    if !(bar_px >= 1.0 && bar_px + 2.0 * margin as f64 <= width as f64)
        || text_w + 2 * margin > width
        || 2 * margin + 12 * scale > height
    {
        return Err(too_large);
    }
    let bar_px = bar_px as u32;
    let y1 = height - margin;
    let y0 = y1 - 3 * scale;
    Ok(Layout {
        bar_px,
        bar: [margin, y0, margin + bar_px, y1],
        scale,
        text_at: [margin, y0 - 2 * scale - 7 * scale],
    })
}

/// Draws a bar `mm` long into `frame` (colour planes only: `rgb`, `alpha`
/// and `linear`; depth and MIP or cost values stay data).
pub fn draw(frame: &mut Frame, mm: f64, mm_per_px: f64) -> Result<Layout, ScaleBarError> {
    let (w, h) = (frame.width, frame.height);
    let lay = layout(mm, mm_per_px, w, h)?;
    let at = |x: u32, y: u32| y as usize * w as usize + x as usize;
    // The shape: the bar and the label's pixels.
    let mut shape = vec![false; w as usize * h as usize];
    let [x0, y0, x1, y1] = lay.bar;
    for y in y0..y1 {
        for x in x0..x1 {
            shape[at(x, y)] = true;
        }
    }
    let s = lay.scale;
    for (i, c) in label(mm).chars().enumerate() {
        for (row, bits) in glyph(c).into_iter().enumerate() {
            for col in 0..5u32 {
                if bits >> (4 - col) & 1 == 0 {
                    continue;
                }
                let gx = lay.text_at[0] + (i as u32 * 6 + col) * s;
                let gy = lay.text_at[1] + row as u32 * s;
                for y in gy..gy + s {
                    for x in gx..gx + s {
                        shape[at(x, y)] = true;
                    }
                }
            }
        }
    }
    // Black where the shape, grown by `scale` pixels, reaches; white on
    // the shape.
    let mut put = |x: u32, y: u32, v: u8| {
        let i = at(x, y);
        frame.rgb[3 * i..3 * i + 3].fill(v);
        frame.alpha[i] = 255;
        if !frame.linear.is_empty() {
            let f = f32::from(v) / 255.0;
            frame.linear[4 * i..4 * i + 4].copy_from_slice(&[f, f, f, 1.0]);
        }
    };
    // The shape's box grown by the outline (the margin holds it).
    let right = x1.max(lay.text_at[0] + label(mm).chars().count() as u32 * 6 * s);
    for y in lay.text_at[1] - s..(y1 + s).min(h) {
        for x in x0 - s..(right + s).min(w) {
            let near = (y.saturating_sub(s)..=(y + s).min(h - 1))
                .any(|yy| (x.saturating_sub(s)..=(x + s).min(w - 1)).any(|xx| shape[at(xx, yy)]));
            if shape[at(x, y)] {
                put(x, y, 255);
            } else if near {
                put(x, y, 0);
            }
        }
    }
    Ok(lay)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auto_lengths_are_1_2_5_within_a_quarter_width() {
        let cases = [
            (400, 0.2, 20.0),  // a quarter: 20 mm
            (400, 0.25, 20.0), // 25 mm
            (1000, 0.01, 2.0), // 2.5 mm
            (100, 0.3, 5.0),   // 7.5 mm
            (40, 1.0, 10.0),   // exactly 10 mm
            (400, 0.003, 0.2), // 0.3 mm
        ];
        for (w, mm_px, want) in cases {
            let got = ScaleBar::Auto.length_mm(w, mm_px);
            assert!(
                (got - want).abs() < 1e-12 * want,
                "{w} px at {mm_px}: {got}"
            );
            assert!(got <= 0.25 * w as f64 * mm_px * (1.0 + 1e-12));
        }
        assert_eq!(ScaleBar::Mm(7.0).length_mm(10, 1.0), 7.0);
        assert_eq!(label(0.2), "0.2 mm");
        assert_eq!(label(20.0), "20 mm");
    }

    #[test]
    fn parse_takes_auto_and_positive_lengths() {
        assert_eq!(ScaleBar::parse("auto"), Ok(ScaleBar::Auto));
        assert_eq!(ScaleBar::parse("12.5"), Ok(ScaleBar::Mm(12.5)));
        for bad in ["0", "-1", "nan", "inf", "ten", ""] {
            assert!(ScaleBar::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn layouts_fit_or_are_refused() {
        // 300 high: margin 6, scale 1; the bar 3 rows on the bottom margin.
        let l = layout(20.0, 0.2, 400, 300).unwrap();
        assert_eq!(l.bar_px, 100);
        assert_eq!(l.bar, [6, 291, 106, 294]);
        assert_eq!(l.text_at, [6, 282]);
        // The bar plus both margins must fit the width, the label the height.
        assert!(layout(20.0, 0.2, 111, 300).is_err());
        assert!(layout(20.0, 0.2, 112, 300).is_ok());
        assert!(matches!(
            layout(1e6, 0.2, 400, 300),
            Err(ScaleBarError::TooLarge { .. })
        ));
        assert!(layout(1e-3, 0.2, 400, 300).is_err(), "under a pixel");
        assert!(layout(1.0, 0.2, 400, 19).is_err(), "no room for the label");
    }
}
