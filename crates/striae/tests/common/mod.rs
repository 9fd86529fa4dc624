//! Helpers shared by the scene tests.

use std::path::Path;
use striae::film::Image;
use striae::integrator::{render, RenderStats};
use striae::scene::{Overrides, Scene};

/// A scene from TOML text (named `test.toml`, relative paths from the working folder); panics
/// with the loader's message if it does not parse.
pub fn scene(text: &str) -> Scene {
    Scene::parse(
        text,
        Path::new("test.toml"),
        Path::new("."),
        &Overrides::default(),
    )
    .unwrap_or_else(|e| panic!("{e}"))
}

/// Render `scene` in a rayon pool of exactly `threads` workers.
pub fn render_with_threads(scene: &Scene, threads: usize) -> (Image, RenderStats) {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(|| render(scene, &|_| {}))
}
