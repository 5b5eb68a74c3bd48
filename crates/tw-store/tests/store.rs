//! Store round trips, determinism, atomic writes, and every kind of damage: flipped bytes (with
//! and without fixed-up checksums), truncation, wrong magic and version (a format-1 store among
//! them), broken references, broken tree structure and broken group links. None of them may
//! panic.

use std::path::Path;

use tw_store::format::{
    checksum, Header, PageEntry, Reader, SectionKind, GROUP_LEN, HEADER_CRC_AT, HEADER_LEN, NODE_LEN,
    PAGE_ENTRY_LEN, SOURCE_LEN,
};
use tw_store::{EncodedCluster, Group, Node, Object, PageCluster, Store, StoreError, StoreInfo, StoreWriter};

fn info(input_triangles: u64) -> StoreInfo {
    StoreInfo {
        bounds_min: [-5.0, -5.0, 0.0],
        bounds_max: [5.0, 5.0, 1.0],
        grid_origin: [-5.0, -5.0, 0.0],
        grid_step: 10.0 / 16777215.0,
        units: "m".into(),
        up_axis: 2,
        build_options: "memory=2G\nthreads=2".into(),
        input_triangles,
    }
}

/// A strip of `n` quads starting at grid x = `x0`, as one cluster of 2n triangles.
fn strip(x0: u32, n: u32, group: u32, level: u8, self_error: f32, object: u32) -> PageCluster {
    let mut c =
        PageCluster { self_error, self_sphere: [1.0, 1.0, 0.0, 0.5], group, level, ..Default::default() };
    for i in 0..=n {
        c.positions.push([x0 + 10 * i, 100, 3]);
        c.positions.push([x0 + 10 * i, 110, 4]);
    }
    for i in 0..n as u8 {
        let (a, b, d, e) = (2 * i, 2 * i + 1, 2 * i + 2, 2 * i + 3);
        c.indices.extend_from_slice(&[a, d, b, b, d, e]);
        c.objects.extend_from_slice(&[object, object + i as u32 % 2]);
    }
    c
}

type Edit = Box<dyn Fn(&mut Scene)>;

struct Scene {
    pages: Vec<(Vec<PageCluster>, bool)>,
    objects: Vec<Object>,
    nodes: Vec<Node>,
    groups: Vec<Group>,
    sources: Vec<u32>,
}

/// Root node 0 with leaves 1 and 2. Leaf groups 0 and 1 (level 0, pages 0 and 1), root group 2
/// (level 1, error ∞, root page 2), simplified from groups 0 and 1 (its sources) in one step:
/// its clusters' self error and sphere are theirs.
fn scene() -> Scene {
    let big = [1.0, 1.0, 0.0, 100.0];
    let simplified = |x0| PageCluster { self_sphere: big, ..strip(x0, 2, 2, 1, 0.75, x0 / 500) };
    let pages = vec![
        (vec![strip(0, 4, 0, 0, 0.0, 0), strip(40, 5, 0, 0, 0.0, 1)], false),
        (vec![strip(1000, 3, 1, 0, 0.0, 2), strip(1030, 6, 1, 0, 0.0, 2)], false),
        (vec![simplified(0), simplified(1000)], true),
    ];
    let tris = |p: usize| pages[p].0.iter().map(|c| c.triangle_count() as u32).sum::<u32>();
    let groups = vec![
        Group {
            sphere: big,
            error: 0.75,
            node: 1,
            level: 0,
            page: 0,
            first_cluster: 0,
            cluster_count: 2,
            triangles: tris(0),
            source_count: 0,
        },
        Group {
            sphere: big,
            error: 0.75,
            node: 2,
            level: 0,
            page: 1,
            first_cluster: 0,
            cluster_count: 2,
            triangles: tris(1),
            source_count: 0,
        },
        Group {
            sphere: big,
            error: f32::INFINITY,
            node: 0,
            level: 1,
            page: 2,
            first_cluster: 0,
            cluster_count: 2,
            triangles: tris(2),
            source_count: 2,
        },
    ];
    let nodes = vec![
        Node {
            min: [0, 100, 3],
            max: [1100, 110, 4],
            first_child: 1,
            child_count: 2,
            first_group: 2,
            group_count: 1,
            max_error: f32::INFINITY,
        },
        Node {
            min: [0, 100, 3],
            max: [90, 110, 4],
            first_child: 0,
            child_count: 0,
            first_group: 0,
            group_count: 1,
            max_error: 0.75,
        },
        Node {
            min: [1000, 100, 3],
            max: [1090, 110, 4],
            first_child: 0,
            child_count: 0,
            first_group: 1,
            group_count: 1,
            max_error: 0.75,
        },
    ];
    let objects = vec![
        Object { name: "wall".into(), color: Some([255, 0, 0, 255]), triangles: 10 },
        Object { name: "door ü".into(), color: None, triangles: 8 },
        Object { name: String::new(), color: Some([1, 2, 3, 4]), triangles: 18 },
    ];
    Scene { pages, objects, nodes, groups, sources: vec![0, 1] }
}

