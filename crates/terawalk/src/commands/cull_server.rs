//! `terawalk cull-server`: the occlusion switch's culling side over TCP (Govindaraju's thesis
//! ch. 3; docs/DESIGN.md, D7). Each client (`bench --cull-server`) gets a thread and its own
//! [`Walkthrough`] of the one store, whose frame pipeline culls the cameras the client sends
//! (select, stream, occlude with the occluders drawn depth only and nothing else drawn:
//! [`Walkthrough::cull_frame`]); the clusters a frame would draw go back as the
//! delta of 4-byte ids against what that client was sent last (tw-net). By default the clients'
//! renderers share one GPU device (`--own-devices`: one each).

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, Result};
use tw_frame::remote::ClusterIds;
use tw_frame::{FrameSettings, Occlusion, Walkthrough};
use tw_gpu::{GpuError, Renderer};
use tw_net::server::{serve, Culled, Culler, ServeSummary, ServerOptions};
use tw_net::transport::Listener;
use tw_net::{CameraRequest, StoreId};
use tw_runtime::{Camera, Projection, StreamOptions};
use tw_store::Store;

use crate::cli::CullServerArgs;

/// Makes a renderer of a size for a client (on the shared device, or a device of its own).
type RendererFactory = dyn Fn(u32, u32) -> Result<Renderer, GpuError> + Send + Sync;

pub fn run(args: CullServerArgs) -> Result<()> {
    let store = Arc::new(crate::commands::open_store(&args.store)?);
    let store_id = StoreId::of(&store);
    let ids = Arc::new(ClusterIds::new(&store));
    // One renderer now: no GPU is an error before any client connects, and `auto` resolves here.
    let base = Renderer::new_headless(64, 64)?;
    let occlusion = args.occlusion.resolve(&base);
    let adapter = base.adapter_summary();
    let gpu_memory = args.gpu_memory;
    let factory: Arc<RendererFactory> = if args.own_devices {
        Arc::new(move |w, h| {
            let mut r = Renderer::new_headless(w, h)?;
            r.set_gpu_budget(gpu_memory);
            Ok(r)
        })
    } else {
        let (device, queue) = base.device();
        let (device, queue, info) = (device.clone(), queue.clone(), base.info().clone());
        Arc::new(move |w, h| {
            let mut r = Renderer::from_device(device.clone(), queue.clone(), info.clone(), w, h)?;
            r.set_gpu_budget(gpu_memory);
            Ok(r)
        })
    };
    let timeout = Duration::from_millis(args.timeout_ms.max(1));
    let listener = Listener::bind(&args.listen, timeout)?;
    let stop = Arc::new(AtomicBool::new(false));
    {
        let stop = stop.clone();
        ctrlc::set_handler(move || stop.store(true, Ordering::Relaxed))
            .context("cannot install the Ctrl-C handler")?;
    }
    outln!(
        "listening on {} ({}; {}, occlusion {} unless the client names one; adapter: {adapter})",
        listener.local_addr()?,
        args.store.display(),
        store_id,
        occlusion.name()
    );
    let options = ServerOptions {
        store: store_id,
        name: format!("terawalk cull-server {}", env!("CARGO_PKG_VERSION")),
    };
    let summary = ServeSummary::default();
    let memory = args.memory;
    let started = Instant::now();
    serve(&listener, &options, &stop, &summary, |hello| {
        tracing::info!("client {:?}: culling with its own walkthrough", hello.client);
        Ok(WalkCuller {
            store: store.clone(),
            ids: ids.clone(),
            factory: factory.clone(),
            memory,
            occlusion,
            walk: None,
        })
    })?;
    outln!(
        "stopped after {:.1} s: {} client(s), {} refused, {} frames culled, {} sent",
        started.elapsed().as_secs_f64(),
        summary.clients.load(Ordering::Relaxed),
        summary.refused.load(Ordering::Relaxed),
        summary.frames.load(Ordering::Relaxed),
        crate::units::fmt_bytes(summary.bytes_sent.load(Ordering::Relaxed))
    );
    Ok(())
}

/// One client's culling: a walkthrough made at its first camera, at that camera's viewport.
struct WalkCuller {
    store: Arc<Store>,
    ids: Arc<ClusterIds>,
    factory: Arc<RendererFactory>,
    memory: u64,
    /// For requests that leave the strategy to the server.
    occlusion: Occlusion,
    walk: Option<Walkthrough>,
}

impl Culler for WalkCuller {
    fn cull(&mut self, request: &CameraRequest) -> Result<Culled, String> {
        let (camera, settings) = frame_of(request, self.occlusion)?;
        let walk = self.walkthrough(request.viewport).map_err(|e| format!("{e:#}"))?;
        // The visible set only: occluders depth only, no second pass, no colour.
        let drawn = walk.cull_frame(&camera, &settings).map_err(|e| e.to_string())?;
        let ids = drawn.drawn.iter().filter_map(|c| self.ids.id(c)).collect();
        Ok(Culled { ids, triangles: drawn.info.triangles })
    }
}

impl WalkCuller {
    /// The walkthrough, at `viewport`'s size (the pixel error and the occlusion tests depend on
    /// it): made at the first camera, its renderer replaced when the size changes.
    fn walkthrough(&mut self, viewport: [u32; 2]) -> Result<&mut Walkthrough> {
        let [w, h] = viewport;
        match &mut self.walk {
            Some(walk) if walk.renderer().size() == (w, h) => {}
            Some(walk) => {
                walk.replace_renderer((self.factory)(w, h)?);
            }
            None => {
                let stream = StreamOptions { budget_bytes: self.memory, ..Default::default() };
                self.walk = Some(Walkthrough::new(self.store.clone(), (self.factory)(w, h)?, stream)?);
            }
        }
        self.walk.as_mut().context("no walkthrough")
    }
}

