//! The default frame of a view (issue 51, item 6): what `cdvol render`
//! and `cdvol serve` show when no `--frame` is given.
//!
//! A view frames the **object**, the scene's 1-cells, rather than the
//! whole volume: a head in a CT that holds much air around it then fills
//! the image. What is known of the object comes from the brick index
//! ([`object`]):
//! - **Its box, exact to the cell.** Bricks the index marks as holding no
//!   1-cell (and, for a narrowed scene, `render --iso`, bricks whose
//!   largest value lies below the scene's iso value) are left out, which
//!   bounds the box to whole bricks; then, face by face, only the bricks
//!   of the outermost layer that may hold a 1-cell are decoded, to find
//!   the outermost 1-cell. A brick's outside neighbour, when the index
//!   marks it empty, bounds how far in the brick's 1-cells begin (its
//!   smallest code), so a face stops decoding once no brick left can
//!   beat the best found: 25 to 66 of the real CT's 256 bricks, 10-50 ms.
//! - **Its outline:** the bricks that may hold a 1-cell, clipped to the
//!   box, as per column of bricks one box from the lowest to the highest
//!   ([`Object::outline`], 8 corners a column). Seen obliquely it is
//!   tighter than the box's 8 corners: the box of a head on its head
//!   rest has corners of air.
//!
//! Placing ([`orbit`]):
//! - Every view looks at the **centre of the object's box**: an orbit (and
//!   `cdvol serve`'s drag) turns about that fixed point, a turntable's
//!   frames and a single image from the same direction agree, and the
//!   object sits in the middle of the image.
//! - **Orthographic:** the outline's corners are projected onto the
//!   view's right and up axes; the frame's height (mm) is the larger of
//!   the projection's height and its width over the image's aspect ratio,
//!   each taken symmetric about the box's centre, with a margin of 5 % of
//!   it on each side ([`MARGIN`]). An explicit frame (`--frame`, the
//!   server's zoom) sets the height about the same centre. The eye stays
//!   outside the volume's bounding sphere, so every ray starts before the
//!   volume.
//! - **Perspective:** the eye is placed on the view axis just far enough
//!   that every corner of the outline lies in the field of view shrunk by
//!   the same margin, and outside the outline's bounding sphere about the
//!   box's centre.
//! - **Turntables** (`--frames` with `--orbit`) share one frame fitted to
//!   every frame's direction ([`Framing::fitted`]): the largest of the
//!   frames' own fits (frame height, or eye distance), so the object stays
//!   in view and the frame does not jump from frame to frame.
//! - A scene with **no 1-cell** frames the volume's bounding sphere
//!   around the volume's centre, as [`Camera::orbit_dir`] always has.
//!
//! Explicit cameras (`--eye --target --up`) are placed as given
//! ([`crate::render::job::View::place`]).

use std::collections::{BTreeMap, HashMap};
use std::sync::Mutex;

use glam::DVec3;

use super::camera::{Camera, CameraError, Projection};
use crate::format::reader::PackedVolume;
use crate::render::brick::{Codes, Planes, RBrick};
use crate::render::options::RenderOptions;
use crate::render::traverse::TGrid;
use crate::render::traverse::OBJECT;

/// A box in mm: lower and upper corner.
pub type MmBox = ([f64; 3], [f64; 3]);

/// The frame is this many times the object's projected extent along the
/// side that binds it: a margin of 5 % of the extent on each side, so the
/// object's outline fills 1 / 1.1 = 91 % of the image that way.
pub const MARGIN: f64 = 1.1;

/// The scene's 1-cells as a view frames them.
#[derive(Debug, Clone, PartialEq)]
pub struct Object {
    /// The box of the 1-cells, exact to the cell.
    pub bounds: MmBox,
    /// Points (mm) whose convex hull holds every 1-cell: per column of
    /// bricks along z that may hold one, the 8 corners of the box from its
    /// lowest to its highest such brick, clipped to `bounds`.
    pub outline: Vec<[f64; 3]>,
}

