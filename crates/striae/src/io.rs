//! Output files are never half-written: everything striae writes goes to a temporary name in
//! the destination folder first and is renamed into place only when complete.

use std::collections::HashSet;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, OnceLock};

/// The most a scene file, a profile file or an OBJ mesh may hold: 256 MiB, far above any real
/// one (the 4,032-triangle teapot as OBJ is 0.3 MiB), so that `/dev/zero` or a runaway file is
/// refused instead of read until memory runs out.
pub const MAX_TEXT_BYTES: u64 = 256 << 20;

/// The most an input image (texture, environment map) or a table file may hold: 4 GiB.
pub const MAX_BINARY_BYTES: u64 = 4 << 30;

/// The most pixels an input image may claim in its header: 2^28 (16384 x 16384), 3 GiB as RGB
/// floats. Checked before anything is decoded, so a 500-byte file cannot ask for 120 GB.
pub const MAX_IMAGE_PIXELS: u64 = 1 << 28;

/// What a file that is not a regular file is (`a folder`, `a FIFO`, `a device`, `a socket`),
/// or `None` for a regular file: the words of every refusal to read or replace it.
fn not_regular(m: &std::fs::Metadata) -> Option<&'static str> {
    use std::os::unix::fs::FileTypeExt;
    let t = m.file_type();
    if t.is_file() {
        None
    } else if t.is_dir() {
        Some("a folder")
    } else if t.is_fifo() {
        Some("a FIFO")
    } else if t.is_char_device() || t.is_block_device() {
        Some("a device")
    } else if t.is_socket() {
        Some("a socket")
    } else {
        Some("a special file")
    }
}

/// Opens `path` for reading only if it is a regular file no larger than `limit` bytes: a
/// folder, a FIFO (which would block with no writer), a device (`/dev/zero` never ends) or a
/// socket is refused before it is opened, with what it is in the message.
pub fn open_regular(path: &Path, limit: u64) -> std::io::Result<std::fs::File> {
    let check = |m: &std::fs::Metadata| -> std::io::Result<()> {
        if let Some(what) = not_regular(m) {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!("is {what}, not a regular file"),
            ));
        }
        if m.len() > limit {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!(
                    "is {} bytes, over the limit of {} MiB for this kind of input",
                    m.len(),
                    limit >> 20
                ),
            ));
        }
        Ok(())
    };
    check(&std::fs::metadata(path)?)?;
    let file = std::fs::File::open(path)?;
    // The file may have been swapped between the two calls: check what was opened.
    check(&file.metadata()?)?;
    Ok(file)
}

/// The bytes of a regular file of at most `limit` bytes ([`open_regular`]); reading stops at
/// the limit even if the file grows meanwhile.
pub fn read_bounded(path: &Path, limit: u64) -> std::io::Result<Vec<u8>> {
    let file = open_regular(path, limit)?;
    let mut bytes = Vec::new();
    file.take(limit + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > limit {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("grew past the limit of {} MiB while read", limit >> 20),
        ));
    }
    Ok(bytes)
}

/// A text input (scene, profile, mesh) of at most [`MAX_TEXT_BYTES`], as UTF-8.
pub fn read_text(path: &Path) -> std::io::Result<String> {
    String::from_utf8(read_bounded(path, MAX_TEXT_BYTES)?)
        .map_err(|_| std::io::Error::new(std::io::ErrorKind::InvalidData, "is not UTF-8 text"))
}

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

/// The temporary files of the process that are not yet renamed into place or removed.
fn live_temporaries() -> &'static Mutex<HashSet<PathBuf>> {
    static LIVE: OnceLock<Mutex<HashSet<PathBuf>>> = OnceLock::new();
    LIVE.get_or_init(|| Mutex::new(HashSet::new()))
}

/// A temporary file (or folder) beside an output ([`temp_path`]), removed when dropped unless
/// [`TempFile::persist`] renamed it into place, and listed for [`remove_temporaries`] while
/// it lives, so an interrupted process leaves nothing behind.
pub struct TempFile {
    path: PathBuf,
}

