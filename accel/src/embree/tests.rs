use super::*;
use crate::FiberOrientation;
use tress_core::math::Frame;
use tress_core::rng::Pcg32;
use tress_groom::test_util::{hair, hair_file_bytes, line, rng_dir, HairArrays};
use tress_groom::{HairAttribute, Rotation};

fn with_basis(basis: CurveBasis) -> HairOptions {
    HairOptions {
        basis,
        ..Default::default()
    }
}

/// Every basis in both shapes.
fn all_curves() -> Vec<HairOptions> {
    [CurveShape::Flat, CurveShape::Round]
        .into_iter()
        .flat_map(|curve| {
            [
                CurveBasis::Linear,
                CurveBasis::CatmullRom,
                CurveBasis::BSpline,
            ]
            .map(|basis| HairOptions {
                basis,
                curve,
                ..Default::default()
            })
        })
        .collect()
}

fn fiber(hit: &Hit) -> (Vec3, f32, f32, u32, f32) {
    match hit.kind {
        HitKind::Fiber {
            tangent,
            h,
            radius,
            strand,
            v,
            ..
        } => (tangent, h, radius, strand, v),
        HitKind::Surface { .. } => panic!("expected a fiber hit, got {hit:?}"),
    }
}

#[test]
fn accel_is_send_and_sync() {
    fn check<T: Send + Sync>() {}
    check::<EmbreeAccel>();
}

#[test]
fn single_fiber_hit_reports_t_tangent_h_and_v() {
    let r = 0.1;
    for options in all_curves() {
        let curve = options.curve;
        for reversed in [false, true] {
            let (a, b) = (Vec3::new(-1.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0));
            let pts = if reversed {
                line(b, a, 3)
            } else {
                line(a, b, 3)
            };
            let accel = SceneBuilder::new()
                .unwrap()
                .add_hair(&hair(&[pts], r), &options, 5)
                .unwrap()
                .build()
                .unwrap();
            for y0 in [0.05f32, -0.07, 0.0, 0.099, -0.099] {
                for dir in [-Vec3::Z, Vec3::new(0.3, 0.0, -1.0).normalize()] {
                    let target = Vec3::new(0.3, y0, 0.0);
                    let ray = Ray::new(target - 5.0 * dir, dir);
                    let hit = accel.intersect(&ray).expect("hit");
                    let (tangent, h, radius, strand, v) = fiber(&hit);
                    let sign = if reversed { -1.0 } else { 1.0 };
                    // The tube is hit on its surface, (r² − y0²)^½ / sin θ before the axis
                    // plane z = 0; the ribbon, met at the axis, reports the tube's hit.
                    let want_t = 5.0 - (r * r - y0 * y0).sqrt() / dir.z.abs();
                    assert!((hit.t - want_t).abs() < 1e-3, "{options:?} t = {}", hit.t);
                    assert!((hit.p - ray.at(want_t)).length() < 1e-3);
                    assert!((tangent - sign * Vec3::X).length() < 1e-4, "{tangent}");
                    // The same impact parameter on the ribbon and on the tube.
                    assert!(
                        (h - sign * y0 / r).abs() < 2e-3,
                        "{options:?} reversed={reversed} y0={y0}: h = {h}"
                    );
                    assert!((radius - r).abs() < 1e-6);
                    assert_eq!((strand, hit.material), (0, 5));
                    // Where the ray passes the axis (the ribbon's curve parameter) or the wall.
                    let at = match curve {
                        CurveShape::Flat => ray.at(5.0),
                        CurveShape::Round => hit.p,
                    };
                    let along = (at.x + 1.0) / 2.0;
                    let want_v = if reversed { 1.0 - along } else { along };
                    assert!((v - want_v).abs() < 1e-3, "{options:?} v = {v}");
                    assert!(accel.occluded(&ray));
                    assert!(!accel.occluded(&ray.with_t_max(0.99 * hit.t)));
                }
            }
            let miss = Ray::new(Vec3::new(0.3, 0.12, 5.0), -Vec3::Z);
            assert!(accel.intersect(&miss).is_none() && !accel.occluded(&miss));
        }
    }
}

