//! The Embree scene: [`SceneBuilder`] adds hair, meshes and spheres; [`EmbreeAccel`] answers
//! ray queries with [`tress_core::Hit`]s. See the crate docs for the fiber frame, the sign of
//! `h` and the self-intersection rule.

use crate::curve_data::{CurveData, HairSegment, SegmentMaterials, StrandRecord};
use crate::curves::{CurveBasis, CurveShape, Overlaps};
use crate::error::{Error, Result};
use crate::fp_mode;
use crate::mesh::TriangleMesh;
use crate::options::HairOptions;
use embree3::sys::RTCFilterFunctionNArguments;
use embree3::{
    BufferUsage, Device, DeviceProperty, Format, GeometryBuilder, GeometryKind,
    IntersectContextExt, RayHit, Scene, SceneFlags,
};
use glam::Vec4;
use std::borrow::Cow;
use std::fmt;
use std::ops::Range;
use std::sync::atomic::{AtomicIsize, Ordering};
use std::sync::Arc;
use tress_core::accel::{Accel, HairCurves, Hit, HitKind, PrimId};
use tress_core::limits::Limits;
use tress_core::math::{Aabb, Ray, Vec3};
use tress_groom::{HairGeometry, Transform};

const NO_ID: u32 = u32::MAX;
const GIB: f64 = (1u64 << 30) as f64;

/// What a query excludes, carried to [`context_filter`] in the intersection context.
#[derive(Clone, Copy, Debug)]
struct Exclude {
    geom: u32,
    prim: u32,
    /// Null, except in [`EmbreeAccel::count_fibers_crossed`]: there the filters record every
    /// kept hit (primitive and distance) here and reject it, so traversal goes on to the end
    /// of the ray.
    hits: *mut Vec<(PrimId, f32)>,
    /// Set by [`Accel::occluded_by_surfaces`]: fibers are transparent to the query.
    skip_hair: bool,
    /// The scene's geometries, indexed by Embree geometry id: each carries its own rule.
    geoms: *const [GeomData],
    /// [`EmbreeAccel::origin_shift`]: how far behind its origin Embree sees the ray start.
    origin_shift: f32,
}

/// How far from the origin, in world units, geometry (its points, padded by fiber and sphere
/// radii) may reach: ray tests square lengths, which overflow f32 beyond about 1e19 (fibers
/// 1e20 wide vanished under the path tracer).
pub const MAX_EXTENT: f32 = 1e18;

/// Refuses an object whose world bounds reach beyond [`MAX_EXTENT`].
fn check_extent(object: &str, bounds: &Aabb) -> Result<()> {
    let reach = bounds.min.abs().max(bounds.max.abs()).max_element();
    if reach.is_nan() || reach > MAX_EXTENT {
        return Err(Error::InvalidGeometry(tress_groom::InvalidGeometry {
            object: object.to_owned(),
            reason: format!(
                "reaches {reach:e} from the origin (bounds {} to {}), beyond the {MAX_EXTENT:e} \
                 that f32 ray tests can square: scale the scene down",
                bounds.min, bounds.max
            ),
        }));
    }
    Ok(())
}

#[derive(Debug)]
enum GeomData {
    Hair(Arc<CurveData>),
    Mesh {
        material: u32,
    },
    Spheres {
        materials: Vec<u32>,
        /// Centre and radius of each sphere.
        spheres: Vec<Vec4>,
    },
}

/// A candidate hit as [`context_filter`] sees it: geometry and primitive ids, the curve
/// parameter `u` (curves only) and the distance `t` from the ray's own origin.
#[derive(Clone, Copy, Debug)]
struct Candidate {
    geom: u32,
    prim: u32,
    u: f32,
    t: f32,
}

impl GeomData {
    /// Whether candidate `hit` on this geometry is kept by a query along `org + t·dir`
    /// excluding `ex`: fibers apply the self-intersection rule and, with
    /// [`Overlaps::PassThrough`], drop hits where the ray leaves a fiber it started inside;
    /// meshes skip only the (flat) triangle the ray leaves, and spheres the whole sphere, which
    /// a ray leaving it inwards meets again where [`EmbreeAccel::sphere_reentry`] finds.
    fn keep(&self, ex: &Exclude, hit: Candidate, org: Vec3, dir: Vec3) -> bool {
        let Candidate { geom, prim, u, t } = hit;
        match self {
            GeomData::Hair(c) => {
                !ex.skip_hair
                    && (geom != ex.geom || c.keep(ex.prim, prim, org, dir))
                    && (c.overlaps == Overlaps::Scatter
                        || !c.leaves_from_inside(prim, u, org, dir, t))
            }
            GeomData::Mesh { .. } | GeomData::Spheres { .. } => geom != ex.geom || prim != ex.prim,
        }
    }
}

/// What an object added to the scene is.
#[derive(Clone, Debug, PartialEq)]
pub enum ObjectKind {
    /// A hair object, drawn as Embree curves.
    Hair {
        /// Strands kept (after subsampling, with at least one non-degenerate segment).
        strands: usize,
        /// Curve segments (Embree primitives).
        segments: usize,
        /// Input points of the kept strands.
        points: usize,
        /// How the strands' polylines became curves.
        basis: CurveBasis,
        /// Whether the curves are ribbons or tubes.
        curve: CurveShape,
    },
    /// A triangle mesh.
    Mesh {
        /// Number of triangles.
        triangles: usize,
        /// Number of vertices.
        vertices: usize,
    },
    /// A sphere.
    Sphere {
        /// Centre, in world space.
        center: Vec3,
        /// Radius, in world units.
        radius: f32,
    },
}

/// One object of the scene, for `tress info`.
#[derive(Clone, Debug, PartialEq)]
pub struct ObjectInfo {
    /// Name used in messages: the object's file, generator description or `sphere #n`.
    pub name: String,
    /// What the object is, with its size.
    pub kind: ObjectKind,
    /// Indices of its materials in `Scene::materials`: one, or for hair with per-strand
    /// variation ([`SceneBuilder::add_hair_varied`]) the span of those its segments use.
    pub materials: Range<u32>,
    /// World bounds, padded by the fiber or sphere radius.
    pub bounds: Aabb,
}

