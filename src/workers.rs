//! Worker thread pools: a plain one (scene loading) and the renders' one, whose threads flush
//! denormals to zero from their start ([`crate::accel::embree::set_flush_denormals`], as
//! Embree's traversal kernels want), so no tile, chain or pool has to set it again.

use crate::error::Error;

fn builder(threads: usize) -> rayon::ThreadPoolBuilder {
    rayon::ThreadPoolBuilder::new().num_threads(threads)
}

fn build(b: rayon::ThreadPoolBuilder, threads: usize) -> Result<rayon::ThreadPool, Error> {
    b.build().map_err(|e| Error::Usage(format!("cannot start {threads} threads: {e}")))
}

/// A worker pool of `threads` threads (0 = all cores).
pub fn pool(threads: usize) -> Result<rayon::ThreadPool, Error> {
    build(builder(threads), threads)
}

/// A render's worker pool of `threads` threads (0 = all cores): each thread sets the
/// flushing of denormals once, when it starts. Everything a render computes runs on it.
pub fn render_pool(threads: usize) -> Result<rayon::ThreadPool, Error> {
    build(builder(threads).start_handler(|_| crate::accel::embree::set_flush_denormals()), threads)
}