#[test]
fn smooth_bases_follow_the_curve_through_the_points() {
    // Seven points on a quarter circle of radius 1 in the xy plane; fiber radius 0.02.
    let r = 0.02;
    let n = 7;
    let angle = |i: f32| i / (n - 1) as f32 * std::f32::consts::FRAC_PI_2;
    let pts: Vec<Vec3> = (0..n)
        .map(|i| Vec3::new(angle(i as f32).cos(), angle(i as f32).sin(), 0.0))
        .collect();
    let h_mid = |basis| {
        let accel = SceneBuilder::new()
            .unwrap()
            .add_hair(&hair(std::slice::from_ref(&pts), r), &with_basis(basis), 0)
            .unwrap()
            .build()
            .unwrap();
        // Next to each input point (Embree's cubic ribbons leave a crack of zero width exactly
        // at segment joints): h ≈ 0 and the circle's tangent.
        for i in 1..n - 1 {
            let a = angle(i as f32) + 1e-3;
            let near = Vec3::new(a.cos(), a.sin(), 0.0);
            let hit = accel
                .intersect(&Ray::new(near + 5.0 * Vec3::Z, -Vec3::Z))
                .unwrap_or_else(|| panic!("{basis:?}: no hit at input point {i}"));
            let (tangent, h, ..) = fiber(&hit);
            let a = angle(i as f32);
            let want = Vec3::new(-a.sin(), a.cos(), 0.0);
            assert!(h.abs() < 0.02, "{basis:?} point {i}: h = {h}");
            if basis != CurveBasis::Linear {
                assert!(
                    tangent.dot(want) > 3f32.to_radians().cos(),
                    "{basis:?} {tangent}"
                );
            }
        }
        // Halfway between two points, on the true circle.
        let a = angle(2.5);
        let on_circle = Vec3::new(a.cos(), a.sin(), 0.0);
        let hit = accel
            .intersect(&Ray::new(on_circle + 5.0 * Vec3::Z, -Vec3::Z))
            .expect("hit between points");
        fiber(&hit).1
    };
    // The chord misses the circle by its sagitta, 1 − cos(7.5°) ≈ 0.43 radii; the cubics follow
    // the circle.
    assert!((h_mid(CurveBasis::Linear).abs() - 0.43).abs() < 0.03);
    assert!(h_mid(CurveBasis::CatmullRom).abs() < 0.05);
    assert!(h_mid(CurveBasis::BSpline).abs() < 0.05);
}

/// Distance from `p` to the polyline `pts`.
fn polyline_distance(p: Vec3, pts: &[Vec3]) -> f32 {
    pts.windows(2)
        .map(|w| {
            let ab = w[1] - w[0];
            let t = ((p - w[0]).dot(ab) / ab.length_squared()).clamp(0.0, 1.0);
            p.distance(w[0] + ab * t)
        })
        .fold(f32::INFINITY, f32::min)
}

/// Shoots rays at random points of strand `strand` (axis `pts`, radius `r`) from random
/// directions; a fifth of the targets sit exactly on joints. Returns the hits on that strand
/// with the incoming direction.
fn hits_on_strand(
    accel: &EmbreeAccel,
    pts: &[Vec3],
    strand: u32,
    r: f32,
    count: usize,
    rng: &mut Pcg32,
) -> Vec<(Hit, Vec3)> {
    let mut out = Vec::new();
    for _ in 0..100 * count {
        if out.len() == count {
            break;
        }
        let seg = (rng.next_f32() * (pts.len() - 1) as f32) as usize;
        let s = if rng.next_f32() < 0.2 {
            0.0
        } else {
            rng.next_f32()
        };
        let axis_point = pts[seg].lerp(pts[seg + 1], s);
        let t = (pts[seg + 1] - pts[seg]).normalize();
        let d_in = rng_dir(rng);
        if d_in.dot(t).abs() > 0.95 {
            continue;
        }
        let side = t.cross(d_in).normalize();
        let target = axis_point + side * r * (2.0 * rng.next_f32() - 1.0) * 0.99;
        if let Some(hit) = accel.intersect(&Ray::new(target - 3.0 * d_in, d_in)) {
            if fiber(&hit).3 == strand {
                out.push((hit, d_in));
            }
        }
    }
    assert_eq!(out.len(), count, "strand {strand} is hard to hit");
    out
}

/// Directions to leave a hit from: uniform, grazing the strand (down to 0.001°), exactly along
/// it, and continuing through the fiber (the hemisphere of the incoming direction).
fn leaving_directions(tangent: Vec3, d_in: Vec3, rng: &mut Pcg32) -> Vec<Vec3> {
    let mut dirs: Vec<Vec3> = (0..12).map(|_| rng_dir(rng)).collect();
    dirs.extend([tangent, -tangent]);
    let f = Frame::from_z(tangent);
    for _ in 0..12 {
        let angle = 10f32.powf(-3.0 + 3.7 * rng.next_f32()).to_radians();
        let phi = 2.0 * std::f32::consts::PI * rng.next_f32();
        let d = f.to_world(Vec3::new(
            angle.sin() * phi.cos(),
            angle.sin() * phi.sin(),
            angle.cos(),
        ));
        dirs.push(if rng.next_f32() < 0.5 { d } else { -d });
    }
    for _ in 0..12 {
        let d = rng_dir(rng);
        dirs.push(if d.dot(d_in) < 0.0 { -d } else { d });
    }
    dirs
}

