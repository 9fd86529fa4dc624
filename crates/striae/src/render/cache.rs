//! Scratch tables shared and cached: in memory by parameter hash ([`TableParams::hash`],
//! [`WallTableParams::hash`]), so each distinct table is computed or loaded once per process
//! however many materials use it, and on disk in [`cache_dir`] as `scratch-table-HASH.npz`
//! (wall tables, dielectric or rough specular: `wall-table-HASH.npz`), written atomically
//! ([`crate::io::write_atomically`], a temporary name unique to the call), so concurrent renders
//! sharing a cache folder never read a half-written file. A cache file that cannot be read, or
//! holds other parameters, is recomputed with a warning ([`crate::log`]); temporary files of
//! processes killed while writing are swept ([`crate::io::sweep_stale_temporaries`]).

use crate::precompute::table::{ScratchTable, TableError, TableParams};
use crate::precompute::wall_table::{WallKind, WallTable, WallTableParams};
use crate::render::bsdf::{GlassWalls, ScratchLobeTable, WallLobeTable};
use crate::render::scratched::ScratchModel;
use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, OnceLock, Weak};

/// The on-disk table cache: `$STRIAE_CACHE`, else `$XDG_CACHE_HOME/striae`, else
/// `~/.cache/striae` (`None` if none can be named).
pub fn cache_dir() -> Option<PathBuf> {
    let var = |k: &str| {
        std::env::var_os(k)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from)
    };
    var("STRIAE_CACHE")
        .or_else(|| var("XDG_CACHE_HOME").map(|d| d.join("striae")))
        .or_else(|| var("HOME").map(|h| h.join(".cache").join("striae")))
}

/// The cache file of a table: `scratch-table-HASH.npz`.
pub fn cache_file(dir: &Path, hash: &str) -> PathBuf {
    dir.join(format!("scratch-table-{hash}.npz"))
}

type Registry<T> = Mutex<HashMap<String, Weak<T>>>;

/// The live table of `hash` in `registry`, or the one `make` gives (then registered). The
/// registry lock is held meanwhile, so two materials needing one table compute it once.
fn shared_in<T>(
    registry: &Registry<T>,
    hash: String,
    make: impl FnOnce() -> Result<T, TableError>,
) -> Result<Arc<T>, TableError> {
    let mut reg = registry.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(t) = reg.get(&hash).and_then(Weak::upgrade) {
        return Ok(t);
    }
    let t = Arc::new(make()?);
    reg.retain(|_, w| w.strong_count() > 0);
    reg.insert(hash, Arc::downgrade(&t));
    Ok(t)
}

/// The live scratch tables of the process by parameter hash.
fn shared(
    hash: String,
    make: impl FnOnce() -> Result<ScratchTable, TableError>,
) -> Result<Arc<ScratchLobeTable>, TableError> {
    static REGISTRY: OnceLock<Registry<ScratchLobeTable>> = OnceLock::new();
    let registry = REGISTRY.get_or_init(|| Mutex::new(HashMap::new()));
    shared_in(registry, hash, || make().map(ScratchLobeTable::new))
}

/// The live wall tables of the process by parameter hash.
fn shared_walls(
    hash: String,
    make: impl FnOnce() -> Result<WallTable, TableError>,
) -> Result<Arc<WallLobeTable>, TableError> {
    static REGISTRY: OnceLock<Registry<WallLobeTable>> = OnceLock::new();
    let registry = REGISTRY.get_or_init(|| Mutex::new(HashMap::new()));
    shared_in(registry, hash, || make().map(|t| WallLobeTable::new(&t)))
}

/// The cache file of a wall table: `wall-table-HASH.npz`.
pub fn wall_cache_file(dir: &Path, hash: &str) -> PathBuf {
    dir.join(format!("wall-table-{hash}.npz"))
}

