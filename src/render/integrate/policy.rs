//! What each traversal needs of the bricks, as the cache's plain
//! [`BrickPolicy`]: the one place that maps a [`Method`] to which planes
//! to build and when a brick may stand in unread. The cache itself never
//! sees the method.

use crate::format::reader::PackedVolume;
use crate::render::brick::Planes;
use crate::render::cache::{BrickCache, BrickPolicy, LAZY_MIN_CODE_CD};
use crate::render::traverse::{DistKind, Method};
use crate::render::RenderOptions;

/// The policy of `method`. FVT never needs the codes of a brick without
/// 1-cells, so it reads none; CD reads them unless the brick's smallest
/// code is already `cd_lazy_min` or more (below it the brick's own larger
/// codes leap further, docs/BENCHMARKS.md "Render levers"); city block and
/// chamfer DDA need the planes of every brick they cross (a stand-in
/// answers only the chessboard bound); the octree answers for bricks
/// without 1-cells from the index.
pub fn brick_policy(method: Method, cd_lazy_min: u8) -> BrickPolicy {
    let (stand_in_min, planes) = match method {
        Method::Fvt => (Some(0), Planes::NONE),
        Method::Cd { .. } => (Some(cd_lazy_min), Planes::NONE),
        Method::CdAniso { .. } => (
            Some(cd_lazy_min),
            Planes {
                octants: true,
                ..Planes::NONE
            },
        ),
        Method::Dda { kind, .. } => match kind {
            DistKind::Chessboard => (Some(cd_lazy_min), Planes::NONE),
            DistKind::Cityblock | DistKind::Chamfer => (
                None,
                Planes {
                    dda: true,
                    ..Planes::NONE
                },
            ),
        },
        Method::Octree => (
            Some(0),
            Planes {
                octree: true,
                ..Planes::NONE
            },
        ),
    };
    BrickPolicy {
        planes,
        stand_in_min,
    }
}

/// The brick cache a render with `opts` uses: its byte budget and the
/// planes its traversal needs ([`planes_for`]).
pub fn cache_for(vol: &PackedVolume, opts: &RenderOptions) -> BrickCache {
    BrickCache::with_planes(vol, opts.cache_bytes, planes_for(vol, opts))
}

/// The planes a render with `opts` needs beside each brick's codes and
/// values. A scene narrower than the file's classification (`render
/// --iso`) rewrites each brick for it ([`Planes::narrow`]).
pub fn planes_for(vol: &PackedVolume, opts: &RenderOptions) -> Planes {
    // The planes do not depend on the stand-in threshold.
    let mut planes = brick_policy(opts.method, LAZY_MIN_CODE_CD).planes;
    planes.narrow = crate::render::options::narrowing(vol.header(), opts);
    planes.grads = gradient_plane(opts) && planes.narrow.is_none();
    // MIP leaps out of nodes that cannot raise a ray's maximum, with the
    // traversals that leap (integrate/mip.rs).
    planes.block_max = matches!(opts.mode, crate::render::options::Mode::Mip)
        && super::mip_leaps_with(opts.method);
    planes
}

/// Whether the bricks carry a gradient plane
/// ([`Planes::grads`]): the f32 composite sampler with smooth gradients
/// (shading or gradient opacity), which asks for the 8 vertex gradients of
/// every cell it samples, many times per brick. 12 bytes per sample, 2.4
/// times a brick's values and codes, counted against the cache budget;
/// docs/BENCHMARKS.md ("Shaded composite: a gradient plane per brick").
pub fn gradient_plane(opts: &RenderOptions) -> bool {
    matches!(opts.mode, crate::render::options::Mode::Composite { .. })
        && opts.sampling == crate::render::options::Precision::F32
        && opts.normals == crate::render::sample::normals::Normals::Smooth
        && (opts.look.shade || !opts.look.gradient_opacity.is_empty())
}