/// Summary of a built scene.
#[derive(Clone, Debug, PartialEq)]
pub struct AccelInfo {
    /// Every object added, in order.
    pub objects: Vec<ObjectInfo>,
    /// Strands over all hair objects.
    pub strands: usize,
    /// Curve segments (Embree primitives) over all hair objects.
    pub segments: usize,
    /// Input points over all hair objects.
    pub points: usize,
    /// Triangles over all meshes.
    pub triangles: usize,
    /// Number of spheres.
    pub spheres: usize,
    /// Bounds of all objects, padded by the fiber and sphere radii.
    pub bounds: Aabb,
    /// Approximate memory: what Embree's device allocated (buffers and BVH) plus the data
    /// kept here for hit construction and filtering.
    pub memory_bytes: usize,
}

impl fmt::Display for AccelInfo {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "{} objects: {} strands, {} curve segments, {} points, {} triangles, {} spheres",
            self.objects.len(),
            self.strands,
            self.segments,
            self.points,
            self.triangles,
            self.spheres
        )?;
        let (lo, hi) = (self.bounds.min, self.bounds.max);
        writeln!(
            f,
            "bounds: ({:.4}, {:.4}, {:.4}) – ({:.4}, {:.4}, {:.4})",
            lo.x, lo.y, lo.z, hi.x, hi.y, hi.z
        )?;
        write!(
            f,
            "memory: {:.1} MiB",
            self.memory_bytes as f64 / (1024.0 * 1024.0)
        )?;
        for o in &self.objects {
            let (start, end) = (o.materials.start, o.materials.end);
            if end - start == 1 {
                write!(f, "\n  {} (material {start}): ", o.name)?;
            } else {
                write!(f, "\n  {} (materials {start}–{}): ", o.name, end - 1)?;
            }
            match &o.kind {
                ObjectKind::Hair {
                    strands,
                    segments,
                    points,
                    basis,
                    curve,
                } => write!(
                    f,
                    "hair, {strands} strands, {segments} segments, {points} points, {basis:?}, {curve:?}"
                )?,
                ObjectKind::Mesh {
                    triangles,
                    vertices,
                } => write!(f, "mesh, {triangles} triangles, {vertices} vertices")?,
                ObjectKind::Sphere { center, radius } => {
                    write!(f, "sphere, centre {center}, radius {radius}")?
                }
            }
        }
        Ok(())
    }
}

fn embree_error(object: &str, what: &str, e: embree3::Error) -> Error {
    Error::Embree(format!("{object}: {what}: {e}"))
}

/// The caller's choice of a material per segment ([`SceneBuilder::add_hair_varied`]).
type ChooseMaterials<'a> =
    Box<dyn FnOnce(&[HairSegment]) -> std::result::Result<Vec<u32>, String> + 'a>;

/// The material of a hair object: one, or one per segment chosen by the caller.
enum Materials<'a> {
    One(u32),
    PerSegment(ChooseMaterials<'a>),
}

/// Builds an [`EmbreeAccel`]: add objects, then [`SceneBuilder::build`].
pub struct SceneBuilder {
    device: Device,
    scene: Scene<'static>,
    geoms: Vec<GeomData>,
    objects: Vec<ObjectInfo>,
    spheres: Vec<(Vec4, u32)>,
    embree_bytes: Arc<AtomicIsize>,
    filters: bool,
    /// What the scene may take: every object added is checked against its memory limit with
    /// what the objects before it take ([`SceneBuilder::limits`]).
    limits: Limits,
    /// Estimated bytes of the objects added so far (see [`OBJECT_BYTES`] and the rates it
    /// cites).
    planned_bytes: f64,
    /// Bytes the caller holds for the scene beside the builder ([`SceneBuilder::hold_beside`]).
    held_beside_bytes: f64,
    /// Whether hair objects keep their fibers' orientation ([`SceneBuilder::with_fiber_orientation`]).
    orientation: bool,
}

/// What one object costs whatever its size, in bytes: Embree's geometry and BVH node overhead
/// and the records kept here (a scene of 100 000 one-strand objects took 0.9 GB, about 9 KB an
/// object).
pub const OBJECT_BYTES: f64 = 16384.0;
/// What a mesh triangle costs: its indices, and its share of Embree's BVH.
const BYTES_PER_TRIANGLE: f64 = 96.0;
/// What a mesh vertex costs: the transformed copy and Embree's vertex buffer.
const BYTES_PER_VERTEX: f64 = 32.0;
/// What a sphere costs: its centre, radius and material, twice, and its share of the BVH.
const BYTES_PER_SPHERE: f64 = 96.0;
/// What a hair point's orientation costs where the scene keeps it: one vector.
const ORIENTATION_BYTES_PER_POINT: f64 = 12.0;

impl SceneBuilder {
    /// A new Embree device and empty scene, held to the default [`Limits`].
    pub fn new() -> Result<Self> {
        let device = fp_mode::preserving_fp_mode(Device::new)
            .map_err(|e| Error::Embree(format!("cannot create device: {e}")))?;
        for (prop, what) in [
            (
                DeviceProperty::FILTER_FUNCTION_SUPPORTED,
                "filter functions",
            ),
            (DeviceProperty::CURVE_GEOMETRY_SUPPORTED, "curves"),
            (DeviceProperty::POINT_GEOMETRY_SUPPORTED, "point geometry"),
        ] {
            if device.get_property(prop).unwrap_or(0) == 0 {
                return Err(Error::Embree(format!(
                    "this Embree library was built without {what}"
                )));
            }
        }
        let embree_bytes = Arc::new(AtomicIsize::new(0));
        let counter = Arc::clone(&embree_bytes);
        device.set_memory_monitor_function(move |bytes, _post| {
            counter.fetch_add(bytes, Ordering::Relaxed);
            true
        });
        let mut scene = device
            .create_scene()
            .map_err(|e| Error::Embree(format!("cannot create scene: {e}")))?;
        scene.set_flags(SceneFlags::CONTEXT_FILTER_FUNCTION);
        Ok(SceneBuilder {
            device,
            scene,
            geoms: Vec::new(),
            objects: Vec::new(),
            spheres: Vec::new(),
            embree_bytes,
            filters: true,
            limits: Limits::default(),
            planned_bytes: 0.0,
            held_beside_bytes: 0.0,
            orientation: false,
        })
    }