fn write(path: &Path, s: &Scene) -> Result<tw_store::WriteSummary, StoreError> {
    let mut w = StoreWriter::create(path)?;
    for (i, (clusters, root)) in s.pages.iter().enumerate() {
        assert_eq!(w.add_page(clusters, *root)?, i as u32);
    }
    w.finish(&info(36), &s.objects, &s.nodes, &s.groups, &s.sources)
}

/// [`write`] with a ray-tracing tree ([`tw_store::RtTree::halving`]) after every cluster.
fn write_with_trees(path: &Path, s: &Scene) -> Result<tw_store::WriteSummary, StoreError> {
    let mut w = StoreWriter::create(path)?;
    w.set_rt_trees(true);
    for (clusters, root) in &s.pages {
        let encoded: Vec<EncodedCluster> = clusters
            .iter()
            .map(|c| {
                let mut e = EncodedCluster::new(c).unwrap();
                tw_store::RtTree::halving(c.triangle_count())
                    .encode(c.triangle_count(), &mut e.bytes)
                    .unwrap();
                e
            })
            .collect();
        w.add_encoded_page(&encoded, *root)?;
    }
    w.finish(&info(36), &s.objects, &s.nodes, &s.groups, &s.sources)
}

fn store_bytes_with_trees(s: &Scene) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.tw");
    write_with_trees(&path, s).unwrap();
    std::fs::read(path).unwrap()
}

/// A store with ray-tracing trees opens, verifies and gives its trees with the same clusters
/// as the store without; every truncation and every byte flip of its pages (checksums
/// recomputed, so the decoder sees them) is refused or decodes, never panics.
#[test]
fn rt_trees_round_trip_and_corrupt_ones_never_panic() {
    let (plain, with) = (store_bytes(&scene()), store_bytes_with_trees(&scene()));
    let (a, b) = (Store::from_bytes(plain).unwrap(), Store::from_bytes(with.clone()).unwrap());
    assert!(b.has_rt_trees() && !a.has_rt_trees());
    b.verify(|_, _| {}).unwrap();
    for i in 0..a.pages().len() as u32 {
        let (clusters, trees) = b.page_with_trees(i).unwrap();
        assert_eq!(clusters, a.page(i).unwrap());
        let expect: Vec<_> = clusters.iter().map(|c| tw_store::RtTree::halving(c.triangle_count())).collect();
        assert_eq!(trees, expect);
    }
    let pages = *b.header().section(SectionKind::Pages);
    for at in pages.offset as usize..pages.end() as usize {
        for x in [0x01u8, 0x10, 0x80, 0xff] {
            let mut bytes = with.clone();
            bytes[at] ^= x;
            refresh_checksums(&mut bytes);
            tw_store::fuzz_bytes(&bytes);
        }
    }
    // A page cut short by one byte (its table entry and checksums adjusted accordingly is not
    // possible without moving the tables, so: the last page's last byte dropped from the
    // region is caught by the layout check).
    let mut short = with.clone();
    short.remove(pages.end() as usize - 1);
    refresh_checksums(&mut short);
    assert!(Store::from_bytes(short).is_err());
}

fn store_bytes(s: &Scene) -> Vec<u8> {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.tw");
    write(&path, s).unwrap();
    std::fs::read(path).unwrap()
}

/// Recomputes every checksum (pages, tables, header) of a store whose bytes were edited, so
/// that the structural checks behind them are exercised. Leaves bytes it cannot parse alone.
fn refresh_checksums(b: &mut [u8]) {
    if b.len() < HEADER_LEN {
        return;
    }
    let Ok(h) = Header::parse(&b[..HEADER_LEN], false) else { return };
    let pt = *h.section(SectionKind::PageTable);
    if pt.end() <= b.len() as u64 {
        for i in 0..h.page_count as usize {
            let at = pt.offset as usize + i * PAGE_ENTRY_LEN;
            let Some(entry) = b.get(at..at + PAGE_ENTRY_LEN) else { break };
            let Ok(p) = PageEntry::parse(&mut Reader::new(entry, 0)) else { continue };
            let Some(page) = b.get(p.offset as usize..(p.offset + p.compressed_len as u64) as usize) else {
                continue;
            };
            let crc = checksum(page);
            b[at + 24..at + 28].copy_from_slice(&crc.to_le_bytes());
        }
    }
    for kind in SectionKind::ALL {
        if kind == SectionKind::Pages {
            continue;
        }
        let s = h.section(kind);
        if let Some(body) = b.get(s.offset as usize..s.end() as usize) {
            let crc = checksum(body);
            let at = 160 + 24 * kind as usize + 16;
            b[at..at + 4].copy_from_slice(&crc.to_le_bytes());
        }
    }
    let crc = checksum(&b[..HEADER_CRC_AT]);
    b[HEADER_CRC_AT..HEADER_LEN].copy_from_slice(&crc.to_le_bytes());
}

/// Opens, verifies and decodes every page; `Err` with the first error.
fn check(bytes: Vec<u8>) -> Result<(), StoreError> {
    let store = Store::from_bytes(bytes)?;
    store.verify(|_, _| {})?;
    for i in 0..store.pages().len() as u32 {
        store.page(i)?;
    }
    Ok(())
}

fn section_offset(bytes: &[u8], kind: SectionKind) -> usize {
    Header::parse(&bytes[..HEADER_LEN], true).unwrap().section(kind).offset as usize
}

