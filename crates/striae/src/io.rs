//! Output files are never half-written: everything striae writes goes to a temporary name in
//! the destination folder first and is renamed into place only when complete.

use std::path::{Path, PathBuf};

/// The temporary sibling used while `path` is being written: `.NAME.tmp-PID` in the same folder,
/// so the final rename is atomic on one filesystem.
pub fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let tmp = format!(".{name}.tmp-{}", std::process::id());
    match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => dir.join(tmp),
        _ => PathBuf::from(tmp),
    }
}

/// Write `path` atomically: `write` fills a temporary file, which is renamed to `path` only if
/// `write` succeeded; on failure the temporary file is removed and `path` is untouched.
pub fn write_atomically<E>(path: &Path, write: impl FnOnce(&Path) -> Result<(), E>) -> Result<(), E>
where
    E: From<std::io::Error>,
{
    let tmp = temp_path(path);
    match write(&tmp) {
        Ok(()) => std::fs::rename(&tmp, path).map_err(|e| {
            let _ = std::fs::remove_file(&tmp);
            E::from(e)
        }),
        Err(e) => {
            let _ = std::fs::remove_file(&tmp);
            Err(e)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn failed_write_leaves_nothing() {
        let dir = std::env::temp_dir().join(format!("striae-io-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let out = dir.join("x.bin");
        let r: Result<(), std::io::Error> = write_atomically(&out, |p| {
            std::fs::write(p, b"partial")?;
            Err(std::io::Error::other("boom"))
        });
        assert!(r.is_err());
        assert!(!out.exists());
        assert_eq!(
            std::fs::read_dir(&dir).unwrap().count(),
            0,
            "temporary file removed"
        );
        write_atomically::<std::io::Error>(&out, |p| std::fs::write(p, b"done")).unwrap();
        assert_eq!(std::fs::read(&out).unwrap(), b"done");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
