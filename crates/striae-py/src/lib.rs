//! `striae._striae`: the Python bindings of the `striae` library, a thin layer that converts
//! arguments and numpy arrays and calls the library; the Python package `striae`
//! (`python/striae`) wraps it. Errors become Python exceptions carrying the library's message
//! (the CLI prints the same one).

use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray2};
use pyo3::exceptions::{PyKeyboardInterrupt, PyMemoryError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;
use striae::layers::{LayerParams, LayerSet as Layers};
use striae::math::{DVec3, Rgb, Vec2, Vec3};
use striae::precompute::table::{ScratchBrdf, ScratchTable, TableParams};
use striae::precompute::trace2d::{TraceSettings, THETA_SLICES};
use striae::render::integrator::{self, Simd};
use striae::render::parts::{Part, PartError};
use striae::render::scene::{Overrides, Scene};

pyo3::create_exception!(_striae, StriaeError, pyo3::exceptions::PyException);

/// A library error as a Python exception with its message (and its causes', as the CLI's).
fn err(e: impl std::error::Error) -> PyErr {
    let mut message = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        message = format!("{message}: {s}");
        source = s.source();
    }
    StriaeError::new_err(message)
}

/// A job or an allocation that does not fit in the memory left (a refused estimate, or an
/// allocation the allocator refused) as Python's `MemoryError`, with the library's message
/// (which names the limit that binds: MemAvailable, ulimit -v or -d, a cgroup's limit).
fn memory_err(e: striae::memory::MemoryError) -> PyErr {
    PyMemoryError::new_err(e.to_string())
}

/// A rayon pool of `threads` workers (all cores when `None`).
fn pool(threads: Option<usize>) -> PyResult<rayon::ThreadPool> {
    if threads == Some(0) {
        return Err(PyValueError::new_err("threads must be at least 1"));
    }
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads.unwrap_or(0))
        .build()
        .map_err(err)
}

/// Run `work` (given a cancel flag and a counter of finished work) on a helper thread while
/// this thread, detached from the interpreter, wakes every 50 ms to pass the counter's new
/// work to `progress` and to check for signals: Ctrl-C (`KeyboardInterrupt`) sets the flag,
/// waits for the work to stop and raises.
fn run_interruptibly<T: Send>(
    py: Python<'_>,
    progress: Option<&Bound<'_, PyAny>>,
    work: impl FnOnce(&AtomicBool, &AtomicU64) -> T + Send,
) -> PyResult<T> {
    let cancel = AtomicBool::new(false);
    let done = AtomicU64::new(0);
    std::thread::scope(|s| {
        let handle = s.spawn(|| work(&cancel, &done));
        let mut reported = 0;
        let mut interrupted = None;
        loop {
            let finished = handle.is_finished();
            let now = done.load(Ordering::Relaxed);
            if let (Some(callback), true) = (progress, now > reported) {
                if let Err(e) = callback.call1((now - reported,)) {
                    interrupted.get_or_insert(e);
                }
                reported = now;
            }
            if let Err(e) = py.check_signals() {
                interrupted.get_or_insert(e);
            }
            if finished || interrupted.is_some() {
                break;
            }
            py.detach(|| std::thread::sleep(Duration::from_millis(50)));
        }
        cancel.store(interrupted.is_some(), Ordering::Relaxed);
        let out = py.detach(|| handle.join());
        match (interrupted, out) {
            (Some(e), _) => Err(e),
            (None, Ok(out)) => Ok(out),
            (None, Err(_)) => Err(StriaeError::new_err("the render thread panicked")),
        }
    })
}

/// Load a scene: `kind` is `"path"` (a scene file), `"toml"` (scene text) or `"json"` (the
/// keys of a scene file as JSON, from a Python dict). Returns the scene and the text that
/// names its render (`parts::RenderId`).
fn load_scene(kind: &str, source: &str, overrides: &Overrides) -> PyResult<(Scene, String)> {
    let parse = |text: String, name: &str| {
        Scene::parse(&text, Path::new(name), Path::new("."), overrides)
            .map(|scene| (scene, text))
            .map_err(err)
    };
    match kind {
        "path" => Scene::load_with_text(Path::new(source), overrides).map_err(err),
        "toml" => parse(source.to_string(), "<scene text>"),
        "json" => {
            let value: serde_json::Value = serde_json::from_str(source).map_err(err)?;
            let text = toml::to_string(&value)
                .map_err(|e| StriaeError::new_err(format!("scene dict: {e}")))?;
            parse(text, "<scene dict>")
        }
        _ => Err(PyValueError::new_err(format!(
            "unknown scene kind {kind:?}"
        ))),
    }
}