/// The wall table of `params`: shared in memory, else read from the disk cache, else traced
/// (seconds at the default sizes) and cached.
pub fn obtain_wall_table(params: &WallTableParams) -> Result<Arc<WallLobeTable>, TableError> {
    let hash = params.hash();
    shared_walls(hash.clone(), || {
        load_or_compute_walls(params, &hash, cache_dir().as_deref())
    })
}

/// The disk-cache step of [`obtain_wall_table`] with an explicit cache folder.
pub fn load_or_compute_walls(
    params: &WallTableParams,
    hash: &str,
    dir: Option<&Path>,
) -> Result<WallTable, TableError> {
    if let Some(t) = read_cached(dir, wall_cache_file, WallTable::load, hash, |t| {
        t.params.hash()
    }) {
        return Ok(t);
    }
    let start = std::time::Instant::now();
    let kind = params.walls.name();
    crate::log::info(&format!(
        "computing {kind} table {} ({}, ior {}, roughness {}) ...",
        &hash[..12],
        params.profile.spec,
        params.ior,
        params.roughness
    ));
    let table = WallTable::compute(params)?;
    crate::log::info(&format!(
        "{kind} table {} computed in {:.2} s",
        &hash[..12],
        start.elapsed().as_secs_f64()
    ));
    if let Some(dir) = dir {
        let file = wall_cache_file(dir, hash);
        let result = std::fs::create_dir_all(dir).and_then(|_| table.save(&file));
        if let Err(e) = result {
            crate::log::warn(&format!("could not cache the {kind} table ({e})"));
        }
    }
    Ok(table)
}

/// Read a table file of any kind: a wall table (its `kind` says which: dielectric or rough
/// specular) or the seed's scratch table.
pub fn load_any_table_file(path: &Path) -> Result<ScratchModel, TableError> {
    let walls = WallTable::load(path).map_err(|e| TableError::WallFile {
        path: path.into(),
        why: e.to_string(),
    });
    match walls {
        Ok(Some(t)) => {
            let specular = matches!(t.params.walls, WallKind::Specular { .. });
            let table = shared_walls(t.params.hash(), || Ok(t))?;
            Ok(if specular {
                ScratchModel::SpecularWalls(table)
            } else {
                ScratchModel::DielectricWalls(GlassWalls::Table(table))
            })
        }
        Err(e) if crate::precompute::wall_table::declares_kind(path) => Err(e),
        // Not a wall table (or not an .npz at all): the seed's reader says why.
        _ => load_table_file(path).map(ScratchModel::Seed),
    }
}

/// The table of `params`: shared in memory if a live one has the same hash, else read from the
/// disk cache, else computed (and cached).
pub fn obtain_table(params: &TableParams) -> Result<Arc<ScratchLobeTable>, TableError> {
    let hash = params.hash();
    shared(hash.clone(), || {
        load_or_compute(params, &hash, cache_dir().as_deref())
    })
}

/// Read a table file (shared in memory by its parameter hash like computed ones).
pub fn load_table_file(path: &Path) -> Result<Arc<ScratchLobeTable>, TableError> {
    let table = ScratchTable::load(path)?;
    shared(table.params.hash(), || Ok(table))
}

/// The table cached in `dir` under `hash` (file name by `file`), if it reads and holds the
/// parameters of that hash; else a warning, and `None`: the caller recomputes it. Temporaries
/// of killed processes (which could not clean up) are swept first: they would stay forever.
fn read_cached<T, E: std::fmt::Display>(
    dir: Option<&Path>,
    file: fn(&Path, &str) -> PathBuf,
    load: impl Fn(&Path) -> Result<Option<T>, E>,
    hash: &str,
    hash_of: impl Fn(&T) -> String,
) -> Option<T> {
    let dir = dir?;
    crate::io::sweep_stale_temporaries(dir, None);
    let file = file(dir, hash);
    if !file.exists() {
        return None;
    }
    match load(&file) {
        Ok(Some(t)) if hash_of(&t) == hash => return Some(t),
        Ok(_) => crate::log::warn(&format!(
            "cached table {} holds other parameters; recomputing it",
            file.display()
        )),
        Err(e) => crate::log::warn(&format!("cached table unreadable ({e}); recomputing it")),
    }
    None
}

