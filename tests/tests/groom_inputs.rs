//! Groom inputs end to end: PLY strand files (ascii and both binary byte orders), pbrt-v4
//! curve scenes and child strands, read the way scene files name them.

use glam::Vec2;
use std::path::{Path, PathBuf};
use tress_accel::{HairOptions, SceneBuilder};
use tress_core::math::Vec3;
use tress_groom::{ChildStrands, HairGeometry, HairSource, PbrtFile, PlyFile};

/// A fresh scratch folder for one test.
fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("groom_inputs_{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Three strands of awkward, exactly known f32 values, and their per-point radii.
fn strands() -> Vec<Vec<([f32; 3], f32)>> {
    (0..3)
        .map(|s| {
            (0..4 + s)
                .map(|i| {
                    let t = (s * 7 + i) as f32;
                    (
                        [0.1 * t - 1.0 / 3.0, (t * 0.7).sin() * 1e3, -2.5e-4 * t],
                        1e-4 * (1.0 + t) / 3.0,
                    )
                })
                .collect()
        })
        .collect()
}

#[derive(Clone, Copy)]
enum Encoding {
    Ascii,
    Little,
    Big,
}

/// A PLY file of [`strands`], written by hand (not with the reader's crate): float vertices
/// with a `radius`, and a `strand` element of vertex counts.
fn ply_bytes(encoding: Encoding) -> Vec<u8> {
    let strands = strands();
    let points: usize = strands.iter().map(Vec::len).sum();
    let format = match encoding {
        Encoding::Ascii => "ascii",
        Encoding::Little => "binary_little_endian",
        Encoding::Big => "binary_big_endian",
    };
    let mut out = format!(
        "ply\nformat {format} 1.0\ncomment written by tress's tests\nelement vertex {points}\n\
         property float x\nproperty float y\nproperty float z\nproperty float radius\n\
         property uchar red\nelement strand {}\nproperty int vertex_count\nend_header\n",
        strands.len()
    )
    .into_bytes();
    let put = |out: &mut Vec<u8>, v: f32| match encoding {
        // `{:?}` prints the shortest text that reads back as the same f32.
        Encoding::Ascii => out.extend(format!("{v:?} ").bytes()),
        Encoding::Little => out.extend(v.to_le_bytes()),
        Encoding::Big => out.extend(v.to_be_bytes()),
    };
    for (p, r) in strands.iter().flatten() {
        p.iter().for_each(|&c| put(&mut out, c));
        put(&mut out, *r);
        match encoding {
            Encoding::Ascii => out.extend(b"200\n"),
            _ => out.push(200),
        }
    }
    for s in &strands {
        match encoding {
            Encoding::Ascii => out.extend(format!("{}\n", s.len()).bytes()),
            Encoding::Little => out.extend((s.len() as i32).to_le_bytes()),
            Encoding::Big => out.extend((s.len() as i32).to_be_bytes()),
        }
    }
    out
}

#[test]
fn ply_round_trips_exactly_in_every_encoding() {
    let dir = scratch("ply_round_trip");
    let expect = strands();
    for (encoding, name) in [
        (Encoding::Ascii, "ascii.ply"),
        (Encoding::Little, "little.PLY"),
        (Encoding::Big, "big.ply"),
    ] {
        let path = dir.join(name);
        std::fs::write(&path, ply_bytes(encoding)).unwrap();
        let g = HairSource::File(path.clone())
            .load(&Default::default())
            .unwrap();
        assert_eq!(g.strand_count(), 3, "{name}");
        let mut at = 0;
        for (s, strand) in expect.iter().enumerate() {
            assert_eq!(g.strand(s).len(), strand.len(), "{name}");
            for (p, r) in strand {
                assert_eq!(g.points[at], Vec3::from_array(*p), "{name} point {at}");
                assert_eq!(g.radii[at], *r, "{name} radius {at}");
                at += 1;
            }
        }
        // The options: one radius for all, and Z-up data turned Y-up.
        let o = HairSource::Ply(PlyFile {
            radius: Some(0.5),
            z_up: true,
            ..PlyFile::new(&path)
        })
        .load(&Default::default())
        .unwrap();
        assert!(o.radii.iter().all(|&r| r == 0.5));
        let [x, y, z] = expect[0][1].0;
        assert_eq!(o.points[1], Vec3::new(x, z, -y));
    }
}

#[test]
fn truncated_and_corrupt_ply_files_are_errors_naming_the_file() {
    let dir = scratch("ply_corrupt");
    for (encoding, name) in [
        (Encoding::Ascii, "cut_ascii.ply"),
        (Encoding::Little, "cut_little.ply"),
        (Encoding::Big, "cut_big.ply"),
    ] {
        let good = ply_bytes(encoding);
        let path = dir.join(name);
        // Every cut inside the payload, and a sample of cuts in the header.
        let header_end = good.windows(11).position(|w| w == b"end_header\n").unwrap() + 11;
        for len in (0..header_end).step_by(7).chain(header_end..good.len()) {
            std::fs::write(&path, &good[..len]).unwrap();
            match HairSource::File(path.clone()).load(&Default::default()) {
                Err(e) => assert!(e.to_string().contains(name), "{len}: {e}"),
                // An ascii file cut after a number's first digits can still read (a shorter
                // number): what reads must be valid.
                Ok(g) => {
                    assert!(
                        matches!(encoding, Encoding::Ascii),
                        "{name} cut at {len} read"
                    );
                    g.validate().unwrap();
                }
            }
        }
    }
    // A vertex count past the end, and a count that takes more vertices than there are.
    let mut text = String::from_utf8(ply_bytes(Encoding::Ascii)).unwrap();
    let path = dir.join("counts.ply");
    let last = text.trim_end().rfind('\n').unwrap();
    text.replace_range(last + 1.., "9\n");
    std::fs::write(&path, &text).unwrap();
    let e = HairSource::File(path)
        .load(&Default::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("counts.ply") && e.contains("strand 2 needs vertices"),
        "{e}"
    );
    let path = dir.join("mesh.ply");
    std::fs::write(
        &path,
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
         property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n\
         0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n",
    )
    .unwrap();
    let e = HairSource::File(path)
        .load(&Default::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("mesh.ply") && e.contains("no strand structure") && e.contains("surface"),
        "{e}"
    );
}

/// The fixture `tests/data/curves.pbrt`.
fn fixture() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("data/curves.pbrt")
}

