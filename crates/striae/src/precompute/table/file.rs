//! The table file (`docs/table-format.md`): its parameters record and hash, the checks
//! of an archive before it is decoded, and [`ScratchTable::save`] / [`ScratchTable::load`].

use super::ScratchTable;
use crate::optics::fresnel::FresnelLaw;
use crate::precompute::groove::GonioError;
use crate::precompute::groove_slices::slice_angles;
use crate::precompute::profile::Profile;
use crate::precompute::trace2d::{bin_centre, TraceError, TraceSettings, THETA_SLICES};
use ndarray::{Array1, ArrayD, IxDyn};
use ndarray_npy::{NpzReader, NpzWriter};
use sha2::{Digest, Sha256};
use std::f64::consts::PI;
use std::path::{Path, PathBuf};

/// Version of the table file layout; files with another version are refused.
pub const FORMAT_VERSION: i64 = 1;

/// Everything that determines a table.
#[derive(Clone, Debug, PartialEq)]
pub struct TableParams {
    pub profile: Profile,
    pub trace: TraceSettings,
}

impl TableParams {
    pub fn new(profile: Profile, trace: TraceSettings) -> Self {
        TableParams { profile, trace }
    }

    /// The JSON record stored in the file (`params_json`).
    pub fn to_json(&self) -> serde_json::Value {
        let mut v = serde_json::to_value(&self.trace).expect("settings serialise");
        let o = v.as_object_mut().expect("object");
        o.insert("profile".into(), self.profile.spec.clone().into());
        o.insert(
            "profile_points".into(),
            serde_json::to_value(&self.profile.points).expect("points"),
        );
        let ior = match self.trace.fresnel_law {
            FresnelLaw::Schlick { n } | FresnelLaw::Dielectric { n } => n,
            FresnelLaw::Conductor { eta, .. } => eta,
            FresnelLaw::None => 1.0,
        };
        o.insert("ior".into(), ior.into());
        o.insert("format_version".into(), FORMAT_VERSION.into());
        o.insert("striae_version".into(), crate::VERSION.into());
        v
    }

    fn from_json(v: &serde_json::Value) -> Result<Self, String> {
        let trace: TraceSettings = serde_json::from_value(v.clone()).map_err(|e| e.to_string())?;
        let spec = v
            .get("profile")
            .and_then(|s| s.as_str())
            .ok_or("missing `profile`")?
            .to_string();
        let points: Vec<[f64; 2]> = serde_json::from_value(
            v.get("profile_points")
                .cloned()
                .ok_or("missing `profile_points`")?,
        )
        .map_err(|e| format!("profile_points: {e}"))?;
        let profile = Profile::from_points(spec, points).map_err(|e| e.to_string())?;
        trace.validate().map_err(|e| e.to_string())?;
        Ok(TableParams { profile, trace })
    }

    /// A stable SHA-256 (hex) of what determines the table's values: the format version, the
    /// tracer version ([`crate::precompute::trace2d::TRACER_VERSION`]), the profile's vertices (not its spec
    /// or file name) and the trace settings. For on-disk caches.
    pub fn hash(&self) -> String {
        let key = serde_json::json!({
            "format_version": FORMAT_VERSION,
            "tracer_version": crate::precompute::trace2d::TRACER_VERSION,
            "profile_points": self.profile.points,
            "trace": self.trace,
        });
        let digest = Sha256::digest(key.to_string().as_bytes());
        digest.iter().map(|b| format!("{b:02x}")).collect()
    }
}

