//! Output files are never half-written: everything striae writes goes to a temporary name in
//! the destination folder first and is renamed into place only when complete.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// The temporary sibling used while `path` is being written: `.NAME.tmp-PID-N` in the same
/// folder, so the final rename is atomic on one filesystem; `N` counts the calls of the process,
/// so two writers of one file (two threads, or a render and a table cache) never share it.
pub fn temp_path(path: &Path) -> PathBuf {
    static CALLS: AtomicU64 = AtomicU64::new(0);
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let call = CALLS.fetch_add(1, Ordering::Relaxed);
    let tmp = format!(".{name}.tmp-{}-{call}", std::process::id());
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
    write_all_atomically(vec![(path, Box::new(write))])
}

/// One file of [`write_all_atomically`]: where it goes, and what fills a temporary file.
pub type Output<'a, E> = (&'a Path, Box<dyn FnOnce(&Path) -> Result<(), E> + 'a>);

/// Write several files as one (a render's EXR and PNG): every temporary file is filled first,
/// and only when all are complete, and no destination is a folder, are they renamed into
/// place. A failure before the renames leaves every destination untouched and no temporary
/// file behind; only a rename failing midway (the filesystem itself failing) can leave some
/// files renamed and not others.
pub fn write_all_atomically<E>(outputs: Vec<Output<'_, E>>) -> Result<(), E>
where
    E: From<std::io::Error>,
{
    let remove = |written: &[(PathBuf, &Path)]| {
        for (tmp, _) in written {
            let _ = std::fs::remove_file(tmp);
        }
    };
    let mut written = Vec::with_capacity(outputs.len());
    for (path, write) in outputs {
        let tmp = temp_path(path);
        if let Err(e) = write(&tmp) {
            let _ = std::fs::remove_file(&tmp);
            remove(&written);
            return Err(e);
        }
        written.push((tmp, path));
    }
    if let Some((_, path)) = written.iter().find(|(_, path)| path.is_dir()) {
        let e = std::io::Error::other(format!("{} is a folder", path.display()));
        remove(&written);
        return Err(E::from(e));
    }
    for (i, (tmp, path)) in written.iter().enumerate() {
        if let Err(e) = std::fs::rename(tmp, path) {
            remove(&written[i..]);
            let e = std::io::Error::new(e.kind(), format!("renaming to {}: {e}", path.display()));
            return Err(E::from(e));
        }
    }
    Ok(())
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

    #[test]
    fn a_set_of_files_is_written_whole_or_not_at_all() {
        let dir = std::env::temp_dir().join(format!("striae-io-set-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let (a, b) = (dir.join("a.bin"), dir.join("b.bin"));
        std::fs::write(&a, b"old").unwrap();
        type Writer = Box<dyn FnOnce(&Path) -> std::io::Result<()>>;
        let write = |text: &'static [u8]| -> Writer { Box::new(move |p| std::fs::write(p, text)) };
        // The second file fails: the first keeps its old content, no temporary file is left.
        let fail: Writer = Box::new(|_| Err(std::io::Error::other("boom")));
        assert!(
            write_all_atomically(vec![(a.as_path(), write(b"new")), (b.as_path(), fail)]).is_err()
        );
        assert_eq!(std::fs::read(&a).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        // A destination that is a folder: nothing renamed, nothing left.
        std::fs::create_dir(&b).unwrap();
        let err = write_all_atomically(vec![
            (a.as_path(), write(b"new")),
            (b.as_path(), write(b"x")),
        ])
        .unwrap_err();
        assert!(err.to_string().contains("b.bin is a folder"), "{err}");
        assert_eq!(std::fs::read(&a).unwrap(), b"old");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 2);
        // Both written.
        std::fs::remove_dir(&b).unwrap();
        write_all_atomically(vec![
            (a.as_path(), write(b"new")),
            (b.as_path(), write(b"x")),
        ])
        .unwrap();
        assert_eq!(std::fs::read(&a).unwrap(), b"new");
        assert_eq!(std::fs::read(&b).unwrap(), b"x");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn concurrent_writers_of_one_file_never_share_a_temporary_name() {
        let dir = std::env::temp_dir().join(format!("striae-io-race-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let out = dir.join("t.bin");
        assert_ne!(temp_path(&out), temp_path(&out));
        // Many threads write the same destination, each its own 64 KiB of one byte value: every
        // write succeeds and the file is one writer's whole content, never a mix.
        std::thread::scope(|s| {
            for k in 0..8u8 {
                let out = &out;
                s.spawn(move || {
                    for _ in 0..20 {
                        write_atomically::<std::io::Error>(out, |p| {
                            std::fs::write(p, vec![k; 1 << 16])
                        })
                        .unwrap();
                    }
                });
            }
        });
        let data = std::fs::read(&out).unwrap();
        assert_eq!(data.len(), 1 << 16);
        assert!(data.iter().all(|&b| b == data[0]));
        assert_eq!(
            std::fs::read_dir(&dir).unwrap().count(),
            1,
            "temporary files left"
        );
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