#[test]
fn rays_leaving_a_fiber_do_not_hit_it_again_but_hit_a_neighbour() {
    let r = 0.05;
    let a = line(Vec3::new(-2.0, 0.0, 0.0), Vec3::new(2.0, 0.0, 0.0), 9);
    let b = line(Vec3::new(-2.0, 0.2, 0.0), Vec3::new(2.0, 0.2, 0.0), 9);
    let mut rng = Pcg32::new(1, 2);
    for options in all_curves() {
        let basis = (options.basis, options.curve);
        let accel = SceneBuilder::new()
            .unwrap()
            .add_hair(&hair(&[a.clone(), b.clone()], r), &options, 0)
            .unwrap()
            .build()
            .unwrap();
        let mut aimed = 0;
        for (hit, d_in) in hits_on_strand(&accel, &a, 0, r, 300, &mut rng) {
            let (tangent, ..) = fiber(&hit);
            for dir in leaving_directions(tangent, d_in, &mut rng) {
                let ray = Ray::leaving(hit.p, dir, hit.prim);
                let again = accel.intersect(&ray);
                if let Some(h2) = &again {
                    assert_ne!(
                        fiber(h2).3,
                        0,
                        "{basis:?}: ray from {} along {dir} re-hit its own straight strand at t = {} (prim {} → {})",
                        hit.p,
                        h2.t,
                        hit.prim.prim,
                        h2.prim.prim
                    );
                }
                assert_eq!(accel.occluded(&ray), again.is_some());
            }
            // Aimed at a point on the axis of the parallel strand, at least 3 radii from its
            // joints: near a joint Embree may report the neighbouring segment's rounded end,
            // whose depth is that of the joint.
            let joint = (hit.p.x / 0.5).round() * 0.5;
            let q = Vec3::new(
                joint + 0.25 * (2.0 * rng.next_f32() - 1.0).signum() + 0.2 * rng.next_f32() - 0.1,
                0.2,
                0.0,
            );
            if q.x.abs() > 2.0 {
                continue;
            }
            let dist = q.distance(hit.p);
            let ray = Ray::leaving(hit.p, (q - hit.p) / dist, hit.prim);
            let h2 = accel.intersect(&ray).expect("the neighbour strand is hit");
            assert_eq!(fiber(&h2).3, 1, "{basis:?}");
            // A tube is hit on its wall, r / sin θ before the axis for a ray at θ to the strand,
            // and a ribbon reports the same.
            let before = r / ray.dir.cross(Vec3::X).length();
            assert!(
                h2.t <= dist * (1.0 + 2e-3) && h2.t >= dist * (1.0 - 2e-3) - before,
                "{basis:?}: t {} vs {dist}",
                h2.t
            );
            assert!(accel.occluded(&ray.with_t_max(1.01 * dist)));
            assert!(!accel.occluded(&ray.with_t_max(0.5 * dist)));
            aimed += 1;
        }
        assert!(aimed > 200);
    }
}

#[test]
fn same_strand_hits_need_free_space_on_a_bent_strand() {
    // A zig-zag strand bending by ±25° at every joint, and a hairpin whose legs face each other.
    let r = 0.05;
    let zig: Vec<Vec3> = (0..9)
        .map(|i| {
            let y = if i % 2 == 0 {
                0.0
            } else {
                0.5 * 25f32.to_radians().tan()
            };
            Vec3::new(-2.0 + 0.5 * i as f32, y, 0.0)
        })
        .collect();
    let mut pin = line(Vec3::new(0.0, 5.0, 0.0), Vec3::new(2.0, 5.0, 0.0), 5);
    pin.extend([Vec3::new(2.3, 5.15, 0.0)]);
    pin.extend(line(Vec3::new(2.0, 5.3, 0.0), Vec3::new(0.0, 5.3, 0.0), 5));
    let mut rng = Pcg32::new(3, 4);
    let accel = SceneBuilder::new()
        .unwrap()
        .add_hair(&hair(&[zig.clone(), pin], r), &HairOptions::default(), 0)
        .unwrap()
        .build()
        .unwrap();
    let mut kept = 0;
    for (hit, d_in) in hits_on_strand(&accel, &zig, 0, r, 300, &mut rng) {
        let (tangent, ..) = fiber(&hit);
        for dir in leaving_directions(tangent, d_in, &mut rng) {
            let Some(h2) = accel.intersect(&Ray::leaving(hit.p, dir, hit.prim)) else {
                continue;
            };
            assert_ne!(h2.prim, hit.prim);
            // Independent check by marching: before the hit the ray must have been outside the
            // fiber (all segment capsules of radius r) somewhere.
            let step = r / 200.0;
            let left = (0..=(h2.t / step) as usize)
                .any(|i| polyline_distance(hit.p + dir * (i as f32 * step), &zig) > r);
            assert!(
                left,
                "ray from {} along {dir} hit its own strand (prim {} → {}) at t = {} without leaving it",
                hit.p, hit.prim.prim, h2.prim.prim, h2.t
            );
            kept += 1;
        }
    }
    // Legitimate hits on the same strand, through free space, are kept.
    for x in [0.3f32, 0.9, 1.4] {
        let from = accel
            .intersect(&Ray::new(Vec3::new(x, 5.0 + 0.01, -3.0), Vec3::Z))
            .expect("lower leg");
        assert_eq!(fiber(&from).3, 1);
        let up = accel
            .intersect(&Ray::leaving(from.p, Vec3::Y, from.prim))
            .expect("upper leg of the hairpin");
        assert_eq!(fiber(&up).3, 1);
        // The legs' axes are 0.29 apart along the ray, which passes the upper one at the
        // height of the lower one's wall: its wall is met that much sooner.
        let want = 0.29 - (r * r - from.p.z * from.p.z).max(0.0).sqrt();
        assert!((up.t - want).abs() < 1e-3, "{} vs {want}", up.t);
    }
    println!("{kept} legitimate same-strand hits on the zig-zag strand");
}