    /// The same builder, with the scene it builds held to `limits`: its memory limit is a
    /// budget for all objects together (hair with its children and instances, meshes, spheres).
    pub fn with_limits(mut self, limits: Limits) -> Self {
        self.limits = limits;
        self
    }

    /// The limits the next object is loaded and added within ([`SceneBuilder::with_limits`]),
    /// with [`Limits::scene_gib`] the memory the objects added so far take: readers and
    /// generators refuse an object that would not fit before allocating it.
    pub fn limits(&self) -> Limits {
        Limits {
            scene_gib: self.limits.scene_gib + (self.planned_bytes + self.held_beside_bytes) / GIB,
            ..self.limits
        }
    }

    /// Counts `bytes` that the caller holds for this scene outside the builder (a file read
    /// once and kept for the later objects that name it) against the memory limit from now on,
    /// in place of what an earlier call counted. Objects added afterwards are checked with
    /// them in; they are not refused here, since they are already allocated.
    pub fn hold_beside(&mut self, bytes: f64) {
        self.held_beside_bytes = bytes;
    }

    /// Counts `bytes` more for `object` against the scene's memory limit, or refuses them,
    /// before they are allocated. `what` says what takes them, for the message.
    fn plan(&mut self, object: &str, what: &str, bytes: f64) -> Result<()> {
        self.limits()
            .check_scene_memory(bytes / GIB)
            .map_err(|reason| {
                Error::InvalidGeometry(tress_groom::InvalidGeometry {
                    object: object.to_owned(),
                    reason: format!("{what} need {reason}"),
                })
            })?;
        self.planned_bytes += bytes;
        Ok(())
    }

    /// A scene without filter support, for measuring Embree's own speed (`tress bench`): its
    /// queries ignore `ray.exclude`, so a ray leaving a fiber may hit that fiber again, and
    /// [`EmbreeAccel::count_fibers_crossed`] sees only the first fiber. Not for rendering.
    pub fn without_filters(mut self) -> Self {
        self.scene.set_flags(SceneFlags::NONE);
        self.filters = false;
        self
    }

    /// Hair objects added from now on keep their fibers' orientation about their axes
    /// ([`HairOptions::orientation`]) and their hits carry it; without this they keep none
    /// (12 bytes a point saved) and hits carry zero. For scenes with a hair model that
    /// [uses it](tress_core::Bcsdf::uses_orientation).
    pub fn with_fiber_orientation(mut self) -> Self {
        self.orientation = true;
        self
    }

    fn check_device(&self, object: &str) -> Result<()> {
        match self.device.get_error() {
            embree3::Error::NONE => Ok(()),
            e => Err(embree_error(object, "device error", e)),
        }
    }

    fn attach(&mut self, geometry: GeometryBuilder<'static>, data: GeomData) -> u32 {
        let id = self.geoms.len() as u32;
        self.scene.attach_geometry_by_id(&geometry.commit(), id);
        self.geoms.push(data);
        id
    }

    /// Adds a hair object: validates it, subsamples and transforms it per `options`, converts
    /// the polylines to the chosen basis and attaches flat or round curves with material
    /// `material`.
    pub fn add_hair(
        self,
        hair: &HairGeometry,
        options: &HairOptions,
        material: u32,
    ) -> Result<Self> {
        self.add_curves(hair, options, Materials::One(material))
    }

    /// [`SceneBuilder::add_hair`] with a material per curve segment: once the strands are
    /// grown, subsampled and cut into segments, `materials` is shown every segment (in
    /// primitive order) and returns each one's material index, or a reason to give up, which
    /// becomes an [`Error::InvalidGeometry`] naming the object.
    pub fn add_hair_varied(
        self,
        hair: &HairGeometry,
        options: &HairOptions,
        materials: impl FnOnce(&[HairSegment]) -> std::result::Result<Vec<u32>, String>,
    ) -> Result<Self> {
        self.add_curves(hair, options, Materials::PerSegment(Box::new(materials)))
    }

    /// Adds a hair object: its strands grown and subsampled ([`strands_to_draw`]), cut into
    /// curve segments ([`Curves::new`]), given their materials ([`Curves::set_materials`]) and
    /// handed to Embree ([`Curves::geometry`]).
    fn add_curves(
        mut self,
        hair: &HairGeometry,
        options: &HairOptions,
        materials: Materials,
    ) -> Result<Self> {
        let grown = strands_to_draw(hair, options, &self.limits())?;
        let (hair, ids) = (&grown.0, &grown.1);
        let per_point = tress_groom::geometry::BYTES_PER_POINT
            + if self.orientation {
                ORIENTATION_BYTES_PER_POINT
            } else {
                0.0
            };
        self.plan(
            &hair.name,
            &format!("its {} hair points", hair.point_count()),
            hair.point_count() as f64 * per_point + OBJECT_BYTES,
        )?;
        let per_segment = matches!(materials, Materials::PerSegment(_));
        let mut curves = Curves::new(hair, ids, options, per_segment, self.orientation)?;
        let material_span = curves.set_materials(materials, &hair.name)?;
        check_extent(&hair.name, &curves.bounds)?;
        let mut data = curves.data;
        data.cps.shrink_to_fit();
        data.first_cp.shrink_to_fit();
        if let Some(kept) = &mut data.orientations {
            kept.shrink_to_fit();
        }
        let data = Arc::new(data);
        let geometry = shared_geometry(&self.device, &hair.name, options.curve, &data)?;
        let info = ObjectInfo {
            name: hair.name.clone(),
            kind: ObjectKind::Hair {
                strands: data.strands.len(),
                segments: data.first_cp.len(),
                points: curves.points,
                basis: options.basis,
                curve: options.curve,
            },
            materials: material_span,
            bounds: curves.bounds,
        };
        self.attach(geometry, GeomData::Hair(data));
        self.check_device(&info.name)?;
        self.objects.push(info);
        Ok(self)
    }