impl Object {
    /// An object known only by its box (the outline is its 8 corners).
    pub fn from_box(bounds: MmBox) -> Object {
        Object {
            bounds,
            outline: corners(bounds).to_vec(),
        }
    }

    /// The centre of [`Object::bounds`].
    pub fn centre(&self) -> DVec3 {
        (DVec3::from_array(self.bounds.0) + DVec3::from_array(self.bounds.1)) * 0.5
    }
}

/// The 8 corners of box `b`, x fastest.
fn corners((lo, hi): MmBox) -> [[f64; 3]; 8] {
    std::array::from_fn(|i| std::array::from_fn(|k| if i >> k & 1 == 0 { lo[k] } else { hi[k] }))
}

/// What a default view frames.
#[derive(Debug, Clone, PartialEq)]
pub struct Framing {
    /// The volume's box.
    pub volume: MmBox,
    /// The scene's 1-cells; `None` when it has none (the volume is
    /// framed then).
    pub object: Option<Object>,
    /// The orthographic frame height (mm), or perspective eye distance
    /// from the object's centre (mm), shared by the views of a turntable
    /// ([`Framing::fitted`]); `None`: each view fits its own direction.
    pub fit: Option<f64>,
}

/// A view direction: the unit vector from the centre to the eye, and up
/// (not parallel to it).
pub type Dir = ([f64; 3], [f64; 3]);

impl Framing {
    /// The volume alone (no object): the frame of a scene with no 1-cell,
    /// and of explicit cameras.
    pub fn volume(volume: MmBox) -> Framing {
        Framing {
            volume,
            object: None,
            fit: None,
        }
    }

    /// The object of `opts`'s scene in `vol` ([`object`]).
    pub fn of(vol: &PackedVolume, opts: &RenderOptions) -> Framing {
        Framing {
            object: object(vol, opts),
            ..Framing::volume(TGrid::<f64>::new(&vol.header().axes).bounds())
        }
    }

    /// This framing with one frame (or eye distance) for all the views
    /// looking from `dirs` (a turntable's frames) at the box's centre,
    /// each `width` x `height` pixels, perspective with a vertical field
    /// of view of `persp_fov` degrees: the largest of the views' own fits,
    /// so the object fits every frame and the frame does not jump.
    /// Directions that are not finite or whose up is parallel to them are
    /// left out; without an object, or without a direction left, it stays
    /// unfitted.
    pub fn fitted(self, dirs: &[Dir], persp_fov: Option<f64>, width: u32, height: u32) -> Framing {
        let Some(obj) = &self.object else {
            return self;
        };
        let fit = dirs
            .iter()
            .filter_map(|&(b, u)| basis(b, u))
            .filter_map(|basis| fit_one(obj, basis, persp_fov, width, height))
            .fold(None, |a: Option<f64>, x| Some(a.map_or(x, |a| a.max(x))));
        Framing { fit, ..self }
    }
}

/// The orthographic frame height, or perspective eye distance (mm), that
/// fits `obj` seen along `basis` (module doc); `None` for an empty image
/// or a field of view out of `(0, 180)` degrees.
fn fit_one(
    obj: &Object,
    (f, r, u): (DVec3, DVec3, DVec3),
    persp_fov: Option<f64>,
    width: u32,
    height: u32,
) -> Option<f64> {
    if width == 0 || height == 0 {
        return None;
    }
    let c = obj.centre();
    let pts = obj.outline.iter().map(|&p| DVec3::from_array(p) - c);
    let aspect = width as f64 / height as f64;
    match persp_fov {
        Some(fov_deg) => {
            if !(fov_deg > 0.0 && fov_deg < 180.0) {
                return None;
            }
            let tan_y = ((0.5 * fov_deg).to_radians().tan() / MARGIN).max(1e-6);
            let tan_x = (tan_y * aspect).max(1e-6);
            let (fit, reach) = pts.fold((0.0f64, 0.0f64), |(d, reach), p| {
                // A point at (x, y, z) in the view's axes lies at depth
                // d + z and needs |x| <= tan_x (d + z), |y| <= tan_y (d + z).
                let need = (p.dot(r).abs() / tan_x).max(p.dot(u).abs() / tan_y) - p.dot(f);
                (d.max(need), reach.max(p.length()))
            });
            Some(fit.max(1.05 * reach))
        }
        None => {
            // Half the extents across and up, about the centre.
            let (x, y) = pts.fold((0.0f64, 0.0f64), |(x, y), p| {
                (x.max(p.dot(r).abs()), y.max(p.dot(u).abs()))
            });
            Some(2.0 * MARGIN * y.max(x / aspect))
        }
    }
}