/// Check that every `.npy` array of a `.npz` archive declares no more data (its header's shape
/// times its item size) than the archive entry holds, so that a corrupt or hostile header
/// (shape `(3, 100000, 100000)` in a small file) is an error instead of a 240 GB allocation
/// that aborts the process: ndarray-npy allocates what the header declares before it reads.
pub(crate) fn check_npz_sizes(file: &std::fs::File) -> Result<(), String> {
    use std::io::Read;
    let mut zip = zip::ZipArchive::new(std::io::BufReader::new(file)).map_err(|e| e.to_string())?;
    for i in 0..zip.len() {
        let mut entry = zip.by_index(i).map_err(|e| e.to_string())?;
        let name = entry.name().to_string();
        if !name.ends_with(".npy") {
            continue;
        }
        let size = entry.size();
        // Magic, version, header length (2 bytes in format 1.0, 4 in 2.0 and 3.0).
        let mut lead = [0u8; 12];
        entry
            .read_exact(&mut lead[..10])
            .map_err(|e| format!("`{name}`: {e}"))?;
        if &lead[..6] != b"\x93NUMPY" {
            return Err(format!("`{name}` is not an .npy array"));
        }
        let (header_len, start) = if lead[6] == 1 {
            (u16::from_le_bytes([lead[8], lead[9]]) as u64, 10)
        } else {
            entry
                .read_exact(&mut lead[10..])
                .map_err(|e| format!("`{name}`: {e}"))?;
            (
                u32::from_le_bytes([lead[8], lead[9], lead[10], lead[11]]) as u64,
                12,
            )
        };
        if start + header_len > size {
            return Err(format!(
                "`{name}`: header longer than the array's {size} bytes"
            ));
        }
        let mut header = String::new();
        entry
            .by_ref()
            .take(header_len)
            .read_to_string(&mut header)
            .map_err(|e| format!("`{name}`: {e}"))?;
        let declared = npy_header_bytes(&header)
            .ok_or_else(|| {
                format!("`{name}`: no readable item size and shape (or their product overflows) in header {header:?}")
            })?;
        if declared > size - start - header_len {
            return Err(format!(
                "`{name}` declares {declared} bytes of data in header {:?} but holds {}",
                header.trim_end(),
                size - start - header_len
            ));
        }
    }
    Ok(())
}

/// The data size an `.npy` header declares: the product of its `shape` times the item size at
/// the end of its `descr` (`'<f8'`: 8); `None` if either cannot be read or the product overflows.
fn npy_header_bytes(header: &str) -> Option<u64> {
    let after = |key: &str| header.split_once(key).map(|(_, rest)| rest);
    let descr = after("'descr':")?.trim_start().strip_prefix('\'')?;
    let descr = &descr[..descr.find('\'')?];
    let digits = descr.trim_start_matches(|c: char| !c.is_ascii_digit());
    let item: u64 = digits.parse().ok()?;
    let shape = after("'shape':")?.trim_start().strip_prefix('(')?;
    let shape = &shape[..shape.find(')')?];
    shape
        .split(',')
        .map(str::trim)
        .filter(|d| !d.is_empty())
        .try_fold(item, |acc, d| acc.checked_mul(d.parse::<u64>().ok()?))
}

