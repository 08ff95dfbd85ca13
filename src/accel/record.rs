//! A log of the ray queries of a render (the `ray-record` feature): every closest-hit and
//! occlusion query of [`Accel`](super::Accel) made while recording is on, from any thread,
//! in the order they take the log's lock (a render on one thread records its queries in the
//! order it makes them). What the ray-bound benchmark (`benches/ray_bound.rs`) replays to
//! time the backend alone on exactly the rays of a render. Without the feature nothing is
//! compiled into the queries; with it, a query while recording is off costs one atomic load.

use super::Ray;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};

/// One recorded query.
#[derive(Clone, Copy, Debug)]
pub enum Query {
    /// A closest-hit query.
    Intersect(Ray),
    /// An occlusion (any-hit) query.
    Occluded(Ray),
}

static RECORDING: AtomicBool = AtomicBool::new(false);
static LOG: Mutex<Vec<Query>> = Mutex::new(Vec::new());

/// Starts recording (dropping what an earlier recording kept).
pub fn start() {
    let mut log = LOG.lock().unwrap_or_else(|e| e.into_inner());
    log.clear();
    RECORDING.store(true, Ordering::SeqCst);
}

/// Stops recording and returns the queries recorded since [`start`].
pub fn stop() -> Vec<Query> {
    RECORDING.store(false, Ordering::SeqCst);
    std::mem::take(&mut *LOG.lock().unwrap_or_else(|e| e.into_inner()))
}

/// Keeps `query` while recording is on.
#[inline]
pub(crate) fn push(query: Query) {
    if RECORDING.load(Ordering::Relaxed) {
        LOG.lock().unwrap_or_else(|e| e.into_inner()).push(query);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::accel::{Accel, Backend, BuildOptions, Geometry};
    use glam::Vec3;

    /// Whether `log` holds the two queries, the hit first, among any others (tests on other
    /// threads may query while this one records).
    fn holds(log: &[Query], hit: &Ray, miss: &Ray) -> bool {
        let first = log.iter().position(|q| matches!(q, Query::Intersect(r) if r == hit));
        let second = log.iter().rposition(|q| matches!(q, Query::Occluded(r) if r == miss));
        matches!((first, second), (Some(a), Some(b)) if a < b)
    }

    #[test]
    fn records_the_queries_made_while_recording() {
        let positions = [Vec3::new(-1.0, -1.0, 0.0), Vec3::new(1.0, -1.0, 0.0), Vec3::new(0.0, 1.0, 0.0)];
        let indices = [[0u32, 1, 2]];
        let geometry = [Geometry::Triangles { positions: &positions, indices: &indices }];
        let accel = Accel::build(Backend::Embree, &geometry, BuildOptions::default()).unwrap();
        // Rays no other test traces.
        let hit = Ray::new(Vec3::new(0.0123, 0.0456, 1.0), Vec3::NEG_Z);
        let miss = Ray::new(Vec3::new(5.0789, 0.0, 1.0), Vec3::NEG_Z);
        accel.intersect(&hit);
        start();
        assert!(accel.intersect(&hit).is_some());
        assert!(!accel.occluded(&miss));
        let log = stop();
        assert!(holds(&log, &hit, &miss), "{log:?}");
        accel.intersect(&hit);
        accel.occluded(&miss);
        start();
        assert!(!holds(&stop(), &hit, &miss));
    }
}