    /// Adds a triangle mesh, transformed, with material `material`.
    pub fn add_mesh(
        mut self,
        mesh: &TriangleMesh,
        transform: &Transform,
        material: u32,
    ) -> Result<Self> {
        mesh.validate()?;
        transform.validate(&mesh.name)?;
        self.plan(
            &mesh.name,
            &format!(
                "its {} triangles and {} vertices",
                mesh.triangles.len(),
                mesh.positions.len()
            ),
            mesh.triangles.len() as f64 * BYTES_PER_TRIANGLE
                + mesh.positions.len() as f64 * BYTES_PER_VERTEX
                + OBJECT_BYTES,
        )?;
        let matrix = transform.matrix();
        let positions: Vec<Vec3> = mesh
            .positions
            .iter()
            .map(|&p| matrix.transform_point3(p))
            .collect();
        let mut bounds = Aabb::EMPTY;
        positions.iter().for_each(|&p| bounds.grow(p));
        check_extent(&mesh.name, &bounds)?;
        let name = &mesh.name;
        let mut geometry = self
            .device
            .create_geometry(GeometryKind::TRIANGLE)
            .map_err(|e| embree_error(name, "cannot create triangles", e))?;
        geometry
            .set_new_buffer::<[f32; 3]>(BufferUsage::VERTEX, 0, Format::FLOAT3, 12, positions.len())
            .map_err(|e| embree_error(name, "cannot allocate vertices", e))?
            .iter_mut()
            .zip(&positions)
            .for_each(|(dst, src)| *dst = src.to_array());
        geometry
            .set_new_buffer::<[u32; 3]>(
                BufferUsage::INDEX,
                0,
                Format::UINT3,
                12,
                mesh.triangles.len(),
            )
            .map_err(|e| embree_error(name, "cannot allocate triangles", e))?
            .copy_from_slice(&mesh.triangles);
        let info = ObjectInfo {
            name: name.clone(),
            kind: ObjectKind::Mesh {
                triangles: mesh.triangles.len(),
                vertices: positions.len(),
            },
            materials: material..material + 1,
            bounds,
        };
        self.attach(geometry, GeomData::Mesh { material });
        self.check_device(&info.name)?;
        self.objects.push(info);
        Ok(self)
    }

    /// Adds a sphere with material `material` (all spheres share one Embree geometry, made in
    /// [`SceneBuilder::build`]).
    pub fn add_sphere(mut self, center: Vec3, radius: f32, material: u32) -> Result<Self> {
        let name = format!("sphere #{}", self.spheres.len());
        if !center.is_finite() {
            return Err(Error::InvalidOption(tress_groom::InvalidOption {
                object: name,
                field: "center",
                reason: format!("must be finite, got {center:?}"),
            }));
        }
        if !(radius.is_finite() && radius > 0.0) {
            return Err(Error::InvalidOption(tress_groom::InvalidOption {
                object: name,
                field: "radius",
                reason: format!("must be finite and positive, got {radius}"),
            }));
        }
        let bounds = Aabb {
            min: center - Vec3::splat(radius),
            max: center + Vec3::splat(radius),
        };
        check_extent(&name, &bounds)?;
        self.plan(&name, "its centre and radius", BYTES_PER_SPHERE)?;
        self.spheres.push((center.extend(radius), material));
        self.objects.push(ObjectInfo {
            name,
            kind: ObjectKind::Sphere { center, radius },
            materials: material..material + 1,
            bounds,
        });
        Ok(self)
    }

    /// Commits the scene (builds the BVH).
    pub fn build(mut self) -> Result<EmbreeAccel> {
        if !self.spheres.is_empty() {
            let mut geometry = self
                .device
                .create_geometry(GeometryKind::SPHERE_POINT)
                .map_err(|e| embree_error("spheres", "cannot create spheres", e))?;
            geometry
                .set_new_buffer::<[f32; 4]>(
                    BufferUsage::VERTEX,
                    0,
                    Format::FLOAT4,
                    16,
                    self.spheres.len(),
                )
                .map_err(|e| embree_error("spheres", "cannot allocate spheres", e))?
                .iter_mut()
                .zip(&self.spheres)
                .for_each(|(dst, (s, _))| *dst = s.to_array());
            let materials = self.spheres.iter().map(|&(_, m)| m).collect();
            let spheres = self.spheres.iter().map(|&(s, _)| s).collect();
            self.attach(geometry, GeomData::Spheres { materials, spheres });
        }
        // High quality (spatial splits) made the preview example on straight.hair 1.7× faster
        // (1M camera + 1M shadow rays: 0.48 s vs 0.82 s) at about the same build time.
        self.scene.set_build_quality(embree3::BuildQuality::HIGH);
        self.scene.commit();
        self.check_device("scene")?;

        let mut info = AccelInfo {
            objects: self.objects,
            strands: 0,
            segments: 0,
            points: 0,
            triangles: 0,
            spheres: 0,
            bounds: Aabb::EMPTY,
            memory_bytes: 0,
        };
        for o in &info.objects {
            info.bounds = info.bounds.union(&o.bounds);
            match o.kind {
                ObjectKind::Hair {
                    strands,
                    segments,
                    points,
                    ..
                } => {
                    info.strands += strands;
                    info.segments += segments;
                    info.points += points;
                }
                ObjectKind::Mesh { triangles, .. } => info.triangles += triangles,
                ObjectKind::Sphere { .. } => info.spheres += 1,
            }
        }
        let ours: usize = self
            .geoms
            .iter()
            .map(|g| match g {
                GeomData::Hair(c) => c.memory_bytes(),
                GeomData::Mesh { .. } => 0,
                GeomData::Spheres { materials, .. } => materials.len() * 20,
            })
            .sum();
        info.memory_bytes = self.embree_bytes.load(Ordering::Relaxed).max(0) as usize + ours;
        tracing::debug!("built Embree scene: {info}");
        let origin_shift = ORIGIN_SHIFT_RADII * max_fiber_radius(&self.geoms);
        Ok(EmbreeAccel {
            scene: self.scene,
            _device: self.device,
            geoms: self.geoms,
            info,
            filters: self.filters,
            origin_shift,
        })
    }
}

