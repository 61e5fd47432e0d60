//! `cdvol._cdvol`: the Python package's extension module, on the library
//! API ([`cdvol::Volume`], [`cdvol::Renderer`], [`cdvol::prep::prep`]).
//!
//! This layer only converts: numpy arrays to [`ArraySource`]s and frames
//! to numpy arrays, keyword arguments to a [`Look`] and a [`View`], and
//! the library's errors to the exception classes of `cdvol/errors.py`.
//! The Python-facing signatures, their defaults and their documentation
//! are in `cdvol/__init__.py`; everything long runs with the GIL released,
//! on cdvol's own threads.

use std::path::PathBuf;

use numpy::ndarray::Dimension;
use numpy::{
    Element as NpElement, PyArray1, PyArrayDescrMethods, PyArrayMethods, PyUntypedArray,
    PyUntypedArrayMethods,
};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyType};

use cdvol::export::ExportWhat;
use cdvol::grid::{Axis, Grid};
use cdvol::input::array::{ArraySource, Element};
use cdvol::input::{Rescale, SliceSource};
use cdvol::look::ModeKind;
use cdvol::orient::NamedView;
use cdvol::prep::{PrepOptions, PrepReport};
use cdvol::progress::Progress;
use cdvol::render::{Background, Integrate};
use cdvol::{Aim, Look, Renderer, View, Volume};

