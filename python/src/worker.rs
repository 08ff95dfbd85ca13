//! Long calls (a load, a render, an experiment) on a worker thread while the calling thread
//! waits without the GIL and answers Ctrl-C: Python runs its signal handlers only on the
//! main thread, between bytecodes, so a call that held it for minutes would delay
//! KeyboardInterrupt until it returned.

use pyo3::exceptions::PyRuntimeError;
use pyo3::prelude::*;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// How often the waiting thread looks for Ctrl-C (Python's signal handlers run there).
const POLL: Duration = Duration::from_millis(50);

/// Runs `work` on a thread named `name`, looking for signals every [`POLL`]. On an
/// exception from a signal handler (KeyboardInterrupt) it raises that exception: with a
/// `stop` flag, after setting it and waiting for `work` to end (which the flag makes
/// prompt); without one, at once, leaving `work` to finish on its own and its result to be
/// dropped. A panic of `work` is a `RuntimeError` saying that `what` failed.
pub fn run_on_worker<T: Send + 'static>(
    py: Python<'_>,
    name: &str,
    what: &str,
    stop: Option<Arc<AtomicBool>>,
    work: impl FnOnce() -> T + Send + 'static,
) -> PyResult<T> {
    let caller = std::thread::current();
    let worker = std::thread::Builder::new()
        .name(name.into())
        .spawn(move || {
            let out = work();
            caller.unpark();
            out
        })
        .map_err(|e| PyRuntimeError::new_err(format!("cannot start the thread of {what}: {e}")))?;
    while !worker.is_finished() {
        py.detach(|| std::thread::park_timeout(POLL));
        if let Err(e) = py.check_signals() {
            if let Some(stop) = stop {
                stop.store(true, Ordering::Relaxed);
                // What the worker returns is not wanted.
                let _ = py.detach(|| worker.join());
            }
            return Err(e);
        }
    }
    worker.join().map_err(|panic| PyRuntimeError::new_err(format!("{what} failed: {}", panic_message(&*panic))))
}

/// The message of a panic's payload.
fn panic_message(payload: &(dyn std::any::Any + Send)) -> &str {
    match (payload.downcast_ref::<&str>(), payload.downcast_ref::<String>()) {
        (Some(s), _) => s,
        (_, Some(s)) => s,
        _ => "a panic without a message",
    }
}
