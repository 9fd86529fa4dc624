//! A stand-in until the `bsdf` branch's `envmap` lands (deleted after the merge).

use crate::math::{Rgb, Vec2, Vec3};

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