fn patch_u32(bytes: &mut [u8], at: usize, v: u32) {
    bytes[at..at + 4].copy_from_slice(&v.to_le_bytes());
    refresh_checksums(bytes);
}

#[test]
fn round_trip_of_a_few_pages() {
    let s = scene();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.tw");
    let summary = write(&path, &s).unwrap();
    assert_eq!(summary.pages, 3);
    assert_eq!(summary.clusters, 6);
    assert_eq!(summary.file_bytes, std::fs::metadata(&path).unwrap().len());

    let store = Store::open(&path).unwrap();
    let h = store.header();
    assert_eq!((h.up_axis, h.input_triangles, h.grid_step), (2, 36, 10.0 / 16777215.0));
    assert_eq!(
        h.triangle_count,
        s.pages.iter().flat_map(|p| &p.0).map(|c| c.triangle_count() as u64).sum::<u64>()
    );
    assert_eq!(store.units(), "m");
    assert_eq!(store.build_options(), "memory=2G\nthreads=2");
    assert_eq!(store.objects(), &s.objects[..]);
    assert_eq!(store.nodes(), &s.nodes[..]);
    assert_eq!(store.groups(), &s.groups[..]);
    assert_eq!(
        [store.group_sources(0), store.group_sources(1), store.group_sources(2)],
        [&[][..], &[], &[0, 1]]
    );
    assert_eq!(
        [store.group_parents(0), store.group_parents(1), store.group_parents(2)],
        [&[2][..], &[2], &[]]
    );
    assert!(store.group_sources(3).is_empty() && store.group_parents(3).is_empty());
    assert!(store.pages()[2].is_root() && !store.pages()[0].is_root());
    for (i, (clusters, _)) in s.pages.iter().enumerate() {
        let back = store.page(i as u32).unwrap();
        let expected: Vec<PageCluster> = clusters.iter().map(|c| c.canonical()).collect();
        assert_eq!(back, expected, "page {i}");
    }
    let mut calls = Vec::new();
    let rep = store.verify(|d, t| calls.push((d, t))).unwrap();
    assert_eq!(calls, vec![(1, 3), (2, 3), (3, 3)]);
    assert_eq!((rep.pages, rep.root_pages, rep.clusters, rep.max_level, rep.group_links), (3, 1, 6, 1, 2));
    assert_eq!(rep.triangles, h.triangle_count);
    assert_eq!(rep.level0_triangles, 36);
    assert!(matches!(store.page(3), Err(StoreError::Page { page: 3, .. })));

    // The mmap reader and the in-memory reader agree.
    let mem = Store::from_bytes(std::fs::read(&path).unwrap()).unwrap();
    assert_eq!(mem.groups(), store.groups());
    assert_eq!(mem.page(1).unwrap(), store.page(1).unwrap());
}

#[test]
fn identical_input_gives_identical_bytes() {
    assert_eq!(store_bytes(&scene()), store_bytes(&scene()));
}

#[test]
fn pages_of_clusters_encoded_apart_give_the_same_store() {
    let s = scene();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("encoded.tw");
    let mut w = StoreWriter::create(&path).unwrap();
    for (i, (clusters, root)) in s.pages.iter().enumerate() {
        // Encoded under group 0, as a builder's worker does, and given the group afterwards.
        let encoded: Vec<EncodedCluster> = clusters
            .iter()
            .map(|c| {
                let mut e = EncodedCluster::new(&PageCluster { group: 0, ..c.clone() }).unwrap();
                e.set_group(c.group);
                e
            })
            .collect();
        assert_eq!(w.add_encoded_page(&encoded, *root).unwrap(), i as u32);
    }
    assert!(matches!(w.add_encoded_page(&[], false), Err(StoreError::Invalid(m)) if m.contains("page")));
    w.finish(&info(36), &s.objects, &s.nodes, &s.groups, &s.sources).unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), store_bytes(&s));
}

#[test]
fn an_unfinished_writer_leaves_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.tw");
    {
        let mut w = StoreWriter::create(&path).unwrap();
        w.add_page(&scene().pages[0].0, false).unwrap();
    }
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 0);

    // A finish that fails validation leaves nothing either, and keeps an existing store.
    std::fs::write(&path, b"old").unwrap();
    let mut s = scene();
    s.groups[0].page = 99;
    assert!(matches!(write(&path, &s), Err(StoreError::Invalid(m)) if m.contains("page 99 beyond")));
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);
    assert_eq!(std::fs::read(&path).unwrap(), b"old");
}

