//! The vertex of a plain material in lanes: [`Path::land`]'s operations for up to [`LANES`]
//! paths at once where their rays met a diffuse surface, a smooth dielectric (scratched glass
//! seen from inside included: its smooth base) or a smooth conductor ([`Kind`]), in three
//! stages:
//!
//! 1. **Gather**, lane by lane: the hit, the path's throughput, the bounce's random numbers
//!    (the dimensions `land` reads, drawn in its order), the texture, the light sample and the
//!    cosine-weighted direction (each a scalar call: `sincosf` and the `Texture` and `Light`
//!    enums do not vectorise) into structure-of-arrays [`Lanes`].
//! 2. **The vertex** ([`Lanes::run`]), one loop over the lanes whose body is the scalar code's
//!    own functions (shading frame, next-event estimation's BSDF value and MIS weight, Fresnel,
//!    the throughput's update, the spawned rays, Russian roulette) with every decision a
//!    select, so that the render loop's SIMD copies run it 8 or 16 lanes at a time.
//! 3. **Scatter**, lane by lane: the path's new ray and state, its deferred shadow test.
//!
//! Each lane runs the operations of `land` on the same numbers, so the image is `land`'s bit
//! for bit (`tests/lanes.rs` on every shipped scene; `lane_vertex_equals_land` lane by lane).

// `!(x > 0.0)` is meant: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::lanes::LANES;
use super::path::{
    chosen_light, light_select_pdf, max_depth, shadow_t_max, survival_probability, DeferredBounce,
    Path, ShadowTest,
};
use super::Worker;
use crate::math::{reflect_z, Ray, Rgb, Vec2, Vec3};
use crate::optics::fresnel_f32;
use crate::render::bsdf::{Bsdf, ConductorIor};
use crate::render::geometry::{offset_origin_by, SurfaceHit};
use crate::render::material::Material;
use crate::render::scene::{Scene, NO_MATERIAL};
use crate::render::shading::shading_frame_of;
use crate::sampling::{cosine_hemisphere_pdf, power_heuristic, square_to_cosine_hemisphere};

/// The BSDFs the lane vertex runs.
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
#[repr(u8)]
pub(super) enum Kind {
    /// `Diffuse`, with next-event estimation.
    Diffuse,
    /// A smooth `Dielectric`.
    Glass,
    /// A smooth `Conductor`.
    Mirror,
}

/// The lane vertex's BSDF for the vertex of a path at `depth` whose ray met `hit`, arriving
/// along `d`, if it takes it: a diffuse, smooth dielectric or smooth conductor material (or
/// scratched glass seen from inside) on a shape that emits nothing, below the depth limit
/// (what `land` does there and nothing more, in a scene [`applies`] to).
#[inline(always)]
pub(super) fn takes(scene: &Scene, hit: &SurfaceHit, depth: u32, d: Vec3) -> Option<Kind> {
    let shape = &scene.geometry.shapes()[hit.shape as usize];
    if shape.material == NO_MATERIAL || shape.area_light.is_some() || depth + 2 > max_depth(scene) {
        return None;
    }
    match &scene.materials[shape.material as usize] {
        Material::Diffuse { .. } => Some(Kind::Diffuse),
        Material::Dielectric { roughness, .. } if *roughness == 0.0 => Some(Kind::Glass),
        Material::Conductor { roughness, .. } if *roughness == 0.0 => Some(Kind::Mirror),
        Material::Scratched(m) if m.has_transmission() && !m.reads_hit_context(-d, hit.ng) => {
            Some(Kind::Glass)
        }
        _ => None,
    }
}

/// Three-component vectors over the lanes, a component an array: loads and stores of one
/// lane's vector that the lane loop's SIMD copies run for 8 or 16 lanes at once without
/// shuffles.
#[derive(Clone, Copy)]
struct Soa3([[f32; LANES]; 3]);

impl Soa3 {
    fn splat(v: Vec3) -> Self {
        Soa3([[v.x; LANES], [v.y; LANES], [v.z; LANES]])
    }

