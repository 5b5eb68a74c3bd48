//! The store's length unit (the `units` string `terawalk build --units` records) in metres, and
//! the human-scale lengths derived from it: one definition for everything that walks through a
//! model at human scale (the generated paths of `terawalk path`, the viewer's walk mode), so a
//! millimetre model is walked 1700 units above its deck, not 1.7.

/// Eye height of a standing person, metres.
pub const EYE_HEIGHT_M: f64 = 1.7;
/// Walking speed, metres per second.
pub const WALK_SPEED_M_S: f64 = 1.4;
/// Standard gravity, metres per second squared.
pub const GRAVITY_M_S2: f64 = 9.81;
/// Radius of a walker's body (the walk mode's collision capsule), metres: `terawalk path`'s
/// agent radius (0.12 eye heights), so the generated walks fit the walker.
pub const WALKER_RADIUS_M: f64 = 0.2;
/// The top of a walker's head above the eye, metres.
pub const HEAD_ABOVE_EYE_M: f64 = 0.1;
/// The highest ledge a walker steps up onto, metres.
pub const STEP_HEIGHT_M: f64 = 0.35;

/// Metres per unit for a store's units string (case and surrounding blanks ignored; `""`, no
/// units recorded, is taken as metres); `None` for a unit this table does not know.
pub fn metres_per_unit(units: &str) -> Option<f64> {
    Some(match units.trim().to_ascii_lowercase().as_str() {
        "" | "m" | "meter" | "metre" | "meters" | "metres" => 1.0,
        "mm" | "millimeter" | "millimetre" | "millimeters" | "millimetres" => 1e-3,
        "cm" | "centimeter" | "centimetre" | "centimeters" | "centimetres" => 1e-2,
        "dm" => 0.1,
        "km" => 1e3,
        "in" | "inch" | "inches" => 0.0254,
        "ft" | "foot" | "feet" => 0.3048,
        "yd" | "yard" | "yards" => 0.9144,
        _ => return None,
    })
}

/// The suffix for lengths in messages and the HUD: the units string as recorded, or "units"
/// when the store records none.
pub fn unit_suffix(units: &str) -> &str {
    match units.trim() {
        "" => "units",
        u => u,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn known_units_in_metres() {
        assert_eq!(metres_per_unit(""), Some(1.0));
        assert_eq!(metres_per_unit("mm"), Some(1e-3));
        assert_eq!(metres_per_unit(" M "), Some(1.0));
        assert_eq!(metres_per_unit("Feet"), Some(0.3048));
        assert_eq!(metres_per_unit("parsec"), None);
    }

    #[test]
    fn suffix_names_missing_units() {
        assert_eq!(unit_suffix(""), "units");
        assert_eq!(unit_suffix(" mm "), "mm");
    }
}