#[test]
fn writer_rejects_bad_clusters_and_tables() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("scene.tw");
    let mut w = StoreWriter::create(&path).unwrap();
    let mut bad = strip(0, 1, 0, 0, 0.0, 0);
    bad.indices[0] = 200;
    assert!(matches!(w.add_page(&[bad], false), Err(StoreError::Invalid(m)) if m.contains("page 0")));
    assert!(w.add_page(&[], false).is_err());

    let cases: Vec<(&str, Edit)> = vec![
        ("cycle", Box::new(|s| s.nodes[2] = Node { first_child: 0, child_count: 1, ..s.nodes[2] })),
        ("self loop", Box::new(|s| s.nodes[1] = Node { first_child: 1, child_count: 1, ..s.nodes[1] })),
        ("two parents", Box::new(|s| s.nodes[1] = Node { first_child: 2, child_count: 1, ..s.nodes[1] })),
        ("child out of range", Box::new(|s| s.nodes[0].child_count = 3)),
        ("bounds", Box::new(|s| s.nodes[1].max[0] = 5000)),
        ("unlisted group", Box::new(|s| s.nodes[1].group_count = 0)),
        ("group node", Box::new(|s| s.groups[0].node = 2)),
        ("cluster range", Box::new(|s| s.groups[0].first_cluster = 1)),
        ("nan error", Box::new(|s| s.groups[0].error = f32::NAN)),
        ("group level", Box::new(|s| s.groups[0].level = 5)),
        ("source after its group", Box::new(|s| s.sources[1] = 2)),
        ("sources unsorted", Box::new(|s| s.sources.swap(0, 1))),
        ("source count", Box::new(|s| s.groups[2].source_count = 1)),
        ("finite error, no parent", Box::new(|s| s.groups[2].error = 0.5)),
        ("no nodes", Box::new(|s| s.nodes.clear())),
        ("bad up axis", Box::new(|_| {})),
    ];
    for (name, f) in cases {
        let mut s = scene();
        f(&mut s);
        let mut w = StoreWriter::create(&path).unwrap();
        for (c, root) in &s.pages {
            w.add_page(c, *root).unwrap();
        }
        let mut i = info(36);
        if name == "bad up axis" {
            i.up_axis = 3;
        }
        let r = w.finish(&i, &s.objects, &s.nodes, &s.groups, &s.sources);
        assert!(matches!(r, Err(StoreError::Invalid(_))), "{name}: {r:?}");
        assert!(!path.exists(), "{name}");
    }
}

#[test]
fn every_flipped_byte_is_detected_without_panic() {
    let bytes = store_bytes(&scene());
    for i in 0..bytes.len() {
        for bit in [0x01u8, 0xff] {
            let mut b = bytes.clone();
            b[i] ^= bit;
            assert!(check(b).is_err(), "flipping byte {i} by {bit:#x} went unnoticed");
        }
    }
}

/// With the checksums recomputed after the flip, the structural checks must still either reject
/// the store or give a store that verifies, and never panic.
#[test]
fn flipped_bytes_behind_fixed_checksums_never_panic() {
    let bytes = store_bytes(&scene());
    let (mut rejected, mut accepted) = (0, 0);
    for i in 0..bytes.len() {
        for bit in [0x01u8, 0x10, 0x80, 0xff] {
            let mut b = bytes.clone();
            b[i] ^= bit;
            refresh_checksums(&mut b);
            match check(b) {
                Ok(()) => accepted += 1,
                Err(_) => rejected += 1,
            }
        }
    }
    println!("{} bytes: {rejected} flips rejected, {accepted} accepted (harmless values)", bytes.len());
    assert!(rejected > accepted);
}

#[test]
fn every_truncation_is_an_error() {
    let bytes = store_bytes(&scene());
    for len in 0..bytes.len() {
        let e = check(bytes[..len].to_vec()).unwrap_err();
        if len >= 8 {
            assert!(matches!(e, StoreError::Truncated { .. }), "length {len}: {e}");
        }
    }
    // Through the mmap path too, including an empty file.
    let dir = tempfile::tempdir().unwrap();
    for len in [0, 5, 12, HEADER_LEN - 1, HEADER_LEN, bytes.len() - 1] {
        let path = dir.path().join("t.tw");
        std::fs::write(&path, &bytes[..len]).unwrap();
        let e = Store::open(&path).unwrap_err();
        assert!(e.to_string().contains("t.tw"), "{e}");
        if len > 0 {
            assert!(matches!(e, StoreError::Truncated { .. }), "length {len}: {e}");
        }
    }
    let mut longer = bytes.clone();
    longer.push(0);
    assert!(matches!(Store::from_bytes(longer), Err(StoreError::Corrupt { .. })));
}

#[test]
fn wrong_magic_is_not_a_store() {
    let mut bytes = store_bytes(&scene());
    bytes[3] = b'x';
    assert!(matches!(Store::from_bytes(bytes), Err(StoreError::NotAStore { .. })));
    assert!(matches!(Store::from_bytes(b"solid cube\n".to_vec()), Err(StoreError::NotAStore { .. })));
}

#[test]
fn wrong_version_says_rebuild() {
    let mut bytes = store_bytes(&scene());
    bytes[8] = 4;
    let e = Store::from_bytes(bytes).unwrap_err();
    assert!(matches!(e, StoreError::Version { found: 4, .. }));
    assert!(e.to_string().contains("written by a newer terawalk (store format 4"), "{e}");
    // A format-2 store (the format before ray-tracing trees): the same bytes but the version
    // (and the header checksum), refused by name with the advice to rebuild.
    let mut v2 = store_bytes(&scene());
    v2[8] = 2;
    refresh_checksums(&mut v2);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("old.tw");
    std::fs::write(&path, &v2).unwrap();
    let e = Store::open(&path).unwrap_err();
    assert!(matches!(e, StoreError::Version { found: 2, .. }), "{e:?}");
    let msg = e.to_string();
    assert!(msg.starts_with(&path.display().to_string()), "{msg}");
    assert!(msg.contains("older terawalk (store format 2); rebuild it with `terawalk build`"), "{msg}");
    // The version is checked before the rest of the header, even if that is cut short.
    let mut short = store_bytes(&scene())[..16].to_vec();
    short[8] = 7;
    assert!(matches!(Store::from_bytes(short), Err(StoreError::Version { found: 7, .. })));
}

