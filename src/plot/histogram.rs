//! `cdvol histogram`: a packed file's value histogram (recorded by prep,
//! `summary.histogram`) as a PNG or SVG plot: samples per bin on a log
//! scale, the 1st and 99th percentiles, the file's classification (its
//! iso value as a line, or its transfer function's non-zero range as a
//! band), and below, one lane per preset with the value range where its
//! opacity is not zero (and its iso value as a tick).

use std::path::{Path, PathBuf};

use plotters::coord::Shift;
use plotters::prelude::*;

use crate::classify::Classification;
use crate::format::histogram::ValueHistogram;
use crate::format::Header;
use crate::info::num;
use crate::presets::Preset;

/// The image format, from the output's extension.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PlotFormat {
    Png,
    Svg,
}

impl PlotFormat {
    /// `.png` or `.svg` (any case); anything else is refused.
    pub fn of(path: &Path) -> Result<PlotFormat, PlotError> {
        let ext = path
            .extension()
            .map(|e| e.to_string_lossy().to_ascii_lowercase());
        match ext.as_deref() {
            Some("png") => Ok(PlotFormat::Png),
            Some("svg") => Ok(PlotFormat::Svg),
            _ => Err(PlotError::Extension {
                path: path.to_path_buf(),
                ext: ext.unwrap_or_default(),
            }),
        }
    }
}

/// What to draw.
#[derive(Debug, Clone)]
pub struct PlotOptions {
    /// Image size in pixels (200..=8192 each).
    pub width: u32,
    pub height: u32,
    /// The presets whose value ranges get a lane each.
    pub presets: Vec<Preset>,
    /// The plot's title (the file's name).
    pub title: String,
}

/// Why a plot was not written.
#[derive(Debug, thiserror::Error)]
pub enum PlotError {
    #[error(
        "{}: unknown plot format {ext:?} (from the extension), expected .png or .svg",
        path.display()
    )]
    Extension { path: PathBuf, ext: String },
    #[error(
        "{}: no value histogram in the header (prepared before cdvol recorded one); \
         prepare it again to record one",
        path.display()
    )]
    NoHistogram { path: PathBuf },
    #[error("{}: no finite sample value to plot ({nan} NaN, {infinite} infinite)", path.display())]
    NoValues {
        path: PathBuf,
        nan: u64,
        infinite: u64,
    },
    #[error("plot size {width} x {height}: expected 200..=8192 pixels each")]
    Size { width: u32, height: u32 },
    #[error("{}: drawing the plot: {msg}", path.display())]
    Draw { path: PathBuf, msg: String },
    #[error(transparent)]
    Write(#[from] crate::fsutil::WriteError),
}

/// Plots the value histogram of the packed file `source` (its header
/// `header`) into `out`, PNG or SVG by the extension, through a
/// temporary file renamed when complete.
pub fn plot(
    header: &Header,
    source: &Path,
    out: &Path,
    opts: &PlotOptions,
) -> Result<(), PlotError> {
    let format = PlotFormat::of(out)?;
    let (w, h) = (opts.width, opts.height);
    if !(200..=8192).contains(&w) || !(200..=8192).contains(&h) {
        return Err(PlotError::Size {
            width: w,
            height: h,
        });
    }
    let hist = header
        .summary
        .histogram
        .as_ref()
        .ok_or_else(|| PlotError::NoHistogram {
            path: source.to_path_buf(),
        })?;
    if hist.counts.is_empty() {
        return Err(PlotError::NoValues {
            path: source.to_path_buf(),
            nan: hist.nan,
            infinite: hist.infinite,
        });
    }
    super::font::register();
    let draw_err = |DrawFailed(msg): DrawFailed| PlotError::Draw {
        path: out.to_path_buf(),
        msg,
    };
    let bytes = match format {
        PlotFormat::Svg => {
            let mut svg = String::new();
            {
                let root = SVGBackend::with_string(&mut svg, (w, h)).into_drawing_area();
                draw(&root, hist, &header.classification, opts).map_err(draw_err)?;
                root.present()
                    .map_err(|e| draw_err(DrawFailed(e.to_string())))?;
            }
            svg.into_bytes()
        }
        PlotFormat::Png => {
            let mut rgb = vec![0u8; w as usize * h as usize * 3];
            {
                let root = BitMapBackend::with_buffer(&mut rgb, (w, h)).into_drawing_area();
                draw(&root, hist, &header.classification, opts).map_err(draw_err)?;
                root.present()
                    .map_err(|e| draw_err(DrawFailed(e.to_string())))?;
            }
            let mut png = Vec::new();
            use image::ImageEncoder;
            image::codecs::png::PngEncoder::new(&mut png)
                .write_image(&rgb, w, h, image::ExtendedColorType::Rgb8)
                .map_err(|e| draw_err(DrawFailed(format!("PNG encoding: {e}"))))?;
            png
        }
    };
    crate::fsutil::write_atomic(out, &bytes)?;
    Ok(())
}

