//! What the CLI's signal handler does: `io::remove_temporaries` removes every temporary file the
//! process is writing. Alone in its own test binary, because it removes the temporaries of every
//! thread of the process, and the library's unit tests write files in parallel.

use striae::io::{remove_temporaries, TempFile};

#[test]
fn a_temporary_being_written_is_removed_on_request() {
    let dir = std::env::temp_dir().join(format!("striae-temporaries-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let tmp = TempFile::new(&dir.join("v.exr"), "");
    std::fs::write(tmp.path(), b"partial").unwrap();
    remove_temporaries();
    assert!(!tmp.path().exists());
    drop(tmp);
    std::fs::remove_dir_all(&dir).unwrap();
}
