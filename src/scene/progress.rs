//! Progress of scene loading on a terminal: a bar per mesh file (bytes read) and a spinner
//! while the accelerator builds. Nothing is drawn unless asked for and stderr is a terminal.

use indicatif::{ProgressBar, ProgressStyle};
use std::io::IsTerminal;
use std::path::Path;
use std::time::Duration;

/// Draws loading progress on stderr, or nothing.
pub struct LoadProgress {
    enabled: bool,
}

impl LoadProgress {
    /// Progress is drawn when `wanted` and stderr is a terminal.
    pub fn new(wanted: bool) -> LoadProgress {
        LoadProgress { enabled: wanted && std::io::stderr().is_terminal() }
    }

    /// A bar for reading the mesh file `path` of `bytes` bytes; set its position to the
    /// bytes read and finish it with [`LoadProgress::done`].
    pub fn file(&self, path: &Path, bytes: u64) -> Option<ProgressBar> {
        if !self.enabled {
            return None;
        }
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
        let bar = ProgressBar::new(bytes);
        if let Ok(style) =
            ProgressStyle::with_template("reading {prefix} {wide_bar} {binary_bytes}/{binary_total_bytes}")
        {
            bar.set_style(style);
        }
        bar.set_prefix(name);
        Some(bar)
    }

    /// A spinner with `message` (e.g. the BVH build), ticking until [`LoadProgress::done`].
    pub fn phase(&self, message: String) -> Option<ProgressBar> {
        if !self.enabled {
            return None;
        }
        let bar = ProgressBar::new_spinner();
        if let Ok(style) = ProgressStyle::with_template("{spinner} {msg} {elapsed}") {
            bar.set_style(style);
        }
        bar.set_message(message);
        bar.enable_steady_tick(Duration::from_millis(120));
        Some(bar)
    }

    /// Replaces a bar or spinner by the line `summary`.
    pub fn done(bar: Option<ProgressBar>, summary: String) {
        if let Some(bar) = bar {
            bar.finish_and_clear();
            eprintln!("{summary}");
        }
    }
}