fn cubic(cp: [Vec3; 4], u: f32) -> Vec3 {
    let s = 1.0 - u;
    s * s * s * cp[0] + 3.0 * s * s * u * cp[1] + 3.0 * s * u * u * cp[2] + u * u * u * cp[3]
}

fn assert_near(got: Vec3, want: Vec3, what: &str) {
    assert!((got - want).length() < 1e-5, "{what}: {got} vs {want}");
}

#[test]
fn the_pbrt_fixture_reads_into_the_expected_strands() {
    let g = HairSource::File(fixture())
        .load(&Default::default())
        .unwrap();
    // Four strands: the sphere and the camera-side Translate play no part.
    assert_eq!(g.strand_count(), 4);
    let sizes: Vec<usize> = (0..4).map(|s| g.strand(s).len()).collect();
    // Straight: no refinement. The bent ones: as many halvings as keep every chord within
    // width/20 of the curve (worked out in the fixture's comments' terms: 16 + 16 pieces for
    // strand 1, 8 + 8 for the B-spline, 4 for the quadratic).
    assert_eq!(sizes, [3, 33, 17, 5]);
    let strand = |s: usize| &g.points[g.strand(s)];
    let radii = |s: usize| &g.radii[g.strand(s)];

    // Strand 0: the line's points at the segment ends, radius = width / 2.
    for (i, y) in [0.0, 3.0, 6.0].into_iter().enumerate() {
        assert_near(strand(0)[i], Vec3::new(0.0, y, 0.0), "strand 0");
    }
    assert!(radii(0).iter().all(|&r| r == 0.05));

    // Strand 1: two joined Bézier segments, translated by x + 2; widths 0.2 → 0.1, 0.1 → 0.05.
    let v = |x: f32, y: f32| Vec3::new(x + 2.0, y, 0.0);
    let segments = [
        [v(0., 0.), v(0., 1.), v(1., 2.), v(1., 3.)],
        [v(1., 3.), v(1., 4.), v(0., 5.), v(0., 6.)],
    ];
    for (k, &p) in strand(1).iter().enumerate() {
        let (seg, u) = if k <= 16 {
            (0, k as f32 / 16.0)
        } else {
            (1, (k - 16) as f32 / 16.0)
        };
        assert_near(p, cubic(segments[seg], u), &format!("strand 1 point {k}"));
        let width = if seg == 0 {
            0.2 - 0.1 * u
        } else {
            0.1 - 0.05 * u
        };
        assert!(
            (radii(1)[k] - width / 2.0).abs() < 1e-6,
            "strand 1 radius {k}"
        );
    }

    // Strand 2: the uniform cubic B-spline of 0, 0, 1, 2, 2 (in y), scaled by 2 and moved to
    // x = −2; the Attribute width 0.08 scaled by 2.
    let ys = [0.0f32, 0.0, 1.0, 2.0, 2.0];
    let bspline = |seg: usize, t: f32| {
        let w = &ys[seg..seg + 4];
        let s = 1.0 - t;
        (s * s * s * w[0]
            + (3.0 * t * t * t - 6.0 * t * t + 4.0) * w[1]
            + (-3.0 * t * t * t + 3.0 * t * t + 3.0 * t + 1.0) * w[2]
            + t * t * t * w[3])
            / 6.0
    };
    for (k, &p) in strand(2).iter().enumerate() {
        let (seg, t) = if k <= 8 {
            (0, k as f32 / 8.0)
        } else {
            (1, (k - 8) as f32 / 8.0)
        };
        assert_near(
            p,
            Vec3::new(-2.0, 2.0 * bspline(seg, t), 0.0),
            &format!("strand 2 point {k}"),
        );
    }
    assert!(radii(2).iter().all(|&r| (r - 0.08).abs() < 1e-6));

    // Strand 3: the quadratic (2u, 2u(1 − u), 0) turned 90° about y, moved to z − 2; width 1.
    for (k, &p) in strand(3).iter().enumerate() {
        let u = k as f32 / 4.0;
        assert_near(
            p,
            Vec3::new(0.0, 2.0 * u * (1.0 - u), -2.0 - 2.0 * u),
            &format!("strand 3 point {k}"),
        );
    }
    assert!(radii(3).iter().all(|&r| (r - 0.5).abs() < 1e-6));

    // The explicit form, Z-up.
    let z_up = HairSource::Pbrt(PbrtFile {
        z_up: true,
        ..PbrtFile::new(fixture())
    })
    .load(&Default::default())
    .unwrap();
    assert_near(z_up.points[2], Vec3::new(0.0, 0.0, -6.0), "z-up");
}

