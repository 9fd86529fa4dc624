//! Stand-ins until the `bsdf` branch's `Material` and `envmap` land (deleted after the merge).

use crate::bsdf::{Bsdf, Conductor, Dielectric, Diffuse};
use crate::math::{Rgb, Vec2, Vec3};
use serde::Deserialize;

#[derive(Clone, Debug, Deserialize)]
#[serde(tag = "type", rename_all = "lowercase", deny_unknown_fields)]
pub enum Material {
    Diffuse { reflectance: [f32; 3], #[serde(default)] checker: Option<[f32; 3]> },
    Dielectric { ior: f32 },
    Conductor { eta: [f32; 3], k: [f32; 3] },
}

impl Material {
    pub fn bsdf_at(&self, uv: Vec2) -> Bsdf {
        match self {
            Material::Diffuse { reflectance, checker } => {
                let odd = ((uv.x * 10.0).floor() as i32 + (uv.y * 10.0).floor() as i32) & 1 == 1;
                let r = match checker { Some(c) if odd => *c, _ => *reflectance };
                Bsdf::Diffuse(Diffuse::new(Rgb::from_array(r)))
            }
            Material::Dielectric { ior } => Bsdf::Dielectric(Dielectric::new(*ior)),
            Material::Conductor { eta, k } => Bsdf::Conductor(Conductor::new(Rgb::from_array(*eta), Rgb::from_array(*k))),
        }
    }
}

#[derive(Debug)]
pub struct EnvMap;
impl EnvMap {
    pub fn load(path: &std::path::Path, _scale: f32, _t: &crate::geometry::Transform) -> Result<EnvMap, String> {
        Err(format!("environment maps are not available yet ({})", path.display()))
    }
    pub fn eval(&self, _d: Vec3) -> Rgb { Rgb::ZERO }
    pub fn pdf(&self, _d: Vec3) -> f32 { 0.0 }
    pub fn sample(&self, _u: Vec2) -> Option<(Vec3, Rgb, f32)> { None }
}
