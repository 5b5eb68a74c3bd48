//! The render side of the cull server (tw_frame::remote): the global cluster numbering covers
//! every cluster once, in page order, and drawing a frame's drawn set again through
//! `draw_clusters` gives that frame's image (no culling of its own, nothing left out). GPU parts
//! on Vulkan (lavapipe), skipped without an adapter unless `TERAWALK_REQUIRE_GPU=1`.

use std::sync::Arc;

use tw_frame::remote::ClusterIds;
use tw_frame::{FrameSettings, Occlusion};
use tw_gpu::wgpu;
use tw_runtime::pathgen::{generate_path, PathOptions, PathPart};
use tw_runtime::ClusterRef;
use tw_store::Store;

mod common;

use common::gpu_lock;

fn plant() -> Arc<Store> {
    common::plant(100_000, 5)
}

#[test]
fn cluster_ids_number_every_cluster_once_in_page_order() {
    let store = plant();
    let ids = ClusterIds::new(&store);
    assert_eq!(ids.len() as u64, store.header().cluster_count);
    let mut next = 0u32;
    for (page, entry) in store.pages().iter().enumerate() {
        for index_in_page in 0..entry.cluster_count {
            let c = ids.cluster(next).unwrap();
            assert_eq!((c.page, c.index_in_page), (page as u32, index_in_page));
            let g = &store.groups()[c.group as usize];
            assert!(
                g.page == c.page
                    && (g.first_cluster..g.first_cluster + g.cluster_count).contains(&index_in_page)
            );
            assert_eq!(ids.id(&c), Some(next));
            next += 1;
        }
        let past = ClusterRef { page: page as u32, index_in_page: entry.cluster_count, group: 0 };
        assert_eq!(ids.id(&past), None, "an index past its page's clusters has no id");
    }
    assert_eq!(ids.cluster(next), None);
    assert_eq!(ids.cluster(u32::MAX), None);
    assert_eq!(ids.id(&ClusterRef { page: u32::MAX, index_in_page: 0, group: 0 }), None);
}

#[test]
fn drawing_a_frames_drawn_clusters_gives_its_image() {
    let _gpu = gpu_lock();
    let store = plant();
    let Some(mut walk) = common::walkthrough(store.clone(), wgpu::Backends::VULKAN, "remote", 256 << 20)
    else {
        return;
    };
    let options = PathOptions { frames: 24, part: PathPart::Walk, seed: 2, ..Default::default() };
    let path = generate_path(&store, &options, &mut |_, _, _| {}).unwrap().path;
    for occlusion in [Occlusion::None, Occlusion::Hzb] {
        let settings = FrameSettings { occlusion, wait_for_pages: true, ..Default::default() };
        walk.reset();
        for (i, f) in path.frames.iter().enumerate().step_by(4) {
            let camera = f.to_scene(store.header()).unwrap();
            let drawn = walk.draw_frame(&camera, &settings).unwrap();
            let local = walk.renderer_mut().read_color().unwrap();
            // As a client gets them: through the ids, in id order.
            let ids = ClusterIds::new(&store);
            let mut wire: Vec<u32> = drawn.drawn.iter().map(|c| ids.id(c).unwrap()).collect();
            wire.sort_unstable();
            let clusters: Vec<ClusterRef> = wire.iter().map(|&id| ids.cluster(id).unwrap()).collect();
            assert!(
                !clusters.is_empty() && local.covered_pixels() > 0,
                "{} frame {i}: nothing drawn",
                occlusion.name()
            );
            let (remote, info) = walk.frame_of_clusters(&camera, &clusters).unwrap();
            assert_eq!(info.clusters, clusters.len() as u64, "{} frame {i}", occlusion.name());
            assert!(
                local.differing_share(&remote).unwrap() == 0.0,
                "{} frame {i}: the drawn set drawn again gives another image",
                occlusion.name()
            );
        }
    }
}

/// A cull server's frame (`cull_frame`: occluders depth only, no second pass) finds the same
/// clusters as a drawn frame, frame after frame (the history evolves the same way), with every
/// strategy; and those clusters drawn give `none`'s image.
#[test]
fn culling_without_drawing_finds_what_a_frame_draws() {
    let _gpu = gpu_lock();
    let store = plant();
    let Some(mut walk) = common::walkthrough(store.clone(), wgpu::Backends::VULKAN, "cull_frame", 256 << 20)
    else {
        return;
    };
    let options = PathOptions { frames: 24, part: PathPart::Walk, seed: 2, ..Default::default() };
    let path = generate_path(&store, &options, &mut |_, _, _| {}).unwrap().path;
    let cameras: Vec<_> =
        path.frames.iter().step_by(3).map(|f| f.to_scene(store.header()).unwrap()).collect();
    let none = FrameSettings { occlusion: Occlusion::None, wait_for_pages: true, ..Default::default() };
    let baseline: Vec<_> = cameras.iter().map(|c| walk.frame(c, &none).unwrap().0).collect();
    for occlusion in [Occlusion::None, Occlusion::Hzb, Occlusion::Queries, Occlusion::GpuHzb] {
        let settings = FrameSettings { occlusion, wait_for_pages: true, ..Default::default() };
        walk.reset();
        let drawn: Vec<Vec<ClusterRef>> =
            cameras.iter().map(|c| walk.draw_frame(c, &settings).unwrap().drawn).collect();
        walk.reset();
        let mut culled_any = 0;
        for (i, c) in cameras.iter().enumerate() {
            let culled = walk.cull_frame(c, &settings).unwrap();
            culled_any += culled.occluded.len();
            let (mut a, mut b) = (culled.drawn.clone(), drawn[i].clone());
            a.sort_by_key(|c| (c.page, c.index_in_page));
            b.sort_by_key(|c| (c.page, c.index_in_page));
            assert_eq!(
                a,
                b,
                "{} frame {i}: cull_frame and draw_frame found other clusters",
                occlusion.name()
            );
            let (image, _) = walk.frame_of_clusters(c, &culled.drawn).unwrap();
            assert_eq!(
                image.differing_pixels(&baseline[i]).unwrap(),
                0,
                "{} frame {i}: the culled set does not give none's image",
                occlusion.name()
            );
        }
        if matches!(occlusion, Occlusion::Hzb | Occlusion::Queries) {
            assert!(culled_any > 0, "{}: nothing culled on the walk", occlusion.name());
        }
    }
}