#[test]
fn meshes_and_spheres_report_facing_normals_and_materials() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("quad.obj");
    std::fs::write(&obj, "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nf 1 2 3 4\n").unwrap();
    let mesh = TriangleMesh::load_obj(&obj).unwrap();
    // Rotated into the plane y = -1 (x axis by −90°: z → y).
    let transform = Transform {
        scale: 2.0,
        rotate: Rotation::Euler(Vec3::new(-90.0, 0.0, 0.0)),
        translate: Vec3::new(0.0, -1.0, 0.0),
    };
    let accel = SceneBuilder::new()
        .unwrap()
        .add_mesh(&mesh, &transform, 3)
        .unwrap()
        .add_sphere(Vec3::new(0.0, 0.0, -5.0), 1.0, 7)
        .unwrap()
        .build()
        .unwrap();
    let surface = |hit: &Hit| match hit.kind {
        HitKind::Surface { normal } => normal,
        HitKind::Fiber { .. } => panic!("expected a surface"),
    };
    let down = accel
        .intersect(&Ray::new(Vec3::new(0.5, 2.0, 0.3), -Vec3::Y))
        .unwrap();
    assert!((down.t - 3.0).abs() < 1e-5 && down.material == 3);
    assert!((surface(&down) - Vec3::Y).length() < 1e-5);
    let up = accel
        .intersect(&Ray::new(Vec3::new(1.5, -4.0, -1.5), Vec3::Y))
        .unwrap();
    assert!((up.t - 3.0).abs() < 1e-5);
    assert!((surface(&up) + Vec3::Y).length() < 1e-5);
    // Outside the scaled quad (half-size 2).
    assert!(accel
        .intersect(&Ray::new(Vec3::new(2.5, 2.0, 0.0), -Vec3::Y))
        .is_none());
    // Leaving the quad downward: nothing else below.
    assert!(accel
        .intersect(&Ray::leaving(down.p, -Vec3::Y, down.prim))
        .is_none());
    let s = accel
        .intersect(&Ray::new(Vec3::new(0.0, 0.0, 0.0), -Vec3::Z))
        .unwrap();
    assert!((s.t - 4.0).abs() < 1e-4 && s.material == 7);
    assert!((surface(&s) - Vec3::Z).length() < 1e-4);
    let n = Vec3::new(0.0, 0.6, 0.8);
    let s = accel
        .intersect(&Ray::new(Vec3::new(0.0, 0.0, -5.0) + 4.0 * n, -n))
        .unwrap();
    assert!((s.t - 3.0).abs() < 1e-4);
    assert!((surface(&s) - Vec3::new(0.0, 0.6, 0.8)).length() < 1e-3);
    // A ray leaving the sphere outward does not hit it again.
    assert!(accel
        .intersect(&Ray::leaving(s.p, Vec3::new(0.0, 0.6, 0.8), s.prim))
        .is_none());

    let info = accel.info();
    assert_eq!((info.triangles, info.spheres, info.strands), (2, 1, 0));
    assert!((info.bounds.min - Vec3::new(-2.0, -1.0, -6.0)).length() < 1e-5);
    assert!((info.bounds.max - Vec3::new(2.0, 1.0, 2.0)).length() < 1e-5);
    assert_eq!(accel.bounds(), info.bounds);
    assert!(info.memory_bytes > 0);
}

#[test]
fn options_transform_taper_and_subsample_hair() {
    let strands: Vec<Vec<Vec3>> = (0..40)
        .map(|i| {
            line(
                Vec3::new(i as f32, 0.0, 0.0),
                Vec3::new(i as f32, 1.0, 0.0),
                5,
            )
        })
        .collect();
    let g = hair(&strands, 0.1);
    let options = HairOptions {
        tip_scale: 0.5,
        radius_scale: 2.0,
        transform: Transform {
            scale: 2.0,
            rotate: Rotation::AxisAngle {
                axis: Vec3::Y,
                degrees: 180.0,
            },
            translate: Vec3::new(0.0, 0.0, 1.0),
        },
        strand_fraction: 0.25,
        strand_seed: 9,
        ..Default::default()
    };
    let accel = SceneBuilder::new()
        .unwrap()
        .add_hair(&g, &options, 2)
        .unwrap()
        .build()
        .unwrap();
    let info = accel.info();
    assert_eq!((info.strands, info.segments, info.points), (10, 40, 50));
    let (_, kept) = g.subsample(0.25, 9);
    for &s in &kept {
        // Strand s now runs from (−2s, 0, 1) up to (−2s, 2, 1); radius 0.1·2·2 = 0.4 at the root,
        // 0.2 at the tip.
        let x = -2.0 * s as f32;
        for (y, radius, v) in [(0.0f32, 0.4f32, 0.0f32), (1.0, 0.3, 0.5), (2.0, 0.2, 1.0)] {
            let y = y.clamp(0.01, 1.99);
            let hit = accel
                .intersect(&Ray::new(Vec3::new(x, y, 10.0), -Vec3::Z))
                .expect("kept strand is hit");
            let (tangent, h, rad, strand, hv) = fiber(&hit);
            assert_eq!(strand, s, "the original strand index is reported");
            assert!((tangent - Vec3::Y).length() < 1e-4);
            assert!(h.abs() < 1e-3);
            assert!((rad - radius).abs() < 0.005, "{rad} vs {radius}");
            assert!((hv - v).abs() < 0.01);
            // Met on the tube's wall, a radius before the axis.
            assert!((hit.t - (9.0 - rad)).abs() < 1e-3, "t = {}", hit.t);
        }
    }
    let dropped = (0..40u32).find(|s| !kept.contains(s)).unwrap();
    assert!(accel
        .intersect(&Ray::new(
            Vec3::new(-2.0 * dropped as f32, 1.0, 10.0),
            -Vec3::Z
        ))
        .is_none());
}

