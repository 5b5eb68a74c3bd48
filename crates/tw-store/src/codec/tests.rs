//! Tests of the page codec: round trips of every position mode, canonical form, the encoder's
//! limits, and a decoder that rejects damaged bytes without panicking.

use super::*;

/// A `w`×`h` grid of quads (2 triangles each) at grid spacing `step`, starting at `base`,
/// split into clusters of ≤ 128 triangles (8×8 quads each), object id per row band.
pub(crate) fn grid_clusters(
    w: u32,
    h: u32,
    step: u32,
    base: [u32; 3],
    objects_per_cluster: u32,
) -> Vec<PageCluster> {
    let mut out = Vec::new();
    for by in (0..h).step_by(8) {
        for bx in (0..w).step_by(8) {
            let (nx, ny) = ((w - bx).min(8), (h - by).min(8));
            let mut c = PageCluster {
                self_sphere: [1.0, 2.0, 3.0, 4.0],
                group: out.len() as u32,
                ..Default::default()
            };
            for y in 0..=ny {
                for x in 0..=nx {
                    let gx = (bx + x) * step;
                    let gy = (by + y) * step;
                    // A gentle height field so z varies too.
                    let gz = ((gx / 7 + gy / 5) % 97) * step / 4;
                    c.positions.push([base[0] + gx, base[1] + gy, base[2] + gz]);
                }
            }
            for y in 0..ny {
                for x in 0..nx {
                    let i = (y * (nx + 1) + x) as u8;
                    let j = i + 1;
                    let k = i + nx as u8 + 1;
                    let l = k + 1;
                    let o = 7 + (y * objects_per_cluster / ny.max(1));
                    c.indices.extend_from_slice(&[i, j, l, i, l, k]);
                    c.objects.extend_from_slice(&[o, o]);
                }
            }
            out.push(c);
        }
    }
    out
}

fn round_trip(clusters: &[PageCluster], force: Option<PositionMode>) -> usize {
    let mut bytes = Vec::new();
    let s = encode_page_with(clusters, &mut bytes, force).unwrap();
    assert_eq!(s.encoded_len, bytes.len());
    let back = decode_page(&bytes, clusters.len()).unwrap();
    for (a, b) in clusters.iter().zip(&back) {
        assert_eq!(&a.canonical(), b);
    }
    bytes.len()
}

#[test]
fn every_position_mode_round_trips() {
    let cs = grid_clusters(24, 16, 3, [1000, 2000, 3000], 3);
    for mode in [PositionMode::Packed, PositionMode::Delta, PositionMode::Meshopt] {
        round_trip(&cs, Some(mode));
    }
    round_trip(&cs, None);
}

#[test]
fn clusters_encoded_apart_make_the_same_page() {
    let mut cs = grid_clusters(24, 16, 3, [1000, 2000, 3000], 3);
    cs[1].level = 3;
    let mut whole = Vec::new();
    let expected = encode_page(&cs, &mut whole).unwrap();
    // Encoded one by one under another group id, which is set afterwards.
    let encoded: Vec<EncodedCluster> = cs
        .iter()
        .map(|c| {
            let mut e = EncodedCluster::new(&PageCluster { group: 12345, ..c.clone() }).unwrap();
            assert_eq!(e.group(), 12345);
            e.set_group(c.group);
            assert_eq!(e.group(), c.group);
            e
        })
        .collect();
    let mut apart = vec![0xAB];
    let s = encoded_page(&encoded, &mut apart).unwrap();
    assert_eq!(&apart[1..], &whole[..]);
    assert_eq!(s, expected);
    assert_eq!((s.level_min, s.level_max), (0, 3));
    assert!(encoded_page(&[], &mut apart).is_err());
    let bad = PageCluster { indices: vec![0, 1], ..cs[0].clone() };
    assert!(EncodedCluster::new(&bad).is_err());
}

#[test]
fn triangles_rotate_to_their_smallest_rotation() {
    for a in 0..5u8 {
        for b in 0..5u8 {
            for c in 0..5u8 {
                let mut t = [a, b, c];
                rotate_triangles(&mut t);
                let best = [[a, b, c], [b, c, a], [c, a, b]].into_iter().min().unwrap();
                assert_eq!(t, best, "{a} {b} {c}");
            }
        }
    }
}

#[test]
fn a_threads_reused_buffers_do_not_leak_into_the_next_cluster() {
    // Clusters of different sizes and object counts, one after the other on this thread,
    // each against a fresh thread's encoding of it alone.
    let mut cs = grid_clusters(24, 16, 3, [1000, 2000, 3000], 3);
    cs.extend(grid_clusters(3, 2, 5, [7, 8, 9], 1));
    cs.extend(grid_clusters(16, 16, 1, [0, 0, 0], 5));
    for c in &cs {
        let here = EncodedCluster::from_parts(c.parts()).unwrap();
        let alone = std::thread::scope(|s| s.spawn(|| EncodedCluster::new(c).unwrap()).join().unwrap());
        assert_eq!(here, alone);
    }
}