/// The camera and settings a request asks for, checked (a peer's numbers are not trusted).
pub fn frame_of(r: &CameraRequest, server_occlusion: Occlusion) -> Result<(Camera, FrameSettings), String> {
    let v = |a: [f32; 3]| glam::Vec3::from_array(a);
    let projection = if r.flags & CameraRequest::ORTHOGRAPHIC != 0 {
        Projection::Orthographic { height: r.fovy }
    } else {
        Projection::Perspective { fovy: r.fovy }
    };
    let camera = Camera::with_projection(v(r.eye), v(r.target), v(r.up), projection, r.near, r.far)
        .map_err(|e| format!("frame {}: {e}", r.frame))?;
    let [w, h] = r.viewport;
    if !(1..=16384).contains(&w) || !(1..=16384).contains(&h) {
        return Err(format!("frame {}: viewport {w}x{h} outside 1..16384", r.frame));
    }
    if !(r.tau.is_finite() && r.tau >= 0.0) {
        return Err(format!("frame {}: pixel error {} is not a finite number ≥ 0", r.frame, r.tau));
    }
    let occlusion = match r.occlusion {
        CameraRequest::SERVER_OCCLUSION => server_occlusion,
        i => *Occlusion::ALL
            .get(i as usize)
            .ok_or_else(|| format!("frame {}: unknown occlusion strategy {i}", r.frame))?,
    };
    let settings = FrameSettings {
        tau: r.tau,
        frustum_culling: r.flags & CameraRequest::FRUSTUM_CULLING != 0,
        occlusion,
        wait_for_pages: r.flags & CameraRequest::WAIT_FOR_PAGES != 0,
        visible_pixels: r.visible_pixels,
        triangle_culling: r.flags & CameraRequest::TRIANGLE_CULLING != 0,
        shadows: None,
        section: Default::default(),
        transition: Default::default(),
    };
    Ok((camera, settings))
}

/// The request for frame `frame` of `camera` with `settings` at `viewport` (the inverse of
/// [`frame_of`]).
pub fn request_of(
    frame: u64,
    camera: &Camera,
    settings: &FrameSettings,
    viewport: (u32, u32),
) -> CameraRequest {
    let flag = |on: bool, bit: u8| if on { bit } else { 0 };
    CameraRequest {
        frame,
        eye: camera.eye.to_array(),
        target: camera.target.to_array(),
        up: camera.up.to_array(),
        fovy: match camera.projection {
            Projection::Perspective { fovy } => fovy,
            Projection::Orthographic { height } => height,
        },
        near: camera.near,
        far: camera.far,
        viewport: [viewport.0, viewport.1],
        tau: settings.tau,
        occlusion: Occlusion::ALL
            .iter()
            .position(|&o| o == settings.occlusion)
            .map_or(CameraRequest::SERVER_OCCLUSION, |i| i as u8),
        flags: flag(settings.frustum_culling, CameraRequest::FRUSTUM_CULLING)
            | flag(settings.triangle_culling, CameraRequest::TRIANGLE_CULLING)
            | flag(settings.wait_for_pages, CameraRequest::WAIT_FOR_PAGES)
            | flag(camera.is_orthographic(), CameraRequest::ORTHOGRAPHIC),
        visible_pixels: settings.visible_pixels,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn requests_carry_the_camera_and_settings_and_bad_ones_are_refused() {
        let camera = Camera::new(
            glam::Vec3::new(1.0, 2.0, 3.0),
            glam::Vec3::new(4.0, 2.0, 3.0),
            glam::Vec3::Z,
            1.0,
            0.01,
            100.0,
        )
        .unwrap();
        for occlusion in Occlusion::ALL {
            let settings = FrameSettings {
                tau: 2.0,
                frustum_culling: false,
                occlusion,
                wait_for_pages: true,
                visible_pixels: 3,
                triangle_culling: false,
                shadows: None,
                section: Default::default(),
                transition: Default::default(),
            };
            let r = request_of(5, &camera, &settings, (640, 480));
            assert_eq!(frame_of(&r, Occlusion::None).unwrap(), (camera, settings));
        }
        let r = request_of(5, &camera, &FrameSettings::default(), (640, 480));
        let bad = [
            CameraRequest { eye: [f32::NAN; 3], ..r },
            CameraRequest { viewport: [0, 480], ..r },
            CameraRequest { tau: -1.0, ..r },
            CameraRequest { occlusion: 9, ..r },
        ];
        for b in bad {
            assert!(frame_of(&b, Occlusion::None).unwrap_err().starts_with("frame 5:"));
        }
        let ortho = Camera { projection: Projection::Orthographic { height: 7.0 }, ..camera };
        let r_ortho = request_of(6, &ortho, &FrameSettings::default(), (640, 480));
        assert_eq!(frame_of(&r_ortho, Occlusion::None).unwrap().0, ortho);
        let flat = CameraRequest { fovy: 0.0, ..r_ortho };
        assert!(frame_of(&flat, Occlusion::None).unwrap_err().contains("orthographic view height"));
        let server = CameraRequest { occlusion: CameraRequest::SERVER_OCCLUSION, ..r };
        assert_eq!(frame_of(&server, Occlusion::Hzb).unwrap().1.occlusion, Occlusion::Hzb);
    }
}
