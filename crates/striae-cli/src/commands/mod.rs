pub mod fidelity;
pub mod figures;
pub mod gonio;
pub mod hologram;
pub mod layers;
pub mod merge;
pub mod plot;
pub mod precompute;
pub mod render;

/// Print what the library reports while it works ([`striae::log`]: a scratch table being
/// computed, a cache file recomputed) on standard error: warnings always, progress lines unless
/// `quiet`.
pub fn print_library_messages(quiet: bool) {
    striae::log::set_handler(Some(Box::new(move |level, message| match level {
        striae::log::Level::Warning => eprintln!("striae: warning: {message}"),
        striae::log::Level::Info if !quiet => eprintln!("striae: {message}"),
        striae::log::Level::Info => {}
    })));
}

/// The output file `path` of `flag`, checked before anything is computed: its folder exists,
/// and its name holds a regular file or nothing (`io::check_destination`).
pub fn check_output_file(flag: &str, path: &std::path::Path) -> anyhow::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => std::path::Path::new("."),
    };
    if !dir.is_dir() {
        anyhow::bail!(
            "{flag} {}: the folder {} does not exist",
            path.display(),
            dir.display()
        );
    }
    striae::io::check_destination(path)
        .map_err(|e| anyhow::anyhow!("{flag} {}: {e}", path.display()))
}
