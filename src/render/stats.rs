//! Counters of a render (the `--stats` contract): rays, traversal steps,
//! hits and the brick cache's reads, per render, summed over the tiles of
//! a part and over the parts or frames of a job.

use std::time::Instant;

use crate::render::cache::{BrickCache, CacheCounters};
use crate::render::options::RenderOptions;
use crate::render::traverse::StepCounts;

/// Counters of a render (the `--stats` contract).
#[derive(Debug, Default, Clone, serde::Serialize, serde::Deserialize)]
pub struct Stats {
    pub rays: u64,
    pub steps: u64,
    pub macro_steps: u64,
    pub cell_steps: u64,
    pub hits: u64,
    /// Rays left untraced because no brick with 1-cells projects onto
    /// their pixel (render/view/cull.rs); counted in `rays`, not in `steps`.
    #[serde(default)]
    pub rays_culled: u64,
    /// Brick payloads read and decoded into the cache (a brick evicted
    /// and needed again counts again; two threads racing to decode the
    /// same brick count once).
    pub bricks_read: u64,
    /// Distinct bricks read: the share of the file the scene needed. In
    /// merged statistics (parts, frames) the sum of theirs, an upper bound.
    #[serde(default)]
    pub bricks_distinct: u64,
    /// Bricks without 1-cells the traversal crossed without reading them.
    pub bricks_skipped: u64,
    /// Bricks without 1-cells read again, with their values, for the
    /// smooth normals of hits next to them (render/sample/normals.rs, "Which
    /// brick a sample is read from"); not in `bricks_read` or
    /// `bricks_distinct`, but their bytes and seconds are in
    /// `bytes_decompressed` and `seconds_decode`.
    #[serde(default)]
    pub bricks_read_values: u64,
    pub cache_hits: u64,
    pub cache_misses: u64,
    pub bytes_decompressed: u64,
    pub peak_cache_bytes: u64,
    pub bricks_total: u64,
    pub seconds_total: f64,
    /// Seconds spent decoding bricks (read, zstd, values, codes, planes),
    /// summed over threads: can exceed `seconds_total` with several.
    #[serde(default)]
    pub seconds_decode: f64,
    /// The tiles' time summed over threads (what `seconds_decode`,
    /// `seconds_traverse` and `seconds_sample` split; `seconds_total`
    /// also holds set-up and colouring, and is wall time).
    #[serde(default)]
    pub seconds_tiles: f64,
    /// The traversal's share of `seconds_tiles` without decode, summed over
    /// threads: cells found, leaps taken. Estimated from one ray in 64
    /// (render/clock.rs); 0 for the template renderer.
    #[serde(default)]
    pub seconds_traverse: f64,
    /// The sampling and shading share of `seconds_tiles` without decode,
    /// summed over threads: hit tests, normals, light, MIP maxima, the
    /// composite's samples along runs of 1-cells. Estimated like
    /// `seconds_traverse`.
    #[serde(default)]
    pub seconds_sample: f64,
    /// System (kernel) CPU seconds of the process during the render,
    /// summed over threads: mostly the clearing of fresh pages for the
    /// bricks a cold frame decodes, which lands in `seconds_decode` too.
    /// Process-wide (`getrusage`); 0 where the platform gives no figure.
    #[serde(default)]
    pub seconds_system: f64,
    /// Page faults of the process during the render (minor and major),
    /// counted like `seconds_system`.
    #[serde(default)]
    pub page_faults: u64,
    /// Chunks of brick planes (2 MiB each) that asked for a huge page
    /// during the render, and how many of those took longer than
    /// [`SLOW_HUGE`](crate::memory::pool::SLOW_HUGE) to clear, after which
    /// the next ones stay on ordinary pages (cdvol::memory::pool); 0 where
    /// the plane pool is not the allocator (the library alone).
    #[serde(default)]
    pub huge_pages: u64,
    #[serde(default)]
    pub huge_pages_slow: u64,
    /// The traversal's stable name ([`Method::name`](crate::render::traverse::Method::name):
    /// `cd`, `cd min_leap=3`, `fvt`, `dda-chamfer no_switch`, ...; the
    /// template renderer prefixes `template `).
    pub traversal: String,
    /// [`Mode::name`](crate::render::Mode::name).
    pub mode: String,
    pub width: u32,
    pub height: u32,
    /// Where the view was placed: with `render --eye --target --up` and
    /// `--frame` (or `--fov`) it draws the same image, for another renderer
    /// or a later run. The first part's or frame's in merged statistics.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub camera: Option<CameraUsed>,
}