/// An exception of `cdvol.errors` named `kind`, with the message of
/// `err` and of its causes (each once, as `cdvol` prints them). An error
/// caused by a missing file is `cdvol.errors.FileNotFound` whatever its
/// kind.
fn raise(py: Python<'_>, kind: &str, err: &(dyn std::error::Error + 'static)) -> PyErr {
    let mut msg = err.to_string();
    let mut cause = err.source();
    let mut missing = false;
    let mut e: Option<&(dyn std::error::Error + 'static)> = Some(err);
    while let Some(x) = e {
        if let Some(io) = x.downcast_ref::<std::io::Error>() {
            missing |= io.kind() == std::io::ErrorKind::NotFound;
        }
        e = x.source();
    }
    while let Some(c) = cause {
        let t = c.to_string();
        if !msg.contains(&t) {
            msg = format!("{msg}: {t}");
        }
        cause = c.source();
    }
    let kind = if missing { "FileNotFound" } else { kind };
    raise_msg(py, kind, msg)
}

/// An exception of `cdvol.errors` named `kind` with `msg`.
fn raise_msg(py: Python<'_>, kind: &str, msg: String) -> PyErr {
    let class = py
        .import("cdvol.errors")
        .and_then(|m| m.getattr(kind))
        .and_then(|c| c.cast_into::<PyType>().map_err(PyErr::from));
    match class {
        Ok(c) => PyErr::from_type(c, msg),
        Err(e) => e,
    }
}

/// The library's error as the exception of its step.
fn api_error(py: Python<'_>, e: cdvol::Error) -> PyErr {
    let kind = match &e {
        cdvol::Error::Format(_) => "FormatError",
        cdvol::Error::Look(_) => "LookError",
        cdvol::Error::View(_) => "ViewError",
        // A look the file was not prepared for, or an option out of
        // range: the caller's to change.
        cdvol::Error::Render(
            cdvol::render::RenderError::Incompatible { .. }
            | cdvol::render::RenderError::Option { .. }
            | cdvol::render::RenderError::Clip(_),
        ) => "LookError",
        cdvol::Error::Render(_) => "RenderError",
        cdvol::Error::Save(_) => "RenderError",
        cdvol::Error::Export(_) => "FormatError",
    };
    raise(py, kind, &e)
}

/// Progress reported to a Python callable `callback(event, stage, n)`:
/// `("begin", stage, total)`, `("advance", "", n)`, `("end", "", 0)`. The
/// package's callable draws a tqdm bar (a terminal's or a notebook's).
struct PyProgress(Option<Py<PyAny>>);

impl PyProgress {
    fn call(&self, event: &str, stage: &str, n: u64) {
        if let Some(f) = &self.0 {
            Python::attach(|py| {
                // A failing bar must not stop the work: its error is
                // printed, as Python prints errors in callbacks it cannot
                // raise.
                if let Err(e) = f.call1(py, (event, stage, n)) {
                    e.print(py);
                }
            });
        }
    }
}

impl Progress for PyProgress {
    fn begin(&self, stage: &str, total: u64) {
        self.call("begin", stage, total);
    }
    fn advance(&self, n: u64) {
        self.call("advance", "", n);
    }
    fn end(&self) {
        self.call("end", "", 0);
    }
    fn println(&self, line: &str) {
        self.call("print", line, 0);
    }
}

/// The grid of an `[nz, ny, nx]` array: uniform x and y from `spacing`
/// (x first, mm) and `origin`, z from `positions` when given.
fn array_grid(
    shape: [usize; 3],
    spacing: [f64; 3],
    origin: [f64; 3],
    positions: Option<Vec<f64>>,
) -> Result<Grid, String> {
    let [nz, ny, nx] = shape;
    let axis = |k: usize, n: usize| {
        Axis::uniform(origin[k], spacing[k], n).map_err(|e| {
            let name = ["x", "y", "z"][k];
            format!("spacing {name} = {} mm over {n} samples: {e}", spacing[k])
        })
    };
    let z = match positions {
        Some(p) => {
            if p.len() != nz {
                return Err(format!(
                    "positions: {} given, expected one per slice ({nz}, the array's first axis)",
                    p.len()
                ));
            }
            Axis::from_coords(p).map_err(|e| format!("positions: {e}"))?
        }
        None => axis(2, nz)?,
    };
    Ok(Grid {
        axes: [axis(0, nx)?, axis(1, ny)?, z],
    })
}

/// `cdvol.prep`'s classification and packing keywords (a dict).
#[derive(FromPyObject)]
#[pyo3(from_item_all)]
struct PrepKw {
    iso: Option<f64>,
    preset: Option<String>,
    envelope: Option<Vec<String>>,
    modality: Option<String>,
    brick: usize,
    zstd_level: i32,
    aniso: bool,
    allow_empty: bool,
    labels: bool,
}

/// `cdvol.prep`'s grid keywords for an array (a dict): spacing x first
/// and origin in mm, z positions, `(slope, intercept)`.
#[derive(FromPyObject)]
#[pyo3(from_item_all)]
struct GridKw {
    spacing: [f64; 3],
    origin: [f64; 3],
    positions: Option<Vec<f64>>,
    rescale: Option<(f64, f64)>,
}

impl PrepKw {
    /// The prep options, with the checks of `cdvol prep`'s flags (no
    /// classification given: `envelope=["auto"]`); errors are `(exception
    /// class, message)`.
    fn options(self) -> Result<PrepOptions, String> {
        use cdvol::classify::Classification;
        let given = [
            self.iso.is_some(),
            self.preset.is_some(),
            self.envelope.is_some(),
            self.labels,
        ];
        if given.iter().filter(|&&g| g).count() > 1 {
            return Err(
                "iso, preset, envelope and labels each choose the classification: give one".into(),
            );
        }
        let classification = match self.iso {
            Some(iso) if !iso.is_finite() => {
                return Err(format!("iso: {iso}, expected a finite number"))
            }
            Some(iso) => Classification::Iso { iso },
            // Replaced by prep once it has seen the input.
            None => Classification::Iso { iso: 0.0 },
        };
        let mut opts = PrepOptions::new(classification);
        opts.brick_size = self.brick;
        opts.zstd_level = self.zstd_level;
        opts.aniso = self.aniso;
        opts.allow_empty = self.allow_empty;
        opts.labels = self.labels;
        if self.labels {
            // Classified by its labels.
        } else if let Some(p) = self.preset {
            cdvol::presets::get(&p).map_err(|e| format!("preset: {e}"))?;
            opts.preset = Some(p);
        } else if self.iso.is_none() {
            let items = self.envelope.unwrap_or_else(|| vec!["auto".into()]);
            let auto = items.len() == 1 && items[0].eq_ignore_ascii_case("auto");
            if !auto {
                cdvol::presets::envelope(&items, cdvol::presets::all())
                    .map_err(|e| format!("envelope: {e}"))?;
            }
            opts.envelope = items;
        }
        opts.modality = match self
            .modality
            .as_deref()
            .map(str::to_ascii_lowercase)
            .as_deref()
        {
            None => None,
            Some("ct") => Some(cdvol::presets::Modality::Ct),
            Some("mr") => Some(cdvol::presets::Modality::Mr),
            Some(other) => return Err(format!("modality: {other:?}, expected \"CT\" or \"MR\"")),
        };
        opts.check().map_err(|e| e.to_string())?;
        Ok(opts)
    }
}

/// What prep did, as a dict.
fn report_dict<'py>(py: Python<'py>, r: &PrepReport) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("seconds", r.seconds)?;
    d.set_item("one_cells", r.header.summary.one_cells)?;
    d.set_item("cells", r.header.summary.cells)?;
    d.set_item("bytes", r.file_bytes)?;
    d.set_item(
        "classification",
        cdvol::prep::describe_classification(&r.header.classification),
    )?;
    d.set_item("warning", r.selection.as_ref().map(|w| w.to_string()))?;
    Ok(d)
}

