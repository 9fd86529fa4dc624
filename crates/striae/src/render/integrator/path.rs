//! One path sample's stages, shared by the render loops of [`super`]: its camera sample, the
//! vertex it makes where its ray lands ([`Path::land`]: emission found, shading, next-event
//! estimation with MIS, BSDF sampling, Russian roulette), and the lazily worked-out ray
//! differentials it carries.

// `!(x > 0.0)` is meant: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::Worker;
use crate::hash::{mix64, GOLDEN};
use crate::math::{Frame, Ray, RayDifferential, Rgb, Vec2, Vec3};
use crate::render::bsdf::{Bsdf, BsdfSample, Diffuse};
use crate::render::geometry::{Geometry, SurfaceHit, PACKET};
use crate::render::lights::Light;
use crate::render::material::{HitView, Material};
use crate::render::sampler::{PixelSampler, SamplerKind, CAMERA_LANES, LOBE_DIM};
use crate::render::scene::{Scene, NO_MATERIAL};
use crate::render::shading::{footprint_dp, spawn_differentials, PixelHit};
use crate::sampling::power_heuristic;
use arrayvec::ArrayVec;
use std::mem::MaybeUninit;

const _: () = assert!(PACKET <= CAMERA_LANES);

/// The shading normals at the starts of a delta bounce's offset rays
/// ([`spawn_differentials`]): the bounce's normal `n` (the frame's, which may be flipped to
/// `wo`'s side or guarded) plus the change of the surface's normal field from the hit to
/// `p + dpdx` and `p + dpdy` ([`Geometry::shading_normal_steps`]). `None` on flat surfaces.
/// Out of line: the render loop calls it only on shapes with curved normals
/// ([`Geometry::has_curved_normals`]), so scenes of flat glass do not carry its code.
#[inline(never)]
pub fn offset_normals(
    geometry: &Geometry,
    hit: &SurfaceHit,
    n: Vec3,
    dpdx: Vec3,
    dpdy: Vec3,
) -> Option<(Vec3, Vec3)> {
    let [dnx, dny] = geometry.shading_normal_steps(hit, [dpdx, dpdy])?;
    let side = if n.dot(hit.ns) < 0.0 { -1.0 } else { 1.0 };
    // The change's component along `n` only changes the normal's length (the interpolated
    // normal is shorter inside a triangle): dropping it keeps `n + dn` unit to second order
    // in the step, with no square root.
    let bent = |dn: Vec3| n + side * (dn - dn.dot(n) * n);
    Some((bent(dnx), bent(dny)))
}

/// A bounce whose spawned ray differentials are not worked out yet ([`PathDifferentials`]):
/// what [`footprint_dp`], [`offset_normals`] and [`spawn_differentials`] read of it.
#[derive(Clone, Copy)]
pub(super) struct DeferredBounce {
    pub hit: SurfaceHit,
    /// The normal of the frame the hit was shaded in (flipped or guarded).
    pub n: Vec3,
    /// Direction of the ray that arrived, and of the one that left.
    pub d_in: Vec3,
    pub wi: Vec3,
    pub delta: bool,
    /// Whether the ray left through the surface (refracted) rather than reflected.
    pub transmitted: bool,
    /// `n_incident / n_transmitted` along the path (1 for a reflection).
    pub eta: f32,
}

impl DeferredBounce {
    /// The differentials of the ray leaving this bounce, from those of the ray that arrived:
    /// the footprint on the hit's tangent plane, the offset rays' normals on curved surfaces
    /// (delta bounces only) and the bent offset rays.
    #[inline(always)]
    pub fn spawn(&self, geometry: &Geometry, rd: &RayDifferential) -> RayDifferential {
        let (dpdx, dpdy) = footprint_dp(&self.hit, rd);
        let normals = if self.delta && geometry.has_curved_normals(self.hit.shape) {
            offset_normals(geometry, &self.hit, self.n, dpdx, dpdy)
        } else {
            None
        };
        spawn_differentials(
            self.hit.p, dpdx, dpdy, self.d_in, rd, self.n, normals, self.wi, self.delta, self.eta,
        )
    }
}

/// The ray differentials of one path, worked out lazily: each bounce is recorded, and the
/// records are turned into differentials only when a later hit reads its footprint (the
/// scratched material seen from outside), so the bounces after a path's last such hit (most of
/// a path through glass: the hits inside, the floor, the sky) cost a copy instead of the
/// bending. The same operations run in the same order as when every bounce is worked out at
/// once, so every footprint, and the image, is the same bit for bit (test
/// `deferred_differentials_equal_eager_ones`); the setting-1 teapot renders 7 % faster so.
/// The path's chain of delta bounces ([`PixelHit::chain`]), read at the same hits, is folded
/// in the same way, instead of a SplitMix64 round at every bounce.
struct PathDifferentials {
    /// Differentials of the ray that arrived at the first pending bounce (of the path's current
    /// ray when none is pending).
    rd: RayDifferential,
    /// The chain of delta bounces up to the first pending bounce; `None` once a bounce was not
    /// a delta one.
    chain: Option<u64>,
    /// The first `len` entries are initialised.
    pending: [MaybeUninit<DeferredBounce>; PathDifferentials::CAPACITY],
    len: usize,
    /// The camera ray's film position minus its pixel's centre ([`PixelHit::offset`]).
    offset: Vec2,
}

impl PathDifferentials {
    /// Bounces kept pending at most; a longer run is worked out as it fills up. 16: paths of
    /// the usual `max_depth = 16` never fill it, so no bounce is worked out that no hit reads
    /// (8 costs 50 instructions a sample in flushes on long paths inside glass, glass teapot
    /// carrying differentials).
    const CAPACITY: usize = 16;

    #[inline(always)]
    fn new(rd: RayDifferential, offset: Vec2) -> Self {
        PathDifferentials {
            rd,
            chain: Some(0),
            pending: [const { MaybeUninit::uninit() }; Self::CAPACITY],
            len: 0,
            offset,
        }
    }