    #[inline(always)]
    fn get(&self, i: usize) -> Vec3 {
        Vec3::new(self.0[0][i], self.0[1][i], self.0[2][i])
    }

    #[inline(always)]
    fn set(&mut self, i: usize, v: Vec3) {
        self.0[0][i] = v.x;
        self.0[1][i] = v.y;
        self.0[2][i] = v.z;
    }
}

/// Whether a scene's plain vertices may run in lanes at all: `land` attenuates by absorption
/// before anything else, which the lanes do not.
#[inline(always)]
pub(super) fn applies(scene: &Scene) -> bool {
    !scene.has_absorption()
}

/// A lane's inputs and results, each field an array over the lanes.
#[derive(Clone, Copy)]
pub(super) struct Lanes {
    // The hit and the path that reached it.
    kind: [Kind; LANES],
    wo: Soa3,
    p: Soa3,
    ng: Soa3,
    ns: Soa3,
    dpdu: Soa3,
    /// The spawned rays' offset ([`crate::render::geometry::Geometry::spawn_offset`]).
    rel: [f32; LANES],
    beta: Soa3,
    eta_scale: [f32; LANES],
    /// Russian roulette after this bounce, with this number.
    roulette: [bool; LANES],
    u_roulette: [f32; LANES],
    // Diffuse: the reflectance, the cosine-weighted direction, the light sample where there is
    // one (`has_light`; `pdf_light` with the light's choice).
    reflectance: Soa3,
    cosine_dir: Soa3,
    light_wi: Soa3,
    light_dist: [f32; LANES],
    light_radiance: Soa3,
    pdf_light: [f32; LANES],
    light_delta: [bool; LANES],
    has_light: [bool; LANES],
    // Glass: the relative index and the lobe's number; mirror: the complex index.
    eta: [f32; LANES],
    u_lobe: [f32; LANES],
    ior_eta: Soa3,
    ior_k: Soa3,

    // Results: the shadow test (`shadow_radiance` counts where `shadowed`), the bounce (where
    // `scattered`), the state after it, whether the path goes on.
    shadowed: [bool; LANES],
    shadow_o: Soa3,
    shadow_t_max: [f32; LANES],
    shadow_radiance: Soa3,
    scattered: [bool; LANES],
    n: Soa3,
    wi_world: Soa3,
    origin: Soa3,
    transmitted: [bool; LANES],
    bounce_eta: [f32; LANES],
    prev_pdf: [f32; LANES],
    goes_on: [bool; LANES],
}

impl Lanes {
    pub fn new() -> Self {
        let v = Soa3::splat(Vec3::Z);
        let f = [1.0; LANES];
        let b = [false; LANES];
        Lanes {
            kind: [Kind::Diffuse; LANES],
            wo: v,
            p: Soa3::splat(Vec3::ZERO),
            ng: v,
            ns: v,
            dpdu: Soa3::splat(Vec3::X),
            rel: f,
            beta: Soa3::splat(Rgb::ONE),
            eta_scale: f,
            roulette: b,
            u_roulette: f,
            reflectance: Soa3::splat(Rgb::ONE),
            cosine_dir: v,
            light_wi: v,
            light_dist: f,
            light_radiance: Soa3::splat(Rgb::ONE),
            pdf_light: f,
            light_delta: b,
            has_light: b,
            eta: f,
            u_lobe: f,
            ior_eta: Soa3::splat(Vec3::ONE),
            ior_k: Soa3::splat(Vec3::ONE),
            shadowed: b,
            shadow_o: v,
            shadow_t_max: f,
            shadow_radiance: Soa3::splat(Rgb::ZERO),
            scattered: b,
            n: v,
            wi_world: v,
            origin: v,
            transmitted: b,
            bounce_eta: f,
            prev_pdf: f,
            goes_on: b,
        }
    }