/// Runs prep of `src` into `out` with the GIL released.
fn run_prep<'py>(
    py: Python<'py>,
    src: &dyn SliceSource,
    out: PathBuf,
    opts: PrepOptions,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let progress = PyProgress(progress);
    let report = py
        .detach(|| cdvol::prep::prep(src, &out, &opts, &progress))
        .map_err(|e| {
            let e = raise(py, "PrepError", &e);
            // The library names the command line's flag; say the keyword.
            let msg = e
                .value(py)
                .to_string()
                .replace("--allow-empty", "allow_empty=True");
            PyErr::from_type(e.get_type(py), msg)
        })?;
    report_dict(py, &report)
}

/// Prepares the volume file or DICOM directory `source` into `out`.
#[pyfunction]
fn prep_path<'py>(
    py: Python<'py>,
    source: PathBuf,
    out: PathBuf,
    kw: PrepKw,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let opts = kw.options().map_err(|m| raise_msg(py, "PrepError", m))?;
    let src = py
        .detach(|| cdvol::input::open(&source))
        .map_err(|e| raise(py, "InputError", &e))?;
    run_prep(py, src.as_ref(), out, opts, progress)
}

/// The element type of a numpy dtype and whether it is `bool` (read as
/// `uint8`); `None` for a dtype cdvol does not read.
fn element_of(py: Python<'_>, dtype: &Bound<'_, numpy::PyArrayDescr>) -> Option<(Element, bool)> {
    macro_rules! find {
        ($($t:ty => $e:expr),* $(,)?) => {
            $(
                if dtype.is_equiv_to(&<$t as NpElement>::get_dtype(py)) {
                    return Some(($e, std::any::TypeId::of::<$t>() == std::any::TypeId::of::<bool>()));
                }
            )*
        };
    }
    find!(
        bool => Element::U8,
        u8 => Element::U8,
        i8 => Element::I8,
        u16 => Element::U16,
        i16 => Element::I16,
        u32 => Element::U32,
        i32 => Element::I32,
        u64 => Element::U64,
        i64 => Element::I64,
        f32 => Element::F32,
        f64 => Element::F64,
    );
    None
}

/// Runs `$body` with `$T` the Rust type of the element `$el` (from
/// [`element_of`]).
macro_rules! typed {
    ($el:expr, $T:ident => $body:expr) => {
        match $el {
            (Element::U8, true) => {
                type $T = bool;
                $body
            }
            (Element::U8, false) => {
                type $T = u8;
                $body
            }
            (Element::I8, _) => {
                type $T = i8;
                $body
            }
            (Element::U16, _) => {
                type $T = u16;
                $body
            }
            (Element::I16, _) => {
                type $T = i16;
                $body
            }
            (Element::U32, _) => {
                type $T = u32;
                $body
            }
            (Element::I32, _) => {
                type $T = i32;
                $body
            }
            (Element::U64, _) => {
                type $T = u64;
                $body
            }
            (Element::I64, _) => {
                type $T = i64;
                $body
            }
            (Element::F32, _) => {
                type $T = f32;
                $body
            }
            (Element::F64, _) => {
                type $T = f64;
                $body
            }
        }
    };
}