    /// Start over, for a new path whose camera ray has differentials `rd`.
    #[inline(always)]
    fn restart(&mut self, rd: RayDifferential, offset: Vec2) {
        self.rd = rd;
        self.chain = Some(0);
        self.len = 0;
        self.offset = offset;
    }

    /// Record a bounce (the ray leaving it is the path's current ray).
    #[inline(always)]
    fn push(&mut self, geometry: &Geometry, bounce: DeferredBounce) {
        if self.len == Self::CAPACITY {
            self.resolve(geometry);
        }
        self.pending[self.len].write(bounce);
        self.len += 1;
    }

    /// The differentials of the path's current ray, and its chain of delta bounces (`None`
    /// after a non-delta bounce).
    #[inline(always)]
    fn resolve(&mut self, geometry: &Geometry) -> (RayDifferential, Option<u64>) {
        for entry in &self.pending[..self.len] {
            // SAFETY: the first `len` entries were written by `push`.
            let bounce = unsafe { entry.assume_init_ref() };
            self.rd = bounce.spawn(geometry, &self.rd);
            self.chain = self
                .chain
                .filter(|_| bounce.delta)
                .map(|chain| PixelHit::chain_after(chain, bounce.hit.shape, bounce.transmitted));
        }
        self.len = 0;
        (self.rd, self.chain)
    }
}

/// A camera ray's closest hit, found before its path runs (in a packet), or not yet.
#[derive(Clone, Copy)]
pub(super) enum CameraHit {
    Traced(Option<SurfaceHit>),
    Untraced,
}

/// One sample of a pixel up to its camera ray.
#[derive(Clone)]
pub(super) struct CameraSample {
    /// The sample's random numbers, past the camera's dimensions.
    sampler: PixelSampler,
    pub ray: Ray,
    /// The ray's differentials (along the ray without `DIFFERENTIALS`).
    rd: RayDifferential,
    /// The film position minus the pixel's centre, in pixels ([`PixelHit::offset`]; zero
    /// without `DIFFERENTIALS`).
    offset: Vec2,
}

/// Sample `s` of pixel `(x, y)` (index `pixel_index`) up to its camera ray. (Forced inline,
/// with what it calls, into the render loop's copies: out of line it runs without their
/// instruction sets, and the sampler with it, 10 % slower.)
#[inline(always)]
pub(super) fn camera_sample<const DIFFERENTIALS: bool>(
    scene: &Scene,
    (x, y): (u32, u32),
    pixel_index: u64,
    s: u32,
) -> CameraSample {
    let mut sampler =
        PixelSampler::with_kind(scene.settings.sampler, pixel_index, s, scene.settings.seed);
    let in_pixel = sampler.next_2d();
    let film = Vec2::new(x as f32, y as f32) + in_pixel;
    let u_lens = sampler.next_2d();
    let (ray, rd, offset) = if DIFFERENTIALS {
        let (ray, rd) = scene.camera.generate_ray(film, u_lens);
        (ray, rd, in_pixel - Vec2::splat(0.5))
    } else {
        let ray = scene.camera.generate_ray_only(film, u_lens);
        (ray, RayDifferential::along(&ray), Vec2::ZERO)
    };
    CameraSample {
        sampler,
        ray,
        rd,
        offset,
    }
}

/// Pixels with at least this many samples trace their camera rays in packets (through a
/// pinhole): at 4 spp packets are 4-7 % faster, at 2 spp neither faster nor slower (glass
/// teapot and smooth close-up, whole process).
const PACKET_MIN_SPP: u32 = 4;

/// Whether a pass of `n` samples a pixel traces its camera rays in packets of a pixel's samples
/// ([`camera_packet`]): from [`PACKET_MIN_SPP`] samples on, through a pinhole (a thin lens's
/// rays share no origin). Both render loops follow it, so they trace the same packets.
#[inline(always)]
pub(super) fn traces_camera_packets(scene: &Scene, n: u32) -> bool {
    n >= PACKET_MIN_SPP && scene.camera.is_pinhole()
}

/// Samples `first..first + n` (`n` at most [`PACKET`]) of pixel `(x, y)` (index
/// `pixel_index`) up to their camera rays, into `samples`, and the rays' closest hits into
/// `hits`, traced together ([`crate::render::geometry::Geometry::intersect_coherent`]; both
/// cleared first). Each sample is what [`camera_sample`] makes of it, bit for bit. Through a
/// pinhole, with Sobol numbers and no differentials, they are made in lanes: the numbers of
/// all of them at once ([`PixelSampler::sobol_camera_lanes`]), then their rays
/// ([`crate::render::camera::PerspectiveCamera::pinhole_directions`]). (With differentials the
/// lane form ran slower, code layout: `BENCHMARKS.md`, "Camera samples in lanes".)
#[inline(always)]
pub(super) fn camera_packet<const DIFFERENTIALS: bool>(
    scene: &Scene,
    (x, y): (u32, u32),
    pixel_index: u64,
    (first, n): (u32, usize),
    samples: &mut ArrayVec<CameraSample, PACKET>,
    hits: &mut ArrayVec<Option<SurfaceHit>, PACKET>,
) {
    samples.clear();
    // (An `ArrayVec`: only what the packet holds is written.)
    let mut rays = ArrayVec::<Ray, PACKET>::new();
    let lanes =
        !DIFFERENTIALS && scene.camera.is_pinhole() && scene.settings.sampler == SamplerKind::Sobol;
    if lanes {
        let (samplers, numbers) =
            PixelSampler::sobol_camera_lanes(pixel_index, first, scene.settings.seed);
        // (A loop, not `[T; N]::map`, which stays an out-of-line call compiled for baseline
        // x86-64, outside the render loop's SIMD copies.)
        let (mut film_x, mut film_y) = ([0.0; CAMERA_LANES], [0.0; CAMERA_LANES]);
        for (k, (fx, fy)) in film_x.iter_mut().zip(&mut film_y).enumerate() {
            (*fx, *fy) = (x as f32 + numbers[0][k], y as f32 + numbers[1][k]);
        }
        let d = scene.camera.pinhole_directions(&film_x, &film_y);
        // (By reference: `into_iter` moves the whole array, `CAMERA_LANES` samplers, first.)
        for (k, sampler) in samplers.iter().take(n).enumerate() {
            let ray = Ray::new(
                scene.camera.position(),
                Vec3::new(d[0][k], d[1][k], d[2][k]),
            );
            rays.push(ray);
            samples.push(CameraSample {
                sampler: sampler.clone(),
                ray,
                rd: RayDifferential::along(&ray),
                offset: Vec2::ZERO,
            });
        }
    } else {
        for s in first..first + n as u32 {
            let sample = camera_sample::<DIFFERENTIALS>(scene, (x, y), pixel_index, s);
            rays.push(sample.ray);
            samples.push(sample);
        }
    }
    scene.geometry.intersect_coherent(&rays, hits);
}

