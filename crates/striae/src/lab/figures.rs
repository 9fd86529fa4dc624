//! The seed's figures, regenerated (`docs/METHOD.md` section 7): Fig. 2 (the polar
//! lobe of the averaged 2D scratch BRDF for one incident angle), Fig. 4 (a, b, c: cell noise,
//! after rotation and stretch, after the threshold), Fig. 6 (setting 1: (a) the scratched glass
//! plate, (b) the scratched glass teapot), Fig. 7 (the same at setting 2) and Fig. 8 (a: a
//! close-up of the setting-1 plate), as PNGs plus an `index.html` that shows them side by side with their
//! parameters and render times. `striae figures -o DIR` is the command.
//!
//! The renders use the shipped scene files (embedded here, so the figures do not depend on the
//! working directory) at the caller's resolution and samples per pixel. Fig. 2 plots the
//! profile the glass scenes use (a 90-degree V groove with diffuse walls) at `phi_i = 30`
//! degrees, traced at the seed's sizes (`M 256, N 10000, N_r 100`; cached after the first run);
//! Fig. 4 shows layer 0 of a setting-2 layer set (setting 1's scratches, 0.0002 wide, are
//! thinner than a texel of a 512-pixel image and would barely show).

use crate::lab::plot::PlotError;
use crate::layers::{raster, LayerError, LayerParams, LayerSet};
use crate::render::film::FilmError;
use crate::render::material::Material;
use crate::render::scene::{Overrides, Scene, SceneError};
use crate::render::scratched::ScratchModel;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// The scenes of Figs. 6-8: `(id, caption, file name, text)`.
pub const FIGURE_SCENES: [(&str, &str, &str, &str); 5] = [
    (
        "fig6a",
        "Fig. 6 (a): glass plate, setting 1",
        "glass-plate-setting1.toml",
        include_str!("../../scenes/glass-plate-setting1.toml"),
    ),
    (
        "fig6b",
        "Fig. 6 (b): glass teapot, setting 1",
        "glass-teapot-setting1.toml",
        include_str!("../../scenes/glass-teapot-setting1.toml"),
    ),
    (
        "fig7a",
        "Fig. 7 (a): glass plate, setting 2",
        "glass-plate-setting2.toml",
        include_str!("../../scenes/glass-plate-setting2.toml"),
    ),
    (
        "fig7b",
        "Fig. 7 (b): glass teapot, setting 2",
        "glass-teapot-setting2.toml",
        include_str!("../../scenes/glass-teapot-setting2.toml"),
    ),
    (
        "fig8a",
        "Fig. 8 (a): close-up of the setting-1 plate",
        "glass-plate-closeup.toml",
        include_str!("../../scenes/glass-plate-closeup.toml"),
    ),
];