/// A format-1 store (320-byte header, no group sources) is refused by name, before anything
/// else of its header is read, through both readers.
#[test]
fn format_1_store_is_refused_with_rebuild_advice() {
    let mut v1 = b"TERAWALK".to_vec();
    v1.extend_from_slice(&1u32.to_le_bytes());
    v1.extend_from_slice(&320u32.to_le_bytes());
    v1.resize(320, 0);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("old.tw");
    std::fs::write(&path, &v1).unwrap();
    for e in [Store::open(&path).unwrap_err(), Store::from_bytes(v1).unwrap_err()] {
        assert!(matches!(e, StoreError::Version { found: 1, .. }), "{e:?}");
        let msg = e.to_string();
        assert!(
            msg.contains(
                "was written by an older terawalk (store format 1); rebuild it with `terawalk build`"
            ),
            "{msg}"
        );
    }
    assert!(Store::open(&path).unwrap_err().to_string().starts_with(&path.display().to_string()));
}

#[test]
fn corrupt_group_link_is_rejected_at_open() {
    let base = store_bytes(&scene());
    let at = section_offset(&base, SectionKind::GroupSources);
    // Group 2's second source made itself.
    let mut bytes = base.clone();
    patch_u32(&mut bytes, at + SOURCE_LEN, 2);
    let e = Store::from_bytes(bytes).unwrap_err();
    match &e {
        StoreError::Corrupt { offset, msg, .. } => {
            assert_eq!(*offset, (at + SOURCE_LEN) as u64, "{e}");
            assert!(msg.contains("group 2: source 2 is not a group before it"), "{e}");
        }
        other => panic!("expected a corrupt store, got {other:?}"),
    }
    // Beyond the group table.
    let mut bytes = base.clone();
    patch_u32(&mut bytes, at, 1000);
    assert!(Store::from_bytes(bytes).unwrap_err().to_string().contains("source 1000"));
    // Group 2 counts one source only: the section holds one too many.
    let mut bytes = base.clone();
    patch_u32(&mut bytes, section_offset(&base, SectionKind::Groups) + 2 * GROUP_LEN + 44, 1);
    assert!(Store::from_bytes(bytes).unwrap_err().to_string().contains("count 1 sources"));
    // Without the checksum fix-up, the section's checksum catches the change.
    let mut bytes = base;
    bytes[at] ^= 1;
    let e = Store::from_bytes(bytes).unwrap_err();
    assert!(e.to_string().contains("group sources checksum mismatch"), "{e}");
}

#[test]
fn group_pointing_beyond_the_pages_is_rejected() {
    let mut bytes = store_bytes(&scene());
    let at = section_offset(&bytes, SectionKind::Groups) + GROUP_LEN + 24;
    patch_u32(&mut bytes, at, 3);
    let e = Store::from_bytes(bytes).unwrap_err();
    assert!(matches!(&e, StoreError::Corrupt { msg, .. } if msg.contains("page 3 beyond 3 pages")), "{e}");
}

#[test]
fn node_cycles_are_rejected() {
    let base = store_bytes(&scene());
    let nodes = section_offset(&base, SectionKind::Nodes);
    // Leaf 2 claims the root as its child: a child before its parent.
    let mut bytes = base.clone();
    patch_u32(&mut bytes, nodes + 2 * NODE_LEN + 24, 0);
    patch_u32(&mut bytes, nodes + 2 * NODE_LEN + 28, 1);
    let e = Store::from_bytes(bytes).unwrap_err();
    assert!(e.to_string().contains("must lie after the node"), "{e}");
    // A node as its own child.
    let mut bytes = base.clone();
    patch_u32(&mut bytes, nodes + NODE_LEN + 24, 1);
    patch_u32(&mut bytes, nodes + NODE_LEN + 28, 1);
    assert!(Store::from_bytes(bytes).is_err());
    // Leaf 1 claims leaf 2 too: two parents (a DAG, not a tree).
    let mut bytes = base;
    patch_u32(&mut bytes, nodes + NODE_LEN + 24, 2);
    patch_u32(&mut bytes, nodes + NODE_LEN + 28, 1);
    let e = Store::from_bytes(bytes).unwrap_err();
    assert!(e.to_string().contains("child 2") || e.to_string().contains("2 parents"), "{e}");
}