/// One path sample in flight: its random numbers, the ray it traces next, the radiance it has
/// gathered, and what its next vertex needs. Both render loops run it stage by stage: the ray's
/// closest hit is found outside (one path at a time, or many together in the lane loop), and
/// [`Path::land`] does everything else one vertex needs, the same operations in the same
/// order whichever loop drives it.
pub(super) struct Path {
    sampler: PixelSampler,
    /// The ray whose hit the path needs next.
    pub ray: Ray,
    /// Radiance gathered so far.
    pub l: Rgb,
    pub state: PathState,
    differentials: PathDifferentials,
    /// Segments traced so far.
    pub depth: u32,
    /// How far below the surface the ray began, where it went on from below one
    /// (`BsdfSample::from`).
    pub origin_depth: f32,
}

/// Light sampled at a vertex whose shadow ray is not tested yet: `radiance` counts once `ray`
/// is found unoccluded.
#[derive(Clone, Copy)]
pub(super) struct ShadowTest {
    pub ray: Ray,
    pub radiance: Rgb,
}

/// What [`Path::land`] leaves to its caller.
pub(super) struct Landing {
    /// The path goes on along [`Path::ray`].
    pub goes_on: bool,
    /// Where the shadow test was deferred: the light sample still to test, counted before the
    /// path's next hit (so radiance is summed in the order of the one-path loop).
    pub shadow: Option<ShadowTest>,
}

impl Path {
    /// Start over as the path of `camera`, in place (the lane loop reuses its lanes' paths:
    /// the pending differentials need not move).
    #[inline(always)]
    pub fn restart(&mut self, camera: CameraSample) {
        self.sampler = camera.sampler;
        self.ray = camera.ray;
        self.l = Rgb::ZERO;
        self.state = PathState::new();
        self.differentials.restart(camera.rd, camera.offset);
        self.depth = 0;
        self.origin_depth = f32::INFINITY;
    }

    #[inline(always)]
    pub fn new(camera: CameraSample) -> Path {
        Path {
            sampler: camera.sampler,
            ray: camera.ray,
            l: Rgb::ZERO,
            state: PathState::new(),
            differentials: PathDifferentials::new(camera.rd, camera.offset),
            depth: 0,
            origin_depth: f32::INFINITY,
        }
    }

    /// The numbers [`Self::land`] reads at the path's bounce on a material that reads no hit
    /// context, from the dimensions it reads them from: light choice, light position (2), BSDF
    /// lobe, BSDF direction (2), Russian roulette (for the lane vertex, `lane_vertex`).
    #[inline(always)]
    pub fn bounce_numbers(&mut self) -> [f32; 7] {
        self.sampler.bounce_numbers(self.depth)
    }

    /// Record a bounce for the differentials a later hit may read.
    #[inline(always)]
    pub fn push_bounce(&mut self, geometry: &Geometry, bounce: DeferredBounce) {
        self.differentials.push(geometry, bounce);
    }