/// An image as an `(h, w, 3)` float32 array.
fn image_array<'py>(
    py: Python<'py>,
    image: &striae::render::film::Image,
) -> PyResult<Bound<'py, PyArray3<f32>>> {
    let (w, h) = (image.width as usize, image.height as usize);
    let mut flat =
        striae::memory::try_with_capacity(3 * w * h, "the image's array").map_err(memory_err)?;
    flat.extend(image.pixels.iter().flat_map(|p| [p.x, p.y, p.z]));
    Ok(Array3::from_shape_vec((h, w, 3), flat)
        .expect("w * h * 3 values")
        .into_pyarray(py))
}

/// A scene and the overrides of `render`'s arguments, as loaded by [`load_scene`].
#[allow(clippy::too_many_arguments)]
fn scene_with(
    kind: &str,
    source: &str,
    spp: Option<u32>,
    res: Option<(u32, u32)>,
    seed: Option<u64>,
    max_depth: Option<u32>,
    sampler: Option<&str>,
) -> PyResult<(Scene, String)> {
    let sampler = sampler
        .map(|s| {
            striae::render::sampler::SamplerKind::from_name(s).ok_or_else(|| {
                PyValueError::new_err(format!(
                    "sampler {s:?} is not {}",
                    striae::render::sampler::SamplerKind::allowed_names()
                ))
            })
        })
        .transpose()?;
    if spp.is_some_and(|s| s == 0 || s > striae::render::sampler::MAX_SPP) {
        return Err(PyValueError::new_err(format!(
            "spp must lie in 1..={}",
            striae::render::sampler::MAX_SPP
        )));
    }
    let overrides = Overrides {
        spp,
        resolution: res,
        seed,
        max_depth,
        sampler,
        lanes: None,
    };
    load_scene(kind, source, &overrides)
}

/// Render a scene (or part `tile = (index, count)` of it, of the samples `samples = (A, B)`
/// only where given, returned as part-file bytes).
#[pyfunction]
#[pyo3(signature = (kind, source, spp=None, res=None, seed=None, threads=None, max_depth=None, sampler=None, progress=None, tile=None, samples=None))]
#[allow(clippy::too_many_arguments)]
fn render<'py>(
    py: Python<'py>,
    kind: &str,
    source: &str,
    spp: Option<u32>,
    res: Option<(u32, u32)>,
    seed: Option<u64>,
    threads: Option<usize>,
    max_depth: Option<u32>,
    sampler: Option<&str>,
    progress: Option<Bound<'py, PyAny>>,
    tile: Option<(u32, u32)>,
    samples: Option<(u32, u32)>,
) -> PyResult<Bound<'py, PyAny>> {
    let (scene, text) = scene_with(kind, source, spp, res, seed, max_depth, sampler)?;
    let pool = pool(threads)?;
    let (w, h) = scene.camera.resolution();
    let size = match res {
        Some(_) => format!("res=({w}, {h})"),
        None => format!("the scene's render.width x render.height, {w}x{h} (res=)"),
    };
    if let Some(tile) = tile {
        let n = striae::render::parts::part_pixel_count((w, h), tile.0, tile.1).map_err(err)?;
        integrator::check_memory(&scene, n as u64, &size, None).map_err(memory_err)?;
        let part = run_interruptibly(py, progress.as_ref(), |cancel, done| {
            let count = |n| {
                done.fetch_add(n, Ordering::Relaxed);
            };
            let samples = samples.map(|(a, b)| [a, b]);
            pool.install(|| Part::render(&scene, &text, tile, samples, &count, cancel))
        })?
        .map_err(err)?
        .0;
        return Ok(PyBytes::new(py, &part.to_bytes()).into_any());
    }
    integrator::check_memory(&scene, w as u64 * h as u64, &size, None).map_err(memory_err)?;
    // Allocated before the first sample: a film the allocator refuses fails at once.
    let mut image = striae::render::film::Image::try_new(w, h, &size).map_err(memory_err)?;
    let tiles: Vec<u32> = (0..integrator::tile_count(w, h)).collect();
    let pixels = run_interruptibly(py, progress.as_ref(), |cancel, done| {
        let count = |n| {
            done.fetch_add(n, Ordering::Relaxed);
        };
        pool.install(|| integrator::render_tiles(&scene, &tiles, &count, cancel, Simd::Auto))
    })?
    .map_err(|_| PyKeyboardInterrupt::new_err("render cancelled"))?
    .0;
    for (&t, px) in tiles.iter().zip(&pixels) {
        integrator::place_tile(&mut image, t, px);
    }
    drop(pixels);
    Ok(image_array(py, &image)?.into_any())
}

