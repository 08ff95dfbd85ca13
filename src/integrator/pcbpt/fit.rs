//! How large PCBPT's cache (contract §3) will be before the first iteration, and which
//! value of each option would make it fit its memory limit: the numbers the render loop's
//! refusal names.

use crate::integrator::pcbpt::{Cache, PcOptions};

/// PCBPT's cache size before the first iteration, as a function of its options: the pool
/// is sized at 1.5 times the pilot's mean connectible vertices per light path.
#[derive(Clone, Copy)]
pub struct CacheFit<'a> {
    pub opts: &'a PcOptions,
    /// Light paths per iteration (M).
    pub light_paths: usize,
    /// The pilot pool's mean connectible vertices per light path.
    pub mean_vertices: f64,
    /// The image's size.
    pub w: u32,
    pub h: u32,
}

impl CacheFit<'_> {
    /// Records, pool vertices and MiB of the cache with this stride, depth and path count.
    pub fn size(&self, stride: u32, depth: u32, light_paths: usize) -> (usize, usize, f64) {
        let o = PcOptions { stride, cache_depth: depth, ..self.opts.clone() };
        let records = o.max_records(self.w, self.h);
        let v = (1.5 * light_paths as f64 * self.mean_vertices).ceil() as usize;
        (records, v, Cache::bytes(records, v) / (1024.0 * 1024.0))
    }

    fn fits(&self, stride: u32, depth: u32, light_paths: usize) -> bool {
        self.size(stride, depth, light_paths).2 <= self.opts.max_cache_mb as f64
    }

    /// The options that make the cache fit, each changed alone, with values that fit.
    pub fn suggestions(&self) -> String {
        let (s, d, m) = (self.opts.stride, self.opts.cache_depth, self.light_paths);
        let mut ways = Vec::new();
        if let Some(stride) = (s + 1..=self.w.max(self.h)).find(|&x| self.fits(x, d, m)) {
            ways.push(format!("--pc-cache-stride {stride}"));
        }
        if let Some(depth) = (1..d).rev().find(|&x| self.fits(s, x, m)) {
            ways.push(format!("--pc-cache-depth {depth}"));
        }
        // Fewer light paths also make a new pilot, whose vertices per path differ from this
        // one's: the count suggested fits pools of up to twice this pilot's mean.
        let wide = CacheFit { mean_vertices: 2.0 * self.mean_vertices, ..*self };
        let mut paths = m - 1;
        while paths > 0 && !wide.fits(s, d, paths) {
            // The cache grows about linearly with the paths: jump close to the count that fits.
            let (_, _, mb) = wide.size(s, d, paths);
            paths = ((paths as f64 * self.opts.max_cache_mb as f64 / mb).floor() as usize).min(paths - 1);
        }
        if paths > 0 {
            // With a pool-vertex target, M would grow back past the count suggested.
            let fixed = if self.opts.pool.pool_vertices > 0 { " --pool-vertices 0" } else { "" };
            ways.push(format!("--pc-light-paths {paths}{fixed}"));
        }
        let need = self.size(s, d, m).2.ceil() as usize;
        ways.push(format!("raise the limit to --pc-max-cache-mb {need}"));
        let last = ways.pop().unwrap_or_default();
        if ways.is_empty() { last } else { format!("it fits with {}, or {last}", ways.join(", or ")) }
    }
}