#[test]
fn verify_finds_cluster_level_invariant_violations() {
    let cases: Vec<(&str, Edit, &str)> = vec![
        ("cluster in the wrong group", Box::new(|s| s.pages[0].0[1].group = 1), "lists clusters"),
        ("self error above group error", Box::new(|s| s.pages[0].0[0].self_error = 1.0), "self error"),
        ("max error too small", Box::new(|s| s.nodes[1].max_error = 0.5), "max error"),
        ("root max error too small", Box::new(|s| s.nodes[0].max_error = 1.0), "max error"),
        ("group triangles", Box::new(|s| s.groups[1].triangles += 1), "triangles"),
        ("sphere not nested", Box::new(|s| s.groups[0].sphere[3] = 0.1), "sphere"),
        ("vertex outside node", Box::new(|s| s.nodes[1].max[0] = 80), "outside the bounds"),
        (
            "simplified cluster from no source",
            Box::new(|s| s.pages[2].0[1].self_sphere[3] = 50.0),
            "match none of the sources",
        ),
        (
            "source no cluster was made from",
            Box::new(|s| s.groups[1].sphere[3] = 99.0),
            "matches none of the group's clusters",
        ),
        (
            "cluster level above group",
            Box::new(|s| {
                s.pages[1].0[0].level = 1;
                s.groups[1].level = 0;
            }),
            "level",
        ),
    ];
    let dir = tempfile::tempdir().unwrap();
    for (name, f, expect) in cases {
        let mut s = scene();
        f(&mut s);
        let path = dir.path().join("v.tw");
        match write(&path, &s) {
            Ok(_) => {
                let store = Store::open(&path).unwrap();
                let e = store.verify(|_, _| {}).expect_err(name);
                assert!(matches!(e, StoreError::Invariant { .. }), "{name}: {e}");
                assert!(e.to_string().contains(expect), "{name}: {e}");
            }
            // Some are already caught by the writer's table checks.
            Err(e) => assert!(e.to_string().contains(expect), "{name}: {e}"),
        }
    }
}

/// Groups 0 and 1 are the sources of one step (same error and sphere) into root group 2; a
/// second root group 3 made from group 1 alone gives them different parents: verify says so.
#[test]
fn verify_finds_a_step_whose_sources_have_different_parents() {
    let mut s = scene();
    let extra = PageCluster { self_sphere: s.groups[1].sphere, ..strip(1000, 1, 3, 1, 0.75, 2) };
    let triangles = extra.triangle_count() as u32;
    s.pages[2].0.push(extra);
    s.groups.push(Group { first_cluster: 2, cluster_count: 1, triangles, source_count: 1, ..s.groups[2] });
    s.sources.push(1);
    s.nodes[0].group_count = 2;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("step.tw");
    write(&path, &s).unwrap();
    let store = Store::open(&path).unwrap();
    assert_eq!((store.group_parents(0), store.group_parents(1)), (&[2][..], &[2, 3][..]));
    let e = store.verify(|_, _| {}).unwrap_err();
    assert!(e.to_string().contains("group 2: sources 0 and 1 have the same error and sphere"), "{e}");
}

#[test]
fn corrupt_page_reports_page_and_offset() {
    let mut bytes = store_bytes(&scene());
    let store = Store::from_bytes(bytes.clone()).unwrap();
    let p = store.pages()[1];
    bytes[p.offset as usize + 5] ^= 0x40;
    let store = Store::from_bytes(bytes).unwrap();
    assert!(store.page(0).is_ok());
    let e = store.page(1).unwrap_err();
    assert!(matches!(e, StoreError::Page { page: 1, offset, .. } if offset == p.offset), "{e}");
    assert!(e.to_string().contains("checksum"), "{e}");
    let e = store.verify(|_, _| {}).unwrap_err();
    assert!(matches!(e, StoreError::Page { page: 1, .. }), "{e}");
}

#[test]
fn empty_scene_stores_and_opens() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("empty.tw");
    let w = StoreWriter::create(&path).unwrap();
    w.finish(&info(0), &[], &[Node::default()], &[], &[]).unwrap();
    let rep = Store::open(&path).unwrap().verify(|_, _| {}).unwrap();
    assert_eq!((rep.pages, rep.triangles, rep.nodes), (0, 0, 1));
}