#[test]
fn bad_objects_are_refused_with_their_name() {
    let g = hair(&[line(Vec3::ZERO, Vec3::X, 3)], 0.1);
    let bad = HairOptions {
        strand_fraction: 1.5,
        ..Default::default()
    };
    let e = SceneBuilder::new()
        .unwrap()
        .add_hair(&g, &bad, 0)
        .err()
        .unwrap()
        .to_string();
    assert!(
        e.contains("test hair") && e.contains("strand_fraction"),
        "{e}"
    );
    let degenerate = hair(&[vec![Vec3::ONE; 4]], 0.1);
    let e = SceneBuilder::new()
        .unwrap()
        .add_hair(&degenerate, &HairOptions::default(), 0)
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("non-zero length"), "{e}");
    assert!(SceneBuilder::new()
        .unwrap()
        .add_sphere(Vec3::ZERO, -1.0, 0)
        .is_err());
    let huge = Transform {
        scale: 1e38,
        ..Default::default()
    };
    let far = hair(&[line(Vec3::ZERO, Vec3::splat(1e5), 3)], 0.1);
    let opts = HairOptions {
        transform: huge,
        ..Default::default()
    };
    assert!(SceneBuilder::new()
        .unwrap()
        .add_hair(&far, &opts, 0)
        .is_err());
}

/// A `.hair` file read as scene files name it (Z-up, converted to Y-up) and built: every strand,
/// segment and point reaches Embree, the bounds are the Y-up ones padded by the radius, and
/// rays through the patch hit it while rays beside it miss.
#[test]
fn a_hair_file_builds_and_is_hit() {
    // A 20 × 20 patch of straight strands hanging from z = 10 to z = 3, 0.2 apart: the radius
    // (the header's thickness 0.25, halved) closes the gaps between them.
    let points: Vec<[f32; 3]> = (0..400)
        .flat_map(|s| {
            (0..8).map(move |k| {
                [
                    0.2 * (s % 20) as f32,
                    0.2 * (s / 20) as f32,
                    10.0 - k as f32,
                ]
            })
        })
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("patch.hair");
    std::fs::write(
        &path,
        hair_file_bytes(400, &points, &HairArrays::default(), 7),
    )
    .unwrap();
    let g = tress_groom::HairFile::new(&path).read().unwrap();
    let accel = SceneBuilder::new()
        .unwrap()
        .add_hair(&g, &HairOptions::default(), 0)
        .unwrap()
        .build()
        .unwrap();
    let info = accel.info();
    assert_eq!(
        (info.strands, info.segments, info.points),
        (400, 2800, 3200)
    );
    // (x, y, z) → (x, z, −y), padded by the radius 0.125.
    let (lo, hi) = (
        Vec3::new(-0.125, 2.875, -3.925),
        Vec3::new(3.925, 10.125, 0.125),
    );
    assert!(
        (info.bounds.min - lo).abs().max_element() < 1e-3
            && (info.bounds.max - hi).abs().max_element() < 1e-3,
        "{:?}",
        info.bounds
    );
    let hits = |x: f32| {
        (0..100)
            .filter(|i| {
                let y = 3.5 + 0.06 * *i as f32;
                accel
                    .intersect(&Ray::new(Vec3::new(x, y, 10.0), -Vec3::Z))
                    .is_some()
            })
            .count()
    };
    assert_eq!(hits(1.9), 100);
    assert_eq!(hits(4.1), 0);
}

#[test]
fn concurrent_queries_match_serial_ones() {
    let g = tress_groom::ProceduralHair {
        strands: 500,
        ..Default::default()
    }
    .generate(&Limits::default())
    .unwrap();
    let accel = SceneBuilder::new()
        .unwrap()
        .add_hair(&g, &HairOptions::default(), 0)
        .unwrap()
        .add_sphere(Vec3::ZERO, 1.0, 1)
        .unwrap()
        .build()
        .unwrap();
    let rays: Vec<Ray> = {
        let mut rng = Pcg32::new(5, 6);
        (0..4000)
            .map(|_| {
                let d = rng_dir(&mut rng);
                Ray::new(-4.0 * d + 0.5 * rng_dir(&mut rng), d)
            })
            .collect()
    };
    let trace = |rays: &[Ray]| -> Vec<Option<(u32, u32, f32)>> {
        rays.iter()
            .map(|r| accel.intersect(r).map(|h| (h.prim.geom, h.prim.prim, h.t)))
            .collect()
    };
    let serial = trace(&rays);
    assert!(serial.iter().filter(|h| h.is_some()).count() > 1000);
    let (a, b) = rays.split_at(rays.len() / 2);
    let (ra, rb) = std::thread::scope(|s| {
        let ha = s.spawn(|| trace(a));
        let hb = s.spawn(|| trace(b));
        (ha.join().unwrap(), hb.join().unwrap())
    });
    assert_eq!([ra, rb].concat(), serial);
}

