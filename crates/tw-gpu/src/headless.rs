//! Quiet Vulkan start-up on machines without a display session.
//!
//! Mesa installs an implicit Vulkan layer with its drivers, `VK_LAYER_MESA_device_select`, that
//! asks the Wayland compositor (then the X server) which GPU is the session's default, to list
//! it first. Where no session runs (CI, ssh, containers) `XDG_RUNTIME_DIR` is unset, and
//! libwayland then prints `error: XDG_RUNTIME_DIR is invalid or not set in the environment.`
//! twice on stderr at every instance creation: two "errors" in the output of a run that
//! succeeds. With no session there is no default to ask for, so the layer is turned off there
//! (`NODEVICE_SELECT=1`, the layer's own switch). wgpu orders adapters by its power preference
//! either way. A user who selects a device through the layer (`MESA_VK_DEVICE_SELECT`,
//! `DRI_PRIME`) keeps it.

use std::ffi::OsString;

/// Whether the device-select layer should be turned off in a process whose environment
/// variable `name` has the value `var(name)`: no Wayland connection is possible (neither
/// `XDG_RUNTIME_DIR` nor `WAYLAND_SOCKET`), and nobody chose a device through the layer or
/// set its switch already.
pub fn device_select_is_noise(var: impl Fn(&str) -> Option<OsString>) -> bool {
    let set = |name: &str| var(name).is_some_and(|v| !v.is_empty());
    let no_wayland = !set("XDG_RUNTIME_DIR") && !set("WAYLAND_SOCKET");
    let chosen = set("MESA_VK_DEVICE_SELECT") || set("DRI_PRIME") || var("NODEVICE_SELECT").is_some();
    no_wayland && !chosen
}

/// Sets `NODEVICE_SELECT=1` where [`device_select_is_noise`] says so. Changes the process
/// environment: call it first thing in `main`, before any thread starts.
pub fn quiet_device_select() {
    if device_select_is_noise(|name| std::env::var_os(name)) {
        std::env::set_var("NODEVICE_SELECT", "1");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn env<'a>(vars: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<OsString> + 'a {
        move |name| vars.iter().find(|(k, _)| *k == name).map(|(_, v)| OsString::from(v))
    }

    #[test]
    fn off_only_without_a_session_and_without_a_choice() {
        assert!(device_select_is_noise(env(&[])));
        assert!(device_select_is_noise(env(&[("XDG_RUNTIME_DIR", ""), ("DISPLAY", ":99")])));
        assert!(!device_select_is_noise(env(&[("XDG_RUNTIME_DIR", "/run/user/1000")])));
        assert!(!device_select_is_noise(env(&[("WAYLAND_SOCKET", "3")])));
        assert!(!device_select_is_noise(env(&[("MESA_VK_DEVICE_SELECT", "10de:2335")])));
        assert!(!device_select_is_noise(env(&[("DRI_PRIME", "1")])));
        // The user's own setting of the switch, whatever it is, stays.
        assert!(!device_select_is_noise(env(&[("NODEVICE_SELECT", "")])));
    }
}