/// How far behind its origin, in the scene's largest fiber radius, every ray is handed to
/// Embree, with its query interval moved by as much: its hits are the ray's own.
/// Embree culls any hit on a flat curve nearer the ray's origin than twice the curve's radius
/// (`EMBREE_CURVE_SELF_INTERSECTION_AVOIDANCE_FACTOR`, 2 in Debian's 3.13.5 build): its own
/// self-intersection avoidance, which tress does not need (the capsule rule below) and which
/// is wrong in hair. Where fibers touch, the next fiber along a ray leaving one often lies
/// within a diameter: measured on a layer of fibers 1.4 deep, shadow rays from the fibers a
/// camera sees passed 62 % of the time against the 33 % the fibers' positions give (tubes,
/// which Embree does not cull, 32 %), so light went through dense hair.
const ORIGIN_SHIFT_RADII: f32 = 2.05;

/// The largest radius of any curve control point of the scene's hair (0 without hair).
fn max_fiber_radius(geoms: &[GeomData]) -> f32 {
    geoms
        .iter()
        .filter_map(|g| match g {
            GeomData::Hair(c) => Some(c.cps.iter().fold(0.0f32, |m, p| m.max(p.w))),
            _ => None,
        })
        .fold(0.0, f32::max)
}

/// Embree's context filter (scene flag `CONTEXT_FILTER_FUNCTION`), the second filter stage
/// after per-geometry filters, of which tress installs none. Only queries that exclude
/// something carry it ([`EmbreeAccel::context`]): camera rays and rays leaving lights pay no
/// callback per candidate hit, and occlusion rays that need no rule stop at Embree's first hit.
///
/// # Safety
/// Embree calls it with the arguments of a query whose context is an
/// `IntersectContextExt<Exclude>` built by [`EmbreeAccel::context`] for a live scene.
unsafe extern "C" fn context_filter(args: *const RTCFilterFunctionNArguments) {
    // SAFETY: Embree passes a valid pointer to the call's arguments, alive for the call.
    let args = unsafe { &*args };
    // SAFETY: the context is the one the query was given, an `IntersectContextExt<Exclude>`
    // from `EmbreeAccel::context` (`repr(C)`, Embree's context first), alive for the query.
    let ex = unsafe { &(*(args.context as *const IntersectContextExt<Exclude>)).ext };
    // SAFETY: `geoms` is the slice of the `EmbreeAccel` being queried, which outlives the query
    // and is not changed after it is built.
    let geoms = unsafe { &*ex.geoms };
    let n = args.N as usize;
    // Embree's SoA layouts of `RTCRayN` and `RTCHitN` (rtcore_ray.h): field k of lane i is
    // element k·N + i.
    let ray = args.ray as *const f32;
    let hit = args.hit as *const u32;
    for i in 0..n {
        // SAFETY: `valid` holds one flag per lane, N of them, which the filter may clear.
        let valid = unsafe { &mut *args.valid.add(i) };
        if *valid == 0 {
            continue;
        }
        // SAFETY: a ray has 12 fields of N lanes (origin, t_near, direction, time, t_far, …):
        // the fields read, k ≤ 8, lie within it.
        let ray_field = |k: usize| unsafe { *ray.add(k * n + i) };
        let dir = Vec3::new(ray_field(4), ray_field(5), ray_field(6));
        // The ray's own origin, in front of the one Embree was given (`EmbreeAccel::embree_ray`).
        let org = Vec3::new(ray_field(0), ray_field(1), ray_field(2)) + ex.origin_shift * dir;
        // SAFETY: a hit has 8 fields of N lanes (normal, u, v, primID, geomID, instID): the
        // fields read, 3, 5 and 6, lie within it.
        let hit_field = |k: usize| unsafe { *hit.add(k * n + i) };
        let (prim, geom) = (hit_field(5), hit_field(6));
        // Field 3 of the hit is its curve parameter u; field 8 of the ray the candidate's
        // distance, measured from the shifted origin.
        let candidate = Candidate {
            geom,
            prim,
            u: f32::from_bits(hit_field(3)),
            t: ray_field(8) - ex.origin_shift,
        };
        if !geoms[geom as usize].keep(ex, candidate, org, dir) {
            *valid = 0;
        } else if !ex.hits.is_null() {
            // SAFETY: set only by `count_fibers_crossed`, whose vector outlives the
            // (synchronous) query and is not otherwise touched during it.
            unsafe { (*ex.hits).push((PrimId { geom, prim }, candidate.t)) };
            *valid = 0;
        }
    }
}

