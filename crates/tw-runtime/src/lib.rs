//! The CPU side of terawalk's per-frame runtime (docs/DESIGN.md "Data flow": camera → select → …):
//!
//! - [`camera`]: the scene-space camera, perspective or orthographic, its matrices
//!   (right-handed, depth 0..1, optional reverse-Z) and the command-line camera string in input coordinates;
//! - [`frustum`]: frustum planes and box/sphere tests;
//! - [`fuzz`]: entry points of the fuzz targets that reach the runtime (path files, stores);
//! - [`hzb`]: the hierarchical Z-buffer and its conservative box test (GigaWalk's occlusion test);
//! - [`occlusion`]: two-pass occlusion culling of a cut against an HZB of last frame's visible set;
//! - [`light`]: the shadow-casting light (sun or point) and its command-line form;
//! - [`lod_error`]: the pixel error of an object-space error (docs/DESIGN.md, D3);
//! - [`shadow`]: shadow-map layers, the lookup rule, cross-culling of receivers and casters;
//! - [`select`]: the LOD cut and frustum culling of one frame over a store;
//! - [`cache`]: decoded pages under a memory budget, LRU, root pages pinned;
//! - [`availability`]: the availability rule (what may be drawn while pages are missing);
//! - [`stream`]: loader threads, per-frame requests by priority, selection that never waits;
//! - [`fit`]: the τ a streamed cut is raised to when its pages would not fit the budget;
//! - [`prefetch`]: the views whose pages the next frames will need;
//! - [`path`]: camera paths (one camera per frame) as JSON, for `path`, `bench` and the viewer;
//! - [`pathgen`]: automatic walkthrough paths (interior walk at eye height, fly-over).
//!
//! ```no_run
//! use tw_runtime::{Camera, InputCamera, PageCache, SelectOptions, Selector};
//! let store = tw_store::Store::open("scene.tw")?;
//! let camera = InputCamera::parse("10,5,1.7;40,5,1.7;0,0,1;70")?.to_scene(store.header())?;
//! let cache = PageCache::new(&store, 512 << 20);
//! cache.load_root_pages(&store);
//! let selector = Selector::new(&store);
//! let frame = selector.select(&store, &cache, &camera, &SelectOptions { tau: 1.0, ..Default::default() });
//! println!("{} clusters, {} triangles, {:?}", frame.clusters.len(), frame.triangles, frame.stats);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! Streaming (a frame never waits for the disk; docs/DESIGN.md, D4):
//!
//! ```no_run
//! use std::sync::Arc;
//! use tw_runtime::{InputCamera, SelectOptions, StreamOptions, Streamer};
//! let store = Arc::new(tw_store::Store::open("scene.tw")?);
//! let camera = InputCamera::parse("10,5,1.7;40,5,1.7;0,0,1;70")?.to_scene(store.header())?;
//! let mut streamer = Streamer::new(store, StreamOptions { budget_bytes: 512 << 20, ..Default::default() })?;
//! for _ in 0..100 {
//!     let frame = streamer.frame(&camera, &SelectOptions::default()); // select, request, prefetch
//!     // draw frame.selection.clusters from frame.pages
//!     println!("{}", serde_json::to_string(&frame.stats)?);
//! }
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod availability;
pub mod cache;
pub mod camera;
pub mod error;
pub mod fit;
pub mod frustum;
pub mod fuzz;
pub mod hzb;
pub mod light;
pub mod lod_error;
pub mod node_test;
pub mod occlusion;
pub mod path;
pub mod pathgen;
pub mod prefetch;
pub mod resolve;
pub mod section;
pub mod select;
pub mod shadow;
pub mod stream;
pub mod triangle_test;

pub use availability::{Availability, Requests};
pub use cache::{CacheStats, ClusterInfo, Eviction, Inserted, PageCache, PageState, ResidentPage};
pub use camera::{Camera, InputCamera, Projection};
pub use error::RuntimeError;
pub use frustum::{Containment, Frustum};
pub use hzb::{Hzb, HzbResult};
pub use light::{InputLight, Light};
pub use lod_error::LodMetric;
pub use node_test::{test_hierarchy, NodeTestOptions, NodeTestResult, NodeTestSwitch};
pub use occlusion::{OcclusionHistory, OcclusionSplit, OcclusionTest};
pub use path::{CameraPath, PathFrame};
pub use pathgen::{
    generate_path, GeneratedPath, OrthoHeight, PathGenError, PathOptions, PathPart, PathReport, RegionKind,
    WalkGrid, WalkParams,
};
pub use prefetch::{prefetch_views, CameraHistory, PrefetchOptions};
pub use resolve::SelectionPages;
pub use section::{Section, SectionBox, SectionError, SectionPlane, MAX_SECTION_PLANES};
pub use select::{ClusterRef, SelectOptions, SelectStats, Selection, Selector};
pub use shadow::{ShadowClass, ShadowLayer, Shadows, TriangleClasses};
pub use stream::{StreamFrame, StreamOptions, StreamStats, StreamTimes, Streamer};
pub use triangle_test::{
    full_mask, test_triangles, visible_triangles, visible_triangles_assuming, TriangleMask,
};