    /// Stage 1 for lane `i`: the vertex of `path` at `hit`, of the kind [`takes`] found, as
    /// `land` begins it: the bounce's numbers drawn from the path's sampler at the dimensions
    /// `land` reads them from, the lane's inputs set.
    #[inline(always)]
    pub fn gather(
        &mut self,
        i: usize,
        scene: &Scene,
        path: &mut Path,
        hit: &SurfaceHit,
        kind: Kind,
    ) {
        let shapes = scene.geometry.shapes();
        let material = &scene.materials[shapes[hit.shape as usize].material as usize];
        let depth = path.depth;
        let [u_choice, u_light_x, u_light_y, u_lobe, u_dir_x, u_dir_y, u_roulette] =
            path.bounce_numbers();
        self.wo.set(i, -path.ray.d);
        self.p.set(i, hit.p);
        self.ng.set(i, hit.ng);
        self.ns.set(i, hit.ns);
        self.dpdu.set(i, hit.dpdu);
        self.rel[i] = scene.geometry.spawn_offset(hit.shape);
        self.beta.set(i, path.state.beta);
        self.eta_scale[i] = path.state.eta_scale;
        self.roulette[i] = depth + 1 >= scene.settings.rr_depth;
        self.u_roulette[i] = u_roulette;
        self.kind[i] = kind;
        self.has_light[i] = false;
        match material {
            Material::Diffuse { reflectance } => {
                self.reflectance.set(i, reflectance.eval(hit.uv));
                self.cosine_dir
                    .set(i, square_to_cosine_hemisphere(Vec2::new(u_dir_x, u_dir_y)));
                // Next-event estimation's light (`direct_light`).
                if !scene.lights.is_empty() {
                    let u_light = Vec2::new(u_light_x, u_light_y);
                    let light = chosen_light(scene, u_choice);
                    if let Some(ls) = light.sample_li(hit.p, u_light, shapes) {
                        self.light_wi.set(i, ls.wi);
                        self.light_dist[i] = ls.dist;
                        self.light_radiance.set(i, ls.radiance);
                        self.pdf_light[i] = light_select_pdf(scene) * ls.pdf;
                        self.light_delta[i] = ls.delta;
                        self.has_light[i] = true;
                    }
                }
            }
            Material::Conductor { ior, .. } => {
                self.ior_eta.set(i, ior.eta);
                self.ior_k.set(i, ior.k);
            }
            Material::Dielectric { eta, .. } => {
                self.eta[i] = *eta;
                self.u_lobe[i] = u_lobe;
            }
            Material::Scratched(m) => {
                let Bsdf::Dielectric(base) = m.base_bsdf() else {
                    unreachable!("scratched glass has a smooth dielectric base")
                };
                self.eta[i] = base.eta;
                self.u_lobe[i] = u_lobe;
            }
            _ => unreachable!("`takes` took the material"),
        }
    }

    /// Stage 2: every lane's vertex, `land`'s operations with its decisions as selects (a
    /// lane [`Self::gather`] did not set computes on stale numbers, and is not scattered).
    #[inline(always)]
    pub fn run(&mut self) {
        for i in 0..LANES {
            self.run_lane(i);
        }
    }