/// The image of parts (`render(..., tile=...)` or `striae render --tile`), each given as a
/// part file's contents or, where `None`, as the part file named by `names`, read as the CLI
/// reads it (a regular file, its size checked against its header before its pixels are read);
/// each named in errors by `names`. With the preview exposure they carry.
#[pyfunction]
fn merge<'py>(
    py: Python<'py>,
    parts: Vec<Option<Vec<u8>>>,
    names: Vec<String>,
) -> PyResult<(Bound<'py, PyArray3<f32>>, f32)> {
    let parts = parts
        .iter()
        .zip(names)
        .map(|(bytes, name)| {
            let name = PathBuf::from(name);
            let part = match bytes {
                Some(bytes) => Part::from_bytes(bytes, &name)?,
                None => Part::read(&name)?,
            };
            Ok((name, part))
        })
        .collect::<Result<Vec<_>, PartError>>()
        .map_err(err)?;
    let (w, h) = parts.first().map_or((0, 0), |(_, p)| {
        (p.header.render.width, p.header.render.height)
    });
    striae::memory::check(
        &format!("merging {} parts into a {w}x{h} image", parts.len()),
        striae::render::parts::merge_memory_estimate(&parts),
        None,
    )
    .map_err(memory_err)?;
    let (image, exposure) = striae::render::parts::merge(&parts).map_err(|e| match e {
        PartError::Memory(e) => memory_err(e),
        e => err(e),
    })?;
    Ok((image_array(py, &image)?, exposure))
}

/// Write an `(h, w, 3)` float32 image as `NAME.exr` and `NAME.png` (atomically), as the CLI.
#[pyfunction]
fn write_image(image: numpy::PyReadonlyArray3<f32>, path: PathBuf, exposure: f32) -> PyResult<()> {
    let a = image.as_array();
    let (h, w, c) = a.dim();
    if c != 3 {
        return Err(PyValueError::new_err("the image must have shape (h, w, 3)"));
    }
    let mut img = striae::render::film::Image::new(w as u32, h as u32);
    for (i, p) in img.pixels.iter_mut().enumerate() {
        *p = Rgb::new(
            a[(i / w, i % w, 0)],
            a[(i / w, i % w, 1)],
            a[(i / w, i % w, 2)],
        );
    }
    let with = |ext: &str| {
        let mut p = path.clone().into_os_string();
        p.push(ext);
        PathBuf::from(p)
    };
    let (exr, png) = (with(".exr"), with(".png"));
    img.write_exr_and_png(&exr, &png, exposure).map_err(err)
}

/// The linear RGB pixels of an EXR file as an `(h, w, 3)` float32 array.
#[pyfunction]
fn read_exr<'py>(py: Python<'py>, path: PathBuf) -> PyResult<Bound<'py, PyArray3<f32>>> {
    use exr::prelude::{read_first_rgba_layer_from_file, Vec2 as Size};
    let image = read_first_rgba_layer_from_file(
        &path,
        |size: Size<usize>, _| striae::render::film::Image::new(size.0 as u32, size.1 as u32),
        |image: &mut striae::render::film::Image,
         pos: Size<usize>,
         (r, g, b, _): (f32, f32, f32, f32)| {
            image.pixels[pos.1 * image.width as usize + pos.0] = Rgb::new(r, g, b);
        },
    )
    .map_err(|e| StriaeError::new_err(format!("cannot read {}: {e}", path.display())))?;
    image_array(py, &image.layer_data.channel_data.pixels)
}