impl TempFile {
    /// A new temporary name for `output`, ending in `suffix` (plotters picks its encoder from
    /// the extension, so a plot's temporary name keeps `.png`).
    pub fn new(output: &Path, suffix: &str) -> TempFile {
        let mut name = temp_path(output).into_os_string();
        name.push(suffix);
        let path = PathBuf::from(name);
        let mut live = live_temporaries().lock().unwrap_or_else(|e| e.into_inner());
        live.insert(path.clone());
        TempFile { path }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Renames the file to `dest`.
    pub fn persist(self, dest: &Path) -> std::io::Result<()> {
        std::fs::rename(&self.path, dest).map_err(|e| {
            std::io::Error::new(e.kind(), format!("renaming to {}: {e}", dest.display()))
        })
    }
}

/// Removes a file, or a folder with what it holds.
fn remove(path: &Path) {
    match std::fs::symlink_metadata(path) {
        Ok(m) if m.is_dir() => drop(std::fs::remove_dir_all(path)),
        Ok(_) => drop(std::fs::remove_file(path)),
        Err(_) => {}
    }
}

impl Drop for TempFile {
    fn drop(&mut self) {
        remove(&self.path);
        let mut live = live_temporaries().lock().unwrap_or_else(|e| e.into_inner());
        live.remove(&self.path);
    }
}

/// Removes every temporary file of the process: the CLI calls it on SIGINT and SIGTERM before
/// it exits.
pub fn remove_temporaries() {
    let live = live_temporaries().lock().unwrap_or_else(|e| e.into_inner());
    for path in live.iter() {
        remove(path);
    }
}

/// Removes the temporary files in `dir` left by processes that no longer run (killed, so
/// unable to clean up): `.NAME.tmp-PID-N...` whose `PID` has no `/proc/PID`. Only names of
/// `output` when given, else all. Does nothing where `/proc` is missing.
pub fn sweep_stale_temporaries(dir: &Path, output: Option<&str>) {
    let proc_fs = Path::new("/proc");
    if !proc_fs.join("self").exists() {
        return;
    }
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let own = std::process::id().to_string();
    for entry in entries.flatten() {
        let name = entry.file_name().to_string_lossy().into_owned();
        let Some((head, tail)) = name.rsplit_once(".tmp-") else {
            continue;
        };
        let named = head
            .strip_prefix('.')
            .is_some_and(|n| output.is_none_or(|o| n == o));
        let pid = tail.split('-').next().unwrap_or("");
        if named
            && !pid.is_empty()
            && pid.bytes().all(|b| b.is_ascii_digit())
            && pid != own
            && !proc_fs.join(pid).exists()
        {
            remove(&entry.path());
        }
    }
}

/// Publishes a folder filled under a temporary name as `dest`: renamed into place when `dest`
/// does not exist, else each of its files renamed into `dest` (replacing files of the same
/// name). Either way every file appears complete, and a failure before this call leaves
/// `dest` as it was.
pub fn publish_folder(tmp: TempFile, dest: &Path) -> std::io::Result<()> {
    if !dest.exists() {
        return tmp.persist(dest);
    }
    for entry in std::fs::read_dir(tmp.path())? {
        let entry = entry?;
        let to = dest.join(entry.file_name());
        check_destination(&to)?;
        std::fs::rename(entry.path(), &to).map_err(|e| {
            std::io::Error::new(e.kind(), format!("renaming to {}: {e}", to.display()))
        })?;
    }
    Ok(())
}

/// An output may replace a regular file or nothing: a device node, a FIFO, a socket or a
/// folder at its name is refused before anything is written (renaming over `/dev/null` would
/// replace the device itself).
pub fn check_destination(path: &Path) -> std::io::Result<()> {
    // The folder first, so that a long render does not end in a failed write.
    let folder = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    if !folder.is_dir() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::NotFound,
            format!(
                "cannot write {}: folder {} does not exist",
                path.display(),
                folder.display()
            ),
        ));
    }
    // `metadata` follows a symbolic link: what it names must be a regular file too.
    match std::fs::metadata(path).ok().as_ref().and_then(not_regular) {
        Some(what) => Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!(
                "{} is {what}, not a regular file; refusing to replace it",
                path.display()
            ),
        )),
        None => Ok(()),
    }
}