    /// [`Self::run`] for lane `i`: the scalar code's functions, in `land`'s order.
    #[inline(always)]
    fn run_lane(&mut self, i: usize) {
        let kind = self.kind[i];
        let (wo_world, p, ng) = (self.wo.get(i), self.p.get(i), self.ng.get(i));
        let transmits = kind == Kind::Glass;
        let frame = shading_frame_of(ng, self.ns.get(i), self.dpdu.get(i), wo_world, transmits);
        let wo = frame.to_local(wo_world);
        let beta = self.beta.get(i);

        // Next-event estimation (`direct_light` with `Diffuse`'s value and density).
        let pdf_light = self.pdf_light[i];
        let light_wi = self.light_wi.get(i);
        let wi = frame.to_local(light_wi);
        let f = diffuse_eval(self.reflectance.get(i), wo, wi) * wi.z.abs();
        let shadow_o = offset_origin_by(p, ng, light_wi, self.rel[i]);
        self.shadow_t_max[i] = shadow_t_max(self.light_dist[i], shadow_o, p);
        self.shadow_o.set(i, shadow_o);
        let w = if self.light_delta[i] {
            1.0
        } else {
            power_heuristic(pdf_light, diffuse_pdf(wo, wi))
        };
        self.shadow_radiance
            .set(i, beta * f * self.light_radiance.get(i) * (w / pdf_light));
        self.shadowed[i] = self.has_light[i] && f != Rgb::ZERO;

        // The BSDF's sample: `Diffuse::sample`, `Dielectric::sample` or `Conductor::sample`.
        let cosine_dir = self.cosine_dir.get(i);
        let (r, cos_t, eta_it) = fresnel_f32::dielectric(wo.z, self.eta[i]);
        let mirror = self.u_lobe[i] < r || r >= 1.0;
        let eta_ti = 1.0 / eta_it;
        let fresnel = ConductorIor {
            eta: self.ior_eta.get(i),
            k: self.ior_k.get(i),
        }
        .fresnel(wo.z);
        // (Selects, not a `match` on the kind: a `switch` keeps the loop from vectorising.)
        let (bs_wi, weight, pdf, bs_eta) = if kind == Kind::Diffuse {
            (
                cosine_dir,
                self.reflectance.get(i),
                cosine_hemisphere_pdf(cosine_dir),
                1.0,
            )
        } else if kind == Kind::Mirror {
            (reflect_z(wo), fresnel, 1.0, 1.0)
        } else if mirror {
            (reflect_z(wo), Rgb::ONE, r, 1.0)
        } else {
            (
                Vec3::new(-eta_ti * wo.x, -eta_ti * wo.y, cos_t),
                Rgb::splat(eta_ti * eta_ti),
                1.0 - r,
                eta_it,
            )
        };
        // `Diffuse::sample` and `Conductor::sample` give none below the surface (or at a zero
        // density); `land` ends the path at a sample of no density or weight.
        let sampled = transmits || !(wo.z <= 0.0);
        self.scattered[i] = sampled && pdf > 0.0 && weight != Rgb::ZERO;
        let wi_world = frame.to_world(bs_wi);
        self.wi_world.set(i, wi_world);
        self.n.set(i, frame.n);
        self.transmitted[i] = bs_wi.z * wo.z < 0.0;
        self.bounce_eta[i] = bs_eta;
        self.prev_pdf[i] = pdf;
        // `PathState::scatter`.
        let beta = beta * weight;
        let eta_scale = self.eta_scale[i] * (bs_eta * bs_eta);
        self.eta_scale[i] = eta_scale;
        self.origin
            .set(i, offset_origin_by(p, ng, wi_world, self.rel[i]));
        // `PathState::survives_roulette`.
        let q = survival_probability(beta, eta_scale);
        let survives = self.u_roulette[i] < q;
        self.goes_on[i] = self.scattered[i] && (!self.roulette[i] || survives);
        self.beta
            .set(i, if self.roulette[i] { beta / q } else { beta });
    }

    /// Stage 3 for lane `i`: its results into `path` (the next ray and the state after the
    /// bounce, where it goes on) and the shadow test it leaves, as `land` leaves them.
    /// Returns whether the path goes on.
    #[inline(always)]
    pub fn scatter<const DIFFERENTIALS: bool>(
        &self,
        i: usize,
        scene: &Scene,
        path: &mut Path,
        hit: &SurfaceHit,
        worker: &mut Worker,
        shadow: &mut Option<ShadowTest>,
    ) -> bool {
        worker.rays += 1;
        if self.shadowed[i] {
            worker.rays += 1;
            *shadow = Some(ShadowTest {
                ray: Ray {
                    o: self.shadow_o.get(i),
                    d: self.light_wi.get(i),
                    t_max: self.shadow_t_max[i],
                },
                radiance: self.shadow_radiance.get(i),
            });
        }
        if !self.scattered[i] {
            return false;
        }
        let delta = self.kind[i] != Kind::Diffuse;
        path.state.beta = self.beta.get(i);
        path.state.eta_scale = self.eta_scale[i];
        path.state.specular = delta;
        path.state.prev_pdf = self.prev_pdf[i];
        if DIFFERENTIALS {
            let transmitted = self.transmitted[i];
            path.push_bounce(
                &scene.geometry,
                DeferredBounce {
                    hit: *hit,
                    n: self.n.get(i),
                    d_in: path.ray.d,
                    wi: self.wi_world.get(i),
                    delta,
                    transmitted,
                    eta: if transmitted {
                        1.0 / self.bounce_eta[i]
                    } else {
                        1.0
                    },
                },
            );
        }
        path.origin_depth = f32::INFINITY;
        path.ray = Ray::new(self.origin.get(i), self.wi_world.get(i));
        path.depth += 1;
        self.goes_on[i]
    }
}