/// The strands of `hair` a hair object draws, validated: with its child strands, then the
/// subset of [`HairOptions::strand_fraction`], and each one's index in the object.
fn strands_to_draw<'a>(
    hair: &'a HairGeometry,
    options: &HairOptions,
    limits: &Limits,
) -> Result<(Cow<'a, HairGeometry>, Vec<u32>)> {
    hair.validate()?;
    options.validate(&hair.name)?;
    let grown = options.with_children(hair, limits)?;
    Ok(if options.strand_fraction < 1.0 {
        let (sub, ids) = grown.subsample(options.strand_fraction, options.strand_seed);
        (Cow::Owned(sub), ids)
    } else {
        let ids = (0..grown.strand_count() as u32).collect();
        (grown, ids)
    })
}

/// A hair object cut into curve segments: what the accelerator keeps of it, Embree's vertex
/// and index buffers included (Embree reads them where they are).
struct Curves {
    data: CurveData,
    /// Points of the strands drawn.
    points: usize,
    bounds: Aabb,
    /// What a caller choosing per-segment materials sees, one per primitive (else empty).
    segments: Vec<HairSegment>,
}

impl Curves {
    /// Transforms, scales and tapers the strands `ids` of `hair` (in slot order) and cuts them
    /// into segments, skipping zero-length ones; `per_segment` also records what a per-segment
    /// material choice sees, `orientation` the fibers' orientation.
    fn new(
        hair: &HairGeometry,
        ids: &[u32],
        options: &HairOptions,
        per_segment: bool,
        orientation: bool,
    ) -> Result<Curves> {
        let basis = options.basis;
        let order = basis.order();
        let matrix = options.transform.matrix();
        let radius_scale = options.radius_scale * options.transform.scale;
        let mut c = Curves {
            data: CurveData {
                basis,
                shape: options.curve,
                overlaps: options.overlaps,
                materials: SegmentMaterials::Uniform(0),
                cps: Vec::new(),
                first_cp: Vec::new(),
                strand_of: Vec::new(),
                capsules: Vec::new(),
                orientations: orientation.then(Vec::new),
                strands: Vec::new(),
            },
            points: 0,
            bounds: Aabb::EMPTY,
            segments: Vec::new(),
        };
        // The centre of the roots, from which each root's outward direction estimates the
        // scalp normal where the orientation has to be made up.
        let root_centre = if orientation {
            let (sum, roots) = (0..hair.strand_count())
                .filter_map(|s| hair.strand(s).next())
                .fold((Vec3::ZERO, 0u32), |(sum, n), at| {
                    (sum + matrix.transform_point3(hair.points[at]), n + 1)
                });
            sum / roots.max(1) as f32
        } else {
            Vec3::ZERO
        };
        for (slot, &id) in ids.iter().enumerate() {
            let range = hair.strand(slot);
            let first_point = range.start;
            let n = range.len();
            if n < 2 {
                continue;
            }
            let pts: Vec<Vec4> = range
                .enumerate()
                .map(|(i, at)| {
                    let v = i as f32 / (n - 1) as f32;
                    let taper = 1.0 + (options.tip_scale - 1.0) * v;
                    matrix
                        .transform_point3(hair.points[at])
                        .extend(hair.radii[at] * radius_scale * taper)
                })
                .collect();
            let strand = c.data.strands.len() as u32;
            let base = c.data.cps.len();
            c.data.cps.extend(basis.control_points(&pts));
            if let Some(kept) = &mut c.data.orientations {
                let centres: Vec<Vec3> = pts.iter().map(|p| p.truncate()).collect();
                let file: Option<Vec<Vec3>> = hair.orientations.as_ref().map(|o| {
                    (first_point..first_point + n)
                        .map(|at| matrix.transform_vector3(o.at(slot, at)))
                        .collect()
                });
                let o = crate::orientation::strand_orientations(
                    &options.orientation,
                    &centres,
                    file.as_deref(),
                    centres[0] - root_centre,
                );
                // Aligned with the control points: a cubic strand's phantom end points take
                // their neighbours'.
                if basis != CurveBasis::Linear {
                    kept.push(o[0]);
                }
                kept.extend_from_slice(&o);
                if basis != CurveBasis::Linear {
                    kept.push(o[n - 1]);
                }
            }
            let before = c.data.first_cp.len();
            for j in 0..n - 1 {
                // A zero-length segment has no area and no tangent.
                if pts[j].truncate() == pts[j + 1].truncate() {
                    continue;
                }
                let cap = basis.capsule(&c.data.cps[base + j..base + j + order]);
                c.bounds.grow(cap.a - Vec3::splat(cap.r));
                c.bounds.grow(cap.a + Vec3::splat(cap.r));
                c.bounds.grow(cap.b - Vec3::splat(cap.r));
                c.bounds.grow(cap.b + Vec3::splat(cap.r));
                c.data.first_cp.push((base + j) as u32);
                c.data.strand_of.push(strand);
                // A linear segment's capsule is its two control points: computed when needed.
                if basis != CurveBasis::Linear {
                    c.data.capsules.push(cap);
                }
                if per_segment {
                    let color = hair.colors.as_ref().map(|colors| {
                        let at = first_point + j;
                        0.5 * (colors.at(slot, at) + colors.at(slot, at + 1))
                    });
                    c.segments.push(HairSegment {
                        strand: id,
                        v: (j as f32 + 0.5) / (n - 1) as f32,
                        color,
                    });
                }
            }
            if c.data.first_cp.len() == before {
                c.data.cps.truncate(base);
                if let Some(kept) = &mut c.data.orientations {
                    kept.truncate(base);
                }
                continue;
            }
            c.data.strands.push(StrandRecord {
                first_prim: before as u32,
                end_prim: c.data.first_cp.len() as u32,
                segments: (n - 1) as u32,
                first_cp: base as u32,
                id,
            });
            c.points += n;
        }
        if c.data.first_cp.is_empty() {
            return Err(Error::InvalidGeometry(tress_groom::InvalidGeometry {
                object: hair.name.clone(),
                reason: "no strand has a segment of non-zero length".into(),
            }));
        }
        if c.data.cps.len() > u32::MAX as usize {
            return Err(Error::InvalidGeometry(tress_groom::InvalidGeometry {
                object: hair.name.clone(),
                reason: "too many control points for one Embree geometry".into(),
            }));
        }
        Ok(c)
    }

