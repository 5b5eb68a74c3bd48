//! A frame's figures as the report records them (tw-report's `FrameRecord`), from the frame
//! pipeline's statistics (tw-frame's `FrameInfo`).

use tw_frame::FrameInfo;
use tw_report::FrameRecord;

/// Frame `i` of path segment `segment`: its times, counts, culling and streaming figures.
pub fn record(i: usize, segment: &str, info: &FrameInfo) -> FrameRecord {
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
    let st = &info.stream;
    FrameRecord {
        frame: i as u32,
        segment: segment.to_string(),
        frame_ms: ms(info.times.total),
        select_ms: ms(info.times.select),
        cut_ms: ms(info.times.select_cut),
        prefetch_ms: ms(info.times.select_prefetch),
        // The version-1 name of `culling_ms` (occlusion culling), kept equal to it. Frustum
        // culling has no time of its own: it is part of the selection (`select_ms`).
        cull_ms: ms(info.times.cull),
        upload_ms: ms(info.times.upload),
        render_ms: ms(info.times.render),
        triangles: info.triangles,
        masked_triangles: info.masked_triangles,
        cut_triangles: info.cut_triangles,
        clusters: info.clusters,
        nodes_visited: info.select.nodes_visited,
        nodes_culled_frustum: info.select.nodes_culled_frustum,
        nodes_culled_lod: info.select.nodes_culled_lod,
        nodes_culled_occlusion: info.occlusion.culled,
        occlusion_queries: info.occlusion.queries,
        occlusion_node_tests: info.occlusion.node_tests,
        occlusion_nodes_hidden: info.occlusion.nodes_hidden,
        culling_box_tests_ms: ms(info.times.cull_box_tests),
        culling_triangle_tests_ms: ms(info.times.cull_triangle_tests),
        culling_readback_ms: ms(info.times.cull_readback),
        culling_ms: ms(info.times.cull),
        resident_mb: st.resident_bytes as f64 / 1e6,
        gpu_resident_mb: info.gpu.resident_bytes as f64 / 1e6,
        disk_read_mb: st.bytes_read as f64 / 1e6,
        pages_requested: st.pages_requested,
        pages_loaded: st.pages_loaded,
        pages_evicted: st.pages_evicted,
        stalls_avoided: st.stalls_avoided,
        tau_scale: st.tau_scale as f64,
        groups_failed: info.select.groups_failed,
        shadow: (info.shadow.layers > 0).then(|| shadow_record(&info.shadow)),
        ..Default::default()
    }
}

/// The shadow stage's figures of a frame (set sizes as the thesis reports them, stage times).
fn shadow_record(s: &tw_frame::ShadowInfo) -> tw_report::ShadowRecord {
    let ms = |d: std::time::Duration| d.as_secs_f64() * 1e3;
    tw_report::ShadowRecord {
        layers: s.layers,
        layers_reused: s.layers_reused,
        light_clusters: s.sets.light_cut,
        light_triangles: s.light_triangles,
        light_drawn_triangles: s.light_drawn_triangles,
        light_visible_clusters: s.sets.light_visible,
        caster_clusters: s.sets.casters,
        caster_triangles: s.caster_triangles,
        lit_triangles: s.sets.triangles_lit,
        shadowed_triangles: s.sets.triangles_shadowed,
        partial_triangles: s.sets.triangles_partial,
        partial_clusters: s.sets.receivers_partial,
        refined_clusters: s.refined_receivers,
        refined_lit_triangles: s.refined_lit_triangles,
        refined_shadowed_triangles: s.refined_shadowed_triangles,
        receiver_clusters: s.sets.receivers_lit + s.sets.receivers_shadowed + s.sets.receivers_partial,
        total_ms: ms(s.total),
        select_ms: ms(s.select),
        draw_ms: ms(s.draw),
        readback_ms: ms(s.readback),
        classify_ms: ms(s.classify),
    }
}

/// How a report names a light.
pub fn light_name(light: &tw_runtime::Light) -> String {
    match light {
        tw_runtime::Light::Sun { towards } => {
            format!("sun towards ({:.2}, {:.2}, {:.2})", towards.x, towards.y, towards.z)
        }
        tw_runtime::Light::Point { position } => {
            format!("point light at ({:.1}, {:.1}, {:.1}) scene", position.x, position.y, position.z)
        }
    }
}