/// Errors computing, reading or writing a table.
#[derive(Debug, thiserror::Error)]
pub enum TableError {
    #[error(transparent)]
    Trace(#[from] TraceError),
    #[error("exact-groove slices: {0}")]
    Groove(GonioError),
    #[error(transparent)]
    Walls(#[from] crate::precompute::groove::GonioError),
    #[error("dielectric-wall table {path}: {why}")]
    WallFile { path: PathBuf, why: String },
    #[error("cannot read or write table {path}")]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("table {path}: not a readable .npz file ({why})")]
    Npz { path: PathBuf, why: String },
    #[error("table {path}: missing key `{key}`")]
    MissingKey { path: PathBuf, key: &'static str },
    #[error("table {path}: key `{key}` cannot be read as {dtype}: {why}")]
    BadArray {
        path: PathBuf,
        key: &'static str,
        dtype: &'static str,
        why: String,
    },
    #[error("table {path}: key `{key}` has shape {got:?}, expected {expected:?}")]
    Shape {
        path: PathBuf,
        key: &'static str,
        got: Vec<usize>,
        expected: Vec<usize>,
    },
    #[error("table {path}: key `{key}` holds a non-finite or negative value {value} at flat index {index}")]
    BadValue {
        path: PathBuf,
        key: &'static str,
        index: usize,
        value: f64,
    },
    #[error("table {path}: format version {found}, this striae reads version {expected}")]
    Incompatible {
        path: PathBuf,
        found: i64,
        expected: i64,
    },
    #[error("table {path}: bad parameters in `params_json`: {why}")]
    Params { path: PathBuf, why: String },
    #[error("table {path}: key `{key}` row {row} (phi_i bin) reflects {albedo} of the incident energy; eq. (1') bounds it by 1")]
    Energy {
        path: PathBuf,
        key: &'static str,
        row: usize,
        albedo: f64,
    },
    #[error(
        "table {path}: stored `albedo_2d` row {row} is {stored}, its `rho_m` gives {computed}"
    )]
    Inconsistent {
        path: PathBuf,
        row: usize,
        stored: f64,
        computed: f64,
    },
    #[error("table {path}: unknown key `{key}` (not an array of format version {FORMAT_VERSION}, docs/table-format.md)")]
    UnknownKey { path: PathBuf, key: String },
    #[error("table {path}: key `{key}` contradicts `params_json`: {why}")]
    Contradiction {
        path: PathBuf,
        key: &'static str,
        why: String,
    },
}

/// The arrays of a table file (format version [`FORMAT_VERSION`], `docs/table-format.md`):
/// any other is refused, so that a file is read whole or not at all.
const KEYS: [&str; 12] = [
    "format_version",
    "params_json",
    "version",
    "phi",
    "theta",
    "rho_m",
    "rho_s",
    "gamma",
    "dropped",
    "albedo_2d",
    "groove_theta",
    "groove_rho",
];

/// Eq. (1') makes every row's 2D albedo at most 1: a table beyond it (plus round-off) is not
/// one striae computed. `rho_m` and each `rho_s` slice are checked, and a stored `albedo_2d`
/// must be what `rho_m` gives.
fn check_energy(path: &Path, t: &ScratchTable, stored: Option<&[f64]>) -> Result<(), TableError> {
    let m = t.m;
    let row_albedo = |values: &[f64], i: usize| -> f64 {
        (0..m)
            .map(|j| values[i * m + j] * t.phi[j].cos() * PI / m as f64)
            .sum()
    };
    let arrays = std::iter::once(("rho_m", &t.rho_m[..]))
        .chain(t.rho_s.chunks(m * m).map(|slice| ("rho_s", slice)))
        .chain(
            t.groove_rho
                .chunks(m * m)
                .map(|slice| ("groove_rho", slice)),
        );
    for (key, values) in arrays {
        if let Some((row, albedo)) = (0..m)
            .map(|i| (i, row_albedo(values, i)))
            .find(|&(_, a)| a > 1.0 + 1e-6)
        {
            return Err(TableError::Energy {
                path: path.into(),
                key,
                row,
                albedo,
            });
        }
    }
    if let Some(stored) = stored {
        let computed = t.albedo_2d();
        if let Some(row) = (0..m).find(|&i| (stored[i] - computed[i]).abs() > 1e-9) {
            return Err(TableError::Inconsistent {
                path: path.into(),
                row,
                stored: stored[row],
                computed: computed[row],
            });
        }
    }
    Ok(())
}

/// A table file being read: its archive, the names of its entries, and the path every error
/// names.
struct TableFile<'a> {
    path: &'a Path,
    npz: NpzReader<std::io::BufReader<std::fs::File>>,
    names: Vec<String>,
}

impl<'a> TableFile<'a> {
    /// Open `path` and check each entry's declared size against the bytes it holds
    /// ([`check_npz_sizes`]) before anything is decoded; one handle serves the check and the
    /// read, so both see the same file.
    fn open(path: &'a Path) -> Result<Self, TableError> {
        use std::io::Seek;
        let io = |e| TableError::Io {
            path: path.into(),
            source: e,
        };
        let npz_error = |why: String| TableError::Npz {
            path: path.into(),
            why,
        };
        let mut file = crate::io::open_regular(path, crate::io::MAX_BINARY_BYTES).map_err(io)?;
        check_npz_sizes(&file).map_err(npz_error)?;
        file.rewind().map_err(io)?;
        let mut npz =
            NpzReader::new(std::io::BufReader::new(file)).map_err(|e| npz_error(e.to_string()))?;
        let names = npz.names().map_err(|e| npz_error(e.to_string()))?;
        Ok(TableFile { path, npz, names })
    }

    fn has(&self, key: &str) -> bool {
        self.names.iter().any(|n| n == key)
    }

