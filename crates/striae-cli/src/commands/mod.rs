pub mod fidelity;
pub mod figures;
pub mod gonio;
pub mod layers;
pub mod memory;
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