/// `occluded_by_surfaces` sees spheres and meshes through hair, and never hair itself.
#[test]
fn surface_occlusion_ignores_fibers() {
    let fiber = hair(
        &[line(Vec3::new(-1.0, 0.0, 2.0), Vec3::new(1.0, 0.0, 2.0), 4)],
        0.05,
    );
    let accel = SceneBuilder::new()
        .unwrap()
        .add_hair(&fiber, &HairOptions::default(), 0)
        .unwrap()
        .add_sphere(Vec3::new(0.0, 0.0, -3.0), 1.0, 1)
        .unwrap()
        .build()
        .unwrap();
    // Through the fiber into the sphere: blocked by both queries.
    let to_sphere = Ray::new(Vec3::new(0.0, 0.0, 5.0), -Vec3::Z);
    assert!(accel.occluded(&to_sphere) && accel.occluded_by_surfaces(&to_sphere));
    // Through the fiber only (stopping before the sphere): hair blocks, no surface does.
    let through_hair = to_sphere.with_t_max(4.0);
    assert!(accel.occluded(&through_hair));
    assert!(!accel.occluded_by_surfaces(&through_hair));
    // Missing everything.
    let miss = Ray::new(Vec3::new(0.0, 5.0, 5.0), -Vec3::Z);
    assert!(!accel.occluded(&miss) && !accel.occluded_by_surfaces(&miss));
    // Hair-only scenes answer without tracing.
    let hair_only = SceneBuilder::new()
        .unwrap()
        .add_hair(&fiber, &HairOptions::default(), 0)
        .unwrap()
        .build()
        .unwrap();
    assert!(!hair_only.occluded_by_surfaces(&to_sphere));
}

/// A neighbour whose axis lies 1.44 radii from the point where a ray leaves a fiber's wall
/// toward it (1.2 radii across, 0.8 up; 2.16 radii from the first fiber's axis: the fibers do
/// not touch): nearer than Embree's culling of flat-curve hits (two radii from the origin)
/// would allow. Every shape and basis.
#[test]
fn rays_leaving_a_fiber_find_a_near_neighbour() {
    let r = 0.01;
    for options in all_curves() {
        let lower = line(Vec3::new(-1.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), 4);
        let (y, z) = (1.2 * r, 1.8 * r);
        let upper = line(Vec3::new(-1.0, y, z), Vec3::new(1.0, y, z), 4);
        let accel = SceneBuilder::new()
            .unwrap()
            .add_hair(&hair(&[lower, upper], r), &options, 0)
            .unwrap()
            .build()
            .unwrap();
        // Straight down onto the lower fiber's top, beside the upper one.
        let camera = Ray::new(Vec3::new(0.3, 0.0, 1.0), -Vec3::Z);
        let first = accel.intersect(&camera).expect("the lower fiber");
        assert_eq!(fiber(&first).3, 0, "{options:?}");
        assert!(
            (first.p.z - r).abs() < 1e-4,
            "{options:?}: hit at {}",
            first.p
        );
        let toward = (Vec3::new(0.3, y, z) - first.p).normalize();
        let leaving = Ray::leaving(first.p, toward, first.prim);
        let next = accel.intersect(&leaving).unwrap_or_else(|| {
            panic!("{options:?}: the ray leaving the lower fiber passed the upper one")
        });
        assert_eq!(fiber(&next).3, 1, "{options:?}");
        // Aimed at the axis: the wall, a radius before it.
        let axis = (Vec3::new(0.3, y, z) - first.p).length();
        assert!(
            (next.t - (axis - r)).abs() < 1e-3 * r + 1e-5,
            "{options:?}: t = {} (wall {})",
            next.t,
            axis - r
        );
        assert!(accel.occluded(&leaving), "{options:?}");
        assert!(!accel.occluded(&leaving.with_t_max(0.4 * r)), "{options:?}");
    }
}