/// The camera looking along `-dir.0` with up `dir.1` at the centre of
/// the object's box, framed by `framing` (module doc): with `framing.fit`
/// (a turntable's), else with this direction's own fit. An explicit `frame_mm` sets an
/// orthographic frame's height; `persp_fov` (degrees) makes the view
/// perspective. Without an object: [`Camera::orbit_dir`] on the volume.
pub fn orbit(
    framing: &Framing,
    dir: Dir,
    persp_fov: Option<f64>,
    frame_mm: Option<f64>,
    width: u32,
    height: u32,
) -> Result<Camera, CameraError> {
    let (back, up) = dir;
    let Some(obj) = &framing.object else {
        return Camera::orbit_dir(framing.volume, back, up, persp_fov, frame_mm, width, height);
    };
    if width == 0 || height == 0 {
        return Err(CameraError::EmptyImage { width, height });
    }
    if let Some(fov_deg) = persp_fov.filter(|f| !(*f > 0.0 && *f < 180.0)) {
        return Err(CameraError::Fov { fov_deg });
    }
    // An up parallel to the view: refused as look_at refuses it.
    let basis = basis(back, up).ok_or(CameraError::UpParallel { up })?;
    let fit = framing
        .fit
        .or_else(|| fit_one(obj, basis, persp_fov, width, height))
        .ok_or(CameraError::UpParallel { up })?;
    let target = obj.centre();
    let (projection, dist) = match persp_fov {
        Some(fov_deg) => (Projection::Persp { fov_deg }, fit),
        None => {
            let (vlo, vhi) = framing.volume;
            let vc = (DVec3::from_array(vlo) + DVec3::from_array(vhi)) * 0.5;
            let radius = 0.5 * (DVec3::from_array(vhi) - DVec3::from_array(vlo)).length();
            (
                Projection::Ortho {
                    frame_mm: frame_mm.unwrap_or(fit),
                },
                2.0 * radius + (target - vc).length(),
            )
        }
    };
    let eye = target + dist * DVec3::from_array(back);
    Camera::look_at(
        eye.to_array(),
        target.to_array(),
        up,
        projection,
        width,
        height,
    )
}

/// Forward, right and up of a view from `back` with `up`, as
/// [`Camera::look_at`] builds them; `None` when `up` is parallel to the
/// view or a vector is not finite.
fn basis(back: [f64; 3], up: [f64; 3]) -> Option<(DVec3, DVec3, DVec3)> {
    let b = DVec3::from_array(back);
    let f = -b / b.length();
    let r = f.cross(DVec3::from_array(up));
    if !(r.dot(r) > 1e-20) || !f.is_finite() {
        return None;
    }
    let right = r / r.length();
    Some((f, right, right.cross(f)))
}

/// Cells `[lo, hi]` (inclusive, per axis) of a box of cells.
type CellBox = ([u64; 3], [u64; 3]);

/// Objects found, by file and scene: `cdvol serve` asks for one per
/// request. A handful of entries; the oldest goes first.
static MEMO: Mutex<Vec<(MemoKey, Option<Object>)>> = Mutex::new(Vec::new());
/// Entries [`MEMO`] keeps.
const MEMO_LEN: usize = 16;