/// `(N, 3)` float64 rows as `Vec3`s (the renderer's f32), named `what` in errors.
fn vectors(a: &PyReadonlyArray2<f64>, what: &str) -> PyResult<Vec<Vec3>> {
    let a = a.as_array();
    if a.ncols() != 3 {
        return Err(PyValueError::new_err(format!(
            "{what} must have shape (N, 3), not {:?}",
            a.shape()
        )));
    }
    Ok(a.rows()
        .into_iter()
        .map(|r| Vec3::new(r[0] as f32, r[1] as f32, r[2] as f32))
        .collect())
}

/// A float64 vector handed to Python.
type Array1Py<'py> = Bound<'py, PyArray1<f64>>;

/// [`Table::sample`]'s arrays: `wi`, `weight`, `pdf`, `valid`.
type Samples<'py> = (
    Bound<'py, PyArray2<f64>>,
    Array1Py<'py>,
    Array1Py<'py>,
    Bound<'py, PyArray1<bool>>,
);

/// A scratch BRDF table and its lobe (`ScratchBrdf`, METHOD.md sections 3-4 and 6).
#[pyclass(module = "striae._striae", frozen)]
struct Table {
    brdf: ScratchBrdf,
}

#[pymethods]
impl Table {
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Table> {
        let table = ScratchTable::load(&path).map_err(err)?;
        Ok(Table {
            brdf: ScratchBrdf::new(table),
        })
    }

    fn save(&self, path: PathBuf) -> PyResult<()> {
        self.brdf.table().save(&path).map_err(err)
    }

    #[getter]
    fn m(&self) -> usize {
        self.brdf.table().m
    }

    #[getter]
    fn phi<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.brdf.table().phi)
    }

    #[getter]
    fn theta<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &THETA_SLICES)
    }

    #[getter]
    fn rho_m<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        self.brdf.table().rho_m_array().into_pyarray(py)
    }

    #[getter]
    fn rho_s<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray3<f64>> {
        self.brdf.table().rho_s_array().into_pyarray(py)
    }

    #[getter]
    fn gamma<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let t = self.brdf.table();
        Array2::from_shape_vec((t.m, t.m), t.gamma.clone())
            .expect("M x M")
            .into_pyarray(py)
    }

    #[getter]
    fn dropped<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        PyArray1::from_slice(py, &self.brdf.table().dropped)
    }

    #[getter]
    fn params_json(&self) -> String {
        self.brdf.table().params.to_json().to_string()
    }

    #[getter]
    fn version(&self) -> String {
        self.brdf.table().version.clone()
    }

    #[getter]
    fn is_delta(&self) -> bool {
        self.brdf.is_delta()
    }

    /// `(f, pdf)` per row of `wo`, `wi`.
    fn eval<'py>(
        &self,
        py: Python<'py>,
        wo: PyReadonlyArray2<f64>,
        wi: PyReadonlyArray2<f64>,
    ) -> PyResult<(Array1Py<'py>, Array1Py<'py>)> {
        let (wo, wi) = (vectors(&wo, "wo")?, vectors(&wi, "wi")?);
        if wo.len() != wi.len() {
            return Err(PyValueError::new_err("wo and wi must have the same length"));
        }
        let (f, pdf): (Vec<f64>, Vec<f64>) = py.detach(|| {
            wo.iter()
                .zip(&wi)
                .map(|(&o, &i)| self.brdf.eval_pdf(o, i))
                .unzip()
        });
        Ok((f.into_pyarray(py), pdf.into_pyarray(py)))
    }

    /// `(wi, weight, pdf, valid)` per row of `wo` and `u` (`(N, 2)`).
    fn sample<'py>(
        &self,
        py: Python<'py>,
        wo: PyReadonlyArray2<f64>,
        u: PyReadonlyArray2<f64>,
    ) -> PyResult<Samples<'py>> {
        let wo = vectors(&wo, "wo")?;
        let u = u.as_array();
        if u.ncols() != 2 || u.nrows() != wo.len() {
            return Err(PyValueError::new_err(
                "u must have shape (N, 2), N rows as wo",
            ));
        }
        let n = wo.len();
        let (mut wi, mut weight) = (Array2::zeros((n, 3)), Array1::zeros(n));
        let (mut pdf, mut valid) = (Array1::zeros(n), Array1::from_elem(n, false));
        for (k, &o) in wo.iter().enumerate() {
            if let Some(s) = self.brdf.sample(o, [u[(k, 0)], u[(k, 1)]]) {
                for c in 0..3 {
                    wi[(k, c)] = s.wi[c] as f64;
                }
                (weight[k], pdf[k], valid[k]) = (s.weight, s.pdf, true);
            }
        }
        Ok((
            wi.into_pyarray(py),
            weight.into_pyarray(py),
            pdf.into_pyarray(py),
            valid.into_pyarray(py),
        ))
    }
}

