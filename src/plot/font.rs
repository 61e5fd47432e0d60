//! The one font of the plots: DejaVu Sans cut to ASCII
//! (`assets/fonts/`, licence beside it), embedded and registered with
//! plotters' ab_glyph text rendering, so PNG plots need no system fonts
//! (no fontconfig or freetype) and SVG plots lay text out the same way.

use plotters::style::{register_font, FontStyle};

static FONT: &[u8] = include_bytes!("../../assets/fonts/DejaVuSans-subset.ttf");

/// Registers the embedded font under the family names plotters' styles
/// use ("sans-serif", "serif", "monospace"), once per process. Every
/// function that draws text calls it first; drawing text with no
/// registered font fails.
pub fn register() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        for family in ["sans-serif", "serif", "monospace"] {
            for style in [FontStyle::Normal, FontStyle::Bold] {
                // The embedded font parses (tested); a failure would only
                // leave text undrawn, reported by plotters as an error.
                let _ = register_font(family, style, FONT);
            }
        }
    });
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_embedded_font_parses() {
        for family in ["sans-serif", "monospace"] {
            super::register();
            let style = plotters::style::FontDesc::new(
                plotters::style::FontFamily::Name(family),
                12.0,
                plotters::style::FontStyle::Normal,
            );
            let (w, h) = style.box_size("cdvol 0.1").expect("text laid out");
            assert!(w > 20 && h > 5, "{w} x {h}");
        }
    }
}