/// A file (its path, length and the checksum of its header and index,
/// which covers the payloads' CRCs) and the scene's iso value.
#[derive(Debug, Clone, PartialEq)]
struct MemoKey {
    path: std::path::PathBuf,
    len: u64,
    checksum: u32,
    narrow: Option<u32>,
}

/// The 1-cells of the scene `opts` renders from `vol` (the file's
/// classification, narrowed by `opts.iso`) as framing sees them, `None`
/// when the scene has none: found as the module doc says, without
/// decoding every brick. A brick that cannot be decoded counts as full of
/// 1-cells (the render reports it when a ray reads it). Remembered per
/// file and scene for the process.
pub fn object(vol: &PackedVolume, opts: &RenderOptions) -> Option<Object> {
    let narrow = crate::render::options::narrowing(vol.header(), opts);
    let key = MemoKey {
        path: vol.path().to_path_buf(),
        len: vol.file_len(),
        checksum: vol.checksum(),
        narrow: narrow.map(f32::to_bits),
    };
    let memo =
        |m: &Vec<(MemoKey, Option<Object>)>| m.iter().find(|e| e.0 == key).map(|e| e.1.clone());
    if let Some(o) = memo(&MEMO.lock().unwrap_or_else(|e| e.into_inner())) {
        return o;
    }
    let mut finder = ObjectFinder::new(vol, narrow);
    let found = finder.cells().map(|cells| Object {
        bounds: mm_box(vol, cells),
        outline: finder.outline(cells),
    });
    let mut m = MEMO.lock().unwrap_or_else(|e| e.into_inner());
    if memo(&m).is_none() {
        if m.len() >= MEMO_LEN {
            m.remove(0);
        }
        m.push((key, found.clone()));
    }
    found
}

/// [`Object::bounds`] of [`object`]: the box in mm of the scene's
/// 1-cells, exact to the cell.
pub fn object_box(vol: &PackedVolume, opts: &RenderOptions) -> Option<MmBox> {
    object(vol, opts).map(|o| o.bounds)
}

/// The box in mm of cells `[lo, hi]`.
fn mm_box(vol: &PackedVolume, (lo, hi): CellBox) -> MmBox {
    let axes = &vol.header().axes;
    let c = |k: usize, i: u64| axes[k].coords()[i as usize];
    (
        std::array::from_fn(|k| c(k, lo[k])),
        std::array::from_fn(|k| c(k, hi[k] + 1)),
    )
}

/// Finds the box of a scene's 1-cells face by face (module doc).
struct ObjectFinder<'v> {
    vol: &'v PackedVolume,
    narrow: Option<f32>,
    /// Per brick: whether it may hold a 1-cell of the scene.
    may: Vec<bool>,
    /// Decoded bricks' boxes of 1-cells (global cells).
    seen: HashMap<u64, Option<CellBox>>,
}