#[test]
fn bad_pbrt_files_name_the_file_and_place() {
    let dir = scratch("pbrt_bad");
    let fixture = std::fs::read_to_string(fixture()).unwrap();
    // Damage the first curve: 6 control points are not 4 + 3n.
    let bad = fixture.replacen("0 5 0  0 6 0 ]", "0 5 0 ]", 1);
    let path = dir.join("bad.pbrt");
    std::fs::write(&path, bad).unwrap();
    let e = HairSource::File(path)
        .load(&Default::default())
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("bad.pbrt") && e.contains("line 18, column 1") && e.contains("6 control points"),
        "{e}"
    );
    // The include is resolved beside the main file: missing here.
    let path = dir.join("alone.pbrt");
    std::fs::write(&path, &fixture).unwrap();
    let e = HairSource::File(path)
        .load(&Default::default())
        .unwrap_err()
        .to_string();
    assert!(e.contains("curves_include.pbrt"), "{e}");
    // Cut anywhere, the fixture gives an error or fewer curves, never a panic.
    std::fs::write(dir.join("curves_include.pbrt"), "").unwrap();
    let path = dir.join("cut.pbrt");
    for len in (0..fixture.len()).step_by(13) {
        if !fixture.is_char_boundary(len) {
            continue;
        }
        std::fs::write(&path, &fixture[..len]).unwrap();
        if let Err(e) = HairSource::File(path.clone()).load(&Default::default()) {
            assert!(e.to_string().contains("cut.pbrt"), "{len}: {e}");
        }
    }
}