/// The whole store for a 10k-triangle grid-like scene: bytes per triangle over everything
/// (header, tables, pages). Run with `--nocapture` to see the number.
#[test]
fn store_size_per_triangle() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("grid.tw");
    let mut w = StoreWriter::create(&path).unwrap();
    let (mut groups, mut tris) = (Vec::new(), 0u64);
    // 100×50 quads on a height field, 8×8 quads per cluster, 8 clusters per group and page.
    let mut clusters = Vec::new();
    for by in (0..50u32).step_by(8) {
        for bx in (0..100u32).step_by(8) {
            let (nx, ny) = ((100 - bx).min(8), (50 - by).min(8));
            let mut c = PageCluster { self_sphere: [0.0, 0.0, 0.0, 1.0], ..Default::default() };
            for y in 0..=ny {
                for x in 0..=nx {
                    let (gx, gy) = ((bx + x) * 1021 + 5_000_000, (by + y) * 1021 + 7_000_000);
                    let gz = 2_000_000
                        + ((gx as f64 * 1e-4).sin() * 3000.0 + (gy as f64 * 2e-4).cos() * 2000.0) as u32;
                    c.positions.push([gx, gy, gz]);
                }
            }
            for y in 0..ny {
                for x in 0..nx {
                    let i = (y * (nx + 1) + x) as u8;
                    let k = i + nx as u8 + 1;
                    c.indices.extend_from_slice(&[i, i + 1, k + 1, i, k + 1, k]);
                    c.objects.extend_from_slice(&[0, 0]);
                }
            }
            clusters.push(c);
        }
    }
    for (p, chunk) in clusters.chunks_mut(8).enumerate() {
        let t: usize = chunk.iter().map(|c| c.triangle_count()).sum();
        for c in chunk.iter_mut() {
            c.group = p as u32;
        }
        let page = w.add_page(chunk, false).unwrap();
        groups.push(Group {
            sphere: [0.0, 0.0, 0.0, 10.0],
            error: f32::INFINITY,
            page,
            cluster_count: chunk.len() as u32,
            triangles: t as u32,
            ..Default::default()
        });
        tris += t as u64;
    }
    assert_eq!(tris, 10_000);
    let nodes = [Node {
        min: [0; 3],
        max: [u32::MAX; 3],
        group_count: groups.len() as u32,
        max_error: f32::INFINITY,
        ..Default::default()
    }];
    let s = w.finish(&info(tris), &[Object::default()], &nodes, &groups, &[]).unwrap();
    let per_tri = s.file_bytes as f64 / tris as f64;
    println!(
        "{tris} triangles: {} bytes in the store, {per_tri:.2} bytes/triangle (pages {:.2})",
        s.file_bytes,
        s.page_bytes as f64 / tris as f64
    );
    assert!(per_tri < 6.0);
    Store::open(&path).unwrap().verify(|_, _| {}).unwrap();
}

/// Writes the test scene as a seed for the `store` fuzz target:
/// `cargo test -p tw-store --test store -- --ignored write_fuzz_seed`.
#[test]
#[ignore]
fn write_fuzz_seed() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/corpus/store");
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("seed-scene.tw"), store_bytes(&scene())).unwrap();
    let mut s = scene();
    s.pages.truncate(1);
    s.pages[0].1 = true;
    s.groups.truncate(1);
    s.groups[0].node = 0;
    s.groups[0].error = f32::INFINITY;
    s.sources.clear();
    s.nodes = vec![Node {
        child_count: 0,
        first_child: 0,
        first_group: 0,
        group_count: 1,
        max_error: f32::INFINITY,
        ..s.nodes[1]
    }];
    std::fs::write(dir.join("seed-one-page.tw"), store_bytes(&s)).unwrap();
    std::fs::write(dir.join("seed-rt-trees.tw"), store_bytes_with_trees(&scene())).unwrap();
}

/// Regression: `terawalk build … -o /dev/null` renamed the finished store over /dev/null.
#[test]
fn writer_refuses_an_output_that_is_not_a_regular_file() {
    let dir = tempfile::tempdir().unwrap();
    let err = StoreWriter::create(dir.path()).err().expect("a directory is refused");
    assert!(err.to_string().contains("not a regular file"), "{err}");
    #[cfg(unix)]
    {
        let err = StoreWriter::create("/dev/null").err().expect("a device is refused");
        assert!(err.to_string().contains("/dev/null"), "{err}");
    }
}

/// Runs `f` on a thread and fails the test if it takes more than 20 s (a reader that blocks on
/// a FIFO or reads an endless device would otherwise hang the suite).
fn within_seconds<T: Send + 'static>(f: impl FnOnce() -> T + Send + 'static) -> T {
    let (tx, rx) = std::sync::mpsc::channel();
    std::thread::spawn(move || {
        let _ = tx.send(f());
    });
    rx.recv_timeout(std::time::Duration::from_secs(20))
        .expect("finished within 20 s (no hang, no endless read)")
}

/// Regression: `info /dev/zero` read the "file" (length 0) to its end until memory ran out, and a
/// FIFO blocked the open. Only regular files are opened, with an error naming the path.
#[test]
fn open_refuses_fifos_devices_and_directories() {
    let dir = tempfile::tempdir().unwrap();
    let e = Store::open(dir.path()).unwrap_err();
    assert!(e.to_string().contains("a directory, not a regular file"), "{e}");
    #[cfg(unix)]
    {
        let e = within_seconds(|| Store::open("/dev/zero").unwrap_err().to_string());
        assert!(e.contains("/dev/zero") && e.contains("character device, not a regular file"), "{e}");
        let fifo = dir.path().join("pipe.tw");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status().unwrap();
        assert!(made.success());
        let f = fifo.clone();
        let e = within_seconds(move || Store::open(&f).unwrap_err().to_string());
        assert!(e.contains("pipe.tw") && e.contains("FIFO"), "{e}");
    }
}