/// The value of a setting named `v` (its serde name, as in a table's parameters).
fn named<T: serde::de::DeserializeOwned>(what: &str, v: &str) -> PyResult<T> {
    serde_json::from_value(serde_json::Value::String(v.into()))
        .map_err(|_| PyValueError::new_err(format!("{what} {v:?} is not a known value")))
}

/// Trace a scratch profile into a table (`striae precompute`).
#[pyfunction]
#[pyo3(signature = (profile, walls, m, n, nr, ior, fresnel, fresnel_law, albedo, max_bounces, seed, estimator, groove_slices=0, threads=None))]
#[allow(clippy::too_many_arguments)]
fn precompute(
    py: Python<'_>,
    profile: &str,
    walls: &str,
    m: usize,
    n: usize,
    nr: usize,
    ior: f64,
    fresnel: &str,
    fresnel_law: &str,
    albedo: f64,
    max_bounces: usize,
    seed: u64,
    estimator: &str,
    groove_slices: usize,
    threads: Option<usize>,
) -> PyResult<Table> {
    let profile = striae::precompute::profile::Profile::parse(profile).map_err(err)?;
    let trace = TraceSettings {
        walls: named("walls", walls)?,
        m,
        n,
        nr,
        albedo,
        max_bounces,
        seed,
        fresnel_mode: named("fresnel", fresnel)?,
        fresnel_law: striae::optics::fresnel::FresnelLaw::parse(fresnel_law, ior)
            .map_err(|e| PyValueError::new_err(format!("fresnel_law: {e}")))?,
        estimator: named("estimator", estimator)?,
        groove_slices,
    };
    trace.validate().map_err(err)?;
    // `striae precompute --m`'s figures: 80 bytes per M^2, and the groove slices' arrays.
    let m2 = (m as u64).saturating_mul(m as u64);
    let slices = match groove_slices {
        0 => 0,
        s => (16 * s as u64 + 16 * 64).saturating_mul(m2),
    };
    striae::memory::check(&format!("m={m}"), (80 * m2).saturating_add(slices), None)
        .map_err(memory_err)?;
    let params = TableParams::new(profile, trace);
    let pool = pool(threads)?;
    let table = run_interruptibly(py, None, |_, _| {
        pool.install(|| ScratchTable::compute(&params, &|_| {}))
    })?
    .map_err(err)?;
    Ok(Table {
        brdf: ScratchBrdf::new(table),
    })
}

/// Scratch layers from Worley noise (METHOD.md section 5).
#[pyclass(module = "striae._striae", frozen)]
struct LayerSet {
    set: Layers,
}

#[pymethods]
impl LayerSet {
    #[new]
    #[pyo3(signature = (setting=None, layers=8, seed=1, length=None, width=None, threshold=None))]
    fn new(
        setting: Option<u32>,
        layers: usize,
        seed: u64,
        length: Option<f64>,
        width: Option<f64>,
        threshold: Option<f64>,
    ) -> PyResult<LayerSet> {
        let mut params = match (setting, length, width, threshold) {
            (Some(s), None, None, None) => LayerParams::setting(s).map_err(err)?,
            (None, Some(length), Some(width), Some(threshold)) => LayerParams {
                length,
                width,
                threshold,
                layers,
            },
            (None, None, None, None) => LayerParams::setting(1).map_err(err)?,
            _ => {
                return Err(PyValueError::new_err(
                    "give either setting or all of length, width and threshold",
                ))
            }
        };
        params.layers = layers;
        Ok(LayerSet {
            set: Layers::new(params, seed).map_err(err)?,
        })
    }

