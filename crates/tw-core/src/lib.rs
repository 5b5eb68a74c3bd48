//! Core types shared by every terawalk crate.
//!
//! - [`Aabb`]: axis-aligned bounds in f64 (input space, before rebasing to the scene origin).
//! - [`Rgba8`]: an sRGB colour with alpha, as importers and the store carry it.
//! - [`Rng`]: a small deterministic random generator (PCG-XSH-RR 64/32), so generated scenes are
//!   identical for a seed on every platform and every version of every dependency.
//!
//! ```
//! use tw_core::{Aabb, Rng};
//! let mut b = Aabb::EMPTY;
//! b.grow([1.0, 2.0, 3.0]);
//! b.grow([-1.0, 0.0, 5.0]);
//! assert_eq!(b.extent(), [2.0, 2.0, 2.0]);
//! let mut rng = Rng::new(42);
//! let x = rng.f64();
//! assert!((0.0..1.0).contains(&x));
//! ```

pub mod bounds;
pub mod cleanup;
pub mod color;
pub mod digits;
pub mod direct_io;
pub mod disk_space;
pub mod mem;
pub mod output;
pub mod printable;
pub mod regular_file;
pub mod release_behind;
pub mod rng;

pub use bounds::Aabb;
pub use color::Rgba8;
pub use rng::Rng;

/// Re-exported so that downstream crates use the same math types.
pub use glam;