/// Prepares a 3-D numpy array `[z, y, x]` into `out`; `files` are those a
/// memmap maps (not to be written over).
#[pyfunction]
fn prep_array<'py>(
    py: Python<'py>,
    array: &Bound<'py, PyUntypedArray>,
    out: PathBuf,
    grid: GridKw,
    kw: PrepKw,
    files: Vec<PathBuf>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let name = match files.first() {
        Some(f) => format!("numpy.memmap of {}", f.display()),
        None => format!("numpy array {:?} {}", array.shape(), array.dtype().str()?),
    };
    let el = element_of(py, &array.dtype()).ok_or_else(|| dtype_error(py, array))?;
    let job = ArrayJob::new(py, name, grid, kw, files, out)?;
    typed!(el, T => {
        let ro = array.cast::<numpy::PyArray3<T>>().map_err(PyErr::from)?.readonly();
        job.run(py, &ro.as_array(), array.strides(), el.0, progress)
    })
}

/// Prepares a sequence of 2-D numpy arrays `[y, x]`, one a slice in z
/// order, into `out`: stacked without a copy.
#[pyfunction]
fn prep_slices<'py>(
    py: Python<'py>,
    slices: Vec<Bound<'py, PyUntypedArray>>,
    out: PathBuf,
    grid: GridKw,
    kw: PrepKw,
    progress: Option<Py<PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let Some(first) = slices.first() else {
        return Err(raise_msg(
            py,
            "ShapeError",
            "no slices: expected at least two".into(),
        ));
    };
    let name = format!(
        "{} numpy slices {:?} {}",
        slices.len(),
        first.shape(),
        first.dtype().str()?
    );
    let el = element_of(py, &first.dtype()).ok_or_else(|| dtype_error(py, first))?;
    let job = ArrayJob::new(py, name, grid, kw, Vec::new(), out)?;
    typed!(el, T => {
        let ro = slices
            .iter()
            .map(|a| Ok(a.cast::<numpy::PyArray2<T>>().map_err(PyErr::from)?.readonly()))
            .collect::<PyResult<Vec<_>>>()?;
        let views: Vec<_> = ro.iter().map(|r| r.as_array()).collect();
        let strides: Vec<&[isize]> = slices.iter().map(|a| a.strides()).collect();
        job.run_planes(py, &views, &strides, el.0, progress)
    })
}

fn dtype_error(py: Python<'_>, array: &Bound<'_, PyUntypedArray>) -> PyErr {
    let dtype = array
        .dtype()
        .str()
        .map(|s| s.to_string())
        .unwrap_or_default();
    raise_msg(
        py,
        "DtypeError",
        format!("array dtype {dtype}: expected one of {}", Element::NAMES),
    )
}

/// A prep of an array, but for the array.
struct ArrayJob {
    name: String,
    grid: GridKw,
    files: Vec<PathBuf>,
    modality: Option<String>,
    opts: PrepOptions,
    out: PathBuf,
}

/// The bytes of a view, from its first element to its last, and its
/// strides in bytes; `None` for an empty axis, or numpy's byte strides
/// (`numpy_strides`) negative or not whole elements (which the view's
/// element strides would round).
fn view_bytes<'a, T, D: numpy::ndarray::Dimension>(
    view: &numpy::ndarray::ArrayView<'a, T, D>,
    numpy_strides: &[isize],
) -> Option<(&'a [u8], Vec<usize>)> {
    let size = std::mem::size_of::<T>();
    if view.shape().contains(&0) || numpy_strides.len() != view.ndim() {
        return None;
    }
    let strides = numpy_strides
        .iter()
        .zip(view.strides())
        .map(|(&b, &e)| {
            let b = usize::try_from(b).ok()?;
            (b % size == 0 && isize::try_from(b / size).ok()? == e).then_some(b)
        })
        .collect::<Option<Vec<usize>>>()?;
    let extent = view
        .shape()
        .iter()
        .zip(&strides)
        .map(|(&n, &s)| (n - 1) * s)
        .sum::<usize>()
        + size;
    // SAFETY: the view is not empty and its elements all lie in `extent`
    // bytes from its first one (non-negative strides, checked above); numpy
    // keeps them alive while the view lives, for 'a. The read-only borrow
    // keeps other rust-numpy borrowers from writing; Python code writing
    // the array during a prep (another thread) is not kept out, and races
    // with these reads as another process writing an input file races with
    // the raw reader: the values read are then unspecified, every read stays
    // in bounds.
    let bytes = unsafe { std::slice::from_raw_parts(view.as_ptr() as *const u8, extent) };
    Some((bytes, strides))
}