    /// Gives the segments their materials; the span of material indices used.
    fn set_materials(&mut self, materials: Materials, object: &str) -> Result<Range<u32>> {
        let segments = std::mem::take(&mut self.segments);
        Ok(match materials {
            Materials::One(m) => {
                self.data.materials = SegmentMaterials::Uniform(m);
                m..m + 1
            }
            Materials::PerSegment(choose) => {
                let fail = |reason: String| {
                    Error::InvalidGeometry(tress_groom::InvalidGeometry {
                        object: object.to_owned(),
                        reason,
                    })
                };
                let chosen = choose(&segments).map_err(fail)?;
                if chosen.len() != segments.len() {
                    return Err(fail(format!(
                        "{} materials chosen for {} curve segments",
                        chosen.len(),
                        segments.len()
                    )));
                }
                let lo = chosen.iter().copied().min().unwrap_or(0);
                let hi = chosen.iter().copied().max().unwrap_or(0);
                self.data.materials = SegmentMaterials::PerSegment(chosen);
                lo..hi.saturating_add(1)
            }
        })
    }
}

/// The Embree curves of `data`, reading its control points and segment indices where they are
/// instead of a copy of each.
fn shared_geometry(
    device: &Device,
    name: &str,
    curve: CurveShape,
    data: &Arc<CurveData>,
) -> Result<GeometryBuilder<'static>> {
    let geometry = device
        .create_geometry(data.basis.geometry_kind(curve))
        .map_err(|e| embree_error(name, "cannot create curves", e))?;
    // SAFETY: Embree reads the two buffers until the scene is released. They live in the
    // `Arc<CurveData>` that `geoms` keeps, are never written again, and `EmbreeAccel` and
    // `SceneBuilder` declare `scene` before `geoms`, so the scene is dropped first.
    unsafe {
        embree3::sys::rtcSetSharedGeometryBuffer(
            geometry.handle(),
            BufferUsage::VERTEX,
            0,
            Format::FLOAT4,
            data.cps.as_ptr().cast(),
            0,
            std::mem::size_of::<Vec4>(),
            data.cps.len(),
        );
        embree3::sys::rtcSetSharedGeometryBuffer(
            geometry.handle(),
            BufferUsage::INDEX,
            0,
            Format::UINT,
            data.first_cp.as_ptr().cast(),
            0,
            4,
            data.first_cp.len(),
        );
    }
    Ok(geometry)
}

/// Hair curves, triangle meshes and spheres in an Embree scene; implements [`Accel`].
///
/// Shared across threads (`Send + Sync`): Embree allows concurrent queries after commit.
pub struct EmbreeAccel {
    scene: Scene<'static>,
    _device: Device,
    geoms: Vec<GeomData>,
    info: AccelInfo,
    /// Whether the scene supports the context filter; without it `ray.exclude` is ignored
    /// (see [`SceneBuilder::without_filters`]).
    filters: bool,
    /// How far behind its origin every ray is handed to Embree, so that Embree's culling of
    /// flat-curve hits within two radii of the origin never applies ([`ORIGIN_SHIFT_RADII`]).
    origin_shift: f32,
}

impl fmt::Debug for EmbreeAccel {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("EmbreeAccel")
            .field("info", &self.info)
            .finish()
    }
}

impl EmbreeAccel {
    /// Counts, bounds and memory of the scene.
    pub fn info(&self) -> &AccelInfo {
        &self.info
    }

    /// The context of a query along `ray`: it carries [`context_filter`] only when the ray
    /// excludes a primitive.
    fn context(&self, ray: &Ray) -> IntersectContextExt<Exclude> {
        let (geom, prim) = ray.exclude.map_or((NO_ID, NO_ID), |p| (p.geom, p.prim));
        let mut ctx = self.unfiltered_context();
        ctx.ext.geom = geom;
        ctx.ext.prim = prim;
        if ray.exclude.is_some() {
            self.set_filter(&mut ctx);
        }
        ctx
    }

    /// A context with nothing to exclude and no filter: Embree's own traversal alone.
    fn unfiltered_context(&self) -> IntersectContextExt<Exclude> {
        IntersectContextExt::incoherent(Exclude {
            geom: NO_ID,
            prim: NO_ID,
            hits: std::ptr::null_mut(),
            skip_hair: false,
            geoms: self.geoms.as_slice(),
            origin_shift: self.origin_shift,
        })
    }

    fn set_filter(&self, ctx: &mut IntersectContextExt<Exclude>) {
        if self.filters {
            ctx.ctx.filter = Some(context_filter);
        }
    }

    /// `ray` over `(t_near, ray.t_max)` as Embree sees it: started [`Self::origin_shift`]
    /// behind its origin, over the same interval moved by as much; Embree's distances are
    /// then that much longer.
    fn embree_ray_from(&self, ray: &Ray, t_near: f32) -> embree3::Ray {
        let shift = self.origin_shift;
        embree3::Ray::new(
            (ray.origin - shift * ray.dir).to_array(),
            ray.dir.to_array(),
            t_near + shift,
            ray.t_max + shift,
            0.0,
            u32::MAX,
            0,
        )
    }

    fn embree_ray(&self, ray: &Ray) -> embree3::Ray {
        self.embree_ray_from(ray, 0.0)
    }
}