/// The "beyond the seed" figures (METHOD.md 8.2, 8.4, 9.1-9.4): `(id, caption, file name,
/// text, what differs)`, each rendered as written (dielectric walls, a direction per scratch,
/// or curves) and under the seed's model ([`seed_variant`]), side by side.
pub const BEYOND_SCENES: [(&str, &str, &str, &str, &str); 6] = [
    (
        "halo-t",
        "Halos in transmission: a small light behind a scratched pane",
        "halo-transmission.toml",
        include_str!("../../scenes/halo-transmission.toml"),
        "Dielectric walls carry light through each scratch along its cone of directions: the lit pieces form arcs around the light seen through the pane. The seed's scratches only reflect: against the light they are invisible.",
    ),
    (
        "halo-r",
        "Halos in reflection: a small light beside the camera",
        "halo-reflection.toml",
        include_str!("../../scenes/halo-reflection.toml"),
        "Smooth glass walls and a direction per scratch: the lit pieces form arcs around the light's mirror image, each perpendicular to the radius. The seed's model (diffuse walls, one direction per layer) spreads each scratch's light over its whole lobe, and its layers' pieces line up along a few directions.",
    ),
    (
        "window",
        "A scratched window against the sky",
        "backlit-window.toml",
        include_str!("../../scenes/backlit-window.toml"),
        "Below the sky's edge, against the dark, the scratches glow with sky light carried through them (dielectric walls); the seed's model transmits nothing at a scratch but the smooth refraction, so they stay dark.",
    ),
    (
        "stripe",
        "The floating stripe: concentric scratches under a small lamp",
        "stripe.toml",
        include_str!("../../scenes/stripe.toml"),
        "Each circle glints where its tangent is perpendicular to l + v projected on the plate: the glints line up on a stripe through the centre. The seed's cell-noise layers (setting 2 in its place) make only straight scratches, which glint where their one direction allows.",
    ),
    (
        "swirl",
        "Polishing swirls around a lamp's reflection",
        "swirl.toml",
        include_str!("../../scenes/swirl.toml"),
        "Random tapered arcs glint on circles around the lamp's reflection. The seed's straight layers (setting 2 in their place) glint along a few lines.",
    ),
    (
        "hologram",
        "A scratch hologram: a wire-frame cube floating off a steel plate",
        "hologram.toml",
        include_str!("../../scenes/hologram.toml"),
        "One arc per point of the cube, each glinting where that point is seen from the eye (`striae hologram`). The seed's layers (setting 2) glint with no shape.",
    ),
];

/// Files the "beyond the seed" scenes read beside them, written next to the figures:
/// `(file name, contents)`.
pub const BEYOND_FILES: [(&str, &str); 1] =
    [("hologram.svg", include_str!("../../scenes/hologram.svg"))];

/// The seed's model of a scene written for dielectric walls: `model = "seed"` in each
/// `[materials.NAME.scratches]` table (the seed's defaults: `layer_mix = "max"`, no
/// exact-groove slices, one Fresnel factor a path), the walls back to the default (`diffuse`,
/// the seed's glass scratches), their `roughness` and `lobes` dropped, one direction per layer,
/// no `lean`; any `model`, `layer_mix`, `fresnel` or `groove_slices` of the scene dropped;
/// curves (`curves`, `pattern`, `polylines` and their stroke keys) replaced by the seed's
/// straight layers of setting 2.
pub fn seed_variant(text: &str) -> String {
    let mut out = Vec::new();
    for l in text.lines() {
        let key = l.trim_start();
        let dropped = [
            "walls = \"dielectric\"",
            "roughness =",
            "lobes =",
            "lean =",
            "model =",
            "layer_mix =",
            "fresnel =",
            "groove_slices =",
            "taper =",
            "dashes =",
            "dash_offset =",
            "depth =",
            "wear =",
            "wear_length =",
        ]
        .iter()
        .any(|k| key.starts_with(k));
        if dropped {
            continue;
        }
        if ["curves =", "pattern =", "polylines ="]
            .iter()
            .any(|k| key.starts_with(k))
        {
            out.push("setting = 2".to_string());
            continue;
        }
        out.push(l.replace("orientation = \"random\"", "orientation = \"layer\""));
        let header = key.trim_end();
        if header.starts_with("[materials.") && header.ends_with(".scratches]") {
            out.push("model = \"seed\"".to_string());
        }
    }
    out.join("\n")
}

/// Incident angle of Fig. 2 (degrees).
pub const FIG2_PHI_I_DEG: f64 = 30.0;

/// The table of Fig. 2: the glass scenes' profile (a 90-degree V groove, diffuse walls) at the
/// seed's sizes `M = 256, N = 10000, N_r = 100` (about 3 s on 2 cores, then cached;
/// the same table as the glass scenes).
pub fn fig2_table_params() -> crate::precompute::table::TableParams {
    let profile = crate::precompute::profile::Profile::parse(
        crate::render::scene::scratches::DEFAULT_PROFILE,
    )
    .expect("valid built-in profile");
    crate::precompute::table::TableParams::new(
        profile,
        crate::precompute::trace2d::TraceSettings::default(),
    )
}