/// The x range: the data's bins, widened to show the file's iso value or
/// transfer-function range when they lie at most one data span outside.
fn x_range(h: &ValueHistogram, cls: &Classification) -> (f64, f64) {
    let (mut a, mut b) = (h.lo, h.hi());
    let span = (b - a).max(h.bin_width);
    let marks: Vec<f64> = match cls {
        Classification::Iso { iso } => vec![*iso],
        Classification::TransferFunction { tf } => {
            tf.support().map(|(p, q)| vec![p, q]).unwrap_or_default()
        }
    };
    for m in marks.into_iter().filter(|m| m.is_finite()) {
        if m < a && m >= h.lo - span {
            a = m;
        }
        if m > b && m <= h.hi() + span {
            b = m;
        }
    }
    let pad = 0.02 * (b - a).max(h.bin_width);
    (a - pad, b + pad)
}

/// A drawing backend's failure, as its message (plotters' errors are
/// generic over the backend): [`PlotError::Draw`] names the file.
struct DrawFailed(String);

/// Draws the whole plot on `root`.
fn draw<DB: DrawingBackend>(
    root: &DrawingArea<DB, Shift>,
    h: &ValueHistogram,
    cls: &Classification,
    opts: &PlotOptions,
) -> Result<(), DrawFailed> {
    let e = |x: DrawingAreaErrorKind<DB::ErrorType>| DrawFailed(x.to_string());
    root.fill(&WHITE).map_err(e)?;
    let (x0, x1) = x_range(h, cls);
    let n_lanes = opts.presets.len();
    let lane_px = 24u32;
    let lanes_h = if n_lanes > 0 {
        (30 + lane_px * n_lanes as u32).min(opts.height / 2)
    } else {
        0
    };
    let (top, bottom) = root.split_vertically(opts.height - lanes_h);

    // Display bins: at most one per 2 pixels of width.
    let bins = h.coarse(((opts.width / 2) as usize).max(1));
    let ymax = bins.iter().map(|b| b.2).max().unwrap_or(1).max(1) as f64 * 2.0;
    let ymin = 0.8;
    let mut chart = ChartBuilder::on(&top)
        .caption(
            format!(
                "{}: {} samples{}",
                opts.title,
                h.samples,
                if h.nan > 0 {
                    format!(", {} NaN", h.nan)
                } else {
                    String::new()
                }
            ),
            ("sans-serif", 18),
        )
        .margin(12)
        .x_label_area_size(40)
        .y_label_area_size(80)
        .build_cartesian_2d(x0..x1, (ymin..ymax).log_scale())
        .map_err(e)?;
    chart
        .configure_mesh()
        .disable_x_mesh()
        .x_desc("value (rescaled: HU for CT)")
        .y_desc(format!(
            "samples per bin of {} (log scale)",
            num(bins_width(&bins))
        ))
        .x_label_formatter(&|v| num(*v))
        .y_label_formatter(&|v| num(*v))
        .label_style(("sans-serif", 13))
        .draw()
        .map_err(e)?;
    let bar = RGBColor(40, 90, 170);
    chart
        .draw_series(
            bins.iter()
                .filter(|b| b.2 > 0)
                .map(|&(a, b, n)| Rectangle::new([(a, ymin), (b, n as f64)], bar.filled())),
        )
        .map_err(e)?;

    // Percentiles 1 and 99: the range a window usually spans.
    let grey = RGBColor(120, 120, 120);
    let pcts: Vec<(f64, f64)> = [1.0, 99.0]
        .iter()
        .filter_map(|&p| h.percentile(p).map(|v| (p, v)))
        .collect();
    if !pcts.is_empty() {
        chart
            .draw_series(
                pcts.iter().map(|&(_, v)| {
                    PathElement::new(vec![(v, ymin), (v, ymax)], grey.stroke_width(1))
                }),
            )
            .map_err(e)?
            .label(format!(
                "percentiles {}",
                pcts.iter()
                    .map(|(p, v)| format!("p{}={}", num(*p), num(*v)))
                    .collect::<Vec<_>>()
                    .join(", ")
            ))
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], grey));
    }

    // The file's classification.
    let red = RGBColor(200, 30, 30);
    match cls {
        Classification::Iso { iso } => {
            let label = format!("this file: iso {}", num(*iso));
            let inside = *iso >= x0 && *iso <= x1;
            chart
                .draw_series(inside.then(|| {
                    PathElement::new(vec![(*iso, ymin), (*iso, ymax)], red.stroke_width(2))
                }))
                .map_err(e)?
                .label(if inside {
                    label
                } else {
                    format!("{label} (outside the plot)")
                })
                .legend(move |(x, y)| {
                    PathElement::new(vec![(x, y), (x + 20, y)], red.stroke_width(2))
                });
        }
        Classification::TransferFunction { tf } => {
            let support = tf.support();
            let band = support
                .map(|(a, b)| (a.max(x0), b.min(x1)))
                .filter(|(a, b)| a < b);
            chart
                .draw_series(
                    band.map(|(a, b)| {
                        Rectangle::new([(a, ymin), (b, ymax)], red.mix(0.15).filled())
                    }),
                )
                .map_err(e)?
                .label(match support {
                    Some((a, b)) => format!(
                        "this file: transfer function, opacity > 0 on {} .. {}",
                        end(a),
                        end(b)
                    ),
                    None => "this file: transfer function (zero opacity)".into(),
                })
                .legend(move |(x, y)| {
                    Rectangle::new([(x, y - 5), (x + 20, y + 5)], red.mix(0.3).filled())
                });
        }
    }
    chart
        .configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .label_font(("sans-serif", 13))
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
        .map_err(e)?;

    if n_lanes > 0 {
        draw_lanes(&bottom, x0, x1, &opts.presets).map_err(e)?;
    }
    Ok(())
}