    /// One vertex of the path: its ray met `hit` (`None`: it escaped). Counts the emission
    /// found there, shades the hit, samples a light (next-event estimation: its shadow ray
    /// tested here, or returned untested with `DEFER_SHADOW`), samples the BSDF for the next
    /// ray and plays Russian roulette.
    #[inline(always)]
    pub fn land<const DIFFERENTIALS: bool, const DEFER_SHADOW: bool>(
        &mut self,
        scene: &Scene,
        hit: Option<SurfaceHit>,
        worker: &mut Worker,
    ) -> Landing {
        let end = |shadow| Landing {
            goes_on: false,
            shadow,
        };
        let settings = &scene.settings;
        let shapes = scene.geometry.shapes();
        let n_lights = scene.lights.len();
        let light_select_pdf = light_select_pdf(scene);
        let max_depth = max_depth(scene);
        let (ray, depth, sampler) = (self.ray, self.depth, &mut self.sampler);
        sampler.start_bounce(depth);
        worker.rays += 1;
        if scene.has_absorption() {
            if let Some(h) = hit.as_ref() {
                self.state.absorb(scene, &ray, h);
            }
        }
        if let Some(c) = self
            .state
            .found_emission(scene, &ray, hit.as_ref(), light_select_pdf)
        {
            self.l += c;
        }
        // (By reference: a copy of the record, read in wide loads right after its narrower
        // stores, stalls on store forwarding.)
        let Some(hit) = hit.as_ref() else {
            return end(None);
        };
        let shape = &shapes[hit.shape as usize];
        let wo_world = -ray.d;
        // Paths of at most `max_depth` segments: the next vertex would make depth + 2. A shape
        // without a material (a pure emitter) absorbs everything.
        if depth + 2 > max_depth || shape.material == NO_MATERIAL {
            return end(None);
        }

        // Shading frame and the material's BSDF.
        let mut bsdf = Bsdf::Diffuse(Diffuse::new(Rgb::ZERO));
        let frame = shade_hit::<DIFFERENTIALS>(
            scene,
            hit,
            Arrival {
                wo: wo_world,
                origin_depth: self.origin_depth,
                depth,
            },
            sampler,
            &mut self.differentials,
            worker,
            &mut bsdf,
        );
        let wo = frame.to_local(wo_world);

        // Next-event estimation.
        let mut shadow = None;
        if !bsdf.is_delta() && n_lights > 0 {
            let vertex = Vertex {
                hit,
                frame,
                wo,
                bsdf: &bsdf,
                beta: self.state.beta,
            };
            if let Some(test) = direct_light::<DEFER_SHADOW>(scene, &vertex, sampler, worker) {
                if DEFER_SHADOW {
                    shadow = Some(test);
                } else {
                    self.l += test.radiance;
                }
            }
        }

        // Continue the path by sampling the BSDF.
        sampler.seek(depth, LOBE_DIM);
        let u_lobe = sampler.next_1d();
        let u_dir = sampler.next_2d();
        let Some(bs) = bsdf.sample(wo, u_lobe, u_dir) else {
            return end(shadow);
        };
        if !(bs.pdf > 0.0) || bs.weight == Rgb::ZERO {
            return end(shadow);
        }
        let bs = match bs.sent_down() {
            Some(_) => {
                let material = &scene.materials[shape.material as usize];
                let key = mix64((u_lobe.to_bits() as u64) << 32 | u_dir.x.to_bits() as u64)
                    ^ u_dir.y.to_bits() as u64;
                match through_grooves_below(material, hit, frame, bs, key) {
                    Some(bs) => bs,
                    None => return end(shadow),
                }
            }
            None => bs,
        };
        let wi_world = frame.to_world(bs.wi);
        self.state.scatter(&bs, bsdf.is_delta());
        if DIFFERENTIALS {
            let transmitted = bs.wi.z * wo.z < 0.0;
            self.differentials.push(
                &scene.geometry,
                DeferredBounce {
                    hit: *hit,
                    n: frame.n,
                    d_in: ray.d,
                    wi: wi_world,
                    delta: bs.delta,
                    transmitted,
                    eta: if transmitted { 1.0 / bs.eta } else { 1.0 },
                },
            );
        }
        let origin = match bs.from {
            // A footprint's lobe: on from the covering scratch's point, on the surface.
            Some(from) if from.z == 0.0 => {
                self.origin_depth = f32::INFINITY;
                let p = hit.p + frame.to_world(from);
                scene.geometry.spawn_origin(p, hit.ng, hit.shape, wi_world)
            }
            // The path left a groove's wall below the surface (traced glass walls seen from
            // inside): on from there, toward the surface beside the groove, where the next hit
            // looks the scratches up again.
            Some(from) => {
                self.origin_depth = -from.z;
                let p = hit.p + frame.to_world(from);
                scene.geometry.spawn_origin(p, hit.ng, hit.shape, wo_world)
            }
            None => {
                self.origin_depth = f32::INFINITY;
                scene
                    .geometry
                    .spawn_origin(hit.p, hit.ng, hit.shape, wi_world)
            }
        };
        self.ray = Ray::new(origin, wi_world);

        self.depth += 1;
        let goes_on =
            self.depth < settings.rr_depth || self.state.survives_roulette(&mut self.sampler);
        Landing { goes_on, shadow }
    }
}

/// The most grooves below the surface that light a groove sent down passes through
/// ([`through_grooves_below`]); past them it goes on from the hit.
const MAX_GROOVES_BELOW: u64 = 8;

/// Light a groove at `hit` sent down into the glass from below the surface (`bs.from`, `bs.wi`
/// going down: traced glass walls seen from inside) through the grooves it meets there before
/// it leaves their depth (METHOD.md 8.1, "Ours": light between grooves; [`Material::groove_below`]),
/// each traced from where the light left the last: the sample that sent it, its direction,
/// weight and relative index those of the light that leaves the last groove met, and where it
/// goes on from; from the hit where it meets none. `key` keys the grooves' random streams.
/// `None` where the light is lost in one.
#[inline(never)]
fn through_grooves_below(
    material: &Material,
    hit: &SurfaceHit,
    frame: Frame,
    mut bs: BsdfSample,
    key: u64,
) -> Option<BsdfSample> {
    for k in 0..MAX_GROOVES_BELOW {
        let Some(from) = bs.sent_down() else {
            return Some(bs);
        };
        let key = mix64(key.wrapping_add(k.wrapping_mul(GOLDEN)));
        let u = crate::hash::unit_f32(key);
        let Some(below) = material.groove_below(hit, frame, from, bs.wi, u) else {
            break;
        };
        let next = below.sample(bs.wi, mix64(key))?;
        bs = BsdfSample {
            wi: next.wi,
            weight: bs.weight * next.weight,
            eta: bs.eta * next.eta,
            from: next.from,
            ..bs
        };
    }
    // Going on down from below the surface: from the hit, as every other sample into the glass.
    if bs.wi.z < 0.0 {
        bs.from = None;
    }
    Some(bs)
}

/// What a path carries from vertex to vertex: its throughput `beta`, the product of the
/// squared relative indices it crossed (to keep Russian roulette independent of radiance
/// scaling at refraction), and what the MIS weight of the next emitter hit needs.
pub(super) struct PathState {
    pub beta: Rgb,
    pub eta_scale: f32,
    /// The last bounce was a delta lobe (the camera counts as one): emitters hit count fully.
    pub specular: bool,
    /// The BSDF sampling pdf of the last bounce.
    pub prev_pdf: f32,
}