    fn bad_array(&self, key: &'static str, dtype: &'static str, why: String) -> TableError {
        TableError::BadArray {
            path: self.path.into(),
            key,
            dtype,
            why,
        }
    }

    /// An `int64` scalar entry.
    fn int_scalar(&mut self, key: &'static str) -> Result<i64, TableError> {
        let a: ndarray::Array0<i64> = self
            .npz
            .by_name(key)
            .map_err(|e| self.bad_array(key, "int64 scalar", e.to_string()))?;
        Ok(a.into_scalar())
    }

    /// A UTF-8 text entry, stored as `uint8[]`.
    fn text(&mut self, key: &'static str) -> Result<String, TableError> {
        let a: Array1<u8> = self
            .npz
            .by_name(key)
            .map_err(|e| self.bad_array(key, "uint8[]", e.to_string()))?;
        String::from_utf8(a.to_vec()).map_err(|e| self.bad_array(key, "UTF-8 text", e.to_string()))
    }

    /// A `float64` entry of exactly `shape`, finite, and `>= 0` with `nonneg`, flattened.
    fn floats(
        &mut self,
        key: &'static str,
        shape: &[usize],
        nonneg: bool,
    ) -> Result<Vec<f64>, TableError> {
        let a: ArrayD<f64> = self
            .npz
            .by_name(key)
            .map_err(|e| self.bad_array(key, "float64", e.to_string()))?;
        if a.shape() != shape {
            return Err(TableError::Shape {
                path: self.path.into(),
                key,
                got: a.shape().to_vec(),
                expected: shape.to_vec(),
            });
        }
        let v: Vec<f64> = a.iter().copied().collect();
        if let Some((index, &value)) = v
            .iter()
            .enumerate()
            .find(|(_, x)| !x.is_finite() || (nonneg && **x < 0.0))
        {
            return Err(TableError::BadValue {
                path: self.path.into(),
                key,
                index,
                value,
            });
        }
        Ok(v)
    }
}

impl TableFile<'_> {
    /// The exact-groove slices' `groove_rho` (`slices x m x m`, after `groove_theta` is checked
    /// against [`slice_angles`]); empty, and neither key read, for `slices = 0`.
    fn groove_rho(&mut self, m: usize, slices: usize) -> Result<Vec<f64>, TableError> {
        if slices == 0 {
            if let Some(key) = ["groove_theta", "groove_rho"]
                .into_iter()
                .find(|k| self.has(k))
            {
                return Err(TableError::Contradiction {
                    path: self.path.into(),
                    key,
                    why: "exact-groove slices in a table whose `groove_slices` is 0".into(),
                });
            }
            return Ok(Vec::new());
        }
        for key in ["groove_theta", "groove_rho"] {
            if !self.has(key) {
                return Err(TableError::MissingKey {
                    path: self.path.into(),
                    key,
                });
            }
        }
        let theta = self.floats("groove_theta", &[slices], false)?;
        check_grid(
            self.path,
            "groove_theta",
            &theta,
            slice_angles(slices).into_iter(),
        )?;
        self.floats("groove_rho", &[slices, m, m], true)
    }
}

/// `got` equals the grid `expected` within `1e-12`, or the first value that does not.
fn check_grid(
    path: &Path,
    key: &'static str,
    got: &[f64],
    expected: impl Iterator<Item = f64>,
) -> Result<(), TableError> {
    match got
        .iter()
        .zip(expected)
        .position(|(&a, b)| (a - b).abs() > 1e-12)
    {
        Some(index) => Err(TableError::BadValue {
            path: path.into(),
            key,
            index,
            value: got[index],
        }),
        None => Ok(()),
    }
}