/// Width of the display bins (all but the last are equal).
fn bins_width(bins: &[(f64, f64, u64)]) -> f64 {
    bins.first().map_or(1.0, |b| b.1 - b.0)
}

/// A range end for a label: `-inf`/`inf` beyond the transfer function.
fn end(v: f64) -> String {
    if v.is_finite() {
        num(v)
    } else if v < 0.0 {
        "-inf".into()
    } else {
        "inf".into()
    }
}

/// One lane per preset: its non-zero opacity range as a band and its iso
/// value as a tick, named at the lane's left.
fn draw_lanes<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    x0: f64,
    x1: f64,
    presets: &[Preset],
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let n = presets.len() as f64;
    let mut lanes = ChartBuilder::on(area)
        .margin_left(12)
        .margin_right(12)
        .margin_bottom(8)
        .x_label_area_size(0)
        .y_label_area_size(80)
        .build_cartesian_2d(x0..x1, 0.0..n)?;
    lanes
        .configure_mesh()
        .disable_mesh()
        .disable_x_axis()
        .y_labels(0)
        .y_desc("presets")
        .label_style(("sans-serif", 13))
        .draw()?;
    let font = ("sans-serif", 12).into_font().color(&BLACK);
    for (i, p) in presets.iter().enumerate() {
        let y0 = n - i as f64 - 0.85;
        let y1 = y0 + 0.7;
        let colour = Palette99::pick(i);
        let support = p.support();
        let band = support
            .map(|(a, b)| (a.max(x0), b.min(x1)))
            .filter(|(a, b)| a < b);
        lanes.draw_series(
            band.map(|(a, b)| Rectangle::new([(a, y0), (b, y1)], colour.mix(0.45).filled())),
        )?;
        let iso = p.iso.filter(|v| *v >= x0 && *v <= x1);
        lanes.draw_series(
            iso.map(|v| PathElement::new(vec![(v, y0), (v, y1)], BLACK.stroke_width(2))),
        )?;
        let range = match support {
            Some((a, b)) => format!("{} .. {}", end(a), end(b)),
            None => "none".into(),
        };
        let mut label = format!("{} ({}, opacity > 0 on {range}", p.name, p.modality.name());
        if let Some(v) = p.iso {
            label += &format!(", iso {}", num(v));
        }
        label += ")";
        if band.is_none() {
            label += ": outside the plot";
        }
        lanes.draw_series(std::iter::once(Text::new(
            label,
            (x0 + 0.005 * (x1 - x0), y1),
            font.clone(),
        )))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_follow_the_extension() {
        assert_eq!(PlotFormat::of(Path::new("a.PNG")).unwrap(), PlotFormat::Png);
        assert_eq!(PlotFormat::of(Path::new("a.svg")).unwrap(), PlotFormat::Svg);
        for bad in ["a.jpg", "a", "a.png.tmp"] {
            let e = PlotFormat::of(Path::new(bad)).unwrap_err().to_string();
            assert!(e.contains("expected .png or .svg"), "{e}");
        }
    }
}
