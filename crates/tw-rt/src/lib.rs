//! terawalk's CPU ray tracing core: a wide SAH BVH over plain arrays, watertight triangle
//! tests, single rays and 8-ray packets, and a tiled image loop.
//!
//! The design follows the in-core part of Wald, Dietrich & Slusallek 2004 ("Interactive
//! out-of-core rendering framework for visualizing massively complex models"): fast coherent
//! primary rays on a per-block acceleration structure, with a top-level structure over blocks.
//! Here the blocks' structure is a [`TriangleBvh`] and the top level can be another [`Bvh`] whose
//! leaves are visited through [`Bvh::traverse`]'s closure; [`Trace`] is what [`trace_image`]
//! needs from either. Nothing here knows about the store: inputs are plain arrays.
//!
//! Pipeline, one module per step:
//! - [`build`](mod@build): binned SAH over primitive boxes (32 bins, all three axes), parallel
//!   with rayon for large nodes; median splits beyond depth 40 bound the depth. For triangles
//!   the SAH counts primitives in blocks of 4 (one SIMD group), which fills the leaves.
//! - `spatial_split`: opt-in for triangles ([`TriangleBvh::build_with`]), the same binned SAH
//!   over triangle references with spatial splits (Stich, Friedrich & Dietrich 2009, SBVH): a
//!   node may cut the triangles crossing a plane into both sides, each part with its clipped
//!   box, within a budget of 20 % more references ([`SpatialSplits`]). Tighter boxes for long
//!   triangles, but no faster on the models measured (see [`TriangleBvh::build_with`]).
//! - `wide`: the binary tree collapsed to 8-wide nodes (children's boxes as structure of arrays:
//!   one AVX2 register per plane; 8-wide measured faster than 4-wide for packets).
//! - `traverse`: single-ray closest-first traversal with a leaf visitor, an uninitialized
//!   stack, and prefetches of the children a node test finds.
//! - `triangle`: Woop/Benthin/Wald 2013 watertight intersection; leaves store up to 4
//!   triangles in SIMD order. One lane-generic implementation serves every path, so single
//!   rays, packets and the scalar reference return bit-identical hits.
//! - `packet`: 8-ray packets (4x2 pixels) with interval-arithmetic node culling for the whole
//!   packet, a per-ray box test of leaf children, and 8-lane triangle tests. The walk takes a
//!   leaf visitor and a lane mask, so a two-level scene ([`scene::cut::CutScene`]) walks its
//!   top level with 16-ray packets (8x2 pixels) and each cluster's BVH with the same packet
//!   for the rays that reach the cluster.
//! - `simd`: AVX2/FMA entry points chosen at run time, a portable fallback ([`Simd`]).
//! - [`camera`](mod@camera) and [`image`](mod@image): pinhole rays and [`trace_image`].
//! - [`proxy`]: Wald 2004's 18-direction proxies (§5.2), what a ray reaching missing geometry
//!   can be shaded from; [`scene::proxies`] makes them for a store's groups and draws a cut with
//!   pages missing the paper's way. Measured against the DAG's coarser levels and not the
//!   default (docs/DESIGN.md D8).
//!
//! Measured with `scripts/peer-embree.sh data/dragon_vrip.ply.gz --rounds 3` (Stanford dragon,
//! 871 K triangles, 1280x720, one primary ray per pixel centre, the model covering 47% of the
//! pixels, 2 threads; medians of 5 runs x 3 alternating rounds; Embree 3.13.5 at
//! `RTC_BUILD_QUALITY_HIGH`). The development VM is shared with other work, so rays per second
//! of on-CPU time per thread ("cpu") is the comparable column; wall-clock rates of the same run
//! were disturbed by other load.
//!
//! | | build s | MB | M rays/s (cpu) | / Embree 8 | M rays/s (wall) |
//! |---|---|---|---|---|---|
//! | tw-rt single rays | 0.86 | 60 | 12.6 | 0.50 | 6.0 |
//! | tw-rt 8-ray packets | 0.86 | 60 | 24.8 | 0.99 | 9.4 |
//! | obvhs 0.4 CWBVH, single rays | 3.9 | 67 | 6.3 | 0.25 | 1.7 |
//! | Embree `rtcIntersect1` | 1.6 | 63 | 14.6 | 0.58 | 7.2 |
//! | Embree `rtcIntersect8`, coherent | 1.6 | 63 | 25.1 | 1.00 | 12.1 |
//!
//! In a quiet moment of the same machine the wall-clock packet rates were 22.8 (tw-rt) and
//! 25.0 (Embree) M rays/s. obvhs traces one ray at a time through a compressed 8-wide BVH with
//! a non-watertight triangle test and has no packet path: a quarter of our packet rate on
//! primary rays, which is why the core is our own.
//!
//! Through a store's LOD cut (two levels: a top-level BVH over clusters, one BVH per
//! cluster), measured with `examples/cut_bench.rs` (single rays and packets alternating in one
//! process, 640x480, 2 threads, medians of 9; same shared VM, so again the "cpu" column):
//!
//! | view of the 10^8-triangle plant | cut | M rays/s (cpu) single | packets |
//! |---|---|---|---|
//! | interior (`examples/cut_bench.rs` names the cameras) | 8.6 K clusters, 853 K triangles | 5.7 | 24.2 |
//! | fly-over | 23 K clusters, 2.3 M triangles | 11.8 | 13.5 |
//!
//! Interior rays visit 3.1 clusters each, nearly always with all 16 rays of their packet, so
//! packets pay on both levels; fly-over rays mostly miss or reach one cluster with 6 of 16 of
//! their packet, and the profile's hot spots in both modes are loads of nodes and cluster
//! records (23 K clusters, 158 MiB of BVHs; prefetching the cluster records did not help).

// The lane loops index several arrays by the same lane on purpose: that is the shape the
// compiler's vectorizer maps onto SIMD registers.
#![allow(clippy::needless_range_loop)]

mod aabb;
pub mod build;
mod bvh;
pub mod camera;
pub mod image;
mod mesh;
mod packet;
pub mod proxy;
mod ray;
pub mod scene;
mod simd;
mod spatial_split;
mod traverse;
mod triangle;
mod validate;
mod wide;

pub use aabb::Aabb;
pub use build::BuildOptions;
pub use bvh::Bvh;
pub use camera::Camera;
pub use image::{trace_image, trace_image_with, Trace, TraceMode};
pub use mesh::{MeshError, TriangleBvh};
pub use packet::PACKET;
pub use ray::{Hit, Ray};
pub use simd::Simd;
pub use spatial_split::SpatialSplits;
pub use triangle::intersect_triangle;