/// What to generate.
#[derive(Clone, Debug)]
pub struct FigureOptions {
    /// Samples per pixel of the renders.
    pub spp: u32,
    /// Render resolution.
    pub resolution: (u32, u32),
    /// Side of the Fig. 4 images.
    pub layer_resolution: usize,
}

impl Default for FigureOptions {
    /// Sized to finish in about 20 s on 2 cores (`BENCHMARKS.md`, "Main jobs").
    fn default() -> Self {
        FigureOptions {
            spp: 32,
            resolution: (384, 288),
            layer_resolution: 512,
        }
    }
}

/// One generated figure.
#[derive(Clone, Debug)]
pub struct Figure {
    pub id: String,
    pub caption: String,
    /// PNG file name inside the output folder.
    pub file: String,
    /// Parameters, one `key: value` per entry.
    pub params: Vec<(String, String)>,
    /// Wall time to make it (render, plot or raster), seconds.
    pub seconds: f64,
}

/// Why the figures could not be made.
#[derive(Debug, thiserror::Error)]
pub enum FigureError {
    #[error(transparent)]
    Scene(#[from] SceneError),
    #[error(transparent)]
    Plot(#[from] PlotError),
    #[error(transparent)]
    Layer(#[from] LayerError),
    #[error(transparent)]
    Film(#[from] FilmError),
    /// (The I/O error is the source: `anyhow`'s chain prints it after the path.)
    #[error("{path}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error(transparent)]
    Table(Box<crate::precompute::table::TableError>),
    #[error("scene {0} has no scratched material")]
    NoScratches(String),
}

fn io(path: &Path) -> impl Fn(std::io::Error) -> FigureError + '_ {
    move |source| FigureError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// The parameters of a scene's scratched material, for the captions.
fn scratch_params(scene: &Scene, name: &str) -> Result<Vec<(String, String)>, FigureError> {
    let m = scene
        .materials
        .iter()
        .find_map(|m| match m {
            Material::Scratched(s) => Some(&**s),
            _ => None,
        })
        .ok_or_else(|| FigureError::NoScratches(name.to_string()))?;
    let l = m.layers.params();
    let mut params = vec![("base".into(), format!("{:?}", m.base))];
    if !m.layers.is_empty() {
        params.push((
            "scratch length L / width W / threshold tau".into(),
            format!("{} / {} / {}", l.length, l.width, l.threshold),
        ));
    }
    if let Some(c) = &m.curves {
        params.push((
            "curves".into(),
            format!("{} curves, {} segments", c.len(), c.segments()),
        ));
    }
    match &m.model {
        ScratchModel::Seed(table) => {
            let t = &table.table().params;
            params.extend([
                (
                    "layers".into(),
                    format!("{} (seed {}, mix {:?})", l.layers, m.layers.seed(), m.mix),
                ),
                ("profile".into(), t.profile.spec.clone()),
                (
                    "table".into(),
                    format!(
                        "{:?} walls, Fresnel {:?} ({:?}), M {} N {} N_r {}",
                        t.trace.walls,
                        t.trace.fresnel_mode,
                        t.trace.fresnel_law,
                        t.trace.m,
                        t.trace.n,
                        t.trace.nr
                    ),
                ),
            ]);
        }
        ScratchModel::DielectricWalls(_) | ScratchModel::SpecularWalls(_) => params.extend([
            (
                "layers".into(),
                format!(
                    "{} (seed {}, mix {:?}, orientation {:?})",
                    l.layers,
                    m.layers.seed(),
                    m.mix,
                    m.layers.orientation()
                ),
            ),
            (
                "table".into(),
                format!(
                    "{} walls (hash {})",
                    match m.model {
                        ScratchModel::SpecularWalls(_) => "rough specular",
                        _ => "dielectric",
                    },
                    &m.model.hash()[..12]
                ),
            ),
        ]),
    }
    Ok(params)
}

/// Generate every figure into `dir` (created if missing) and write `index.html`. `log`
/// receives one line per step.
pub fn generate(
    dir: &Path,
    opts: &FigureOptions,
    log: &dyn Fn(&str),
) -> Result<Vec<Figure>, FigureError> {
    // Every option is checked before the first file is written, and the figures are made in
    // a temporary folder published whole at the end: an error or a signal leaves `dir` as it
    // was.
    crate::layers::raster::check_resolution(opts.layer_resolution)?;
    let overrides = Overrides {
        spp: Some(opts.spp),
        resolution: Some(opts.resolution),
        ..Overrides::default()
    };
    overrides.validate()?;
    if dir.exists() && !dir.is_dir() {
        return Err(FigureError::Io {
            path: dir.to_path_buf(),
            source: std::io::Error::other("exists and is not a folder"),
        });
    }
    if let Some(parent) = dir.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent).map_err(io(parent))?;
    }
    let tmp = crate::io::TempFile::new(dir, "");
    let work = tmp.path();
    std::fs::create_dir(work).map_err(io(work))?;
    let mut figures = vec![lobe_figure(work, log)?];
    figures.extend(layer_figures(work, opts.layer_resolution, log)?);
    figures.extend(render_figures(work, opts, log)?);
    let html = index_html(&figures, opts);
    std::fs::write(work.join("index.html"), html.as_bytes()).map_err(io(work))?;
    crate::io::publish_folder(tmp, dir).map_err(io(dir))?;
    log(&format!(
        "wrote {} figures and index.html to {}",
        figures.len(),
        dir.display()
    ));
    Ok(figures)
}

/// Fig. 2: the lobe of the glass scenes' profile at the seed's table size.
fn lobe_figure(dir: &Path, log: &dyn Fn(&str)) -> Result<Figure, FigureError> {
    let start = Instant::now();
    let params = fig2_table_params();
    let table =
        crate::render::cache::obtain_table(&params).map_err(|e| FigureError::Table(Box::new(e)))?;
    let file = "fig2-lobe.png".to_string();
    crate::lab::plot::plot_lobe(table.table(), FIG2_PHI_I_DEG, &dir.join(&file))?;
    let t = &params.trace;
    let params = vec![
        ("profile".to_string(), params.profile.spec.clone()),
        (
            "table".to_string(),
            format!(
                "{:?} walls, M {} N {} N_r {} (the seed's sizes)",
                t.walls, t.m, t.n, t.nr
            ),
        ),
        (
            "phi_i".to_string(),
            format!("{FIG2_PHI_I_DEG} degrees (the nearest bin centre)"),
        ),
    ];
    let seconds = start.elapsed().as_secs_f64();
    log(&format!("fig2: lobe at phi_i = {FIG2_PHI_I_DEG} deg ({seconds:.2} s, table computed or read from the cache)"));
    Ok(Figure {
        id: "fig2".into(),
        caption: "Fig. 2: the 2D scratch BRDF rho_m(phi_o, phi_i), polar plot".into(),
        file,
        params,
        seconds,
    })
}

/// Fig. 4: the stages of layer 0 of a setting-2 set at `res x res`.
fn layer_figures(dir: &Path, res: usize, log: &dyn Fn(&str)) -> Result<Vec<Figure>, FigureError> {
    let mut figures = Vec::new();
    let lp = LayerParams::setting(2)?;
    let set = LayerSet::new(lp, 1)?;
    let layer = &set.layers()[0];
    let lparams = vec![
        (
            "setting".to_string(),
            format!("2 (L {} W {} tau {})", lp.length, lp.width, lp.threshold),
        ),
        (
            "layer".to_string(),
            format!(
                "0 of seed 1, alpha = {:.1} degrees",
                layer.angle().to_degrees()
            ),
        ),
        ("resolution".to_string(), format!("{res} x {res}")),
    ];
    let stages: [(&str, &str, &str); 3] = [
        (
            "fig4a",
            "Fig. 4 (a): Worley cell noise (1 - F1)",
            "fig4a-noise.png",
        ),
        (
            "fig4b",
            "Fig. 4 (b): rotated by alpha, stretched by (L, W)",
            "fig4b-stretched.png",
        ),
        (
            "fig4c",
            "Fig. 4 (c): thresholded, F1 < tau (scratch coverage)",
            "fig4c-threshold.png",
        ),
    ];
    for (i, (id, caption, file)) in stages.iter().enumerate() {
        let start = Instant::now();
        let png = match i {
            0 => raster::encode_png(
                res,
                &raster::to_u8(&raster::stage_noise(layer, res)?),
                1,
                "Fig. 4 a",
            )?,
            1 => raster::encode_png(
                res,
                &raster::to_u8(&raster::stage_stretched(layer, res)?),
                1,
                "Fig. 4 b",
            )?,
            _ => set.rasterize(0, res)?.to_png()?,
        };
        let path = dir.join(file);
        crate::io::write_atomically(&path, |tmp| std::fs::write(tmp, &png)).map_err(io(&path))?;
        let seconds = start.elapsed().as_secs_f64();
        log(&format!("{id}: {file} ({seconds:.2} s)"));
        figures.push(Figure {
            id: id.to_string(),
            caption: caption.to_string(),
            file: file.to_string(),
            params: lparams.clone(),
            seconds,
        });
    }
    Ok(figures)
}

/// Figs. 6-8: the renders, at the resolution and sample count of `opts`.
fn render_figures(
    dir: &Path,
    opts: &FigureOptions,
    log: &dyn Fn(&str),
) -> Result<Vec<Figure>, FigureError> {
    let overrides = Overrides {
        spp: Some(opts.spp),
        resolution: Some(opts.resolution),
        seed: None,
        max_depth: None,
        sampler: None,
        lanes: None,
    };
    let mut jobs: Vec<(String, String, &str, String)> = FIGURE_SCENES
        .iter()
        .map(|&(id, caption, name, text)| (id.into(), caption.into(), name, text.into()))
        .collect();
    for (id, caption, name, text, differs) in BEYOND_SCENES {
        jobs.push((
            format!("{id}-seed"),
            format!("{caption}: the seed's model"),
            name,
            seed_variant(text),
        ));
        jobs.push((
            id.into(),
            format!("{caption}: as the scene file says. {differs}"),
            name,
            text.into(),
        ));
    }
    for (file, contents) in BEYOND_FILES {
        let path = dir.join(file);
        crate::io::write_atomically(&path, |tmp| std::fs::write(tmp, contents)).map_err(
            |source| FigureError::Io {
                path: path.clone(),
                source,
            },
        )?;
    }
    let mut figures = Vec::new();
    for (id, caption, name, text) in jobs {
        let start = Instant::now();
        let scene = Scene::parse(&text, Path::new(name), dir, &overrides)?;
        let mut params = scratch_params(&scene, name)?;
        let load = start.elapsed().as_secs_f64();
        let (image, stats) = crate::render::integrator::render(&scene, &|_| {});
        let file = format!("{id}.png");
        image.write_png(&dir.join(&file), scene.settings.exposure)?;
        let seconds = start.elapsed().as_secs_f64();
        let s = &scene.settings;
        params.insert(0, ("scene".into(), format!("scenes/{name}")));
        params.push((
            "render".into(),
            format!(
                "{} x {}, {} spp, max depth {}, seed {}",
                s.width, s.height, s.spp, s.max_depth, s.seed
            ),
        ));
        params.push((
            "time".into(),
            format!(
                "{:.2} s render ({:.3} M samples/s, {:.2} M rays/s) + {:.2} s scene and table",
                stats.seconds,
                stats.samples_per_second() / 1e6,
                stats.rays_per_second() / 1e6,
                load
            ),
        ));
        log(&format!(
            "{id}: {name} at {}x{}, {} spp in {seconds:.2} s",
            s.width, s.height, s.spp
        ));
        figures.push(Figure {
            id,
            caption,
            file,
            params,
            seconds,
        });
    }
    Ok(figures)
}

fn escape(s: &str) -> String {
    s.replace('&', "&amp;")
        .replace('<', "&lt;")
        .replace('>', "&gt;")
        .replace('"', "&quot;")
}

/// The page: one row per figure group, images side by side, each with its caption, parameters
/// and time.
pub fn index_html(figures: &[Figure], opts: &FigureOptions) -> String {
    let groups: [(&str, &[&str]); 8] = [
        ("Fig. 2: the scratch BRDF lobe", &["fig2"]),
        (
            "Fig. 4: scratch layer from cell noise",
            &["fig4a", "fig4b", "fig4c"],
        ),
        ("Fig. 6: setting 1 (plate, teapot)", &["fig6a", "fig6b"]),
        ("Fig. 7: setting 2 (plate, teapot)", &["fig7a", "fig7b"]),
        ("Fig. 8: close-up", &["fig8a"]),
        (
            "Beyond the seed: halos in transmission (seed's model, dielectric walls)",
            &["halo-t-seed", "halo-t"],
        ),
        (
            "Beyond the seed: halos in reflection (seed's model, dielectric walls)",
            &["halo-r-seed", "halo-r"],
        ),
        (
            "Beyond the seed: a scratched window against the sky (seed's model, dielectric walls)",
            &["window-seed", "window"],
        ),
    ];
    let total: f64 = figures.iter().map(|f| f.seconds).sum();
    let mut h = String::new();
    h.push_str("<!DOCTYPE html>\n<html lang=\"en\">\n<head>\n<meta charset=\"utf-8\">\n<title>striae: the seed's figures</title>\n<style>\n");
    h.push_str(
        "body { background: #1b1c1f; color: #ddd; font-family: sans-serif; margin: 2em; }\n",
    );
    h.push_str(".row { display: flex; flex-wrap: wrap; gap: 1.5em; margin-bottom: 2em; }\n");
    h.push_str("figure { margin: 0; max-width: 520px; } img { max-width: 100%; border: 1px solid #444; }\n");
    h.push_str("figcaption { font-size: 0.85em; } dt { color: #9ab; } dd { margin: 0 0 0.3em 1em; }\n</style>\n</head>\n<body>\n");
    h.push_str(&format!(
        "<h1>Rendering scratches on transparent objects: the seed's figures</h1>\n<p>Generated by striae {} (<code>striae figures</code>), renders at {} x {}, {} spp; {:.1} s in all. Method: docs/METHOD.md; scratched material: docs/scratched.md.</p>\n",
        crate::VERSION,
        opts.resolution.0,
        opts.resolution.1,
        opts.spp,
        total
    ));
    for (title, ids) in groups {
        h.push_str(&format!(
            "<h2>{}</h2>\n<div class=\"row\">\n",
            escape(title)
        ));
        for id in ids {
            let Some(f) = figures.iter().find(|f| f.id == *id) else {
                continue;
            };
            h.push_str(&format!(
                "<figure><img src=\"{}\" alt=\"{}\"><figcaption><b>{}</b><dl>\n",
                escape(&f.file),
                escape(&f.caption),
                escape(&f.caption)
            ));
            for (k, v) in &f.params {
                h.push_str(&format!("<dt>{}</dt><dd>{}</dd>\n", escape(k), escape(v)));
            }
            h.push_str(&format!(
                "<dt>made in</dt><dd>{:.2} s</dd>\n</dl></figcaption></figure>\n",
                f.seconds
            ));
        }
        h.push_str("</div>\n");
    }
    h.push_str("</body>\n</html>\n");
    h
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn figure_scenes_parse_and_have_scratches() {
        // Every embedded scene is valid and scratched (tables are cached on disk after the
        // first run; the default sizes compute in about a second).
        for (_, _, name, text) in FIGURE_SCENES {
            let o = Overrides {
                spp: Some(1),
                resolution: Some((8, 6)),
                seed: None,
                max_depth: None,
                sampler: None,
                lanes: None,
            };
            let scene = Scene::parse(text, Path::new(name), Path::new("."), &o)
                .unwrap_or_else(|e| panic!("{name}: {e}"));
            let p = scratch_params(&scene, name).unwrap();
            assert!(p.iter().any(|(k, _)| k == "layers"));
        }
    }

    /// Each "beyond the seed" scene goes past the seed (dielectric walls, a direction per
    /// scratch or curves), and its seed variant is the seed's table model with one direction
    /// per layer, no lean and no curves.
    #[test]
    fn beyond_the_seed_scenes_and_their_seed_variants() {
        let o = Overrides {
            spp: Some(1),
            resolution: Some((8, 6)),
            ..Overrides::default()
        };
        let model = |text: &str, name: &str| {
            let scenes = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
            let scene = Scene::parse(text, Path::new(name), &scenes, &o)
                .unwrap_or_else(|e| panic!("{name}: {e}"));
            scratch_params(&scene, name).unwrap();
            scene
                .materials
                .iter()
                .find_map(|m| match m {
                    Material::Scratched(s) => Some((
                        matches!(s.model, ScratchModel::DielectricWalls(_))
                            || s.has_lean()
                            || s.curves.is_some(),
                        s.layers.orientation(),
                        s.mix,
                        match &s.model {
                            ScratchModel::Seed(t) => Some(t.table().params.trace.clone()),
                            _ => None,
                        },
                    )),
                    _ => None,
                })
                .unwrap()
        };
        for (_, _, name, text, _) in BEYOND_SCENES {
            let (walls, orientation, ..) = model(text, name);
            assert!(
                walls || orientation == crate::layers::Orientation::Random,
                "{name}"
            );
            // (`lobes` applies to dielectric walls only, so it goes with them; `lean` is ours.)
            let with_lobes = text.replace(
                "walls = \"dielectric\"",
                "walls = \"dielectric\"\nlobes = \"table\"\nlean = true",
            );
            // (A scene of the new defaults spelt out: the variant is the seed's all the same.)
            let with_defaults = text.replace(
                "walls = \"dielectric\"",
                "walls = \"dielectric\"\nmodel = \"default\"\nlayer_mix = \"union\"",
            );
            for text in [text, &with_lobes[..], &with_defaults[..]] {
                let (walls, orientation, mix, trace) = model(&seed_variant(text), name);
                assert!(
                    !walls && orientation == crate::layers::Orientation::Layer,
                    "{name}"
                );
                // The seed's table (eq. (3), its sizes; on glass one Fresnel factor and
                // diffuse walls, on metal [Raymond16]'s mirror walls) and layer choice.
                let seed = crate::precompute::trace2d::TraceSettings::default();
                let trace = trace.expect("the seed's 2D table");
                assert_eq!(mix, crate::render::scratched::LayerMix::Max, "{name}");
                if text.contains("base = \"metal\"") {
                    assert_eq!(
                        (trace.m, trace.n, trace.nr, trace.groove_slices),
                        (seed.m, seed.n, seed.nr, 0),
                        "{name}"
                    );
                } else {
                    assert_eq!(trace, seed, "{name}");
                }
            }
        }
    }

    #[test]
    fn index_lists_every_figure_with_escaped_text() {
        let figs = vec![
            Figure {
                id: "fig2".into(),
                caption: "a <b>".into(),
                file: "fig2-lobe.png".into(),
                params: vec![("k".into(), "v & w".into())],
                seconds: 1.5,
            },
            Figure {
                id: "fig6a".into(),
                caption: "plate".into(),
                file: "fig6a.png".into(),
                params: vec![],
                seconds: 2.0,
            },
        ];
        let h = index_html(&figs, &FigureOptions::default());
        assert!(h.contains("src=\"fig2-lobe.png\"") && h.contains("src=\"fig6a.png\""));
        assert!(h.contains("a &lt;b&gt;") && h.contains("v &amp; w"));
        assert!(h.contains("3.5 s in all"));
    }
}