/// Sixteen guides of a small wavy patch.
fn guides() -> HairGeometry {
    let mut g = HairGeometry::empty("guides");
    for s in 0..16 {
        let root = Vec3::new((s % 4) as f32 * 0.3, 0.0, (s / 4) as f32 * 0.3);
        let points: Vec<Vec3> = (0..12)
            .map(|i| {
                let v = i as f32 / 11.0;
                root + Vec3::new(0.1 * (5.0 * v + s as f32).sin(), -2.0 * v, 0.2 * v * v)
            })
            .collect();
        g.push_strand(&points, 0.01);
    }
    g
}

#[test]
fn child_strands_are_added_deterministically_around_kept_guides() {
    let g = guides();
    let children = ChildStrands {
        per_guide: 6,
        radius: 0.1,
        seed: 3,
        blend: 1,
        clump: 0.0,
        thinning: 0.0,
        radius_jitter: 0.0,
    };
    let grown = children.grow(&g, 1.0, &Default::default()).unwrap();
    assert_eq!(grown.strand_count(), 16 * 7);
    assert_eq!(grown.points[..g.point_count()], g.points[..]);
    assert_eq!(grown, children.grow(&g, 1.0, &Default::default()).unwrap());
    // Without clumping a child keeps its root's distance to the guide all along.
    for c in 0..16 * 6 {
        let guide = &g.points[g.strand(c / 6)];
        let child = &grown.points[grown.strand(16 + c)];
        let offset = (child[0] - guide[0]).length();
        assert!(offset <= 0.1 + 1e-6, "child {c}: root {offset}");
        for (p, q) in child.iter().zip(guide) {
            assert!(((*p - *q).length() - offset).abs() < 1e-4, "child {c}");
        }
    }
    // Through the scene builder: the options grow the children (radius in scene units, after
    // the transform's scale), then draw the strand subset.
    let options = |children: Option<ChildStrands>, fraction: f32| HairOptions {
        children,
        strand_fraction: fraction,
        transform: tress_groom::Transform {
            scale: 2.0,
            ..Default::default()
        },
        ..Default::default()
    };
    let strands = |o: &HairOptions| {
        let accel = SceneBuilder::new()
            .and_then(|b| b.add_hair(&g, o, 0))
            .and_then(|b| b.build())
            .unwrap();
        accel.info().strands
    };
    assert_eq!(strands(&options(None, 1.0)), 16);
    assert_eq!(strands(&options(Some(children.clone()), 1.0)), 112);
    assert_eq!(strands(&options(Some(children.clone()), 0.5)), 56);
    let bad = HairOptions {
        children: Some(ChildStrands {
            radius: -1.0,
            ..children
        }),
        ..Default::default()
    };
    let e = SceneBuilder::new()
        .and_then(|b| b.add_hair(&g, &bad, 0))
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("guides") && e.contains("children.radius"), "{e}");
}

/// Fraction of a `side`² image the scene's hair covers, from 8 × 8 camera rays a pixel.
fn coverage(scene: &tress_core::Scene, side: u32) -> f64 {
    const SUB: u32 = 8;
    let mut hits = 0u64;
    for y in 0..side * SUB {
        for x in 0..side * SUB {
            let (px, py) = ((x as f32 + 0.5) / SUB as f32, (y as f32 + 0.5) / SUB as f32);
            let ray = scene.camera.generate_ray(px, py, side, side, Vec2::ZERO);
            hits += u64::from(scene.accel().intersect(&ray).is_some());
        }
    }
    hits as f64 / f64::from(side * side * SUB * SUB)
}

/// [`guides`] as a TressFX file: the 160-byte header (version, strand count, vertices per
/// strand, the positions' offset) and a float4 per vertex.
fn tfx_bytes(g: &HairGeometry) -> Vec<u8> {
    let mut b = vec![0u8; 160];
    let per = g.strand(0).len() as u32;
    b[0..4].copy_from_slice(&4.0f32.to_le_bytes());
    b[4..8].copy_from_slice(&(g.strand_count() as u32).to_le_bytes());
    b[8..12].copy_from_slice(&per.to_le_bytes());
    b[12..16].copy_from_slice(&160u32.to_le_bytes());
    for p in &g.points {
        for v in [p.x, p.y, p.z, 1.0] {
            b.extend_from_slice(&v.to_le_bytes());
        }
    }
    b
}