impl ArrayJob {
    fn new(
        py: Python<'_>,
        name: String,
        grid: GridKw,
        kw: PrepKw,
        files: Vec<PathBuf>,
        out: PathBuf,
    ) -> PyResult<ArrayJob> {
        let modality = kw.modality.clone();
        let opts = kw.options().map_err(|m| raise_msg(py, "PrepError", m))?;
        Ok(ArrayJob {
            name,
            grid,
            files,
            modality,
            opts,
            out,
        })
    }

    fn shape_error(&self, py: Python<'_>, what: String) -> PyErr {
        raise_msg(
            py,
            "ShapeError",
            format!(
                "array {}: {what}: expected no empty axis and strides of whole, \
                 non-negative elements (numpy.ascontiguousarray makes them)",
                self.name
            ),
        )
    }

    /// Prepares a 3-D view, read in place by [`ArraySource::new`].
    fn run<'py, T>(
        self,
        py: Python<'py>,
        view: &numpy::ndarray::ArrayView3<'_, T>,
        numpy_strides: &[isize],
        element: Element,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let shape: [usize; 3] = view.raw_dim().into_pattern().into();
        let what = || format!("shape {shape:?} strides {numpy_strides:?} bytes");
        let Some((bytes, strides)) = view_bytes(view, numpy_strides) else {
            return Err(self.shape_error(py, what()));
        };
        let grid = self.grid(py, shape)?;
        let src = ArraySource::new(
            bytes,
            element,
            shape,
            [strides[0], strides[1], strides[2]],
            grid,
            &self.name,
        )
        .map_err(|e| raise(py, "InputError", &e))?;
        self.finish(py, src, progress)
    }

    /// Prepares 2-D views, one a slice, read in place by
    /// [`ArraySource::from_planes`].
    fn run_planes<'py, T>(
        self,
        py: Python<'py>,
        views: &[numpy::ndarray::ArrayView2<'_, T>],
        numpy_strides: &[&[isize]],
        element: Element,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let shape: [usize; 2] = views[0].raw_dim().into_pattern().into();
        let mut planes = Vec::with_capacity(views.len());
        let mut strides = None;
        for (z, v) in views.iter().enumerate() {
            let s: [usize; 2] = v.raw_dim().into_pattern().into();
            let what = || {
                format!(
                    "slice {z}: shape {s:?} strides {:?} bytes",
                    numpy_strides[z]
                )
            };
            let Some((bytes, st)) = view_bytes(v, numpy_strides[z]).filter(|_| s == shape) else {
                return Err(self.shape_error(py, what()));
            };
            if *strides.get_or_insert(st.clone()) != st {
                return Err(self.shape_error(py, format!("{} (slice 0's strides differ)", what())));
            }
            planes.push(bytes);
        }
        let strides = strides.unwrap_or_default();
        let grid = self.grid(py, [views.len(), shape[0], shape[1]])?;
        let src = ArraySource::from_planes(
            planes,
            element,
            shape,
            [strides[0], strides[1]],
            grid,
            &self.name,
        )
        .map_err(|e| raise(py, "InputError", &e))?;
        self.finish(py, src, progress)
    }

    fn grid(&self, py: Python<'_>, shape: [usize; 3]) -> PyResult<Grid> {
        let g = &self.grid;
        array_grid(shape, g.spacing, g.origin, g.positions.clone())
            .map_err(|m| raise_msg(py, "InputError", format!("array {}: {m}", self.name)))
    }

    fn finish<'py>(
        self,
        py: Python<'py>,
        src: ArraySource<'_>,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let mut src = src
            .with_files(self.files)
            .with_modality(self.modality.map(|m| m.to_ascii_uppercase()));
        if let Some((slope, intercept)) = self.grid.rescale {
            src = src.with_rescale(Rescale { slope, intercept });
        }
        run_prep(py, &src, self.out, self.opts, progress)
    }
}

/// An open packed file and a renderer of it (`cdvol.Volume` wraps it).
#[pyclass(frozen, module = "cdvol._cdvol")]
struct RVolume {
    vol: Volume,
}