impl<'v> ObjectFinder<'v> {
    fn new(vol: &'v PackedVolume, narrow: Option<f32>) -> ObjectFinder<'v> {
        let may = vol
            .index()
            .iter()
            .map(|e| {
                !e.has_no_object()
                    && !matches!((narrow, e.value_max()),
                        (Some(iso), Some(m)) if crate::render::brick::to_f32(m) < iso)
            })
            .collect();
        ObjectFinder {
            vol,
            narrow,
            may,
            seen: HashMap::new(),
        }
    }

    /// The scene's box of 1-cells, `None` without one.
    fn cells(&mut self) -> Option<CellBox> {
        let h = self.vol.header();
        // The box of the bricks that may hold one, in brick coordinates.
        let (mut blo, mut bhi) = ([u64::MAX; 3], [0u64; 3]);
        for id in (0..self.may.len()).filter(|&i| self.may[i]) {
            let c = h.brick_coords(id as u64);
            for k in 0..3 {
                blo[k] = blo[k].min(c[k]);
                bhi[k] = bhi[k].max(c[k]);
            }
        }
        if blo[0] > bhi[0] {
            return None;
        }
        let mut lo = [0u64; 3];
        let mut hi = [0u64; 3];
        for k in 0..3 {
            lo[k] = self.face(k, false, blo[k]..=bhi[k])?;
            hi[k] = self.face(k, true, (blo[k]..=bhi[k]).rev())?;
        }
        Some((lo, hi))
    }

    /// [`Object::outline`] for the box of 1-cells `cells`.
    fn outline(&self, cells: CellBox) -> Vec<[f64; 3]> {
        let h = self.vol.header();
        // Per column (y, x) of bricks: the cells of its bricks that may
        // hold a 1-cell, clipped to `cells`.
        let mut columns: BTreeMap<(u64, u64), CellBox> = BTreeMap::new();
        for id in (0..self.may.len()).filter(|&i| self.may[i]) {
            let c = h.brick_coords(id as u64);
            let r: [(u64, u64); 3] = std::array::from_fn(|k| {
                let (a, b) = h.brick_cells(k, c[k]);
                (a.max(cells.0[k]), (b - 1).min(cells.1[k]))
            });
            if r.iter().any(|&(a, b)| a > b) {
                continue;
            }
            let col = columns
                .entry((c[1], c[0]))
                .or_insert((r.map(|r| r.0), r.map(|r| r.1)));
            col.0[2] = col.0[2].min(r[2].0);
            col.1[2] = col.1[2].max(r[2].1);
        }
        columns
            .into_values()
            .flat_map(|b| corners(mm_box(self.vol, b)))
            .collect()
    }

    /// The outermost cell index along axis `k` of a 1-cell, on the upper
    /// side when `upper`, searching the brick layers `layers` from the
    /// outside in.
    fn face(&mut self, k: usize, upper: bool, layers: impl Iterator<Item = u64>) -> Option<u64> {
        let h = self.vol.header();
        for layer in layers {
            let (c0, c1) = h.brick_cells(k, layer);
            // Bricks of the layer that may hold a 1-cell, with a lower
            // bound of how far in from the layer's face it begins.
            let mut list: Vec<(u64, u64)> = (0..self.may.len() as u64)
                .filter(|&id| self.may[id as usize] && h.brick_coords(id)[k] == layer)
                .map(|id| (self.depth_bound(id, k, upper), id))
                .collect();
            list.sort_unstable();
            let mut best: Option<u64> = None;
            for (bound, id) in list {
                if best.is_some_and(|b| b <= bound) {
                    break;
                }
                if let Some((lo, hi)) = self.extent(id) {
                    let depth = if upper { c1 - 1 - hi[k] } else { lo[k] - c0 };
                    best = Some(best.map_or(depth, |b| b.min(depth)));
                }
            }
            if let Some(d) = best {
                return Some(if upper { c1 - 1 - d } else { c0 + d });
            }
        }
        None
    }

    /// A lower bound of how many cells in from its face along axis `k`
    /// (the upper face when `upper`) brick `id`'s 1-cells begin: the
    /// smallest code of the neighbour outside that face when the index
    /// marks it empty (code `c`: no 1-cell within chessboard distance
    /// `c` of its cells, and those next to the face lie one cell from the
    /// brick's first layer), else 0.
    fn depth_bound(&self, id: u64, k: usize, upper: bool) -> u64 {
        let h = self.vol.header();
        let mut c = h.brick_coords(id);
        match upper {
            true if c[k] + 1 < h.bricks[k] => c[k] += 1,
            false if c[k] > 0 => c[k] -= 1,
            _ => return 0,
        }
        let e = self.vol.index()[h.brick_id(c) as usize];
        if e.has_no_object() {
            e.uniform_code as u64
        } else {
            0
        }
    }

    /// The box of brick `id`'s scene 1-cells in global cells, decoded once.
    fn extent(&mut self, id: u64) -> Option<CellBox> {
        if let Some(e) = self.seen.get(&id) {
            return *e;
        }
        // Codes and values only: a narrowed scene's 1-cells are judged
        // here as render/brick/envelope.rs judges them, without its codes.
        let e = match RBrick::decode(self.vol, id, Planes::NONE, false) {
            Ok((b, _)) => brick_extent(&b, self.narrow),
            Err(_) => {
                let h = self.vol.header();
                let c = h.brick_coords(id);
                let r: [(u64, u64); 3] = std::array::from_fn(|k| h.brick_cells(k, c[k]));
                Some((r.map(|r| r.0), r.map(|r| r.1 - 1)))
            }
        };
        self.seen.insert(id, e);
        e
    }
}

/// The box of decoded brick `b`'s 1-cells in global cells; with `narrow`,
/// of those that are 1-cells of the scene at that iso value: a vertex at
/// or above it (in f32, NaN never), as render/brick/envelope.rs keeps them.
fn brick_extent(b: &RBrick, narrow: Option<f32>) -> Option<CellBox> {
    let first = b.first.map(u64::from);
    let [nx, ny, nz] = b.cells.map(|c| c as usize);
    let whole = (
        first,
        std::array::from_fn(|k| first[k] + b.cells[k] as u64 - 1),
    );
    let p = match &b.codes {
        Codes::Uniform(c) => {
            return (*c == OBJECT && narrow.is_none() && nx * ny * nz > 0).then_some(whole)
        }
        Codes::Plane(p) => p,
    };
    let (mut lo, mut hi) = ([usize::MAX; 3], [0usize; 3]);
    for z in 0..nz {
        for y in 0..ny {
            let row = &p[(z * ny + y) * nx..][..nx];
            let one = |x: usize| {
                row[x] == OBJECT
                    && narrow.is_none_or(|iso| {
                        let v = b.vertices([x, y, z].map(|i| i as u32));
                        v.iter().any(|&v| v >= iso)
                    })
            };
            let Some(x0) = (0..nx).find(|&x| one(x)) else {
                continue;
            };
            let x1 = (x0..nx).rev().find(|&x| one(x)).unwrap_or(x0);
            for (k, (a, b)) in [(x0, x1), (y, y), (z, z)].into_iter().enumerate() {
                lo[k] = lo[k].min(a);
                hi[k] = hi[k].max(b);
            }
        }
    }
    (lo[0] != usize::MAX).then(|| {
        (
            std::array::from_fn(|k| first[k] + lo[k] as u64),
            std::array::from_fn(|k| first[k] + hi[k] as u64),
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::view::camera::orbit_dirs;

    fn ortho(cam: &Camera) -> f64 {
        match cam.projection {
            Projection::Ortho { frame_mm } => frame_mm,
            Projection::Persp { .. } => f64::NAN,
        }
    }

    /// A framing of a 200 mm cube with a 20 x 40 x 10 mm object off-centre.
    fn framing() -> Framing {
        Framing {
            object: Some(Object::from_box(([10.0, 20.0, 30.0], [30.0, 60.0, 40.0]))),
            ..Framing::volume(([0.0; 3], [200.0; 3]))
        }
    }

    #[test]
    fn ortho_views_fit_the_object_centred() {
        let f = framing();
        // Looking along +y (eye on -y), up +z: x across (20 mm), z up (10).
        let dir = ([0.0, -1.0, 0.0], [0.0, 0.0, 1.0]);
        let cam = orbit(&f, dir, None, None, 100, 100).unwrap();
        assert!((ortho(&cam) - 20.0 * MARGIN).abs() < 1e-9, "{cam:?}");
        // A wide image: the 10 mm height binds, not 20 mm / 4.
        let cam = orbit(&f, dir, None, None, 400, 100).unwrap();
        assert!((ortho(&cam) - 10.0 * MARGIN).abs() < 1e-9, "{cam:?}");
        // The centre pixel's ray passes through the box's centre.
        let cam = orbit(&f, dir, None, None, 101, 101).unwrap();
        let r = cam.ray(50, 50);
        assert!((r.origin.x - 20.0).abs() < 1e-9 && (r.origin.z - 35.0).abs() < 1e-9);
        // The eye is outside the volume's sphere.
        let vc = DVec3::splat(100.0);
        assert!((cam.eye - vc).length() > 100.0 * 3f64.sqrt());
        // An explicit frame keeps the centre.
        let cam = orbit(&f, dir, None, Some(77.0), 101, 101).unwrap();
        assert_eq!(ortho(&cam), 77.0);
        assert!((cam.ray(50, 50).origin.x - 20.0).abs() < 1e-9);
    }

    #[test]
    fn an_outline_without_the_box_corners_frames_tighter() {
        // A cross of two bars in the xy plane: seen along the diagonal its
        // outline spans x + y in 5..35, 15 either side of the box's
        // centre, where the box spans 0..40.
        let obj = Object {
            bounds: ([0.0; 3], [20.0, 20.0, 10.0]),
            outline: corners(([0.0, 5.0, 0.0], [20.0, 15.0, 10.0]))
                .into_iter()
                .chain(corners(([5.0, 0.0, 0.0], [15.0, 20.0, 10.0])))
                .collect(),
        };
        let f = Framing {
            object: Some(obj),
            ..Framing::volume(([0.0; 3], [100.0; 3]))
        };
        let cam = orbit(&f, orbit_dirs(45.0, 0.0), None, None, 65, 65).unwrap();
        let want = 30.0 / 2f64.sqrt() * MARGIN;
        assert!((ortho(&cam) - want).abs() < 1e-9, "{cam:?}");
        // The centre pixel's ray passes the box's centre.
        let o = cam.ray(32, 32).origin;
        assert!(
            (o.x + o.y - 20.0).abs() < 1e-9 && (o.z - 5.0).abs() < 1e-9,
            "{o}"
        );
    }

    #[test]
    fn turntables_fit_every_frame_and_no_object_frames_the_volume() {
        let dirs: Vec<Dir> = (0..4).map(|f| orbit_dirs(90.0 * f as f64, 0.0)).collect();
        let f = framing().fitted(&dirs, None, 64, 64);
        let frames: Vec<f64> = dirs
            .iter()
            .map(|&d| ortho(&orbit(&f, d, None, None, 64, 64).unwrap()))
            .collect();
        // From the side the 40 mm depth binds: every frame fits it.
        assert!(
            frames.iter().all(|&x| (x - 40.0 * MARGIN).abs() < 1e-9),
            "{frames:?}"
        );
        let none = Framing::volume(([0.0; 3], [200.0; 3]));
        let (b, u) = dirs[1];
        let got = orbit(&none, (b, u), None, None, 64, 64).unwrap();
        let want = Camera::orbit_dir(none.volume, b, u, None, None, 64, 64).unwrap();
        assert_eq!(got, want);
    }

    #[test]
    fn perspective_views_keep_every_corner_in_view() {
        let f = framing();
        let bounds = f.object.as_ref().unwrap().bounds;
        for (az, el) in [(0.0, 0.0), (35.0, 20.0), (120.0, -60.0)] {
            let cam = orbit(&f, orbit_dirs(az, el), Some(30.0), None, 80, 60).unwrap();
            let (hw, hh) = cam.half_extents();
            let mut widest: f64 = 0.0;
            for c in corners(bounds) {
                let p = DVec3::from_array(c) - cam.eye;
                let z = p.dot(cam.forward);
                assert!(z > 0.0);
                let (x, y) = (p.dot(cam.right) / z / hw, p.dot(cam.up) / z / hh);
                assert!(x.abs() <= 1.0 / MARGIN + 1e-9 && y.abs() <= 1.0 / MARGIN + 1e-9);
                widest = widest.max(x.abs()).max(y.abs());
            }
            // ... and the box is not framed loosely.
            assert!((widest - 1.0 / MARGIN).abs() < 1e-6, "{az},{el}: {widest}");
        }
        let dir = ([0.0, -1.0, 0.0], [0.0, 0.0, 1.0]);
        let e = orbit(&framing(), dir, Some(180.0), None, 8, 8);
        assert!(matches!(e, Err(CameraError::Fov { .. })));
    }
}
