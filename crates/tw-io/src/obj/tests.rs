use std::io::Write;

use super::*;
use crate::MeshChunk;

/// A sink that keeps everything.
#[derive(Default)]
struct Collect {
    objects: Vec<(ObjectId, ObjectInfo)>,
    triangles: Vec<Triangle>,
    progress: Vec<u64>,
}

impl TriangleSink for Collect {
    fn object(&mut self, id: ObjectId, info: &ObjectInfo) -> Result<(), ImportError> {
        assert_eq!(id as usize, self.objects.len(), "ids are dense and in order");
        self.objects.push((id, info.clone()));
        Ok(())
    }

    fn triangle(&mut self, t: &Triangle) -> Result<(), ImportError> {
        assert!((t.object as usize) < self.objects.len(), "object announced first");
        self.triangles.push(*t);
        Ok(())
    }

    fn mesh(&mut self, _chunk: &MeshChunk<'_>) -> Result<(), ImportError> {
        unreachable!("the OBJ importer yields triangles")
    }

    fn progress(&mut self, done: u64) {
        self.progress.push(done);
    }
}

fn stream_input(input: Input, options: &ImportOptions) -> Result<(Collect, SourceSummary), ImportError> {
    let mut sink = Collect::default();
    let summary = open(input, options)?.stream(&mut sink)?;
    assert_eq!(summary.objects as usize, sink.objects.len());
    Ok((sink, summary))
}

fn load(text: &str) -> Result<(Collect, SourceSummary), ImportError> {
    load_bytes(text.as_bytes())
}

fn load_bytes(bytes: &[u8]) -> Result<(Collect, SourceSummary), ImportError> {
    stream_input(Input::from_bytes(Path::new("dir/part.obj"), bytes.to_vec()), &ImportOptions::default())
}

fn ok(text: &str) -> Collect {
    load(text).unwrap_or_else(|e| panic!("{e}")).0
}

/// Loads `text`, expecting an error on `line` whose message contains `needle`.
fn fails(text: &str, line: u64, needle: &str) {
    fails_bytes(text.as_bytes(), line, needle)
}

fn fails_bytes(bytes: &[u8], line: u64, needle: &str) {
    let e = load_bytes(bytes).err().expect("expected an error");
    assert_eq!(e.position(), Some(Position::Line(line)), "{e}");
    let msg = e.to_string();
    assert!(msg.starts_with(&format!("dir/part.obj: line {line}: ")), "{msg}");
    assert!(msg.contains(needle), "{msg:?} should contain {needle:?}");
}

fn positions(t: &Triangle) -> [[f64; 3]; 3] {
    t.positions
}

const SQUARE: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n";