/// In a dense stack of parallel fibers (eight sublayers a hair's breadth apart, fibers two to
/// three radii apart within each), the fibers a ray finds by chaining hits — and whether a
/// shadow ray from the first passes — are exactly the crossings the fibers' positions give,
/// for ribbons and tubes, at any angle across the fibers.
#[test]
fn chained_hits_count_every_fiber_of_a_dense_layer() {
    let (r, half) = (0.01f32, 1.0f32);
    let mut rng = Pcg32::new(7, 1);
    // About four fibers crossed by a vertical line, more by oblique ones.
    let mut strands: Vec<Vec<Vec3>> = Vec::new();
    for k in 0..8 {
        let z = -2.05 * r * k as f32;
        let mut y = -half + r * rng.next_f32();
        while y < half {
            let x0 = (2.0 * rng.next_f32() - 1.0) * half - 0.5;
            strands.push(line(Vec3::new(x0, y, z), Vec3::new(x0 + 1.0, y, z), 3));
            y += 2.0 * r + r * rng.next_f32();
        }
    }
    // Rays in the y-z plane, up to 63° from the vertical, through (x, y, 0). Flat linear curves
    // are hit within a radius of the segment (rounded ends included); the line has constant x.
    let distance = |s: &[Vec3], x: f32, y: f32, a: f32| {
        let dx = (s[0].x - x).max(x - s[2].x).max(0.0);
        dx.hypot((s[0].y - y) * a.cos() + s[0].z * a.sin())
    };
    let crossings =
        |x: f32, y: f32, a: f32| strands.iter().filter(|s| distance(s, x, y, a) < r).count();
    for curve in [CurveShape::Flat, CurveShape::Round] {
        let options = HairOptions {
            curve,
            basis: CurveBasis::Linear,
            ..Default::default()
        };
        let accel = SceneBuilder::new()
            .unwrap()
            .add_hair(&hair(&strands, r), &options, 0)
            .unwrap()
            .build()
            .unwrap();
        let (mut rays, mut wrong_count, mut wrong_shadow, mut several) = (0, 0, 0, 0);
        for _ in 0..4000 {
            let (x, y, a) = (
                (2.0 * rng.next_f32() - 1.0) * 0.5 * half,
                (2.0 * rng.next_f32() - 1.0) * 0.5 * half,
                (2.0 * rng.next_f32() - 1.0) * 1.1,
            );
            let want = crossings(x, y, a);
            // Grazing a fiber's edge: either answer is right to rounding.
            if strands
                .iter()
                .any(|s| (distance(s, x, y, a) - r).abs() < 1e-4 * r)
            {
                continue;
            }
            rays += 1;
            several += usize::from(want > 1);
            let dir = Vec3::new(0.0, a.sin(), -a.cos());
            let camera = Ray::new(Vec3::new(x, y, 0.0) - 3.0 * dir, dir);
            let Some(first) = accel.intersect(&camera) else {
                wrong_count += usize::from(want != 0);
                continue;
            };
            // A tube is entered and left: count the distinct strands.
            let mut found = vec![fiber(&first).3];
            let mut ray = Ray::leaving(first.p, dir, first.prim);
            while let Some(h) = accel.intersect(&ray) {
                let strand = fiber(&h).3;
                if !found.contains(&strand) {
                    found.push(strand);
                }
                ray = Ray::leaving(h.p, dir, h.prim);
            }
            wrong_count += usize::from(found.len() != want);
            let passes = !accel.occluded(&Ray::leaving(first.p, dir, first.prim));
            wrong_shadow += usize::from(passes != (want == 1));
        }
        assert!(
            several > rays / 2,
            "the stack is not dense: {several} of {rays}"
        );
        assert!(
            wrong_count == 0 && wrong_shadow == 0,
            "{curve:?}: {wrong_count} chained counts and {wrong_shadow} shadow rays of {rays} \
             disagree with the fibers' positions"
        );
    }
}

/// Where two fibers interpenetrate, a ray leaving one from inside the other scatters off the
/// second where it leaves it (`Overlaps::Scatter`), or passes through it to the next fiber
/// (`Overlaps::PassThrough`, the default and Mitsuba 3's convention); a fiber entered from outside
/// is hit either way — for every basis, ribbons and tubes, intersection and occlusion.
#[test]
fn rays_starting_inside_another_fiber_follow_the_overlap_convention() {
    let r = 0.1;
    // A along x at the origin; B overlapping it from below (axes 1.2 r apart); C free, lower.
    // Rays cross at x = 0, mid-segment, away from the joints' rounded ends.
    let at = |z: f32| line(Vec3::new(-1.0, 0.0, z), Vec3::new(1.0, 0.0, z), 4);
    let strands = [at(0.0), at(-1.2 * r), at(-10.0 * r)];
    for overlaps in [Overlaps::Scatter, Overlaps::PassThrough] {
        for options in all_curves() {
            let options = HairOptions {
                overlaps,
                ..options
            };
            let accel = SceneBuilder::new()
                .unwrap()
                .add_hair(&hair(&strands, r), &options, 0)
                .unwrap()
                .build()
                .unwrap();
            let down = Ray::new(Vec3::new(0.0, 0.0, 1.0), -Vec3::Z);
            let top_of_a = accel.intersect(&down).expect("A");
            assert_eq!(fiber(&top_of_a).3, 0, "{options:?}");
            // Leaving A's underside, 0.2 r inside B, straight down.
            let origin = Vec3::new(0.0, 0.0, -r);
            let leaving = Ray::leaving(origin, -Vec3::Z, top_of_a.prim);
            let next = accel.intersect(&leaving).expect("B or C");
            let (strand, t) = match overlaps {
                Overlaps::Scatter => (1, 1.2 * r),     // B's lower wall
                Overlaps::PassThrough => (2, 8.0 * r), // C's upper wall
            };
            assert_eq!(fiber(&next).3, strand, "{options:?}");
            assert!(
                (next.t - t).abs() < 1e-3,
                "{options:?}: t = {}, want {t}",
                next.t
            );
            assert_eq!(
                accel.occluded(&leaving.with_t_max(4.0 * r)),
                overlaps == Overlaps::Scatter,
                "{options:?}"
            );
            // Leaving C's top upwards: B is entered from outside, whatever the convention.
            let up = Ray::new(Vec3::new(0.0, 0.0, -20.0 * r), Vec3::Z);
            let bottom_of_c = accel.intersect(&up).expect("C");
            assert_eq!(fiber(&bottom_of_c).3, 2, "{options:?}");
            let leaving_c = Ray::leaving(Vec3::new(0.0, 0.0, -9.0 * r), Vec3::Z, bottom_of_c.prim);
            let b = accel.intersect(&leaving_c).expect("B");
            assert_eq!(fiber(&b).3, 1, "{options:?}");
            assert!((b.t - 6.8 * r).abs() < 1e-3, "{options:?}: t = {}", b.t);
        }
    }
}

