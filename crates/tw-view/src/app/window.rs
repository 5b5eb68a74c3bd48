//! The window and what draws into it, shared by the viewer with a scene ([`super::App`]) and
//! without one ([`super::empty::Empty`]): opening it with its device and egui, and presenting a
//! frame of the UI (with the window screenshot when one is due).

use std::path::PathBuf;
use std::sync::Arc;

use winit::event_loop::ActiveEventLoop;
use winit::window::Window;

use super::WindowState;
use crate::error::ViewError;
use crate::gfx::Gfx;

impl WindowState {
    /// Opens a window of `size` pixels titled "terawalk — `title`", its device and egui.
    pub(super) fn open(
        event_loop: &ActiveEventLoop,
        size: (u32, u32),
        title: &str,
    ) -> Result<WindowState, ViewError> {
        let attrs = Window::default_attributes()
            .with_title(format!("terawalk — {title}"))
            .with_inner_size(winit::dpi::PhysicalSize::new(size.0, size.1));
        let window = Arc::new(event_loop.create_window(attrs).map_err(|e| ViewError::Window(e.to_string()))?);
        let gfx = Gfx::new(window.clone(), event_loop.owned_display_handle())?;
        tracing::info!("window adapter: {}", gfx.adapter_summary());
        let ctx = egui::Context::default();
        let max_side = gfx.device.limits().max_texture_dimension_2d as usize;
        let egui = egui_winit::State::new(
            ctx,
            egui::ViewportId::ROOT,
            &*window,
            Some(window.scale_factor() as f32),
            None,
            Some(max_side),
        );
        Ok(WindowState { window, gfx, egui, scene_tex: None })
    }

    /// Presents the UI's output, capturing the whole window into `shot` when given; returns
    /// whether egui asks to be repainted at once, and what became of the screenshot (the
    /// message to show).
    pub(super) fn present_ui(
        &mut self,
        mut out: egui::FullOutput,
        shot: Option<PathBuf>,
    ) -> Result<(bool, Option<String>), ViewError> {
        self.egui.handle_platform_output(&self.window, out.platform_output);
        let jobs = self.egui.egui_ctx().tessellate(out.shapes, out.pixels_per_point);
        let mut captured = None;
        self.gfx.present(
            &self.window,
            &jobs,
            &mut out.textures_delta,
            out.pixels_per_point,
            shot.is_some().then_some(&mut captured),
        )?;
        let said = match (shot, captured) {
            (Some(p), Some(img)) => Some(match img.save_png(&p) {
                Ok(()) => format!("window screenshot {}", p.display()),
                Err(e) => format!("window screenshot failed: {e}"),
            }),
            _ => None,
        };
        let repaint =
            out.viewport_output.get(&egui::ViewportId::ROOT).is_some_and(|v| v.repaint_delay.is_zero());
        Ok((repaint, said))
    }
}