/// `Diffuse::eval` for the reflectance `reflectance`.
#[inline(always)]
fn diffuse_eval(reflectance: Rgb, wo: Vec3, wi: Vec3) -> Rgb {
    crate::render::bsdf::Diffuse::new(reflectance).eval(wo, wi)
}

/// `Diffuse::pdf`.
#[inline(always)]
fn diffuse_pdf(wo: Vec3, wi: Vec3) -> f32 {
    crate::render::bsdf::Diffuse::new(Rgb::ONE).pdf(wo, wi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::geometry::SurfaceHit;
    use crate::render::integrator::path::camera_sample;
    use crate::render::scene::Overrides;

    /// Diffuse (textured and plain), glass (a smooth mesh and a sphere) and gold under every kind of
    /// light the lanes sample: a rectangle and a sphere that emit, a point light (delta) and a
    /// constant sky (left to BSDF sampling).
    const SCENE: &str = r#"
[render]
width = 24
height = 16
max_depth = 10
rr_depth = 2
sampler = "SAMPLER"

[camera]
position = [0.0, 1.6, 5.0]
look_at = [0.0, 0.6, 0.0]
fov = 45.0

[materials.glass]
type = "dielectric"
ior = 1.5

[materials.dense]
type = "dielectric"
ior = 2.4

[materials.floor]
type = "diffuse"
reflectance = { type = "checkerboard", color0 = [0.8, 0.7, 0.6], color1 = [0.1, 0.2, 0.1], scale = 8.0 }

[materials.white]
type = "diffuse"
reflectance = [0.9, 0.85, 0.8]

[materials.gold]
type = "conductor"
preset = "gold"

[[shapes]]
type = "teapot"
material = "glass"
subdivisions = 4
transform = [{ scale = 0.4 }, { translate = [-0.7, 0.0, 0.0] }]

[[shapes]]
type = "sphere"
center = [0.8, 0.5, 0.3]
radius = 0.5
material = "dense"

[[shapes]]
type = "sphere"
center = [0.1, 0.3, 1.2]
radius = 0.3
material = "white"

[[shapes]]
type = "sphere"
center = [-1.1, 0.45, 1.5]
radius = 0.45
material = "gold"

[[shapes]]
type = "rectangle"
material = "floor"
transform = [{ scale = 4.0 }, { rotate = { axis = [1, 0, 0], angle = -90 } }]

[[shapes]]
type = "rectangle"
emission = [6.0, 5.0, 4.0]
transform = [{ scale = 0.6 }, { rotate = { axis = [1, 0, 0], angle = 90 } }, { translate = [-1.0, 3.0, 1.0] }]

[[shapes]]
type = "sphere"
center = [1.5, 2.0, -1.0]
radius = 0.3
emission = [3.0, 3.0, 3.0]

[[lights]]
type = "point"
position = [0.5, 2.5, 2.0]
intensity = 4.0

[environment]
type = "constant"
radiance = [0.2, 0.25, 0.3]
"#;

    fn scene(sampler: &str) -> Scene {
        let text = SCENE.replace("SAMPLER", sampler);
        let file = std::path::Path::new("lanes.toml");
        Scene::parse(
            &text,
            file,
            std::path::Path::new("."),
            &Overrides::default(),
        )
        .unwrap()
    }

    fn ray_bits(r: &Ray) -> [u32; 7] {
        let [a, b, c] = r.o.to_array().map(f32::to_bits);
        let [d, e, f] = r.d.to_array().map(f32::to_bits);
        [a, b, c, d, e, f, r.t_max.to_bits()]
    }

    /// Everything of a path a vertex changes, as bits.
    fn path_bits(p: &Path) -> Vec<u32> {
        let mut v = ray_bits(&p.ray).to_vec();
        v.extend(p.l.to_array().map(f32::to_bits));
        v.extend(p.state.beta.to_array().map(f32::to_bits));
        v.extend([
            p.state.eta_scale.to_bits(),
            p.state.specular as u32,
            p.state.prev_pdf.to_bits(),
            p.depth,
            p.origin_depth.to_bits(),
        ]);
        v
    }

    fn shadow_bits(s: &Option<ShadowTest>) -> Option<([u32; 7], [u32; 3])> {
        s.as_ref()
            .map(|s| (ray_bits(&s.ray), s.radiance.to_array().map(f32::to_bits)))
    }

    /// Each vertex the lanes take, run in lane `i` (every lane in turn, the others holding the
    /// vertices before it), gives `land`'s path, shadow test, ray count and ending bit for bit,
    /// over whole paths of every pixel: both samplers, with and without differentials.
    #[test]
    fn lane_vertex_equals_land() {
        for sampler in ["sobol", "independent"] {
            let scene = scene(sampler);
            let (mut taken, mut glass, mut mirror, mut shadowed, mut ended) = (0, 0, 0, 0, 0);
            let mut lanes = Lanes::new();
            let mut lane = 0;
            for y in 0..16 {
                for x in 0..24 {
                    let index = y as u64 * 24 + x as u64;
                    for s in 0..4 {
                        let camera = camera_sample::<false>(&scene, (x, y), index, s);
                        let (mut a, mut b) = (Path::new(camera.clone()), Path::new(camera));
                        let (mut wa, mut wb) = (Worker::default(), Worker::default());
                        loop {
                            let hit = scene.geometry.intersect(&a.ray);
                            let kind = hit
                                .as_ref()
                                .and_then(|h| takes(&scene, h, a.depth, a.ray.d));
                            let la = a.land::<false, true>(&scene, hit, &mut wa);
                            let (goes_on, shadow) = if let Some(kind) = kind {
                                let hit: SurfaceHit = hit.unwrap();
                                lanes.gather(lane, &scene, &mut b, &hit, kind);
                                lanes.run();
                                let mut shadow = None;
                                let goes_on = lanes.scatter::<false>(
                                    lane,
                                    &scene,
                                    &mut b,
                                    &hit,
                                    &mut wb,
                                    &mut shadow,
                                );
                                taken += 1;
                                glass += (kind == Kind::Glass) as u32;
                                mirror += (kind == Kind::Mirror) as u32;
                                lane = (lane + 1) % LANES;
                                (goes_on, shadow)
                            } else {
                                let lb = b.land::<false, true>(&scene, hit, &mut wb);
                                (lb.goes_on, lb.shadow)
                            };
                            assert_eq!(la.goes_on, goes_on, "pixel ({x}, {y}) sample {s}");
                            assert_eq!(shadow_bits(&la.shadow), shadow_bits(&shadow));
                            assert_eq!(wa.rays, wb.rays);
                            shadowed += shadow.is_some() as u32;
                            if !goes_on {
                                ended += kind.is_some() as u32;
                                break;
                            }
                            assert_eq!(path_bits(&a), path_bits(&b), "pixel ({x}, {y}) sample {s}");
                        }
                    }
                }
            }
            // Every kind of vertex, light samples, and paths ended by roulette or absorption.
            let diffuse = taken - glass - mirror;
            assert!(
                diffuse > 200 && glass > 200 && mirror > 50,
                "{diffuse} {glass} {mirror}"
            );
            assert!(shadowed > 200 && ended > 50, "{shadowed} {ended}");
        }
    }
}