    fn __len__(&self) -> usize {
        self.set.len()
    }

    /// `(K, 2)` unit scratch directions in texture space.
    #[getter]
    fn directions<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let k = self.set.len();
        let flat = (0..k).flat_map(|i| self.set.direction(i)).collect();
        Array2::from_shape_vec((k, 2), flat)
            .expect("K x 2")
            .into_pyarray(py)
    }

    /// `(K,)` angles in radians, counter-clockwise from `+u`.
    #[getter]
    fn angles<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<f64>> {
        let a: Vec<f64> = self.set.layers().iter().map(|l| l.angle()).collect();
        a.into_pyarray(py)
    }

    #[getter]
    fn expected_coverage(&self) -> f64 {
        self.set.expected_coverage()
    }

    /// `(K, R, R)` float32 coverage masks (`striae layers`' images; row 0 at the top).
    fn masks<'py>(&self, py: Python<'py>, res: usize) -> PyResult<Bound<'py, PyArray3<f32>>> {
        use striae::layers::{raster, LayerError};
        raster::check_resolution(res).map_err(err)?;
        let k = self.set.len();
        let what = format!("res={res} ({k} layers)");
        striae::memory::check(&what, raster::masks_bytes(res, k), None).map_err(memory_err)?;
        let flat = py.detach(|| {
            let mut flat = striae::memory::try_with_capacity(k * res * res, &what)?;
            for i in 0..k {
                flat.extend_from_slice(self.set.rasterize(i, res)?.level(0).1);
            }
            Ok::<_, LayerError>(flat)
        });
        let flat = flat.map_err(|e| match e {
            LayerError::Memory(e) => memory_err(e),
            e => err(e),
        })?;
        Ok(Array3::from_shape_vec((k, res, res), flat)
            .expect("K x R x R")
            .into_pyarray(py))
    }

    /// `(N, K)` float32 coverage of each footprint `uv + s duvdx + t duvdy`, `s, t` in
    /// `[-1/2, 1/2]` (`(N, 2)` arrays), per layer.
    fn coverage<'py>(
        &self,
        py: Python<'py>,
        uv: PyReadonlyArray2<f64>,
        duvdx: PyReadonlyArray2<f64>,
        duvdy: PyReadonlyArray2<f64>,
    ) -> PyResult<Bound<'py, PyArray2<f32>>> {
        let rows = |a: &PyReadonlyArray2<f64>, what: &str| -> PyResult<Vec<Vec2>> {
            let a = a.as_array();
            if a.ncols() != 2 {
                return Err(PyValueError::new_err(format!(
                    "{what} must have shape (N, 2)"
                )));
            }
            Ok(a.rows()
                .into_iter()
                .map(|r| Vec2::new(r[0] as f32, r[1] as f32))
                .collect())
        };
        let (uv, dx, dy) = (
            rows(&uv, "uv")?,
            rows(&duvdx, "duvdx")?,
            rows(&duvdy, "duvdy")?,
        );
        if uv.len() != dx.len() || uv.len() != dy.len() {
            return Err(PyValueError::new_err(
                "uv, duvdx and duvdy must have the same length",
            ));
        }
        let k = self.set.len();
        let mut out = Array2::<f32>::zeros((uv.len(), k));
        for (i, mut row) in out.rows_mut().into_iter().enumerate() {
            let row = row.as_slice_mut().expect("contiguous");
            self.set.coverage_all(uv[i], dx[i], dy[i], row);
        }
        Ok(out.into_pyarray(py))
    }
}