impl PathState {
    #[inline(always)]
    fn new() -> Self {
        PathState {
            beta: Rgb::ONE,
            eta_scale: 1.0,
            specular: true,
            prev_pdf: 0.0,
        }
    }

    /// The MIS weight of emission found by BSDF sampling ([`emission_weight`]).
    #[inline(always)]
    fn emission_weight(&self, light_pdf: impl FnOnce() -> f32) -> f32 {
        emission_weight(self.specular, self.prev_pdf, light_pdf)
    }

    /// Emission the path finds along `ray`, times its throughput and MIS-weighted against
    /// light sampling: the environment's where it escapes (`hit` is `None`), an area light's
    /// where it hits one.
    #[inline(always)]
    pub(super) fn found_emission(
        &self,
        scene: &Scene,
        ray: &Ray,
        hit: Option<&SurfaceHit>,
        light_select_pdf: f32,
    ) -> Option<Rgb> {
        let Some(hit) = hit else {
            let env = scene.environment()?;
            let le = env.eval(ray.d);
            let w = self.emission_weight(|| light_select_pdf * env.light_pdf(ray.d));
            return Some(self.beta * le * w);
        };
        let shapes = scene.geometry.shapes();
        let light = &scene.lights[shapes[hit.shape as usize].area_light? as usize];
        let le = light.emitted(hit.ng, -ray.d);
        if le == Rgb::ZERO {
            return None;
        }
        let w = self.emission_weight(|| {
            light_select_pdf * light.area_pdf(shapes, ray.o, hit.t, ray.d, hit.ng)
        });
        Some(self.beta * le * w)
    }

    /// Beer-Lambert absorption along the segment `ray` travelled to `hit`: where it ends on the
    /// back side (w.r.t. `ng`) of a surface whose material absorbs
    /// ([`crate::render::material::Material::absorption`]), it ran inside that object, and the
    /// throughput is multiplied by `exp(-sigma_a t)`, `t` the segment's length. Nested media are
    /// not tracked: a segment inside an absorbing object that ends on another object's front
    /// side is not attenuated.
    #[inline(never)]
    pub(super) fn absorb(&mut self, scene: &Scene, ray: &Ray, hit: &SurfaceHit) {
        let material = scene.geometry.shapes()[hit.shape as usize].material;
        if material == NO_MATERIAL || !(ray.d.dot(hit.ng) > 0.0) {
            return;
        }
        if let Some(sigma_a) = scene.materials[material as usize].absorption() {
            let t = hit.t * ray.d.length();
            self.beta *= (-sigma_a * t).exp();
        }
    }

    /// Continue through the sampled bounce `bs`, from a BSDF that skipped light sampling
    /// ([`Bsdf::is_delta`]) or not.
    #[inline(always)]
    fn scatter(&mut self, bs: &BsdfSample, skipped_light_sampling: bool) {
        self.beta *= bs.weight;
        self.eta_scale *= bs.eta * bs.eta;
        self.specular = bs.delta || skipped_light_sampling;
        self.prev_pdf = bs.pdf;
    }

    /// Russian roulette: survive with probability `q = min(max(beta eta_scale), 0.95)` and
    /// divide the throughput by it.
    #[inline(always)]
    fn survives_roulette(&mut self, sampler: &mut PixelSampler) -> bool {
        let q = survival_probability(self.beta, self.eta_scale);
        if !(sampler.next_1d() < q) {
            return false;
        }
        self.beta /= q;
        true
    }
}

/// The MIS weight of emission a path found by BSDF sampling: 1 after a delta bounce (and at the
/// camera), else the power heuristic of the BSDF's pdf `prev_pdf` against light sampling's,
/// `light_pdf()` (light choice included).
#[inline(always)]
fn emission_weight(specular: bool, prev_pdf: f32, light_pdf: impl FnOnce() -> f32) -> f32 {
    if specular {
        1.0
    } else {
        power_heuristic(prev_pdf, light_pdf())
    }
}

/// How the ray that made a hit arrived: the direction toward the viewer (world), how far
/// below the surface it began ([`crate::render::shading::ShadingContext::origin_depth`]) and
/// the path's bounce at the hit.
#[derive(Clone, Copy)]
struct Arrival {
    wo: Vec3,
    origin_depth: f32,
    depth: u32,
}

/// The shading frame at `hit` (not a pure emitter) for the ray `arrival`, with the material's
/// BSDF written into `bsdf` ([`Material::shade_into`]), and what the material reads of the
/// hit worked out only where it reads it: `u_layer`, the footprint, and the chain of delta
/// bounces that led here.
#[inline(always)]
fn shade_hit<'a, const DIFFERENTIALS: bool>(
    scene: &'a Scene,
    hit: &SurfaceHit,
    arrival: Arrival,
    sampler: &mut PixelSampler,
    differentials: &mut PathDifferentials,
    worker: &mut Worker,
    bsdf: &mut Bsdf<'a>,
) -> Frame {
    let Arrival {
        wo: wo_world,
        origin_depth,
        depth,
    } = arrival;
    let material = &scene.materials[scene.geometry.shapes()[hit.shape as usize].material as usize];
    // `u_layer`: dimension 0 of the bounce's block, drawn only where the material reads it
    // (the scratched material, not glass seen from inside). Where it only breaks ties between
    // crossing scratches it is hashed: the block's first Sobol set (light choice and position)
    // is computed only where light sampling runs, not at every hit of a scratched surface
    // (most of them see no scratch and are delta bounces). A material that picks one lobe by
    // it (`layer_mix = "stochastic"`) reads the bounce's BSDF-lobe number instead, and its
    // BSDF the place of that number within the pick's share: one stratified number picks the
    // layer and the component, as `union`'s sampling does with all the layers' lobes (drawn
    // apart, the two choices gave mirror-walled glints twice the variance).
    let u_layer = if material.reads_hit_context(wo_world, hit.ng) {
        if material.picks_lobe_by_lobe_number() {
            let u = sampler.peek(depth, LOBE_DIM);
            sampler.seek(depth, 1);
            Some(u)
        } else {
            Some(sampler.next_1d_hashed())
        }
    } else {
        sampler.seek(depth, 1);
        None
    };
    let reads_footprint = u_layer.is_some() && material.reads_footprint_at(wo_world, hit.ng);
    let (rd_here, chain) = if DIFFERENTIALS && reads_footprint {
        let (rd, chain) = differentials.resolve(&scene.geometry);
        (Some(rd), chain)
    } else {
        (None, None)
    };
    let view = HitView {
        wo: wo_world,
        rd: rd_here.as_ref(),
        u_layer,
        pixel: chain.map(|chain| PixelHit {
            shape: hit.shape,
            chain,
            offset: differentials.offset,
        }),
        origin_depth,
    };
    material.shade_into(hit, view, &mut worker.coverage, bsdf)
}