#[test]
fn extreme_coordinates_round_trip() {
    let c = PageCluster {
        positions: vec![[0, u32::MAX, 5], [u32::MAX, 0, 5], [7, 7, u32::MAX]],
        indices: vec![0, 1, 2, 2, 1, 0],
        objects: vec![u32::MAX, 0],
        self_error: 0.5,
        self_sphere: [0.0; 4],
        group: u32::MAX,
        level: 255,
    };
    for mode in [PositionMode::Packed, PositionMode::Delta, PositionMode::Meshopt] {
        round_trip(std::slice::from_ref(&c), Some(mode));
    }
}

#[test]
fn degenerate_and_unused_vertices_round_trip() {
    let c = PageCluster {
        positions: vec![[1, 1, 1], [9, 9, 9], [2, 3, 4], [5, 5, 5]],
        indices: vec![2, 2, 0, 0, 2, 3],
        objects: vec![4, 4],
        ..Default::default()
    };
    let canon = c.canonical();
    assert_eq!(canon.positions, vec![[2, 3, 4], [1, 1, 1], [5, 5, 5], [9, 9, 9]]);
    assert_eq!(canon.indices, vec![0, 0, 1, 0, 2, 1]);
    round_trip(&[c], None);
}

#[test]
fn canonical_keeps_winding_and_triangle_order() {
    let c = PageCluster {
        positions: vec![[0; 3], [1, 0, 0], [0, 1, 0], [1, 1, 0]],
        indices: vec![3, 1, 2, 2, 1, 0],
        objects: vec![1, 2],
        ..Default::default()
    };
    let k = c.canonical();
    for t in 0..2 {
        let orig: Vec<[u32; 3]> = (0..3).map(|i| c.positions[c.indices[3 * t + i] as usize]).collect();
        let new: Vec<[u32; 3]> = (0..3).map(|i| k.positions[k.indices[3 * t + i] as usize]).collect();
        let rotations: Vec<Vec<[u32; 3]>> =
            (0..3).map(|r| (0..3).map(|i| orig[(i + r) % 3]).collect()).collect();
        assert!(rotations.contains(&new), "triangle {t}: {new:?} is not a rotation of {orig:?}");
    }
    assert_eq!(k.objects, vec![1, 2]);
}

#[test]
fn encoder_rejects_invalid_clusters() {
    let ok = PageCluster {
        positions: vec![[0; 3]; 3],
        indices: vec![0, 1, 2],
        objects: vec![0],
        ..Default::default()
    };
    let mut out = Vec::new();
    let cases: Vec<(&str, PageCluster)> = vec![
        ("no triangles", PageCluster { indices: vec![], objects: vec![], ..ok.clone() }),
        ("index range", PageCluster { indices: vec![0, 1, 3], ..ok.clone() }),
        ("objects", PageCluster { objects: vec![], ..ok.clone() }),
        ("too many", PageCluster { indices: vec![0; 3 * 129], objects: vec![0; 129], ..ok.clone() }),
        ("vertices", PageCluster { positions: vec![[0; 3]; 256], ..ok.clone() }),
        ("nan error", PageCluster { self_error: f32::NAN, ..ok.clone() }),
        ("inf error", PageCluster { self_error: f32::INFINITY, ..ok.clone() }),
        ("sphere", PageCluster { self_sphere: [0.0, 0.0, 0.0, -1.0], ..ok.clone() }),
    ];
    for (name, c) in cases {
        assert!(encode_page(&[c], &mut out).is_err(), "{name} accepted");
    }
    assert!(encode_page(&[], &mut out).is_err());
    assert!(encode_page(&[ok], &mut out).is_ok());
}

#[test]
fn decoder_rejects_short_trailing_and_overcounted_pages() {
    let cs = grid_clusters(16, 8, 1, [0; 3], 1);
    let mut bytes = Vec::new();
    encode_page(&cs, &mut bytes).unwrap();
    for len in 0..bytes.len() {
        assert!(decode_page(&bytes[..len], cs.len()).is_err(), "{len}-byte prefix decoded");
    }
    let mut longer = bytes.clone();
    longer.push(0);
    assert!(decode_page(&longer, cs.len()).unwrap_err().msg.contains("after the last cluster"));
    assert!(decode_page(&bytes, cs.len() + 1).is_err());
    assert!(decode_page(&bytes, 1_000_000_000).is_err());
}