#[pymethods]
impl RVolume {
    #[new]
    fn open(py: Python<'_>, path: PathBuf) -> PyResult<RVolume> {
        let vol = py
            .detach(|| Volume::open(&path))
            .map_err(|e| api_error(py, e))?;
        Ok(RVolume { vol })
    }

    /// `cdvol info --json`'s text.
    fn info_json(&self) -> PyResult<String> {
        serde_json::to_string(&self.vol.info())
            .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))
    }

    /// `(counts, lo, bin_width)` of the value histogram, or None.
    fn histogram(&self) -> Option<(Vec<u64>, f64, f64)> {
        self.vol
            .histogram()
            .map(|h| (h.counts.clone(), h.lo, h.bin_width))
    }

    /// The offered presets' `(name, modality, description)`.
    fn presets(&self) -> Vec<(String, String, String)> {
        self.vol
            .presets()
            .into_iter()
            .map(|p| {
                (
                    p.name,
                    format!("{:?}", p.modality).to_uppercase(),
                    p.description,
                )
            })
            .collect()
    }

    /// `(dtype name, [nx, ny, nz] samples, [ncx, ncy, ncz] cells)`.
    fn layout(&self) -> (String, [u64; 3], [u64; 3]) {
        let h = self.vol.header();
        (h.dtype.name().to_string(), h.dims, h.cells())
    }

    /// `what` of the volume as little-endian bytes (a numpy uint8 array).
    #[pyo3(signature = (what, progress))]
    fn export<'py>(
        &self,
        py: Python<'py>,
        what: &str,
        progress: Option<Py<PyAny>>,
    ) -> PyResult<Bound<'py, PyArray1<u8>>> {
        let what = match what {
            "values" => ExportWhat::Values,
            "codes" => ExportWhat::Codes,
            "classes" => ExportWhat::Classes,
            other => {
                return Err(raise_msg(
                    py,
                    "Error",
                    format!("export {other:?}: expected \"values\", \"codes\" or \"classes\""),
                ))
            }
        };
        let progress = PyProgress(progress);
        let bytes = py
            .detach(|| self.vol.export(what, &progress))
            .map_err(|e| api_error(py, e))?;
        Ok(PyArray1::from_vec(py, bytes))
    }

    /// A renderer with a cache of `cache_mb` MiB.
    fn renderer(&self, cache_mb: usize) -> RRenderer {
        RRenderer {
            r: self
                .vol
                .renderer()
                .with_cache_bytes(cache_mb.saturating_mul(1 << 20)),
        }
    }
}

/// A renderer that keeps its brick cache across calls.
#[pyclass(frozen, module = "cdvol._cdvol")]
struct RRenderer {
    r: Renderer,
}

/// `Renderer.render`'s keywords (a dict).
#[derive(FromPyObject)]
#[pyo3(from_item_all)]
struct RenderKw<'py> {
    view: Bound<'py, PyAny>,
    mode: Option<String>,
    preset: Option<String>,
    iso: Option<f64>,
    width: u32,
    height: u32,
    background: String,
    shadows: bool,
    shade: bool,
    step: Option<f64>,
    perspective: Option<f64>,
    frame: Option<f64>,
    float: bool,
    crop: Option<[[f64; 2]; 3]>,
    clip: Vec<[f64; 4]>,
    cap: bool,
    labels: Option<String>,
    integrate: Option<String>,
}

