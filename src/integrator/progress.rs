//! How a render shows its progress: a bar on a terminal, and on anything else (a Slurm log,
//! a pipe) a line every `log_interval` seconds with the time elapsed, the samples per pixel
//! done (of how many), the samples per second, the time left and, with a noise threshold,
//! the render's relMSE estimate, instead of a bar's control codes.

use crate::integrator::run::{Budget, RunOptions};
use std::io::IsTerminal;
use std::sync::Mutex;
use std::time::{Duration, Instant};

/// The progress of one render loop.
pub(crate) enum Progress {
    Off,
    Bar { bar: indicatif::ProgressBar, budget: Budget, tiles: u64 },
    Log { every: Duration, last: Mutex<Instant>, budget: Budget, w: u32, h: u32, spp: u32 },
}

impl Progress {
    /// The progress of a render of `w × h` pixels in `tiles` tiles, `spp` samples per pixel
    /// (for a sample budget), started at `start`: nothing without `opts.progress`.
    pub fn new(opts: &RunOptions, w: u32, h: u32, tiles: usize, spp: u32, start: Instant) -> Progress {
        if !opts.progress {
            return Progress::Off;
        }
        if !std::io::stderr().is_terminal() {
            let every = Duration::from_secs_f64(opts.log_interval.max(0.0));
            return Progress::Log { every, last: Mutex::new(start), budget: opts.budget, w, h, spp };
        }
        let (len, template) = match opts.budget {
            Budget::Spp(_) => (
                spp as u64 * tiles as u64,
                format!("{w}×{h} {{wide_bar}} {{percent}}% of {spp} spp, ETA {{eta}} — {{msg}}"),
            ),
            Budget::Time(_) => (1000, format!("{w}×{h} {{wide_bar}} {{elapsed}} — {{msg}}")),
        };
        let bar = indicatif::ProgressBar::new(len);
        if let Ok(style) = indicatif::ProgressStyle::with_template(&template) {
            bar.set_style(style);
        }
        bar.enable_steady_tick(Duration::from_secs(1));
        Progress::Bar { bar, budget: opts.budget, tiles: tiles as u64 }
    }

    /// A tile of `count` iterations is done (a pass of a large image takes long: the bar
    /// moves by tiles).
    pub fn tile_done(&self, count: u32, start: Instant) {
        if let Progress::Bar { bar, budget, .. } = self {
            match budget {
                Budget::Spp(_) => bar.inc(count as u64),
                Budget::Time(secs) => bar.set_position(time_position(start, *secs)),
            }
        }
    }

    /// A pass is done: `done` samples per pixel in all, `samples` samples since `start`, and
    /// the relMSE estimate when the render takes one.
    pub fn pass_done(&self, done: u32, samples: u64, noise: Option<f64>, start: Instant) {
        let secs = start.elapsed().as_secs_f64().max(1e-9);
        let rate = samples as f64 / secs / 1e6;
        match self {
            Progress::Off => {}
            Progress::Bar { bar, budget, tiles } => {
                match budget {
                    Budget::Spp(_) => bar.set_position(done as u64 * tiles),
                    Budget::Time(t) => bar.set_position(time_position(start, *t)),
                }
                bar.set_message(format!("{done} spp, {rate:.2} M samples/s{}", noise_part(noise)));
            }
            Progress::Log { every, last, budget, w, h, spp } => {
                let mut last = last.lock().unwrap_or_else(|e| e.into_inner());
                if last.elapsed() < *every {
                    return;
                }
                *last = Instant::now();
                eprintln!("{}{}", log_line(*budget, (*w, *h), *spp, done, rate, secs), noise_part(noise));
            }
        }
    }

    /// The render is over.
    pub fn finish(self) {
        if let Progress::Bar { bar, .. } = self {
            bar.finish_and_clear();
        }
    }
}

/// One line of a log's progress: `[12 s] 320×180: 16 of 64 spp (25%), 1.23 M samples/s, about
/// 36 s left` (for a time budget, the seconds of the budget instead of the samples planned).
fn log_line(budget: Budget, (w, h): (u32, u32), spp: u32, done: u32, rate: f64, secs: f64) -> String {
    let (of, left) = match budget {
        Budget::Spp(_) => {
            let fraction = done as f64 / spp.max(1) as f64;
            let left = if fraction > 0.0 { secs * (1.0 - fraction) / fraction } else { f64::NAN };
            (format!("{done} of {spp} spp ({:.0}%)", 100.0 * fraction), left)
        }
        Budget::Time(t) => (format!("{done} spp in {secs:.0} of {t:.0} s"), (t - secs).max(0.0)),
    };
    let left = if left.is_finite() { format!(", about {left:.0} s left") } else { String::new() };
    format!("[{secs:.0} s] {w}×{h}: {of}, {rate:.2} M samples/s{left}")
}

/// The relMSE estimate's part of a progress line (nothing without one).
fn noise_part(noise: Option<f64>) -> String {
    noise.map(|e| format!(", relMSE estimate {e:.3e}")).unwrap_or_default()
}

/// The position of a time budget's progress bar: thousandths of `budget` seconds elapsed.
fn time_position(start: Instant, budget: f64) -> u64 {
    (start.elapsed().as_secs_f64() / budget * 1000.0).min(1000.0) as u64
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn log_lines_say_what_is_done_and_what_is_left() {
        let l = log_line(Budget::Spp(64), (320, 180), 64, 16, 1.234, 12.0);
        assert_eq!(l, "[12 s] 320×180: 16 of 64 spp (25%), 1.23 M samples/s, about 36 s left");
        let t = log_line(Budget::Time(60.0), (8, 8), 0, 5, 0.5, 20.0);
        assert_eq!(t, "[20 s] 8×8: 5 spp in 20 of 60 s, 0.50 M samples/s, about 40 s left");
        let none = log_line(Budget::Spp(4), (8, 8), 4, 0, 0.0, 0.5);
        assert_eq!(none, "[0 s] 8×8: 0 of 4 spp (0%), 0.00 M samples/s");
        assert_eq!(noise_part(Some(0.0123)), ", relMSE estimate 1.230e-2");
        assert_eq!(noise_part(None), "");
    }
}