/// The disk-cache step of [`obtain_table`] with an explicit cache folder (`None`: no cache).
pub fn load_or_compute(
    params: &TableParams,
    hash: &str,
    dir: Option<&Path>,
) -> Result<ScratchTable, TableError> {
    let load = |f: &Path| ScratchTable::load(f).map(Some);
    if let Some(t) = read_cached(dir, cache_file, load, hash, |t| t.params.hash()) {
        return Ok(t);
    }
    let start = std::time::Instant::now();
    let t = &params.trace;
    let slices = match t.groove_slices {
        0 => String::new(),
        s => format!(", {s} exact-groove slices"),
    };
    crate::log::info(&format!(
        "computing scratch table {} ({}, {:?} walls, M {} N {} N_r {}{slices}) ...",
        &hash[..12],
        params.profile.spec,
        t.walls,
        t.m,
        t.n,
        t.nr
    ));
    let table = ScratchTable::compute(params, &|_| {})?;
    crate::log::info(&format!(
        "scratch table {} computed in {:.2} s",
        &hash[..12],
        start.elapsed().as_secs_f64()
    ));
    if let Some(dir) = dir {
        let result = std::fs::create_dir_all(dir)
            .map_err(|e| TableError::Io {
                path: dir.to_path_buf(),
                source: e,
            })
            .and_then(|_| table.save(&cache_file(dir, hash)));
        if let Err(e) = result {
            crate::log::warn(&format!("could not cache the scratch table ({e})"));
        }
    }
    Ok(table)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optics::fresnel::FresnelLaw;
    use crate::precompute::profile::Profile;
    use crate::precompute::trace2d::{FresnelMode, TraceSettings, Walls};

    #[test]
    fn table_cache_writes_reads_and_recovers_from_corruption() {
        let dir = std::env::temp_dir().join(format!("striae-cache-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let trace = TraceSettings {
            m: 8,
            n: 100,
            nr: 2,
            seed: 99,
            ..TraceSettings::default()
        };
        let params = TableParams::new(Profile::parse("v:angle=80").unwrap(), trace);
        let hash = params.hash();
        let a = load_or_compute(&params, &hash, Some(&dir)).unwrap();
        let file = cache_file(&dir, &hash);
        assert!(file.exists());
        // Only the final file remains (no temporary left behind).
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        let b = load_or_compute(&params, &hash, Some(&dir)).unwrap();
        assert_eq!(a, b);
        // A corrupt cache file is recomputed (with a warning) and replaced.
        std::fs::write(&file, b"garbage").unwrap();
        let c = load_or_compute(&params, &hash, Some(&dir)).unwrap();
        assert_eq!(a.rho_s, c.rho_s);
        assert!(ScratchTable::load(&file).is_ok());
        // A file under the wrong name (other parameters) is not trusted either.
        let mut other = params.clone();
        other.trace.seed = 100;
        std::fs::copy(&file, cache_file(&dir, &other.hash())).unwrap();
        let d = load_or_compute(&other, &other.hash(), Some(&dir)).unwrap();
        assert_eq!(d.params, other);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn tables_are_shared_by_hash() {
        let trace = TraceSettings {
            m: 8,
            n: 50,
            nr: 2,
            seed: 12345,
            ..TraceSettings::default()
        };
        let params = TableParams::new(Profile::parse("v:angle=70").unwrap(), trace);
        let a = obtain_table(&params).unwrap();
        let b = obtain_table(&params).unwrap();
        assert!(Arc::ptr_eq(&a, &b));
        let mut other = params.clone();
        other.trace.seed += 1;
        let c = obtain_table(&other).unwrap();
        assert!(!Arc::ptr_eq(&a, &c));
    }

    /// A table's parameters read back from its file are the ones written, bit for bit, so that
    /// its hash (the cache file's name) matches: a curved profile's vertices are not round
    /// numbers, and a JSON parser that rounds them by one ulp made every render of the scratched
    /// metal teapot recompute its cached table.
    #[test]
    fn table_parameters_read_back_bit_for_bit() {
        let trace = TraceSettings {
            m: 8,
            n: 100,
            walls: Walls::Specular,
            fresnel_mode: FresnelMode::Walls,
            fresnel_law: FresnelLaw::Conductor {
                eta: 0.1431189626455307,
                k: 3.9831604957580566,
            },
            ..TraceSettings::default()
        };
        let params = TableParams::new(Profile::parse("round:depth=0.3").unwrap(), trace);
        let dir =
            std::env::temp_dir().join(format!("striae-roundtrip-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let hash = params.hash();
        load_or_compute(&params, &hash, Some(&dir)).unwrap();
        let loaded = ScratchTable::load(&cache_file(&dir, &hash)).unwrap();
        assert_eq!(loaded.params.profile.points, params.profile.points);
        assert_eq!(loaded.params.trace, params.trace);
        assert_eq!(loaded.params.hash(), hash);
        std::fs::remove_dir_all(&dir).ok();
    }

    /// A table file of any kind loads as its model; a dielectric-wall file with a negative
    /// fraction, or more energy out than in, is refused naming the array; the disk cache of
    /// wall tables recovers from a corrupt file.
    #[test]
    fn table_files_of_both_kinds_and_corrupt_wall_tables() {
        let dir = std::env::temp_dir().join(format!("striae-walls-cache-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let walls = WallTableParams {
            theta_bins: 2,
            phi_bins: 2,
            bins: 4,
            paths: 200,
            seed: 5,
            ..WallTableParams::new(Profile::parse("v:angle=90").unwrap(), 1.5, 0.0)
        };
        let hash = walls.hash();
        let a = load_or_compute_walls(&walls, &hash, Some(&dir)).unwrap();
        let file = wall_cache_file(&dir, &hash);
        assert!(matches!(
            load_any_table_file(&file).unwrap(),
            ScratchModel::DielectricWalls(_)
        ));
        std::fs::write(&file, b"garbage").unwrap();
        let b = load_or_compute_walls(&walls, &hash, Some(&dir)).unwrap();
        assert_eq!(a.lobes, b.lobes);
        // Corrupt values: negative, and R + T > 1.
        for (value, needle) in [(-0.5, "r_out"), (0.9, "send out")] {
            let mut bad = a.clone();
            bad.lobes[0][3] = value;
            let path = dir.join("bad.npz");
            bad.save(&path).unwrap();
            let e = load_any_table_file(&path).unwrap_err().to_string();
            assert!(e.contains(needle), "{e}");
        }
        // A metal's rough specular walls load as their own model.
        let specular = WallTableParams {
            theta_bins: 2,
            phi_bins: 2,
            bins: 4,
            paths: 200,
            ..WallTableParams::specular(
                Profile::parse("v:angle=90").unwrap(),
                FresnelLaw::None,
                0.2,
            )
        };
        let path = dir.join("specular.npz");
        WallTable::compute(&specular).unwrap().save(&path).unwrap();
        assert!(matches!(
            load_any_table_file(&path).unwrap(),
            ScratchModel::SpecularWalls(_)
        ));
        let seed = TableParams::new(
            Profile::parse("v:angle=90").unwrap(),
            TraceSettings {
                m: 8,
                n: 50,
                nr: 2,
                ..TraceSettings::default()
            },
        );
        let path = dir.join("seed.npz");
        ScratchTable::compute(&seed, &|_| {})
            .unwrap()
            .save(&path)
            .unwrap();
        assert!(matches!(
            load_any_table_file(&path).unwrap(),
            ScratchModel::Seed(_)
        ));
        std::fs::remove_dir_all(&dir).ok();
    }
}