impl RenderKw<'_> {
    /// The view: a name or `(az, el)`.
    fn view(&self) -> Result<View, String> {
        let v = &self.view;
        let expected = || {
            format!(
                "view {v}: expected one of {} or (azimuth, elevation) in degrees",
                NamedView::NAMES
            )
        };
        let aim = if v.is_none() {
            Aim::Orbit {
                az_deg: 0.0,
                el_deg: 0.0,
            }
        } else if let Ok(name) = v.extract::<String>() {
            Aim::Named(NamedView::parse(&name).ok_or_else(expected)?)
        } else if let Ok((az_deg, el_deg)) = v.extract::<(f64, f64)>() {
            Aim::Orbit { az_deg, el_deg }
        } else {
            return Err(expected());
        };
        Ok(View {
            aim,
            persp_fov_deg: self.perspective,
            frame_mm: self.frame,
            width: self.width,
            height: self.height,
        })
    }

    /// The look, with the checks `cdvol render` makes of its flags.
    fn look(&self) -> Result<Look, String> {
        let mut look = Look::default();
        look.ask.mode = match self.mode.as_deref() {
            None => None,
            Some("surface") => Some(ModeKind::Surface),
            Some("composite") => Some(ModeKind::Composite),
            Some("mip") => Some(ModeKind::Mip),
            Some("depth") => Some(ModeKind::Depth),
            Some("cost") => Some(ModeKind::Cost),
            Some(other) => {
                return Err(format!(
                    "mode {other:?}: expected \"surface\", \"composite\", \"mip\", \"depth\" \
                     or \"cost\""
                ))
            }
        };
        look.ask.preset = self.preset.clone();
        if let Some(iso) = self.iso.filter(|i| !i.is_finite()) {
            return Err(format!("iso {iso}: expected a finite number"));
        }
        look.ask.iso = self.iso;
        look.ask.shadows = self.shadows;
        look.ask.shade = self.shade;
        if let Some(s) = self.step {
            if !(s.is_finite() && s >= cdvol::render::MIN_STEP_MM) {
                return Err(format!(
                    "step {s} mm: expected at least {} mm",
                    cdvol::render::MIN_STEP_MM
                ));
            }
            look.ask.step_mm = s;
        }
        look.unrounded = self.float;
        look.clip = cdvol::render::clip::Clip {
            crop: self.crop,
            planes: self
                .clip
                .iter()
                .map(|p| cdvol::render::clip::Plane {
                    normal: [p[0], p[1], p[2]],
                    d: p[3],
                })
                .collect(),
        };
        look.uncapped = !self.cap;
        look.ask.labels = self.labels.clone();
        look.integrate = match self.integrate.as_deref() {
            None => self.step.map(|_| Integrate::Step),
            Some("segment") => Some(Integrate::Segment {
                tol: Integrate::SEGMENT_TOL,
            }),
            Some("step") => Some(Integrate::Step),
            Some("reference") => Some(Integrate::Reference {
                substeps: Integrate::REFERENCE_SUBSTEPS,
            }),
            Some(other) => {
                return Err(format!(
                    "integrate {other:?}: expected \"segment\", \"step\" or \"reference\""
                ))
            }
        };
        Ok(look)
    }
}

/// What a render returns: the image (flat, uint8 or float32), the depth
/// mode's depths (flat float32) and the statistics as JSON.
type Rendered<'py> = (Bound<'py, PyAny>, Option<Bound<'py, PyArray1<f32>>>, String);

#[pymethods]
impl RRenderer {
    /// Renders one view: `(rgba, depth, stats)` where `rgba` is a flat
    /// uint8 array (float32 with `float`), `depth` the depth mode's flat
    /// float32 array or None, and `stats` the render's statistics as
    /// JSON (`render --stats-json`).
    fn render<'py>(&self, py: Python<'py>, kw: RenderKw<'py>) -> PyResult<Rendered<'py>> {
        let view = kw.view().map_err(|m| raise_msg(py, "ViewError", m))?;
        let look = kw.look().map_err(|m| raise_msg(py, "LookError", m))?;
        let bg = Background::parse(&kw.background).map_err(|e| raise(py, "LookError", &e))?;
        let image = py
            .detach(|| self.r.render(&view, &look))
            .map_err(|e| api_error(py, e))?;
        let rgba = if kw.float {
            let px = py.detach(|| image.rgba_f32(bg));
            PyArray1::from_vec(py, px).into_any()
        } else {
            let px = py.detach(|| image.rgba8(bg));
            PyArray1::from_vec(py, px).into_any()
        };
        let depth = image.frame.depth.clone().map(|d| PyArray1::from_vec(py, d));
        let stats = serde_json::to_string(&image.stats)
            .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(e.to_string()))?;
        Ok((rgba, depth, stats))
    }
}

#[pymodule]
fn _cdvol(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(prep_path, m)?)?;
    m.add_function(wrap_pyfunction!(prep_array, m)?)?;
    m.add_function(wrap_pyfunction!(prep_slices, m)?)?;
    m.add_class::<RVolume>()?;
    m.add_class::<RRenderer>()?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