/// A placed camera as `render`'s exact-camera options spell it
/// ([`Camera::used`](crate::render::view::camera::Camera::used)).
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CameraUsed {
    pub eye: [f64; 3],
    /// A point on the view axis (1 mm ahead of the eye).
    pub target: [f64; 3],
    pub up: [f64; 3],
    /// Orthographic: the frame's height in mm.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame_mm: Option<f64>,
    /// Perspective: the vertical field of view in degrees.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fov_deg: Option<f64>,
}

impl Stats {
    /// The counters of a render with `opts` through `cache`, started at
    /// `t0`; `width` and `height` are the caller's to fill, and `traversal`
    /// is [`Method::name`](crate::render::traverse::Method::name) of `opts.method`.
    pub(crate) fn counted(
        rays: u64,
        hits: u64,
        steps: &StepCounts,
        cc: &CacheCounters,
        cache: &BrickCache,
        opts: &RenderOptions,
        t0: Instant,
    ) -> Stats {
        Stats {
            rays,
            steps: steps.steps,
            macro_steps: steps.macro_steps,
            cell_steps: steps.cell_steps,
            hits,
            rays_culled: 0,
            bricks_read: cc.bricks_read,
            bricks_distinct: cache.distinct_read(),
            bricks_skipped: cc.bricks_skipped,
            bricks_read_values: cc.bricks_read_values,
            cache_hits: cc.cache_hits,
            cache_misses: cc.cache_misses,
            bytes_decompressed: cc.bytes_decompressed,
            peak_cache_bytes: cache.peak_bytes() as u64,
            bricks_total: cache.volume().header().brick_count(),
            seconds_total: t0.elapsed().as_secs_f64(),
            seconds_decode: cc.decode_seconds,
            seconds_tiles: 0.0,
            seconds_traverse: 0.0,
            seconds_sample: 0.0,
            seconds_system: 0.0,
            page_faults: 0,
            huge_pages: 0,
            huge_pages_slow: 0,
            traversal: opts.method.name(),
            mode: opts.mode.name().into(),
            width: 0,
            height: 0,
            camera: None,
        }
    }

    /// The kernel's share since `k0` ([`KernelUse`](crate::render::clock::KernelUse)).
    pub(crate) fn set_kernel(&mut self, k0: crate::render::clock::KernelUse) {
        let k = crate::render::clock::KernelUse::since(k0);
        self.seconds_system = k.seconds_system;
        self.page_faults = k.page_faults;
        self.huge_pages = k.huge_pages;
        self.huge_pages_slow = k.huge_pages_slow;
    }

    /// Adds the counters of `o` (another part or frame): sums, except
    /// `peak_cache_bytes` (the larger); `seconds_total` sums too.
    pub fn merge(&mut self, o: &Stats) {
        self.rays += o.rays;
        self.steps += o.steps;
        self.macro_steps += o.macro_steps;
        self.cell_steps += o.cell_steps;
        self.hits += o.hits;
        self.rays_culled += o.rays_culled;
        self.bricks_read += o.bricks_read;
        self.bricks_distinct += o.bricks_distinct;
        self.bricks_skipped += o.bricks_skipped;
        self.bricks_read_values += o.bricks_read_values;
        self.cache_hits += o.cache_hits;
        self.cache_misses += o.cache_misses;
        self.bytes_decompressed += o.bytes_decompressed;
        self.peak_cache_bytes = self.peak_cache_bytes.max(o.peak_cache_bytes);
        self.seconds_total += o.seconds_total;
        self.seconds_decode += o.seconds_decode;
        self.seconds_tiles += o.seconds_tiles;
        self.seconds_traverse += o.seconds_traverse;
        self.seconds_sample += o.seconds_sample;
        self.seconds_system += o.seconds_system;
        self.page_faults += o.page_faults;
        self.huge_pages += o.huge_pages;
        self.huge_pages_slow += o.huge_pages_slow;
        if self.camera.is_none() {
            self.camera.clone_from(&o.camera);
        }
    }
}