/// Hits carry the fibers' orientation: a fixed direction made orthogonal to the strand, the
/// file's per-strand orientation, or by default the minimum-twist frame started away from the
/// centre of the roots; in scenes that keep it (models using it), and zero in the others,
/// which store none.
#[test]
fn hits_carry_the_orientation_the_options_state() {
    // Two straight strands along x, rooted at x = −1, on either side of the roots' centre.
    let strands = [
        line(Vec3::new(-1.0, 0.5, 0.0), Vec3::new(1.0, 0.5, 0.0), 3),
        line(Vec3::new(-1.0, -0.5, 0.0), Vec3::new(1.0, -0.5, 0.0), 3),
    ];
    let orientation_at = |hair: &HairGeometry, orientation: FiberOrientation, y: f32| {
        let options = HairOptions {
            orientation,
            ..Default::default()
        };
        let accel = SceneBuilder::new()
            .unwrap()
            .with_fiber_orientation()
            .add_hair(hair, &options, 0)
            .unwrap()
            .build()
            .unwrap();
        let ray = Ray::new(Vec3::new(0.3, y, 5.0), -Vec3::Z);
        match accel.intersect(&ray).expect("hit").kind {
            HitKind::Fiber { orientation, .. } => orientation,
            HitKind::Surface { .. } => panic!("expected a fiber"),
        }
    };
    let plain = hair(&strands, 0.1);
    let fixed = FiberOrientation::Fixed((1.0, 0.0, 2.0));
    assert!((orientation_at(&plain, fixed, 0.5) - Vec3::Z).length() < 1e-5);
    // Away from the roots' centre (0, 0, 0): +y for the upper strand, −y for the lower.
    for orientation in [FiberOrientation::Groom, FiberOrientation::ScalpNormal] {
        let up = orientation_at(&plain, orientation.clone(), 0.5);
        let down = orientation_at(&plain, orientation, -0.5);
        assert!((up - Vec3::Y).length() < 1e-5 && (down + Vec3::Y).length() < 1e-5);
    }
    let mut from_file = plain.clone();
    from_file.orientations = Some(HairAttribute::PerStrand(vec![Vec3::Z, Vec3::Z]));
    let groom = orientation_at(&from_file, FiberOrientation::Groom, 0.5);
    assert!((groom - Vec3::Z).length() < 1e-5, "{groom}");
    let scalp = orientation_at(&from_file, FiberOrientation::ScalpNormal, 0.5);
    assert!((scalp - Vec3::Y).length() < 1e-5, "{scalp}");

    let plain_accel = |oriented: bool| {
        let builder = SceneBuilder::new().unwrap();
        let builder = if oriented {
            builder.with_fiber_orientation()
        } else {
            builder
        };
        builder
            .add_hair(&from_file, &with_basis(CurveBasis::CatmullRom), 0)
            .unwrap()
            .build()
            .unwrap()
    };
    let (without, with) = (plain_accel(false), plain_accel(true));
    let ray = Ray::new(Vec3::new(0.3, 0.5, 5.0), -Vec3::Z);
    match without.intersect(&ray).expect("hit").kind {
        HitKind::Fiber { orientation, .. } => assert_eq!(orientation, Vec3::ZERO),
        HitKind::Surface { .. } => panic!("expected a fiber"),
    }
    match with.intersect(&ray).expect("hit").kind {
        HitKind::Fiber { orientation, .. } => assert!((orientation - Vec3::Z).length() < 1e-5),
        HitKind::Surface { .. } => panic!("expected a fiber"),
    }
    // 12 bytes for each of the 2 strands' 3 points and 2 phantom control points.
    assert_eq!(
        with.info().memory_bytes - without.info().memory_bytes,
        2 * 5 * 12,
    );
}

/// What the caller holds beside the builder (a file kept for later objects) counts against
/// the scene's memory limit, each call replacing the last count.
#[test]
fn bytes_held_beside_the_builder_count_against_the_memory_limit() {
    let limits = Limits {
        memory_gib: 1.0,
        ..Limits::default()
    };
    let strands = hair(&[line(Vec3::ZERO, Vec3::Y, 100)], 0.01);
    let mut builder = SceneBuilder::new().unwrap().with_limits(limits);
    builder.hold_beside(0.25 * GIB);
    assert_eq!(builder.limits().scene_gib, 0.25);
    builder.hold_beside(0.5 * GIB);
    assert_eq!(builder.limits().scene_gib, 0.5);
    let mut builder = builder
        .add_hair(&strands, &HairOptions::default(), 0)
        .expect("fits beside half a GiB");
    builder.hold_beside(GIB);
    let e = builder
        .add_hair(&strands, &HairOptions::default(), 0)
        .err()
        .expect("nothing fits beside a whole GiB")
        .to_string();
    assert!(e.contains("GiB"), "{e}");
}