// A brute-force crossing count for the density grid (in `tress-dual-scattering`, built from
// `Accel::hair_curves`) to be calibrated and tested against.
impl EmbreeAccel {
    /// Brute-force count of the fibers crossed along `ray` over `(0, ray.t_max)`: the distinct
    /// hair segments hit, with the same `ray.exclude` rule as [`Accel::intersect`]; meshes and
    /// spheres neither count nor block. Flat ribbons face the ray, so a fiber crossed is one
    /// hit, except through a joint, where the rounded ends of both segments are hit: such a
    /// pair (consecutive segments of a strand hit within the sum of their radii in depth)
    /// counts once. For calibrating and testing [`crate::DensityGrid`]; it traverses the whole
    /// ray.
    pub fn count_fibers_crossed(&self, ray: &Ray) -> u32 {
        let mut hits: Vec<(PrimId, f32)> = Vec::new();
        let mut ctx = self.context(ray);
        ctx.ext.hits = &mut hits;
        self.set_filter(&mut ctx);
        let mut r = self.embree_ray(ray);
        self.scene.occluded(&mut ctx, &mut r);
        // Embree may report a primitive more than once (spatial splits, curve subdivision).
        hits.sort_unstable_by_key(|(h, _)| (h.geom, h.prim));
        hits.dedup_by_key(|(h, _)| *h);
        let mut count = 0;
        for (i, &(h, t)) in hits.iter().enumerate() {
            let GeomData::Hair(c) = &self.geoms[h.geom as usize] else {
                continue;
            };
            let through_joint = i > 0 && {
                let (p, tp) = hits[i - 1];
                let (a, b) = (p.prim as usize, h.prim as usize);
                p.geom == h.geom
                    && a + 1 == b
                    && c.same_strand(a, b)
                    && (t - tp).abs() <= c.capsule(a).r + c.capsule(b).r
            };
            count += u32::from(!through_joint);
        }
        count
    }
}

impl EmbreeAccel {
    /// Where a ray leaving a sphere inwards meets it again, on the far side of its chord, with
    /// the sphere's material: solved here in f64, since skipping the sphere let rays bounced
    /// inside a closed sphere reach the sky, and Embree's f32 roots miss the short chords of
    /// grazing rays.
    fn sphere_reentry(&self, ray: &Ray) -> Option<(f32, u32, Vec3)> {
        let ex = ray.exclude?;
        let GeomData::Spheres { materials, spheres } = self.geoms.get(ex.geom as usize)? else {
            return None;
        };
        let s = spheres[ex.prim as usize];
        let (center, r) = (s.truncate(), f64::from(s.w));
        let o = (ray.origin - center).as_dvec3();
        let d = ray.dir.as_dvec3();
        let b = o.dot(d);
        if b >= 0.0 {
            return None; // leaving outwards
        }
        // The far root of |o + t d|² = r², whether rounding put the origin just in or out.
        let t = (-b + (b * b - (o.length_squared() - r * r)).max(0.0).sqrt()) as f32;
        (t > 0.0 && t < ray.t_max).then_some((t, materials[ex.prim as usize], center))
    }
}

impl Accel for EmbreeAccel {
    fn intersect(&self, ray: &Ray) -> Option<Hit> {
        let reentry = self.sphere_reentry(ray);
        let mut ctx = self.context(ray);
        let mut rh = RayHit::from(self.embree_ray(ray));
        if let Some((t, ..)) = reentry {
            // Nothing beyond the sphere's far side can be hit.
            rh.ray.tfar = t + self.origin_shift;
        }
        self.scene.intersect(&mut ctx, &mut rh);
        if !rh.hit.is_valid() {
            return reentry.map(|(t, material, center)| {
                let p = ray.at(t);
                let n = (p - center).try_normalize().unwrap_or(-ray.dir);
                Hit {
                    t,
                    p,
                    prim: ray.exclude.expect("a re-entry has an excluded sphere"),
                    material,
                    // The inside, facing the ray.
                    kind: HitKind::Surface { normal: -n },
                }
            });
        }
        let t = rh.ray.tfar - self.origin_shift;
        let (geom, prim) = (rh.hit.geomID, rh.hit.primID);
        let surface = || {
            let n = Vec3::new(rh.hit.Ng_x, rh.hit.Ng_y, rh.hit.Ng_z)
                .try_normalize()
                .unwrap_or(-ray.dir);
            HitKind::Surface {
                normal: if n.dot(ray.dir) > 0.0 { -n } else { n },
            }
        };
        let (kind, material, t) = match &self.geoms[geom as usize] {
            GeomData::Hair(c) => {
                let (kind, t) = c.fiber_hit(prim, rh.hit.u, ray, t);
                (kind, c.material(prim), t)
            }
            GeomData::Mesh { material } => (surface(), *material, t),
            GeomData::Spheres { materials, .. } => (surface(), materials[prim as usize], t),
        };
        Some(Hit {
            t,
            p: ray.at(t),
            prim: PrimId { geom, prim },
            material,
            kind,
        })
    }

    fn occluded(&self, ray: &Ray) -> bool {
        if self.sphere_reentry(ray).is_some() {
            return true;
        }
        let mut ctx = self.context(ray);
        let mut r = self.embree_ray(ray);
        self.scene.occluded(&mut ctx, &mut r)
    }

    fn occluded_by_surfaces(&self, ray: &Ray) -> bool {
        if !self.has_surfaces() {
            return false;
        }
        if self.sphere_reentry(ray).is_some() {
            return true;
        }
        let mut ctx = self.context(ray);
        ctx.ext.skip_hair = true;
        self.set_filter(&mut ctx);
        let mut r = self.embree_ray(ray);
        self.scene.occluded(&mut ctx, &mut r)
    }

    fn has_surfaces(&self) -> bool {
        self.info.triangles > 0 || self.info.spheres > 0
    }

    fn bounds(&self) -> Aabb {
        self.info.bounds
    }

    fn hair_curves(&self) -> Vec<(u32, Arc<dyn HairCurves>)> {
        let hair = self.geoms.iter().enumerate().filter_map(|(id, g)| match g {
            GeomData::Hair(c) => Some((id as u32, Arc::clone(c) as Arc<dyn HairCurves>)),
            _ => None,
        });
        hair.collect()
    }
}

// A child module: it builds the private intersection context the filter functions read.
pub mod raw;

#[cfg(test)]
mod tests;

#[cfg(test)]
mod variation_tests;
