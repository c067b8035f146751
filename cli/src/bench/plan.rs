//! What one run measures: its sizes, models and their labels.

use std::path::PathBuf;
use tress_accel::CurveShape;
use tress_loader::integrators::IntegratorDesc;
use tress_materials::dual_scattering::DualScatteringSettings;

/// Sizes of one run.
pub(super) struct Plan {
    /// Procedural strand counts: the scaling pair (small, large).
    pub(super) strands: [u32; 2],
    /// Rays per kind in the raw measurements.
    pub(super) rays: usize,
    /// Film of the integrator renders: width = height, spp.
    pub(super) film: (u32, u32),
    /// BCSDF calls per timing.
    pub(super) bcsdf_calls: usize,
    /// Timed repetitions of every integrator render and replay; the fastest counts, since
    /// interference from other processes only ever slows a run down.
    pub(super) runs: usize,
    /// Resolution of the dual-scattering tables whose build time is measured.
    pub(super) tables: DualScatteringSettings,
    /// Every registered integrator: with test settings for `--quick`, defaults otherwise.
    pub(super) integrators: Vec<IntegratorDesc>,
}

impl Plan {
    pub(super) fn new(quick: bool) -> Plan {
        if quick {
            Plan {
                strands: [1_000, 10_000],
                rays: 1 << 12,
                film: (32, 2),
                bcsdf_calls: 20_000,
                runs: 1,
                tables: DualScatteringSettings {
                    theta_nodes: 16,
                    h_nodes: 8,
                    theta_quad: 16,
                    phi_quad: 24,
                    walks: 1024,
                    ..Default::default()
                },
                integrators: IntegratorDesc::all_for_tests(),
            }
        } else {
            Plan {
                strands: [10_000, 100_000],
                rays: 1 << 18,
                film: (128, 8),
                bcsdf_calls: 400_000,
                runs: 3,
                tables: DualScatteringSettings::default(),
                integrators: IntegratorDesc::all(),
            }
        }
    }
}

/// Segments per procedural strand.
pub(super) const SEGMENTS: u32 = 32;
/// Strands of the `--huge` model.
pub(super) const HUGE_STRANDS: u32 = 1_000_000;
/// Raw queries handed to a worker at a time (a multiple of the packet width).
pub(super) const CHUNK: usize = 1024;

/// Where a model's hair comes from.
#[derive(Clone)]
pub(super) enum Source {
    /// Procedural wavy hair: strands, fiber radius.
    Procedural(u32, f32),
    File(PathBuf),
}

/// Whether the path tracer's ray-rate target applies: the large procedural model (100k strands
/// at the common radius) and the hair file.
pub(super) fn ray_target(source: &Source, plan: &Plan) -> bool {
    match *source {
        Source::Procedural(n, r) => n == plan.strands[1] && n == 100_000 && r == RADIUS,
        Source::File(_) => true,
    }
}

/// Fiber radius of the procedural models (the procedural default).
pub(super) const RADIUS: f32 = 0.004;

/// Radius of `strands` fibers covering as much as `reference` fibers of [`RADIUS`] do (equal
/// total cross-section, so equal optical thickness and the same picture).
pub(super) fn equal_coverage_radius(strands: u32, reference: u32) -> f32 {
    RADIUS * (reference as f32 / strands as f32).sqrt()
}

/// Label of the large procedural model thinned to the small one's coverage.
pub(super) fn thin_label(strands: u32) -> String {
    format!("{}-thin", strand_label(strands))
}

pub(super) struct ModelSpec {
    pub(super) name: String,
    pub(super) source: Source,
    /// Raw measurements and the integrators' renders; otherwise (the huge model) the path
    /// tracer on a small film only.
    pub(super) full: bool,
    /// Every integrator, or only the path tracer (the round-curve variants).
    pub(super) all_integrators: bool,
    pub(super) curve: CurveShape,
}

pub(super) fn strand_label(n: u32) -> String {
    if n >= 1_000_000 && n.is_multiple_of(1_000_000) {
        format!("{}M", n / 1_000_000)
    } else if n >= 1000 && n.is_multiple_of(1000) {
        format!("{}k", n / 1000)
    } else {
        n.to_string()
    }
}
