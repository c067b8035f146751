//! Per-segment materials ([`SceneBuilder::add_hair_varied`]).

use super::*;
use tress_core::math::Rgb;
use tress_groom::test_util::{hair, line};
use tress_groom::HairAttribute;

/// Two strands along x at y = 0 and y = 1 (z = 0), of 4 segments each, with per-point colours.
fn two_strands() -> HairGeometry {
    let mut g = hair(
        &[
            line(Vec3::new(0.0, 0.0, 0.0), Vec3::new(4.0, 0.0, 0.0), 5),
            line(Vec3::new(0.0, 1.0, 0.0), Vec3::new(4.0, 1.0, 0.0), 5),
        ],
        0.05,
    );
    g.colors = Some(HairAttribute::PerPoint(
        (0..10).map(|i| Rgb::splat(i as f32 / 10.0)).collect(),
    ));
    g
}

fn material_at(accel: &EmbreeAccel, x: f32, y: f32) -> u32 {
    let hit = accel
        .intersect(&Ray::new(Vec3::new(x, y, 5.0), -Vec3::Z))
        .expect("hit");
    hit.material
}

#[test]
fn every_segment_gets_the_material_chosen_for_it() {
    let mut seen = Vec::new();
    let accel = SceneBuilder::new()
        .unwrap()
        .add_hair_varied(&two_strands(), &HairOptions::default(), |segments| {
            seen = segments.to_vec();
            // Material 10 + 10·strand + segment index.
            Ok(segments
                .iter()
                .map(|s| 10 + 10 * s.strand + (s.v * 4.0) as u32)
                .collect())
        })
        .unwrap()
        .build()
        .unwrap();
    assert_eq!(seen.len(), 8);
    for (k, s) in seen.iter().enumerate() {
        let (strand, j) = (k / 4, k % 4);
        assert_eq!(s.strand, strand as u32);
        assert_eq!(s.v, (j as f32 + 0.5) / 4.0);
        // The mean of the end points' colours.
        let point = 5 * strand + j;
        let want = (point as f32 + 0.5) / 10.0;
        assert!((s.color.unwrap() - Rgb::splat(want)).abs().max_element() < 1e-6);
    }
    for strand in 0..2 {
        for j in 0..4 {
            let m = material_at(&accel, j as f32 + 0.5, strand as f32);
            assert_eq!(m, 10 + 10 * strand + j, "strand {strand}, segment {j}");
        }
    }
    assert_eq!(accel.info().objects[0].materials, 10..24);
    assert!(accel.info().to_string().contains("(materials 10–23)"));
}

#[test]
fn subsampled_and_degenerate_strands_keep_segments_and_materials_aligned() {
    // A strand whose first segment has zero length (skipped) and a subsample keeping one of
    // two strands: what the caller sees are the primitives, in order.
    let mut g = two_strands();
    g.points[1] = g.points[0];
    let options = HairOptions {
        strand_fraction: 0.5,
        strand_seed: 1,
        ..Default::default()
    };
    let mut seen = Vec::new();
    let accel = SceneBuilder::new()
        .unwrap()
        .add_hair_varied(&g, &options, |segments| {
            seen = segments.to_vec();
            Ok(segments
                .iter()
                .map(|s| 100 * s.strand + (s.v * 4.0) as u32)
                .collect())
        })
        .unwrap()
        .build()
        .unwrap();
    let kept = seen[0].strand;
    let expect_segments = if kept == 0 { 3 } else { 4 };
    assert_eq!(seen.len(), expect_segments);
    assert!(seen.iter().all(|s| s.strand == kept));
    for j in 4 - expect_segments..4 {
        let m = material_at(&accel, j as f32 + 0.5, kept as f32);
        assert_eq!(m, 100 * kept + j as u32);
    }
}

#[test]
fn a_wrong_material_count_or_a_refusal_names_the_object() {
    let e = SceneBuilder::new()
        .unwrap()
        .add_hair_varied(&two_strands(), &HairOptions::default(), |s| {
            Ok(vec![0; s.len() - 1])
        })
        .err()
        .expect("an error")
        .to_string();
    assert!(
        e.contains("test hair") && e.contains("7 materials chosen for 8"),
        "{e}"
    );
    let e = SceneBuilder::new()
        .unwrap()
        .add_hair_varied(&two_strands(), &HairOptions::default(), |_| {
            Err("strand 3 is purple".into())
        })
        .err()
        .expect("an error")
        .to_string();
    assert_eq!(e, "test hair: strand 3 is purple");
}

#[test]
fn hair_without_variation_has_one_material() {
    let accel = SceneBuilder::new()
        .unwrap()
        .add_hair(&two_strands(), &HairOptions::default(), 4)
        .unwrap()
        .build()
        .unwrap();
    assert_eq!(accel.info().objects[0].materials, 4..5);
    assert_eq!(material_at(&accel, 2.5, 1.0), 4);
    assert!(accel.info().to_string().contains("(material 4)"));
}