/// Russian roulette's survival probability for throughput `beta` and the radiance scaling
/// `eta_scale` crossed: `min(max(beta eta_scale), 0.95)`.
#[inline(always)]
pub(super) fn survival_probability(beta: Rgb, eta_scale: f32) -> f32 {
    (beta * eta_scale).max_element().min(0.95)
}

/// The light next-event estimation chooses with `u_choice` (uniformly; the scene has one).
#[inline(always)]
pub(super) fn chosen_light(scene: &Scene, u_choice: f32) -> &Light {
    let n_lights = scene.lights.len();
    &scene.lights[((u_choice * n_lights as f32) as usize).min(n_lights - 1)]
}

/// The length of a shadow ray from `origin` (spawned off the hit `p`) to a light sample
/// `dist` from `p`, a little short of it; unbounded toward a light at infinity.
#[inline(always)]
pub(super) fn shadow_t_max(dist: f32, origin: Vec3, p: Vec3) -> f32 {
    if dist.is_finite() {
        (dist - (origin - p).length()) * (1.0 - 1e-3)
    } else {
        f32::INFINITY
    }
}

/// The most segments a path may have (`render.max_depth`, 0 for no limit).
#[inline(always)]
pub(super) fn max_depth(scene: &Scene) -> u32 {
    match scene.settings.max_depth {
        0 => u32::MAX,
        d => d,
    }
}

/// The probability of next-event estimation choosing a given light (uniform; 0 without lights).
#[inline(always)]
pub(super) fn light_select_pdf(scene: &Scene) -> f32 {
    match scene.lights.len() {
        0 => 0.0,
        n => 1.0 / n as f32,
    }
}

/// A path vertex as next-event estimation reads it: the hit, its shading frame, the direction
/// toward the viewer in that frame, the BSDF there and the path throughput that reached it.
struct Vertex<'a, 'b> {
    hit: &'a SurfaceHit,
    frame: Frame,
    wo: Vec3,
    bsdf: &'a Bsdf<'b>,
    beta: Rgb,
}