/// Sixteen TressFX guides, framed from the front, with and without children, through a scene
/// file.
#[test]
fn tfx_guides_with_children_cover_far_more_of_the_image() {
    let dir = scratch("tfx_children");
    let file = dir.join("guides.tfx");
    std::fs::write(&file, tfx_bytes(&guides())).unwrap();
    let scene = |children: &str| {
        format!(
            r#"(
    camera: (look_from: (0.5, -1, 4), look_at: (0.5, -1, 0), fov: 40),
    film: (width: 48, height: 48, spp: 1, seed: 1),
    integrator: Path(),
    materials: {{ "brown": Hair(Chiang(beta_m: 0.3, beta_n: 0.3, alpha: 2.0,
                                     pigment: Melanin(eumelanin: 1.3, pheomelanin: 0.2))) }},
    objects: [ Hair(source: Tfx(path: {file:?}, radius: 0.005), material: "brown",
                    options: (basis: CatmullRom, tip_scale: 0.5 {children})) ],
    lights: [Sky(rotation: 0, scale: 1)],
)"#
        )
    };
    let measure = |children: &str| {
        let path = dir.join("scene.ron");
        std::fs::write(&path, scene(children)).unwrap();
        let desc = tress_loader::scene_desc::load(&path).unwrap();
        let built = tress_loader::scene_desc::build(&desc, &path, &Default::default()).unwrap();
        (coverage(&built.scene, 48), built.summary)
    };
    let (guides_only, summary) = measure("");
    assert!(summary.contains(" 16 strands"), "{summary}");
    let (with_children, summary) =
        measure(", children: Some(per_guide: 16, radius: 0.15, seed: 1, blend: 3, clump: 0.2)");
    assert!(summary.contains(" 272 strands"), "{summary}");
    eprintln!("coverage: guides {guides_only:.4}, with 16 children a guide {with_children:.4}");
    assert!(guides_only > 0.0);
    assert!(
        with_children > 6.0 * guides_only,
        "{guides_only} → {with_children}"
    );
}

/// Objects that name the same file with the same reader options share one read (each keeps
/// its own transform); the same path with other reader options is another read.
#[test]
fn a_file_several_objects_name_is_read_once() {
    let dir = scratch("shared_reads");
    let file = dir.join("guides.tfx");
    std::fs::write(&file, tfx_bytes(&guides())).unwrap();
    let summary = |objects: &[(&str, f32)]| {
        let objects: Vec<String> = objects
            .iter()
            .map(|(source, x)| {
                format!(
                    r#"Hair(source: {source}, material: "brown",
                            options: (transform: (translate: ({x}, 0, 0))))"#
                )
            })
            .collect();
        let path = dir.join("scene.ron");
        std::fs::write(
            &path,
            format!(
                r#"(
    camera: (look_from: (1.5, -1, 8), look_at: (1.5, -1, 0), fov: 40),
    film: (width: 48, height: 48, spp: 1, seed: 1),
    integrator: Path(),
    materials: {{ "brown": Hair(Chiang()) }},
    objects: [ {} ],
    lights: [Sky(rotation: 0, scale: 1)],
)"#,
                objects.join(",\n")
            ),
        )
        .unwrap();
        let desc = tress_loader::scene_desc::load(&path).unwrap();
        tress_loader::scene_desc::build(&desc, &path, &Default::default())
            .unwrap()
            .summary
    };
    let plain = format!("File({file:?})");
    let other_radius = format!("Tfx(path: {file:?}, radius: 0.005)");

    let shared = summary(&[
        (&plain, 0.0),
        (&plain, 1.0),
        (&other_radius, 2.0),
        (&plain, 3.0),
    ]);
    assert!(
        shared.contains("2 objects reused a file read for an earlier object"),
        "{shared}"
    );
    assert_eq!(shared.matches(" 16 strands").count(), 4, "{shared}");

    // Named once, a file is read once and not kept: no reuse to report.
    let alone = summary(&[(&plain, 0.0), (&other_radius, 2.0)]);
    assert!(!alone.contains("reused"), "{alone}");
    assert_eq!(alone.matches(" 16 strands").count(), 2, "{alone}");
}