impl ScratchTable {
    /// Write the `.npz` (atomically; layout in `docs/table-format.md`).
    pub fn save(&self, path: &Path) -> Result<(), TableError> {
        let m = self.m;
        let npz_err = |e: ndarray_npy::WriteNpzError| std::io::Error::other(e.to_string());
        let json = serde_json::to_string_pretty(&self.params.to_json()).expect("json");
        crate::io::write_atomically(path, |tmp| {
            let file = std::fs::File::create(tmp)?;
            let mut w = NpzWriter::new(std::io::BufWriter::new(file));
            let sh = |v: &[f64], s: &[usize]| {
                ArrayD::from_shape_vec(IxDyn(s), v.to_vec()).expect("shape")
            };
            w.add_array("phi", &Array1::from(self.phi.clone()))
                .map_err(npz_err)?;
            w.add_array("theta", &Array1::from(THETA_SLICES.to_vec()))
                .map_err(npz_err)?;
            w.add_array("rho_m", &sh(&self.rho_m, &[m, m]))
                .map_err(npz_err)?;
            w.add_array("rho_s", &sh(&self.rho_s, &[3, m, m]))
                .map_err(npz_err)?;
            w.add_array("gamma", &sh(&self.gamma, &[m, m]))
                .map_err(npz_err)?;
            w.add_array("dropped", &Array1::from(self.dropped.clone()))
                .map_err(npz_err)?;
            w.add_array("albedo_2d", &Array1::from(self.albedo_2d()))
                .map_err(npz_err)?;
            let slices = self.groove_rho.len() / (m * m);
            if slices > 0 {
                w.add_array("groove_theta", &Array1::from(slice_angles(slices)))
                    .map_err(npz_err)?;
                w.add_array("groove_rho", &sh(&self.groove_rho, &[slices, m, m]))
                    .map_err(npz_err)?;
            }
            w.add_array("params_json", &Array1::from(json.as_bytes().to_vec()))
                .map_err(npz_err)?;
            w.add_array("version", &Array1::from(self.version.as_bytes().to_vec()))
                .map_err(npz_err)?;
            w.add_array("format_version", &ndarray::arr0(FORMAT_VERSION))
                .map_err(npz_err)?;
            w.finish().map_err(npz_err)?;
            Ok(())
        })
        .map_err(|e| TableError::Io {
            path: path.into(),
            source: e,
        })
    }