#[test]
fn decoder_never_panics_on_flipped_bytes() {
    let mut cs = grid_clusters(16, 8, 5, [77, 0, 9], 4);
    cs[0].positions.iter_mut().for_each(|p| p[0] += 1 << 20);
    let mut bytes = Vec::new();
    encode_page(&cs, &mut bytes).unwrap();
    for i in 0..bytes.len() {
        for bit in [0x01, 0x80, 0xff] {
            let mut b = bytes.clone();
            b[i] ^= bit;
            if let Ok(back) = decode_page(&b, cs.len()) {
                for c in &back {
                    c.validate().unwrap();
                }
            }
        }
    }
}

#[test]
fn decoder_reports_out_of_range_indices_and_bad_modes() {
    let c = PageCluster {
        positions: vec![[0; 3]; 3],
        indices: vec![0, 1, 2],
        objects: vec![0],
        ..Default::default()
    };
    let mut bytes = Vec::new();
    encode_page(&[c], &mut bytes).unwrap();
    let mut b = bytes.clone();
    b[1] = 2; // claim 2 vertices: index 2 is now out of range (and the position block shrinks)
    assert!(decode_page(&b, 1).is_err());
    let mut b = bytes.clone();
    b[3] = 3;
    assert!(decode_page(&b, 1).unwrap_err().msg.contains("position mode"));
    let mut b = bytes;
    b[0] = 200;
    assert!(decode_page(&b, 1).unwrap_err().msg.contains("triangles"));
}

#[test]
fn varints_round_trip() {
    for v in [0, 1, 127, 128, 16383, 16384, u32::MAX] {
        let mut b = Vec::new();
        put_varint(&mut b, v);
        assert_eq!(b.len(), varint_len(v));
        assert_eq!(Cursor { bytes: &b, pos: 0 }.varint().unwrap(), v);
    }
    assert!(Cursor { bytes: &[0xff, 0xff, 0xff, 0xff, 0x7f], pos: 0 }.varint().is_err());
    assert!(Cursor { bytes: &[0x80; 6], pos: 0 }.varint().is_err());
}

/// Bytes per triangle of each position mode on a 10k-triangle height-field grid, at two grid
/// spacings (dense scan-like and sparse CAD-like). Run with `--nocapture` to see the numbers.
#[test]
fn compression_size_per_triangle() {
    for (step, label) in [(1u32, "spacing 1"), (37, "spacing 37"), (1021, "spacing 1021")] {
        let cs = grid_clusters(100, 50, step, [123_456, 654_321, 1_000], 1);
        let tris: usize = cs.iter().map(|c| c.triangle_count()).sum();
        assert_eq!(tris, 10_000);
        let mut line = format!("{label}: {} clusters", cs.len());
        let mut auto = 0;
        for (name, mode) in [
            ("packed", Some(PositionMode::Packed)),
            ("delta", Some(PositionMode::Delta)),
            ("meshopt", Some(PositionMode::Meshopt)),
            ("auto", None),
        ] {
            let len = round_trip(&cs, mode);
            line += &format!(", {name} {:.2} B/tri", len as f64 / tris as f64);
            auto = len;
        }
        println!("{line}");
        assert!((auto as f64 / tris as f64) < 6.0, "{line}");
    }
}

/// Encode and decode speed: `cargo test --release -p tw-store codec_throughput -- --ignored --nocapture`.
#[test]
#[ignore]
fn codec_throughput() {
    let cs = grid_clusters(1000, 500, 37, [123_456, 654_321, 1_000], 2);
    let tris: usize = cs.iter().map(|c| c.triangle_count()).sum();
    let t0 = std::time::Instant::now();
    let mut bytes = Vec::new();
    for page in cs.chunks(64) {
        encode_page(page, &mut bytes).unwrap();
    }
    let enc = t0.elapsed().as_secs_f64();
    let t0 = std::time::Instant::now();
    let mut pos = 0;
    let mut n = 0;
    for page in cs.chunks(64) {
        let mut one = Vec::new();
        let s = encode_page(page, &mut one).unwrap();
        let back = decode_page(&bytes[pos..pos + s.encoded_len], page.len()).unwrap();
        n += back.len();
        pos += s.encoded_len;
    }
    let dec = t0.elapsed().as_secs_f64() - enc; // the loop re-encodes to find page lengths
    assert_eq!(n, cs.len());
    println!(
        "{tris} triangles, {:.2} B/tri: encode {:.1} M tri/s, decode ~{:.1} M tri/s",
        bytes.len() as f64 / tris as f64,
        tris as f64 / enc / 1e6,
        tris as f64 / dec.max(1e-9) / 1e6
    );
}