/// The arcs of a scratch hologram for the points `(N, 3)` (`striae::lab::hologram`, METHOD.md
/// 9.4): a dict with the SVG text (`svg`), the arcs as arrays (`centres` `(N, 2)`, `radii`,
/// `start`, `end` in radians from `+x` toward `+y`, `z`), the drawing's `plate`
/// `(x0, y0, size_x, size_y)`, the stroke `width`, the `scale` and the count of arcs reaching
/// `outside` a given plate. `view_angle` (degrees, default 45) and `scale` exclude each other.
#[pyfunction]
#[pyo3(signature = (points, plate=None, view_angle=None, scale=None, span=striae::lab::hologram::DEFAULT_SPAN, azimuth=striae::lab::hologram::DEFAULT_AZIMUTH, width=None))]
#[allow(clippy::too_many_arguments)]
fn hologram<'py>(
    py: Python<'py>,
    points: PyReadonlyArray2<f64>,
    plate: Option<Vec<f64>>,
    view_angle: Option<f64>,
    scale: Option<f64>,
    span: f64,
    azimuth: f64,
    width: Option<f64>,
) -> PyResult<Bound<'py, PyDict>> {
    use striae::lab::hologram::{self as holo, HologramParams, Plate};
    let a = points.as_array();
    if a.ncols() != 3 {
        return Err(PyValueError::new_err(format!(
            "points must have shape (N, 3), not {:?}",
            a.shape()
        )));
    }
    if view_angle.is_some() && scale.is_some() {
        return Err(PyValueError::new_err("give view_angle or scale, not both"));
    }
    let plate = match plate.as_deref() {
        None => None,
        Some(&[x0, y0, size_x, size_y]) => Some(Plate {
            x0,
            y0,
            size_x,
            size_y,
        }),
        Some(p) => {
            return Err(PyValueError::new_err(format!(
                "plate must be (x0, y0, size_x, size_y), not {} numbers",
                p.len()
            )))
        }
    };
    let params = HologramParams {
        plate,
        view_angle: view_angle.unwrap_or(holo::DEFAULT_VIEW_ANGLE),
        scale,
        span,
        azimuth,
        width,
    };
    let pts: Vec<DVec3> = a
        .rows()
        .into_iter()
        .map(|r| DVec3::new(r[0], r[1], r[2]))
        .collect();
    let (h, svg) = py
        .detach(|| {
            holo::hologram(&pts, &params).map(|h| {
                let svg = h.to_svg();
                (h, svg)
            })
        })
        .map_err(err)?;
    let n = h.arcs.len();
    let mut centres = Array2::<f64>::zeros((n, 2));
    for (mut row, arc) in centres.rows_mut().into_iter().zip(&h.arcs) {
        row[0] = arc.centre.x;
        row[1] = arc.centre.y;
    }
    let column =
        |f: fn(&holo::HologramArc) -> f64| -> Array1<f64> { h.arcs.iter().map(f).collect() };
    let out = PyDict::new(py);
    out.set_item("svg", svg)?;
    out.set_item("centres", centres.into_pyarray(py))?;
    out.set_item("radii", column(|a| a.radius).into_pyarray(py))?;
    out.set_item("start", column(|a| a.start).into_pyarray(py))?;
    out.set_item("end", column(|a| a.end).into_pyarray(py))?;
    out.set_item("z", column(|a| a.z).into_pyarray(py))?;
    let p = h.plate;
    out.set_item("plate", (p.x0, p.y0, p.size_x, p.size_y))?;
    out.set_item("width", h.width)?;
    out.set_item("scale", h.scale)?;
    out.set_item("outside", h.outside)?;
    Ok(out)
}

#[pymodule]
fn _striae(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("StriaeError", m.py().get_type::<StriaeError>())?;
    m.add("VERSION", striae::VERSION)?;
    m.add_class::<Table>()?;
    m.add_class::<LayerSet>()?;
    m.add_function(wrap_pyfunction!(precompute, m)?)?;
    m.add_function(wrap_pyfunction!(render, m)?)?;
    m.add_function(wrap_pyfunction!(merge, m)?)?;
    m.add_function(wrap_pyfunction!(write_image, m)?)?;
    m.add_function(wrap_pyfunction!(read_exr, m)?)?;
    m.add_function(wrap_pyfunction!(hologram, m)?)?;
    Ok(())
}
