//! The one channel through which the library tells the user something while it works: a table
//! being computed, a cache file that could not be read. The library never prints; it hands each
//! message to the handler installed with [`set_handler`] (the CLI prints it above its progress
//! bar, the Python package passes it to Python's `warnings`), or, when none is installed, to
//! standard error as `striae: MESSAGE` / `striae: warning: MESSAGE`.

use std::sync::RwLock;

/// How much a message matters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Level {
    /// Progress worth a line (a table computed and how long it took).
    Info,
    /// Something went wrong and was worked around (a cache file recomputed).
    Warning,
}

/// A message handler.
pub type Handler = Box<dyn Fn(Level, &str) + Send + Sync>;

static HANDLER: RwLock<Option<Handler>> = RwLock::new(None);

/// Install the handler for every later message of the process (`None`: standard error).
pub fn set_handler(handler: Option<Handler>) {
    *HANDLER.write().unwrap_or_else(|e| e.into_inner()) = handler;
}

/// Hand a message to the handler.
pub fn emit(level: Level, message: &str) {
    match &*HANDLER.read().unwrap_or_else(|e| e.into_inner()) {
        Some(handler) => handler(level, message),
        None => match level {
            Level::Info => eprintln!("striae: {message}"),
            Level::Warning => eprintln!("striae: warning: {message}"),
        },
    }
}

/// [`emit`] at [`Level::Info`].
pub fn info(message: &str) {
    emit(Level::Info, message);
}

/// [`emit`] at [`Level::Warning`].
pub fn warn(message: &str) {
    emit(Level::Warning, message);
}