#[test]
fn one_triangle_in_a_default_object_named_after_the_file() {
    let (c, s) = load("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    assert_eq!(s, SourceSummary { objects: 1, vertices: 3, bytes: 32 });
    assert_eq!(c.objects, vec![(0, ObjectInfo { name: "part".into(), color: None })]);
    assert_eq!(c.triangles, vec![Triangle::new([[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], 0)]);
}

#[test]
fn default_object_name_drops_gz_and_extension() {
    assert_eq!(file_stem(Path::new("/a/Pump.v2.obj.gz")), "Pump.v2");
    assert_eq!(file_stem(Path::new("noext")), "noext");
    assert_eq!(file_stem(Path::new(".hidden")), ".hidden");
}

#[test]
fn every_corner_form() {
    let text = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\nvn 0 0 2\nvn 0 0 3\n\
                f 1 2 3\nf 1/1 2/2 3/3\nf 1//1 2//2 3//3\nf 1/1/1 2/2/2 3/3/3\nf 1/ 2/ 3/\n";
    let c = ok(text);
    assert_eq!(c.triangles.len(), 5);
    for t in &c.triangles {
        assert_eq!(positions(t), [[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    }
    let n = Some([[0.0, 0.0, 1.0], [0.0, 0.0, 2.0], [0.0, 0.0, 3.0]]);
    let normals: Vec<_> = c.triangles.iter().map(|t| t.normals).collect();
    assert_eq!(normals, vec![None, None, n, n, None]);
}

#[test]
fn normals_only_when_every_corner_has_one() {
    let c = ok("v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2 3//1\n");
    assert_eq!(c.triangles[0].normals, None);
}

#[test]
fn negative_indices_count_back_from_the_latest() {
    let c = ok("v 9 9 9\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvn 1 0 0\nvt 0 0\nf -3/-1/-1 -2/-1/-1 -1/-1/-1\n");
    assert_eq!(positions(&c.triangles[0]), [[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    assert_eq!(c.triangles[0].normals, Some([[1.0, 0.0, 0.0]; 3]));
    // Relative to the vertices defined so far, not to the end of the file.
    let c = ok("v 0 0 0\nv 1 0 0\nv 0 1 0\nf -3 -2 -1\nv 5 5 5\nf -4 -3 -1\n");
    assert_eq!(positions(&c.triangles[1]), [[0.0; 3], [1.0, 0.0, 0.0], [5.0, 5.0, 5.0]]);
}

#[test]
fn polygons_are_fan_triangulated() {
    let c = ok(&format!("{SQUARE}v 0.5 2 0\nf 1 2 3 4\nf 1 2 3 5 4\n"));
    let p: Vec<_> = c.triangles.iter().map(positions).collect();
    let v = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0], [0.5, 2.0, 0.0]];
    assert_eq!(
        p,
        vec![
            [v[0], v[1], v[2]],
            [v[0], v[2], v[3]],
            [v[0], v[1], v[2]],
            [v[0], v[2], v[4]],
            [v[0], v[4], v[3]]
        ]
    );
}

#[test]
fn old_fo_keyword_is_a_face() {
    assert_eq!(ok("v 0 0 0\nv 1 0 0\nv 0 1 0\nfo 1 2 3\n").triangles.len(), 1);
}

#[test]
fn objects_and_groups() {
    let text = format!(
        "{SQUARE}f 1 2 3\no first\ng first_group\nf 1 2 3\nf 1 3 4\ng empty\no second\nf 1 2 3\n\
         g\nf 1 2 3\no trailing_without_faces\n"
    );
    let c = ok(&text);
    let names: Vec<_> = c.objects.iter().map(|(_, o)| o.name.as_str()).collect();
    assert_eq!(names, vec!["part", "first_group", "second", "part"]);
    let ids: Vec<_> = c.triangles.iter().map(|t| t.object).collect();
    assert_eq!(ids, vec![0, 1, 1, 2, 3]);
}

#[test]
fn group_names_keep_spaces_and_non_utf8_bytes() {
    let c = ok_bytes(b"v 0 0 0\nv 1 0 0\nv 0 1 0\ng  pipe\tA \xff \nf 1 2 3\n");
    assert_eq!(c.objects[0].1.name, "pipe\tA \u{fffd}");
}

fn ok_bytes(bytes: &[u8]) -> Collect {
    load_bytes(bytes).unwrap_or_else(|e| panic!("{e}")).0
}

fn write_files(files: &[(&str, &[u8])]) -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for (name, bytes) in files {
        let p = dir.path().join(name);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, bytes).unwrap();
    }
    dir
}

fn load_file(path: &Path) -> Result<(Collect, SourceSummary), ImportError> {
    stream_input(Input::open(path)?, &ImportOptions::default())
}

const MTL: &[u8] = b"newmtl red\nKd 1 0 0\nnewmtl green\nKd 0 1 0\nnewmtl plain\n";

#[test]
fn usemtl_gives_the_object_its_diffuse_colour() {
    let obj = format!(
        "mtllib mats/lib.mtl\n{SQUARE}usemtl red\nf 1 2 3\no pipe\nusemtl green\nf 1 2 3\n\
         usemtl plain\nf 1 2 3\n"
    );
    let dir = write_files(&[("mats/lib.mtl", MTL), ("m.obj", obj.as_bytes())]);
    let (c, _) = load_file(&dir.path().join("m.obj")).unwrap();
    let red = Some(Rgba8([255, 0, 0, 255]));
    let green = Some(Rgba8([0, 255, 0, 255]));
    assert_eq!(
        c.objects,
        vec![
            (0, ObjectInfo { name: "m".into(), color: red }),
            (1, ObjectInfo { name: "pipe".into(), color: green }),
            (2, ObjectInfo { name: "pipe/plain".into(), color: None }),
        ]
    );
}

#[test]
fn usemtl_change_inside_an_object_splits_it_and_switching_back_reuses() {
    let obj = format!(
        "mtllib lib.mtl\n{SQUARE}o valve\nf 1 2 3\nusemtl red\nf 1 2 3\nusemtl green\nf 1 2 3\n\
         usemtl red\nusemtl red\nf 1 2 3\no valve\nusemtl red\nf 1 2 3\n"
    );
    let dir = write_files(&[("lib.mtl", MTL), ("m.obj", obj.as_bytes())]);
    let (c, s) = load_file(&dir.path().join("m.obj")).unwrap();
    let names: Vec<_> = c.objects.iter().map(|(_, o)| o.name.as_str()).collect();
    assert_eq!(names, vec!["valve", "valve/red", "valve/green", "valve"]);
    let ids: Vec<_> = c.triangles.iter().map(|t| t.object).collect();
    assert_eq!(ids, vec![0, 1, 2, 1, 3]);
    assert_eq!(s.objects, 4);
    assert_eq!(c.objects[3].1.color, Some(Rgba8([255, 0, 0, 255])));
}

#[test]
fn mtllib_with_spaces_in_the_name_and_several_libraries() {
    let obj =
        format!("mtllib my lib.mtl\nmtllib a.mtl b.mtl\n{SQUARE}usemtl red\nf 1 2 3\nusemtl b\nf 1 2 3\n");
    let dir = write_files(&[
        ("my lib.mtl", MTL),
        ("a.mtl", b"newmtl a\nKd 0 0 1\n"),
        ("b.mtl", b"newmtl b\nKd 0 0 1\n"),
        ("m.obj", obj.as_bytes()),
    ]);
    let (c, _) = load_file(&dir.path().join("m.obj")).unwrap();
    assert_eq!(c.objects[0].1.color, Some(Rgba8([255, 0, 0, 255])));
    assert_eq!(c.objects[1].1.color, Some(Rgba8([0, 0, 255, 255])));
}

#[test]
fn missing_mtl_and_unknown_material_are_not_errors() {
    let obj = format!("mtllib nowhere.mtl\nmtllib\n{SQUARE}usemtl red\nf 1 2 3\n");
    let dir = write_files(&[("m.obj", obj.as_bytes())]);
    let (c, _) = load_file(&dir.path().join("m.obj")).unwrap();
    assert_eq!(c.objects, vec![(0, ObjectInfo { name: "m".into(), color: None })]);
}

#[test]
fn crlf_and_tabs() {
    let c = ok("v\t0 0 0\r\nv 1\t0 0 \r\n  v 0 1 0\r\n\r\no\tA\r\nf\t1 2\t3\r\n");
    assert_eq!(c.objects[0].1.name, "A");
    assert_eq!(positions(&c.triangles[0]), [[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
}

#[test]
fn no_newline_at_the_end() {
    assert_eq!(ok("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3").triangles.len(), 1);
}

#[test]
fn byte_order_mark_is_skipped() {
    assert_eq!(ok("\u{feff}v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").triangles.len(), 1);
}

#[test]
fn continuation_lines() {
    let c = ok("v 0 0 0\nv 1 \\\n 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 \\\r\n3 \\  \n4\n# comment \\\nf 1 2 3\n");
    assert_eq!(c.triangles.len(), 3);
    assert_eq!(positions(&c.triangles[0])[1], [1.0, 0.0, 0.0]);
    assert_eq!(positions(&c.triangles[1])[2], [0.0, 0.0, 1.0]);
}

#[test]
fn continued_statement_reports_its_first_line() {
    fails("v 0 0 0\nf 1 \\\n2 \\\n3\n", 2, "vertex index 2 is out of range");
}

#[test]
fn continuation_at_the_end_of_the_file() {
    assert_eq!(ok("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3 \\\n").triangles.len(), 1);
}

#[test]
fn vertex_colours() {
    let c = ok("v 0 0 0\nv 0 0 1 1 0 0\nv 1 0 0 0 1 0\nv 0 1 0 0 0 1\nf 2 3 4\nf 1 2 3\n");
    let rgb = [Rgba8([255, 0, 0, 255]), Rgba8([0, 255, 0, 255]), Rgba8([0, 0, 255, 255])];
    assert_eq!(c.triangles[0].colors, Some(rgb));
    assert_eq!(c.triangles[1].colors, None, "vertex 1 has no colour");
    let c = ok("v 0 0 0 1 0 0\nv 1 0 0\nv 0 1 0 0 0 1\nf 1 2 3\nf -3 -1 -3\n");
    assert_eq!(c.triangles[0].colors, None, "vertex 2 has no colour");
    assert_eq!(c.triangles[1].colors, Some([rgb[0], rgb[2], rgb[0]]));
}

#[test]
fn vertex_weight_is_ignored() {
    let c = ok("v 0 0 0 1\nv 1 0 0 0.5\nv 0 1 0 2\nf 1 2 3\n");
    assert_eq!(positions(&c.triangles[0]), [[0.0; 3], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
    assert_eq!(c.triangles[0].colors, None);
}

#[test]
fn numbers_in_every_notation() {
    let c = ok("v 1e2 -2.5E-1 +3.\nv .5 -0 1234567890123456789012\nv 0.1 0.2 0.3\nf 1 2 3\n");
    let [a, b, d] = positions(&c.triangles[0]);
    assert_eq!(a, [100.0, -0.25, 3.0]);
    assert_eq!(b, [0.5, 0.0, 1234567890123456789012.0]);
    assert_eq!(d, [0.1, 0.2, 0.3]);
}

#[test]
fn skipped_statements() {
    let text = format!(
        "# comment\n\n   \nmtllib\ns 1\ns off\nl 1 2\np 1\nvp 0.5 0.5\ncstype bezier\ncurv 0 1 1 2\n\
         end\nmg 1\nlod 1\nbevel off\nusemap off\ncall other.obj\ncsh rm -rf /\nfrobnicate 1 2\n\
         frobnicate again\nusemtl\n{SQUARE}f 1 2 3\n"
    );
    let (c, s) = load(&text).unwrap();
    assert_eq!(c.triangles.len(), 1);
    assert_eq!(s.vertices, 4);
}

#[test]
fn non_utf8_bytes_in_comments_are_fine() {
    assert_eq!(ok_bytes(b"# \xff\xfe\x00 caf\xe9\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").triangles.len(), 1);
}

#[test]
fn progress_and_summary_bytes() {
    let (c, s) = load(&format!("{SQUARE}f 1 2 3\n")).unwrap();
    assert_eq!(s.bytes, (SQUARE.len() + 8) as u64);
    assert_eq!(c.progress.last(), Some(&s.bytes));
}

#[test]
fn lines_straddling_buffer_fills() {
    // More than one read buffer (1 MiB), with lines of every length across the boundary.
    let mut text = String::new();
    let mut expected = 0;
    for i in 0..60_000 {
        text += &format!("v {i}.{} {} 0\n", "5".repeat(i % 7), i % 13);
        if i >= 2 {
            text += &format!("f {} -1 {}\n", i - 1, i);
            expected += 1;
        }
    }
    assert!(text.len() > 1 << 20);
    let (c, s) = load(&text).unwrap();
    assert_eq!(s.vertices, 60_000);
    assert_eq!(c.triangles.len(), expected);
    // Face 29 999 is written after vertex 30 001 (0-based): "f 30000 -1 30001".
    let t = c.triangles[29_999].positions;
    assert_eq!(t, [[29999.5555, 8.0, 0.0], [30001.555555, 10.0, 0.0], [30000.55555, 9.0, 0.0]]);
    assert!(c.progress.len() >= 2);
}

#[test]
fn spilled_vertices_keep_exact_coordinates() {
    // vertex_memory 0: each store keeps two blocks of 4096 vertices, so most of these spill.
    let n = 5 * 4096 + 100;
    let coord = |i: u64| [i as f64 * 0.001 - 7.0, -(i as f64) / 3.0, 1e-7 * i as f64];
    let mut text = String::new();
    for i in 0..n {
        let [x, y, z] = coord(i);
        text += &format!("v {x:?} {y:?} {z:?}\nvn 0 0 {i}\n");
    }
    // Faces referring to the first, middle and last vertices, in scattered order.
    let picks: Vec<u64> = (0..n).step_by(997).chain([0, n - 1, 4095, 4096]).collect();
    for w in picks.windows(3) {
        text +=
            &format!("f {}//{} {}//{} {}//{}\n", w[0] + 1, w[0] + 1, w[1] + 1, w[1] + 1, w[2] + 1, w[2] + 1);
    }
    let dir = tempfile::tempdir().unwrap();
    let options = ImportOptions { vertex_memory: 0, spill_dir: Some(dir.path().to_path_buf()) };
    let input = Input::from_bytes(Path::new("big.obj"), text.into_bytes());
    let (c, s) = stream_input(input, &options).unwrap();
    assert_eq!(s.vertices, n);
    assert_eq!(c.triangles.len(), picks.len() - 2);
    for (t, w) in c.triangles.iter().zip(picks.windows(3)) {
        assert_eq!(t.positions, [coord(w[0]), coord(w[1]), coord(w[2])]);
        let nz = |i: u64| [0.0, 0.0, i as f32];
        assert_eq!(t.normals, Some([nz(w[0]), nz(w[1]), nz(w[2])]));
    }
}

#[test]
fn gzip_input() {
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    enc.write_all(format!("{SQUARE}f 1 2 3 4\n").as_bytes()).unwrap();
    let gz = enc.finish().unwrap();
    let dir = write_files(&[("g.obj.gz", &gz)]);
    let (c, s) = load_file(&dir.path().join("g.obj.gz")).unwrap();
    assert_eq!(c.triangles.len(), 2);
    assert_eq!(c.objects[0].1.name, "g");
    assert_eq!(s.bytes, gz.len() as u64);
}

#[test]
fn through_format_detection() {
    let dir = write_files(&[("x.obj", format!("{SQUARE}f 1 2 3\n").as_bytes())]);
    let source = crate::open_source(&dir.path().join("x.obj"), &ImportOptions::default()).unwrap();
    assert_eq!(source.progress_total(), Some(SQUARE.len() as u64 + 8));
    let mut sink = Collect::default();
    assert_eq!(source.stream(&mut sink).unwrap().objects, 1);
}

// Errors, each with its line.

#[test]
fn error_index_zero() {
    fails(&format!("{SQUARE}f 1 0 2\n"), 5, "vertex index 0 is invalid");
}

#[test]
fn error_index_out_of_range() {
    fails(&format!("{SQUARE}f 1 2 5\n"), 5, "vertex index 5 is out of range: 4 vertices");
}

#[test]
fn error_negative_index_out_of_range() {
    fails(&format!("{SQUARE}f -1 -2 -5\n"), 5, "vertex index -5 is out of range");
}

#[test]
fn error_forward_reference() {
    fails("v 0 0 0\nv 1 0 0\nf 1 2 3\nv 0 1 0\n", 3, "vertex index 3 is out of range");
}

#[test]
fn error_normal_index_out_of_range() {
    fails(&format!("{SQUARE}vn 0 0 1\nf 1//1 2//1 3//2\n"), 6, "normal index 2 is out of range: 1 normals");
}

#[test]
fn error_normal_index_without_normals() {
    fails(&format!("{SQUARE}f 1//1 2//1 3//1\n"), 5, "normal index 1 is out of range: 0 normals");
}

#[test]
fn error_texcoord_index_out_of_range() {
    fails(&format!("{SQUARE}vt 0 0\nf 1/1 2/-2 3/1\n"), 6, "texture coordinate index -2 is out of range");
}

#[test]
fn error_huge_index() {
    fails(&format!("{SQUARE}f 1 2 99999999999999999999999\n"), 5, "malformed vertex index");
    fails(&format!("{SQUARE}f 1 2 999999999999999999\n"), 5, "out of range");
}

#[test]
fn error_malformed_index() {
    fails(&format!("{SQUARE}f 1 2 3x\n"), 5, "malformed vertex index \"3x\"");
    fails(&format!("{SQUARE}f 1 2 /3\n"), 5, "malformed vertex index \"\"");
    fails(&format!("{SQUARE}vn 0 0 1\nf 1 2 3//1/1\n"), 6, "malformed normal index \"1/1\"");
    fails(&format!("{SQUARE}f 1 2 -\n"), 5, "malformed vertex index \"-\"");
}

#[test]
fn error_malformed_number() {
    fails("v 0 0 0\nv 1 0x1 0\n", 2, "malformed number \"0x1\" in a vertex");
    fails("vn 0 0 1.2.3\n", 1, "malformed number \"1.2.3\" in a normal");
    fails("vt u\n", 1, "malformed number \"u\" in a texture coordinate");
    fails("v 1 2 3 4 5 six\n", 1, "malformed number \"six\"");
}

#[test]
fn error_nan_and_infinity() {
    fails("v 0 0 0\nv nan 0 0\n", 2, "vertex has a non-finite number \"nan\"");
    fails("v 0 -inf 0\n", 1, "non-finite number \"-inf\"");
    fails("v 0 0 1e999\n", 1, "non-finite number \"1e999\"");
    fails("vn 0 0 NaN\n", 1, "normal has a non-finite number");
}

#[test]
fn error_vertex_with_too_few_numbers() {
    fails("v 0 0 0\n\nv 1 2\n", 3, "a vertex needs 3 coordinates, found 2");
    fails("v\n", 1, "found 0");
    fails("vn 1 0\n", 1, "a normal needs 3 components, found 2");
    fails("vt\n", 1, "a texture coordinate needs at least 1 number");
}

#[test]
fn error_face_with_too_few_vertices() {
    fails(&format!("{SQUARE}f 1 2\n"), 5, "a face needs at least 3 vertices, found 2");
    fails(&format!("{SQUARE}f\n"), 5, "found 0");
}

#[test]
fn error_face_with_too_many_vertices() {
    let face = " 1".repeat(MAX_FACE_VERTICES + 1);
    fails(&format!("{SQUARE}f{face}\n"), 5, "a face has more than 65536 vertices");
    // Exactly the limit is fine.
    let face = " 1 2 3".repeat(MAX_FACE_VERTICES / 3);
    assert_eq!(ok(&format!("{SQUARE}f{face}\n")).triangles.len(), MAX_FACE_VERTICES / 3 * 3 - 2);
}

#[test]
fn error_non_utf8_in_a_statement() {
    fails_bytes(b"v 0 0 0\nv 1 \xff 0\n", 2, "malformed number \"\u{fffd}\"");
}

#[test]
fn error_binary_garbage() {
    fails_bytes(b"\x00\x01\x02\x03garbage\n", 1, "is not an OBJ statement (binary data?)");
    fails_bytes(b"v 0 0 0\n\x89PNG\r\n", 2, "is not an OBJ statement");
    // Pseudo-random bytes fail somewhere, with a line, and do not panic.
    let mut rng = tw_core::Rng::new(7);
    for _ in 0..20 {
        let bytes: Vec<u8> = (0..4096).map(|_| (rng.f64() * 256.0) as u8).collect();
        let e = load_bytes(&bytes).err().expect("garbage is an error");
        assert!(matches!(e.position(), Some(Position::Line(_))), "{e}");
    }
}

#[test]
fn error_line_too_long() {
    let mut bytes = b"v 0 0 0\n# ".to_vec();
    bytes.resize(MAX_LINE + 100, b'x');
    fails_bytes(&bytes, 2, "line longer than");
}

#[test]
fn error_from_the_sink_is_passed_on() {
    struct Refuse;
    impl TriangleSink for Refuse {
        fn object(&mut self, _: ObjectId, _: &ObjectInfo) -> Result<(), ImportError> {
            Ok(())
        }
        fn triangle(&mut self, _: &Triangle) -> Result<(), ImportError> {
            Err(ImportError::Sink("disk full".into()))
        }
    }
    let input = Input::from_bytes(Path::new("a.obj"), format!("{SQUARE}f 1 2 3\n").into_bytes());
    let e = open(input, &ImportOptions::default()).unwrap().stream(&mut Refuse).unwrap_err();
    assert_eq!(e.to_string(), "disk full");
}

// Numbers.

#[test]
fn parse_f64_matches_std_bit_for_bit() {
    let mut rng = tw_core::Rng::new(1);
    let mut cases: Vec<String> = [
        "0",
        "-0",
        "+1",
        "1.",
        ".5",
        "0.1",
        "0.3",
        "-1.234567",
        "123456789012345678",
        "9007199254740993",
        "1234567890.1234567",
        "0.0000000000000000000001",
        "0.00000000000000000000001",
        "1e10",
        "1E-5",
        "inf",
        "-Infinity",
        "nan",
        "1.7976931348623157e308",
        "4.9e-324",
        "00000000000000000001.5",
        "1234567890123456789",
        "12345678901234567890",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    for _ in 0..20_000 {
        let x = (rng.f64() - 0.5) * 10f64.powi((rng.f64() * 12.0) as i32 - 4);
        let digits = (rng.f64() * 12.0) as usize;
        cases.push(format!("{x:.digits$}"));
        cases.push(format!("{x:?}"));
    }
    for s in &cases {
        let expected: Option<f64> = s.parse().ok();
        let got = parse_f64(s.as_bytes());
        assert_eq!(got.map(f64::to_bits), expected.map(f64::to_bits), "{s}");
    }
}

#[test]
fn parse_f64_rejects_malformed() {
    for s in ["", "-", "+", ".", "-.", "1.2.3", "1,5", "1 ", "0x10", "1e", "--1", "1-", "\u{fffd}"] {
        assert_eq!(parse_f64(s.as_bytes()), None, "{s:?}");
    }
}

#[test]
fn parse_index_forms() {
    assert_eq!(parse_index(b"1"), Some(1));
    assert_eq!(parse_index(b"-42"), Some(-42));
    assert_eq!(parse_index(b"+7"), Some(7));
    assert_eq!(parse_index(b"999999999999999999"), Some(999_999_999_999_999_999));
    for s in [&b""[..], b"-", b"1.0", b"1e3", b"9999999999999999999", b" 1"] {
        assert_eq!(parse_index(s), None, "{s:?}");
    }
}

#[test]
fn find_newline_at_every_offset() {
    for len in 0..40 {
        for at in 0..=len {
            let mut s = vec![b'a'; len];
            if at < len {
                s[at] = b'\n';
            }
            let expected = (at < len).then_some(at);
            assert_eq!(find_newline(&s), expected, "len {len} at {at}");
        }
    }
    assert_eq!(find_newline(b"\x8a\x0a"), Some(1));
    assert_eq!(find_newline(b"\x0b\x09\x8a\xff\x0a"), Some(4));
}