/// Whether two paths name the same existing file (an output that would overwrite the
/// command's own input).
pub fn same_file(a: &Path, b: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (std::fs::metadata(a), std::fs::metadata(b)) {
        (Ok(x), Ok(y)) => x.dev() == y.dev() && x.ino() == y.ino(),
        _ => false,
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
    for (path, _) in &outputs {
        check_destination(path).map_err(E::from)?;
        if let (Some(dir), Some(name)) = (path.parent(), path.file_name()) {
            let dir = if dir.as_os_str().is_empty() {
                Path::new(".")
            } else {
                dir
            };
            sweep_stale_temporaries(dir, Some(&name.to_string_lossy()));
        }
    }
    // Dropping a `TempFile` removes it: any early return leaves no temporary file.
    let mut written = Vec::with_capacity(outputs.len());
    for (path, write) in outputs {
        let tmp = TempFile::new(path, "");
        write(tmp.path())?;
        written.push((tmp, path));
    }
    if let Some((_, path)) = written.iter().find(|(_, path)| path.is_dir()) {
        return Err(E::from(std::io::Error::other(format!(
            "{} is a folder",
            path.display()
        ))));
    }
    for (tmp, path) in written {
        tmp.persist(path).map_err(E::from)?;
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
        // A device node is never replaced.
        let e =
            write_atomically::<std::io::Error>(Path::new("/dev/null"), |p| std::fs::write(p, b"x"))
                .unwrap_err();
        assert!(e.to_string().contains("not a regular file"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn temporaries_of_dead_processes_are_swept() {
        let dir = std::env::temp_dir().join(format!("striae-io-sweep-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // PID 4194304 is above Linux's largest (2^22): never a live process.
        let dead = dir.join(".t.npz.tmp-4194304-0");
        let dead_other = dir.join(".u.npz.tmp-4194304-3");
        let live = dir.join(format!(".t.npz.tmp-{}-99", std::process::id()));
        let unrelated = dir.join("t.npz.tmp-notes");
        for p in [&dead, &dead_other, &live, &unrelated] {
            std::fs::write(p, b"x").unwrap();
        }
        sweep_stale_temporaries(&dir, Some("t.npz"));
        assert!(!dead.exists() && dead_other.exists() && live.exists() && unrelated.exists());
        sweep_stale_temporaries(&dir, None);
        assert!(!dead_other.exists() && live.exists() && unrelated.exists());
        // A write sweeps its own name's stale temporaries.
        std::fs::write(&dead, b"x").unwrap();
        write_atomically::<std::io::Error>(&dir.join("t.npz"), |p| std::fs::write(p, b"t"))
            .unwrap();
        assert!(!dead.exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn only_bounded_regular_files_are_read() {
        let dir = std::env::temp_dir().join(format!("striae-io-read-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("a.txt");
        std::fs::write(&file, "0123456789").unwrap();
        assert_eq!(read_text(&file).unwrap(), "0123456789");
        let over = read_bounded(&file, 4).unwrap_err().to_string();
        assert!(over.contains("over the limit"), "{over}");
        for (path, what) in [
            (dir.as_path(), "a folder"),
            (Path::new("/dev/zero"), "a device"),
            (Path::new("/dev/urandom"), "a device"),
        ] {
            let e = read_text(path).unwrap_err().to_string();
            assert!(e.contains(what), "{}: {e}", path.display());
        }
        // A FIFO with no writer: refused at once instead of blocking in `open`.
        let fifo = dir.join("fifo");
        let made = std::process::Command::new("mkfifo").arg(&fifo).status();
        if made.is_ok_and(|s| s.success()) {
            let e = read_text(&fifo).unwrap_err().to_string();
            assert!(e.contains("a FIFO"), "{e}");
        }
        std::fs::write(&file, [0xff, 0xfe]).unwrap();
        assert!(read_text(&file).unwrap_err().to_string().contains("UTF-8"));
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