/// A store cut short whose header claims huge sections (pages region, tables) is refused quickly
/// as truncated or corrupt, without reading or allocating what the header claims.
#[test]
fn truncated_store_claiming_huge_sizes_is_refused_quickly() {
    let bytes = store_bytes(&scene());
    let dir = tempfile::tempdir().unwrap();
    let length_at = |kind: SectionKind| 160 + 24 * kind as usize + 8;
    let huge = [u64::MAX, 1 << 62, 1 << 40];
    for kind in SectionKind::ALL {
        for claim in huge {
            let mut b = bytes[..HEADER_LEN + 64].to_vec();
            b[length_at(kind)..length_at(kind) + 8].copy_from_slice(&claim.to_le_bytes());
            refresh_checksums(&mut b);
            let path = dir.path().join("huge.tw");
            std::fs::write(&path, &b).unwrap();
            let p = path.clone();
            let e = within_seconds(move || Store::open(&p).unwrap_err());
            assert!(
                matches!(e, StoreError::Truncated { .. } | StoreError::Corrupt { .. }),
                "{kind:?} = {claim}: {e}"
            );
        }
    }
    // Counts that agree with huge table lengths: 2^32 - 1 pages of a 32-byte entry each.
    let mut b = bytes[..HEADER_LEN + 64].to_vec();
    b[132..136].copy_from_slice(&u32::MAX.to_le_bytes());
    let len = u32::MAX as u64 * PAGE_ENTRY_LEN as u64;
    let at = length_at(SectionKind::PageTable);
    b[at..at + 8].copy_from_slice(&len.to_le_bytes());
    refresh_checksums(&mut b);
    let e = within_seconds(move || Store::from_bytes(b).unwrap_err());
    assert!(matches!(e, StoreError::Truncated { .. } | StoreError::Corrupt { .. }), "{e}");
}

/// Regression: a store with a grid step of 1e300 opened and verified although every position
/// of it is infinite in f32 scene space. Steps that cannot render are refused at open (so by
/// `verify` too), as are non-finite, zero and negative ones.
#[test]
fn grid_steps_that_cannot_render_are_refused() {
    let bytes = store_bytes(&scene());
    // Only the header changes: its own checksum is the one to refresh (refresh_checksums
    // leaves a header it cannot parse alone).
    let refresh_checksums = |b: &mut Vec<u8>| {
        let crc = checksum(&b[..HEADER_CRC_AT]);
        b[HEADER_CRC_AT..HEADER_LEN].copy_from_slice(&crc.to_le_bytes());
    };
    for step in [1e300, 1e19, 1e-300, 1e-40, 0.0, -1.0, f64::NAN, f64::INFINITY] {
        let mut b = bytes.clone();
        b[96..104].copy_from_slice(&step.to_le_bytes());
        refresh_checksums(&mut b);
        let e = Store::from_bytes(b).unwrap_err();
        assert!(matches!(e, StoreError::Corrupt { offset: 96, .. }), "step {step}: {e}");
        assert!(e.to_string().contains("grid step"), "{e}");
    }
    // Scene bounds (relative to the grid origin) beyond f32 rendering: the camera is framed by
    // them.
    for (at, v) in [(48, 1e300), (24, -1e19), (72, 1e30)] {
        let mut b = bytes.clone();
        b[at..at + 8].copy_from_slice(&f64::to_le_bytes(v));
        refresh_checksums(&mut b);
        let e = Store::from_bytes(b).unwrap_err();
        assert!(matches!(e, StoreError::Corrupt { .. }) && e.to_string().contains("scene bound"), "{e}");
    }
    // A step that is fine alone, with a root box whose far corner is beyond f32 rendering.
    let mut b = bytes.clone();
    b[96..104].copy_from_slice(&1e17f64.to_le_bytes());
    refresh_checksums(&mut b);
    let e = Store::from_bytes(b).unwrap_err();
    assert!(e.to_string().contains("root box"), "{e}");
    assert!(check(bytes).is_ok());
}

/// Regression (found by the `store` fuzz target): a table whose length reaches past the end of
/// the u64 range made the next table's expected offset overflow (a panic with overflow checks)
/// instead of an error.
#[test]
fn a_table_length_past_u64_is_an_error() {
    let mut b = store_bytes(&scene());
    // The group sources: their length is not bounded by an entry count in the header.
    let at = 160 + 24 * SectionKind::GroupSources as usize + 8;
    b[at..at + 8].copy_from_slice(&(u64::MAX - 7).to_le_bytes());
    refresh_checksums(&mut b);
    let e = Store::from_bytes(b).unwrap_err();
    assert!(e.to_string().contains("truncated") || e.to_string().contains("tables"), "{e}");
}

/// Replays the `store` fuzz target's corpus and crashers (fuzz/corpus/store,
/// fuzz/regressions/store) with their checksums recomputed: the fuzzer's build skips checksums,
/// so without this the ordinary build would stop at the checksum before the code that failed.
#[test]
fn fuzz_inputs_with_valid_checksums_do_not_panic() {
    let fuzz = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz");
    let mut files = Vec::new();
    for dir in ["corpus/store", "regressions/store"] {
        if let Ok(entries) = std::fs::read_dir(fuzz.join(dir)) {
            files.extend(entries.filter_map(|e| e.ok()).map(|e| e.path()));
        }
    }
    assert!(!files.is_empty(), "no corpus for the store fuzz target");
    let panicked: Vec<_> = files
        .iter()
        .filter(|f| {
            let mut b = std::fs::read(f).unwrap();
            refresh_checksums(&mut b);
            std::panic::catch_unwind(|| tw_store::fuzz_bytes(&b)).is_err()
        })
        .collect();
    assert!(panicked.is_empty(), "these inputs panic: {panicked:?}");
}
