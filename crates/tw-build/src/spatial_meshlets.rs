//! meshopt's spatial clusterizer (`meshopt_buildMeshletsSpatial`, fill weight 1) with level-0
//! in-meshlet reordering (`meshopt_optimizeMeshlet`), into buffers kept per thread: the cells'
//! DAG (`crate::clusterlod`) and HLOD (`crate::hlod`) call it for every cell and group.
//!
//! The calls are those of `meshopt::build_meshlets_spatial`, so the meshlets are the same (a
//! test compares them), but the wrapper allocates its output zero-filled on every call, sized by
//! `meshopt_buildMeshletsBound(.., min_triangles)` times the most vertices and triangles a
//! meshlet takes: about 33 bytes per input triangle for clusters of ≤ 128 triangles and ≤ 255
//! vertices. meshoptimizer.h (`meshopt_buildMeshlets`) gives the worst cases as one vertex and
//! one triangle byte per index; the buffers here are sized so and only ever grow.

use meshopt::ffi::{self, meshopt_Meshlet};
use meshopt::VertexDataAdapter;
use std::cell::RefCell;

thread_local! {
    /// One [`Scratch`] per build thread (cells and HLOD nodes are built in parallel).
    static SCRATCH: RefCell<Scratch> = RefCell::default();
}

/// The clusterizer's output buffers, kept from one call to the next.
#[derive(Default)]
struct Scratch {
    meshlets: Vec<meshopt_Meshlet>,
    vertices: Vec<u32>,
    triangles: Vec<u8>,
}

/// Clusters `indices` over `vertices` with limits `(max_vertices, min_triangles,
/// max_triangles)` and hands each meshlet to `meshlet(vertices, triangles)` in order: its
/// vertices (indices of `vertices`) and its triangles (three local indices each), reordered at
/// level 0. Panics on limits out of meshopt's range (≤ 256 vertices, ≤ 512 triangles) or an
/// index past the vertices: the callers' constants and meshes guarantee both.
pub(crate) fn spatial_meshlets(
    indices: &[u32],
    vertices: &VertexDataAdapter<'_>,
    (max_vertices, min_triangles, max_triangles): (usize, usize, usize),
    mut meshlet: impl FnMut(&[u32], &[u8]),
) {
    assert!(indices.len().is_multiple_of(3) && (3..=256).contains(&max_vertices));
    assert!(1 <= min_triangles && min_triangles <= max_triangles && max_triangles <= 512);
    assert!(indices.iter().all(|&i| (i as usize) < vertices.vertex_count));
    SCRATCH.with_borrow_mut(|scratch| {
        let count = scratch.build(indices, vertices, (max_vertices, min_triangles, max_triangles));
        for m in &scratch.meshlets[..count] {
            let (v0, vn) = (m.vertex_offset as usize, m.vertex_count as usize);
            let (t0, tn) = (m.triangle_offset as usize, m.triangle_count as usize * 3);
            meshlet(&scratch.vertices[v0..v0 + vn], &scratch.triangles[t0..t0 + tn]);
        }
    });
}

impl Scratch {
    /// The two meshopt calls, with arguments checked by [`spatial_meshlets`]; returns how many
    /// meshlets were written at the start of `self.meshlets`.
    fn build(
        &mut self,
        indices: &[u32],
        vertices: &VertexDataAdapter<'_>,
        (max_vertices, min_triangles, max_triangles): (usize, usize, usize),
    ) -> usize {
        // SAFETY: the bound only computes from its arguments, which are in its range.
        let bound = unsafe { ffi::meshopt_buildMeshletsBound(indices.len(), max_vertices, min_triangles) };
        let empty =
            meshopt_Meshlet { vertex_offset: 0, triangle_offset: 0, vertex_count: 0, triangle_count: 0 };
        grow(&mut self.meshlets, bound, empty);
        grow(&mut self.vertices, indices.len(), 0);
        grow(&mut self.triangles, indices.len(), 0);
        // SAFETY: the buffers hold the bound's meshlets and one element per index (the worst
        // cases meshoptimizer.h gives); the indices are below the adapter's vertex count and
        // the limits within the clusterizer's (checked by the caller).
        let count = unsafe {
            ffi::meshopt_buildMeshletsSpatial(
                self.meshlets.as_mut_ptr(),
                self.vertices.as_mut_ptr(),
                self.triangles.as_mut_ptr(),
                indices.as_ptr(),
                indices.len(),
                vertices.pos_ptr(),
                vertices.vertex_count,
                vertices.vertex_stride,
                max_vertices,
                min_triangles,
                max_triangles,
                1.0,
            )
        };
        for m in &self.meshlets[..count] {
            let (v0, vn) = (m.vertex_offset as usize, m.vertex_count as usize);
            let (t0, tn) = (m.triangle_offset as usize, m.triangle_count as usize);
            let (verts, tris) = (&mut self.vertices[v0..v0 + vn], &mut self.triangles[t0..t0 + tn * 3]);
            // SAFETY: the slices hold the meshlet's vertices and triangles (bounds-checked).
            unsafe { ffi::meshopt_optimizeMeshlet(verts.as_mut_ptr(), tris.as_mut_ptr(), tn, vn) };
        }
        count
    }
}

/// Lengthens `buffer` to at least `len` elements (filled with `value`); never shortens it.
fn grow<T: Copy>(buffer: &mut Vec<T>, len: usize, value: T) {
    if buffer.len() < len {
        buffer.resize(len, value);
    }
}