    /// Read and validate a table written by [`ScratchTable::save`]: every array present, of
    /// its type and shape, finite (and `>= 0` where a BRDF value), the bin centres those of
    /// eq. (1'), the format version this crate's, no array the format lacks ([`KEYS`]) and
    /// none the parameters contradict (exact-groove slices in a table without them).
    pub fn load(path: &Path) -> Result<Self, TableError> {
        let mut f = TableFile::open(path)?;
        for key in [
            "format_version",
            "params_json",
            "phi",
            "theta",
            "rho_m",
            "rho_s",
            "gamma",
        ] {
            if !f.has(key) {
                return Err(TableError::MissingKey {
                    path: path.into(),
                    key,
                });
            }
        }
        let found = f.int_scalar("format_version")?;
        if found != FORMAT_VERSION {
            return Err(TableError::Incompatible {
                path: path.into(),
                found,
                expected: FORMAT_VERSION,
            });
        }
        if let Some(key) = f.names.iter().find(|n| !KEYS.contains(&n.as_str())) {
            return Err(TableError::UnknownKey {
                path: path.into(),
                key: key.clone(),
            });
        }
        let json = f.text("params_json")?;
        let version = if f.has("version") {
            f.text("version")?
        } else {
            String::new()
        };
        let value: serde_json::Value =
            serde_json::from_str(&json).map_err(|e| TableError::Params {
                path: path.into(),
                why: e.to_string(),
            })?;
        if let Some(v) = value
            .get("format_version")
            .filter(|v| v.as_i64() != Some(found))
        {
            return Err(TableError::Contradiction {
                path: path.into(),
                key: "format_version",
                why: format!("the array holds {found}, `params_json` says {v}"),
            });
        }
        let params = TableParams::from_json(&value).map_err(|why| TableError::Params {
            path: path.into(),
            why,
        })?;
        let m = params.trace.m;
        let phi = f.floats("phi", &[m], false)?;
        let theta = f.floats("theta", &[3], false)?;
        let rho_m = f.floats("rho_m", &[m, m], true)?;
        let rho_s = f.floats("rho_s", &[3, m, m], true)?;
        let gamma = f.floats("gamma", &[m, m], true)?;
        let dropped = if f.has("dropped") {
            f.floats("dropped", &[m], true)?
        } else {
            vec![0.0; m]
        };
        let stored_albedo = match f.has("albedo_2d") {
            true => Some(f.floats("albedo_2d", &[m], true)?),
            false => None,
        };
        check_grid(path, "phi", &phi, (0..m).map(|k| bin_centre(k, m)))?;
        check_grid(path, "theta", &theta, THETA_SLICES.iter().copied())?;
        let groove_rho = f.groove_rho(m, params.trace.groove_slices)?;
        let table = ScratchTable {
            params,
            m,
            phi,
            rho_m,
            rho_s,
            gamma,
            dropped,
            groove_rho,
            version,
        };
        check_energy(path, &table, stored_albedo.as_deref())?;
        Ok(table)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::precompute::table::tests::{params, tmpdir};
    use crate::precompute::trace2d::{FresnelMode, Walls};

    #[test]
    fn save_load_round_trip_and_hash() {
        let p = params(
            "trapezoid:depth=0.3,bottom=0.3",
            Walls::Diffuse,
            FresnelMode::Walls,
        );
        let t = ScratchTable::compute(&p, &|_| {}).unwrap();
        let dir = tmpdir();
        let f = dir.join("t.npz");
        t.save(&f).unwrap();
        let u = ScratchTable::load(&f).unwrap();
        assert_eq!(t, u);
        // Hash: stable for equal parameters, different for different ones.
        assert_eq!(p.hash(), u.params.hash());
        assert_eq!(p.hash().len(), 64);
        let mut q = p.clone();
        q.trace.seed += 1;
        assert_ne!(p.hash(), q.hash());
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn tables_beyond_eq_1_prime_or_contradicting_themselves_are_rejected() {
        let p = params("v:depth=0.4", Walls::Diffuse, FresnelMode::Seed);
        let t = ScratchTable::compute(&p, &|_| {}).unwrap();
        let dir = tmpdir();
        let good = dir.join("energy-good.npz");
        t.save(&good).unwrap();
        ScratchTable::load(&good).unwrap();
        // Twice the energy of a lossless groove, or ten times a slice's: beyond eq. (1').
        for (key, scale) in [("rho_m", 2.0), ("rho_s", 10.0)] {
            let mut hot = t.clone();
            match key {
                "rho_m" => hot.rho_m.iter_mut().for_each(|v| *v *= scale),
                _ => hot.rho_s.iter_mut().for_each(|v| *v *= scale),
            }
            let f = dir.join(format!("energy-hot-{key}.npz"));
            hot.save(&f).unwrap();
            let err = ScratchTable::load(&f).unwrap_err();
            assert!(
                matches!(err, TableError::Energy { key: k, .. } if k == key),
                "{err}"
            );
        }
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn bad_files_are_rejected() {
        let p = params("v:depth=0.4", Walls::Specular, FresnelMode::Seed);
        let t = ScratchTable::compute(&p, &|_| {}).unwrap();
        let dir = tmpdir();
        let good = dir.join("good.npz");
        t.save(&good).unwrap();
        let bytes = std::fs::read(&good).unwrap();
        // Missing file, garbage, truncated.
        assert!(matches!(
            ScratchTable::load(&dir.join("none.npz")),
            Err(TableError::Io { .. })
        ));
        let f = dir.join("garbage.npz");
        std::fs::write(&f, b"not a zip at all").unwrap();
        assert!(matches!(
            ScratchTable::load(&f),
            Err(TableError::Npz { .. })
        ));
        let f = dir.join("trunc.npz");
        std::fs::write(&f, &bytes[..bytes.len() / 2]).unwrap();
        assert!(ScratchTable::load(&f).is_err());
        // A header declaring far more data than the file holds (240 GB): an error, not an
        // allocation that aborts. The entries are stored uncompressed, so the header is edited
        // in place, its padding absorbing the longer shape.
        let at = |needle: &[u8], from: usize| {
            from + bytes[from..]
                .windows(needle.len())
                .position(|w| w == needle)
                .unwrap()
        };
        let start = at(b"'shape': (3, ", 0);
        let end = at(b"\n", start);
        let mut huge = bytes.clone();
        let mut header = b"'shape': (3, 100000, 100000)}".to_vec();
        header.resize(end - start, b' ');
        huge[start..end].copy_from_slice(&header);
        let f = dir.join("huge.npz");
        std::fs::write(&f, &huge).unwrap();
        let err = ScratchTable::load(&f).unwrap_err();
        assert!(
            matches!(err, TableError::Npz { .. }) && err.to_string().contains("240000000000"),
            "{err}"
        );
        // Hand-made incompatible files.
        let write = |name: &str, edit: &dyn Fn(&mut NpzWriter<std::fs::File>)| {
            let f = dir.join(name);
            let mut w = NpzWriter::new(std::fs::File::create(&f).unwrap());
            edit(&mut w);
            w.finish().unwrap();
            f
        };
        let m = t.m;
        let json = serde_json::to_string(&t.params.to_json()).unwrap();
        let full = |w: &mut NpzWriter<std::fs::File>,
                    fv: i64,
                    json: &str,
                    rho_shape: Vec<usize>,
                    rho_val: f64| {
            w.add_array("format_version", &ndarray::arr0(fv)).unwrap();
            w.add_array("params_json", &Array1::from(json.as_bytes().to_vec()))
                .unwrap();
            w.add_array("phi", &Array1::from(t.phi.clone())).unwrap();
            w.add_array("theta", &Array1::from(THETA_SLICES.to_vec()))
                .unwrap();
            w.add_array("rho_m", &ArrayD::from_elem(IxDyn(&rho_shape), rho_val))
                .unwrap();
            w.add_array("rho_s", &ArrayD::from_elem(IxDyn(&[3, m, m]), 0.0))
                .unwrap();
            w.add_array("gamma", &ArrayD::from_elem(IxDyn(&[m, m]), 1.0))
                .unwrap();
        };
        // Sanity: the hand-made good file loads.
        let ok = write("ok.npz", &|w| {
            full(w, FORMAT_VERSION, &json, vec![m, m], 0.25)
        });
        ScratchTable::load(&ok).unwrap();
        let f = write("version.npz", &|w| full(w, 99, &json, vec![m, m], 0.25));
        assert!(matches!(
            ScratchTable::load(&f),
            Err(TableError::Incompatible { found: 99, .. })
        ));
        let f = write("shape.npz", &|w| {
            full(w, FORMAT_VERSION, &json, vec![m, m + 1], 0.5)
        });
        assert!(matches!(
            ScratchTable::load(&f),
            Err(TableError::Shape { key: "rho_m", .. })
        ));
        let f = write("nan.npz", &|w| {
            full(w, FORMAT_VERSION, &json, vec![m, m], f64::NAN)
        });
        assert!(matches!(
            ScratchTable::load(&f),
            Err(TableError::BadValue { key: "rho_m", .. })
        ));
        let f = write("neg.npz", &|w| {
            full(w, FORMAT_VERSION, &json, vec![m, m], -1.0)
        });
        assert!(matches!(
            ScratchTable::load(&f),
            Err(TableError::BadValue { key: "rho_m", .. })
        ));
        let f = write("json.npz", &|w| {
            full(w, FORMAT_VERSION, "{not json", vec![m, m], 0.25)
        });
        assert!(matches!(
            ScratchTable::load(&f),
            Err(TableError::Params { .. })
        ));
        let bad_m = json.replace(&format!("\"m\":{m}"), "\"m\":0");
        assert_ne!(bad_m, json);
        let f = write("m0.npz", &|w| {
            full(w, FORMAT_VERSION, &bad_m, vec![m, m], 0.25)
        });
        assert!(matches!(
            ScratchTable::load(&f),
            Err(TableError::Params { .. })
        ));
        let f = write("missing.npz", &|w| {
            w.add_array("format_version", &ndarray::arr0(FORMAT_VERSION))
                .unwrap();
        });
        assert!(matches!(
            ScratchTable::load(&f),
            Err(TableError::MissingKey { .. })
        ));
        let f = write("dtype.npz", &|w| {
            w.add_array("format_version", &ndarray::arr0(1.0f64))
                .unwrap();
            w.add_array("params_json", &Array1::from(json.as_bytes().to_vec()))
                .unwrap();
            for k in ["phi", "theta", "rho_m", "rho_s", "gamma"] {
                w.add_array(k, &Array1::from(vec![0.0f64])).unwrap();
            }
        });
        assert!(matches!(
            ScratchTable::load(&f),
            Err(TableError::BadArray {
                key: "format_version",
                ..
            })
        ));
        std::fs::remove_dir_all(&dir).ok();
    }

    /// Files whose parameters contradict their arrays, or that carry arrays the format lacks,
    /// are refused with an error naming the file and the key.
    #[test]
    fn contradicting_or_unknown_keys_are_rejected() {
        let p = params("v:depth=0.4", Walls::Diffuse, FresnelMode::Seed);
        let t = ScratchTable::compute(&p, &|_| {}).unwrap();
        let dir = tmpdir().join("contradictions");
        std::fs::create_dir_all(&dir).unwrap();
        let m = t.m;
        let json = serde_json::to_string(&t.params.to_json()).unwrap();
        let write = |name: &str, json: &str, extra: &dyn Fn(&mut NpzWriter<std::fs::File>)| {
            let f = dir.join(name);
            let mut w = NpzWriter::new(std::fs::File::create(&f).unwrap());
            w.add_array("format_version", &ndarray::arr0(FORMAT_VERSION))
                .unwrap();
            w.add_array("params_json", &Array1::from(json.as_bytes().to_vec()))
                .unwrap();
            w.add_array("phi", &Array1::from(t.phi.clone())).unwrap();
            w.add_array("theta", &Array1::from(THETA_SLICES.to_vec()))
                .unwrap();
            let sh = |v: &[f64], s: &[usize]| ArrayD::from_shape_vec(IxDyn(s), v.to_vec()).unwrap();
            w.add_array("rho_m", &sh(&t.rho_m, &[m, m])).unwrap();
            w.add_array("rho_s", &sh(&t.rho_s, &[3, m, m])).unwrap();
            w.add_array("gamma", &sh(&t.gamma, &[m, m])).unwrap();
            extra(&mut w);
            w.finish().unwrap();
            f
        };
        let named = |f: &Path, err: TableError, key: &str| {
            let text = err.to_string();
            assert!(
                text.contains(&f.display().to_string()) && text.contains(&format!("`{key}`")),
                "{text}"
            );
            err
        };
        ScratchTable::load(&write("ok.npz", &json, &|_| {})).unwrap();
        // An array the format lacks.
        let f = write("extra.npz", &json, &|w| {
            w.add_array("rho_x", &Array1::from(vec![0.0f64])).unwrap();
        });
        let e = named(&f, ScratchTable::load(&f).unwrap_err(), "rho_x");
        assert!(matches!(e, TableError::UnknownKey { .. }), "{e}");
        // The parameters say M = 2m, the arrays are m x m.
        let twice = json.replace(&format!("\"m\":{m}"), &format!("\"m\":{}", 2 * m));
        assert_ne!(twice, json);
        let f = write("m.npz", &twice, &|_| {});
        let e = named(&f, ScratchTable::load(&f).unwrap_err(), "phi");
        assert!(matches!(e, TableError::Shape { .. }), "{e}");
        // Exact-groove slices in a table whose parameters have none.
        let f = write("slices.npz", &json, &|w| {
            w.add_array("groove_theta", &Array1::from(slice_angles(2)))
                .unwrap();
            w.add_array("groove_rho", &ArrayD::from_elem(IxDyn(&[2, m, m]), 0.1))
                .unwrap();
        });
        let e = named(&f, ScratchTable::load(&f).unwrap_err(), "groove_theta");
        assert!(matches!(e, TableError::Contradiction { .. }), "{e}");
        // The parameters' format version against the array's.
        let other = json.replace(
            &format!("\"format_version\":{FORMAT_VERSION}"),
            "\"format_version\":7",
        );
        assert_ne!(other, json);
        let f = write("version.npz", &other, &|_| {});
        let e = named(&f, ScratchTable::load(&f).unwrap_err(), "format_version");
        assert!(matches!(e, TableError::Contradiction { .. }), "{e}");
        std::fs::remove_dir_all(&dir).ok();
    }
}
