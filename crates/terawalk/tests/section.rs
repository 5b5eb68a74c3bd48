//! `terawalk render --section / --section-box` (tw_runtime::section): a plane between two cubes
//! removes exactly one cube's pixels and leaves the other's identical to the frame without a
//! section; a box does the same; a plane through both cubes shows their insides in the flat
//! section colour; the ray tracer removes the same cube; bad sections are refused with a
//! message. On lavapipe; skipped without an adapter unless `TERAWALK_REQUIRE_GPU=1`.

use std::path::Path;
use std::sync::OnceLock;

#[allow(dead_code)] // stdout is not used here.
mod common;

use common::{no_gpu, stderr, terawalk};

/// The renderer's background (sRGB).
const BACKGROUND: [u8; 3] = [205, 218, 235];
/// tw_core::color::SECTION.
const SECTION: [u8; 3] = [200, 30, 60];

/// Two unit cubes, `west` at x 0..1 and `east` at x 3..4 (y, z 0..1), wound counter-clockwise
/// seen from outside (glTF's convention, which the section colour of back faces relies on),
/// built into a store once.
fn cubes() -> &'static Path {
    static STORE: OnceLock<(tempfile::TempDir, std::path::PathBuf)> = OnceLock::new();
    &STORE
        .get_or_init(|| {
            let dir = tempfile::tempdir().unwrap();
            let obj = common::wound_cubes_obj(&[("west", 0.0), ("east", 3.0)]);
            std::fs::write(dir.path().join("cubes.obj"), obj).unwrap();
            let o = terawalk(&["-q", "build", "cubes.obj", "-o", "cubes.tw", "--threads", "1"], dir.path());
            assert!(o.status.success(), "{}", stderr(&o));
            let p = dir.path().join("cubes.tw");
            (dir, p)
        })
        .1
}

/// Renders the cubes from the front and above into `name` with `extra` arguments; the pixels
/// (RGB) and the width, or `None` when skipped.
fn render(dir: &Path, name: &str, extra: &[&str]) -> Option<(Vec<[u8; 3]>, usize)> {
    let store = cubes().to_str().unwrap();
    let camera = "2,-5,3.5;2,0.5,0.3;0,0,1;45";
    let mut args = vec!["render", store, "-o", name, "--size", "320x200", "--error", "0", "--camera", camera];
    args.extend_from_slice(extra);
    let o = terawalk(&args, dir);
    if no_gpu(&o) {
        return None;
    }
    assert!(o.status.success(), "{}", stderr(&o));
    let decoder = png::Decoder::new(std::io::BufReader::new(std::fs::File::open(dir.join(name)).unwrap()));
    let mut reader = decoder.read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap();
    let px = buf[..info.buffer_size()].chunks_exact(4).map(|p| [p[0], p[1], p[2]]).collect();
    Some((px, info.width as usize))
}

/// Pixels of `img` in the columns `cols` that are not the background.
fn covered(img: &(Vec<[u8; 3]>, usize), cols: std::ops::Range<usize>) -> usize {
    img.0.iter().enumerate().filter(|(i, p)| cols.contains(&(i % img.1)) && **p != BACKGROUND).count()
}

/// Pixels in the columns `cols` where `a` and `b` differ.
fn differing(a: &(Vec<[u8; 3]>, usize), b: &(Vec<[u8; 3]>, usize), cols: std::ops::Range<usize>) -> usize {
    a.0.iter().zip(&b.0).enumerate().filter(|(i, (p, q))| cols.contains(&(i % a.1)) && p != q).count()
}

#[test]
fn a_plane_or_a_box_removes_exactly_one_cubes_pixels() {
    let dir = tempfile::tempdir().unwrap();
    let Some(whole) = render(dir.path(), "whole.png", &[]) else { return };
    let (west, east) = (0..160, 160..320);
    assert!(covered(&whole, west.clone()) > 500 && covered(&whole, east.clone()) > 500);
    // x ≥ 2 keeps `east` only; x ≤ 2 (a negative normal and offset) `west` only.
    let keep_east = render(dir.path(), "east.png", &["--section", "1,0,0,2"]).unwrap();
    assert_eq!(covered(&keep_east, west.clone()), 0, "west is removed");
    assert_eq!(differing(&keep_east, &whole, east.clone()), 0, "east is drawn as without a section");
    let keep_west = render(dir.path(), "west.png", &["--section", "-1,0,0,-2"]).unwrap();
    assert_eq!(covered(&keep_west, east.clone()), 0, "east is removed");
    assert_eq!(differing(&keep_west, &whole, west.clone()), 0, "west is drawn as without a section");
    // A box around `west` (negative corners parse).
    let boxed = render(dir.path(), "box.png", &["--section-box", "-1,-1,-1;1.5,2,2"]).unwrap();
    assert_eq!(boxed.0, keep_west.0, "the box keeps what the plane keeps");
    // The ray tracer looks through what the section removes too.
    let traced = render(dir.path(), "rt.png", &["--renderer", "rt"]).unwrap();
    let traced_east =
        render(dir.path(), "rt-east.png", &["--renderer", "rt", "--section", "1,0,0,2"]).unwrap();
    assert!(covered(&traced, west.clone()) > 500);
    assert_eq!(covered(&traced_east, west), 0, "rt: west is removed");
    assert_eq!(differing(&traced_east, &traced, east), 0, "rt: east is traced as without a section");
}

#[test]
fn a_cut_through_both_cubes_shows_their_insides_in_the_section_colour() {
    let dir = tempfile::tempdir().unwrap();
    let Some(whole) = render(dir.path(), "whole.png", &[]) else { return };
    let is_section = |p: &[u8; 3]| p.iter().zip(SECTION).all(|(&a, b)| (a as i32 - b as i32).abs() <= 2);
    assert_eq!(whole.0.iter().filter(|p| is_section(p)).count(), 0, "no inside shows uncut");
    // Keep z ≤ 0.5: seen from above, the lower halves' inner faces (back faces) show.
    let cut = render(dir.path(), "cut.png", &["--section", "0,0,-1,-0.5"]).unwrap();
    let inside = cut.0.iter().filter(|p| is_section(p)).count();
    assert!(inside > 1000, "{inside} pixels in the section colour");
    assert!(covered(&cut, 0..320) < covered(&whole, 0..320), "the upper halves are gone");
}

#[test]
fn bad_sections_are_refused_with_a_message() {
    let dir = tempfile::tempdir().unwrap();
    let store = cubes().to_str().unwrap();
    let run = |extra: &[&str]| {
        let mut args = vec!["render", store, "-o", "x.png"];
        args.extend_from_slice(extra);
        let o = terawalk(&args, dir.path());
        assert!(!o.status.success() && !stderr(&o).contains("panicked"), "{extra:?}: {}", stderr(&o));
        stderr(&o)
    };
    let seven: Vec<&str> = ["--section", "1,0,0,0"].repeat(7);
    assert!(run(&seven).contains("at most 6 section planes"));
    assert!(run(&["--section", "0,0,0,1"]).contains("must not be zero"));
    assert!(run(&["--section", "1,0,0"]).contains("4 numbers"));
    assert!(run(&["--section-box", "1,1,1;0,0,0"]).contains("must not exceed"));
}