/// Next-event estimation at a non-delta vertex: one light chosen uniformly, its sample weighted
/// by MIS (power heuristic) against BSDF sampling; a constant environment, left to BSDF
/// sampling, gives no sample when chosen (pbrt-v4's `allowIncompletePDF`). Returns the radiance
/// the path gains with the shadow ray it needs, `None` where the light's sample adds nothing or
/// is occluded. With `DEFER_SHADOW` the shadow ray is left to the caller to test; else it is
/// tested here, before the MIS weight is worked out.
#[inline(always)]
fn direct_light<const DEFER_SHADOW: bool>(
    scene: &Scene,
    v: &Vertex<'_, '_>,
    sampler: &mut PixelSampler,
    worker: &mut Worker,
) -> Option<ShadowTest> {
    let (hit, frame, wo, bsdf) = (v.hit, v.frame, v.wo, v.bsdf);
    let shapes = scene.geometry.shapes();
    let light_select_pdf = light_select_pdf(scene);
    let u_choice = sampler.next_1d();
    let u_light = sampler.next_2d();
    let ls = chosen_light(scene, u_choice).sample_li(hit.p, u_light, shapes)?;
    let wi = frame.to_local(ls.wi);
    let (f, pdf_bsdf) = bsdf.eval_for_light(wo, wi, ls.delta);
    let f = f * wi.z.abs();
    if f == Rgb::ZERO {
        return None;
    }
    let origin = scene.geometry.spawn_origin(hit.p, hit.ng, hit.shape, ls.wi);
    let t_max = shadow_t_max(ls.dist, origin, hit.p);
    worker.rays += 1;
    let shadow = Ray {
        o: origin,
        d: ls.wi,
        t_max,
    };
    if !DEFER_SHADOW && scene.geometry.occluded(&shadow) {
        return None;
    }
    let pdf_light = light_select_pdf * ls.pdf;
    let w = if ls.delta {
        1.0
    } else {
        let pdf_bsdf = pdf_bsdf.unwrap_or_else(|| bsdf.pdf(wo, wi));
        power_heuristic(pdf_light, pdf_bsdf)
    };
    Some(ShadowTest {
        ray: shadow,
        radiance: v.beta * f * ls.radiance * (w / pdf_light),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::math::reflect;
    use crate::render::geometry::{Shape, ShapeGeometry, TriangleMesh};
    use crate::render::integrator::offset_origin;
    use crate::render::shading::{footprint_dp, refract_dir};

    fn geometry(g: ShapeGeometry) -> Geometry {
        Geometry::new(vec![Shape {
            geometry: g,
            material: 0,
            area_light: None,
        }])
    }

    /// Where a ray leaves a delta bounce off `hit` (shading normal), reflected or refracted
    /// into glass of index 1.5 from outside.
    fn bounce(d: Vec3, ns: Vec3, reflection: bool) -> Vec3 {
        let n = if d.dot(ns) < 0.0 { ns } else { -ns };
        if reflection {
            reflect(-d, n)
        } else {
            refract_dir(d, n, 1.0 / 1.5).unwrap()
        }
    }

    /// Deferred differentials ([`PathDifferentials`]) equal the ones worked out at every
    /// bounce, bit for bit, and so do the chains of delta bounces, whenever a hit asks for
    /// them: along paths of reflections, refractions and diffuse bounces inside and around the
    /// teapot and a sphere, asked at irregular bounces and longer than the pending capacity (so
    /// the records also flush as they fill up).
    #[test]
    fn deferred_differentials_equal_eager_ones() {
        let shapes = [
            geometry(ShapeGeometry::sphere(Vec3::ZERO, 1.0).unwrap()),
            geometry(ShapeGeometry::Mesh(TriangleMesh::teapot(12))),
        ];
        let bits = |rd: &RayDifferential| {
            [rd.rx_o, rd.rx_d, rd.ry_o, rd.ry_d].map(|v| v.to_array().map(f32::to_bits))
        };
        let (mut compared, mut longest, mut chains) = (0, 0, 0);
        for g in &shapes {
            for path in 0..30u32 {
                let a = path as f32 * 0.73;
                let o = Vec3::new(4.0 * a.cos(), 0.7 + 0.4 * (1.7 * a).sin(), 4.0 * a.sin());
                let d = (Vec3::new(0.05 * a.sin(), 0.7, 0.0) - o).normalize();
                let ex = d.cross(Vec3::Y).normalize();
                let ey = ex.cross(d);
                let camera = RayDifferential {
                    rx_o: o + 1e-3 * ex,
                    rx_d: (d + 1e-3 * ex).normalize(),
                    ry_o: o + 1e-3 * ey,
                    ry_d: (d + 1e-3 * ey).normalize(),
                };
                let mut eager = camera;
                let mut eager_chain = Some(0u64);
                let mut lazy = PathDifferentials::new(camera, Vec2::ZERO);
                let mut ray = Ray::new(o, d);
                let mut bounces = 0;
                while let Some(hit) = g.intersect(&ray) {
                    // The render loop's eager propagation (before `PathDifferentials`).
                    let k = bounces as u32 + 7 * path;
                    let delta = k % 5 != 3;
                    let n = if ray.d.dot(hit.ns) < 0.0 {
                        hit.ns
                    } else {
                        -hit.ns
                    };
                    let inside = ray.d.dot(hit.ng) > 0.0;
                    let eta = if inside { 1.5 } else { 1.0 / 1.5 };
                    // Refracted in, then reflected inside: long paths.
                    let refracted = refract_dir(ray.d, n, eta).filter(|_| delta && !inside);
                    let wi = match (delta, refracted) {
                        (true, Some(t)) => t.normalize(),
                        (true, None) => reflect(-ray.d, n),
                        // A diffuse bounce: some direction on the incoming side.
                        (false, _) => (n + 0.6 * hit.dpdu.normalize()).normalize(),
                    };
                    let eta_path = if refracted.is_some() { eta } else { 1.0 };
                    let (dpdx, dpdy) = footprint_dp(&hit, &eager);
                    let normals = if delta && g.has_curved_normals(hit.shape) {
                        offset_normals(g, &hit, n, dpdx, dpdy)
                    } else {
                        None
                    };
                    eager = spawn_differentials(
                        hit.p, dpdx, dpdy, ray.d, &eager, n, normals, wi, delta, eta_path,
                    );
                    // The render loop's chain of delta bounces (before it moved into
                    // `PathDifferentials`).
                    eager_chain = eager_chain
                        .filter(|_| delta)
                        .map(|chain| PixelHit::chain_after(chain, hit.shape, refracted.is_some()));
                    lazy.push(
                        g,
                        DeferredBounce {
                            hit,
                            n,
                            d_in: ray.d,
                            wi,
                            delta,
                            transmitted: refracted.is_some(),
                            eta: eta_path,
                        },
                    );
                    bounces += 1;
                    // Ask at irregular bounces, and never for some paths' first 12.
                    if k.wrapping_mul(2_654_435_761) % 7 < 2 && (path % 3 != 0 || bounces > 12) {
                        let (rd, chain) = lazy.resolve(g);
                        assert_eq!(bits(&rd), bits(&eager), "path {path}");
                        assert_eq!(chain, eager_chain, "path {path}");
                        chains += chain.is_some_and(|c| c != 0) as usize;
                        compared += 1;
                    }
                    if bounces == 3 * PathDifferentials::CAPACITY {
                        break;
                    }
                    ray = Ray::new(offset_origin(hit.p, hit.ng, wi), wi);
                }
                let (rd, chain) = lazy.resolve(g);
                assert_eq!(bits(&rd), bits(&eager), "path {path}, end");
                assert_eq!(chain, eager_chain, "path {path}, end");
                compared += 1;
                longest = longest.max(bounces);
            }
        }
        assert!(longest > 2 * PathDifferentials::CAPACITY, "{longest}");
        assert!(compared > 100, "{compared}");
        assert!(chains >= 10, "{chains} non-trivial chains compared");
    }

    /// A pixel's camera samples made together ([`camera_packet`], in lanes through a pinhole
    /// with Sobol numbers) equal those made one at a time ([`camera_sample`]): rays, offsets,
    /// differentials and the streams' next numbers, bit for bit, for whole and cut chunks and
    /// for every kind of camera sample the render loops make.
    #[test]
    fn camera_samples_made_together_equal_one_at_a_time() {
        use crate::render::scene::{Overrides, Scene};
        let teapot = include_str!("../../../scenes/glass-teapot.toml");
        let lens = teapot.replace("fov = 30.0", "fov = 30.0\naperture_radius = 0.05");
        let independent = teapot.replace("seed = 0", "seed = 0\nsampler = \"independent\"");
        let bits = |v: Vec3| v.to_array().map(f32::to_bits);
        for text in [teapot, &lens, &independent] {
            let o = Overrides::default();
            let scene =
                Scene::parse(text, std::path::Path::new("t.toml"), ".".as_ref(), &o).unwrap();
            for (x, y, first, n) in [(3, 5, 0, PACKET), (400, 300, 96, 7)] {
                let pixel = y as u64 * 512 + x as u64;
                let (mut together, mut hits) = (ArrayVec::new(), ArrayVec::new());
                camera_packet::<false>(&scene, (x, y), pixel, (first, n), &mut together, &mut hits);
                let mut with_rd = ArrayVec::new();
                camera_packet::<true>(&scene, (x, y), pixel, (first, n), &mut with_rd, &mut hits);
                assert_eq!(together.len(), n);
                for (k, (a, b)) in together.into_iter().zip(with_rd).enumerate() {
                    let s = first + k as u32;
                    for (mut got, mut want) in [
                        (a, camera_sample::<false>(&scene, (x, y), pixel, s)),
                        (b, camera_sample::<true>(&scene, (x, y), pixel, s)),
                    ] {
                        assert_eq!(bits(got.ray.o), bits(want.ray.o));
                        assert_eq!(bits(got.ray.d), bits(want.ray.d), "sample {s}");
                        assert_eq!(bits(got.rd.rx_d), bits(want.rd.rx_d));
                        assert_eq!(bits(got.rd.ry_d), bits(want.rd.ry_d));
                        assert_eq!(got.offset, want.offset);
                        got.sampler.start_bounce(1);
                        want.sampler.start_bounce(1);
                        assert_eq!(got.sampler.next_1d(), want.sampler.next_1d());
                    }
                }
            }
        }
    }

    /// A delta bounce's offset rays follow their neighbours: a ray offset by a small step
    /// from the central one, traced exactly to its own hit and bounced about its own shading
    /// normal, leaves in the direction the spawned differential says, on an analytic sphere
    /// and on the teapot's interpolated normals, for reflection and refraction at many
    /// angles. The locally flat rule (the hit's normal for every offset ray, `None`) misses
    /// the curvature's whole effect there.
    #[test]
    fn delta_bounce_differentials_follow_neighbour_rays_on_curved_surfaces() {
        let shapes = [
            (
                "sphere",
                geometry(ShapeGeometry::sphere(Vec3::ZERO, 1.0).unwrap()),
            ),
            (
                "teapot",
                geometry(ShapeGeometry::Mesh(TriangleMesh::teapot(12))),
            ),
        ];
        let step = 1e-3f32;
        let mut checked = 0;
        for (name, g) in &shapes {
            for i in 0..40 {
                // Rays from a ring of eye points toward the shape's middle, slightly off axis.
                let a = i as f32 * 0.61;
                let o = Vec3::new(4.0 * a.cos(), 0.8 + 0.5 * (1.3 * a).sin(), 4.0 * a.sin());
                let target = Vec3::new(0.1 * (2.0 * a).sin(), 0.7, 0.1 * a.cos());
                let d = (target - o).normalize();
                let Some(hit) = g.intersect(&Ray::new(o, d)) else {
                    continue;
                };
                let ex = d.cross(Vec3::Y).normalize();
                let ey = ex.cross(d);
                let rd = RayDifferential {
                    rx_o: o + step * ex,
                    rx_d: d,
                    ry_o: o + step * ey,
                    ry_d: d,
                };
                let (dpdx, dpdy) = footprint_dp(&hit, &rd);
                for reflection in [true, false] {
                    let wi = bounce(d, hit.ns, reflection);
                    let eta = if reflection { 1.0 } else { 1.0 / 1.5 };
                    let normals = offset_normals(g, &hit, hit.ns, dpdx, dpdy);
                    assert!(
                        normals.is_some(),
                        "{name}: curved surfaces have offset normals"
                    );
                    let spawn = |normals| {
                        spawn_differentials(
                            hit.p, dpdx, dpdy, d, &rd, hit.ns, normals, wi, true, eta,
                        )
                    };
                    let (curved, flat) = (spawn(normals), spawn(None));
                    for (o_off, got, got_flat) in [
                        (rd.rx_o, curved.rx_d, flat.rx_d),
                        (rd.ry_o, curved.ry_d, flat.ry_d),
                    ] {
                        let Some(h) = g.intersect(&Ray::new(o_off, d)) else {
                            continue;
                        };
                        if (h.shape, h.ng.dot(d) < 0.0) != (hit.shape, hit.ng.dot(d) < 0.0) {
                            continue;
                        }
                        let want = bounce(d, h.ns, reflection);
                        let spread = (want - wi).length();
                        assert!(spread > 1e-5, "{name}: the neighbour must turn ({spread})");
                        let err = (got - want).length();
                        let err_flat = (got_flat - want).length();
                        assert!(
                            err < 0.02 * spread,
                            "{name} ray {i} reflection {reflection}: off by {err} of {spread}"
                        );
                        assert!(
                            err_flat > 0.5 * spread,
                            "{name} ray {i}: the flat rule should miss ({err_flat} of {spread})"
                        );
                        checked += 1;
                    }
                }
            }
        }
        assert!(checked > 200, "{checked}");
        // Flat faces keep the hit's normal: a box has normals, all equal per face.
        let cube = geometry(ShapeGeometry::Mesh(TriangleMesh::cuboid()));
        assert!(shapes.iter().all(|(_, g)| g.has_curved_normals(0)));
        assert!(!cube.has_curved_normals(0));
        let ray = Ray::new(Vec3::new(0.3, 0.2, 5.0), -Vec3::Z);
        let hit = cube.intersect(&ray).unwrap();
        let normals = offset_normals(&cube, &hit, hit.ns, 0.1 * Vec3::X, 0.1 * Vec3::Y);
        assert_eq!(normals, None);
    }
}
